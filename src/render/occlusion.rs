//! Hierarchical-Z occlusion culling of patches, in two passes per frame:
//!
//! 1. the patches that passed last frame's test are drawn;
//! 2. their depth is reduced to a pyramid, each texel the farthest depth
//!    under it (glsl/hiz.comp, every sample of a multisampled pixel);
//! 3. every patch's box (x and z from its corners, its Y bounds, which
//!    allow for material displacement) is tested against the pyramid
//!    (glsl/occlusion.comp), leaving one word of `OCCLUSION_*_BIT`s per
//!    patch;
//! 4. the patches found visible that were not drawn first are drawn.
//!
//! Step 4 finds whatever step 1 missed, so nothing visible is missing on a
//! first frame or after a camera cut: the state only decides how much is
//! drawn twice-tested instead of once. The tess path's control shader
//! reads the state (glsl/occlusion.glsl) and culls the patches a phase does
//! not keep. Every draw is indirect (the geomip path's patches, the tess
//! path's batches of patches and its full-resolution ones): before each
//! pass a compute shader (glsl/occlusion_draws.comp) sets each one's
//! instance count to 1 when the pass keeps any of its patches and to 0
//! otherwise, so a draw with nothing to draw costs nothing.

use std::mem::size_of;

use ash::vk;
use glam::Vec3;
use gpu_allocator::MemoryLocation;

use super::shaders;
use super::uniforms::FrameUniforms;
use crate::gpu::commands::Recorder;
use crate::gpu::descriptors::{DescriptorSet, DescriptorSets};
use crate::gpu::memory::{Buffer, BufferDesc};
use crate::gpu::owned::{DescriptorSetLayout, Pipeline, PipelineLayout, Sampler};
use crate::gpu::target::TargetViews;
use crate::gpu::Device;
use crate::render::error::{RenderError, Result};
use crate::shader_constants::{
    BINDING_CONTROL_POINTS, BINDING_DRAW_COMMANDS, BINDING_DRAW_PATCHES, BINDING_FRAME,
    BINDING_HIZ_DEPTH, BINDING_HIZ_PYRAMID, BINDING_OCCLUSION_COUNT, BINDING_VISIBILITY,
    HIZ_LEVELS_PER_DISPATCH, OCCLUSION_PHASE_FIRST, OCCLUSION_PHASE_SECOND, OCCLUSION_VISIBLE_BIT,
};
use crate::shader_variants::{HizSource, Shader};
use crate::terrain::Terrain;

/// Levels one glsl/hiz.comp dispatch writes, texels a side of its first
/// level that one workgroup of 8x8 invocations covers (each reduces a
/// block halved down to one texel), and the workgroup size of
/// glsl/occlusion.comp.
const REDUCE_LEVELS: usize = HIZ_LEVELS_PER_DISPATCH as usize;
const REDUCE_TILE: u32 = 8 << (HIZ_LEVELS_PER_DISPATCH - 1);
const TEST_GROUP: u32 = 64;

/// Push constants of glsl/hiz.comp.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct ReduceConstants {
    src_size: [i32; 2],
    src_offset: u32,
    dst_offset: u32,
    samples: u32,
    levels: u32,
}
const _: () = assert!(size_of::<ReduceConstants>() == 24);

/// Push constants of glsl/occlusion.comp.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct TestConstants {
    size: [i32; 2],
    levels: u32,
}
const _: () = assert!(size_of::<TestConstants>() == 12);

/// Push constants of glsl/occlusion_draws.comp.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct SelectConstants {
    count: u32,
    phase: u32,
    first: u32,
}
const _: () = assert!(size_of::<SelectConstants>() == 12);

/// A draw the CPU lists: the patches it covers (first, count, in grid
/// order) and its index range. A pass draws it when the occlusion state
/// keeps any of its patches.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ListedDraw {
    pub patches: [u32; 2],
    pub first_index: u32,
    pub index_count: u32,
    /// Its first instance: a listed geomip draw's place in its list
    /// (`GeomipList`), else 0.
    pub first_instance: u32,
}

/// One VkDrawIndexedIndirectCommand.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct DrawCommand {
    index_count: u32,
    instance_count: u32,
    first_index: u32,
    vertex_offset: i32,
    first_instance: u32,
}
const _: () = assert!(size_of::<DrawCommand>() == size_of::<ash::vk::DrawIndexedIndirectCommand>());

impl DrawCommand {
    /// One instance of `index_count` indices from `first_index`.
    pub(super) fn once(first_index: u32, index_count: u32) -> Self {
        DrawCommand {
            index_count,
            instance_count: 1,
            first_index,
            ..DrawCommand::default()
        }
    }

    /// `once`, its one instance numbered `first_instance`: a listed
    /// geomip draw's place in its list (`GeomipList`).
    pub(super) fn listed(first_index: u32, index_count: u32, first_instance: u32) -> Self {
        DrawCommand {
            first_instance,
            ..DrawCommand::once(first_index, index_count)
        }
    }
}

/// Bytes of one indirect command.
pub const DRAW_COMMAND_BYTES: u64 = size_of::<DrawCommand>() as u64;
const _: () = assert!(DRAW_COMMAND_BYTES == 20);

const PUSH_SIZE: u32 = 32;

/// Most draws a frame may list, whatever the terrain: a frame that needs
/// more (on a terrain of hundreds of thousands of patches) is drawn
/// without occlusion culling (see `TerrainRenderer::record`), so the lists
/// of a huge terrain stay a few MiB.
pub const MAX_LISTED_DRAWS: u64 = 1 << 16;

