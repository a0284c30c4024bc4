//! What each frame in flight owns (its uniform block, descriptor set,
//! queries, the tess path's choice buffers and the lists its indirect
//! draws read), and the descriptor set layout every frame's set follows.

use std::mem::size_of;

use ash::vk;

use super::appearance::GpuAppearance;
use super::geomip_path::{GeomipConstants, GeomipDraw};
use super::occlusion::{DrawCommand, DRAW_COMMAND_BYTES, MAX_LISTED_DRAWS};
use super::seen::SeenBuffer;
use super::settings::RenderSettings;
use super::tess_path::ChoiceBuffers;
use super::uniforms::FrameUniforms;
use crate::gpu::descriptors::{DescriptorSet, DescriptorSets};
use crate::gpu::memory::{Buffer, Image};
use crate::gpu::owned::Sampler;
use crate::gpu::queries::FrameQueries;
use crate::gpu::Device;
use crate::lod::geomip_choice::ChosenPatches;
use crate::lod::plan::Planner;
use crate::render::error::Result;
use crate::shader_constants::{
    BINDING_ERROR_TABLE, BINDING_FRAME, BINDING_FRAME_STORAGE, BINDING_FULL_RESOLUTION,
    BINDING_HEIGHTMAP, BINDING_PAGES, BINDING_PAGE_TABLE, BINDING_PATCH_CONSTANTS,
    BINDING_SEEN_PIXELS, BINDING_VISIBILITY,
};

/// Parts of a frame whose pipeline statistics are counted apart: the
/// whole frame, or, with occlusion culling, the draws before the culling
/// pass and those after it.
pub(super) const COUNTED_PARTS: u32 = 2;

/// Per-frame-in-flight resources: the uniform block is rewritten each frame,
/// so a frame still on the GPU keeps its own.
pub(super) struct FrameSlot {
    pub(super) uniforms: Buffer,
    pub(super) set: DescriptorSet,
    pub(super) queries: FrameQueries,
    /// The tess path's error LOD: the buffers its control shader reads
    /// the frame plan from.
    pub(super) choice: Option<ChoiceBuffers>,
    /// Draws of the choice's merged node indices, (first index, index
    /// count), split where the driver limits patches per draw.
    pub(super) merged_batches: Vec<(u32, u32)>,
    /// What `prepare` set this slot's frame up for; `record` draws it.
    pub(super) settings: Option<RenderSettings>,
    /// Whether the slot's last recorded frame was drawn in two passes
    /// with occlusion culling between them.
    pub(super) culled: bool,
    /// Whether it asked for culling, culled or not (`CullingTurns`).
    pub(super) asked_to_cull: bool,
    /// The tess path's draws this frame, (first index, index count): the
    /// runs of patches the CPU's frustum test keeps (and the error LOD
    /// does not draw at full resolution), split where the driver limits
    /// patches per draw.
    pub(super) tess_batches: Vec<(u32, u32)>,
    /// `tess_batches` as indirect commands, drawn in one call where the
    /// device has multiDrawIndirect.
    pub(super) batch_commands: IndirectCommands,
    /// The frame's geomip draws (the geomip path's patches, or the tess
    /// path's full-resolution ones) listed for one indirect call.
    pub(super) geomip_list: GeomipList,
    /// What `prepare` chose for this slot's frame.
    pub(super) prepared: PreparedFrame,
    /// The error LOD's choice, with the buffers it fills kept from this
    /// slot's last frame.
    pub(super) planner: Planner,
    /// The geomip path's levels for every patch, with its buffers kept
    /// from this slot's last frame.
    pub(super) geomip_choice: ChosenPatches,
    /// The pixels each patch showed, in a frame that counts them.
    pub(super) seen: SeenBuffer,
}

/// A frame's draws as indirect commands in a per-slot buffer, so that one
/// draw call records them all and recording costs the same for ten draws
/// or ten thousand: the tess path's batches (the 4097^2 terrain's overview
/// draws about 2,000) on a device with multiDrawIndirect, and the geomip
/// draws of a `GeomipList`. Sized when the renderer is built, one command
/// a patch up to `MAX_LISTED_DRAWS`, so it never allocates during a run; a
/// frame of more draws records them one by one.
pub(super) struct IndirectCommands {
    buffer: Option<Buffer>,
    capacity: usize,
    /// Commands written for the frame, None where its draws were not
    /// written (no buffer, or more than fit).
    written: Option<u32>,
}

