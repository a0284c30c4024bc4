//! Window surfaces and swapchains. `SUBOPTIMAL` and `OUT_OF_DATE` are
//! states that mean "rebuild", reported as such, not errors.

use std::ffi::c_char;

use ash::vk;
use std::sync::Arc;

use raw_window_handle::{HasDisplayHandle, HasWindowHandle, RawDisplayHandle};

use super::commands::Recorder;
use super::device::Device;
use super::error::{Result, VkError, VkResultExt};
use super::memory::{Buffer, Image, ImageDesc, Transition};
use super::owned::{Owned, Semaphore};
use super::target::{depth_usage, Multisampled, TargetViews, DEPTH_FORMAT, DEPTH_USED};

/// Instance extensions a surface for this display needs.
pub fn surface_extensions(display: RawDisplayHandle) -> Result<&'static [*const c_char]> {
    ash_window::enumerate_required_extensions(display)
        .context("listing the window system's Vulkan extensions")
}

/// A window's surface. It holds the window and the device (whose
/// instance it was made from), so both outlive it; swapchains hold the
/// surface, so it outlives them.
pub struct Surface {
    loader: ash::khr::surface::Instance,
    raw: vk::SurfaceKHR,
    device: Device,
    _window: Arc<dyn std::any::Any + Send + Sync>,
}

impl Surface {
    /// A surface for `window`, checked to be one `device` can present to.
    pub fn new<W>(device: &Device, window: Arc<W>) -> Result<Self>
    where
        W: HasDisplayHandle + HasWindowHandle + Send + Sync + 'static,
    {
        let handles = window.display_handle().and_then(|d| {
            let w = window.window_handle()?;
            Ok((d.as_raw(), w.as_raw()))
        });
        let (display, handle) = handles
            .map_err(|e| VkError::Unsupported(format!("the window has no usable handle: {e}")))?;
        let instance = device.instance();
        // SAFETY: the handles come from `window`, which the surface holds
        // for as long as it lives.
        let raw = unsafe {
            ash_window::create_surface(&instance.entry, &instance.raw, display, handle, None)
        }
        .context("creating a window surface")?;
        let surface = Surface {
            loader: ash::khr::surface::Instance::new(&instance.entry, &instance.raw),
            raw,
            device: device.clone(),
            _window: window,
        };
        // SAFETY: plain query.
        let supported = unsafe {
            surface.loader.get_physical_device_surface_support(
                device.physical,
                device.queue_family,
                surface.raw,
            )
        }
        .context("checking presentation support")?;
        if !supported {
            return Err(VkError::Unsupported(format!(
                "{} cannot present to this window",
                device.caps.device_name
            )));
        }
        Ok(surface)
    }
}