/// Draws one frame may list for a terrain of `patches` patches: the tess
/// path's batches (at most one per patch) and its full-resolution patches,
/// up to `MAX_LISTED_DRAWS`.
fn list_capacity(patches: u64) -> u64 {
    (2 * patches).min(MAX_LISTED_DRAWS)
}

/// The wider side of a full-size patch, in world units.
fn patch_width(terrain: &Terrain) -> f32 {
    let spacing = terrain.info().spacing();
    (terrain.grid().cells_per_patch() as f64 * spacing.x.max(spacing.y)) as f32
}

/// The pyramid's levels over a `width` x `height` depth: level l has
/// ceil(size / 2^(l+1)) texels a side, down to 1x1. Mirror of
/// `level_size` in glsl/occlusion.comp.
pub fn pyramid_levels(width: u32, height: u32) -> Vec<[u32; 2]> {
    let mut levels = Vec::new();
    let mut l = 0;
    loop {
        let size = [
            width.div_ceil(2u32 << l).max(1),
            height.div_ceil(2u32 << l).max(1),
        ];
        levels.push(size);
        if size == [1, 1] {
            return levels;
        }
        l += 1;
    }
}

/// The state the draws read, and what builds and tests against the
/// pyramid where the device can read depth attachments.
pub(super) struct Occlusion {
    /// One word per patch, kept from frame to frame (every patch visible
    /// at first, so a first frame draws everything in its first pass).
    pub(super) visibility: Buffer,
    patches: usize,
    /// The graphics stage that reads the state, and how: the tessellation
    /// control shader's storage reads where the device has one, nothing
    /// otherwise (the listed draws read it through their commands).
    readers: (vk::PipelineStageFlags2, vk::AccessFlags2),
    culling: Option<Culling>,
    /// Which frames that ask for culling get it.
    turns: CullingTurns,
}

/// Frames that culling sits out after a culled frame that hid no patch,
/// or too few to pay for it (`WORTH_CULLING`), or that took longer than
/// the frame drawn without it (`CullingTurns`): its depth pyramid, patch
/// test and second pass cost what they could not save. It tries again
/// after them, so a view that turns towards hidden ground is culled again
/// within this many frames, and at once after a cut (the eye placed more
/// than a patch's width away, `CUT_STEP`). A camera that keeps moving,
/// however fast, sits the frames out: each frame's view is much like the
/// last, and what culling found in one is the best guess for the next.
/// Images are the same either way.
pub const IDLE_AFTER_NOTHING_HIDDEN: u32 = 15;

/// How many times as far as the frame before a cut moves the eye. A
/// camera that flies, however fast, changes its pace gradually; one placed
/// elsewhere moves by a patch's width or more in one frame after standing
/// still or moving slowly.
const CUT_STEP: f32 = 2.0;

/// The share of the patches in view a culled frame must find hidden for
/// culling to go on. Culling costs a pass over the depth, a test of every
/// patch and a second pass: where it hid little, it added 7 % to 20 % to
/// a frame's GPU time on lavapipe and 14 % to 70 % on an NVIDIA H200.
/// Hidden patches lie behind nearer ground, farther than most of the
/// view, so their share of the frame's drawing is smaller than their
/// share of the patches: fewer than a quarter of the patches cannot save
/// what culling costs. (More can still cost more than they save: on
/// lavapipe, a frame culling nearly half the patches in view was still
/// 3 % slower than without.)
pub const WORTH_CULLING: f32 = 0.25;

/// What a culled frame found: the patches in view, and those of them
/// hidden.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HiddenCount {
    pub in_view: u32,
    pub hidden: u32,
}

impl HiddenCount {
    /// Whether culling the next frames can pay for itself: at least
    /// `WORTH_CULLING` of the patches in view were hidden.
    pub fn worth_culling(&self) -> bool {
        self.hidden > 0 && self.hidden as f32 >= WORTH_CULLING * self.in_view as f32
    }
}

/// Culled frames after which one frame that asks for culling is drawn
/// without it, to time the frame unculled again (`CullingTurns`).
pub const PROBE_AFTER_CULLED: u32 = 15;

/// What a frame slot's last frame was, as culling's turns see it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LastFrame {
    /// It did not ask for culling, or the slot has drawn nothing yet.
    Unasked,
    /// It asked for culling and was drawn in one pass (culling sat out, or
    /// the frame timed the view unculled), taking `gpu_ms` where the
    /// device has timestamps.
    Plain { gpu_ms: Option<f32> },
    /// It was culled, found `hidden`, and took `gpu_ms`.
    Culled {
        hidden: HiddenCount,
        gpu_ms: Option<f32>,
    },
}

/// Which frames that ask for occlusion culling get it. Culling pays
/// where what it hides costs more to draw than its depth pyramid, patch
/// test and second pass; that balance differs by device (on lavapipe a
/// frame drawing half the patches it would have was still slower
/// culled; on a GPU that draws the whole view in a millisecond, culling
/// is the larger part). So besides the share of patches a culled frame
/// found hidden (`HiddenCount::worth_culling`), culling is judged by its
/// time: after two culled frames in a row (the first may start from
/// another view's visibility), one frame is drawn unculled, and where
/// the culled frame took longer than the unculled one, culling sits out
/// `IDLE_AFTER_NOTHING_HIDDEN` frames. While culling pays, the unculled
/// time is taken again every `PROBE_AFTER_CULLED` culled frames. Times
/// are compared only between frames seen from within a patch's width of
/// each other; a device without timestamps is judged by the share
/// alone. Images are the same whichever frames are culled.
#[derive(Clone, Debug, PartialEq)]
pub struct CullingTurns {
    /// Frames left that sit culling out, and a patch's width: a cut, which
    /// ends them, moves the eye farther than that and more than
    /// `CUT_STEP` times as far as the frame before.
    idle: u32,
    patch_width: f32,
    /// How far the eye moved from the frame before to the frame prepared
    /// last.
    step: f32,
    /// The last frame drawn unculled while asking for culling: its GPU
    /// milliseconds and eye.
    plain: Option<(f32, Vec3)>,
    /// The last culled frame that followed another culled one: its GPU
    /// milliseconds and eye.
    culled: Option<(f32, Vec3)>,
    /// Culled frames since the last one drawn unculled.
    culled_run: u32,
    /// The next frame that asks is drawn unculled, to be timed.
    probe: bool,
    /// The last frame was that one.
    probing: bool,
    /// The eye of the frame prepared last, which the next `look_from`
    /// reports on.
    last_eye: Option<Vec3>,
}

