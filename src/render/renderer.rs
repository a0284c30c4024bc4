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

use super::appearance::GpuAppearance;
use super::frame::{build_frames, DescriptorPlan, FrameSlot};
use super::geomip_path::GeomipGeometry;
use super::occlusion::Occlusion;
use super::pipelines::{
    build_pipelines, create_sky_pipeline, CulledPipelines, PathPipelines, PipelineTarget,
};
use super::residency::StreamShape;
use super::seen::SeenState;
use super::settings::{ErrorMeasure, LodMetric, RenderPath, RenderSettings};
use super::streaming::{NoStream, StreamConfig, StreamStats, Streamer};
use super::tess_path::{ChoiceBuffers, TessGeometry};
use super::view::FrameView;
use crate::appearance::Appearance;
use crate::gpu::descriptors::DescriptorSets;
use crate::gpu::memory::{Buffer, Image};
use crate::gpu::owned::{DescriptorSetLayout, Pipeline, PipelineLayout, Sampler};
use crate::gpu::queries::PipelineStatistics;
use crate::gpu::{sample_count_flag, Device, Gpu, VkError};
use crate::lod::geomip_choice::ChosenPatches;
use crate::lod::hierarchy::Hierarchy;
use crate::lod::plan::{Planner, PLANNED_BLOCKS};
use crate::render::error::{RenderError, Result};
use crate::terrain::tiled::TiledHeightmap;
use crate::terrain::{ErrorTable, Terrain, TerrainInfo};

