//! `render`, `info` and `generate`.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use glam::DVec3;
use serde::Serialize;

use super::args::{
    parse_color, parse_dvec3, parse_fov, parse_range, parse_samples, with_gpu, FeatureArgs,
    SizeArgs, TerrainArgs,
};
use crate::gpu::Capabilities;
use crate::lod::PeerPolicy;
use crate::output::{save_png, write_atomically};
use crate::render::settings::{measurement_notes, sample_count};
use crate::render::{
    offscreen, with_fallback, HeadlessFrame, LodMetric, RenderPath, RenderSettings,
    RendererOptions, Shading, StreamStats,
};
use crate::render::{ErrorMeasure, FrameFigures};
use crate::render::{LoadTimings, LoadedScene, Loading};
use crate::scene::{Scene, DEFAULT_PIXEL_ERROR};
use crate::terrain::camera::Camera;
use crate::terrain::generate::{generate as generate_heightmap, write_png16, GeneratorParams};
use crate::terrain::grid::validate_cells_per_patch;
use crate::terrain::{DistanceLod, DistanceMode, TerrainInfo};

/// Which way the terrain is drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum PathArg {
    /// Hardware tessellation.
    #[default]
    Tess,
    /// Geomipmapping with stitched edges and geomorphing (no tessellation
    /// shaders needed).
    Geomip,
    /// The full-resolution reference mesh.
    Brute,
}

