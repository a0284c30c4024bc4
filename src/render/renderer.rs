//! The terrain renderer. It shares one heightmap image, descriptor set
//! layout and per-frame uniforms between the render paths, and builds the
//! geometry and pipelines of only the paths asked for:
//!
//! - **tess**: patches of four control points; factors and culling in the
//!   control shader, displacement in the evaluation shader. With the error
//!   LOD, patches that need the data's full resolution are chosen on the
//!   CPU each frame and drawn with the reference's own triangles (the geomip
//!   path's level 0), and the control shader gives every edge they share a
//!   vertex on every sample, so the two meet exactly.
//! - **geomip**: geomipmapping for devices without tessellation: one
//!   vertex template and one index list per level and stitched-side mask,
//!   shared by every patch; levels chosen on the CPU each frame, patches
//!   drawn with their level in push constants, geomorphing in the vertex
//!   shader (see `lod::geomip`).
//! - **brute**: every sample a vertex, with `height_at`'s triangle split and
//!   no buffers at all (the vertex shader derives each sample from its
//!   index); the reference that error is measured against.
//!
//! The tess and geomip paths cull hidden patches with a depth pyramid, in
//! two passes per frame (see `occlusion`), where the device can read its
//! depth attachments and the frame's settings ask for it.
//!
//! A tiled terrain can be streamed instead of uploaded whole (see
//! `streaming`): the heightmap binding then holds a one-texel stand-in, and
//! every path reads heights from the page pool through the page table.

use std::mem::size_of;
use std::sync::Arc;
use std::time::Instant;

use ash::vk;

use super::material::{GpuAppearance, ShaderVariant};
use super::occlusion::{ListedDraw, Occlusion, DRAW_COMMAND_BYTES};
use super::residency::StreamShape;
use super::settings::{ErrorMeasure, LodMetric, RenderPath, RenderSettings};
use super::shaders;
use super::streaming::{NoStream, StreamConfig, StreamStats, Streamer};
use super::tess_choice::{patch_batches, ChoiceBuffers};
use super::uniforms::FrameUniforms;
use super::view::FrameView;
use crate::lod::geomip;
use crate::lod::hierarchy::Hierarchy;
use crate::lod::plan::{patches_in_view, plan, FramePlan, PlanInputs};
use crate::lod::view::Tau;
use crate::lod::view_measure::{view_error_table, Diagonal, ViewErrors, ViewLod};
use crate::material::Appearance;
use crate::shader_constants::{
    BINDING_ERROR_TABLE, BINDING_FRAME, BINDING_FULL_RESOLUTION, BINDING_HEIGHTMAP, BINDING_PAGES,
    BINDING_PAGE_TABLE, BINDING_VISIBILITY, OCCLUSION_PHASE_ALL, OCCLUSION_PHASE_CULLED,
    OCCLUSION_PHASE_FIRST, OCCLUSION_PHASE_SECOND,
};
use crate::shader_variants::{Placing, Shader};
use crate::terrain::tiled::TiledHeightmap;
use crate::terrain::{ErrorTable, Terrain, TerrainInfo};
use crate::vk::commands::{Recorder, RenderingPart};
use crate::vk::descriptors::{DescriptorSet, DescriptorSets};
use crate::vk::memory::{Buffer, Image};
use crate::vk::owned::{DescriptorSetLayout, Pipeline, PipelineLayout, Sampler};
use crate::vk::pipeline::GraphicsPipelineDesc;
use crate::vk::queries::{FrameQueries, PipelineStatistics, COUNTED_PARTS};
use crate::vk::target::{TargetViews, DEPTH_FORMAT};
use crate::vk::{sample_count_flag, Device, Gpu, Result, VkError};

/// Per-frame-in-flight resources: the uniform block is rewritten each frame,
/// so a frame still on the GPU keeps its own.
struct FrameSlot {
    uniforms: Buffer,
    set: DescriptorSet,
    queries: FrameQueries,
    /// The tess path's error LOD: the buffers its control shader reads
    /// the frame plan from.
    choice: Option<ChoiceBuffers>,
    /// Draws of the choice's merged node indices, (first index, index
    /// count), split where the driver limits patches per draw.
    merged_batches: Vec<(u32, u32)>,
    /// What `prepare` set this slot's frame up for; `record` draws it.
    settings: Option<RenderSettings>,
    /// Whether the slot's last recorded frame was drawn in two passes
    /// with occlusion culling between them.
    culled: bool,
    /// The tess path's draws this frame, (first index, index count): the
    /// runs of patches the CPU's frustum test keeps (and the error LOD
    /// does not draw at full resolution), split where the driver limits
    /// patches per draw.
    tess_batches: Vec<(u32, u32)>,
}

/// What a renderer builds up front. A frame asking for anything else
/// (another path, line pipelines) has it built by `prepare`, so the
/// settings of a frame and the renderer cannot disagree.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RendererOptions {
    pub paths: Vec<RenderPath>,
    /// Also build line pipelines (needs fillModeNonSolid).
    pub wireframe: bool,
    /// Samples per pixel of the targets it draws into (see
    /// `settings::sample_count`).
    pub samples: u32,
    /// Stream heights from a tiled terrain file instead of uploading the
    /// terrain's heightmap whole (see `streaming`). The terrain's Y bounds
    /// must allow for the base level (`Terrain::widen_y_bounds_to_blocks`).
    pub stream: Option<StreamConfig>,
}

impl RendererOptions {
    /// Fill pipelines of `paths`, one sample per pixel.
    pub fn single_sample(paths: Vec<RenderPath>) -> Self {
        RendererOptions {
            paths,
            wireframe: false,
            samples: 1,
            stream: None,
        }
    }
}

/// Fill and (when asked for) wireframe pipelines of one path.
struct PathPipelines {
    fill: Pipeline,
    wireframe: Option<Pipeline>,
}

impl PathPipelines {
    fn select(&self, wireframe: bool) -> Result<&Pipeline> {
        if !wireframe {
            return Ok(&self.fill);
        }
        self.wireframe.as_ref().ok_or_else(|| {
            VkError::Unsupported("the wireframe pipeline was not built for this renderer".into())
        })
    }
}

struct TessGeometry {
    control_points: Buffer,
    indices: Buffer,
    /// Fractional even spacing, for the distance LOD.
    pipelines: PathPipelines,
    /// Equal spacing, for the error LOD's whole factors.
    error_pipelines: PathPipelines,
    /// Per-patch errors, for choosing the full-resolution patches.
    errors: ErrorTable,
    /// This frame's visible full-resolution patches (error LOD), drawn
    /// with the geomip path's level 0.
    exact: Vec<GeomipDraw>,
}

struct GeomipGeometry {
    template: Buffer,
    indices: Buffer,
    variants: Vec<(u32, u32)>,
    /// (first index, count) of the unstitched full-resolution list of each
    /// patch size (cells x, z) the grid has: remainder patches at the far
    /// edges draw only their own cells.
    full_resolution: Vec<([usize; 2], (u32, u32))>,
    pipelines: PathPipelines,
    /// The shared layout plus the per-patch push constants.
    layout: PipelineLayout,
    /// This frame's visible patches.
    draws: Vec<GeomipDraw>,
    /// Per-patch errors of each level, for choosing levels by projected error.
    errors: ErrorTable,
    /// Levels set from outside (`set_geomip_levels`) instead of chosen,
    /// balanced, with no morph.
    given: Option<geomip::PatchLevels>,
}

/// The show-culled overlay's pipelines: the tess path's stages with a
/// one-colour fragment shader, no depth test, lines where the device has
/// them; fractional even and equal spacing.
struct CulledPipelines {
    fractional: Pipeline,
    equal: Pipeline,
}

/// One patch of the geomip path: its index list and push constants.
#[derive(Clone, Copy, Debug)]
struct GeomipDraw {
    /// The patch's index in the grid.
    patch: u32,
    first: u32,
    count: u32,
    constants: GeomipConstants,
}

/// Push constants of glsl/geomip.vert.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GeomipConstants {
    pub origin: [i32; 2],
    pub level: i32,
    pub interior: f32,
    pub sides: [f32; 4],
}
const _: () = assert!(size_of::<GeomipConstants>() == 32);
const _: () = assert!(std::mem::offset_of!(GeomipConstants, sides) == 16);

struct BruteGeometry {
    vertex_count: u32,
    pipelines: PathPipelines,
}