impl Drop for Surface {
    fn drop(&mut self) {
        let _ = self.device.wait_idle();
        // SAFETY: every swapchain of this surface has been dropped: each
        // holds the surface. The instance is alive while `device` is.
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

/// What a swapchain for a surface will be: an sRGB format where offered,
/// the present mode asked for or FIFO, the surface's extent (or `size`
/// within its limits), one image more than the minimum.
struct SurfaceChoice {
    format: vk::SurfaceFormatKHR,
    present_mode: vk::PresentModeKHR,
    extent: vk::Extent2D,
    image_count: u32,
    /// Images can be copied out (for screenshots).
    readable: bool,
    transform: vk::SurfaceTransformFlagsKHR,
}

impl SurfaceChoice {
    fn new(
        device: &Device,
        surface: &Surface,
        size: vk::Extent2D,
        present_mode: vk::PresentModeKHR,
    ) -> Result<Self> {
        let (loader, physical) = (&surface.loader, device.physical);
        // SAFETY: plain queries on a live surface.
        let (caps, formats, modes) = unsafe {
            (
                loader
                    .get_physical_device_surface_capabilities(physical, surface.raw)
                    .context("reading surface capabilities")?,
                loader
                    .get_physical_device_surface_formats(physical, surface.raw)
                    .context("reading surface formats")?,
                loader
                    .get_physical_device_surface_present_modes(physical, surface.raw)
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
        Ok(SurfaceChoice {
            format,
            present_mode,
            extent,
            image_count,
            readable: caps
                .supported_usage_flags
                .contains(vk::ImageUsageFlags::TRANSFER_SRC),
            transform: caps.current_transform,
        })
    }
}

/// What the frames in flight draw into besides the swapchain's images.
enum Attachments {
    /// One sample per pixel: a depth image.
    Depth(Image),
    /// More: multisampled colour and depth, the colour resolved into the
    /// swapchain's image.
    Multisampled(Multisampled),
}

impl Attachments {
    /// The targets of a swapchain of `extent` and `format` drawn with
    /// `samples` samples per pixel.
    fn new(
        device: &Device,
        extent: vk::Extent2D,
        format: vk::Format,
        samples: u32,
    ) -> Result<Self> {
        Ok(
            match Multisampled::new(device, extent, format, samples, "swapchain")? {
                Some(ms) => Attachments::Multisampled(ms),
                None => Attachments::Depth(device.create_image(
                    ImageDesc {
                        extent,
                        format: DEPTH_FORMAT,
                        usage: depth_usage(device, 1),
                        aspect: vk::ImageAspectFlags::DEPTH,
                        samples: vk::SampleCountFlags::TYPE_1,
                    },
                    "swapchain.depth",
                )?),
            },
        )
    }
}

/// A swapchain with a view and a semaphore per image, and the depth image
/// (or multisampled colour and depth images) its frames in flight share.
/// Dropping it waits for the device to go idle first.
pub struct Swapchain {
    loader: ash::khr::swapchain::Device,
    raw: vk::SwapchainKHR,
    pub format: vk::SurfaceFormatKHR,
    pub extent: vk::Extent2D,
    pub present_mode: vk::PresentModeKHR,
    images: Vec<vk::Image>,
    views: Vec<Owned<vk::ImageView>>,
    /// One per image: a semaphore is only reused once its image comes back.
    render_finished: Vec<Semaphore>,
    attachments: Attachments,
    /// Whether images can be copied out (for screenshots).
    pub readable: bool,
    device: Device,
    /// Kept alive for as long as the swapchain.
    _surface: Arc<Surface>,
}

impl Swapchain {
    /// A swapchain for `surface` of about `size` (the surface may insist on
    /// its own), in `present_mode` when supported and FIFO otherwise. sRGB
    /// formats are preferred. `old` is retired by the new one. Frames are
    /// drawn with `samples` samples per pixel.
    pub fn new(
        device: &Device,
        surface: &Arc<Surface>,
        size: vk::Extent2D,
        present_mode: vk::PresentModeKHR,
        samples: u32,
        old: Option<Swapchain>,
    ) -> Result<Self> {
        let choice = SurfaceChoice::new(device, surface, size, present_mode)?;
        let SurfaceChoice {
            format,
            present_mode,
            extent,
            image_count,
            readable,
            transform,
        } = choice;
        let mut usage = vk::ImageUsageFlags::COLOR_ATTACHMENT;
        if readable {
            usage |= vk::ImageUsageFlags::TRANSFER_SRC;
        }
        let loader = ash::khr::swapchain::Device::new(&device.instance().raw, device.ash());
        let info = vk::SwapchainCreateInfoKHR::default()
            .surface(surface.raw)
            .min_image_count(image_count)
            .image_format(format.format)
            .image_color_space(format.color_space)
            .image_extent(extent)
            .image_array_layers(1)
            .image_usage(usage)
            .image_sharing_mode(vk::SharingMode::EXCLUSIVE)
            .pre_transform(transform)
            .composite_alpha(vk::CompositeAlphaFlagsKHR::OPAQUE)
            .present_mode(present_mode)
            .clipped(true)
            .old_swapchain(old.as_ref().map_or(vk::SwapchainKHR::null(), |o| o.raw));
        // SAFETY: the swapchain holds the surface; the old swapchain is
        // retired here and dropped below (its Drop waits for idle).
        let created = unsafe { loader.create_swapchain(&info, None) };
        // The old targets go before the new ones are made, so a memory
        // budget never has to hold both sizes at once.
        drop(old);
        let raw = created.context("creating the swapchain")?;
        let attachments = match Attachments::new(device, extent, format.format, samples) {
            Ok(attachments) => attachments,
            Err(e) => {
                // SAFETY: just created, and nothing uses it yet.
                unsafe { loader.destroy_swapchain(raw, None) };
                return Err(e);
            }
        };
        device.set_name(raw, "swapchain");
        // Owned from here: a failure below destroys it.
        let mut swapchain = Swapchain {
            loader,
            raw,
            format,
            extent,
            present_mode,
            images: Vec::new(),
            views: Vec::new(),
            render_finished: Vec::new(),
            attachments,
            readable,
            device: device.clone(),
            _surface: Arc::clone(surface),
        };
        // SAFETY: the swapchain was just created.
        let images = unsafe { swapchain.loader.get_swapchain_images(raw) }
            .context("listing swapchain images")?;
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
            let view = unsafe { device.ash().create_image_view(&view_info, None) }
                .context("creating a swapchain view")?;
            swapchain.views.push(Owned::new(
                device,
                view,
                &format!("swapchain.image[{i}].view"),
            ));
            swapchain
                .render_finished
                .push(device.create_semaphore(&format!("swapchain.render_finished[{i}]"))?);
        }
        swapchain.images = images;
        Ok(swapchain)
    }

    /// The next image; `signal` is signalled when it may be drawn into.
    pub fn acquire(&self, signal: &Semaphore) -> Result<Acquired> {
        // SAFETY: `signal` is unsignalled: the frame slot that owns it waited
        // for the submission that last waited on it.
        match unsafe {
            self.loader
                .acquire_next_image(self.raw, u64::MAX, signal.raw(), vk::Fence::null())
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
    pub fn present(&self, index: u32) -> Result<bool> {
        let wait = [self.render_finished[index as usize].raw()];
        let swapchains = [self.raw];
        let indices = [index];
        let info = vk::PresentInfoKHR::default()
            .wait_semaphores(&wait)
            .swapchains(&swapchains)
            .image_indices(&indices);
        // SAFETY: the image was acquired and rendered to by a submission that
        // signals `wait`.
        match unsafe { self.loader.queue_present(self.device.queue, &info) } {
            Ok(suboptimal) => Ok(suboptimal),
            Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => Ok(true),
            Err(result) => Err(VkError::Call {
                context: "presenting",
                result,
            }),
        }
    }

    pub fn render_finished(&self, index: u32) -> &Semaphore {
        &self.render_finished[index as usize]
    }

    pub fn views(&self, index: u32) -> TargetViews {
        let color = self.views[index as usize].raw();
        match &self.attachments {
            Attachments::Multisampled(ms) => ms.views(self.extent, color, None),
            Attachments::Depth(depth) => TargetViews {
                extent: self.extent,
                color_view: color,
                color_format: self.format.format,
                samples: vk::SampleCountFlags::TYPE_1,
                depth_view: depth.view(),
                depth_image: depth.raw(),
                depth_serial: depth.serial(),
                depth_readable: depth.desc.usage.contains(vk::ImageUsageFlags::SAMPLED),
                color_resolve: None,
                depth_resolve: None,
            },
        }
    }

    /// Makes image `index` and the images drawn into with it attachments;
    /// earlier contents are discarded.
    pub fn record_begin(&self, rec: &Recorder, index: u32) {
        use vk::{AccessFlags2 as A, PipelineStageFlags2 as S};
        let image = self.images[index as usize];
        // Ordered after the acquire semaphore's wait stage.
        let after_acquire = (S::COLOR_ATTACHMENT_OUTPUT, A::NONE);
        match &self.attachments {
            Attachments::Depth(depth) => rec.transition_images(&Transition::to_attachments(
                image,
                after_acquire,
                depth.raw(),
                // The depth image is shared by the frames in flight: the
                // previous frame's depth writes and reads must finish first.
                DEPTH_USED,
            )),
            Attachments::Multisampled(ms) => {
                rec.transition_images(&[Transition::to_color_attachment(image, after_acquire)]);
                ms.record_begin(rec);
            }
        }
    }

    /// Makes image `index` ready to present after drawing, copying it into
    /// `capture` first when given (which must hold width x height x 4
    /// bytes; `readable` swapchains only).
    pub fn record_present(&self, rec: &Recorder, index: u32, capture: Option<&Buffer>) {
        use vk::{AccessFlags2 as A, ImageLayout as L, PipelineStageFlags2 as S};
        let image = self.images[index as usize];
        let to_present = |from| Transition {
            image,
            aspect: vk::ImageAspectFlags::COLOR,
            from,
            // Presentation waits on the semaphore, which covers all commands.
            to: (L::PRESENT_SRC_KHR, S::NONE, A::NONE),
        };
        match capture {
            Some(buffer) => {
                rec.transition_images(&[Transition::color_output_to_copy(image)]);
                rec.copy_image_to_buffer(image, vk::ImageAspectFlags::COLOR, self.extent, buffer);
                rec.transition_images(&[to_present((L::TRANSFER_SRC_OPTIMAL, S::COPY, A::NONE))]);
            }
            None => rec.transition_images(&[to_present((
                L::COLOR_ATTACHMENT_OPTIMAL,
                S::COLOR_ATTACHMENT_OUTPUT,
                A::COLOR_ATTACHMENT_WRITE,
            ))]),
        }
    }
}

impl Drop for Swapchain {
    fn drop(&mut self) {
        // Presentation and the last frames may still use the images.
        let _ = self.device.wait_idle();
        // The views of its images go before the swapchain.
        self.views.clear();
        // SAFETY: the device is idle and nothing refers to the images now.
        unsafe { self.loader.destroy_swapchain(self.raw, None) };
    }
}

impl Device {
    pub fn create_semaphore(&self, name: &str) -> Result<Semaphore> {
        // SAFETY: valid create info.
        let semaphore = unsafe {
            self.ash()
                .create_semaphore(&vk::SemaphoreCreateInfo::default(), None)
        }
        .context("creating a semaphore")?;
        Ok(Owned::new(self, semaphore, name))
    }
}
