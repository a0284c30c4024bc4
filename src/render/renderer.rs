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
//!   shader (see `terrain::geomip`).
//! - **brute**: every sample a vertex, with `height_at`'s triangle split and
//!   no buffers at all (the vertex shader derives each sample from its
//!   index); the reference that error is measured against.

use std::mem::size_of;

use ash::vk;

use super::material::{GpuAppearance, ShaderVariant};
use super::shaders;
use super::uniforms::{FrameUniforms, FrameView, LodMetric, RenderSettings};
use crate::material::Appearance;
use crate::shader_constants::{
    BINDING_ERROR_TABLE, BINDING_FRAME, BINDING_FULL_RESOLUTION, BINDING_HEIGHTMAP,
};
use crate::terrain::lod::{choose_tess_error, TessErrorChoice};
use crate::terrain::{geomip, ErrorTable, Terrain};
use crate::vk::commands::Recorder;
use crate::vk::memory::{Buffer, Image};
use crate::vk::pipeline::GraphicsPipelineDesc;
use crate::vk::queries::{FrameQueries, PipelineStatistics};
use crate::vk::target::{TargetViews, DEPTH_FORMAT};
use crate::vk::{Device, Gpu, Result, VkError};

/// Per-frame-in-flight resources: the uniform block is rewritten each frame,
/// so a frame still on the GPU keeps its own.
struct FrameSlot {
    uniforms: Buffer,
    set: vk::DescriptorSet,
    queries: FrameQueries,
    /// The tess path's full-resolution patches, one bit each (error LOD).
    full_resolution: Option<Buffer>,
}

/// Which way the terrain is drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RenderPath {
    /// Hardware tessellation.
    #[default]
    Tess,
    /// Geomipmapping with stitched edges and geomorphing.
    Geomip,
    /// The full-resolution mesh.
    Brute,
}

/// What the device lacks changes what is drawn: without tessellation
/// shaders geomip draws the same terrain, without fillModeNonSolid it is
/// drawn filled. Says so in `notes`.
pub fn with_fallback(
    settings: RenderSettings,
    caps: &crate::vk::Capabilities,
    notes: &mut Vec<String>,
) -> RenderSettings {
    let mut settings = settings;
    if settings.wireframe && !caps.fill_mode_non_solid {
        notes.push(format!(
            "{}: fillModeNonSolid is unavailable, drawing filled instead of wireframe",
            caps.device_name
        ));
        settings.wireframe = false;
    }
    if settings.path == RenderPath::Tess && !caps.tessellation_shader {
        notes.push(format!(
            "{}: tessellationShader is unavailable, falling back to the geomip path",
            caps.device_name
        ));
        return RenderSettings {
            path: RenderPath::Geomip,
            ..settings
        };
    }
    settings
}

/// What a renderer builds.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RendererOptions {
    pub paths: Vec<RenderPath>,
    /// Also build line pipelines (needs fillModeNonSolid).
    pub wireframe: bool,
}

/// Fill and (when asked for) wireframe pipelines of one path.
struct PathPipelines {
    fill: vk::Pipeline,
    wireframe: Option<vk::Pipeline>,
}

impl PathPipelines {
    fn select(&self, wireframe: bool) -> Result<vk::Pipeline> {
        if !wireframe {
            return Ok(self.fill);
        }
        self.wireframe.ok_or_else(|| {
            VkError::Unsupported("the wireframe pipeline was not built for this renderer".into())
        })
    }

    fn destroy(self, device: &Device) {
        for pipeline in std::iter::once(self.fill).chain(self.wireframe) {
            device.destroy_pipeline(pipeline);
        }
    }
}

struct TessGeometry {
    control_points: Buffer,
    indices: Buffer,
    index_count: u32,
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
    /// The shared layout plus the per-patch push constants.
    layout: vk::PipelineLayout,
    pipelines: PathPipelines,
    /// This frame's visible patches.
    draws: Vec<GeomipDraw>,
    /// Per-patch errors of each level, for choosing levels by projected error.
    errors: ErrorTable,
    /// Levels set from outside (`set_geomip_levels`) instead of chosen,
    /// balanced, with no morph.
    given: Option<geomip::PatchLevels>,
}