impl CullingTurns {
    /// Turns for a terrain whose patches are `patch_width` wide.
    pub fn new(patch_width: f32) -> Self {
        CullingTurns {
            idle: 0,
            patch_width,
            step: 0.0,
            plain: None,
            culled: None,
            culled_run: 0,
            probe: false,
            probing: false,
            last_eye: None,
        }
    }

    /// A frame about to be prepared from `eye`, after `last`, the frame
    /// prepared before it.
    pub fn look_from(&mut self, eye: Vec3, last: LastFrame) {
        if let Some(seen_from) = self.last_eye.replace(eye) {
            self.judge(seen_from, last);
            let step = eye.distance(seen_from);
            if step > self.patch_width {
                // Times are compared within a patch's width: this view
                // starts its own run of culled frames before it is timed
                // unculled.
                self.probe = false;
                self.culled_run = 0;
                if step > CUT_STEP * self.step {
                    // A cut: what the last view found says nothing here.
                    self.idle = 0;
                }
            }
            self.step = step;
        }
    }

    /// What `last`, seen from `eye`, says of culling here.
    fn judge(&mut self, eye: Vec3, last: LastFrame) {
        log::debug!(
            "culling turns: last {last:?}, idle {}, run {}, plain {:?}, culled {:?}, probing {}",
            self.idle,
            self.culled_run,
            self.plain.map(|p| p.0),
            self.culled.map(|p| p.0),
            self.probing
        );
        let width = self.patch_width;
        let near = |seen: Option<(f32, Vec3)>| seen.filter(|&(_, at)| eye.distance(at) <= width);
        match last {
            LastFrame::Unasked => {}
            LastFrame::Culled { hidden, gpu_ms } => {
                self.probing = false;
                self.culled_run += 1;
                if !hidden.worth_culling() {
                    self.sit_out();
                } else if let (Some(ms), true) = (gpu_ms, self.culled_run >= 2) {
                    self.culled = Some((ms, eye));
                    match near(self.plain) {
                        Some((plain, _)) if ms > plain => self.sit_out(),
                        Some(_) => self.probe |= self.culled_run >= PROBE_AFTER_CULLED,
                        None => self.probe = true,
                    }
                }
            }
            LastFrame::Plain { gpu_ms } => {
                self.culled_run = 0;
                if let Some(ms) = gpu_ms {
                    self.plain = Some((ms, eye));
                    if std::mem::take(&mut self.probing)
                        && near(self.culled).is_some_and(|(culled, _)| culled > ms)
                    {
                        self.sit_out();
                    }
                }
            }
        }
    }

    fn sit_out(&mut self) {
        self.idle = IDLE_AFTER_NOTHING_HIDDEN;
        self.probe = false;
    }

    /// Whether a frame that asks for culling gets it: not while culling
    /// sits out (each such frame counts one off), nor when the frame is
    /// to be timed unculled.
    pub fn takes_turn(&mut self) -> bool {
        if self.idle > 0 {
            self.idle -= 1;
            return false;
        }
        if std::mem::take(&mut self.probe) {
            self.probing = true;
            return false;
        }
        true
    }
}

/// The compute side: pipelines and, per frame slot, the pyramid, the
/// culled-patch count and a descriptor set.
struct Culling {
    /// Read through the sets: the patches' boxes.
    _boxes: Buffer,
    slots: Vec<CullingSlot>,
    /// The slots' sets come from here.
    _sets: DescriptorSets,
    from_depth: Pipeline,
    from_multisampled_depth: Pipeline,
    reduce: Pipeline,
    test: Pipeline,
    select: Pipeline,
    layout: PipelineLayout,
    _set_layout: DescriptorSetLayout,
}

struct CullingSlot {
    set: DescriptorSet,
    /// The patches culled this frame, read after its fence.
    count: Buffer,
    /// The pyramid and the depth extent it was sized for.
    pyramid: Option<(Buffer, vk::Extent2D)>,
    /// The depth image the set reads (`TargetViews::depth_identity`).
    depth: Option<u64>,
    /// The patches of each listed draw, and their indirect commands: the
    /// first pass's, then (from command `list_capacity` on) the second's.
    draw_patches: Buffer,
    commands: Buffer,
    /// Draws listed this frame.
    listed: u32,
}

impl Occlusion {
    /// The visibility state for `terrain`'s patches and, where `culling`,
    /// the compute pipelines, with one set per frame slot reading that
    /// slot's `uniforms`.
    pub(super) fn new(
        device: &Device,
        terrain: &Terrain,
        uniforms: &[&Buffer],
        culling: bool,
    ) -> Result<Self> {
        let patches = terrain.grid().patch_count().max(1);
        let visibility = device.upload_buffer(
            "terrain.occlusion.visibility",
            vk::BufferUsageFlags::STORAGE_BUFFER,
            bytemuck::cast_slice(&vec![OCCLUSION_VISIBLE_BIT; patches]),
        )?;
        let culling = match culling {
            true => Some(Culling::new(device, terrain, uniforms, &visibility)?),
            false => None,
        };
        let readers = if device.caps.tessellation_shader {
            (
                vk::PipelineStageFlags2::TESSELLATION_CONTROL_SHADER,
                vk::AccessFlags2::SHADER_STORAGE_READ,
            )
        } else {
            (vk::PipelineStageFlags2::NONE, vk::AccessFlags2::NONE)
        };
        Ok(Occlusion {
            visibility,
            patches,
            readers,
            culling,
            turns: CullingTurns::new(patch_width(terrain)),
        })
    }