impl From<PathArg> for RenderPath {
    fn from(p: PathArg) -> Self {
        match p {
            PathArg::Tess => RenderPath::Tess,
            PathArg::Geomip => RenderPath::Geomip,
            PathArg::Brute => RenderPath::Brute,
        }
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum LodArg {
    /// By distance from the eye (the first level reaches --lod-distance's MIN).
    #[default]
    Distance,
    /// By each level's largest error projected to the screen.
    Error,
    /// SaschaWillems/Vulkan terraintessellation: each edge's bounding
    /// sphere on screen over 20 px, times 0.75 (tess path).
    Sphere,
    /// Dupuy's longest-edge-bisection terrain: 7 px edges on screen (tess
    /// path).
    EdgeLength,
    /// CDLOD: distance ranges doubling from --lod-distance's MIN, morphing
    /// over the last third of each (tess path).
    Cdlod,
}

fn positive_pixels(s: &str) -> Result<f32, String> {
    let v = super::args::parse_finite(s)?;
    if v > 0.0 {
        Ok(v as f32)
    } else {
        Err(format!("--pixel-error {s:?} must be positive"))
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum LodModeArg {
    /// Euclidean distance, continuous factors.
    #[default]
    Smooth,
    /// xz max-norm distance, power-of-two factors only.
    Debug,
}

/// Camera, LOD and look: what the window demo and `render` share.
#[derive(clap::Args, Clone, Debug)]
pub struct ViewArgs {
    /// Cells per patch side: a power of two from 2 to 64.
    #[arg(long, value_name = "N")]
    pub cells_per_patch: Option<u32>,

    /// Full tessellation up to MIN from the eye, falling to the lowest at MAX.
    #[arg(long, value_name = "MIN,MAX", value_parser = parse_range)]
    pub lod_distance: Option<(f32, f32)>,

    /// Exponents of the factor range: 2^MINEXP far away, 2^MAXEXP near (0..=6).
    #[arg(long, value_name = "MINEXP,MAXEXP", value_parser = parse_range)]
    pub lod_levels: Option<(f32, f32)>,

    /// How distance becomes a factor.
    #[arg(long, value_enum, default_value_t = LodModeArg::Smooth)]
    pub lod_mode: LodModeArg,

    /// Eye position in world coordinates.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_dvec3, allow_hyphen_values = true)]
    pub eye: Option<DVec3>,

    /// Point the camera looks at.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_dvec3, allow_hyphen_values = true)]
    pub target: Option<DVec3>,

    /// Vertical field of view in degrees.
    #[arg(long, value_name = "DEG", value_parser = parse_fov)]
    pub fov: Option<f32>,

    /// Render path.
    #[arg(long, value_enum, default_value_t = PathArg::Tess)]
    pub path: PathArg,

    /// Draw triangle edges only (needs fillModeNonSolid).
    #[arg(long)]
    pub wireframe: bool,

    /// Colour by tessellation factor.
    #[arg(long, conflicts_with = "flat")]
    pub lod_colors: bool,

    /// Constant white, unlit (for crack inspection).
    #[arg(long)]
    pub flat: bool,

    /// Background colour, components in [0, 1] (drawn flat, without the
    /// sky).
    #[arg(long, value_name = "R,G,B", value_parser = parse_color)]
    pub clear_color: Option<[f32; 3]>,

    /// Samples per pixel: 1 (no anti-aliasing), 2, 4 or 8, as the device
    /// allows. Default: 4 where the device can draw them, otherwise 1.
    #[arg(long, value_name = "N", value_parser = parse_samples)]
    pub samples: Option<u32>,

    /// A flat background of the clear colour instead of the sky.
    #[arg(long)]
    pub no_sky: bool,

    /// Turn GPU frustum culling of patches off.
    #[arg(long)]
    pub no_cull: bool,

    /// How levels are chosen: by distance, or by projected error (the tess
    /// path's factors and the geomip path's levels alike). Default: the
    /// scene's; error at 1 px for a heightmap or a scene that names no LOD
    /// (the default scene uses distance).
    #[arg(long, value_enum)]
    pub lod: Option<LodArg>,

    /// Largest projected error in pixels for the error LOD (implies
    /// --lod error unless --lod says otherwise). Default: the scene's, or 1.
    /// --lod-distance or --lod-levels without --lod imply --lod distance.
    #[arg(long, value_name = "PIXELS", value_parser = positive_pixels)]
    pub pixel_error: Option<f32>,

    /// What the error LOD holds within --pixel-error: `sight` (the
    /// default), the frame's 99th percentile from the terrain's
    /// precomputed view model, chosen in well under a millisecond a frame;
    /// `view`, the same percentile measured sample by sample every frame
    /// (hidden ground included): fewer triangles for stills, at 20 ms to
    /// 4 s of CPU a frame on 1025^2 to 4097^2 terrains; `bound`, every
    /// patch's largest vertical error, face-on from its nearest point.
    /// Streamed terrains use `bound`.
    #[arg(long, value_enum, default_value_t = ErrorMeasureArg::Sight)]
    pub error_measure: ErrorMeasureArg,

    /// Geomip path: switch levels abruptly instead of geomorphing.
    #[arg(long)]
    pub no_morph: bool,

    /// Occlusion culling of patches hidden behind nearer terrain (tess and
    /// geomip paths): on where the device can sample depth attachments.
    #[arg(long, value_enum, default_value_t = Switch::On)]
    pub occlusion: Switch,

    /// Tess path, error LOD: draw blocks of patches whose every factor is
    /// 1 as one larger patch (merged nodes, up to 64x64 patches).
    #[arg(long, value_enum, default_value_t = Switch::On)]
    pub merge_patches: Switch,

    #[command(flatten)]
    pub features: FeatureArgs,
}

/// `--error-measure`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum ErrorMeasureArg {
    #[default]
    Sight,
    View,
    Bound,
}

/// An option turned on or off.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum Switch {
    #[default]
    On,
    Off,
}

impl ViewArgs {
    /// Applies the patch and LOD options to a scene (the camera options
    /// apply once the terrain is loaded: see `camera_override`).
    pub fn apply_to_scene(&self, scene: &mut Scene) -> Result<()> {
        if let Some(n) = self.cells_per_patch {
            validate_cells_per_patch(n)?;
            scene.cells_per_patch = n;
        }
        // Checked here, applied by `settings` over the terrain's distances.
        self.distance_overrides(DistanceLod::default()).validate()?;
        Ok(())
    }

    /// `lod` with --lod-distance and --lod-levels applied.
    fn distance_overrides(&self, lod: DistanceLod) -> DistanceLod {
        let mut lod = lod;
        if let Some((min, max)) = self.lod_distance {
            lod.min_dist = min;
            lod.max_dist = max;
        }
        if let Some((min, max)) = self.lod_levels {
            lod.min_exp = min;
            lod.max_exp = max;
        }
        lod
    }

    pub fn camera_override(&self) -> CameraOverride {
        CameraOverride {
            eye: self.eye,
            target: self.target,
            fov: self.fov,
        }
    }

    /// The scene's settings for its terrain, with these options applied.
    pub fn settings(&self, scene: &Scene, info: &TerrainInfo) -> RenderSettings {
        let base = RenderSettings::for_scene(scene, info);
        let pixels = self
            .pixel_error
            .or(scene.pixel_error)
            .unwrap_or(DEFAULT_PIXEL_ERROR);
        let lod_metric = match (self.lod, self.pixel_error) {
            (Some(LodArg::Distance), _) => LodMetric::Distance,
            (Some(LodArg::Sphere), _) => LodMetric::Peer(PeerPolicy::Sphere),
            (Some(LodArg::EdgeLength), _) => LodMetric::Peer(PeerPolicy::EdgeLength),
            (Some(LodArg::Cdlod), _) => LodMetric::Peer(PeerPolicy::Cdlod),
            (Some(LodArg::Error), _) | (None, Some(_)) => LodMetric::Error(pixels),
            // Distances on the command line ask for the distance LOD.
            (None, None) if self.lod_distance.is_some() || self.lod_levels.is_some() => {
                LodMetric::Distance
            }
            (None, None) => base.lod_metric,
        };
        RenderSettings {
            path: self.path.into(),
            lod_mode: match self.lod_mode {
                LodModeArg::Smooth => DistanceMode::Smooth,
                LodModeArg::Debug => DistanceMode::Debug,
            },
            shading: if self.flat {
                Shading::Flat
            } else if self.lod_colors {
                Shading::LodColors
            } else {
                Shading::Lit
            },
            wireframe: self.wireframe,
            clear_color: self.clear_color.unwrap_or(if self.flat {
                [0.0; 3]
            } else {
                base.clear_color
            }),
            // A colour of one's own, or flat white, asks for a flat
            // background.
            sky: base.sky && !self.no_sky && !self.flat && self.clear_color.is_none(),
            cull: !self.no_cull,
            occlusion: self.occlusion == Switch::On,
            merge_patches: self.merge_patches == Switch::On,
            geomorph: !self.no_morph,
            error_measure: match self.error_measure {
                ErrorMeasureArg::Sight => ErrorMeasure::Sight,
                ErrorMeasureArg::View => ErrorMeasure::View,
                ErrorMeasureArg::Bound => ErrorMeasure::Bound,
            },
            lod_metric,
            lod: self.distance_overrides(base.lod),
            ..base
        }
    }
}

/// Camera options given on the command line, applied over the scene's
/// camera (or its overview camera).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraOverride {
    pub eye: Option<DVec3>,
    pub target: Option<DVec3>,
    pub fov: Option<f32>,
}

impl CameraOverride {
    pub fn apply(&self, base: Camera) -> Result<Camera> {
        let camera = Camera {
            eye: self.eye.unwrap_or(base.eye),
            target: self.target.unwrap_or(base.target),
            fov_y_deg: self.fov.unwrap_or(base.fov_y_deg),
        };
        if camera.eye == camera.target {
            bail!(
                "the camera's eye and target are the same point {}",
                camera.eye
            );
        }
        Ok(camera)
    }
}

#[derive(clap::Args, Debug)]
pub struct RenderCmd {
    #[command(flatten)]
    pub terrain: TerrainArgs,