impl IndirectCommands {
    /// Room for `capacity` commands, named `name`; no buffer for 0.
    fn new(device: &Device, name: &str, capacity: usize) -> Result<Self> {
        let buffer = match capacity {
            0 => None,
            n => Some(device.create_host_buffer(
                name,
                vk::BufferUsageFlags::INDIRECT_BUFFER,
                &vec![0; n * DRAW_COMMAND_BYTES as usize],
            )?),
        };
        Ok(IndirectCommands {
            buffer,
            capacity,
            written: None,
        })
    }

    /// The tess path's batches: room for one a patch (capped) on a device
    /// with multiDrawIndirect, nothing otherwise.
    fn for_batches(device: &Device, slot: usize, patches: usize) -> Result<Self> {
        let capacity = match device.caps.multi_draw_indirect {
            true => patches.clamp(1, MAX_LISTED_DRAWS as usize),
            false => 0,
        };
        Self::new(device, &format!("terrain.batch_commands[{slot}]"), capacity)
    }

    /// Whether `count` commands fit.
    fn fits(&self, count: usize) -> bool {
        self.buffer.is_some() && count <= self.capacity
    }

    /// Writes `commands`, where they fit.
    fn write(&mut self, commands: impl ExactSizeIterator<Item = DrawCommand>) -> Result<()> {
        self.written = None;
        let Some(buffer) = self
            .buffer
            .as_mut()
            .filter(|_| commands.len() <= self.capacity)
        else {
            return Ok(());
        };
        let count = commands.len() as u32;
        buffer.write_records(commands)?;
        self.written = Some(count);
        Ok(())
    }

    /// Writes `batches` ((first index, index count) each) as commands,
    /// where they fit.
    pub(super) fn write_batches(&mut self, batches: &[(u32, u32)]) -> Result<()> {
        self.write(
            batches
                .iter()
                .map(|&(first, count)| DrawCommand::once(first, count)),
        )
    }

    /// The commands written for the frame, and how many.
    pub(super) fn written(&self) -> Option<(&Buffer, u32)> {
        self.buffer.as_ref().zip(self.written)
    }
}

/// A frame's geomip draws listed for one indirect call, where the device
/// has multiDrawIndirect and drawIndirectFirstInstance: each draw's
/// constants (`GeomipConstants`, read by glsl/geomip.vert at its instance
/// index) and its command, whose first instance is its place in the list.
/// Recording then costs the same for ten patches or ten thousand, and so
/// does the GPU's side of the draws (on the 4097^2 terrain the geomip path
/// drew about 10,000 patches a frame, one call and one push each). Sized
/// when the renderer is built, one entry a patch up to
/// `MAX_LISTED_DRAWS`; a frame of more draws pushes each draw's own.
pub(super) struct GeomipList {
    /// Bound at `BINDING_PATCH_CONSTANTS`; one entry where nothing is
    /// listed, so the binding is always valid.
    constants: Buffer,
    commands: IndirectCommands,
}

impl GeomipList {
    fn new(device: &Device, slot: usize, patches: usize) -> Result<Self> {
        let capacity = match device.caps.lists_geomip_draws() {
            true => patches.clamp(1, MAX_LISTED_DRAWS as usize),
            false => 0,
        };
        let constants = device.create_host_buffer(
            &format!("terrain.geomip_constants[{slot}]"),
            vk::BufferUsageFlags::STORAGE_BUFFER,
            &vec![0; capacity.max(1) * size_of::<GeomipConstants>()],
        )?;
        Ok(GeomipList {
            constants,
            commands: IndirectCommands::new(
                device,
                &format!("terrain.geomip_commands[{slot}]"),
                capacity,
            )?,
        })
    }

    /// Points `set`'s constants binding at the list.
    fn bind(&self, device: &Device, set: DescriptorSet) {
        device.write_buffer(
            set,
            BINDING_PATCH_CONSTANTS,
            vk::DescriptorType::STORAGE_BUFFER,
            &self.constants,
            vk::WHOLE_SIZE,
        );
    }