    /// Whether frames can be culled (the device reads depth attachments).
    pub(super) fn can_cull(&self) -> bool {
        self.culling.is_some()
    }

    /// A frame about to be prepared from `eye`, and what the slot's last
    /// frame was (`CullingTurns::look_from`).
    pub(super) fn look_from(&mut self, eye: Vec3, last: LastFrame) {
        self.turns.look_from(eye, last);
    }

    /// Whether a frame that asks for culling gets it
    /// (`CullingTurns::takes_turn`).
    pub(super) fn takes_turn(&mut self) -> bool {
        self.turns.takes_turn()
    }

    /// Points slot `slot`'s set at `target`'s depth and sizes its pyramid
    /// for it, when either changed. The slot's previous frame must have
    /// completed.
    pub(super) fn prepare_target(
        &mut self,
        device: &Device,
        slot: usize,
        target: &TargetViews,
        sampler: &Sampler,
    ) -> Result<()> {
        let culling = self.culling.as_mut().ok_or_else(not_built)?;
        let s = &mut culling.slots[slot];
        if s.depth != Some(target.depth_identity()) {
            device.write_target_depth(s.set, BINDING_HIZ_DEPTH, target, sampler);
            s.depth = Some(target.depth_identity());
        }
        if s.pyramid.as_ref().map(|(_, e)| *e) != Some(target.extent) {
            let texels: u32 = pyramid_levels(target.extent.width, target.extent.height)
                .iter()
                .map(|[w, h]| w * h)
                .sum();
            let pyramid = device.create_buffer(
                BufferDesc {
                    size: u64::from(texels) * 4,
                    // Copied out by `read_pyramid`.
                    usage: vk::BufferUsageFlags::STORAGE_BUFFER
                        | vk::BufferUsageFlags::TRANSFER_SRC,
                    location: MemoryLocation::GpuOnly,
                },
                &format!("terrain.occlusion.pyramid[{slot}]"),
            )?;
            device.write_buffer(
                s.set,
                BINDING_HIZ_PYRAMID,
                vk::DescriptorType::STORAGE_BUFFER,
                &pyramid,
                pyramid.desc.size,
            );
            s.pyramid = Some((pyramid, target.extent));
        }
        Ok(())
    }

    /// Lists this frame's CPU-chosen draws for slot `slot`, their
    /// instance counts still 0.
    pub(super) fn write_draws(&mut self, slot: usize, draws: &[ListedDraw]) -> Result<()> {
        let capacity = self.list_capacity();
        let culling = self.culling.as_mut().ok_or_else(not_built)?;
        let s = &mut culling.slots[slot];
        if draws.len() > capacity {
            return Err(RenderError::Unsupported(format!(
                "{} draws listed, room for {capacity}",
                draws.len()
            )));
        }
        let ranges: Vec<[u32; 2]> = draws.iter().map(|d| d.patches).collect();
        let commands: Vec<DrawCommand> = draws
            .iter()
            .map(|d| DrawCommand {
                index_count: d.index_count,
                first_index: d.first_index,
                first_instance: d.first_instance,
                ..DrawCommand::default()
            })
            .collect();
        let command_bytes: &[u8] = bytemuck::cast_slice(&commands);
        let ranges_bytes: &[u8] = bytemuck::cast_slice(&ranges);
        let unmapped = || RenderError::NotMapped("the draw list");
        s.draw_patches.mapped_mut().ok_or_else(unmapped)?[..ranges_bytes.len()]
            .copy_from_slice(ranges_bytes);
        let second = capacity * DRAW_COMMAND_BYTES as usize;
        let mapped = s.commands.mapped_mut().ok_or_else(unmapped)?;
        mapped[..command_bytes.len()].copy_from_slice(command_bytes);
        mapped[second..second + command_bytes.len()].copy_from_slice(command_bytes);
        s.listed = draws.len() as u32;
        Ok(())
    }

    /// Draws one frame may list (`list_capacity`).
    pub(super) fn list_capacity(&self) -> usize {
        list_capacity(self.patches as u64) as usize
    }

    /// The indirect commands of the listed draws for `phase`: the buffer,
    /// and the phase's first command.
    pub(super) fn draw_commands(&self, slot: usize, phase: u32) -> Result<(&Buffer, u64)> {
        let culling = self.culling.as_ref().ok_or_else(not_built)?;
        Ok((&culling.slots[slot].commands, self.first_command(phase)?))
    }

    /// Where `phase`'s commands start in a slot's command buffer: the
    /// first pass's at 0, the second's after room for a whole list.
    fn first_command(&self, phase: u32) -> Result<u64> {
        match phase {
            OCCLUSION_PHASE_FIRST => Ok(0),
            OCCLUSION_PHASE_SECOND => Ok(self.list_capacity() as u64),
            _ => Err(RenderError::Unsupported(format!(
                "no listed draws for occlusion phase {phase}"
            ))),
        }
    }