    #[command(flatten)]
    pub view: ViewArgs,

    #[command(flatten)]
    pub size: SizeArgs,

    /// Where to write the PNG.
    #[arg(long, value_name = "PATH")]
    pub out: PathBuf,

    /// Where to write frame statistics as JSON.
    #[arg(long, value_name = "PATH")]
    pub stats: Option<PathBuf>,

    /// Turn on the Vulkan validation layer (also VKTERRAIN_VALIDATE=1).
    #[arg(long)]
    pub validate: bool,
}

/// stats.json: what a frame cost and what it drew. Figures a device cannot
/// measure are null, never zero.
#[derive(Serialize, Debug, Clone, PartialEq)]
pub struct FrameStats {
    pub device: String,
    pub driver: String,
    pub path: RenderPath,
    /// How levels were chosen, with the error LOD's tolerance.
    pub lod: LodMetric,
    pub width: u32,
    pub height: u32,
    /// Samples per pixel.
    pub samples: u32,
    pub patches_total: usize,
    pub patches_in_frustum: usize,
    /// Of those, the patches the tess path's error LOD drew at full
    /// resolution without the control shader.
    pub patches_full_resolution: usize,
    /// Merged nodes the tess path's error LOD drew, each one patch for a
    /// block of patches (`lod::patch_merge`).
    pub merged_nodes: usize,
    #[serde(flatten)]
    pub figures: FrameFigures,
    pub tcs_patches: Option<u64>,
    pub vertex_invocations: Option<u64>,
    pub clipping_invocations: Option<u64>,
    /// Whether the frame was drawn with occlusion culling (two passes).
    pub occlusion: bool,
    /// Patches in view that occlusion culling hid (null without it).
    pub patches_occluded: Option<u32>,
    /// GPU milliseconds of building the depth pyramid and testing the
    /// patches, part of `gpu_ms` (null without occlusion culling).
    pub culling_gpu_ms: Option<f64>,
    /// The largest error the error LOD's choice expects on screen, in
    /// pixels; null for the distance LOD and brute.
    pub predicted_max_px: Option<f32>,
    /// The frame's 99th percentile error the error LOD's choice expects,
    /// in pixels; null where the view was not measured.
    pub predicted_p99_px: Option<f32>,
    /// The share of the terrain's pixels the view model puts over tau at
    /// the levels chosen; null where the error LOD did not read the model.
    pub predicted_over_share: Option<f32>,
    /// What streaming did for the frame (null for a terrain uploaded
    /// whole): tiles resident, uploaded, evicted, and the largest error a
    /// tile drawn from the base level adds.
    pub stream: Option<StreamStats>,
    pub gpu_memory_bytes: u64,
    pub gpu_memory: BTreeMap<String, u64>,
    pub validation_enabled: bool,
    pub validation_messages: u32,
    pub eye: [f64; 3],
    pub target: [f64; 3],
    pub fov_deg: f32,
    pub startup: StartupStats,
}

/// Where the time before the first frame went, in milliseconds.
#[derive(Serialize, Debug, Clone, Copy, Default, PartialEq)]
pub struct StartupStats {
    /// Reading and decoding the heightmap.
    pub load_ms: f64,
    /// Reading the textures, building their mip chains and baking the
    /// lightmap.
    pub material_ms: f64,
    /// Per-patch Y bounds and control points.
    pub bounds_ms: f64,
    /// The per-patch error tables, and the view model where the frame's
    /// LOD reads it.
    pub error_table_ms: f64,
    /// Uploads to the GPU and pipeline creation (the rest of building the
    /// renderer).
    pub gpu_setup_ms: f64,
    /// Resident memory of the process after the first frame, in bytes
    /// (Linux; 0 where unknown).
    pub resident_bytes: u64,
}

/// Resident set size of this process: VmRSS in /proc/self/status (Linux).
pub fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let kib: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())?;
    Some(kib * 1024)
}