/// One patch of the geomip path: its index list and push constants.
#[derive(Clone, Copy, Debug)]
struct GeomipDraw {
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

/// Draws a terrain into any target, by the paths it was built for.
pub struct TerrainRenderer {
    heightmap: Image,
    /// Material layers, blend maps and lightmap, as the scene needs.
    appearance: GpuAppearance,
    sampler: vk::Sampler,
    set_layout: vk::DescriptorSetLayout,
    pipeline_layout: vk::PipelineLayout,
    descriptor_pool: vk::DescriptorPool,
    tess: Option<TessGeometry>,
    geomip: Option<GeomipGeometry>,
    brute: Option<BruteGeometry>,
    /// Per-patch errors for the tess path's error-bounded factors.
    error_table: Option<Buffer>,
    color_format: vk::Format,
    max_patches_per_draw: Option<u32>,
    frames: Vec<FrameSlot>,
    /// Milliseconds spent computing the error table in `new` (0 when no
    /// path needs it).
    error_table_ms: f64,
    /// The largest error the last prepared frame's LOD choice expects on
    /// screen, in pixels (error LOD only).
    predicted_max_px: Option<f32>,
}

/// What one frame's queries measured; None where the device can't tell.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameMeasurements {
    pub gpu_ms: Option<f64>,
    pub statistics: Option<PipelineStatistics>,
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
        let info = terrain.info();
        let (cols, rows) = (info.cols() as u32, info.rows() as u32);
        let limit = device.caps.max_image_dimension_2d;
        if cols > limit || rows > limit {
            return Err(VkError::Unsupported(format!(
                "heightmap of {cols}x{rows} samples exceeds this device's largest image ({limit}x{limit})"
            )));
        }
        let features = device.format_features(&gpu.instance, vk::Format::R32_SFLOAT);
        if !features
            .contains(vk::FormatFeatureFlags::SAMPLED_IMAGE | vk::FormatFeatureFlags::TRANSFER_DST)
        {
            return Err(VkError::Unsupported(format!(
                "{} cannot sample R32_SFLOAT images ({features:?})",
                device.caps.device_name
            )));
        }
        if options.wireframe && !device.caps.fill_mode_non_solid {
            return Err(VkError::Unsupported(format!(
                "wireframe needs fillModeNonSolid, which {} lacks",
                device.caps.device_name
            )));
        }
        let wants = |path| options.paths.contains(&path);
        if wants(RenderPath::Tess) && !device.caps.tessellation_shader {
            return Err(VkError::Unsupported(format!(
                "the tess path needs tessellationShader, which {} lacks",
                device.caps.device_name
            )));
        }
        // Brute draws 6 vertices per cell, counted by a signed index in GLSL.
        let brute_vertices = 6 * u64::from(cols - 1) * u64::from(rows - 1);
        if wants(RenderPath::Brute) && brute_vertices > i32::MAX as u64 {
            return Err(VkError::Unsupported(format!(
                "the brute path draws {brute_vertices} vertices for {cols}x{rows} samples, over the {} one draw can address",
                i32::MAX
            )));
        }