    /// Sets the listed draws' instance counts for `phase` from the state.
    fn record_select(
        &self,
        rec: &Recorder,
        culling: &Culling,
        slot: usize,
        phase: u32,
    ) -> Result<()> {
        let s = &culling.slots[slot];
        if s.listed == 0 {
            return Ok(());
        }
        rec.bind_compute(&culling.select, &culling.layout, s.set);
        let constants = SelectConstants {
            count: s.listed,
            phase,
            first: self.first_command(phase)? as u32,
        };
        rec.push_constants(
            &culling.layout,
            vk::ShaderStageFlags::COMPUTE,
            bytemuck::bytes_of(&constants),
        );
        rec.dispatch([s.listed.div_ceil(TEST_GROUP), 1, 1]);
        Ok(())
    }

    /// Before the first pass: the previous frame's test is done with the
    /// state, the slot's count starts at 0, and the listed draws keep the
    /// patches visible last frame.
    pub(super) fn record_start(&self, rec: &Recorder, slot: usize) -> Result<()> {
        use vk::{AccessFlags2 as A, PipelineStageFlags2 as S};
        let culling = self.culling.as_ref().ok_or_else(not_built)?;
        rec.memory_barrier(
            (S::COMPUTE_SHADER, A::SHADER_STORAGE_WRITE),
            (
                self.readers.0 | S::COMPUTE_SHADER | S::ALL_TRANSFER,
                A::SHADER_STORAGE_READ | A::SHADER_STORAGE_WRITE | A::TRANSFER_WRITE,
            ),
        );
        rec.fill_buffer(&culling.slots[slot].count, 0);
        self.record_select(rec, culling, slot, OCCLUSION_PHASE_FIRST)?;
        rec.memory_barrier(
            (S::COMPUTE_SHADER, A::SHADER_STORAGE_WRITE),
            (S::DRAW_INDIRECT, A::INDIRECT_COMMAND_READ),
        );
        Ok(())
    }

    /// Between the passes (outside rendering): builds slot `slot`'s
    /// pyramid from `target`'s depth and tests every patch.
    pub(super) fn record_cull(
        &self,
        rec: &Recorder,
        slot: usize,
        target: &TargetViews,
    ) -> Result<()> {
        use vk::{AccessFlags2 as A, PipelineStageFlags2 as S};
        let culling = self.culling.as_ref().ok_or_else(not_built)?;
        let s = &culling.slots[slot];
        let extent = target.extent;
        if s.pyramid.as_ref().map(|(_, e)| *e) != Some(extent) {
            return Err(RenderError::Unsupported(format!(
                "occlusion slot {slot} was not prepared for a {}x{} target",
                extent.width, extent.height
            )));
        }
        rec.depth_to_compute(target);
        // The count's fill and the first pass's reads of the state come
        // before the test's writes.
        rec.memory_barrier(
            (S::ALL_TRANSFER | self.readers.0, A::TRANSFER_WRITE),
            (
                S::COMPUTE_SHADER,
                A::SHADER_STORAGE_READ | A::SHADER_STORAGE_WRITE,
            ),
        );
        let levels = pyramid_levels(extent.width, extent.height);
        let samples = target.samples.as_raw();
        let mut src_size = [extent.width as i32, extent.height as i32];
        let mut src_offset = 0u32;
        let mut dst_offset = 0u32;
        for (first, chunk) in levels.chunks(REDUCE_LEVELS).enumerate() {
            let pipeline = match (first, samples) {
                (0, 1) => &culling.from_depth,
                (0, _) => &culling.from_multisampled_depth,
                _ => &culling.reduce,
            };
            if first > 0 {
                rec.memory_barrier(
                    (S::COMPUTE_SHADER, A::SHADER_STORAGE_WRITE),
                    (S::COMPUTE_SHADER, A::SHADER_STORAGE_READ),
                );
            }
            rec.bind_compute(pipeline, &culling.layout, s.set);
            let constants = ReduceConstants {
                src_size,
                src_offset,
                dst_offset,
                samples,
                levels: chunk.len() as u32,
            };
            rec.push_constants(
                &culling.layout,
                vk::ShaderStageFlags::COMPUTE,
                bytemuck::bytes_of(&constants),
            );
            let [w, h] = chunk[0];
            rec.dispatch([w.div_ceil(REDUCE_TILE), h.div_ceil(REDUCE_TILE), 1]);
            // The next dispatch reads this one's last level.
            for &[w, h] in chunk {
                src_offset = dst_offset;
                dst_offset += w * h;
                src_size = [w as i32, h as i32];
            }
        }
        rec.memory_barrier(
            (S::COMPUTE_SHADER, A::SHADER_STORAGE_WRITE),
            (S::COMPUTE_SHADER, A::SHADER_STORAGE_READ),
        );
        rec.bind_compute(&culling.test, &culling.layout, s.set);
        let constants = TestConstants {
            size: [extent.width as i32, extent.height as i32],
            levels: levels.len() as u32,
        };
        rec.push_constants(
            &culling.layout,
            vk::ShaderStageFlags::COMPUTE,
            bytemuck::bytes_of(&constants),
        );
        rec.dispatch([(self.patches as u32).div_ceil(TEST_GROUP), 1, 1]);
        rec.memory_barrier(
            (S::COMPUTE_SHADER, A::SHADER_STORAGE_WRITE),
            (S::COMPUTE_SHADER, A::SHADER_STORAGE_READ),
        );
        self.record_select(rec, culling, slot, OCCLUSION_PHASE_SECOND)
    }

