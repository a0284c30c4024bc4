//! Command pools and buffers, and a recorder whose methods wrap the few
//! commands the renderer records.

use ash::vk;

use super::device::Device;
use super::error::{Result, VkResultExt};
use super::target::TargetViews;

impl Device {
    /// A pool whose buffers can be reset one by one (one per frame in flight).
    pub fn create_command_pool(&self, name: &str) -> Result<vk::CommandPool> {
        let info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(self.queue_family)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: valid create info.
        let pool = unsafe { self.raw.create_command_pool(&info, None) }
            .context("creating a command pool")?;
        self.set_name(pool, name);
        Ok(pool)
    }

    pub fn allocate_command_buffers(
        &self,
        pool: vk::CommandPool,
        count: u32,
        name: &str,
    ) -> Result<Vec<vk::CommandBuffer>> {
        let info = vk::CommandBufferAllocateInfo::default()
            .command_pool(pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(count);
        // SAFETY: the pool belongs to this device.
        let cmds = unsafe { self.raw.allocate_command_buffers(&info) }
            .context("allocating command buffers")?;
        for (i, &cmd) in cmds.iter().enumerate() {
            self.set_name(cmd, &format!("{name}[{i}]"));
        }
        Ok(cmds)
    }

    /// Destroys the pool and the buffers allocated from it.
    pub fn destroy_command_pool(&self, pool: vk::CommandPool) {
        // SAFETY: none of its buffers is pending execution.
        unsafe { self.raw.destroy_command_pool(pool, None) };
    }

    /// Resets `cmd` and starts recording a one-time submission.
    pub fn begin_commands(&self, cmd: vk::CommandBuffer) -> Result<Recorder<'_>> {
        let begin = vk::CommandBufferBeginInfo::default()
            .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: the caller has waited for the last submission of `cmd`.
        unsafe {
            self.raw
                .reset_command_buffer(cmd, vk::CommandBufferResetFlags::empty())
                .context("resetting a command buffer")?;
            self.raw
                .begin_command_buffer(cmd, &begin)
                .context("beginning commands")?;
        }
        Ok(Recorder {
            device: &self.raw,
            cmd,
        })
    }

    pub fn reset_fence(&self, fence: vk::Fence) -> Result<()> {
        // SAFETY: the fence is not in use by a pending submission.
        unsafe { self.raw.reset_fences(&[fence]) }.context("resetting a fence")
    }

    pub fn wait_fence(&self, fence: vk::Fence) -> Result<()> {
        // SAFETY: a fence of this device.
        unsafe { self.raw.wait_for_fences(&[fence], true, u64::MAX) }.context("waiting for the GPU")
    }

    pub fn destroy_fence(&self, fence: vk::Fence) {
        // SAFETY: no pending submission signals it.
        unsafe { self.raw.destroy_fence(fence, None) };
    }
}

/// A command buffer being recorded.
pub struct Recorder<'a> {
    pub device: &'a ash::Device,
    pub cmd: vk::CommandBuffer,
}