        let heightmap = device.upload_r32f_image(
            "terrain.heightmap",
            cols,
            rows,
            info.heightmap().heights(),
        )?;
        let sampler = match device.create_nearest_sampler("terrain.heightmap_sampler") {
            Ok(s) => s,
            Err(e) => {
                device.destroy_image(heightmap);
                return Err(e);
            }
        };
        let gpu_appearance = match GpuAppearance::new(device, &gpu.instance, appearance, info) {
            Ok(a) => a,
            Err(e) => {
                device.destroy_sampler(sampler);
                device.destroy_image(heightmap);
                return Err(e);
            }
        };
        let mut stages = vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT;
        if wants(RenderPath::Tess) {
            stages |= vk::ShaderStageFlags::TESSELLATION_CONTROL
                | vk::ShaderStageFlags::TESSELLATION_EVALUATION;
        }
        let mut bindings = vec![
            (BINDING_FRAME, vk::DescriptorType::UNIFORM_BUFFER, stages),
            (
                BINDING_HEIGHTMAP,
                vk::DescriptorType::COMBINED_IMAGE_SAMPLER,
                stages,
            ),
        ];
        let mut pool_sizes = vec![
            (vk::DescriptorType::UNIFORM_BUFFER, 1),
            (vk::DescriptorType::COMBINED_IMAGE_SAMPLER, 1),
        ];
        // The tess path's error-bounded factors read the per-patch error
        // table (7 floats a patch); the geomip path's error LOD has its own,
        // for its fixed diagonal. Both come from one pass.
        let table_start = std::time::Instant::now();
        let tables =
            (wants(RenderPath::Tess) || wants(RenderPath::Geomip)).then(|| terrain.error_tables());
        let (table, geomip_table) = tables.unzip();
        let error_table_ms = table_start.elapsed().as_secs_f64() * 1e3;
        if wants(RenderPath::Tess) {
            for binding in [BINDING_ERROR_TABLE, BINDING_FULL_RESOLUTION] {
                bindings.push((
                    binding,
                    vk::DescriptorType::STORAGE_BUFFER,
                    vk::ShaderStageFlags::TESSELLATION_CONTROL,
                ));
            }
            pool_sizes.push((vk::DescriptorType::STORAGE_BUFFER, 2));
        }
        let vertex_stages = stages & !vk::ShaderStageFlags::FRAGMENT;
        for binding in gpu_appearance.bindings(vertex_stages) {
            pool_sizes.push((binding.1, 1));
            bindings.push(binding);
        }
        // Null handles until made; destroying a null handle does nothing,
        // so a failure part-way tears down exactly what was built.
        let mut renderer = TerrainRenderer {
            heightmap,
            appearance: gpu_appearance,
            sampler,
            set_layout: vk::DescriptorSetLayout::null(),
            pipeline_layout: vk::PipelineLayout::null(),
            descriptor_pool: vk::DescriptorPool::null(),
            tess: None,
            geomip: None,
            brute: None,
            error_table: None,
            color_format,
            max_patches_per_draw: device.caps.max_patches_per_draw,
            frames: Vec::new(),
            error_table_ms,
            predicted_max_px: None,
        };
        let built = (|| {
            if let (true, Some(table)) = (wants(RenderPath::Tess), &table) {
                renderer.error_table = Some(device.upload_buffer(
                    "terrain.error_table",
                    vk::BufferUsageFlags::STORAGE_BUFFER,
                    bytemuck::cast_slice(table.as_slice()),
                )?);
            }
            renderer.set_layout =
                device.create_descriptor_set_layout(&bindings, "terrain.set_layout")?;
            renderer.pipeline_layout =
                device.create_pipeline_layout(&[renderer.set_layout], "terrain.pipeline_layout")?;
            let (descriptor_pool, sets) = device.allocate_descriptor_sets(
                renderer.set_layout,
                &pool_sizes,
                frames_in_flight,
                "terrain.frame_set",
            )?;
            renderer.descriptor_pool = descriptor_pool;
            for (i, set) in sets.into_iter().enumerate() {
                let uniforms = device.create_host_buffer(
                    &format!("terrain.frame_uniforms[{i}]"),
                    vk::BufferUsageFlags::UNIFORM_BUFFER,
                    bytemuck::bytes_of(&FrameUniforms::default()),
                )?;
                let queries =
                    match FrameQueries::new(device, &format!("terrain.frame_queries[{i}]")) {
                        Ok(q) => q,
                        Err(e) => {
                            device.destroy_buffer(uniforms);
                            return Err(e);
                        }
                    };
                let full_resolution = if renderer.error_table.is_some() {
                    let words = terrain.grid().patch_count().div_ceil(32).max(1);
                    match device.create_host_buffer(
                        &format!("terrain.full_resolution[{i}]"),
                        vk::BufferUsageFlags::STORAGE_BUFFER,
                        bytemuck::cast_slice(&vec![0u32; words]),
                    ) {
                        Ok(b) => Some(b),
                        Err(e) => {
                            device.destroy_buffer(uniforms);
                            queries.destroy(&device.raw);
                            return Err(e);
                        }
                    }
                } else {
                    None
                };
                device.write_buffer(
                    set,
                    BINDING_FRAME,
                    vk::DescriptorType::UNIFORM_BUFFER,
                    uniforms.raw,
                    size_of::<FrameUniforms>() as u64,
                );
                device.write_sampled_image(
                    set,
                    BINDING_HEIGHTMAP,
                    renderer.heightmap.view,
                    renderer.sampler,
                );
                renderer.appearance.write(device, set);
                if let Some(errors) = &renderer.error_table {
                    device.write_buffer(
                        set,
                        BINDING_ERROR_TABLE,
                        vk::DescriptorType::STORAGE_BUFFER,
                        errors.raw,
                        errors.desc.size,
                    );
                }
                if let Some(bits) = &full_resolution {
                    device.write_buffer(
                        set,
                        BINDING_FULL_RESOLUTION,
                        vk::DescriptorType::STORAGE_BUFFER,
                        bits.raw,
                        bits.desc.size,
                    );
                }
                renderer.frames.push(FrameSlot {
                    uniforms,
                    set,
                    queries,
                    full_resolution,
                });
            }
            if let (true, Some(table)) = (wants(RenderPath::Tess), &table) {
                renderer.tess = Some(build_tess(
                    device,
                    &renderer,
                    terrain,
                    table.clone(),
                    options.wireframe,
                )?);
            }
            // The tess path draws its full-resolution patches with geomip's
            // level 0.
            let geomip_needed = wants(RenderPath::Geomip) || wants(RenderPath::Tess);
            if let (true, Some(table)) = (geomip_needed, geomip_table) {
                renderer.geomip = Some(build_geomip(
                    device,
                    &renderer,
                    terrain,
                    table,
                    options.wireframe,
                )?);
            }
            if wants(RenderPath::Brute) {
                renderer.brute = Some(BruteGeometry {
                    vertex_count: brute_vertices as u32,
                    pipelines: build_pipelines(
                        device,
                        &renderer,
                        RenderPath::Brute,
                        options.wireframe,
                    )?,
                });
            }
            Ok(())
        })();
        match built {
            Ok(()) => Ok(renderer),
            Err(e) => {
                renderer.destroy(device);
                Err(e)
            }
        }
    }

    /// Milliseconds `new` spent computing the per-patch error table.
    pub fn error_table_ms(&self) -> f64 {
        self.error_table_ms
    }

    pub fn color_format(&self) -> vk::Format {
        self.color_format
    }

    /// Writes the uniforms of frame slot `slot` (its previous frame must
    /// have completed) and, for the geomip path, chooses this frame's patch
    /// levels.
    pub fn prepare(
        &mut self,
        slot: usize,
        terrain: &Terrain,
        view: &FrameView,
        settings: &RenderSettings,
    ) -> Result<()> {
        let uniforms = FrameUniforms::new(terrain, view, settings);
        self.frames[slot]
            .uniforms
            .mapped_mut()
            .ok_or_else(|| VkError::Unsupported("uniform memory is not host-mapped".into()))?
            .copy_from_slice(bytemuck::bytes_of(&uniforms));
        self.predicted_max_px = None;
        match (settings.path, settings.lod_metric) {
            (RenderPath::Geomip, _) => {
                if let Some(geomip) = self.geomip.as_mut() {
                    let drawn = view.patches_drawn(terrain, settings.cull);
                    self.predicted_max_px = geomip.choose(terrain, view, settings, &drawn);
                }
            }
            (RenderPath::Tess, LodMetric::Error(pixels)) => {
                if let (Some(tess), Some(bits)) = (
                    self.tess.as_mut(),
                    self.frames[slot].full_resolution.as_mut(),
                ) {
                    let choice = choose_tess_error(
                        terrain,
                        &tess.errors,
                        view.eye_local,
                        view.pixels_per_radian,
                        pixels,
                    );
                    bits.mapped_mut()
                        .ok_or_else(|| {
                            VkError::Unsupported("patch flag memory is not host-mapped".into())
                        })?
                        .copy_from_slice(bytemuck::cast_slice(&choice.full_resolution));
                    let geomip = self.geomip.as_ref().ok_or_else(|| {
                        VkError::Unsupported("the tess path's exact draws need geomip".into())
                    })?;
                    let drawn = view.patches_drawn(terrain, settings.cull);
                    self.predicted_max_px =
                        Some(tess.set_exact_draws(terrain, &drawn, &choice, geomip));
                }
            }
            (RenderPath::Tess | RenderPath::Brute, _) => {}
        }
        Ok(())
    }

    /// The largest error the last prepared frame's level choice expects on
    /// screen, in pixels: over the patches in view, each one's error bound
    /// at its level seen from its nearest point (0 where drawn at full
    /// resolution). None for the distance LOD and the brute path.
    pub fn predicted_max_px(&self) -> Option<f32> {
        self.predicted_max_px
    }

    /// Makes the geomip path draw every patch at the given level (one per
    /// patch, in patch order), without geomorphing, instead of choosing
    /// levels; `None` goes back to choosing. Levels are balanced first, so
    /// the stitched sides still meet. This is how the benchmark's oracle
    /// draws its per-patch levels.
    pub fn set_geomip_levels(&mut self, terrain: &Terrain, levels: Option<&[u8]>) -> Result<()> {
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

    /// Records the terrain draw of `settings.path` into `target` (already in
    /// attachment layouts), timed and counted by slot `slot`'s queries.
    pub fn record(
        &self,
        rec: &Recorder,
        slot: usize,
        target: &TargetViews,
        settings: &RenderSettings,
    ) -> Result<()> {
        let not_built = || {
            VkError::Unsupported(format!(
                "the {:?} path was not built for this renderer",
                settings.path
            ))
        };
        let frame = &self.frames[slot];
        frame.queries.reset(rec.device, rec.cmd);
        rec.begin_rendering(target, settings.clear_color);
        frame.queries.begin(rec.device, rec.cmd);
        match settings.path {
            RenderPath::Tess => {
                let tess = self.tess.as_ref().ok_or_else(not_built)?;
                let pipelines = match settings.lod_metric {
                    LodMetric::Error(_) => &tess.error_pipelines,
                    _ => &tess.pipelines,
                };
                rec.bind_graphics(
                    pipelines.select(settings.wireframe)?,
                    self.pipeline_layout,
                    frame.set,
                );
                rec.bind_geometry(tess.control_points.raw, tess.indices.raw);
                // One draw, or batches where the driver needs them (see
                // `Capabilities::max_patches_per_draw`).
                let batch = self
                    .max_patches_per_draw
                    .map_or(tess.index_count, |n| n * 4);
                let mut first = 0;
                while first < tess.index_count {
                    let count = (tess.index_count - first).min(batch);
                    rec.draw_indexed(first, count);
                    first += count;
                }
                if matches!(settings.lod_metric, LodMetric::Error(_)) && !tess.exact.is_empty() {
                    let geomip = self.geomip.as_ref().ok_or_else(not_built)?;
                    geomip.draw(rec, frame.set, settings.wireframe, &tess.exact)?;
                }
            }
            RenderPath::Geomip => {
                let geomip = self.geomip.as_ref().ok_or_else(not_built)?;
                geomip.draw(rec, frame.set, settings.wireframe, &geomip.draws)?;
            }
            RenderPath::Brute => {
                let brute = self.brute.as_ref().ok_or_else(not_built)?;
                rec.bind_graphics(
                    brute.pipelines.select(settings.wireframe)?,
                    self.pipeline_layout,
                    frame.set,
                );
                rec.draw(brute.vertex_count);
            }
        }
        frame.queries.end(rec.device, rec.cmd);
        rec.end_rendering();
        Ok(())
    }

    /// What slot `slot`'s last frame measured; call after its fence.
    pub fn measurements(&self, device: &Device, slot: usize) -> Result<FrameMeasurements> {
        let queries = &self.frames[slot].queries;
        Ok(FrameMeasurements {
            gpu_ms: queries.gpu_ms(&device.raw)?,
            statistics: queries.statistics(&device.raw)?,
        })
    }

    pub fn destroy(self, device: &Device) {
        for frame in self.frames {
            device.destroy_buffer(frame.uniforms);
            frame.queries.destroy(&device.raw);
            if let Some(bits) = frame.full_resolution {
                device.destroy_buffer(bits);
            }
        }
        if let Some(tess) = self.tess {
            tess.pipelines.destroy(device);
            tess.error_pipelines.destroy(device);
            device.destroy_buffer(tess.control_points);
            device.destroy_buffer(tess.indices);
        }
        if let Some(geomip) = self.geomip {
            geomip.pipelines.destroy(device);
            device.destroy_pipeline_layout(geomip.layout);
            device.destroy_buffer(geomip.template);
            device.destroy_buffer(geomip.indices);
        }
        if let Some(brute) = self.brute {
            brute.pipelines.destroy(device);
        }
        if let Some(errors) = self.error_table {
            device.destroy_buffer(errors);
        }
        device.destroy_pipeline_layout(self.pipeline_layout);
        // The pool frees its sets; the layout goes after them.
        device.destroy_descriptor_pool(self.descriptor_pool);
        device.destroy_descriptor_set_layout(self.set_layout);
        device.destroy_sampler(self.sampler);
        device.destroy_image(self.heightmap);
        self.appearance.destroy(device);
    }
}

