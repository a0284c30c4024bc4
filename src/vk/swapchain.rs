//! Window surfaces and swapchains. `SUBOPTIMAL` and `OUT_OF_DATE` are
//! states that mean "rebuild", reported as such, not errors.

use std::ffi::c_char;

use ash::vk;
use raw_window_handle::{RawDisplayHandle, RawWindowHandle};

use super::device::Device;
use super::error::{Result, VkError, VkResultExt};
use super::instance::Instance;
use super::memory::{Image, ImageDesc};
use super::target::{TargetViews, DEPTH_FORMAT};

/// Instance extensions a surface for this display needs.
pub fn surface_extensions(display: RawDisplayHandle) -> Result<&'static [*const c_char]> {
    ash_window::enumerate_required_extensions(display)
        .context("listing the window system's Vulkan extensions")
}

pub struct Surface {
    loader: ash::khr::surface::Instance,
    pub raw: vk::SurfaceKHR,
}

impl Surface {
    pub fn new(
        instance: &Instance,
        display: RawDisplayHandle,
        window: RawWindowHandle,
    ) -> Result<Self> {
        // SAFETY: the handles come from a live window that the caller keeps
        // alive for longer than the surface.
        let raw = unsafe {
            ash_window::create_surface(&instance.entry, &instance.raw, display, window, None)
        }
        .context("creating a window surface")?;
        Ok(Surface {
            loader: ash::khr::surface::Instance::new(&instance.entry, &instance.raw),
            raw,
        })
    }

    /// Fails unless the device's queue can present to this surface.
    pub fn check_support(&self, device: &Device) -> Result<()> {
        // SAFETY: plain query.
        let supported = unsafe {
            self.loader.get_physical_device_surface_support(
                device.physical,
                device.queue_family,
                self.raw,
            )
        }
        .context("checking presentation support")?;
        if supported {
            Ok(())
        } else {
            Err(VkError::Unsupported(format!(
                "{} cannot present to this window",
                device.caps.device_name
            )))
        }
    }

    /// Destroyed before the instance, after every swapchain made from it.
    pub fn destroy(self) {
        // SAFETY: no swapchain of this surface remains.
        unsafe { self.loader.destroy_surface(self.raw, None) };
    }
}

/// The outcome of acquiring an image.
pub enum Acquired {
    /// Index of the image; `suboptimal` asks for a rebuild after this frame.
    Image { index: u32, suboptimal: bool },
    /// The swapchain no longer matches the surface: rebuild, then retry.
    OutOfDate,
}

pub struct Swapchain {
    loader: ash::khr::swapchain::Device,
    raw: vk::SwapchainKHR,
    pub format: vk::SurfaceFormatKHR,
    pub extent: vk::Extent2D,
    pub present_mode: vk::PresentModeKHR,
    images: Vec<vk::Image>,
    views: Vec<vk::ImageView>,
    /// One per image: a semaphore is only reused once its image comes back.
    render_finished: Vec<vk::Semaphore>,
    depth: Image,
    /// Whether images can be copied out (for screenshots).
    pub readable: bool,
}