/// Draws a terrain into any target, by the paths it was built for. Its
/// Vulkan objects free themselves; dropping it first waits for the device
/// to go idle, so no submitted frame still uses them. Fields drop in
/// declaration order: the users of the descriptor sets and layouts before
/// them.
pub struct TerrainRenderer {
    frames: Vec<FrameSlot>,
    tess: Option<TessGeometry>,
    geomip: Option<GeomipGeometry>,
    brute: Option<BruteGeometry>,
    /// The patches' occlusion state and culling.
    occlusion: Occlusion,
    /// Built when a frame first shows culled patches.
    culled_pipelines: Option<CulledPipelines>,
    /// Where the frames' sets come from.
    _sets: DescriptorSets,
    pipeline_layout: PipelineLayout,
    set_layout: DescriptorSetLayout,
    /// Read through the frames' sets: the heightmap (a one-texel stand-in
    /// for a streamed terrain, whose heights are in its page pool).
    _heightmap: Image,
    /// Heights streamed from a tiled terrain; with none, a one-layer pool
    /// and an empty page table stand in its bindings.
    streamer: Option<Streamer>,
    _no_stream: Option<NoStream>,
    sampler: Sampler,
    /// Material layers, blend maps and lightmap, as the scene needs.
    appearance: GpuAppearance,
    device: Device,
    color_format: vk::Format,
    samples: vk::SampleCountFlags,
    /// The sky, drawn where the terrain left the far plane.
    sky: Pipeline,
    max_patches_per_draw: Option<u32>,
    /// Milliseconds spent computing the error table in `new` (0 when no
    /// path needs it).
    error_table_ms: f64,
    /// The largest error the last prepared frame's LOD choice expects on
    /// screen, in pixels (error LOD only).
    predicted_max_px: Option<f32>,
    /// The frame's 99th percentile error the last prepared frame's LOD
    /// choice expects, in pixels (error LOD, where the view measured it).
    predicted_p99_px: Option<f32>,
    /// Merged nodes the last prepared frame draws (tess path, error LOD).
    merged_nodes: usize,
    /// The quadtree the level choices walk, built with the first path
    /// that draws patches.
    hierarchy: Option<Hierarchy>,
    /// Milliseconds the last prepared frame's level choice took (the tess
    /// path's frame plan, or the geomip path's levels), the view measure
    /// included where it runs.
    lod_ms: Option<f64>,
    /// Patches in view in the last prepared frame (`patches_in_view`).
    patches_in_view: usize,
}

/// What one frame's queries measured; None where the device can't tell.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameMeasurements {
    pub gpu_ms: Option<f64>,
    pub statistics: Option<PipelineStatistics>,
    /// What occlusion culling did, for a frame drawn with it.
    pub occlusion: Option<OcclusionMeasurements>,
}

/// One frame's occlusion culling.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OcclusionMeasurements {
    /// Patches in the view that the test found hidden and nothing drew.
    pub patches_occluded: u32,
    /// GPU milliseconds of building the pyramid and testing the patches.
    pub culling_ms: Option<f64>,
}

impl TerrainRenderer {
    /// Uploads the terrain and builds the pipelines of `options.paths` for
    /// targets of `color_format`, coloured by height.
    pub fn new(
        gpu: &Gpu,
        terrain: &Terrain,
        color_format: vk::Format,
        frames_in_flight: u32,
        options: &RendererOptions,
    ) -> Result<Self> {
        Self::with_appearance(
            gpu,
            terrain,
            &Appearance::default(),
            color_format,
            frames_in_flight,
            options,
        )
    }

    /// Like `new`, drawn with a scene's material layers and lightmap. The
    /// terrain's Y bounds must already allow for the material's
    /// displacement (`Appearance::y_margin`).
    pub fn with_appearance(
        gpu: &Gpu,
        terrain: &Terrain,
        appearance: &Appearance,
        color_format: vk::Format,
        frames_in_flight: u32,
        options: &RendererOptions,
    ) -> Result<Self> {
        let device = &gpu.device;
        check_device(device, terrain, options)?;
        let samples = sample_count_flag(options.samples);
        let info = terrain.info();
        // A streamed terrain's heights, its base level included, are in
        // the page pool, made after the paths (which count against the
        // memory budget first).
        let heightmap = match options.stream {
            None => upload_heightmap(device, info, "terrain.heightmap")?,
            Some(_) => device.upload_r32f_image("terrain.heightmap.placeholder", 1, 1, &[0.0])?,
        };
        let sampler = device.create_nearest_sampler("terrain.heightmap_sampler")?;
        let mut appearance = GpuAppearance::new(device, appearance, info)?;
        let tiled = match &options.stream {
            Some(config) => Some(open_streamed(info, config)?),
            None => None,
        };
        appearance.variant.stream = options
            .stream
            .as_ref()
            .zip(tiled.as_deref())
            .map(|(config, tiled)| config.shape(tiled));
        // With tessellation the layout has the tess path's bindings, so the
        // path can be built later (`ensure`) on the same sets.
        let layout = DescriptorPlan::new(device.caps.tessellation_shader, &appearance);
        let set_layout =
            device.create_descriptor_set_layout(&layout.bindings, "terrain.set_layout")?;
        // The tess path's control shader takes the draw's occlusion phase.
        let pipeline_layout = device.create_pipeline_layout_with_push(
            &[&set_layout],
            vk::ShaderStageFlags::TESSELLATION_CONTROL,
            if device.caps.tessellation_shader {
                size_of::<u32>() as u32
            } else {
                0
            },
            "terrain.pipeline_layout",
        )?;
        let sets = device.allocate_descriptor_sets(
            &set_layout,
            &layout.pool_sizes,
            frames_in_flight,
            "terrain.frame_set",
        )?;
        let sky = create_sky_pipeline(device, &pipeline_layout, color_format, samples)?;
        let frames = build_frames(device, &sets, (&heightmap, &sampler), &appearance)?;
        let no_stream = NoStream::new(device, "terrain.stream")?;
        for frame in &frames {
            no_stream.write_bindings(device, frame.set, &sampler);
        }
        let uniforms: Vec<&Buffer> = frames.iter().map(|f| &f.uniforms).collect();
        let occlusion = Occlusion::new(
            device,
            terrain,
            &uniforms,
            device.caps.supports_occlusion(options.samples),
        )?;
        let mut renderer = TerrainRenderer {
            frames,
            tess: None,
            geomip: None,
            brute: None,
            occlusion,
            culled_pipelines: None,
            _sets: sets,
            pipeline_layout,
            set_layout,
            _heightmap: heightmap,
            streamer: None,
            _no_stream: Some(no_stream),
            sampler,
            appearance,
            sky,
            device: device.clone(),
            color_format,
            samples,
            max_patches_per_draw: device.workarounds.max_patches_per_draw,
            error_table_ms: 0.0,
            predicted_max_px: None,
            predicted_p99_px: None,
            merged_nodes: 0,
            lod_ms: None,
            patches_in_view: 0,
            hierarchy: None,
        };
        for &path in &options.paths {
            renderer.ensure(terrain, path, options.wireframe)?;
        }
        if let (Some(config), Some(tiled)) = (&options.stream, tiled) {
            let streamer = Streamer::new(device, info, config, tiled, renderer.frames.len())?;
            for (slot, frame) in renderer.frames.iter().enumerate() {
                streamer.write_bindings(frame.set, slot, &renderer.sampler);
            }
            renderer.streamer = Some(streamer);
            renderer._no_stream = None;
        }
        Ok(renderer)
    }

    /// What streaming did in the last prepared frame; None for a terrain
    /// uploaded whole.
    pub fn stream_stats(&self) -> Option<StreamStats> {
        self.streamer.as_ref().map(Streamer::stats)
    }

    /// How a streamed terrain streams: its tiles, pages and base level.
    pub fn stream_shape(&self) -> Option<StreamShape> {
        self.streamer.as_ref().map(Streamer::shape)
    }

    /// A streamed terrain's page table as the next frame will draw with
    /// it: per tile, the page it is drawn from (`residency::page_entry`),
    /// its base page where no finer one is resident.
    pub fn stream_page_table(&self) -> Option<&[u32]> {
        self.streamer.as_ref().map(Streamer::page_table)
    }

    /// Pages evicted from the pool since the start (streamed terrains).
    pub fn stream_evictions(&self) -> Option<u64> {
        self.streamer.as_ref().map(Streamer::evictions)
    }