impl Recorder<'_> {
    pub fn finish(self) -> Result<vk::CommandBuffer> {
        // SAFETY: recording was begun by `begin_commands`.
        unsafe { self.device.end_command_buffer(self.cmd) }.context("ending commands")?;
        Ok(self.cmd)
    }

    /// Starts dynamic rendering into `target`, clearing colour and depth
    /// (to 0: reversed Z puts the far plane at 0), with a full-size viewport.
    ///
    /// The clear is a `vkCmdClearAttachments` inside the rendering rather
    /// than a CLEAR load op: lavapipe (Mesa 22.3) re-applies a CLEAR load op
    /// each time it flushes a full tile scene in the middle of a large draw,
    /// wiping everything drawn before the flush. A clear command runs once.
    pub fn begin_rendering(&self, target: &TargetViews, clear_color: [f32; 3]) {
        let color = [vk::RenderingAttachmentInfo::default()
            .image_view(target.color_view)
            .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            .load_op(vk::AttachmentLoadOp::DONT_CARE)
            .store_op(vk::AttachmentStoreOp::STORE)];
        let depth = vk::RenderingAttachmentInfo::default()
            .image_view(target.depth_view)
            .image_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
            .load_op(vk::AttachmentLoadOp::DONT_CARE)
            .store_op(vk::AttachmentStoreOp::STORE);
        let area = vk::Rect2D::default().extent(target.extent);
        let info = vk::RenderingInfo::default()
            .render_area(area)
            .layer_count(1)
            .color_attachments(&color)
            .depth_attachment(&depth);
        let viewport = vk::Viewport {
            x: 0.0,
            y: 0.0,
            width: target.extent.width as f32,
            height: target.extent.height as f32,
            min_depth: 0.0,
            max_depth: 1.0,
        };
        let clears = [
            vk::ClearAttachment {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                color_attachment: 0,
                clear_value: vk::ClearValue {
                    color: vk::ClearColorValue {
                        float32: [clear_color[0], clear_color[1], clear_color[2], 1.0],
                    },
                },
            },
            vk::ClearAttachment {
                aspect_mask: vk::ImageAspectFlags::DEPTH,
                color_attachment: 0,
                clear_value: vk::ClearValue {
                    depth_stencil: vk::ClearDepthStencilValue {
                        depth: 0.0,
                        stencil: 0,
                    },
                },
            },
        ];
        let rect = [vk::ClearRect::default().rect(area).layer_count(1)];
        // SAFETY: the target's images are in the attachment layouts named
        // above (the target's owner transitions them).
        unsafe {
            self.device.cmd_begin_rendering(self.cmd, &info);
            self.device.cmd_clear_attachments(self.cmd, &clears, &rect);
            self.device.cmd_set_viewport(self.cmd, 0, &[viewport]);
            self.device.cmd_set_scissor(self.cmd, 0, &[area]);
        }
    }

    /// Copies a whole 2D image (in TRANSFER_SRC_OPTIMAL) into `buffer`,
    /// tightly packed, then makes the copy visible to host reads after the
    /// submission's fence.
    pub fn copy_image_to_buffer(
        &self,
        image: vk::Image,
        aspect: vk::ImageAspectFlags,
        extent: vk::Extent2D,
        buffer: vk::Buffer,
    ) {
        let region = vk::BufferImageCopy::default()
            .image_subresource(
                vk::ImageSubresourceLayers::default()
                    .aspect_mask(aspect)
                    .layer_count(1),
            )
            .image_extent(vk::Extent3D {
                width: extent.width,
                height: extent.height,
                depth: 1,
            });
        let barrier = [vk::MemoryBarrier2::default()
            .src_stage_mask(vk::PipelineStageFlags2::COPY)
            .src_access_mask(vk::AccessFlags2::TRANSFER_WRITE)
            .dst_stage_mask(vk::PipelineStageFlags2::HOST)
            .dst_access_mask(vk::AccessFlags2::HOST_READ)];
        // SAFETY: the image is in TRANSFER_SRC_OPTIMAL and the buffer holds
        // the whole image.
        unsafe {
            self.device.cmd_copy_image_to_buffer(
                self.cmd,
                image,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                buffer,
                &[region],
            );
            self.device.cmd_pipeline_barrier2(
                self.cmd,
                &vk::DependencyInfo::default().memory_barriers(&barrier),
            );
        }
    }

    pub fn copy_color_to_buffer(&self, image: vk::Image, extent: vk::Extent2D, buffer: vk::Buffer) {
        self.copy_image_to_buffer(image, vk::ImageAspectFlags::COLOR, extent, buffer);
    }

    pub fn end_rendering(&self) {
        // SAFETY: matches `begin_rendering`.
        unsafe { self.device.cmd_end_rendering(self.cmd) };
    }

    pub fn bind_graphics(
        &self,
        pipeline: vk::Pipeline,
        layout: vk::PipelineLayout,
        set: vk::DescriptorSet,
    ) {
        // SAFETY: pipeline, layout and set are compatible objects of this device.
        unsafe {
            self.device
                .cmd_bind_pipeline(self.cmd, vk::PipelineBindPoint::GRAPHICS, pipeline);
            self.device.cmd_bind_descriptor_sets(
                self.cmd,
                vk::PipelineBindPoint::GRAPHICS,
                layout,
                0,
                &[set],
                &[],
            );
        }
    }

    pub fn bind_geometry(&self, vertices: vk::Buffer, indices: vk::Buffer) {
        // SAFETY: buffers with VERTEX_BUFFER / INDEX_BUFFER usage.
        unsafe {
            self.device
                .cmd_bind_vertex_buffers(self.cmd, 0, &[vertices], &[0]);
            self.device
                .cmd_bind_index_buffer(self.cmd, indices, 0, vk::IndexType::UINT32);
        }
    }

    /// Runs `groups` workgroups of a compute pipeline, then makes its
    /// storage writes visible to host reads after the fence.
    pub fn dispatch_for_host(
        &self,
        pipeline: vk::Pipeline,
        layout: vk::PipelineLayout,
        set: vk::DescriptorSet,
        groups: u32,
    ) {
        let barrier = [vk::MemoryBarrier2::default()
            .src_stage_mask(vk::PipelineStageFlags2::COMPUTE_SHADER)
            .src_access_mask(vk::AccessFlags2::SHADER_STORAGE_WRITE)
            .dst_stage_mask(vk::PipelineStageFlags2::HOST)
            .dst_access_mask(vk::AccessFlags2::HOST_READ)];
        // SAFETY: pipeline, layout and set are compatible objects of this
        // device; `cmd` is recording outside rendering.
        unsafe {
            self.device
                .cmd_bind_pipeline(self.cmd, vk::PipelineBindPoint::COMPUTE, pipeline);
            self.device.cmd_bind_descriptor_sets(
                self.cmd,
                vk::PipelineBindPoint::COMPUTE,
                layout,
                0,
                &[set],
                &[],
            );
            self.device.cmd_dispatch(self.cmd, groups, 1, 1);
            self.device.cmd_pipeline_barrier2(
                self.cmd,
                &vk::DependencyInfo::default().memory_barriers(&barrier),
            );
        }
    }

    /// Sets vertex-stage push constants from offset 0.
    pub fn push_vertex_constants(&self, layout: vk::PipelineLayout, bytes: &[u8]) {
        // SAFETY: `layout` has a vertex push-constant range covering `bytes`.
        unsafe {
            self.device
                .cmd_push_constants(self.cmd, layout, vk::ShaderStageFlags::VERTEX, 0, bytes)
        };
    }

    /// A non-indexed draw without vertex buffers (the shader uses
    /// gl_VertexIndex).
    pub fn draw(&self, vertex_count: u32) {
        // SAFETY: a pipeline is bound, inside rendering.
        unsafe { self.device.cmd_draw(self.cmd, vertex_count, 1, 0, 0) };
    }

    pub fn draw_indexed(&self, first_index: u32, index_count: u32) {
        // SAFETY: geometry and pipeline are bound, inside rendering; the
        // caller keeps the range inside the index buffer.
        unsafe {
            self.device
                .cmd_draw_indexed(self.cmd, index_count, 1, first_index, 0, 0)
        };
    }
}
