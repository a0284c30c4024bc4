//! Command buffers in slots guarded by their fences, and a recorder whose
//! methods wrap the few commands the renderer records.

use ash::vk;

use super::descriptors::DescriptorSet;
use super::device::Device;
use super::error::{Result, VkError, VkResultExt};
use super::memory::{subresource_range, Buffer, Transition};
use super::owned::{Fence, Owned, Pipeline, PipelineLayout, Semaphore};
use super::views::TargetViews;

/// Command buffers for work in flight, one per slot, each with the fence
/// its last submission signals. Recording into a slot first waits for that
/// submission, so a command buffer (and what its slot's frame uses) is
/// never reused while the GPU still reads it.
pub struct CommandSlots {
    slots: Vec<Slot>,
    /// Frees the slots' command buffers with itself.
    pool: Owned<vk::CommandPool>,
}

struct Slot {
    cmd: vk::CommandBuffer,
    fence: Fence,
    /// The fence will be signalled by the slot's last submission.
    submitted: bool,
}

impl Device {
    /// `count` slots whose buffers are named `name[i]`.
    pub fn create_command_slots(&self, count: u32, name: &str) -> Result<CommandSlots> {
        let info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(self.queue_family)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: valid create info.
        let pool = unsafe { self.ash().create_command_pool(&info, None) }
            .context("creating a command pool")?;
        let pool = Owned::new(self, pool, &format!("{name}.pool"));
        let info = vk::CommandBufferAllocateInfo::default()
            .command_pool(pool.raw())
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(count);
        // SAFETY: the pool belongs to this device.
        let cmds = unsafe { self.ash().allocate_command_buffers(&info) }
            .context("allocating command buffers")?;
        let mut slots = Vec::with_capacity(cmds.len());
        for (i, cmd) in cmds.into_iter().enumerate() {
            self.set_name(cmd, &format!("{name}[{i}]"));
            slots.push(Slot {
                cmd,
                fence: self.create_fence(&format!("{name}.fence[{i}]"), false)?,
                submitted: false,
            });
        }
        Ok(CommandSlots { slots, pool })
    }

    /// Submits `cmd`, waiting on `wait` at colour output and signalling
    /// `signal` and `fence` when done.
    pub(super) fn submit(
        &self,
        cmd: vk::CommandBuffer,
        wait: &[vk::Semaphore],
        signal: &[vk::Semaphore],
        fence: &Fence,
    ) -> Result<()> {
        let cmds = [vk::CommandBufferSubmitInfo::default().command_buffer(cmd)];
        let infos = |list: &[vk::Semaphore], stage| -> Vec<vk::SemaphoreSubmitInfo> {
            list.iter()
                .map(|&s| {
                    vk::SemaphoreSubmitInfo::default()
                        .semaphore(s)
                        .stage_mask(stage)
                })
                .collect()
        };
        let waits = infos(wait, vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT);
        let signals = infos(signal, vk::PipelineStageFlags2::ALL_COMMANDS);
        let submit = vk::SubmitInfo2::default()
            .command_buffer_infos(&cmds)
            .wait_semaphore_infos(&waits)
            .signal_semaphore_infos(&signals);
        self.count_submission()?;
        // SAFETY: `cmd` is fully recorded; the fence is unsignalled and
        // belongs to this device, as do the semaphores.
        unsafe { self.ash().queue_submit2(self.queue, &[submit], fence.raw()) }
            .context("submitting commands")
    }

    pub(super) fn wait_fence(&self, fence: &Fence) -> Result<()> {
        // SAFETY: a fence of this device.
        unsafe { self.ash().wait_for_fences(&[fence.raw()], true, u64::MAX) }
            .context("waiting for the GPU")
    }
}

impl CommandSlots {
    /// Waits for slot `slot`'s last submission. True when there was one,
    /// so what it wrote (queries, readbacks) can be read now.
    pub fn wait(&self, slot: usize) -> Result<bool> {
        let s = &self.slots[slot];
        if s.submitted {
            self.pool.device().wait_fence(&s.fence)?;
        }
        Ok(s.submitted)
    }