    /// For a streamed terrain, reads and uploads what `view` needs until
    /// it is resident (or the pool holds what helps most), waiting on the
    /// disk: what a one-shot render does before it draws. Slot `slot` must
    /// be idle. Returns the tiles uploaded (0 for a terrain uploaded whole).
    pub fn settle(&mut self, slot: usize, view: &FrameView) -> Result<u32> {
        match self.streamer.as_mut() {
            Some(streamer) => streamer.settle(slot, view),
            None => Ok(0),
        }
    }

    /// Builds what drawing `path` (with line pipelines when `wireframe`)
    /// needs and this renderer lacks: the path's geometry and pipelines,
    /// and for the tess path the error table, the full-resolution bits and
    /// the geomip path's level 0. A no-op when all is there. Building
    /// rewrites descriptor sets, so it first waits for the GPU.
    fn ensure(&mut self, terrain: &Terrain, path: RenderPath, wireframe: bool) -> Result<()> {
        // The tess path draws its full-resolution patches with geomip's
        // level 0.
        let needed: &[RenderPath] = match path {
            RenderPath::Tess => &[RenderPath::Tess, RenderPath::Geomip],
            RenderPath::Geomip => &[RenderPath::Geomip],
            RenderPath::Brute => &[RenderPath::Brute],
        };
        if needed.iter().all(|&p| self.has(p, wireframe)) {
            return Ok(());
        }
        check_path(&self.device, terrain, path, wireframe)?;
        self.device.wait_idle()?;
        for &p in needed {
            if !self.has(p, wireframe) {
                self.build(terrain, p, wireframe)?;
            }
        }
        Ok(())
    }

    /// The pipelines of `path` when it is built (the tess path's two sets
    /// are always built together, with or without lines).
    fn path_pipelines(&self, path: RenderPath) -> Option<&PathPipelines> {
        match path {
            RenderPath::Tess => self.tess.as_ref().map(|t| &t.pipelines),
            RenderPath::Geomip => self.geomip.as_ref().map(|g| &g.pipelines),
            RenderPath::Brute => self.brute.as_ref().map(|b| &b.pipelines),
        }
    }

    /// Whether `path` is built, with line pipelines when `wireframe`.
    fn has(&self, path: RenderPath, wireframe: bool) -> bool {
        self.path_pipelines(path)
            .is_some_and(|p| !wireframe || p.wireframe.is_some())
    }

    /// Builds `path` (again, with line pipelines, when it lacks them).
    fn build(&mut self, terrain: &Terrain, path: RenderPath, wireframe: bool) -> Result<()> {
        // A path built before keeps its line pipelines.
        let wireframe = wireframe || self.has(path, true);
        match path {
            RenderPath::Tess => {
                // The tess path's error-bounded factors read the per-patch
                // error table (ERROR_LEVEL_COUNT floats a patch); the geomip
                // path's error LOD has its own, for its fixed diagonal.
                // Both come from one pass, kept by the terrain.
                let (table, _) = self.error_tables(terrain);
                self.hierarchy
                    .get_or_insert_with(|| Hierarchy::new(terrain, table));
                if self.frames.iter().any(|f| f.choice.is_none()) {
                    self.add_error_lod_buffers(terrain, table)?;
                }
                self.tess = Some(build_tess(self, terrain, table.clone(), wireframe)?);
            }
            RenderPath::Geomip => {
                let (tess_table, table) = self.error_tables(terrain);
                self.hierarchy
                    .get_or_insert_with(|| Hierarchy::new(terrain, tess_table));
                self.geomip = Some(build_geomip(self, terrain, table.clone(), wireframe)?);
            }
            RenderPath::Brute => {
                self.brute = Some(BruteGeometry {
                    vertex_count: brute_vertex_count(terrain) as u32,
                    pipelines: build_pipelines(
                        self,
                        &self.pipeline_layout,
                        (RenderPath::Brute, false),
                        wireframe,
                    )?,
                });
            }
        }
        Ok(())
    }