    /// Lists `draws` (their order kept), where they fit.
    pub(super) fn write(&mut self, draws: &[GeomipDraw]) -> Result<()> {
        if draws.is_empty() || !self.commands.fits(draws.len()) {
            self.commands.written = None;
            return Ok(());
        }
        self.constants
            .write_records(draws.iter().map(|d| d.constants))?;
        self.commands.write(
            draws
                .iter()
                .enumerate()
                .map(|(i, d)| DrawCommand::listed(d.first, d.count, i as u32)),
        )
    }

    /// The frame's listed commands and how many, None where its draws
    /// push their own constants.
    pub(super) fn listed(&self) -> Option<(&Buffer, u32)> {
        self.commands.written()
    }
}

/// What a prepared frame chose to draw and what it expects; the renderer
/// reports the last prepared slot's.
#[derive(Clone, Debug, Default)]
pub(super) struct PreparedFrame {
    /// Milliseconds of the level choice (None for the brute path).
    pub(super) lod_ms: Option<f64>,
    /// The largest error and the 99th percentile the choice expects on
    /// screen, in pixels (error LOD).
    pub(super) predicted_max_px: Option<f32>,
    pub(super) predicted_p99_px: Option<f32>,
    /// The share of the frame's terrain pixels the view model puts over
    /// tau (`FramePlan::predicted_over_share`; error LOD by the model).
    pub(super) predicted_over_share: Option<f32>,
    /// Merged nodes drawn (tess path, error LOD).
    pub(super) merged_nodes: usize,
    /// Patches in view, drawn on their own or in merged nodes.
    pub(super) patches_in_view: usize,
    /// The tess path's full-resolution patches, drawn with the geomip
    /// path's level 0.
    pub(super) exact: Vec<GeomipDraw>,
    /// The geomip path's patches.
    pub(super) geomip: Vec<GeomipDraw>,
}

/// One uniform block and query set per descriptor set, with the set
/// written (the tess path adds its own bindings when it is built).
pub(super) fn build_frames(
    device: &Device,
    sets: &DescriptorSets,
    (heightmap, sampler): (&Image, &Sampler),
    appearance: &GpuAppearance,
    (patches, seen_patches): (usize, Option<usize>),
) -> Result<Vec<FrameSlot>> {
    let mut frames = Vec::new();
    for (i, set) in sets.iter().enumerate() {
        let uniforms = device.create_host_buffer(
            &format!("terrain.frame_uniforms[{i}]"),
            vk::BufferUsageFlags::UNIFORM_BUFFER | vk::BufferUsageFlags::STORAGE_BUFFER,
            bytemuck::bytes_of(&FrameUniforms::default()),
        )?;
        let queries = FrameQueries::new(
            device,
            COUNTED_PARTS,
            &format!("terrain.frame_queries[{i}]"),
        )?;
        write_frame_bindings(device, set, &uniforms, heightmap, sampler);
        appearance.write(device, set);
        let seen = SeenBuffer::new(device, i, seen_patches)?;
        seen.bind(device, set);
        let geomip_list = GeomipList::new(device, i, patches)?;
        geomip_list.bind(device, set);
        frames.push(FrameSlot {
            uniforms,
            set,
            queries,
            choice: None,
            merged_batches: Vec::new(),
            settings: None,
            culled: false,
            asked_to_cull: false,
            tess_batches: Vec::new(),
            batch_commands: IndirectCommands::for_batches(device, i, patches)?,
            geomip_list,
            prepared: PreparedFrame::default(),
            planner: Planner::default(),
            geomip_choice: ChosenPatches::default(),
            seen,
        });
    }
    Ok(frames)
}

/// Points a set's frame-uniform and heightmap bindings at their objects:
/// what every pipeline of the renderer (and the mirror check) reads.
pub(super) fn write_frame_bindings(
    device: &Device,
    set: DescriptorSet,
    uniforms: &Buffer,
    heightmap: &Image,
    sampler: &Sampler,
) {
    let size = size_of::<FrameUniforms>() as u64;
    device.write_buffer(
        set,
        BINDING_FRAME,
        vk::DescriptorType::UNIFORM_BUFFER,
        uniforms,
        size,
    );
    device.write_sampled_image(set, BINDING_HEIGHTMAP, heightmap, sampler);
}