    /// Waits for slot `slot`'s last submission, then starts recording a
    /// one-time submission into its command buffer.
    pub fn begin(&mut self, slot: usize) -> Result<Recorder<'_>> {
        self.wait(slot)?;
        let device = self.pool.device();
        let s = &mut self.slots[slot];
        let begin = vk::CommandBufferBeginInfo::default()
            .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: the slot's last submission has completed (waited above),
        // so its command buffer is not pending.
        unsafe {
            device
                .ash()
                .reset_command_buffer(s.cmd, vk::CommandBufferResetFlags::empty())
                .context("resetting a command buffer")?;
            device
                .ash()
                .begin_command_buffer(s.cmd, &begin)
                .context("beginning commands")?;
        }
        Ok(Recorder {
            device,
            cmd: s.cmd,
            slot: Some((&s.fence, &mut s.submitted)),
        })
    }
}

impl Drop for CommandSlots {
    fn drop(&mut self) {
        // Submitted work may still use the buffers and signal the fences;
        // an error (device lost) leaves nothing better to do than free them.
        let _ = self.pool.device().wait_idle();
    }
}

/// How a rendering starts and ends (see `Recorder::begin_rendering`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderingSpan {
    /// Cleared to this colour (and depth to 1) first; None: continues
    /// what an earlier rendering stored.
    pub clear_color: Option<[f32; 3]>,
    /// Resolved at its end (multisampled targets); otherwise stored for a
    /// later rendering to continue.
    pub resolve: bool,
}

/// A command buffer being recorded.
pub struct Recorder<'a> {
    pub(super) device: &'a Device,
    pub(super) cmd: vk::CommandBuffer,
    /// The slot's fence and submitted flag; None inside `one_shot`.
    slot: Option<(&'a Fence, &'a mut bool)>,
}

impl<'a> Recorder<'a> {
    pub(super) fn new(device: &'a Device, cmd: vk::CommandBuffer) -> Self {
        Recorder {
            device,
            cmd,
            slot: None,
        }
    }

    /// Ends recording and submits, signalling the slot's fence.
    pub fn submit(self) -> Result<()> {
        self.submit_with(&[], &[])
    }

    /// Ends recording and submits, then waits for it to finish.
    pub fn submit_and_wait(self) -> Result<()> {
        let device = self.device;
        let fence = self.slot.as_ref().map(|(fence, _)| *fence);
        self.submit()?;
        match fence {
            Some(fence) => device.wait_fence(fence),
            None => Ok(()),
        }
    }

    /// Ends recording and submits one frame of a window: waits on
    /// `image_available` at colour output and signals `render_finished`.
    pub fn submit_frame(
        self,
        image_available: &Semaphore,
        render_finished: &Semaphore,
    ) -> Result<()> {
        self.submit_with(&[image_available.raw()], &[render_finished.raw()])
    }

    fn submit_with(self, wait: &[vk::Semaphore], signal: &[vk::Semaphore]) -> Result<()> {
        let Some((fence, submitted)) = self.slot else {
            return Err(VkError::Unsupported(
                "a one-shot recorder is submitted by its owner".into(),
            ));
        };
        // SAFETY: recording was begun by `CommandSlots::begin`.
        unsafe { self.device.ash().end_command_buffer(self.cmd) }.context("ending commands")?;
        *submitted = false;
        // SAFETY: the fence's last submission was waited for in `begin`.
        unsafe { self.device.ash().reset_fences(&[fence.raw()]) }.context("resetting a fence")?;
        self.device.submit(self.cmd, wait, signal, fence)?;
        *submitted = true;
        Ok(())
    }

    /// Records a batch of image transitions as one barrier.
    pub(super) fn transition_images(&self, transitions: &[Transition]) {
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
        // SAFETY: the images belong to this device and `cmd` is recording.
        unsafe {
            self.device
                .ash()
                .cmd_pipeline_barrier2(self.cmd, &dependency)
        };
    }