fn build_pipelines(
    device: &Device,
    renderer: &TerrainRenderer,
    path: RenderPath,
    wireframe: bool,
) -> Result<PathPipelines> {
    build_pipelines_with(
        device,
        renderer,
        renderer.pipeline_layout,
        (path, false),
        wireframe,
    )
}

/// `path.1`: the tess path with equal spacing (the error LOD).
fn build_pipelines_with(
    device: &Device,
    renderer: &TerrainRenderer,
    layout: vk::PipelineLayout,
    path: (RenderPath, bool),
    wireframe: bool,
) -> Result<PathPipelines> {
    let variant = &renderer.appearance.variant;
    let color_format = renderer.color_format;
    let create =
        |mode, suffix| create_pipeline(device, layout, color_format, variant, path, mode, suffix);
    let fill = create(vk::PolygonMode::FILL, "fill")?;
    let wireframe = if wireframe {
        match create(vk::PolygonMode::LINE, "wireframe") {
            Ok(p) => Some(p),
            Err(e) => {
                device.destroy_pipeline(fill);
                return Err(e);
            }
        }
    } else {
        None
    };
    Ok(PathPipelines { fill, wireframe })
}

fn create_pipeline(
    device: &Device,
    layout: vk::PipelineLayout,
    color_format: vk::Format,
    variant: &ShaderVariant,
    (path, equal_spacing): (RenderPath, bool),
    polygon_mode: vk::PolygonMode,
    suffix: &str,
) -> Result<vk::Pipeline> {
    let frag = shaders::spirv("terrain.frag", &variant.fragment_defines());
    let placing = |file| shaders::spirv(file, &variant.vertex_defines());
    let mut tese_defines = variant.vertex_defines();
    if equal_spacing {
        tese_defines.push("EQUAL_SPACING");
    }
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
            &[
                (vk::ShaderStageFlags::VERTEX, shaders::terrain_vert()),
                (
                    vk::ShaderStageFlags::TESSELLATION_CONTROL,
                    shaders::terrain_tesc(),
                ),
                (
                    vk::ShaderStageFlags::TESSELLATION_EVALUATION,
                    shaders::spirv("terrain.tese", &tese_defines),
                ),
                (vk::ShaderStageFlags::FRAGMENT, frag),
            ],
            vk::PrimitiveTopology::PATCH_LIST,
            4,
            size_of::<[f32; 4]>() as u32,
            &[(0, vk::Format::R32G32B32A32_SFLOAT, 0)],
        ),
        RenderPath::Geomip => (
            format!("terrain.pipeline.geomip.{suffix}"),
            &[
                (vk::ShaderStageFlags::VERTEX, placing("geomip.vert")),
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
                (vk::ShaderStageFlags::VERTEX, placing("brute.vert")),
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
        layout,
        specialization: &variant.specialization(),
    })
}