    /// After `record_cull`: hands depth, colour and the state to the
    /// second pass.
    pub(super) fn record_resume(&self, rec: &Recorder, target: &TargetViews) {
        use vk::{AccessFlags2 as A, PipelineStageFlags2 as S};
        // The state and the commands feed the second pass's draws, the
        // count the host.
        rec.memory_barrier(
            (S::COMPUTE_SHADER, A::SHADER_STORAGE_WRITE),
            (
                self.readers.0 | S::DRAW_INDIRECT | S::HOST,
                self.readers.1 | A::INDIRECT_COMMAND_READ | A::HOST_READ,
            ),
        );
        rec.depth_to_attachment(target);
        // The second pass loads what the first stored.
        rec.memory_barrier(
            (S::COLOR_ATTACHMENT_OUTPUT, A::COLOR_ATTACHMENT_WRITE),
            (
                S::COLOR_ATTACHMENT_OUTPUT,
                A::COLOR_ATTACHMENT_READ | A::COLOR_ATTACHMENT_WRITE,
            ),
        );
    }

    /// The pyramid slot `slot`'s last culled frame built, every level one
    /// after another (`pyramid_levels`), copied out through a host-visible
    /// buffer; `None` where frames are not culled, or before any was. Call
    /// after the slot's fence.
    pub(super) fn read_pyramid(&self, device: &Device, slot: usize) -> Result<Option<Vec<f32>>> {
        use vk::{AccessFlags2 as A, PipelineStageFlags2 as S};
        let Some((pyramid, _)) = self
            .culling
            .as_ref()
            .and_then(|c| c.slots[slot].pyramid.as_ref())
        else {
            return Ok(None);
        };
        let size = pyramid.desc.size;
        let host = device.create_buffer(
            BufferDesc {
                size,
                usage: vk::BufferUsageFlags::TRANSFER_DST,
                location: MemoryLocation::GpuToCpu,
            },
            "terrain.occlusion.pyramid_readback",
        )?;
        device.one_shot("terrain.occlusion.read_pyramid", |rec| {
            rec.memory_barrier(
                (S::COMPUTE_SHADER, A::SHADER_STORAGE_WRITE),
                (S::COPY, A::TRANSFER_READ),
            );
            rec.copy_buffer(pyramid, &host, size);
            rec.memory_barrier((S::COPY, A::TRANSFER_WRITE), (S::HOST, A::HOST_READ));
        })?;
        let bytes = host
            .mapped()
            .ok_or(RenderError::NotMapped("the pyramid readback"))?;
        Ok(Some(bytemuck::pod_collect_to_vec(&bytes[..size as usize])))
    }

    /// The patches slot `slot`'s last frame culled (found hidden, and
    /// hidden the frame before, so nothing drew them); call after its
    /// fence.
    pub(super) fn culled(&self, slot: usize) -> Result<u32> {
        Ok(self.counts(slot)?[0])
    }

    /// The patches in view slot `slot`'s last frame found hidden, drawn in
    /// its first pass or not (what culling would save the next frame), and
    /// the patches in view; call after its fence.
    pub(super) fn hidden(&self, slot: usize) -> Result<HiddenCount> {
        let [_, hidden, in_view] = self.counts(slot)?;
        Ok(HiddenCount { in_view, hidden })
    }

    fn counts(&self, slot: usize) -> Result<[u32; 3]> {
        let culling = self.culling.as_ref().ok_or_else(not_built)?;
        let bytes = culling.slots[slot]
            .count
            .mapped()
            .ok_or(RenderError::NotMapped("the culled count"))?;
        Ok(bytemuck::pod_read_unaligned(&bytes[..12]))
    }
}