    /// Starts dynamic rendering into `target` over `span`, with a
    /// full-size viewport. A span with a clear colour clears colour and
    /// depth (to 0: reversed Z puts the far plane at 0), else it loads what
    /// the rendering before it stored; a resolving span resolves
    /// multisampled attachments and discards them, colour by the average of
    /// its samples, depth by sample 0, else it stores them for the next.
    ///
    /// The clear is a `vkCmdClearAttachments` inside the rendering rather
    /// than a CLEAR load op: lavapipe (Mesa 22.3) re-applies a CLEAR load op
    /// each time it flushes a full tile scene in the middle of a large draw,
    /// wiping everything drawn before the flush. A clear command runs once.
    pub fn begin_rendering(&self, target: &TargetViews, span: RenderingSpan) {
        let RenderingSpan {
            clear_color,
            resolve,
        } = span;
        let load_op = match clear_color {
            Some(_) => vk::AttachmentLoadOp::DONT_CARE,
            None => vk::AttachmentLoadOp::LOAD,
        };
        let attachment = |view, layout, resolve_into: Option<vk::ImageView>, mode| {
            let info = vk::RenderingAttachmentInfo::default()
                .image_view(view)
                .image_layout(layout)
                .load_op(load_op);
            match resolve_into {
                Some(resolve_view) if resolve => info
                    .resolve_mode(mode)
                    .resolve_image_view(resolve_view)
                    .resolve_image_layout(layout)
                    .store_op(vk::AttachmentStoreOp::DONT_CARE),
                _ => info.store_op(vk::AttachmentStoreOp::STORE),
            }
        };
        let color = [attachment(
            target.color_view,
            vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
            target.color_resolve,
            vk::ResolveModeFlags::AVERAGE,
        )];
        let depth = attachment(
            target.depth_view,
            vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL,
            target.depth_resolve,
            vk::ResolveModeFlags::SAMPLE_ZERO,
        );
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
        let clear_color = clear_color.unwrap_or_default();
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
            self.device.ash().cmd_begin_rendering(self.cmd, &info);
            if load_op != vk::AttachmentLoadOp::LOAD {
                self.device
                    .ash()
                    .cmd_clear_attachments(self.cmd, &clears, &rect);
            }
            self.device.ash().cmd_set_viewport(self.cmd, 0, &[viewport]);
            self.device.ash().cmd_set_scissor(self.cmd, 0, &[area]);
        }
    }

    /// Copies a whole 2D image (in TRANSFER_SRC_OPTIMAL) into `buffer`,
    /// tightly packed, then makes the copy visible to host reads after the
    /// submission's fence.
    pub(super) fn copy_image_to_buffer(
        &self,
        image: vk::Image,
        aspect: vk::ImageAspectFlags,
        extent: vk::Extent2D,
        buffer: &Buffer,
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
            self.device.ash().cmd_copy_image_to_buffer(
                self.cmd,
                image,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                buffer.raw(),
                &[region],
            );
            self.device.ash().cmd_pipeline_barrier2(
                self.cmd,
                &vk::DependencyInfo::default().memory_barriers(&barrier),
            );
        }
    }

    pub fn end_rendering(&self) {
        // SAFETY: matches `begin_rendering`.
        unsafe { self.device.ash().cmd_end_rendering(self.cmd) };
    }

    pub fn bind_graphics(&self, pipeline: &Pipeline, layout: &PipelineLayout, set: DescriptorSet) {
        self.bind(vk::PipelineBindPoint::GRAPHICS, pipeline, layout, set);
    }

    /// Binds `pipeline` and `set` (at set 0 of `layout`) at `point`.
    fn bind(
        &self,
        point: vk::PipelineBindPoint,
        pipeline: &Pipeline,
        layout: &PipelineLayout,
        set: DescriptorSet,
    ) {
        // SAFETY: pipeline, layout and set are compatible objects of this
        // device, the pipeline made for `point`.
        unsafe {
            self.device
                .ash()
                .cmd_bind_pipeline(self.cmd, point, pipeline.raw());
            self.device.ash().cmd_bind_descriptor_sets(
                self.cmd,
                point,
                layout.raw(),
                0,
                &[set.0],
                &[],
            );
        }
    }

    pub fn bind_geometry(&self, vertices: &Buffer, indices: &Buffer) {
        // SAFETY: buffers with VERTEX_BUFFER / INDEX_BUFFER usage.
        unsafe {
            self.device
                .ash()
                .cmd_bind_vertex_buffers(self.cmd, 0, &[vertices.raw()], &[0]);
            self.device.ash().cmd_bind_index_buffer(
                self.cmd,
                indices.raw(),
                0,
                vk::IndexType::UINT32,
            );
        }
    }

    /// Runs `groups` workgroups of a compute pipeline, then makes its
    /// storage writes visible to host reads after the fence.
    pub fn dispatch_for_host(
        &self,
        pipeline: &Pipeline,
        layout: &PipelineLayout,
        set: DescriptorSet,
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
            self.device.ash().cmd_bind_pipeline(
                self.cmd,
                vk::PipelineBindPoint::COMPUTE,
                pipeline.raw(),
            );
            self.device.ash().cmd_bind_descriptor_sets(
                self.cmd,
                vk::PipelineBindPoint::COMPUTE,
                layout.raw(),
                0,
                &[set.0],
                &[],
            );
            self.device.ash().cmd_dispatch(self.cmd, groups, 1, 1);
            self.device.ash().cmd_pipeline_barrier2(
                self.cmd,
                &vk::DependencyInfo::default().memory_barriers(&barrier),
            );
        }
    }

    /// Sets push constants of `stages` from offset 0.
    pub fn push_constants(
        &self,
        layout: &PipelineLayout,
        stages: vk::ShaderStageFlags,
        bytes: &[u8],
    ) {
        // SAFETY: `layout` has a push-constant range of `stages` covering
        // `bytes`.
        unsafe {
            self.device
                .ash()
                .cmd_push_constants(self.cmd, layout.raw(), stages, 0, bytes)
        };
    }

    pub fn bind_compute(&self, pipeline: &Pipeline, layout: &PipelineLayout, set: DescriptorSet) {
        self.bind(vk::PipelineBindPoint::COMPUTE, pipeline, layout, set);
    }

    /// Runs `groups` workgroups of the bound compute pipeline.
    pub fn dispatch(&self, groups: [u32; 3]) {
        // SAFETY: a compute pipeline and its sets are bound, outside
        // rendering.
        unsafe {
            self.device
                .ash()
                .cmd_dispatch(self.cmd, groups[0], groups[1], groups[2])
        };
    }

    /// A global memory barrier: the `before` (stages, accesses) complete
    /// and are visible to the `after` ones.
    pub fn memory_barrier(
        &self,
        before: (vk::PipelineStageFlags2, vk::AccessFlags2),
        after: (vk::PipelineStageFlags2, vk::AccessFlags2),
    ) {
        let barrier = [vk::MemoryBarrier2::default()
            .src_stage_mask(before.0)
            .src_access_mask(before.1)
            .dst_stage_mask(after.0)
            .dst_access_mask(after.1)];
        // SAFETY: `cmd` is recording outside rendering.
        unsafe {
            self.device.ash().cmd_pipeline_barrier2(
                self.cmd,
                &vk::DependencyInfo::default().memory_barriers(&barrier),
            )
        };
    }

    /// Copies the first `bytes` of `src` to the start of `dst` (outside
    /// rendering); a transfer read and write.
    pub fn copy_buffer(&self, src: &Buffer, dst: &Buffer, bytes: u64) {
        let region = [vk::BufferCopy::default().size(bytes)];
        // SAFETY: buffers of this device with TRANSFER_SRC and TRANSFER_DST
        // usage, each at least `bytes` long.
        unsafe {
            self.device
                .ash()
                .cmd_copy_buffer(self.cmd, src.raw(), dst.raw(), &region)
        };
    }

    /// Fills `buffer` with the 32-bit `value` (outside rendering); a
    /// transfer write.
    pub fn fill_buffer(&self, buffer: &Buffer, value: u32) {
        // SAFETY: a buffer of this device with TRANSFER_DST usage.
        unsafe {
            self.device
                .ash()
                .cmd_fill_buffer(self.cmd, buffer.raw(), 0, vk::WHOLE_SIZE, value)
        };
    }

    /// Makes `target`'s depth, just drawn, readable by compute shaders
    /// (SHADER_READ_ONLY_OPTIMAL), keeping its contents.
    pub fn depth_to_compute(&self, target: &TargetViews) {
        use vk::{AccessFlags2 as A, ImageLayout as L, PipelineStageFlags2 as S};
        self.transition_images(&[Transition {
            image: target.depth_image,
            aspect: vk::ImageAspectFlags::DEPTH,
            from: (
                L::DEPTH_ATTACHMENT_OPTIMAL,
                S::EARLY_FRAGMENT_TESTS | S::LATE_FRAGMENT_TESTS,
                A::DEPTH_STENCIL_ATTACHMENT_WRITE,
            ),
            to: (
                L::SHADER_READ_ONLY_OPTIMAL,
                S::COMPUTE_SHADER,
                A::SHADER_SAMPLED_READ,
            ),
        }]);
    }

    /// Makes `target`'s depth an attachment again after `depth_to_compute`,
    /// keeping its contents.
    pub fn depth_to_attachment(&self, target: &TargetViews) {
        use vk::{AccessFlags2 as A, ImageLayout as L, PipelineStageFlags2 as S};
        self.transition_images(&[Transition {
            image: target.depth_image,
            aspect: vk::ImageAspectFlags::DEPTH,
            from: (L::SHADER_READ_ONLY_OPTIMAL, S::COMPUTE_SHADER, A::NONE),
            to: (
                L::DEPTH_ATTACHMENT_OPTIMAL,
                S::EARLY_FRAGMENT_TESTS | S::LATE_FRAGMENT_TESTS,
                A::DEPTH_STENCIL_ATTACHMENT_READ | A::DEPTH_STENCIL_ATTACHMENT_WRITE,
            ),
        }]);
    }

    /// A non-indexed draw without vertex buffers (the shader uses
    /// gl_VertexIndex).
    pub fn draw(&self, vertex_count: u32) {
        // SAFETY: a pipeline is bound, inside rendering.
        unsafe { self.device.ash().cmd_draw(self.cmd, vertex_count, 1, 0, 0) };
    }

    /// `count` indexed draws whose parameters (tightly packed
    /// VkDrawIndexedIndirectCommands) the GPU reads from `buffer` at
    /// `offset`: the device must have multiDrawIndirect enabled where
    /// `count` > 1, and `count` must not pass its maxDrawIndirectCount.
    pub fn draw_indexed_indirect(&self, buffer: &Buffer, offset: u64, count: u32) {
        let stride = std::mem::size_of::<vk::DrawIndexedIndirectCommand>() as u32;
        // SAFETY: geometry and pipeline are bound, inside rendering; the
        // buffer has INDIRECT_BUFFER usage and holds `count` commands from
        // `offset`; the caller checked the feature and the limit.
        unsafe {
            self.device.ash().cmd_draw_indexed_indirect(
                self.cmd,
                buffer.raw(),
                offset,
                count,
                stride,
            )
        };
    }

    pub fn draw_indexed(&self, first_index: u32, index_count: u32) {
        // SAFETY: geometry and pipeline are bound, inside rendering; the
        // caller keeps the range inside the index buffer.
        unsafe {
            self.device
                .ash()
                .cmd_draw_indexed(self.cmd, index_count, 1, first_index, 0, 0)
        };
    }
}