/// Uploads two buffers; if the second fails the first is freed, so the
/// caller gets the real error and nothing is left allocated.
fn upload_two(
    device: &Device,
    a: (&str, vk::BufferUsageFlags, &[u8]),
    b: (&str, vk::BufferUsageFlags, &[u8]),
) -> Result<(Buffer, Buffer)> {
    let first = device.upload_buffer(a.0, a.1, a.2)?;
    match device.upload_buffer(b.0, b.1, b.2) {
        Ok(second) => Ok((first, second)),
        Err(e) => {
            device.destroy_buffer(first);
            Err(e)
        }
    }
}

fn build_tess(
    device: &Device,
    renderer: &TerrainRenderer,
    terrain: &Terrain,
    errors: ErrorTable,
    wireframe: bool,
) -> Result<TessGeometry> {
    let (control_points, indices) = upload_two(
        device,
        (
            "terrain.control_points",
            vk::BufferUsageFlags::VERTEX_BUFFER,
            bytemuck::cast_slice(terrain.control_points()),
        ),
        (
            "terrain.patch_indices",
            vk::BufferUsageFlags::INDEX_BUFFER,
            bytemuck::cast_slice(terrain.indices()),
        ),
    )?;
    let layout = renderer.pipeline_layout;
    let built =
        build_pipelines(device, renderer, RenderPath::Tess, wireframe).and_then(|pipelines| {
            match build_pipelines_with(
                device,
                renderer,
                layout,
                (RenderPath::Tess, true),
                wireframe,
            ) {
                Ok(error_pipelines) => Ok((pipelines, error_pipelines)),
                Err(e) => {
                    pipelines.destroy(device);
                    Err(e)
                }
            }
        });
    match built {
        Ok((pipelines, error_pipelines)) => Ok(TessGeometry {
            control_points,
            indices,
            index_count: terrain.indices().len() as u32,
            pipelines,
            error_pipelines,
            errors,
            exact: Vec::new(),
        }),
        Err(e) => {
            device.destroy_buffer(control_points);
            device.destroy_buffer(indices);
            Err(e)
        }
    }
}

