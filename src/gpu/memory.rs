//! Buffers and images with memory from gpu-allocator, and uploads through a
//! staging buffer. Each frees its handles and memory when dropped.

use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use std::mem::ManuallyDrop;

use super::commands::Recorder;
use super::device::{Device, DeviceShared};
use super::error::{Result, VkError, VkResultExt};
use super::owned::{Fence, Owned};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BufferDesc {
    pub size: u64,
    pub usage: vk::BufferUsageFlags,
    pub location: MemoryLocation,
}

/// Memory from the device's allocator, given back when dropped.
struct Memory {
    allocation: ManuallyDrop<Allocation>,
    device: Device,
}

impl Drop for Memory {
    fn drop(&mut self) {
        // SAFETY: taken once, here; the field is never used again.
        let allocation = unsafe { ManuallyDrop::take(&mut self.allocation) };
        // A failure here means the allocation wasn't from this allocator,
        // which by construction cannot happen; there is nothing to recover.
        let _ = self.device.allocator().free(allocation);
    }
}

/// A buffer and its memory. Fields drop in order: the buffer, then the
/// memory it was bound to.
pub struct Buffer {
    raw: Owned<vk::Buffer>,
    memory: Memory,
    pub desc: BufferDesc,
    name: String,
}

impl Buffer {
    /// The mapped bytes of a host-visible buffer.
    pub fn mapped(&self) -> Option<&[u8]> {
        self.memory
            .allocation
            .mapped_slice()
            .map(|s| &s[..self.desc.size as usize])
    }

    pub fn mapped_mut(&mut self) -> Option<&mut [u8]> {
        let size = self.desc.size as usize;
        self.memory
            .allocation
            .mapped_slice_mut()
            .map(|s| &mut s[..size])
    }