/// The picture a render makes: its size, and its samples per pixel (None:
/// `render::DEFAULT_SAMPLES` where the device can draw them).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Picture {
    pub width: u32,
    pub height: u32,
    pub samples: Option<u32>,
    /// Stream a tiled terrain (rather than upload it whole).
    pub stream: bool,
}

/// Everything one headless render produces.
pub struct RenderOutput {
    pub frame: HeadlessFrame,
    pub stats: FrameStats,
    /// What changed from what was asked for, and why (fallbacks).
    pub notes: Vec<String>,
}

/// Renders one frame of `scene` headless, with the settings `view` gives
/// for its terrain: builds the GPU objects, draws, reads back, and tears
/// everything down again, counting validation messages after the device
/// is destroyed (any fails the render).
///
/// `view` gives the camera and settings for the loaded terrain; the GPU is
/// opened with `gpu`.
pub fn render_scene(
    scene: &Scene,
    view: impl FnOnce(&TerrainInfo) -> Result<(Camera, RenderSettings)>,
    picture: Picture,
    gpu: &crate::gpu::GpuOptions,
) -> Result<RenderOutput> {
    let Picture { width, height, .. } = picture;
    let ms = |t: std::time::Instant| t.elapsed().as_secs_f64() * 1e3;
    let LoadedScene {
        terrain,
        appearance,
        stream,
        timings,
    } = LoadedScene::load(
        scene,
        Loading {
            stream: picture.stream,
            appearance: true,
        },
    )?;
    let (camera, settings) = view(terrain.info())?;
    let LoadTimings {
        terrain_ms: load_ms,
        appearance_ms: material_ms,
        model_ms: bounds_ms,
    } = timings;
    let ((frame, mut stats, notes), validation) = with_gpu(gpu, |gpu| {
        let mut notes = Vec::new();
        let settings = &with_fallback(settings, &gpu.device.caps, &mut notes);
        let caps = &gpu.device.caps;
        notes.extend(measurement_notes(caps, &appearance));
        let samples = sample_count(picture.samples, caps, &mut notes)?;
        let started = std::time::Instant::now();
        let options = RendererOptions {
            paths: vec![settings.path],
            wireframe: settings.wireframe,
            samples,
            stream,
        };
        let (mut renderer, mut headless) =
            offscreen(gpu, &terrain, &appearance, &options, (width, height))
                .context("preparing the terrain for the GPU")?;
        // Before the frame, so that its CPU time is the frame's alone.
        renderer.build_view_model(&terrain, settings);
        let error_table_ms = renderer.error_table_ms();
        let gpu_setup_ms = ms(started) - error_table_ms;
        let frame = headless
            .render(&mut renderer, &terrain, &camera, settings)
            .context("rendering")?;
        // Memory is reported while everything is still allocated.
        let gpu_memory: BTreeMap<String, u64> = gpu.device.memory_report().into_iter().collect();
        let statistics = frame.measurements.statistics;
        let stats = FrameStats {
            device: caps.device_name.clone(),
            driver: format!("{} ({})", caps.driver_name, caps.driver_info),
            path: settings.path,
            lod: settings.lod_metric,
            width,
            height,
            samples,
            patches_total: terrain.grid().patch_count(),
            patches_in_frustum: frame.patches_in_frustum,
            patches_full_resolution: renderer.full_resolution_patches(),
            merged_nodes: renderer.merged_nodes(),
            figures: frame.figures(),
            tcs_patches: statistics.map(|s| s.tcs_patches),
            vertex_invocations: statistics.map(|s| s.vertex_invocations),
            clipping_invocations: statistics.map(|s| s.clipping_invocations),
            occlusion: frame.measurements.occlusion.is_some(),
            patches_occluded: frame.measurements.occlusion.map(|o| o.patches_occluded),
            culling_gpu_ms: frame.measurements.occlusion.and_then(|o| o.culling_ms),
            predicted_max_px: renderer.predicted_max_px(),
            predicted_p99_px: renderer.predicted_p99_px(),
            predicted_over_share: renderer.predicted_over_share(),
            stream: renderer.stream_stats(),
            gpu_memory_bytes: gpu_memory.values().sum(),
            gpu_memory,
            // Set from the report once the device is gone.
            validation_enabled: false,
            validation_messages: 0,
            eye: camera.eye.to_array(),
            target: camera.target.to_array(),
            fov_deg: camera.fov_y_deg,
            startup: StartupStats {
                load_ms,
                material_ms,
                bounds_ms,
                error_table_ms,
                gpu_setup_ms,
                resident_bytes: resident_bytes().unwrap_or(0),
            },
        };
        Ok((frame, stats, notes))
    })?;
    stats.validation_enabled = validation.enabled;
    stats.validation_messages = validation.count;
    Ok(RenderOutput {
        frame,
        stats,
        notes,
    })
}