fn build_geomip(
    device: &Device,
    renderer: &TerrainRenderer,
    terrain: &Terrain,
    errors: ErrorTable,
    wireframe: bool,
) -> Result<GeomipGeometry> {
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
    let (template, indices) = upload_two(
        device,
        (
            "terrain.geomip_vertex_template",
            vk::BufferUsageFlags::VERTEX_BUFFER,
            bytemuck::cast_slice(&geomip::vertex_template(n)),
        ),
        (
            "terrain.geomip_indices",
            vk::BufferUsageFlags::INDEX_BUFFER,
            bytemuck::cast_slice(&variants.indices),
        ),
    )?;
    let layout_and_pipelines = device
        .create_pipeline_layout_with_push(
            &[renderer.set_layout],
            vk::ShaderStageFlags::VERTEX,
            size_of::<GeomipConstants>() as u32,
            "terrain.pipeline_layout.geomip",
        )
        .and_then(|layout| {
            match build_pipelines_with(
                device,
                renderer,
                layout,
                (RenderPath::Geomip, false),
                wireframe,
            ) {
                Ok(pipelines) => Ok((layout, pipelines)),
                Err(e) => {
                    device.destroy_pipeline_layout(layout);
                    Err(e)
                }
            }
        });
    match layout_and_pipelines {
        Ok((layout, pipelines)) => Ok(GeomipGeometry {
            template,
            indices,
            variants: variants.ranges,
            full_resolution,
            layout,
            pipelines,
            draws: Vec::new(),
            errors,
            given: None,
        }),
        Err(e) => {
            device.destroy_buffer(template);
            device.destroy_buffer(indices);
            Err(e)
        }
    }
}