    /// The terrain's error tables; the first call's time is kept for
    /// `error_table_ms`.
    fn error_tables<'t>(&mut self, terrain: &'t Terrain) -> &'t (ErrorTable, ErrorTable) {
        let start = std::time::Instant::now();
        let tables = terrain.error_tables();
        if self.error_table_ms == 0.0 {
            self.error_table_ms = start.elapsed().as_secs_f64() * 1e3;
        }
        tables
    }

    /// Per frame slot, the tess path's choice buffers (starting as
    /// `table`), and the slot's set pointed at them and the occlusion
    /// state (the bindings of the tess path's control shader).
    fn add_error_lod_buffers(&mut self, terrain: &Terrain, table: &ErrorTable) -> Result<()> {
        for (i, frame) in self.frames.iter_mut().enumerate() {
            frame.choice = Some(ChoiceBuffers::new(
                &self.device,
                i,
                terrain,
                table,
                frame.set,
                &self.occlusion.visibility,
            )?);
        }
        Ok(())
    }

    /// Milliseconds `new` spent computing the per-patch error table.
    pub fn error_table_ms(&self) -> f64 {
        self.error_table_ms
    }

    pub fn color_format(&self) -> vk::Format {
        self.color_format
    }

    /// Samples per pixel of the targets this renderer draws into.
    pub fn samples(&self) -> u32 {
        self.samples.as_raw()
    }

    /// Sets frame slot `slot` up for a frame of `settings` (its previous
    /// frame must have completed): builds the path if this renderer lacks
    /// it, writes the uniforms and, for the geomip path and the tess
    /// path's error LOD, chooses this frame's patch levels. `record` then
    /// draws exactly this.
    pub fn prepare(
        &mut self,
        slot: usize,
        terrain: &Terrain,
        view: &FrameView,
        settings: &RenderSettings,
    ) -> Result<()> {
        self.ensure(terrain, settings.path, settings.wireframe)?;
        if settings.show_culled && self.culled_pipelines.is_none() && self.tess.is_some() {
            self.culled_pipelines = Some(CulledPipelines {
                fractional: create_culled_pipeline(self, false)?,
                equal: create_culled_pipeline(self, true)?,
            });
        }
        self.frames[slot].settings = Some(*settings);
        if let Some(streamer) = self.streamer.as_mut() {
            streamer.prepare(slot, view)?;
        }
        let uniforms = FrameUniforms::new(terrain, view, settings);
        self.frames[slot]
            .uniforms
            .mapped_mut()
            .ok_or_else(|| VkError::Unsupported("uniform memory is not host-mapped".into()))?
            .copy_from_slice(bytemuck::bytes_of(&uniforms));
        self.predicted_max_px = None;
        self.predicted_p99_px = None;
        self.merged_nodes = 0;
        self.lod_ms = None;
        self.frames[slot].tess_batches.clear();
        self.frames[slot].merged_batches.clear();
        if let Some(tess) = self.tess.as_mut() {
            tess.exact.clear();
        }
        match (settings.path, settings.lod_metric) {
            (RenderPath::Geomip, _) => {
                if let (Some(geomip), Some(hierarchy)) =
                    (self.geomip.as_mut(), self.hierarchy.as_ref())
                {
                    if let (LodMetric::Error(_), ErrorMeasure::Sight) =
                        (settings.lod_metric, settings.error_measure)
                    {
                        // Computed once per terrain, before the choice is
                        // timed.
                        terrain.sight_table();
                    }
                    let start = Instant::now();
                    let predicted = geomip.choose(terrain, hierarchy, view, settings);
                    self.lod_ms = Some(start.elapsed().as_secs_f64() * 1e3);
                    self.predicted_max_px = predicted.map(|p| p.0);
                    self.predicted_p99_px = predicted.and_then(|p| p.1);
                    self.patches_in_view = geomip.draws.len();
                }
            }
            (RenderPath::Tess, LodMetric::Error(pixels)) => {
                self.prepare_tess_error(slot, terrain, view, settings, pixels)?;
            }
            (RenderPath::Tess, _) => {
                let hierarchy = self
                    .hierarchy
                    .as_ref()
                    .ok_or_else(|| VkError::Unsupported("the tess path was not built".into()))?;
                let start = Instant::now();
                let lod_view = view.lod_view(Tau::DEFAULT);
                let (visible, _) = patches_in_view(terrain, hierarchy, &lod_view, settings.cull);
                self.lod_ms = Some(start.elapsed().as_secs_f64() * 1e3);
                self.patches_in_view = visible.len();
                self.frames[slot].tess_batches = patch_batches(visible, self.max_patches_per_draw);
            }
            (RenderPath::Brute, _) => self.patches_in_view = terrain.grid().patch_count(),
        }
        Ok(())
    }

    /// The tess path's error LOD for slot `slot`: the frame plan (with the
    /// view's measured table under `ErrorMeasure::View`), written into the
    /// slot's choice buffers, and the frame's draws.
    fn prepare_tess_error(
        &mut self,
        slot: usize,
        terrain: &Terrain,
        view: &FrameView,
        settings: &RenderSettings,
        pixels: f32,
    ) -> Result<()> {
        let (Some(tess), Some(hierarchy)) = (self.tess.as_mut(), self.hierarchy.as_ref()) else {
            return Err(VkError::Unsupported("the tess path was not built".into()));
        };
        let sight = match settings.error_measure {
            // Computed once per terrain, before the choice is timed.
            ErrorMeasure::Sight => terrain.sight_table(),
            _ => None,
        };
        let start = Instant::now();
        let seen = match settings.error_measure {
            ErrorMeasure::View => {
                let drawn = view.patches_drawn(terrain, settings.cull);
                seen_errors(
                    terrain,
                    &tess.errors,
                    Diagonal::Either,
                    view,
                    (settings, pixels),
                    &drawn,
                )
            }
            _ => None,
        };
        let lod_view = view.lod_view(Tau::new(pixels).unwrap_or_default());
        let frame_plan = plan(
            terrain,
            hierarchy,
            &lod_view,
            &PlanInputs {
                table: seen.as_ref().map_or(&tess.errors, |s| &s.table),
                sight,
                merge: settings.merge_patches,
                cull: settings.cull,
            },
        );
        self.lod_ms = Some(start.elapsed().as_secs_f64() * 1e3);
        let frame = &mut self.frames[slot];
        let choice = frame.choice.as_mut().ok_or_else(|| {
            VkError::Unsupported("the tess path's error LOD was not built".into())
        })?;
        let merged_indices = choice.write(&frame_plan, &tess.errors, terrain)?;
        frame.merged_batches = patch_batches(0..merged_indices / 4, self.max_patches_per_draw);
        let geomip = self.geomip.as_ref().ok_or_else(|| {
            VkError::Unsupported("the tess path's exact draws need geomip".into())
        })?;
        tess.set_exact_draws(terrain, &frame_plan, geomip);
        frame.tess_batches = patch_batches(
            frame_plan
                .patches
                .iter()
                .filter(|p| !p.full_resolution)
                .map(|p| p.index),
            self.max_patches_per_draw,
        );
        self.predicted_max_px = Some(
            seen.as_ref()
                .map_or(frame_plan.predicted_max_px, |s| s.predicted_max_px),
        );
        self.predicted_p99_px = seen.map(|s| s.predicted_p99_px);
        self.merged_nodes = frame_plan.merged.len();
        self.patches_in_view = frame_plan.patches.len()
            + frame_plan
                .merged
                .iter()
                .map(|n| (n.span() * n.span()) as usize)
                .sum::<usize>();
        Ok(())
    }

    /// The largest error the last prepared frame's level choice expects on
    /// screen, in pixels: over the patches in view, each one's error bound
    /// at its level seen from its nearest point (0 where drawn at full
    /// resolution). None for the distance LOD and the brute path.
    pub fn predicted_max_px(&self) -> Option<f32> {
        self.predicted_max_px
    }

    /// The frame's 99th percentile error the last prepared frame's level
    /// choice expects on screen, in pixels, where the view measured it
    /// (`lod::view_measure`): None for the distance LOD, the brute path
    /// and streamed terrains.
    pub fn predicted_p99_px(&self) -> Option<f32> {
        self.predicted_p99_px
    }

    /// Milliseconds the last prepared frame spent choosing its levels: the
    /// frame plan of the tess path (its frustum walk alone for the distance
    /// and peer policies), the geomip path's levels, the view measure
    /// where it runs. None for the brute path.
    pub fn lod_ms(&self) -> Option<f64> {
        self.lod_ms
    }

    /// How many patches the last prepared frame found in view (all of them
    /// for the brute path): drawn on their own or in merged nodes.
    pub fn patches_in_view(&self) -> usize {
        self.patches_in_view
    }

    /// How many merged nodes (`lod::patch_merge`) the last prepared
    /// frame of the tess path's error LOD draws, each instead of its block
    /// of patches (0 on other paths).
    pub fn merged_nodes(&self) -> usize {
        self.merged_nodes
    }

    /// How many patches in view the last prepared frame of the tess
    /// path's error LOD draws at full resolution, with the reference's
    /// own triangles instead of the control shader (0 on other paths).
    pub fn full_resolution_patches(&self) -> usize {
        self.tess.as_ref().map_or(0, |tess| tess.exact.len())
    }

    /// Makes the geomip path draw every patch at the given level (one per
    /// patch, in patch order), without geomorphing, instead of choosing
    /// levels; `None` goes back to choosing. Levels are balanced first, so
    /// the stitched sides still meet. This is how the benchmark's oracle
    /// draws its per-patch levels.
    pub fn set_geomip_levels(&mut self, terrain: &Terrain, levels: Option<&[u8]>) -> Result<()> {
        self.ensure(terrain, RenderPath::Geomip, false)?;
        let geomip = self.geomip.as_mut().ok_or_else(|| {
            VkError::Unsupported("the geomip path was not built for this renderer".into())
        })?;
        let grid = terrain.grid();
        let count = geomip::level_count(grid.cells_per_patch());
        geomip.given = match levels {
            None => None,
            Some(levels) => {
                if levels.len() != grid.patch_count()
                    || levels.iter().any(|&l| usize::from(l) >= count)
                {
                    return Err(VkError::Unsupported(format!(
                        "{} geomip levels given for {} patches of at most {count} levels",
                        levels.len(),
                        grid.patch_count()
                    )));
                }
                let mut levels = levels.to_vec();
                geomip::balance(&mut levels, grid);
                Some(geomip::PatchLevels {
                    morph: vec![0.0; levels.len()],
                    levels,
                })
            }
        };
        Ok(())
    }

    /// Records the frame `prepare` set slot `slot` up for into `target`
    /// (already in attachment layouts), timed and counted by the slot's
    /// queries: in one pass, or with occlusion culling in two.
    pub fn record(&mut self, rec: &Recorder, slot: usize, target: &TargetViews) -> Result<()> {
        let settings = self.frames[slot].settings.ok_or_else(|| {
            VkError::Unsupported(format!(
                "frame slot {slot} was recorded before it was prepared"
            ))
        })?;
        if target.samples != self.samples || target.color_format != self.color_format {
            return Err(VkError::Unsupported(format!(
                "a target of {:?} with {:?} samples per pixel, for a renderer built for {:?} with {:?}",
                target.color_format, target.samples, self.color_format, self.samples
            )));
        }
        let mut cull = settings.occlusion
            && settings.path != RenderPath::Brute
            && target.depth_readable
            && self.occlusion.can_cull();
        if cull {
            // Every draw is indirect (the geomip path's patches, the tess
            // path's batches and its full-resolution patches), each pass
            // drawing those that hold a patch the occlusion state keeps.
            let patch_draws = |draws: &[GeomipDraw]| -> Vec<ListedDraw> {
                draws
                    .iter()
                    .map(|d| ListedDraw {
                        patches: [d.patch, 1],
                        first_index: d.first,
                        index_count: d.count,
                    })
                    .collect()
            };
            let commands: Vec<ListedDraw> = match (settings.path, &self.tess, &self.geomip) {
                (RenderPath::Geomip, _, Some(g)) => patch_draws(&g.draws),
                (RenderPath::Tess, Some(t), _) => {
                    // Four indices per patch.
                    let mut list: Vec<ListedDraw> = self.frames[slot]
                        .tess_batches
                        .iter()
                        .map(|&(first, count)| ListedDraw {
                            patches: [first / 4, count / 4],
                            first_index: first,
                            index_count: count,
                        })
                        .collect();
                    if matches!(settings.lod_metric, LodMetric::Error(_)) {
                        list.extend(patch_draws(&t.exact));
                    }
                    list
                }
                _ => Vec::new(),
            };
            // A frame of more draws than the lists hold is drawn in one
            // pass; culling is conservative, so the next frame's first
            // pass may start from an older visible set.
            if commands.len() > self.occlusion.list_capacity() {
                cull = false;
            } else {
                self.occlusion
                    .prepare_target(&self.device, slot, target, &self.sampler)?;
                self.occlusion.write_draws(slot, &commands)?;
            }
        }
        self.frames[slot].culled = cull;
        let frame = &self.frames[slot];
        let clear_color = settings.clear_color;
        frame.queries.reset(rec);
        frame.queries.begin_timing(rec);
        if let Some(streamer) = &self.streamer {
            streamer.record(rec, slot);
        }
        if cull {
            let occlusion = &self.occlusion;
            occlusion.record_start(rec, slot)?;
            rec.begin_rendering(target, RenderingPart::First { clear_color });
            frame.queries.begin_counting(rec, 0);
            self.draw_terrain(rec, slot, &settings, OCCLUSION_PHASE_FIRST)?;
            frame.queries.end_counting(rec, 0);
            rec.end_rendering();
            // The marks come before barriers: lavapipe takes a timestamp
            // when it next flushes, and a barrier flushes.
            frame.queries.mark_span_start(rec);
            occlusion.record_cull(rec, slot, target)?;
            frame.queries.mark_span_end(rec);
            occlusion.record_resume(rec, target);
            rec.begin_rendering(target, RenderingPart::Last);
            frame.queries.begin_counting(rec, 1);
            self.draw_terrain(rec, slot, &settings, OCCLUSION_PHASE_SECOND)?;
            frame.queries.end_counting(rec, 1);
            if settings.show_culled {
                self.draw_culled(rec, frame, &settings)?;
            }
        } else {
            rec.begin_rendering(target, RenderingPart::Whole { clear_color });
            frame.queries.begin_counting(rec, 0);
            self.draw_terrain(rec, slot, &settings, OCCLUSION_PHASE_ALL)?;
            frame.queries.end_counting(rec, 0);
        }
        // The sky is timed with the terrain but not counted: the frame's
        // triangle counts stay the terrain's.
        if settings.sky {
            rec.bind_graphics(&self.sky, &self.pipeline_layout, frame.set);
            rec.draw(3);
        }
        frame.queries.end_timing(rec);
        rec.end_rendering();
        Ok(())
    }

    /// Draws the patches of `phase` (`OCCLUSION_PHASE_*`) by the frame's
    /// path.
    fn draw_terrain(
        &self,
        rec: &Recorder,
        slot: usize,
        settings: &RenderSettings,
        phase: u32,
    ) -> Result<()> {
        let frame = &self.frames[slot];
        let not_built = || {
            VkError::Unsupported(format!(
                "the {:?} path was not built for this renderer",
                settings.path
            ))
        };
        match settings.path {
            RenderPath::Tess => {
                let tess = self.tess.as_ref().ok_or_else(not_built)?;
                let pipelines = match settings.lod_metric {
                    LodMetric::Error(_) => &tess.error_pipelines,
                    _ => &tess.pipelines,
                };
                let indirect = self.indirect_draws(slot, phase)?;
                let pipeline = pipelines.select(settings.wireframe)?;
                self.draw_patches(rec, frame, (tess, pipeline), phase, indirect);
                // Merged nodes go in the first pass, untested for occlusion.
                if let (Some(choice), OCCLUSION_PHASE_ALL | OCCLUSION_PHASE_FIRST) =
                    (&frame.choice, phase)
                {
                    if !frame.merged_batches.is_empty() {
                        rec.bind_geometry(&tess.control_points, &choice.merged_indices);
                        for &(first, count) in &frame.merged_batches {
                            rec.draw_indexed(first, count);
                        }
                    }
                }
                if matches!(settings.lod_metric, LodMetric::Error(_)) && !tess.exact.is_empty() {
                    let geomip = self.geomip.as_ref().ok_or_else(not_built)?;
                    // Listed after the batches.
                    let batches = frame.tess_batches.len() as u64;
                    let exact = indirect.map(|(commands, base)| (commands, base + batches));
                    geomip.draw(rec, frame.set, settings.wireframe, &tess.exact, exact)?;
                }
            }
            RenderPath::Geomip => {
                let geomip = self.geomip.as_ref().ok_or_else(not_built)?;
                let indirect = self.indirect_draws(slot, phase)?;
                geomip.draw(rec, frame.set, settings.wireframe, &geomip.draws, indirect)?;
            }
            RenderPath::Brute => {
                let brute = self.brute.as_ref().ok_or_else(not_built)?;
                rec.bind_graphics(
                    brute.pipelines.select(settings.wireframe)?,
                    &self.pipeline_layout,
                    frame.set,
                );
                rec.draw(brute.vertex_count);
            }
        }
        Ok(())
    }

    /// Where the CPU-listed draws of `phase` read their commands: none for
    /// a frame drawn in one pass.
    fn indirect_draws(&self, slot: usize, phase: u32) -> Result<Option<(&Buffer, u64)>> {
        if phase == OCCLUSION_PHASE_ALL {
            return Ok(None);
        }
        Ok(Some(self.occlusion.draw_commands(slot, phase)?))
    }

    /// The frame's tess patches through `pipeline`, for `phase`, in the
    /// draws of its `tess_batches`; with `indirect`, draw b reads its
    /// instance count from command `first + b` (see `indirect_draws`).
    fn draw_patches(
        &self,
        rec: &Recorder,
        frame: &FrameSlot,
        (tess, pipeline): (&TessGeometry, &Pipeline),
        phase: u32,
        indirect: Option<(&Buffer, u64)>,
    ) {
        rec.bind_graphics(pipeline, &self.pipeline_layout, frame.set);
        rec.push_constants(
            &self.pipeline_layout,
            vk::ShaderStageFlags::TESSELLATION_CONTROL,
            bytemuck::bytes_of(&phase),
        );
        rec.bind_geometry(&tess.control_points, &tess.indices);
        for (b, &(first, count)) in frame.tess_batches.iter().enumerate() {
            match indirect {
                Some((commands, base)) => {
                    rec.draw_indexed_indirect(commands, (base + b as u64) * DRAW_COMMAND_BYTES)
                }
                None => rec.draw_indexed(first, count),
            }
        }
    }

    /// The tess path's patches that occlusion culled, in one colour over
    /// the frame (the full-resolution patches of the error LOD, drawn
    /// near the eye, are not shown).
    fn draw_culled(
        &self,
        rec: &Recorder,
        frame: &FrameSlot,
        settings: &RenderSettings,
    ) -> Result<()> {
        let (Some(tess), Some(culled)) = (self.tess.as_ref(), self.culled_pipelines.as_ref())
        else {
            return Ok(());
        };
        if settings.path != RenderPath::Tess {
            return Ok(());
        }
        let pipeline = match settings.lod_metric {
            LodMetric::Error(_) => &culled.equal,
            _ => &culled.fractional,
        };
        self.draw_patches(rec, frame, (tess, pipeline), OCCLUSION_PHASE_CULLED, None);
        Ok(())
    }

    /// What slot `slot`'s last frame measured; call after its fence.
    pub fn measurements(&self, slot: usize) -> Result<FrameMeasurements> {
        let frame = &self.frames[slot];
        let occlusion = match frame.culled {
            true => Some(OcclusionMeasurements {
                patches_occluded: self.occlusion.culled(slot)?,
                culling_ms: frame.queries.span_ms()?,
            }),
            false => None,
        };
        let parts = if frame.culled { COUNTED_PARTS } else { 1 };
        Ok(FrameMeasurements {
            gpu_ms: frame.queries.gpu_ms()?,
            statistics: frame.queries.statistics(parts)?,
            occlusion,
        })
    }

    /// The occlusion pyramid slot `slot`'s last culled frame built from its
    /// first pass's depth, every level one after another
    /// (`occlusion::pyramid_levels`); `None` where this renderer does not
    /// cull, or before any culled frame. Call after the slot's fence.
    pub fn occlusion_pyramid(&self, slot: usize) -> Result<Option<Vec<f32>>> {
        self.occlusion.read_pyramid(&self.device, slot)
    }

    /// Whether this renderer can cull hidden patches (the device reads its
    /// depth attachments at the renderer's sample count).
    pub fn can_cull_occluded(&self) -> bool {
        self.occlusion.can_cull()
    }
}