impl Culling {
    fn new(
        device: &Device,
        terrain: &Terrain,
        uniforms: &[&Buffer],
        visibility: &Buffer,
    ) -> Result<Self> {
        let stage = vk::ShaderStageFlags::COMPUTE;
        let storage = vk::DescriptorType::STORAGE_BUFFER;
        let set_layout = device.create_descriptor_set_layout(
            &[
                (BINDING_FRAME, vk::DescriptorType::UNIFORM_BUFFER, stage),
                (
                    BINDING_HIZ_DEPTH,
                    vk::DescriptorType::COMBINED_IMAGE_SAMPLER,
                    stage,
                ),
                (BINDING_HIZ_PYRAMID, storage, stage),
                (BINDING_CONTROL_POINTS, storage, stage),
                (BINDING_VISIBILITY, storage, stage),
                (BINDING_OCCLUSION_COUNT, storage, stage),
                (BINDING_DRAW_PATCHES, storage, stage),
                (BINDING_DRAW_COMMANDS, storage, stage),
            ],
            "terrain.occlusion.set_layout",
        )?;
        let layout = device.create_pipeline_layout_with_push(
            &[&set_layout],
            stage,
            PUSH_SIZE,
            "terrain.occlusion.pipeline_layout",
        )?;
        let sets = device.allocate_descriptor_sets(
            &set_layout,
            &[
                (vk::DescriptorType::UNIFORM_BUFFER, 1),
                (vk::DescriptorType::COMBINED_IMAGE_SAMPLER, 1),
                (storage, 6),
            ],
            uniforms.len() as u32,
            "terrain.occlusion.set",
        )?;
        let pipeline = |shader, name: &str| {
            device.create_compute_pipeline(
                shaders::spirv(shader),
                &layout,
                &format!("terrain.occlusion.{name}"),
            )
        };
        // The tess path's control points: x, z and each patch's Y bounds.
        let boxes = device.upload_buffer(
            "terrain.occlusion.boxes",
            vk::BufferUsageFlags::STORAGE_BUFFER,
            bytemuck::cast_slice(terrain.control_points()),
        )?;
        let mut slots = Vec::with_capacity(uniforms.len());
        for (i, (set, frame)) in sets.iter().zip(uniforms).enumerate() {
            // Three words: the patches culled, those found hidden, and
            // those in view.
            let count = device.create_buffer(
                BufferDesc {
                    size: 12,
                    usage: vk::BufferUsageFlags::STORAGE_BUFFER
                        | vk::BufferUsageFlags::TRANSFER_DST,
                    location: MemoryLocation::GpuToCpu,
                },
                &format!("terrain.occlusion.count[{i}]"),
            )?;
            device.write_buffer(
                set,
                BINDING_FRAME,
                vk::DescriptorType::UNIFORM_BUFFER,
                frame,
                size_of::<FrameUniforms>() as u64,
            );
            let patches = terrain.grid().patch_count().max(1) as u64;
            let list = |name: &str, size: u64, usage: vk::BufferUsageFlags| {
                device.create_buffer(
                    BufferDesc {
                        size,
                        usage: vk::BufferUsageFlags::STORAGE_BUFFER | usage,
                        location: MemoryLocation::CpuToGpu,
                    },
                    &format!("terrain.occlusion.{name}[{i}]"),
                )
            };
            // A patch range (two u32) per listed draw, and a command per
            // listed draw for each of the two passes.
            let capacity = list_capacity(patches);
            let draw_patches = list(
                "draw_patches",
                capacity * size_of::<[u32; 2]>() as u64,
                vk::BufferUsageFlags::empty(),
            )?;
            let commands = list(
                "draw_commands",
                2 * capacity * DRAW_COMMAND_BYTES,
                vk::BufferUsageFlags::INDIRECT_BUFFER,
            )?;
            for (binding, buffer) in [
                (BINDING_CONTROL_POINTS, &boxes),
                (BINDING_VISIBILITY, visibility),
                (BINDING_OCCLUSION_COUNT, &count),
                (BINDING_DRAW_PATCHES, &draw_patches),
                (BINDING_DRAW_COMMANDS, &commands),
            ] {
                device.write_buffer(set, binding, storage, buffer, buffer.desc.size);
            }
            slots.push(CullingSlot {
                set,
                count,
                pyramid: None,
                depth: None,
                draw_patches,
                commands,
                listed: 0,
            });
        }
        Ok(Culling {
            from_depth: pipeline(Shader::HizComp(HizSource::Depth), "pyramid_from_depth")?,
            from_multisampled_depth: pipeline(
                Shader::HizComp(HizSource::DepthMultisampled),
                "pyramid_from_multisampled_depth",
            )?,
            reduce: pipeline(Shader::HizComp(HizSource::Pyramid), "pyramid_reduce")?,
            test: pipeline(Shader::OcclusionComp, "test")?,
            select: pipeline(Shader::OcclusionDrawsComp, "select_draws")?,
            _boxes: boxes,
            slots,
            _sets: sets,
            layout,
            _set_layout: set_layout,
        })
    }
}

fn not_built() -> RenderError {
    RenderError::NotBuilt("occlusion culling")
}

#[cfg(test)]
mod tests {
    use super::*;

    const WORTH: HiddenCount = HiddenCount {
        in_view: 100,
        hidden: 40,
    };

    /// Which of `frames` frames from `eye` are culled, when a culled frame
    /// finds `hidden` and takes `culled_ms`, and an unculled one takes
    /// `plain_ms` (None: no timestamps). The turns are asked as the
    /// renderer asks them: the last frame told, then this one's turn.
    fn culled_frames(
        turns: &mut CullingTurns,
        eye: Vec3,
        frames: usize,
        (hidden, culled_ms, plain_ms): (HiddenCount, Option<f32>, Option<f32>),
    ) -> Vec<bool> {
        let mut last = LastFrame::Unasked;
        (0..frames)
            .map(|_| {
                turns.look_from(eye, last);
                let culled = turns.takes_turn();
                last = match culled {
                    true => LastFrame::Culled {
                        hidden,
                        gpu_ms: culled_ms,
                    },
                    false => LastFrame::Plain { gpu_ms: plain_ms },
                };
                culled
            })
            .collect()
    }

    #[test]
    fn culling_that_pays_in_time_goes_on_and_is_timed_unculled_now_and_then() {
        let mut turns = CullingTurns::new(10.0);
        let frames = culled_frames(&mut turns, Vec3::ZERO, 40, (WORTH, Some(5.0), Some(8.0)));
        // Two culled frames, one timed unculled, then PROBE_AFTER_CULLED
        // culled frames between unculled ones.
        let plain: Vec<usize> = (0..40).filter(|&i| !frames[i]).collect();
        assert_eq!(plain, vec![2, 18, 34], "{frames:?}");
    }

    #[test]
    fn culling_slower_than_drawing_everything_sits_out() {
        let mut turns = CullingTurns::new(10.0);
        let frames = culled_frames(&mut turns, Vec3::ZERO, 40, (WORTH, Some(9.0), Some(8.0)));
        // Culled twice, timed unculled, then it sits out; it tries again
        // after IDLE_AFTER_NOTHING_HIDDEN frames, with two culled frames,
        // compared with the unculled time it holds.
        let culled: Vec<usize> = (0..40).filter(|&i| frames[i]).collect();
        let retry = 3 + IDLE_AFTER_NOTHING_HIDDEN as usize;
        assert_eq!(
            culled,
            vec![0, 1, retry, retry + 1, retry + 17, retry + 18],
            "{frames:?}"
        );
    }

    #[test]
    fn without_timestamps_the_share_alone_decides() {
        let mut turns = CullingTurns::new(10.0);
        let frames = culled_frames(&mut turns, Vec3::ZERO, 40, (WORTH, None, None));
        assert!(frames.iter().all(|&c| c), "{frames:?}");
        let few = HiddenCount {
            in_view: 100,
            hidden: 10,
        };
        let mut turns = CullingTurns::new(10.0);
        let frames = culled_frames(&mut turns, Vec3::ZERO, 20, (few, None, None));
        let culled: Vec<usize> = (0..20).filter(|&i| frames[i]).collect();
        assert_eq!(culled, vec![0, 1 + IDLE_AFTER_NOTHING_HIDDEN as usize]);
    }

