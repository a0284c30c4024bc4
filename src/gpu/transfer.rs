//! Work recorded on the transient command pool and waited for, and the
//! copies a frame records: uploads through a staging buffer, a layer
//! pool's layout and the copies into its layers. Above `memory`, `target`
//! and `commands`, which it joins.

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::commands::Recorder;
use super::device::Device;
use super::error::{Result, VkResultExt};
use super::memory::{
    layer_pool_desc, subresource_range, Buffer, BufferDesc, Image, ImageDesc, TexelUpload,
    Transition,
};

impl Device {
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