/// The bindings of glsl/terrain_common.glsl in `stages`: the frame's
/// uniforms, the heightmap, the page pool and the page table; what every terrain pipeline's layout (and the mirror check's)
/// starts with, and `write_frame_bindings` and `NoStream` fill.
pub(super) fn frame_bindings(
    stages: vk::ShaderStageFlags,
) -> [(u32, vk::DescriptorType, vk::ShaderStageFlags); 4] {
    use vk::DescriptorType as D;
    [
        (BINDING_FRAME, D::UNIFORM_BUFFER, stages),
        (BINDING_HEIGHTMAP, D::COMBINED_IMAGE_SAMPLER, stages),
        (BINDING_PAGES, D::COMBINED_IMAGE_SAMPLER, stages),
        (BINDING_PAGE_TABLE, D::STORAGE_BUFFER, stages),
    ]
}

/// The bindings of the renderer's one descriptor set layout, and what its
/// pool must hold per set: only what the built paths and the scene's
/// material use.
pub(super) struct DescriptorPlan {
    pub(super) bindings: Vec<(u32, vk::DescriptorType, vk::ShaderStageFlags)>,
    pub(super) pool_sizes: Vec<(vk::DescriptorType, u32)>,
}

impl DescriptorPlan {
    pub(super) fn new(tess: bool, appearance: &GpuAppearance) -> Self {
        let mut stages = vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT;
        if tess {
            stages |= vk::ShaderStageFlags::TESSELLATION_CONTROL
                | vk::ShaderStageFlags::TESSELLATION_EVALUATION;
        }
        let mut plan = DescriptorPlan {
            bindings: frame_bindings(stages).to_vec(),
            pool_sizes: vec![
                (vk::DescriptorType::UNIFORM_BUFFER, 1),
                (vk::DescriptorType::COMBINED_IMAGE_SAMPLER, 2),
                (vk::DescriptorType::STORAGE_BUFFER, 3),
            ],
        };
        // The pixels each patch shows (render::seen), and the geomip
        // draws' listed constants (`GeomipList`).
        plan.bindings.push((
            BINDING_SEEN_PIXELS,
            vk::DescriptorType::STORAGE_BUFFER,
            vk::ShaderStageFlags::FRAGMENT,
        ));
        plan.bindings.push((
            BINDING_PATCH_CONSTANTS,
            vk::DescriptorType::STORAGE_BUFFER,
            vk::ShaderStageFlags::VERTEX,
        ));
        if tess {
            // The control shader's: the error table, the full-resolution
            // bits, the occlusion state, and the frame block again as a
            // read-only storage buffer. A driver may specialise a shader
            // on the uniform-buffer values its branches test: lavapipe
            // (Mesa 22.3) does so whenever that removes half a shader's
            // code, again at every bind, and keeps each compile until the
            // device goes. The control shader's LOD-metric branches are
            // most of its code, so it was compiled once more every
            // tessellated frame, about 1 MB of resident memory a frame
            // (benches/notes.md, section 9). Storage-buffer values are
            // not specialised on. The other stages keep the uniform
            // buffer: bound as a storage buffer in every stage, lavapipe
            // drew textured scenes with their textures blurred away
            // (the material tests' golden images and triplanar scale).
            for binding in [
                BINDING_ERROR_TABLE,
                BINDING_FULL_RESOLUTION,
                BINDING_VISIBILITY,
                BINDING_FRAME_STORAGE,
            ] {
                plan.bindings.push((
                    binding,
                    vk::DescriptorType::STORAGE_BUFFER,
                    vk::ShaderStageFlags::TESSELLATION_CONTROL,
                ));
            }
            plan.pool_sizes
                .push((vk::DescriptorType::STORAGE_BUFFER, 4));
        }
        let vertex_stages = stages & !vk::ShaderStageFlags::FRAGMENT;
        for binding in appearance.bindings(vertex_stages) {
            plan.pool_sizes.push((binding.1, 1));
            plan.bindings.push(binding);
        }
        plan
    }
}