impl Swapchain {
    /// A swapchain for `surface` of about `size` (the surface may insist on
    /// its own), in `present_mode` when supported and FIFO otherwise. sRGB
    /// formats are preferred. `old` is retired by the new one.
    pub fn new(
        instance: &Instance,
        device: &Device,
        surface: &Surface,
        size: vk::Extent2D,
        present_mode: vk::PresentModeKHR,
        old: Option<Swapchain>,
    ) -> Result<Self> {
        // SAFETY: plain queries on a live surface.
        let (caps, formats, modes) = unsafe {
            (
                surface
                    .loader
                    .get_physical_device_surface_capabilities(device.physical, surface.raw)
                    .context("reading surface capabilities")?,
                surface
                    .loader
                    .get_physical_device_surface_formats(device.physical, surface.raw)
                    .context("reading surface formats")?,
                surface
                    .loader
                    .get_physical_device_surface_present_modes(device.physical, surface.raw)
                    .context("reading present modes")?,
            )
        };
        let format = formats
            .iter()
            .copied()
            .find(|f| {
                matches!(
                    f.format,
                    vk::Format::B8G8R8A8_SRGB | vk::Format::R8G8B8A8_SRGB
                ) && f.color_space == vk::ColorSpaceKHR::SRGB_NONLINEAR
            })
            .or_else(|| formats.first().copied())
            .ok_or_else(|| VkError::Unsupported("the surface offers no formats".into()))?;
        let present_mode = if modes.contains(&present_mode) {
            present_mode
        } else {
            log::warn!("present mode {present_mode:?} is not supported here; using FIFO");
            vk::PresentModeKHR::FIFO
        };
        let extent = if caps.current_extent.width != u32::MAX {
            caps.current_extent
        } else {
            vk::Extent2D {
                width: size
                    .width
                    .clamp(caps.min_image_extent.width, caps.max_image_extent.width),
                height: size
                    .height
                    .clamp(caps.min_image_extent.height, caps.max_image_extent.height),
            }
        };
        let mut image_count = caps.min_image_count + 1;
        if caps.max_image_count > 0 {
            image_count = image_count.min(caps.max_image_count);
        }
        let readable = caps
            .supported_usage_flags
            .contains(vk::ImageUsageFlags::TRANSFER_SRC);
        let mut usage = vk::ImageUsageFlags::COLOR_ATTACHMENT;
        if readable {
            usage |= vk::ImageUsageFlags::TRANSFER_SRC;
        }
        let loader = ash::khr::swapchain::Device::new(&instance.raw, &device.raw);
        let info = vk::SwapchainCreateInfoKHR::default()
            .surface(surface.raw)
            .min_image_count(image_count)
            .image_format(format.format)
            .image_color_space(format.color_space)
            .image_extent(extent)
            .image_array_layers(1)
            .image_usage(usage)
            .image_sharing_mode(vk::SharingMode::EXCLUSIVE)
            .pre_transform(caps.current_transform)
            .composite_alpha(vk::CompositeAlphaFlagsKHR::OPAQUE)
            .present_mode(present_mode)
            .clipped(true)
            .old_swapchain(old.as_ref().map_or(vk::SwapchainKHR::null(), |o| o.raw));
        // SAFETY: the surface outlives the swapchain; the old swapchain is
        // retired here and destroyed below once the device is idle.
        let created = unsafe { loader.create_swapchain(&info, None) };
        if let Some(old) = old {
            old.destroy(device);
        }
        let raw = created.context("creating the swapchain")?;
        device.set_name(raw, "swapchain");
        // SAFETY: the swapchain was just created.
        let images =
            unsafe { loader.get_swapchain_images(raw) }.context("listing swapchain images")?;
        let mut views = Vec::with_capacity(images.len());
        let mut render_finished = Vec::with_capacity(images.len());
        for (i, &image) in images.iter().enumerate() {
            device.set_name(image, &format!("swapchain.image[{i}]"));
            let view_info = vk::ImageViewCreateInfo::default()
                .image(image)
                .view_type(vk::ImageViewType::TYPE_2D)
                .format(format.format)
                .subresource_range(super::memory::subresource_range(
                    vk::ImageAspectFlags::COLOR,
                ));
            // SAFETY: the view matches the image's format.
            let view = unsafe { device.raw.create_image_view(&view_info, None) }
                .context("creating a swapchain view")?;
            device.set_name(view, &format!("swapchain.image[{i}].view"));
            views.push(view);
            render_finished
                .push(device.create_semaphore(&format!("swapchain.render_finished[{i}]"))?);
        }
        let depth = device.create_image(
            ImageDesc {
                extent,
                format: DEPTH_FORMAT,
                usage: vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT,
                aspect: vk::ImageAspectFlags::DEPTH,
            },
            "swapchain.depth",
        )?;
        Ok(Swapchain {
            loader,
            raw,
            format,
            extent,
            present_mode,
            images,
            views,
            render_finished,
            depth,
            readable,
        })
    }