    /// Copies `bytes` to the start of a host-visible buffer.
    pub fn write(&mut self, bytes: &[u8]) -> Result<()> {
        let name = self.name.clone();
        let mapped = self.mapped_mut().ok_or_else(|| {
            VkError::Unsupported(format!("{name}: host-visible memory is not mapped"))
        })?;
        let Some(start) = mapped.get_mut(..bytes.len()) else {
            return Err(VkError::Unsupported(format!(
                "{name}: {} bytes do not fit in {}",
                bytes.len(),
                mapped.len()
            )));
        };
        start.copy_from_slice(bytes);
        Ok(())
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    pub(super) fn raw(&self) -> vk::Buffer {
        self.raw.raw()
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ImageDesc {
    pub extent: vk::Extent2D,
    pub format: vk::Format,
    pub usage: vk::ImageUsageFlags,
    pub aspect: vk::ImageAspectFlags,
    /// Samples per pixel (TYPE_1 but for multisampled attachments).
    pub samples: vk::SampleCountFlags,
}

/// An image, its whole view and its memory. Fields drop in order: the
/// view, the image, then the memory.
pub struct Image {
    view: Owned<vk::ImageView>,
    raw: Owned<vk::Image>,
    _memory: Memory,
    pub desc: ImageDesc,
    serial: u64,
}

/// The next image's serial number.
static NEXT_IMAGE_SERIAL: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

impl Image {
    pub(super) fn raw(&self) -> vk::Image {
        self.raw.raw()
    }

    /// A number no other image of this process has had: unlike a Vulkan
    /// handle, which a driver may hand to a new image once this one is
    /// destroyed, it tells the image apart from every later one.
    pub(super) fn serial(&self) -> u64 {
        self.serial
    }

    pub(super) fn view(&self) -> vk::ImageView {
        self.view.raw()
    }
}

impl DeviceShared {
    /// Bytes currently allocated, per resource name (from the allocator's
    /// own report).
    pub fn memory_report(&self) -> Vec<(String, u64)> {
        let mut bytes = std::collections::BTreeMap::<String, u64>::new();
        for a in self.allocator().generate_report().allocations {
            *bytes.entry(a.name).or_default() += a.size;
        }
        bytes.into_iter().collect()
    }

    /// Bytes currently allocated in all.
    pub fn memory_in_use(&self) -> u64 {
        self.allocator().generate_report().total_allocated_bytes
    }
}

impl Device {
    /// Memory for `requirements`, within the budget.
    fn allocate(
        &self,
        name: &str,
        requirements: vk::MemoryRequirements,
        location: MemoryLocation,
        linear: bool,
    ) -> Result<Memory> {
        if let Some(budget) = self.memory_budget() {
            let in_use = self.memory_in_use();
            if in_use.saturating_add(requirements.size) > budget {
                return Err(VkError::OverBudget {
                    name: name.to_string(),
                    requested: requirements.size,
                    in_use,
                    budget,
                });
            }
        }
        self.count_allocation(name)?;
        let allocation = self
            .allocator()
            .allocate(&AllocationCreateDesc {
                name,
                requirements,
                location,
                linear,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            })
            .map_err(|source| VkError::Allocation {
                name: name.to_string(),
                source,
            })?;
        Ok(Memory {
            allocation: ManuallyDrop::new(allocation),
            device: self.clone(),
        })
    }

    pub fn create_buffer(&self, desc: BufferDesc, name: &str) -> Result<Buffer> {
        let info = vk::BufferCreateInfo::default()
            .size(desc.size.max(1))
            .usage(desc.usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid create info on a live device.
        let raw = unsafe { self.ash().create_buffer(&info, None) }.context("creating a buffer")?;
        let raw = Owned::new(self, raw, name);
        // SAFETY: `raw` was just created from this device.
        let requirements = unsafe { self.ash().get_buffer_memory_requirements(raw.raw()) };
        let memory = self.allocate(name, requirements, desc.location, true)?;
        let a = &memory.allocation;
        // SAFETY: memory and offset come from the allocator for these
        // requirements; the buffer has no memory yet.
        unsafe {
            self.ash()
                .bind_buffer_memory(raw.raw(), a.memory(), a.offset())
        }
        .context("binding buffer memory")?;
        Ok(Buffer {
            raw,
            memory,
            desc,
            name: name.to_string(),
        })
    }

    /// A host-visible buffer filled with `bytes`.
    pub fn create_host_buffer(
        &self,
        name: &str,
        usage: vk::BufferUsageFlags,
        bytes: &[u8],
    ) -> Result<Buffer> {
        let mut buffer = self.create_buffer(
            BufferDesc {
                size: bytes.len() as u64,
                usage,
                location: MemoryLocation::CpuToGpu,
            },
            name,
        )?;
        buffer.write(bytes)?;
        Ok(buffer)
    }

    /// A device-local buffer with `bytes` copied in through a staging buffer.
    pub fn upload_buffer(
        &self,
        name: &str,
        usage: vk::BufferUsageFlags,
        bytes: &[u8],
    ) -> Result<Buffer> {
        let staging = self.create_host_buffer(
            &format!("{name}.staging"),
            vk::BufferUsageFlags::TRANSFER_SRC,
            bytes,
        )?;
        let buffer = self.create_buffer(
            BufferDesc {
                size: bytes.len() as u64,
                usage: usage | vk::BufferUsageFlags::TRANSFER_DST,
                location: MemoryLocation::GpuOnly,
            },
            name,
        )?;
        self.one_shot(&format!("{name}.upload"), |rec| {
            rec.copy_buffer(&staging, &buffer, bytes.len() as u64)
        })?;
        Ok(buffer)
    }

    pub fn create_image(&self, desc: ImageDesc, name: &str) -> Result<Image> {
        self.create_image_array(desc, 1, 1, vk::ImageViewType::TYPE_2D, name)
    }

    /// An image of `levels` mip levels and `layers` array layers, viewed
    /// whole as `view_type`.
    pub fn create_image_array(
        &self,
        desc: ImageDesc,
        levels: u32,
        layers: u32,
        view_type: vk::ImageViewType,
        name: &str,
    ) -> Result<Image> {
        let info = image_info(&desc, levels, layers);
        // SAFETY: valid create info.
        let raw = unsafe { self.ash().create_image(&info, None) }.context("creating an image")?;
        let raw = Owned::new(self, raw, name);
        // SAFETY: `raw` was just created from this device.
        let requirements = unsafe { self.ash().get_image_memory_requirements(raw.raw()) };
        let memory = self.allocate(name, requirements, MemoryLocation::GpuOnly, false)?;
        let a = &memory.allocation;
        // SAFETY: memory and offset come from the allocator for these
        // requirements; the image has no memory yet.
        unsafe {
            self.ash()
                .bind_image_memory(raw.raw(), a.memory(), a.offset())
        }
        .context("binding image memory")?;
        let view_info = vk::ImageViewCreateInfo::default()
            .image(raw.raw())
            .view_type(view_type)
            .format(desc.format)
            .subresource_range(subresource_range(desc.aspect));
        // SAFETY: the view matches the image's format and aspect.
        let view = unsafe { self.ash().create_image_view(&view_info, None) }
            .context("creating an image view")?;
        Ok(Image {
            view: Owned::new(self, view, &format!("{name}.view")),
            raw,
            _memory: memory,
            desc,
            serial: NEXT_IMAGE_SERIAL.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
        })
    }

    /// Records `record` into a fresh command buffer of the transient pool,
    /// submits it and waits for it to finish.
    pub fn one_shot(&self, name: &str, record: impl FnOnce(&Recorder)) -> Result<()> {
        let pool = self.transient_pool();
        let info = vk::CommandBufferAllocateInfo::default()
            .command_pool(*pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the pool belongs to this device and is held locked.
        let cmd = unsafe { self.ash().allocate_command_buffers(&info) }
            .context("allocating a command buffer")?[0];
        self.set_name(cmd, name);
        let result = (|| {
            let fence = self.create_fence(&format!("{name}.fence"), false)?;
            let begin = vk::CommandBufferBeginInfo::default()
                .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
            // SAFETY: a freshly allocated command buffer.
            unsafe { self.ash().begin_command_buffer(cmd, &begin) }
                .context("beginning commands")?;
            record(&Recorder::new(self, cmd));
            // SAFETY: recording was begun above.
            unsafe { self.ash().end_command_buffer(cmd) }.context("ending commands")?;
            self.submit(cmd, &[], &[], &fence)?;
            self.wait_fence(&fence)
        })();
        if result.is_err() {
            // A failed submission may still have started: let it finish
            // before the command buffer and what it used are freed.
            let _ = self.wait_idle();
        }
        // SAFETY: the submission finished (or never started).
        unsafe { self.ash().free_command_buffers(*pool, &[cmd]) };
        result
    }

    pub fn create_fence(&self, name: &str, signalled: bool) -> Result<Fence> {
        let flags = if signalled {
            vk::FenceCreateFlags::SIGNALED
        } else {
            vk::FenceCreateFlags::empty()
        };
        // SAFETY: valid create info.
        let fence = unsafe {
            self.ash()
                .create_fence(&vk::FenceCreateInfo::default().flags(flags), None)
        }
        .context("creating a fence")?;
        Ok(Owned::new(self, fence, name))
    }
}

/// Every level and layer of an image.
pub fn subresource_range(aspect: vk::ImageAspectFlags) -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange::default()
        .aspect_mask(aspect)
        .level_count(vk::REMAINING_MIP_LEVELS)
        .layer_count(vk::REMAINING_ARRAY_LAYERS)
}

/// The shape of an image `Device::upload_image` fills.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TexelUpload {
    pub format: vk::Format,
    pub width: u32,
    pub height: u32,
    pub layers: u32,
    pub view_type: vk::ImageViewType,
}

/// One image layout transition with synchronization2 scopes.
#[derive(Clone, Copy, Debug)]
pub(super) struct Transition {
    pub image: vk::Image,
    pub aspect: vk::ImageAspectFlags,
    pub from: (vk::ImageLayout, vk::PipelineStageFlags2, vk::AccessFlags2),
    pub to: (vk::ImageLayout, vk::PipelineStageFlags2, vk::AccessFlags2),
}

/// The stages and accesses that write a depth image during rendering:
/// depth tests, and (for the single-sample image a multisampled depth
/// attachment resolves into) the resolve, which Vulkan counts as a colour
/// attachment write whatever the format.
pub const DEPTH_WRITTEN: (vk::ImageLayout, vk::PipelineStageFlags2, vk::AccessFlags2) = (
    vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL,
    vk::PipelineStageFlags2::from_raw(
        vk::PipelineStageFlags2::EARLY_FRAGMENT_TESTS.as_raw()
            | vk::PipelineStageFlags2::LATE_FRAGMENT_TESTS.as_raw()
            | vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT.as_raw(),
    ),
    vk::AccessFlags2::from_raw(
        vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_READ.as_raw()
            | vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE.as_raw()
            | vk::AccessFlags2::COLOR_ATTACHMENT_WRITE.as_raw(),
    ),
);

impl Transition {
    /// A colour and a depth image made attachments, their old contents
    /// discarded, once the work before them at `color_after` and
    /// `depth_after` (stage, access) is done.
    pub fn to_attachments(
        color: vk::Image,
        color_after: (vk::PipelineStageFlags2, vk::AccessFlags2),
        depth: vk::Image,
        depth_after: (vk::PipelineStageFlags2, vk::AccessFlags2),
    ) -> [Transition; 2] {
        [
            Transition::to_color_attachment(color, color_after),
            Transition {
                image: depth,
                aspect: vk::ImageAspectFlags::DEPTH,
                from: (vk::ImageLayout::UNDEFINED, depth_after.0, depth_after.1),
                to: DEPTH_WRITTEN,
            },
        ]
    }

    /// A colour image made an attachment, its old contents discarded, once
    /// the work before it at `after` (stage, access) is done.
    pub fn to_color_attachment(
        image: vk::Image,
        after: (vk::PipelineStageFlags2, vk::AccessFlags2),
    ) -> Transition {
        use vk::{AccessFlags2 as A, ImageLayout as L, PipelineStageFlags2 as S};
        Transition {
            image,
            aspect: vk::ImageAspectFlags::COLOR,
            from: (L::UNDEFINED, after.0, after.1),
            to: (
                L::COLOR_ATTACHMENT_OPTIMAL,
                S::COLOR_ATTACHMENT_OUTPUT,
                A::COLOR_ATTACHMENT_WRITE,
            ),
        }
    }

    /// A colour attachment just drawn, made ready to be copied from.
    pub fn color_output_to_copy(image: vk::Image) -> Transition {
        use vk::{AccessFlags2 as A, ImageLayout as L, PipelineStageFlags2 as S};
        Transition {
            image,
            aspect: vk::ImageAspectFlags::COLOR,
            from: (
                L::COLOR_ATTACHMENT_OPTIMAL,
                S::COLOR_ATTACHMENT_OUTPUT,
                A::COLOR_ATTACHMENT_WRITE,
            ),
            to: (L::TRANSFER_SRC_OPTIMAL, S::COPY, A::TRANSFER_READ),
        }
    }
}

impl Device {
    /// A sampled R32_SFLOAT image holding `texels` (row-major, `width`
    /// per row), uploaded through a staging buffer and left in
    /// SHADER_READ_ONLY_OPTIMAL for vertex to fragment stages.
    pub fn upload_r32f_image(
        &self,
        name: &str,
        width: u32,
        height: u32,
        texels: &[f32],
    ) -> Result<Image> {
        self.upload_image(
            name,
            &TexelUpload {
                format: vk::Format::R32_SFLOAT,
                width,
                height,
                layers: 1,
                view_type: vk::ImageViewType::TYPE_2D,
            },
            &[bytemuck::cast_slice(texels)],
        )
    }

    /// A sampled image whose level i is `levels[i]`: every layer in turn,
    /// each (width >> i) x (height >> i) texels (at least 1) of `up.format`,
    /// rows top first. Uploaded through one staging buffer and left in
    /// SHADER_READ_ONLY_OPTIMAL for vertex to fragment stages.
    pub fn upload_image(&self, name: &str, up: &TexelUpload, levels: &[&[u8]]) -> Result<Image> {
        let image = self.create_image_array(
            ImageDesc {
                extent: vk::Extent2D {
                    width: up.width,
                    height: up.height,
                },
                format: up.format,
                usage: vk::ImageUsageFlags::SAMPLED | vk::ImageUsageFlags::TRANSFER_DST,
                aspect: vk::ImageAspectFlags::COLOR,
                samples: vk::SampleCountFlags::TYPE_1,
            },
            levels.len() as u32,
            up.layers,
            up.view_type,
            name,
        )?;
        let staging = self.create_host_buffer(
            &format!("{name}.staging"),
            vk::BufferUsageFlags::TRANSFER_SRC,
            &levels.concat(),
        )?;
        let mut offset = 0u64;
        let regions: Vec<vk::BufferImageCopy> = levels
            .iter()
            .enumerate()
            .map(|(i, bytes)| {
                let region = vk::BufferImageCopy::default()
                    .buffer_offset(offset)
                    .image_subresource(
                        vk::ImageSubresourceLayers::default()
                            .aspect_mask(vk::ImageAspectFlags::COLOR)
                            .mip_level(i as u32)
                            .layer_count(up.layers),
                    )
                    .image_extent(vk::Extent3D {
                        width: (up.width >> i).max(1),
                        height: (up.height >> i).max(1),
                        depth: 1,
                    });
                offset += bytes.len() as u64;
                region
            })
            .collect();
        use vk::{AccessFlags2 as A, ImageLayout as L, PipelineStageFlags2 as S};
        self.one_shot(&format!("{name}.upload"), |rec| {
            rec.transition_images(&[Transition {
                image: image.raw(),
                aspect: vk::ImageAspectFlags::COLOR,
                from: (L::UNDEFINED, S::NONE, A::NONE),
                to: (L::TRANSFER_DST_OPTIMAL, S::COPY, A::TRANSFER_WRITE),
            }]);
            // SAFETY: the staging buffer holds every level at the offsets
            // of `regions`, each level's extent of texels per layer.
            unsafe {
                self.ash().cmd_copy_buffer_to_image(
                    rec.cmd,
                    staging.raw(),
                    image.raw(),
                    L::TRANSFER_DST_OPTIMAL,
                    &regions,
                )
            };
            rec.transition_images(&[Transition {
                image: image.raw(),
                aspect: vk::ImageAspectFlags::COLOR,
                from: (L::TRANSFER_DST_OPTIMAL, S::COPY, A::TRANSFER_WRITE),
                to: (
                    L::SHADER_READ_ONLY_OPTIMAL,
                    S::ALL_GRAPHICS,
                    A::SHADER_SAMPLED_READ,
                ),
            }]);
        })?;
        Ok(image)
    }
}

/// One region of a `Recorder::copy_to_layers`: `width` x `height` texels
/// from `offset` bytes into the staging buffer, into the top-left corner
/// of array layer `layer`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LayerCopy {
    pub offset: u64,
    pub layer: u32,
    pub width: u32,
    pub height: u32,
}

impl Device {
    /// A 2D array image of `layers` layers of `side` x `side` R32_SFLOAT
    /// texels that shaders sample and copies write (see
    /// `Recorder::copy_to_layers`), in SHADER_READ_ONLY_OPTIMAL. Its
    /// contents start undefined.
    pub fn create_layer_pool(&self, name: &str, side: u32, layers: u32) -> Result<Image> {
        let image = self.create_image_array(
            layer_pool_desc(side),
            1,
            layers,
            vk::ImageViewType::TYPE_2D_ARRAY,
            name,
        )?;
        self.one_shot(&format!("{name}.layout"), |rec| {
            rec.transition_images(&[Transition {
                image: image.raw(),
                aspect: vk::ImageAspectFlags::COLOR,
                from: UNDEFINED_NONE,
                to: SAMPLED,
            }]);
        })?;
        Ok(image)
    }
}

/// A layer pool's layers: `side` x `side` f32 samples, sampled and
/// copied into.
fn layer_pool_desc(side: u32) -> ImageDesc {
    ImageDesc {
        extent: vk::Extent2D {
            width: side,
            height: side,
        },
        format: vk::Format::R32_SFLOAT,
        usage: vk::ImageUsageFlags::SAMPLED | vk::ImageUsageFlags::TRANSFER_DST,
        aspect: vk::ImageAspectFlags::COLOR,
        samples: vk::SampleCountFlags::TYPE_1,
    }
}

/// The create info of a 2D image of `desc` with `levels` mip levels and
/// `layers` array layers.
fn image_info(desc: &ImageDesc, levels: u32, layers: u32) -> vk::ImageCreateInfo<'static> {
    vk::ImageCreateInfo::default()
        .image_type(vk::ImageType::TYPE_2D)
        .format(desc.format)
        .extent(vk::Extent3D {
            width: desc.extent.width,
            height: desc.extent.height,
            depth: 1,
        })
        .mip_levels(levels)
        .array_layers(layers)
        .samples(desc.samples)
        .tiling(vk::ImageTiling::OPTIMAL)
        .usage(desc.usage)
        .sharing_mode(vk::SharingMode::EXCLUSIVE)
        .initial_layout(vk::ImageLayout::UNDEFINED)
}

impl Device {
    /// Bytes of memory a layer pool of `layers` layers of `side` x `side`
    /// samples takes (`create_layer_pool`), without making it.
    pub fn layer_pool_bytes(&self, side: u32, layers: u32) -> u64 {
        let info = image_info(&layer_pool_desc(side), 1, layers.max(1));
        let query = vk::DeviceImageMemoryRequirements::default().create_info(&info);
        let mut requirements = vk::MemoryRequirements2::default();
        // SAFETY: a valid create info; Vulkan 1.3 is required of the device.
        unsafe {
            self.ash()
                .get_device_image_memory_requirements(&query, &mut requirements)
        };
        requirements.memory_requirements.size
    }
}

type LayoutScope = (vk::ImageLayout, vk::PipelineStageFlags2, vk::AccessFlags2);
const UNDEFINED_NONE: LayoutScope = (
    vk::ImageLayout::UNDEFINED,
    vk::PipelineStageFlags2::NONE,
    vk::AccessFlags2::NONE,
);
/// Sampled by any graphics stage.
const SAMPLED: LayoutScope = (
    vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
    vk::PipelineStageFlags2::ALL_GRAPHICS,
    vk::AccessFlags2::SHADER_SAMPLED_READ,
);
/// Written by a copy.
const COPIED: LayoutScope = (
    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
    vk::PipelineStageFlags2::COPY,
    vk::AccessFlags2::TRANSFER_WRITE,
);

impl Recorder<'_> {
    /// One barrier moving each array layer in `layers` (one at a time, so
    /// the others stay readable) from `from` to `to`.
    fn layer_barriers(
        &self,
        image: vk::Image,
        layers: impl IntoIterator<Item = u32>,
        (from, to): (LayoutScope, LayoutScope),
    ) {
        let barriers: Vec<vk::ImageMemoryBarrier2> = layers
            .into_iter()
            .map(|layer| {
                vk::ImageMemoryBarrier2::default()
                    .image(image)
                    .subresource_range(
                        subresource_range(vk::ImageAspectFlags::COLOR)
                            .base_array_layer(layer)
                            .layer_count(1),
                    )
                    .old_layout(from.0)
                    .src_stage_mask(from.1)
                    .src_access_mask(from.2)
                    .new_layout(to.0)
                    .dst_stage_mask(to.1)
                    .dst_access_mask(to.2)
            })
            .collect();
        // SAFETY: the image belongs to this device and `cmd` is recording
        // outside rendering.
        unsafe {
            self.device.ash().cmd_pipeline_barrier2(
                self.cmd,
                &vk::DependencyInfo::default().image_memory_barriers(&barriers),
            )
        };
    }