pub fn render(cmd: RenderCmd, out: &mut dyn Write) -> Result<()> {
    let mut scene = cmd.terrain.scene()?;
    cmd.view.apply_to_scene(&mut scene)?;
    let view = &cmd.view;
    let output = render_scene(
        &scene,
        |info| {
            let camera = view.camera_override().apply(scene.camera_for(info))?;
            Ok((camera, view.settings(&scene, info)))
        },
        Picture {
            width: cmd.size.width,
            height: cmd.size.height,
            samples: view.samples,
            stream: !view.features.no_streaming,
        },
        &view.features.gpu_options(cmd.validate),
    )?;
    for note in &output.notes {
        writeln!(out, "{note}")?;
    }
    save_png(&output.frame.rgba_image(), &cmd.out)?;
    if let Some(path) = &cmd.stats {
        let json = serde_json::to_string_pretty(&output.stats)?;
        write_atomically(path, |tmp| {
            std::fs::write(tmp, json + "\n")
                .with_context(|| format!("{}: cannot write stats", path.display()))
        })?;
    }
    let s = &output.stats;
    let figure = |v: Option<u64>| v.map_or("n/a".to_string(), |v| v.to_string());
    writeln!(
        out,
        "wrote {} ({}x{}): {} triangles, {} of {} patches in view, GPU {}, CPU {:.2} ms, {} validation messages",
        cmd.out.display(),
        s.width,
        s.height,
        figure(s.figures.triangles),
        s.patches_in_frustum,
        s.patches_total,
        s.figures.gpu_ms.map_or("n/a".into(), |ms| format!("{ms:.2} ms")),
        s.figures.cpu_ms,
        s.validation_messages,
    )?;
    Ok(())
}