    pub fn acquire(&self, signal: vk::Semaphore) -> Result<Acquired> {
        // SAFETY: `signal` is unsignalled and not waited on by anything pending.
        match unsafe {
            self.loader
                .acquire_next_image(self.raw, u64::MAX, signal, vk::Fence::null())
        } {
            Ok((index, suboptimal)) => Ok(Acquired::Image { index, suboptimal }),
            Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => Ok(Acquired::OutOfDate),
            Err(result) => Err(VkError::Call {
                context: "acquiring a swapchain image",
                result,
            }),
        }
    }

    /// Presents image `index` once its `render_finished` semaphore signals.
    /// Returns true when the swapchain should be rebuilt.
    pub fn present(&self, device: &Device, index: u32) -> Result<bool> {
        let wait = [self.render_finished[index as usize]];
        let swapchains = [self.raw];
        let indices = [index];
        let info = vk::PresentInfoKHR::default()
            .wait_semaphores(&wait)
            .swapchains(&swapchains)
            .image_indices(&indices);
        // SAFETY: the image was acquired and rendered to by a submission that
        // signals `wait`.
        match unsafe { self.loader.queue_present(device.queue, &info) } {
            Ok(suboptimal) => Ok(suboptimal),
            Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => Ok(true),
            Err(result) => Err(VkError::Call {
                context: "presenting",
                result,
            }),
        }
    }

    pub fn render_finished(&self, index: u32) -> vk::Semaphore {
        self.render_finished[index as usize]
    }

    pub fn views(&self, index: u32) -> TargetViews {
        TargetViews {
            extent: self.extent,
            color_image: self.images[index as usize],
            color_view: self.views[index as usize],
            color_format: self.format.format,
            depth_image: self.depth.raw,
            depth_view: self.depth.view,
            depth_format: DEPTH_FORMAT,
        }
    }

    /// The caller has waited for the device to go idle.
    pub fn destroy(self, device: &Device) {
        // SAFETY: nothing pending uses these objects.
        unsafe {
            for view in &self.views {
                device.raw.destroy_image_view(*view, None);
            }
            for semaphore in &self.render_finished {
                device.raw.destroy_semaphore(*semaphore, None);
            }
            self.loader.destroy_swapchain(self.raw, None);
        }
        device.destroy_image(self.depth);
    }
}

impl Device {
    pub fn create_semaphore(&self, name: &str) -> Result<vk::Semaphore> {
        // SAFETY: valid create info.
        let semaphore = unsafe {
            self.raw
                .create_semaphore(&vk::SemaphoreCreateInfo::default(), None)
        }
        .context("creating a semaphore")?;
        self.set_name(semaphore, name);
        Ok(semaphore)
    }

    pub fn destroy_semaphore(&self, semaphore: vk::Semaphore) {
        // SAFETY: no pending work waits on or signals it.
        unsafe { self.raw.destroy_semaphore(semaphore, None) };
    }

    /// Submits `cmd` waiting on `wait` at colour output and signalling
    /// `signal` and `fence` when done: one frame of a window.
    pub fn submit_frame(
        &self,
        cmd: vk::CommandBuffer,
        wait: vk::Semaphore,
        signal: vk::Semaphore,
        fence: vk::Fence,
    ) -> Result<()> {
        let cmds = [vk::CommandBufferSubmitInfo::default().command_buffer(cmd)];
        let waits = [vk::SemaphoreSubmitInfo::default()
            .semaphore(wait)
            .stage_mask(vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT)];
        let signals = [vk::SemaphoreSubmitInfo::default()
            .semaphore(signal)
            .stage_mask(vk::PipelineStageFlags2::ALL_COMMANDS)];
        let submit = vk::SubmitInfo2::default()
            .command_buffer_infos(&cmds)
            .wait_semaphore_infos(&waits)
            .signal_semaphore_infos(&signals);
        self.count_submission()?;
        // SAFETY: `cmd` is recorded; `fence` is unsignalled.
        unsafe { self.raw.queue_submit2(self.queue, &[submit], fence) }
            .context("submitting a frame")
    }
}