    /// Copies `regions` of `staging` into layers of `pool` (from
    /// `create_layer_pool`), outside rendering: each written layer leaves
    /// SHADER_READ_ONLY_OPTIMAL after every earlier command's reads of it,
    /// and is back before any later one's.
    pub fn copy_to_layers(&self, staging: &Buffer, pool: &Image, regions: &[LayerCopy]) {
        if regions.is_empty() {
            return;
        }
        let layers: Vec<u32> = regions.iter().map(|r| r.layer).collect();
        self.layer_barriers(pool.raw(), layers.iter().copied(), (SAMPLED, COPIED));
        let copies: Vec<vk::BufferImageCopy> = regions
            .iter()
            .map(|r| {
                vk::BufferImageCopy::default()
                    .buffer_offset(r.offset)
                    .image_subresource(
                        vk::ImageSubresourceLayers::default()
                            .aspect_mask(vk::ImageAspectFlags::COLOR)
                            .base_array_layer(r.layer)
                            .layer_count(1),
                    )
                    .image_extent(vk::Extent3D {
                        width: r.width,
                        height: r.height,
                        depth: 1,
                    })
            })
            .collect();
        // SAFETY: the staging buffer holds every region's texels at its
        // offset (the caller wrote them), each region lies inside the
        // pool, and the barrier above orders the copy after earlier reads.
        unsafe {
            self.device.ash().cmd_copy_buffer_to_image(
                self.cmd,
                staging.raw(),
                pool.raw(),
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &copies,
            )
        };
        self.layer_barriers(pool.raw(), layers, (COPIED, SAMPLED));
    }
}