mod budget;
use budget::BuildInputs;
mod checks;
use checks::{brute_vertex_count, check_device, check_path};
mod prepare;
mod record;

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
    /// The slot `prepare` last set up, whose choice the accessors report.
    last_prepared: usize,
    /// Milliseconds spent computing the error tables in `new` (0 when no
    /// path needs them), and the view model where a frame asked for it
    /// (`build_view_model`).
    error_table_ms: f64,
    /// The quadtree the level choices walk, built with the first path
    /// that draws patches.
    hierarchy: Option<Hierarchy>,
    /// What the frames counted of the pixels each patch shows.
    seen: SeenState,
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
    /// Patches in the view the test found hidden, drawn by the first
    /// pass or not, and every patch in the view: whether culling goes on
    /// (`occlusion::HiddenCount::worth_culling`).
    pub found: super::occlusion::HiddenCount,
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
    ///
    /// A streamed terrain takes what the memory budget leaves: a coarser
    /// base level and fewer pool layers where it must. Under a budget too
    /// small for its smallest layout, the error names the smallest budget
    /// that works, measured by building that layout with the budget lifted.
    pub fn with_appearance(
        gpu: &Gpu,
        terrain: &Terrain,
        appearance: &Appearance,
        color_format: vk::Format,
        frames_in_flight: u32,
        options: &RendererOptions,
    ) -> Result<Self> {
        let inputs = (gpu, terrain, appearance, color_format, frames_in_flight);
        let before = gpu.device.memory_in_use();
        let mut options = options.clone();
        loop {
            match (Self::build_within_budget(inputs, &options), &options.stream) {
                (Ok(Built::Renderer(renderer)), _) => return Ok(*renderer),
                (Ok(Built::Rebase(config)), _) => options.stream = Some(config),
                (Err(RenderError::Vk(VkError::OverBudget { budget, .. })), Some(config)) => {
                    return Err(Self::refuse_budget(
                        inputs,
                        &options,
                        config,
                        (before, budget),
                    ));
                }
                (Err(e), _) => return Err(e),
            }
        }
    }

    /// A renderer of `options`, or (streaming) the configuration to build
    /// instead where the memory budget asks for a coarser base level.
    fn build_within_budget(
        (gpu, terrain, appearance, color_format, frames_in_flight): BuildInputs,
        options: &RendererOptions,
    ) -> Result<Built> {
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
        let frames = build_frames(
            device,
            &sets,
            (&heightmap, &sampler),
            &appearance,
            (
                terrain.grid().patch_count(),
                // The error LOD of either path reads the counts, but not
                // on a streamed terrain.
                options
                    .stream
                    .is_none()
                    .then(|| terrain.grid().patch_count()),
            ),
        )?;
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
            hierarchy: None,
            seen: SeenState::default(),
            last_prepared: 0,
        };
        for &path in &options.paths {
            renderer.ensure(terrain, path, options.wireframe)?;
        }
        if let (Some(config), Some(tiled)) = (&options.stream, tiled) {
            let frames = renderer.frames.len();
            let memory = Streamer::plan(device, (config, info.cells_per_patch()), &tiled, frames)?;
            if memory.shape.base_level != config.shape(&tiled).base_level {
                // The shaders are specialised on the base level.
                return Ok(Built::Rebase(config.with_base(&memory.shape)));
            }
            let streamer = Streamer::new(device, info, (config, memory), tiled, frames)?;
            for (slot, frame) in renderer.frames.iter().enumerate() {
                streamer.write_bindings(frame.set, slot, &renderer.sampler);
            }
            renderer.streamer = Some(streamer);
            renderer._no_stream = None;
        }
        Ok(Built::Renderer(Box::new(renderer)))
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
                self.tess = Some(TessGeometry::new(
                    &self.pipeline_target(),
                    &self.pipeline_layout,
                    terrain,
                    table.clone(),
                    wireframe,
                )?);
            }
            RenderPath::Geomip => {
                let (tess_table, table) = self.error_tables(terrain);
                self.hierarchy
                    .get_or_insert_with(|| Hierarchy::new(terrain, tess_table));
                self.geomip = Some(GeomipGeometry::new(
                    &self.pipeline_target(),
                    &self.set_layout,
                    terrain,
                    table.clone(),
                    wireframe,
                )?);
                // The error LOD of either path (the tess path builds this
                // one too) chooses into its frame slots' buffers: sized
                // and written now, not by a first frame.
                let patches = terrain.grid().patch_count();
                let blocks = patches.min(PLANNED_BLOCKS);
                for frame in &mut self.frames {
                    frame.planner = Planner::with_capacity(blocks);
                    frame.geomip_choice = ChosenPatches::with_capacity(patches, blocks);
                }
            }
            RenderPath::Brute => {
                self.brute = Some(BruteGeometry {
                    vertex_count: brute_vertex_count(terrain) as u32,
                    pipelines: build_pipelines(
                        &self.pipeline_target(),
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
        let start = Instant::now();
        let tables = terrain.error_tables();
        if self.error_table_ms == 0.0 {
            self.error_table_ms = start.elapsed().as_secs_f64() * 1e3;
        }
        tables
    }

    /// Builds, or reads from its cache, the view model (`terrain::sight`)
    /// a frame of `settings` reads, where it reads one and the CPU holds
    /// the terrain's heights: the error LOD's choice by the model, on
    /// either path. A renderer asks for it only then, so one that draws
    /// by distance alone never holds it (an 8193^2 terrain's is 497 MB).
    /// `prepare` calls this before the choice is timed; a caller that
    /// times its frames calls it first, to keep the build out of them. The
    /// build's time is added to `error_table_ms` (none where the terrain
    /// already held its model).
    pub fn build_view_model(&mut self, terrain: &Terrain, settings: &RenderSettings) {
        let reads = settings.path != RenderPath::Brute
            && matches!(settings.lod_metric, LodMetric::Error(_))
            && settings.error_measure == ErrorMeasure::Sight;
        if reads && !terrain.sight_table_asked() {
            let start = Instant::now();
            terrain.sight_table();
            self.error_table_ms += start.elapsed().as_secs_f64() * 1e3;
        }
    }

    /// Per frame slot, the tess path's choice buffers (starting as
    /// `table`), and the slot's set pointed at them and the occlusion
    /// state and its own frame block (the bindings of the tess path's
    /// control shader).
    fn add_error_lod_buffers(&mut self, terrain: &Terrain, table: &ErrorTable) -> Result<()> {
        for (i, frame) in self.frames.iter_mut().enumerate() {
            frame.choice = Some(ChoiceBuffers::new(
                &self.device,
                i,
                terrain,
                table,
                (frame.set, &frame.uniforms),
                &self.occlusion.visibility,
            )?);
        }
        Ok(())
    }

    /// Milliseconds spent computing the per-patch error tables (in `new`)
    /// and the view model or reading it from the cache (the first time a
    /// frame asked for it, `build_view_model`).
    pub fn error_table_ms(&self) -> f64 {
        self.error_table_ms
    }

    pub fn color_format(&self) -> vk::Format {
        self.color_format
    }

    /// What this renderer's pipelines are built for.
    fn pipeline_target(&self) -> PipelineTarget<'_> {
        PipelineTarget {
            device: &self.device,
            color_format: self.color_format,
            samples: self.samples,
            variant: &self.appearance.variant,
        }
    }

    /// Samples per pixel of the targets this renderer draws into.
    pub fn samples(&self) -> u32 {
        self.samples.as_raw()
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

/// The terrain's heights as an R32_SFLOAT image, one texel per sample.
pub(super) fn upload_heightmap(device: &Device, info: &TerrainInfo, name: &str) -> Result<Image> {
    let (cols, rows) = (info.cols() as u32, info.rows() as u32);
    let heightmap = info.heightmap().ok_or_else(|| {
        RenderError::Unsupported(
            "a tiled terrain read a tile at a time can only be drawn streamed".into(),
        )
    })?;
    device
        .upload_r32f_image(name, cols, rows, heightmap.heights())
        .map_err(RenderError::from)
}

/// The tiled terrain file `config` streams: the one the terrain's CPU
/// model reads already, when it is that file, so its header and directory
/// are read once.
fn open_streamed(info: &TerrainInfo, config: &StreamConfig) -> Result<Arc<TiledHeightmap>> {
    match info.tiled_samples() {
        Some(tiled) if tiled.path() == config.path => Ok(Arc::clone(tiled)),
        _ => TiledHeightmap::open(&config.path)
            .map(Arc::new)
            .map_err(|e| RenderError::Stream(e.to_string())),
    }
}

/// What `TerrainRenderer::build` made.
enum Built {
    Renderer(Box<TerrainRenderer>),
    /// A streamed terrain's configuration with the coarser base level the
    /// memory budget leaves room for.
    Rebase(StreamConfig),
}