impl Drop for TerrainRenderer {
    fn drop(&mut self) {
        // Submitted frames may still read the buffers, images and
        // pipelines; an error here (device lost) leaves nothing better to
        // do than free them anyway.
        let _ = self.device.wait_idle();
    }
}

/// One uniform block and query set per descriptor set, with the set
/// written (the tess path adds its own bindings when it is built).
fn build_frames(
    device: &Device,
    sets: &DescriptorSets,
    (heightmap, sampler): (&Image, &Sampler),
    appearance: &GpuAppearance,
) -> Result<Vec<FrameSlot>> {
    let mut frames = Vec::new();
    for (i, set) in sets.iter().enumerate() {
        let uniforms = device.create_host_buffer(
            &format!("terrain.frame_uniforms[{i}]"),
            vk::BufferUsageFlags::UNIFORM_BUFFER,
            bytemuck::bytes_of(&FrameUniforms::default()),
        )?;
        let queries = FrameQueries::new(device, &format!("terrain.frame_queries[{i}]"))?;
        write_frame_bindings(device, set, &uniforms, heightmap, sampler);
        appearance.write(device, set);
        frames.push(FrameSlot {
            uniforms,
            set,
            queries,
            choice: None,
            merged_batches: Vec::new(),
            settings: None,
            culled: false,
            tess_batches: Vec::new(),
        });
    }
    Ok(frames)
}