    #[test]
    fn times_from_elsewhere_are_not_compared() {
        // Sitting out at one place, then a cut: the new view culls at once,
        // and its culled frames are not judged by the old unculled time.
        let mut turns = CullingTurns::new(10.0);
        culled_frames(&mut turns, Vec3::ZERO, 4, (WORTH, Some(9.0), Some(8.0)));
        assert!(turns.idle > 0);
        let far = Vec3::new(25.0, 0.0, 0.0);
        let frames = culled_frames(&mut turns, far, 4, (WORTH, Some(5.0), Some(1.0)));
        assert_eq!(frames, vec![true, true, false, false], "{frames:?}");
        // The frame before a cut is reported from the eye that drew it:
        // its unculled time stays there, and the new view, culled
        // cheaper than that, goes on culling.
        let mut turns = CullingTurns::new(10.0);
        culled_frames(&mut turns, Vec3::ZERO, 4, (WORTH, Some(9.0), Some(2.0)));
        turns.look_from(far, LastFrame::Plain { gpu_ms: Some(2.0) });
        let mut culled = Vec::new();
        for _ in 0..3 {
            culled.push(turns.takes_turn());
            turns.look_from(
                far,
                LastFrame::Culled {
                    hidden: WORTH,
                    gpu_ms: Some(5.0),
                },
            );
        }
        assert_eq!(culled, vec![true, true, false], "probed, not sat out");
        // Two culled frames here would time the next one unculled; after a
        // cut the new view is culled first.
        let mut turns = CullingTurns::new(10.0);
        culled_frames(&mut turns, Vec3::ZERO, 2, (WORTH, Some(5.0), Some(8.0)));
        let culled = LastFrame::Culled {
            hidden: WORTH,
            gpu_ms: Some(5.0),
        };
        turns.look_from(far, culled);
        assert!(turns.takes_turn(), "the cut's first frame is culled");
        turns.look_from(far, culled);
        assert!(turns.takes_turn());
        turns.look_from(far, culled);
        assert!(!turns.takes_turn(), "then timed unculled");
    }

    /// Which of `frames` frames are culled along a straight flight whose
    /// eye moves `step(i)` before frame `i`, each culled frame finding
    /// `hidden`.
    fn culled_along_flight(
        step: impl Fn(usize) -> f32,
        frames: usize,
        hidden: HiddenCount,
    ) -> Vec<bool> {
        let mut turns = CullingTurns::new(10.0);
        let mut last = LastFrame::Unasked;
        let mut x = 0.0;
        (0..frames)
            .map(|i| {
                x += if i == 0 { 0.0 } else { step(i) };
                turns.look_from(Vec3::new(x, 0.0, 0.0), last);
                let culled = turns.takes_turn();
                last = match culled {
                    true => LastFrame::Culled {
                        hidden,
                        gpu_ms: Some(5.0),
                    },
                    false => LastFrame::Plain { gpu_ms: Some(8.0) },
                };
                culled
            })
            .collect()
    }

    #[test]
    fn a_moving_camera_sits_culling_out_however_fast_it_moves() {
        let few = HiddenCount {
            in_view: 100,
            hidden: 10,
        };
        let idle = IDLE_AFTER_NOTHING_HIDDEN as usize;
        // A third of a patch's width a frame, two widths a frame, and a
        // pace about a patch's width that jumps every other frame: the eye
        // passes many patches during the sit-out, which still ends on its
        // count alone. (The fast flight's first move, from a still eye, is
        // a cut, and culls once more.)
        let about_a_width = |i: usize| if i % 2 == 0 { 9.5 } else { 10.5 };
        let flights: [(&dyn Fn(usize) -> f32, usize); 3] =
            [(&|_| 3.0, 0), (&|_| 20.0, 1), (&about_a_width, 1)];
        for (n, (step, first)) in flights.into_iter().enumerate() {
            let frames = culled_along_flight(step, 40, few);
            let culled: Vec<usize> = (0..40).filter(|&i| frames[i]).collect();
            let after = |k: usize| first + k * (idle + 1);
            let mut expected = vec![0, after(0), after(1), after(2)];
            expected.dedup();
            assert_eq!(culled, expected, "flight {n}: {frames:?}");
        }
        // A cut during the sit-out ends it.
        let cut_at_5 = |i: usize| if i == 5 { 100.0 } else { 3.0 };
        let frames = culled_along_flight(cut_at_5, 8, few);
        assert_eq!(
            frames,
            [true, false, false, false, false, true, false, false]
        );
        // Where culling pays, a fast flight culls every frame: it never
        // stays within a patch's width to be timed unculled.
        let frames = culled_along_flight(|_| 20.0, 40, WORTH);
        assert!(frames.iter().all(|&c| c), "{frames:?}");
        // Slowly, it is timed unculled after two culled frames.
        let frames = culled_along_flight(|_| 3.0, 40, WORTH);
        assert!(!frames[2], "{frames:?}");
    }

    #[test]
    fn pyramid_levels_halve_rounding_up_down_to_one_texel() {
        assert_eq!(
            pyramid_levels(1280, 720),
            vec![
                [640, 360],
                [320, 180],
                [160, 90],
                [80, 45],
                [40, 23],
                [20, 12],
                [10, 6],
                [5, 3],
                [3, 2],
                [2, 1],
                [1, 1]
            ]
        );
        assert_eq!(pyramid_levels(1, 1), vec![[1, 1]]);
        assert_eq!(pyramid_levels(3, 1), vec![[2, 1], [1, 1]]);
    }
}