/// Where the bare command writes the default scene.
pub const DEFAULT_OUTPUT: &str = "vkterrain-default.png";

#[derive(clap::Args, Debug)]
pub struct InfoCmd {
    /// Turn on the Vulkan validation layer.
    #[arg(long)]
    pub validate: bool,

    #[command(flatten)]
    pub features: FeatureArgs,
}

#[derive(Serialize)]
struct InfoReport<'a> {
    device: &'a Capabilities,
    used: Vec<&'static str>,
    missing: Vec<&'static str>,
    validation: bool,
}

pub fn info(cmd: InfoCmd, out: &mut dyn Write) -> Result<()> {
    let ((caps, validation), _) = cmd.features.with_gpu(cmd.validate, |gpu| {
        Ok((gpu.device.caps.clone(), gpu.validation_enabled()))
    })?;
    let caps = &caps;
    let optional = [
        (
            "tessellationShader (the tess path; geomip otherwise)",
            caps.tessellation_shader,
        ),
        ("fillModeNonSolid (wireframe)", caps.fill_mode_non_solid),
        (
            "pipelineStatisticsQuery (triangle counts)",
            caps.pipeline_statistics_query,
        ),
        (
            "samplerAnisotropy (texture filtering)",
            caps.sampler_anisotropy,
        ),
        ("timestamps (GPU time)", caps.timestamp_period_ns.is_some()),
        (
            "sampled depth attachments (occlusion culling)",
            !caps.occlusion_sample_counts.is_empty(),
        ),
        (
            "multiDrawIndirect (a frame's patch batches in one draw call)",
            caps.multi_draw_indirect,
        ),
    ];
    let mut used = vec!["dynamicRendering", "synchronization2"];
    used.extend(optional.iter().filter(|o| o.1).map(|o| o.0));
    let missing = optional.iter().filter(|o| !o.1).map(|o| o.0).collect();
    let report = InfoReport {
        device: caps,
        used,
        missing,
        validation,
    };
    serde_json::to_writer_pretty(&mut *out, &report)?;
    writeln!(out)?;
    Ok(())
}

#[derive(clap::Args, Debug)]
pub struct GenerateCmd {
    /// Samples per side.
    #[arg(long, default_value_t = GeneratorParams::default().size)]
    pub size: usize,
    /// Noise seed.
    #[arg(long, default_value_t = GeneratorParams::default().seed)]
    pub seed: u64,
    /// Raindrops simulated by the erosion pass (default 250000; over
    /// 8193 samples a side, 0.02 per sample).
    #[arg(long)]
    pub droplets: Option<u32>,
    /// Where to write it: a 16-bit PNG, or, for a path ending in .vkt, a
    /// tiled terrain (`import`'s format), which sizes over 8193 need: they
    /// are generated a band of rows at a time, never whole.
    #[arg(long, value_name = "PATH")]
    pub out: PathBuf,
    /// Cells per tile side of a tiled output.
    #[arg(long, value_name = "N", default_value_t = crate::terrain::tiled::DEFAULT_TILE_CELLS)]
    pub tile: u32,
    /// Patch size whose error tables a tiled output stores [default: 32,
    /// or 64 past 8193 samples a side].
    #[arg(long, value_name = "N")]
    pub cells_per_patch: Option<u32>,
    /// Height of the top of the range in a tiled output (its heights are
    /// fixed when written); a PNG holds 0 to 1, scaled when loaded.
    #[arg(long, value_name = "S", value_parser = super::args::parse_finite)]
    pub height_scale: Option<f64>,
}