/// Refuses what this device or the draw limits cannot do, before anything
/// is built.
fn check_device(device: &Device, terrain: &Terrain, options: &RendererOptions) -> Result<()> {
    let info = terrain.info();
    let (cols, rows) = (info.cols() as u32, info.rows() as u32);
    let limit = device.caps.max_image_dimension_2d;
    if options.stream.is_none() && (cols > limit || rows > limit) {
        return Err(VkError::Unsupported(format!(
            "heightmap of {cols}x{rows} samples exceeds this device's largest image ({limit}x{limit})"
        )));
    }
    let features = device.format_features(vk::Format::R32_SFLOAT);
    if !features
        .contains(vk::FormatFeatureFlags::SAMPLED_IMAGE | vk::FormatFeatureFlags::TRANSFER_DST)
    {
        return Err(VkError::Unsupported(format!(
            "{} cannot sample R32_SFLOAT images ({features:?})",
            device.caps.device_name
        )));
    }
    device.caps.check_samples(options.samples)?;
    for &path in &options.paths {
        check_path(device, terrain, path, options.wireframe)?;
    }
    Ok(())
}

/// Refuses a path (with line pipelines when `wireframe`) this device or
/// the draw limits cannot do.
fn check_path(device: &Device, terrain: &Terrain, path: RenderPath, wireframe: bool) -> Result<()> {
    let caps = &device.caps;
    if wireframe && !caps.fill_mode_non_solid {
        return Err(VkError::Unsupported(format!(
            "wireframe needs fillModeNonSolid, which {} lacks",
            caps.device_name
        )));
    }
    if path == RenderPath::Tess && !caps.tessellation_shader {
        return Err(VkError::Unsupported(format!(
            "the tess path needs tessellationShader, which {} lacks",
            caps.device_name
        )));
    }
    let brute_vertices = brute_vertex_count(terrain);
    if path == RenderPath::Brute && brute_vertices > i32::MAX as u64 {
        let info = terrain.info();
        return Err(VkError::Unsupported(format!(
            "the brute path draws {brute_vertices} vertices for {}x{} samples, over the {} one draw can address",
            info.cols(),
            info.rows(),
            i32::MAX
        )));
    }
    Ok(())
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

/// The terrain's heights as an R32_SFLOAT image, one texel per sample.
pub(super) fn upload_heightmap(device: &Device, info: &TerrainInfo, name: &str) -> Result<Image> {
    let (cols, rows) = (info.cols() as u32, info.rows() as u32);
    let heightmap = info.heightmap().ok_or_else(|| {
        VkError::Unsupported(
            "a tiled terrain read a tile at a time can only be drawn streamed".into(),
        )
    })?;
    device.upload_r32f_image(name, cols, rows, heightmap.heights())
}

/// The tiled terrain file `config` streams: the one the terrain's CPU
/// model reads already, when it is that file, so its header and directory
/// are read once.
fn open_streamed(info: &TerrainInfo, config: &StreamConfig) -> Result<Arc<TiledHeightmap>> {
    match info.tiled_samples() {
        Some(tiled) if tiled.path() == config.path => Ok(Arc::clone(tiled)),
        _ => TiledHeightmap::open(&config.path)
            .map(Arc::new)
            .map_err(|e| VkError::Stream(e.to_string())),
    }
}

/// Brute draws 6 vertices per cell, counted by a signed index in GLSL.
fn brute_vertex_count(terrain: &Terrain) -> u64 {
    let info = terrain.info();
    6 * (info.cols() as u64 - 1) * (info.rows() as u64 - 1)
}

/// The bindings of the renderer's one descriptor set layout, and what its
/// pool must hold per set: only what the built paths and the scene's
/// material use.
struct DescriptorPlan {
    bindings: Vec<(u32, vk::DescriptorType, vk::ShaderStageFlags)>,
    pool_sizes: Vec<(vk::DescriptorType, u32)>,
}

impl DescriptorPlan {
    fn new(tess: bool, appearance: &GpuAppearance) -> Self {
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
                (vk::DescriptorType::STORAGE_BUFFER, 1),
            ],
        };
        if tess {
            // The control shader's: the error table, the full-resolution
            // bits and the occlusion state.
            for binding in [
                BINDING_ERROR_TABLE,
                BINDING_FULL_RESOLUTION,
                BINDING_VISIBILITY,
            ] {
                plan.bindings.push((
                    binding,
                    vk::DescriptorType::STORAGE_BUFFER,
                    vk::ShaderStageFlags::TESSELLATION_CONTROL,
                ));
            }
            plan.pool_sizes
                .push((vk::DescriptorType::STORAGE_BUFFER, 3));
        }
        let vertex_stages = stages & !vk::ShaderStageFlags::FRAGMENT;
        for binding in appearance.bindings(vertex_stages) {
            plan.pool_sizes.push((binding.1, 1));
            plan.bindings.push(binding);
        }
        plan
    }
}

/// The fill pipeline of `path` on `layout` and, when asked, the wireframe
/// one. `path.1`: the tess path with equal spacing (the error LOD).
fn build_pipelines(
    renderer: &TerrainRenderer,
    layout: &PipelineLayout,
    path: (RenderPath, bool),
    wireframe: bool,
) -> Result<PathPipelines> {
    let variant = &renderer.appearance.variant;
    let create = |mode, suffix| {
        create_pipeline(
            &renderer.device,
            layout,
            (renderer.color_format, renderer.samples),
            variant,
            path,
            mode,
            suffix,
        )
    };
    Ok(PathPipelines {
        fill: create(vk::PolygonMode::FILL, "fill")?,
        wireframe: match wireframe {
            true => Some(create(vk::PolygonMode::LINE, "wireframe")?),
            false => None,
        },
    })
}

fn create_pipeline(
    device: &Device,
    layout: &PipelineLayout,
    (color_format, samples): (vk::Format, vk::SampleCountFlags),
    variant: &ShaderVariant,
    (path, equal_spacing): (RenderPath, bool),
    polygon_mode: vk::PolygonMode,
    suffix: &str,
) -> Result<Pipeline> {
    let frag = shaders::spirv(Shader::TerrainFrag(variant.shading()));
    let placing = variant.placing();
    let (name, stages, topology, patch_control_points, vertex_stride, vertex_attributes): (
        String,
        &[_],
        _,
        _,
        _,
        &[_],
    ) = match path {
        RenderPath::Tess => (
            if equal_spacing {
                format!("terrain.pipeline.tess_error.{suffix}")
            } else {
                format!("terrain.pipeline.tess.{suffix}")
            },
            &tess_stages(placing, equal_spacing, frag),
            vk::PrimitiveTopology::PATCH_LIST,
            4,
            size_of::<[f32; 4]>() as u32,
            &[(0, vk::Format::R32G32B32A32_SFLOAT, 0)],
        ),
        RenderPath::Geomip => (
            format!("terrain.pipeline.geomip.{suffix}"),
            &[
                (
                    vk::ShaderStageFlags::VERTEX,
                    shaders::spirv(Shader::GeomipVert(placing)),
                ),
                (vk::ShaderStageFlags::FRAGMENT, frag),
            ],
            vk::PrimitiveTopology::TRIANGLE_LIST,
            0,
            size_of::<[u16; 2]>() as u32,
            &[(0, vk::Format::R16G16_UINT, 0)],
        ),
        RenderPath::Brute => (
            format!("terrain.pipeline.brute.{suffix}"),
            &[
                (
                    vk::ShaderStageFlags::VERTEX,
                    shaders::spirv(Shader::BruteVert(placing)),
                ),
                (vk::ShaderStageFlags::FRAGMENT, frag),
            ],
            vk::PrimitiveTopology::TRIANGLE_LIST,
            0,
            0,
            &[],
        ),
    };
    device.create_graphics_pipeline(&GraphicsPipelineDesc {
        name: &name,
        stages,
        vertex_stride,
        vertex_attributes,
        topology,
        patch_control_points,
        polygon_mode,
        color_format,
        depth_format: DEPTH_FORMAT,
        // Reversed Z: nearer is larger.
        depth_compare: vk::CompareOp::GREATER,
        depth_write: true,
        samples,
        layout,
        specialization: &variant.specialization(),
    })
}

