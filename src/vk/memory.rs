//! Buffers and images with memory from gpu-allocator, and uploads through a
//! staging buffer. Destroying takes the resource by value, so it cannot be
//! used or freed twice.

use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use super::device::Device;
use super::error::{Result, VkError, VkResultExt};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BufferDesc {
    pub size: u64,
    pub usage: vk::BufferUsageFlags,
    pub location: MemoryLocation,
}

pub struct Buffer {
    pub raw: vk::Buffer,
    pub desc: BufferDesc,
    allocation: Allocation,
    name: String,
}

impl Buffer {
    /// The mapped bytes of a host-visible buffer.
    pub fn mapped(&self) -> Option<&[u8]> {
        self.allocation
            .mapped_slice()
            .map(|s| &s[..self.desc.size as usize])
    }

    pub fn mapped_mut(&mut self) -> Option<&mut [u8]> {
        let size = self.desc.size as usize;
        self.allocation.mapped_slice_mut().map(|s| &mut s[..size])
    }

    pub fn name(&self) -> &str {
        &self.name
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ImageDesc {
    pub extent: vk::Extent2D,
    pub format: vk::Format,
    pub usage: vk::ImageUsageFlags,
    pub aspect: vk::ImageAspectFlags,
}

pub struct Image {
    pub raw: vk::Image,
    pub view: vk::ImageView,
    pub desc: ImageDesc,
    allocation: Allocation,
    name: String,
}

impl Device {
    fn allocate(
        &self,
        name: &str,
        requirements: vk::MemoryRequirements,
        location: MemoryLocation,
        linear: bool,
    ) -> Result<Allocation> {
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
            .allocator
            .lock()
            .expect("allocator lock")
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
        *self
            .memory
            .lock()
            .expect("memory lock")
            .entry(name.to_string())
            .or_default() += allocation.size();
        Ok(allocation)
    }

    fn release(&self, name: &str, allocation: Allocation) {
        let size = allocation.size();
        if let Some(bytes) = self.memory.lock().expect("memory lock").get_mut(name) {
            *bytes = bytes.saturating_sub(size);
        }
        // A failure here means the allocation wasn't from this allocator,
        // which by construction cannot happen; there is nothing to recover.
        let _ = self
            .allocator
            .lock()
            .expect("allocator lock")
            .free(allocation);
    }

    /// Allocates memory for a new buffer or image and binds it. On failure
    /// the memory is freed and `destroy` disposes of the resource, so nothing
    /// leaks half-made.
    fn allocate_bound(
        &self,
        name: &str,
        requirements: vk::MemoryRequirements,
        location: MemoryLocation,
        linear: bool,
        bind: impl FnOnce(&Allocation) -> std::result::Result<(), vk::Result>,
        destroy: impl FnOnce(),
    ) -> Result<Allocation> {
        let allocation = match self.allocate(name, requirements, location, linear) {
            Ok(a) => a,
            Err(e) => {
                destroy();
                return Err(e);
            }
        };
        if let Err(result) = bind(&allocation) {
            self.release(name, allocation);
            destroy();
            return Err(VkError::Call {
                context: "binding memory",
                result,
            });
        }
        Ok(allocation)
    }

    /// Bytes currently allocated, per resource name (zero entries dropped).
    pub fn memory_report(&self) -> Vec<(String, u64)> {
        self.memory
            .lock()
            .expect("memory lock")
            .iter()
            .filter(|(_, &b)| b > 0)
            .map(|(n, &b)| (n.clone(), b))
            .collect()
    }

    /// Refuses allocations that would bring the bytes in use past `budget`
    /// (None: no limit), with an error naming the resource.
    pub fn set_memory_budget(&self, budget: Option<u64>) {
        self.memory_budget.store(
            budget.unwrap_or(u64::MAX),
            std::sync::atomic::Ordering::Relaxed,
        );
    }

    pub fn memory_budget(&self) -> Option<u64> {
        let b = self
            .memory_budget
            .load(std::sync::atomic::Ordering::Relaxed);
        (b != u64::MAX).then_some(b)
    }

    /// Bytes currently allocated in all.
    pub fn memory_in_use(&self) -> u64 {
        self.memory.lock().expect("memory lock").values().sum()
    }

    pub fn create_buffer(&self, desc: BufferDesc, name: &str) -> Result<Buffer> {
        let info = vk::BufferCreateInfo::default()
            .size(desc.size.max(1))
            .usage(desc.usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid create info on a live device.
        let raw = unsafe { self.raw.create_buffer(&info, None) }.context("creating a buffer")?;
        // SAFETY: `raw` was just created from this device.
        let requirements = unsafe { self.raw.get_buffer_memory_requirements(raw) };
        let allocation = self.allocate_bound(
            name,
            requirements,
            desc.location,
            true,
            // SAFETY: memory and offset come from the allocator for these requirements.
            |a| unsafe { self.raw.bind_buffer_memory(raw, a.memory(), a.offset()) },
            // SAFETY: an unused buffer of this device.
            || unsafe { self.raw.destroy_buffer(raw, None) },
        )?;
        self.set_name(raw, name);
        Ok(Buffer {
            raw,
            desc,
            allocation,
            name: name.to_string(),
        })
    }

    pub fn destroy_buffer(&self, buffer: Buffer) {
        // SAFETY: the caller guarantees the GPU no longer uses the buffer.
        unsafe { self.raw.destroy_buffer(buffer.raw, None) };
        self.release(&buffer.name, buffer.allocation);
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
        buffer
            .mapped_mut()
            .ok_or_else(|| {
                VkError::Unsupported(format!("{name}: host-visible memory is not mapped"))
            })?
            .copy_from_slice(bytes);
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
        let buffer = match self.create_buffer(
            BufferDesc {
                size: bytes.len() as u64,
                usage: usage | vk::BufferUsageFlags::TRANSFER_DST,
                location: MemoryLocation::GpuOnly,
            },
            name,
        ) {
            Ok(b) => b,
            Err(e) => {
                self.destroy_buffer(staging);
                return Err(e);
            }
        };
        let copied = self.one_shot(&format!("{name}.upload"), |cmd| {
            let region = vk::BufferCopy::default().size(bytes.len() as u64);
            // SAFETY: both buffers are large enough and not in use elsewhere.
            unsafe {
                self.raw
                    .cmd_copy_buffer(cmd, staging.raw, buffer.raw, &[region])
            };
        });
        self.destroy_buffer(staging);
        match copied {
            Ok(()) => Ok(buffer),
            Err(e) => {
                self.destroy_buffer(buffer);
                Err(e)
            }
        }
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
        let info = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(desc.format)
            .extent(vk::Extent3D {
                width: desc.extent.width,
                height: desc.extent.height,
                depth: 1,
            })
            .mip_levels(levels)
            .array_layers(layers)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(desc.usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        // SAFETY: valid create info.
        let raw = unsafe { self.raw.create_image(&info, None) }.context("creating an image")?;
        // SAFETY: `raw` was just created from this device.
        let requirements = unsafe { self.raw.get_image_memory_requirements(raw) };
        let allocation = self.allocate_bound(
            name,
            requirements,
            MemoryLocation::GpuOnly,
            false,
            // SAFETY: memory and offset come from the allocator for these requirements.
            |a| unsafe { self.raw.bind_image_memory(raw, a.memory(), a.offset()) },
            // SAFETY: an unused image of this device.
            || unsafe { self.raw.destroy_image(raw, None) },
        )?;
        let view_info = vk::ImageViewCreateInfo::default()
            .image(raw)
            .view_type(view_type)
            .format(desc.format)
            .subresource_range(subresource_range(desc.aspect));
        // SAFETY: the view matches the image's format and aspect.
        let view = unsafe { self.raw.create_image_view(&view_info, None) }
            .context("creating an image view")?;
        self.set_name(raw, name);
        self.set_name(view, &format!("{name}.view"));
        Ok(Image {
            raw,
            view,
            desc,
            allocation,
            name: name.to_string(),
        })
    }

    pub fn destroy_image(&self, image: Image) {
        // SAFETY: the caller guarantees the GPU no longer uses the image.
        unsafe {
            self.raw.destroy_image_view(image.view, None);
            self.raw.destroy_image(image.raw, None);
        }
        self.release(&image.name, image.allocation);
    }

    /// Records `record` into a fresh command buffer, submits it and waits.
    pub fn one_shot(&self, name: &str, record: impl FnOnce(vk::CommandBuffer)) -> Result<()> {
        let info = vk::CommandBufferAllocateInfo::default()
            .command_pool(self.transient_pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the pool belongs to this device and is used from one thread.
        let cmd = unsafe { self.raw.allocate_command_buffers(&info) }
            .context("allocating a command buffer")?[0];
        self.set_name(cmd, name);
        let fence = self.create_fence(&format!("{name}.fence"), false)?;
        let result = (|| {
            let begin = vk::CommandBufferBeginInfo::default()
                .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
            // SAFETY: a freshly allocated command buffer.
            unsafe { self.raw.begin_command_buffer(cmd, &begin) }.context("beginning commands")?;
            record(cmd);
            // SAFETY: recording was begun above.
            unsafe { self.raw.end_command_buffer(cmd) }.context("ending commands")?;
            self.submit_and_wait(cmd, fence)
        })();
        // SAFETY: the submission finished (or never started), so both are idle.
        unsafe {
            self.raw.destroy_fence(fence, None);
            self.raw.free_command_buffers(self.transient_pool, &[cmd]);
        }
        result
    }

    /// Submits one command buffer and blocks until it completes.
    pub fn submit_and_wait(&self, cmd: vk::CommandBuffer, fence: vk::Fence) -> Result<()> {
        self.submit(cmd, fence)?;
        self.wait_fence(fence)
    }

    pub fn create_fence(&self, name: &str, signalled: bool) -> Result<vk::Fence> {
        let flags = if signalled {
            vk::FenceCreateFlags::SIGNALED
        } else {
            vk::FenceCreateFlags::empty()
        };
        // SAFETY: valid create info.
        let fence = unsafe {
            self.raw
                .create_fence(&vk::FenceCreateInfo::default().flags(flags), None)
        }
        .context("creating a fence")?;
        self.set_name(fence, name);
        Ok(fence)
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
pub struct Transition {
    pub image: vk::Image,
    pub aspect: vk::ImageAspectFlags,
    pub from: (vk::ImageLayout, vk::PipelineStageFlags2, vk::AccessFlags2),
    pub to: (vk::ImageLayout, vk::PipelineStageFlags2, vk::AccessFlags2),
}

impl Transition {
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

/// Records a batch of image transitions as one barrier.
pub fn transition_images(device: &ash::Device, cmd: vk::CommandBuffer, transitions: &[Transition]) {
    let barriers: Vec<vk::ImageMemoryBarrier2> = transitions
        .iter()
        .map(|t| {
            vk::ImageMemoryBarrier2::default()
                .image(t.image)
                .subresource_range(subresource_range(t.aspect))
                .old_layout(t.from.0)
                .src_stage_mask(t.from.1)
                .src_access_mask(t.from.2)
                .new_layout(t.to.0)
                .dst_stage_mask(t.to.1)
                .dst_access_mask(t.to.2)
        })
        .collect();
    let dependency = vk::DependencyInfo::default().image_memory_barriers(&barriers);
    // SAFETY: the images belong to `device` and `cmd` is recording.
    unsafe { device.cmd_pipeline_barrier2(cmd, &dependency) };
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
            },
            levels.len() as u32,
            up.layers,
            up.view_type,
            name,
        )?;
        let staging = match self.create_host_buffer(
            &format!("{name}.staging"),
            vk::BufferUsageFlags::TRANSFER_SRC,
            &levels.concat(),
        ) {
            Ok(b) => b,
            Err(e) => {
                self.destroy_image(image);
                return Err(e);
            }
        };
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
        let uploaded = self.one_shot(&format!("{name}.upload"), |cmd| {
            transition_images(
                &self.raw,
                cmd,
                &[Transition {
                    image: image.raw,
                    aspect: vk::ImageAspectFlags::COLOR,
                    from: (L::UNDEFINED, S::NONE, A::NONE),
                    to: (L::TRANSFER_DST_OPTIMAL, S::COPY, A::TRANSFER_WRITE),
                }],
            );
            // SAFETY: the staging buffer holds every level at the offsets
            // of `regions`, each level's extent of texels per layer.
            unsafe {
                self.raw.cmd_copy_buffer_to_image(
                    cmd,
                    staging.raw,
                    image.raw,
                    L::TRANSFER_DST_OPTIMAL,
                    &regions,
                )
            };
            transition_images(
                &self.raw,
                cmd,
                &[Transition {
                    image: image.raw,
                    aspect: vk::ImageAspectFlags::COLOR,
                    from: (L::TRANSFER_DST_OPTIMAL, S::COPY, A::TRANSFER_WRITE),
                    to: (
                        L::SHADER_READ_ONLY_OPTIMAL,
                        S::ALL_GRAPHICS,
                        A::SHADER_SAMPLED_READ,
                    ),
                }],
            );
        });
        self.destroy_buffer(staging);
        match uploaded {
            Ok(()) => Ok(image),
            Err(e) => {
                self.destroy_image(image);
                Err(e)
            }
        }
    }

    /// Submits one recorded command buffer; `fence` signals when it is done.
    pub fn submit(&self, cmd: vk::CommandBuffer, fence: vk::Fence) -> Result<()> {
        let cmds = [vk::CommandBufferSubmitInfo::default().command_buffer(cmd)];
        let submit = vk::SubmitInfo2::default().command_buffer_infos(&cmds);
        self.count_submission()?;
        // SAFETY: `cmd` is fully recorded and `fence` unsignalled.
        unsafe { self.raw.queue_submit2(self.queue, &[submit], fence) }
            .context("submitting commands")
    }
}
