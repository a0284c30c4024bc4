//! Buffers and images with memory from gpu-allocator, within the memory
//! budget. Each frees its handles and memory when dropped; uploads into
//! them are recorded by `transfer`.

use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use std::mem::ManuallyDrop;

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
        self.mapped_start(bytes.len())?.copy_from_slice(bytes);
        Ok(())
    }

    /// Writes `records` one after another from the start of a host-visible
    /// buffer, straight into its mapped memory: nothing is collected
    /// first, and the memory needs no alignment for `T`.
    pub fn write_records<T: bytemuck::Pod>(
        &mut self,
        records: impl ExactSizeIterator<Item = T>,
    ) -> Result<()> {
        let size = std::mem::size_of::<T>();
        let start = self.mapped_start(records.len() * size)?;
        for (into, record) in start.chunks_exact_mut(size).zip(records) {
            into.copy_from_slice(bytemuck::bytes_of(&record));
        }
        Ok(())
    }

    /// The first `len` bytes of the mapped memory, or why there are none.
    fn mapped_start(&mut self, len: usize) -> Result<&mut [u8]> {
        let name = self.name.clone();
        let mapped = self.mapped_mut().ok_or_else(|| {
            VkError::Unsupported(format!("{name}: host-visible memory is not mapped"))
        })?;
        let available = mapped.len();
        mapped.get_mut(..len).ok_or_else(|| {
            VkError::Unsupported(format!("{name}: {len} bytes do not fit in {available}"))
        })
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

/// A layer pool's layers: `side` x `side` f32 samples, sampled and
/// copied into.
pub(super) fn layer_pool_desc(side: u32) -> ImageDesc {
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