/// The tess path's stages: the vertex and control shaders, the evaluation
/// shader placing vertices as `placing` with `equal_spacing` or fractional
/// even spacing, and `frag`.
fn tess_stages(
    placing: Placing,
    equal_spacing: bool,
    frag: &'static [u8],
) -> [(vk::ShaderStageFlags, &'static [u8]); 4] {
    [
        (
            vk::ShaderStageFlags::VERTEX,
            shaders::spirv(Shader::TerrainVert),
        ),
        (
            vk::ShaderStageFlags::TESSELLATION_CONTROL,
            shaders::spirv(Shader::TerrainTesc),
        ),
        (
            vk::ShaderStageFlags::TESSELLATION_EVALUATION,
            shaders::spirv(Shader::TerrainTese {
                placing,
                equal_spacing,
            }),
        ),
        (vk::ShaderStageFlags::FRAGMENT, frag),
    ]
}

/// The show-culled overlay's pipeline for the tess path with `equal_spacing`
/// (the error LOD) or fractional even spacing.
fn create_culled_pipeline(renderer: &TerrainRenderer, equal_spacing: bool) -> Result<Pipeline> {
    let device = &renderer.device;
    let spacing = if equal_spacing { "equal" } else { "fractional" };
    device.create_graphics_pipeline(&GraphicsPipelineDesc {
        name: &format!("terrain.pipeline.culled.{spacing}"),
        stages: &tess_stages(
            renderer.appearance.variant.placing(),
            equal_spacing,
            shaders::spirv(Shader::CulledFrag),
        ),
        vertex_stride: size_of::<[f32; 4]>() as u32,
        vertex_attributes: &[(0, vk::Format::R32G32B32A32_SFLOAT, 0)],
        topology: vk::PrimitiveTopology::PATCH_LIST,
        patch_control_points: 4,
        polygon_mode: if device.caps.fill_mode_non_solid {
            vk::PolygonMode::LINE
        } else {
            vk::PolygonMode::FILL
        },
        color_format: renderer.color_format,
        depth_format: DEPTH_FORMAT,
        depth_compare: vk::CompareOp::ALWAYS,
        depth_write: false,
        samples: renderer.samples,
        layout: &renderer.pipeline_layout,
        specialization: &renderer.appearance.variant.specialization(),
    })
}

/// The sky's pipeline: one triangle at the far plane, drawn where the
/// depth is still the cleared far value, writing no depth.
fn create_sky_pipeline(
    device: &Device,
    layout: &PipelineLayout,
    color_format: vk::Format,
    samples: vk::SampleCountFlags,
) -> Result<Pipeline> {
    device.create_graphics_pipeline(&GraphicsPipelineDesc {
        name: "terrain.pipeline.sky",
        stages: &[
            (
                vk::ShaderStageFlags::VERTEX,
                shaders::spirv(Shader::SkyVert),
            ),
            (
                vk::ShaderStageFlags::FRAGMENT,
                shaders::spirv(Shader::SkyFrag),
            ),
        ],
        vertex_stride: 0,
        vertex_attributes: &[],
        topology: vk::PrimitiveTopology::TRIANGLE_LIST,
        patch_control_points: 0,
        polygon_mode: vk::PolygonMode::FILL,
        color_format,
        depth_format: DEPTH_FORMAT,
        depth_compare: vk::CompareOp::GREATER_OR_EQUAL,
        depth_write: false,
        samples,
        layout,
        specialization: &[],
    })
}

fn build_tess(
    renderer: &TerrainRenderer,
    terrain: &Terrain,
    errors: ErrorTable,
    wireframe: bool,
) -> Result<TessGeometry> {
    let device = &renderer.device;
    let layout = &renderer.pipeline_layout;
    Ok(TessGeometry {
        control_points: device.upload_buffer(
            "terrain.control_points",
            vk::BufferUsageFlags::VERTEX_BUFFER,
            bytemuck::cast_slice(terrain.control_points()),
        )?,
        indices: device.upload_buffer(
            "terrain.patch_indices",
            vk::BufferUsageFlags::INDEX_BUFFER,
            bytemuck::cast_slice(terrain.indices()),
        )?,
        pipelines: build_pipelines(renderer, layout, (RenderPath::Tess, false), wireframe)?,
        error_pipelines: build_pipelines(renderer, layout, (RenderPath::Tess, true), wireframe)?,
        errors,
        exact: Vec::new(),
    })
}

fn build_geomip(
    renderer: &TerrainRenderer,
    terrain: &Terrain,
    errors: ErrorTable,
    wireframe: bool,
) -> Result<GeomipGeometry> {
    let device = &renderer.device;
    let n = terrain.grid().cells_per_patch();
    let mut variants = geomip::IndexVariants::build(n);
    let grid = terrain.grid();
    let mut full_resolution: Vec<([usize; 2], (u32, u32))> = Vec::new();
    for p in 0..grid.patch_count() {
        let rect = grid.sample_rect(grid.patch_id(p));
        let cells = [rect.cells_x(), rect.cells_z()];
        if full_resolution.iter().all(|(c, _)| *c != cells) {
            let list = geomip::full_resolution_indices(n, cells);
            let range = (variants.indices.len() as u32, list.len() as u32);
            variants.indices.extend(list);
            full_resolution.push((cells, range));
        }
    }
    let layout = device.create_pipeline_layout_with_push(
        &[&renderer.set_layout],
        vk::ShaderStageFlags::VERTEX,
        size_of::<GeomipConstants>() as u32,
        "terrain.pipeline_layout.geomip",
    )?;
    Ok(GeomipGeometry {
        template: device.upload_buffer(
            "terrain.geomip_vertex_template",
            vk::BufferUsageFlags::VERTEX_BUFFER,
            bytemuck::cast_slice(&geomip::vertex_template(n)),
        )?,
        indices: device.upload_buffer(
            "terrain.geomip_indices",
            vk::BufferUsageFlags::INDEX_BUFFER,
            bytemuck::cast_slice(&variants.indices),
        )?,
        variants: variants.ranges,
        full_resolution,
        pipelines: build_pipelines(renderer, &layout, (RenderPath::Geomip, false), wireframe)?,
        layout,
        draws: Vec::new(),
        errors,
        given: None,
    })
}

impl GeomipGeometry {
    /// Levels by distance or error for the patches in view, balanced; they
    /// become this frame's draws, with their morph factors. Returns the
    /// largest error the error LOD expects on screen, and the 99th
    /// percentile where the view measured it.
    fn choose(
        &mut self,
        terrain: &Terrain,
        hierarchy: &Hierarchy,
        view: &FrameView,
        settings: &RenderSettings,
    ) -> Option<(f32, Option<f32>)> {
        let grid = terrain.grid();
        let count = geomip::level_count(grid.cells_per_patch());
        let tau = match settings.lod_metric {
            LodMetric::Error(pixels) => Some(pixels),
            _ => None,
        };
        let lod_view = view.lod_view(tau.and_then(|t| Tau::new(t).ok()).unwrap_or_default());
        if let Some(chosen) = self.given.take() {
            let (visible, _) = patches_in_view(terrain, hierarchy, &lod_view, settings.cull);
            self.set_draws(terrain, settings, &visible, &chosen);
            self.given = Some(chosen);
            return None;
        }
        if let (Some(pixels), ErrorMeasure::View) = (tau, settings.error_measure) {
            return Some(self.choose_by_view_measure(terrain, view, settings, pixels));
        }
        // Every patch starts at the coarsest level, and those in view get
        // theirs; the coarsest constrains no neighbour.
        let mut levels = vec![(count - 1) as u8; grid.patch_count()];
        let visible: Vec<u32> = match tau {
            None => {
                let (visible, _) = patches_in_view(terrain, hierarchy, &lod_view, settings.cull);
                for &p in &visible {
                    let d = patch_distance(terrain, p as usize, view.eye_local);
                    levels[p as usize] =
                        geomip::level_for_distance(d, settings.lod.min_dist, count) as u8;
                }
                visible
            }
            Some(_) => {
                let sight = match settings.error_measure {
                    ErrorMeasure::Sight => terrain.sight_table(),
                    _ => None,
                };
                let frame_plan = plan(
                    terrain,
                    hierarchy,
                    &lod_view,
                    &PlanInputs {
                        table: &self.errors,
                        sight,
                        merge: false,
                        cull: settings.cull,
                    },
                );
                // Geomip level l has n / 2^l segments a side: the error
                // table's level index log2(n) - l.
                for patch in &frame_plan.patches {
                    let k = usize::from(patch.level).min(count - 1);
                    levels[patch.index as usize] = (count - 1 - k) as u8;
                }
                frame_plan.patches.iter().map(|p| p.index).collect()
            }
        };
        geomip::balance_from(&mut levels, grid, &visible);
        let mut chosen = geomip::PatchLevels {
            morph: vec![0.0; levels.len()],
            levels,
        };
        for &p in &visible {
            let p = p as usize;
            let level = usize::from(chosen.levels[p]);
            if level + 1 >= count {
                continue;
            }
            let d = patch_distance(terrain, p, view.eye_local);
            chosen.morph[p] = match tau {
                None => geomip::morph_factor(d, settings.lod.min_dist, level),
                // The fraction of the way from where the bound accepts this
                // level to where it accepts the next coarser one.
                Some(pixels) => {
                    let threshold = |l: usize| {
                        self.errors.error(p, count - 1 - l) * view.pixels_per_radian
                            / pixels.max(f32::MIN_POSITIVE)
                    };
                    let (from, to) = (threshold(level), threshold(level + 1));
                    if to <= from {
                        1.0
                    } else {
                        crate::lod::saturate((d - from) / (to - from))
                    }
                }
            };
        }
        self.set_draws(terrain, settings, &visible, &chosen);
        tau.map(|_| {
            let max = visible
                .iter()
                .map(|&p| {
                    geomip::predicted_px(
                        terrain,
                        &self.errors,
                        &chosen,
                        p as usize,
                        view.eye_local,
                        view.pixels_per_radian,
                        settings.geomorph,
                    )
                })
                .fold(0.0, f32::max);
            (max, None)
        })
    }

    /// The error LOD's levels from the view measure's table (every patch,
    /// sample by sample): the patches in the frustum become the draws.
    fn choose_by_view_measure(
        &mut self,
        terrain: &Terrain,
        view: &FrameView,
        settings: &RenderSettings,
        pixels: f32,
    ) -> (f32, Option<f32>) {
        let drawn = view.patches_drawn(terrain, settings.cull);
        let seen = seen_errors(
            terrain,
            &self.errors,
            Diagonal::Reference,
            view,
            (settings, pixels),
            &drawn,
        );
        let table = seen.as_ref().map_or(&self.errors, |s| &s.table);
        let mut chosen = geomip::select_levels_by_error(
            terrain,
            table,
            view.eye_local,
            view.pixels_per_radian,
            pixels,
            &drawn,
        );
        if let Some(v) = &seen {
            geomip::limit_morph(&mut chosen, &v.morph_limits, &drawn, terrain.grid());
        }
        let visible: Vec<u32> = (0..drawn.len() as u32)
            .filter(|&p| drawn[p as usize])
            .collect();
        self.set_draws(terrain, settings, &visible, &chosen);
        match seen {
            Some(v) => (v.predicted_max_px, Some(v.predicted_p99_px)),
            None => (0.0, None),
        }
    }

    /// The unstitched full-resolution index list of a patch of `cells`.
    fn full_resolution_range(&self, cells: [usize; 2]) -> (u32, u32) {
        self.full_resolution
            .iter()
            .find(|(c, _)| *c == cells)
            .map_or(self.variants[0], |&(_, range)| range)
    }

    /// Draws `draws` (this path's patches, or the tess path's
    /// full-resolution ones) with the geomip pipeline.
    /// With `indirect`, draw i reads its instance count (0 or 1, set by
    /// the occlusion state) from the command buffer's command `first + i`.
    fn draw(
        &self,
        rec: &Recorder,
        set: DescriptorSet,
        wireframe: bool,
        draws: &[GeomipDraw],
        indirect: Option<(&Buffer, u64)>,
    ) -> Result<()> {
        rec.bind_graphics(self.pipelines.select(wireframe)?, &self.layout, set);
        rec.bind_geometry(&self.template, &self.indices);
        for (i, draw) in draws.iter().enumerate() {
            rec.push_constants(
                &self.layout,
                vk::ShaderStageFlags::VERTEX,
                bytemuck::bytes_of(&draw.constants),
            );
            match indirect {
                Some((commands, first)) => {
                    rec.draw_indexed_indirect(commands, (first + i as u64) * DRAW_COMMAND_BYTES)
                }
                None => rec.draw_indexed(draw.first, draw.count),
            }
        }
        Ok(())
    }

    /// The patches `visible` this frame (in grid order), at their `chosen`
    /// levels, become its draws.
    fn set_draws(
        &mut self,
        terrain: &Terrain,
        settings: &RenderSettings,
        visible: &[u32],
        chosen: &geomip::PatchLevels,
    ) {
        let grid = terrain.grid();
        self.draws.clear();
        for &p in visible {
            let p = p as usize;
            let id = grid.patch_id(p);
            let level = usize::from(chosen.levels[p]);
            let (coarser, _) = geomip::neighbour_masks(&chosen.levels, grid, id);
            let rect = grid.sample_rect(id);
            let (first, count) = if level == 0 && coarser == 0 {
                self.full_resolution_range([rect.cells_x(), rect.cells_z()])
            } else {
                self.variants[level * 16 + usize::from(coarser)]
            };
            let (interior, sides) = if settings.geomorph {
                geomip::patch_morph(chosen, grid, id)
            } else {
                (0.0, [0.0; 4])
            };
            self.draws.push(GeomipDraw {
                patch: p as u32,
                first,
                count,
                constants: GeomipConstants {
                    origin: [rect.col0 as i32, rect.row0 as i32],
                    level: level as i32,
                    interior,
                    sides,
                },
            });
        }
    }
}

/// The error table `bound` as `view` sees it for the patches `drawn`
/// (`lod::view_measure`), where `settings` measure the view and the CPU
/// holds the heights; None keeps the bounds (a streamed terrain's too),
/// with no expectation to report.
fn seen_errors(
    terrain: &Terrain,
    bound: &ErrorTable,
    diagonal: Diagonal,
    view: &FrameView,
    (settings, pixel_error): (&RenderSettings, f32),
    drawn: &[bool],
) -> Option<ViewErrors> {
    if settings.error_measure != ErrorMeasure::View {
        return None;
    }
    let heightmap = terrain.info().heightmap()?;
    Some(view_error_table(
        terrain,
        heightmap,
        bound,
        diagonal,
        &ViewLod {
            eye_local: view.eye_local,
            pixels_per_radian: view.pixels_per_radian,
            viewport_pixels: f64::from(view.viewport.x) * f64::from(view.viewport.y),
            frustum: view.frustum,
            pixel_error,
        },
        drawn,
    ))
}

/// Distance from `eye_local` to the nearest point of patch `p`'s box.
fn patch_distance(terrain: &Terrain, p: usize, eye_local: glam::Vec3) -> f32 {
    let (centre, extents) = terrain.patch_aabb(terrain.grid().patch_id(p));
    ((eye_local - centre).abs() - extents)
        .max(glam::Vec3::ZERO)
        .length()
}

impl TessGeometry {
    /// The full-resolution patches of `plan` become its exact draws
    /// (geomip level 0, no stitching: every edge they share is tessellated
    /// with a vertex on every sample).
    fn set_exact_draws(&mut self, terrain: &Terrain, plan: &FramePlan, geomip: &GeomipGeometry) {
        let grid = terrain.grid();
        self.exact.clear();
        for patch in plan.patches.iter().filter(|p| p.full_resolution) {
            let p = patch.index as usize;
            let rect = grid.sample_rect(grid.patch_id(p));
            let (first, count) = geomip.full_resolution_range([rect.cells_x(), rect.cells_z()]);
            self.exact.push(GeomipDraw {
                patch: p as u32,
                first,
                count,
                constants: GeomipConstants {
                    origin: [rect.col0 as i32, rect.row0 as i32],
                    level: 0,
                    interior: 0.0,
                    sides: [0.0; 4],
                },
            });
        }
    }
}