/// Largest side of a generated PNG (held whole) and of a tiled output.
const MAX_PNG_SIZE: usize = 16385;
const MAX_TILED_SIZE: usize = 65537;

pub fn generate(cmd: GenerateCmd, out: &mut dyn Write) -> Result<()> {
    use crate::terrain::generate::{BandedRows, BANDED_DROPLETS_PER_SAMPLE, WHOLE_MAX_SIZE};
    use crate::terrain::tiled::{self, IntegerMapping, MemoryRows, RowSource};
    let tiled_out = cmd
        .out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("vkt"));
    let max = if tiled_out {
        MAX_TILED_SIZE
    } else {
        MAX_PNG_SIZE
    };
    if !(2..=max).contains(&cmd.size) {
        bail!(
            "--size {} is outside 2..={max}{}",
            cmd.size,
            if tiled_out {
                ""
            } else {
                " for a PNG (write a tiled .vkt for larger)"
            }
        );
    }
    if !tiled_out {
        if cmd.height_scale.is_some() {
            bail!("--height-scale applies to a tiled (.vkt) output; a PNG's heights are scaled when it is loaded");
        }
        let map = generate_heightmap(&GeneratorParams {
            size: cmd.size,
            seed: cmd.seed,
            droplets: cmd.droplets.unwrap_or(GeneratorParams::default().droplets),
        })?;
        write_atomically(&cmd.out, |tmp| {
            write_png16(&map, tmp)
                .with_context(|| format!("{}: cannot write PNG", cmd.out.display()))
        })?;
        writeln!(
            out,
            "wrote {} ({}x{})",
            cmd.out.display(),
            cmd.size,
            cmd.size
        )?;
        return Ok(());
    }
    tiled::validate_tile_cells(cmd.tile)?;
    if let Some(n) = cmd.cells_per_patch {
        crate::terrain::grid::validate_cells_per_patch(n)?;
    }
    let cells_per_patch = cmd
        .cells_per_patch
        .unwrap_or_else(|| crate::terrain::info::stored_cells_per_patch(cmd.size, cmd.size));
    let height_scale = cmd.height_scale.unwrap_or(1.0);
    let mapping = IntegerMapping {
        scale: height_scale,
        divisor: 65535.0,
        offset: 0.0,
    };
    let mut source: Box<dyn RowSource> = if cmd.size <= WHOLE_MAX_SIZE {
        // The same map as the PNG, quantised the same way.
        let map = generate_heightmap(&GeneratorParams {
            size: cmd.size,
            seed: cmd.seed,
            droplets: cmd.droplets.unwrap_or(GeneratorParams::default().droplets),
        })?;
        let heights = map
            .heights()
            .iter()
            .map(|&h| mapping.height((f64::from(h.clamp(0.0, 1.0)) * 65535.0).round() as i64))
            .collect();
        let map = crate::terrain::Heightmap::from_heights(cmd.size, cmd.size, heights)?;
        Box::new(MemoryRows::new(map, Some(mapping)))
    } else {
        let density = cmd.droplets.map_or(BANDED_DROPLETS_PER_SAMPLE, |d| {
            f64::from(d) / (cmd.size as f64 * cmd.size as f64)
        });
        Box::new(BandedRows::new(cmd.size, cmd.seed, density, height_scale))
    };
    let bar = super::progress::progress_bar(cmd.size as u64, "rows");
    let mut report = None;
    write_atomically(&cmd.out, |tmp| {
        report = Some(
            tiled::import(
                source.as_mut(),
                cmd.tile,
                Some(cells_per_patch),
                tmp,
                &mut |done, _| bar.set_position(done),
            )
            .with_context(|| format!("{}: generation failed", cmd.out.display()))?,
        );
        Ok(())
    })?;
    bar.finish_and_clear();
    let report = report.expect("written");
    writeln!(
        out,
        "wrote {} ({}x{}, tiled: {}-cell tiles, {} bytes, {:.2} bytes per sample, {:.1} s)",
        cmd.out.display(),
        cmd.size,
        cmd.size,
        cmd.tile,
        report.file_bytes,
        report.bytes_per_sample,
        report.seconds
    )?;
    Ok(())
}