impl GeomipGeometry {
    /// Levels by distance or error, balanced; the patches `drawn` this
    /// frame become its draws, with their morph factors. Returns the largest
    /// error the error LOD expects on screen.
    fn choose(
        &mut self,
        terrain: &Terrain,
        view: &FrameView,
        settings: &RenderSettings,
        drawn: &[bool],
    ) -> Option<f32> {
        if let Some(chosen) = self.given.take() {
            self.set_draws(terrain, settings, drawn, &chosen);
            self.given = Some(chosen);
            return None;
        }
        let chosen = match settings.lod_metric {
            // The peers' policies are tessellation factors; geomip draws
            // them by distance.
            LodMetric::Distance | LodMetric::Peer(_) => {
                geomip::select_levels_by_distance(terrain, view.eye_local, settings.lod.min_dist)
            }
            LodMetric::Error(pixels) => geomip::select_levels_by_error(
                terrain,
                &self.errors,
                view.eye_local,
                view.pixels_per_radian,
                pixels,
            ),
        };
        self.set_draws(terrain, settings, drawn, &chosen);
        let LodMetric::Error(_) = settings.lod_metric else {
            return None;
        };
        let predicted = geomip::predicted_px(
            terrain,
            &self.errors,
            &chosen,
            view.eye_local,
            view.pixels_per_radian,
            settings.geomorph,
        );
        Some(max_drawn(drawn, &predicted))
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
    fn draw(
        &self,
        rec: &Recorder,
        set: vk::DescriptorSet,
        wireframe: bool,
        draws: &[GeomipDraw],
    ) -> Result<()> {
        rec.bind_graphics(self.pipelines.select(wireframe)?, self.layout, set);
        rec.bind_geometry(self.template.raw, self.indices.raw);
        for draw in draws {
            rec.push_vertex_constants(self.layout, bytemuck::bytes_of(&draw.constants));
            rec.draw_indexed(draw.first, draw.count);
        }
        Ok(())
    }

    /// The patches `drawn` this frame, at their `chosen` levels, become its
    /// draws.
    fn set_draws(
        &mut self,
        terrain: &Terrain,
        settings: &RenderSettings,
        drawn: &[bool],
        chosen: &geomip::PatchLevels,
    ) {
        let grid = terrain.grid();
        self.draws.clear();
        for (p, _) in drawn.iter().enumerate().filter(|&(_, &d)| d) {
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

/// The largest of per-patch `values` over the patches `drawn` (0 if none).
fn max_drawn(drawn: &[bool], values: &[f32]) -> f32 {
    values
        .iter()
        .zip(drawn)
        .filter(|&(_, &d)| d)
        .fold(0.0, |m, (&v, _)| m.max(v))
}

impl TessGeometry {
    /// The full-resolution patches of `choice` that are `drawn` this frame
    /// become its exact draws (geomip level 0, no stitching: every edge
    /// they share is tessellated with a vertex on every sample). Returns
    /// the largest error the choice expects on screen.
    fn set_exact_draws(
        &mut self,
        terrain: &Terrain,
        drawn: &[bool],
        choice: &TessErrorChoice,
        geomip: &GeomipGeometry,
    ) -> f32 {
        let grid = terrain.grid();
        self.exact.clear();
        for (p, _) in drawn.iter().enumerate().filter(|&(_, &d)| d) {
            if !choice.is_full_resolution(p) {
                continue;
            }
            let rect = grid.sample_rect(grid.patch_id(p));
            let (first, count) = geomip.full_resolution_range([rect.cells_x(), rect.cells_z()]);
            self.exact.push(GeomipDraw {
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
        max_drawn(drawn, &choice.predicted_px)
    }
}
