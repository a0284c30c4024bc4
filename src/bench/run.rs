//! The benchmark run: every configuration rendered from the same cameras,
//! timed by GPU timestamps, counted by pipeline statistics, and measured
//! against the brute path's render of the same frame.

use glam::DMat4;
use serde::{Deserialize, Serialize};

use super::cameras::{flythrough, named_views, FLYTHROUGH};
use super::error::{differing_pixels, pixel_errors, DepthView, ErrorHistogram};
use crate::gpu::target::OFFSCREEN_COLOR_FORMAT;
use crate::gpu::Gpu;
use crate::lod::geomip;
use crate::lod::{PeerLod, PeerPolicy};
use crate::render::figures::{mean_count, median, FrameFigures};
use crate::render::{
    ErrorMeasure, Headless, HeadlessFrame, LodMetric, RenderPath, RenderSettings, RendererOptions,
    Shading, TerrainRenderer, TimedFrame,
};
use crate::terrain::camera::Camera;
use crate::terrain::{DistanceLod, Terrain};

/// Pixel tolerances of the error-driven configurations.
pub const TAUS: [f32; 6] = [0.25, 0.5, 1.0, 2.0, 4.0, 8.0];
/// `--quick`'s shorter list.
pub const QUICK_TAUS: [f32; 3] = [0.5, 1.0, 2.0];
/// The tolerance of the error modes run with occlusion culling (its
/// counterparts without are in both tau lists).
pub const OCCLUSION_TAU: f32 = 1.0;
/// The tolerance of the error modes run with the view measure, beside the
/// real-time choice's rows at the same tolerance.
pub const VIEW_MEASURE_TAU: f32 = 1.0;
/// Frames timed per named view, after `WARM_UP` untimed ones, unless told
/// otherwise (`BenchOptions::timed_frames`).
pub const TIMED_FRAMES: usize = 10;
pub const WARM_UP: usize = 2;
/// Times the flythrough's loop is flown. The first pass reads every frame
/// back and measures it; the others only time it. A row's time for each
/// frame is its median over the passes, and the row's the median over
/// its frames. A frame's cost differs from the next one's, so a single
/// slow draw would otherwise move the row's median by a rank or two: on a
/// 2-core machine running lavapipe, a one-pass run drew three or four of
/// twenty frames 14 to 25 ms slower in one row than in another row making
/// the same draws.
pub const FLYTHROUGH_PASSES: usize = 3;

/// Untimed frames a fixed view's single timed frame follows, for a row
/// whose choice reads earlier frames of its view (`render::seen`): the
/// view's first frame counts nothing, the second counts, the third reads
/// that and counts again, and the timed frame reads both.
pub const STILL_FRAMES: usize = 3;
/// How long `--single-frame` goes on timing a fixed view's row after the
/// frame it reads back: frames of the same row are drawn back to back, up
/// to the run's timed frames in all (`BenchOptions::timed_frames`,
/// `SINGLE_FRAME_TIMED_FRAMES` unless told otherwise), until this long
/// after that frame began. A device that draws the row in a few
/// milliseconds times it by a median, as a full run does; a frame that
/// takes longer (brute's 33.5 M triangles on lavapipe) is timed once.
pub const SINGLE_FRAME_TIMING: std::time::Duration = std::time::Duration::from_millis(2500);
/// Frames `--single-frame` times per row unless told otherwise. A row's
/// frames there are drawn back to back, so one slow stretch of the machine
/// moves a short run's median: with up to 10 frames within 500 ms (about 6
/// of a 75 ms frame), the 4097^2 valley's tess row at 1 px came to 1.17x to
/// 1.36x its fastest row in seven runs; with up to 30 within 2.5 s, 1.25x,
/// 1.26x and 1.25x in three (notes section 64).
pub const SINGLE_FRAME_TIMED_FRAMES: usize = 30;
/// Share of a patch's pixels the oracle lets exceed tau (its per-patch
/// 99th percentile is then at most tau).
pub const ORACLE_EXCEED_FRACTION: f64 = 0.01;

/// One way of drawing the terrain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Config {
    /// Every sample a vertex: the reference.
    Brute,
    /// Tessellation factors by distance.
    TessDistance(DistanceLod),
    /// Tessellation factors bounding the projected error to tau pixels.
    TessError(f32),
    /// A peer's LOD policy with its published parameters
    /// (`lod::PeerLod`); CDLOD's ranges start at the scene's first
    /// LOD distance.
    TessPeer(PeerPolicy),
    /// Geomip levels by distance, the first level reaching this far.
    GeomipDistance(f32),
    /// Geomip levels bounding the projected error to tau pixels.
    GeomipError(f32),
    /// Per patch, the coarsest uniform level whose measured error is within
    /// tau pixels (see `oracle_levels`).
    Oracle(f32),
    /// `TessError` with occlusion culling.
    TessErrorOccluded(f32),
    /// `GeomipError` with occlusion culling.
    GeomipErrorOccluded(f32),
    /// `TessError` with the view measured sample by sample every frame
    /// (`--error-measure view`).
    TessErrorView(f32),
    /// `GeomipError` with the view measured sample by sample.
    GeomipErrorView(f32),
}

/// How a row was drawn: a render path, or the oracle (geomip levels from
/// measured error).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RowPath {
    Brute,
    Tess,
    Geomip,
    Oracle,
}

/// How a row chose levels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RowLod {
    Distance,
    Error,
    /// The error LOD with the view measured sample by sample every frame.
    ErrorView,
    /// A peer's policy, by `PeerPolicy::name`.
    Sphere,
    EdgeLength,
    Cdlod,
}

impl RowPath {
    pub fn name(self) -> &'static str {
        match self {
            RowPath::Brute => "brute",
            RowPath::Tess => "tess",
            RowPath::Geomip => "geomip",
            RowPath::Oracle => "oracle",
        }
    }
}

impl RowLod {
    pub fn name(self) -> &'static str {
        match self {
            RowLod::Distance => "distance",
            RowLod::Error => "error",
            RowLod::ErrorView => "error-view",
            RowLod::Sphere => PeerPolicy::Sphere.name(),
            RowLod::EdgeLength => PeerPolicy::EdgeLength.name(),
            RowLod::Cdlod => PeerPolicy::Cdlod.name(),
        }
    }
}

impl Config {
    pub fn path(&self) -> RowPath {
        match self {
            Config::Brute => RowPath::Brute,
            Config::TessDistance(_)
            | Config::TessError(_)
            | Config::TessPeer(_)
            | Config::TessErrorOccluded(_)
            | Config::TessErrorView(_) => RowPath::Tess,
            Config::GeomipDistance(_)
            | Config::GeomipError(_)
            | Config::GeomipErrorOccluded(_)
            | Config::GeomipErrorView(_) => RowPath::Geomip,
            Config::Oracle(_) => RowPath::Oracle,
        }
    }

    pub fn lod(&self) -> Option<RowLod> {
        match self {
            Config::Brute | Config::Oracle(_) => None,
            Config::TessDistance(_) | Config::GeomipDistance(_) => Some(RowLod::Distance),
            Config::TessError(_)
            | Config::GeomipError(_)
            | Config::TessErrorOccluded(_)
            | Config::GeomipErrorOccluded(_) => Some(RowLod::Error),
            Config::TessErrorView(_) | Config::GeomipErrorView(_) => Some(RowLod::ErrorView),
            Config::TessPeer(PeerPolicy::Sphere) => Some(RowLod::Sphere),
            Config::TessPeer(PeerPolicy::EdgeLength) => Some(RowLod::EdgeLength),
            Config::TessPeer(PeerPolicy::Cdlod) => Some(RowLod::Cdlod),
        }
    }

    pub fn tau(&self) -> Option<f32> {
        match *self {
            Config::TessError(t)
            | Config::GeomipError(t)
            | Config::Oracle(t)
            | Config::TessErrorOccluded(t)
            | Config::GeomipErrorOccluded(t)
            | Config::TessErrorView(t)
            | Config::GeomipErrorView(t) => Some(t),
            _ => None,
        }
    }

    /// Whether the row's level choice reads what earlier frames of its
    /// view counted (`render::seen`): the tess path's error LOD.
    pub fn reads_earlier_frames(&self) -> bool {
        matches!(self, Config::TessError(_) | Config::TessErrorOccluded(_))
    }

    /// Whether the row is drawn with occlusion culling.
    pub fn occlusion(&self) -> bool {
        matches!(
            self,
            Config::TessErrorOccluded(_) | Config::GeomipErrorOccluded(_)
        )
    }

    /// The same configuration without occlusion culling (for an occluded
    /// one), whose image it must equal.
    pub fn unoccluded(&self) -> Option<Config> {
        match *self {
            Config::TessErrorOccluded(t) => Some(Config::TessError(t)),
            Config::GeomipErrorOccluded(t) => Some(Config::GeomipError(t)),
            _ => None,
        }
    }

    /// Whether `configs` hold an occluded row of this configuration,
    /// which is compared with its images.
    pub fn has_occluded_row(&self, configs: &[Config]) -> bool {
        configs.iter().any(|c| c.unoccluded() == Some(*self))
    }

    /// Whether a fixed view's first frame of this configuration is drawn
    /// apart and compared: an occluded row's (a camera cut) and its
    /// counterpart's.
    pub fn draws_cut_frame(&self, configs: &[Config]) -> bool {
        self.occlusion() || self.has_occluded_row(configs)
    }

    /// A short description naming every parameter.
    pub fn label(&self) -> String {
        match self {
            Config::Brute => "brute".into(),
            Config::TessDistance(l) => format!(
                "tess distance {}-{} m, factors 2^{}-2^{}",
                l.min_dist, l.max_dist, l.min_exp, l.max_exp
            ),
            Config::TessError(t) => format!("tess error {t} px"),
            Config::TessPeer(PeerPolicy::Sphere) => {
                let p = PeerLod::default();
                format!(
                    "tess SaschaWillems sphere {} px x {}",
                    p.sphere_edge_px, p.sphere_factor
                )
            }
            Config::TessPeer(PeerPolicy::EdgeLength) => {
                format!("tess Dupuy edge {} px", PeerLod::default().edge_target_px)
            }
            Config::TessPeer(PeerPolicy::Cdlod) => "tess CDLOD".into(),
            Config::GeomipDistance(d) => format!("geomip distance {d} m"),
            Config::GeomipError(t) => format!("geomip error {t} px"),
            Config::Oracle(t) => format!("oracle {t} px"),
            Config::TessErrorOccluded(t) => format!("tess error {t} px + occlusion"),
            Config::GeomipErrorOccluded(t) => format!("geomip error {t} px + occlusion"),
            Config::TessErrorView(t) => format!("tess error {t} px, view measure"),
            Config::GeomipErrorView(t) => format!("geomip error {t} px, view measure"),
        }
    }

    fn render_path(&self) -> RenderPath {
        match self {
            Config::Brute => RenderPath::Brute,
            Config::TessDistance(_)
            | Config::TessError(_)
            | Config::TessPeer(_)
            | Config::TessErrorOccluded(_)
            | Config::TessErrorView(_) => RenderPath::Tess,
            _ => RenderPath::Geomip,
        }
    }

    fn settings(&self, scene_lod: DistanceLod) -> RenderSettings {
        let base = RenderSettings {
            path: self.render_path(),
            lod: scene_lod,
            shading: Shading::Lit,
            geomorph: true,
            cull: true,
            occlusion: self.occlusion(),
            ..RenderSettings::default()
        };
        match *self {
            Config::Brute => base,
            Config::TessDistance(lod) => RenderSettings { lod, ..base },
            Config::TessError(t)
            | Config::GeomipError(t)
            | Config::TessErrorOccluded(t)
            | Config::GeomipErrorOccluded(t) => RenderSettings {
                lod_metric: LodMetric::Error(t),
                ..base
            },
            Config::TessErrorView(t) | Config::GeomipErrorView(t) => RenderSettings {
                lod_metric: LodMetric::Error(t),
                error_measure: ErrorMeasure::View,
                ..base
            },
            Config::TessPeer(policy) => RenderSettings {
                lod_metric: LodMetric::Peer(policy),
                ..base
            },
            Config::GeomipDistance(d) => RenderSettings {
                lod: DistanceLod {
                    min_dist: d,
                    ..scene_lod
                },
                ..base
            },
            Config::Oracle(_) => RenderSettings {
                geomorph: false,
                ..base
            },
        }
    }
}

/// The configurations of a run, brute first. The distance sweeps scale the
/// scene's LOD distances; `tessellation` false leaves the tess path out.
pub fn configs(scene_lod: DistanceLod, quick: bool, tessellation: bool) -> Vec<Config> {
    let scaled = |s: f32, min_exp: f32| DistanceLod {
        min_dist: scene_lod.min_dist * s,
        max_dist: scene_lod.max_dist * s,
        min_exp,
        max_exp: scene_lod.max_exp,
    };
    let taus: &[f32] = if quick { &QUICK_TAUS } else { &TAUS };
    let mut configs = vec![Config::Brute];
    if tessellation {
        let sweep: &[(f32, f32)] = if quick {
            &[(0.5, 0.0), (1.0, 0.0), (4.0, 0.0)]
        } else {
            &[
                (0.25, 0.0),
                (0.5, 0.0),
                (1.0, 0.0),
                (2.0, 0.0),
                (4.0, 0.0),
                (8.0, 0.0),
                (1.0, 2.0),
                (4.0, 2.0),
            ]
        };
        configs.extend(sweep.iter().map(|&(s, e)| {
            Config::TessDistance(scaled(s, e.max(scene_lod.min_exp).min(scene_lod.max_exp)))
        }));
        configs.extend(taus.iter().map(|&t| Config::TessError(t)));
        configs.extend(PeerPolicy::ALL.map(Config::TessPeer));
        configs.push(Config::TessErrorOccluded(OCCLUSION_TAU));
        configs.push(Config::TessErrorView(VIEW_MEASURE_TAU));
    }
    let geomip_scales: &[f32] = if quick { &[1.0] } else { &[0.5, 1.0, 2.0, 4.0] };
    configs.extend(
        geomip_scales
            .iter()
            .map(|&s| Config::GeomipDistance(scene_lod.min_dist * s)),
    );
    configs.extend(taus.iter().map(|&t| Config::GeomipError(t)));
    configs.extend(taus.iter().map(|&t| Config::Oracle(t)));
    configs.push(Config::GeomipErrorOccluded(OCCLUSION_TAU));
    configs.push(Config::GeomipErrorView(VIEW_MEASURE_TAU));
    configs
}

/// What the run covers.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchOptions {
    pub width: u32,
    pub height: u32,
    /// One view and a short sweep.
    pub quick: bool,
    /// Frames of the flythrough (0: none).
    pub flythrough_frames: usize,
    /// Each named view rendered and measured once, without warm-up, and
    /// timed by that frame and the frames drawn straight after it within
    /// `SINGLE_FRAME_TIMING`: for terrains whose brute frame takes seconds
    /// on a CPU rasteriser.
    pub single_frame: bool,
    /// Only these views (named views and the flythrough); empty: all of
    /// them (the first named view alone with `quick`).
    pub views: Vec<String>,
    /// Before each timed frame of a fixed view, the same frame is drawn
    /// untimed for this long, so that a GPU that lowers its clock when
    /// lightly loaded draws the timed one at the clock a busy application
    /// would see (0: not drawn).
    pub gpu_warm_ms: u32,
    /// Frames timed per row of a fixed view (`default_timed_frames`
    /// unless told otherwise); with `single_frame`, at most this many.
    pub timed_frames: usize,
}

/// Frames timed per row of a fixed view unless told otherwise:
/// `SINGLE_FRAME_TIMED_FRAMES` with `single_frame`, else `TIMED_FRAMES`.
pub fn default_timed_frames(single_frame: bool) -> usize {
    if single_frame {
        SINGLE_FRAME_TIMED_FRAMES
    } else {
        TIMED_FRAMES
    }
}

/// One configuration seen from one camera (or the whole flythrough).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Row {
    pub scene: String,
    pub device: String,
    pub driver: String,
    pub width: u32,
    pub height: u32,
    pub camera: String,
    /// Frames the error is measured over (the flythrough's length, or 1).
    pub frames: usize,
    pub path: RowPath,
    /// How levels were chosen; null for brute and the oracle.
    pub lod: Option<RowLod>,
    pub tau: Option<f32>,
    pub config: String,
    /// The median of each time over the timed frames and the mean of each
    /// count over the measured ones (per frame of the flythrough).
    #[serde(flatten)]
    pub figures: FrameFigures,
    /// The largest level choice of any frame of the row, warm-up frames
    /// and each fixed view's first frame included.
    #[serde(default)]
    pub lod_ms_max: Option<f64>,
    /// Median over the timed frames of CPU plus GPU time: what a frame
    /// costs a user. Null without GPU timestamps.
    #[serde(default)]
    pub frame_ms: Option<f64>,
    /// Fragment shader invocations per frame (mean over the flythrough);
    /// null without pipeline statistics.
    #[serde(default)]
    pub fragment_invocations: Option<u64>,
    /// Pixels the terrain covers (mean per frame): with
    /// `fragment_invocations`, the path's overdraw.
    #[serde(default)]
    pub covered_pixels: Option<u64>,
    /// Device memory of this path's renderer plus the render target.
    pub gpu_memory_bytes: u64,
    /// The largest error the LOD choice expected on screen, over the
    /// frames (`TerrainRenderer::predicted_max_px`); null for brute, the
    /// oracle and the distance LOD.
    #[serde(default)]
    pub predicted_max_px: Option<f64>,
    /// The frame's 99th percentile error the LOD choice expected, the
    /// largest over the frames (`TerrainRenderer::predicted_p99_px`);
    /// null where the view was not measured.
    #[serde(default)]
    pub predicted_p99_px: Option<f64>,
    /// The share of the terrain's pixels the view model put over tau at
    /// the levels chosen (`TerrainRenderer::predicted_over_share`), the
    /// mean over the frames measured; null where the choice did not read
    /// the model.
    #[serde(default)]
    pub predicted_over_share: Option<f64>,
    /// The share of the pixels measured whose error is over tau, over all
    /// frames; null without a tau.
    #[serde(default)]
    pub over_share: Option<f64>,
    pub max_px: f64,
    pub p99_px: f64,
    pub mean_px: f64,
    /// Pixels measured (terrain in either render), over all frames.
    pub error_pixels: usize,
    /// Of those, terrain in one render and sky in the other.
    pub mismatched_pixels: usize,
    /// Drawn with occlusion culling.
    #[serde(default)]
    pub occlusion: bool,
    /// Patches occlusion culling hid (mean per frame; null without it).
    #[serde(default)]
    pub patches_occluded: Option<u64>,
    /// Patches drawn though the reference shows none of their pixels
    /// (mean per frame; with occlusion culling only).
    #[serde(default)]
    pub patches_drawn_hidden: Option<u64>,
    /// GPU milliseconds of the depth pyramid and the patch test (median;
    /// null without occlusion culling), part of `gpu_ms`.
    #[serde(default)]
    pub culling_gpu_ms: Option<f64>,
    /// Pixels, over all frames, whose colour differs from the same
    /// configuration's without occlusion culling (null without it).
    #[serde(default)]
    pub differing_pixels: Option<usize>,
}

/// Progress reports: renders done of the total, and what runs now.
pub trait Progress {
    fn start(&mut self, total: u64);
    fn advance(&mut self, message: &str);
}

/// Figures of one configuration, gathered over a camera sequence.
#[derive(Default)]
struct Gathered {
    /// The timed frames' figures, each with its sample of the row's
    /// sequence (the flythrough's passes time each sample more than once),
    /// and the figures of the frames counted.
    timed: Vec<(usize, FrameFigures)>,
    counted: Vec<FrameFigures>,
    lod_ms_max: Option<f64>,
    fragment_invocations: Vec<u64>,
    covered_pixels: Vec<u64>,
    predicted_max_px: Option<f64>,
    predicted_p99_px: Option<f64>,
    /// The view model's share over tau of each frame measured.
    predicted_over_share: Vec<f64>,
    /// Pixels measured over tau, over all frames.
    over_tau: usize,
    errors: ErrorHistogram,
    patches_occluded: Vec<u64>,
    patches_drawn_hidden: Vec<u64>,
    culling_ms: Vec<f64>,
    differing_pixels: Option<usize>,
}

/// A renderer of one path, with or without occlusion culling (each keeps
/// its own visibility state from frame to frame), and the device memory it
/// holds.
struct PathRenderer {
    path: RenderPath,
    occlusion: bool,
    renderer: TerrainRenderer,
    bytes: u64,
}

/// The GPU objects of a run; they free themselves when it drops.
pub struct Bench<'a> {
    gpu: &'a Gpu,
    terrain: &'a Terrain,
    scene_lod: DistanceLod,
    headless: Headless,
    target_bytes: u64,
    renderers: Vec<PathRenderer>,
    /// Untimed samples at the start of each configuration's sequence.
    warm_up: usize,
    /// How long a fixed view's frame is drawn untimed before it is timed
    /// (`BenchOptions::gpu_warm_ms`).
    gpu_warm: std::time::Duration,
    /// The most frames a single-frame view's row is timed by
    /// (`BenchOptions::timed_frames`).
    timed_frames: usize,
}

impl<'a> Bench<'a> {
    /// Builds one renderer per path the configurations use, each measured
    /// for its memory, and the offscreen target.
    pub fn new(
        gpu: &'a Gpu,
        terrain: &'a Terrain,
        scene_lod: DistanceLod,
        configs: &[Config],
        width: u32,
        height: u32,
    ) -> anyhow::Result<Self> {
        let before = gpu.device.memory_in_use();
        // One sample per pixel: the error measurement compares depth
        // pixel for pixel with the reference's.
        let headless = Headless::new(gpu, width, height, 1)?;
        let mut bench = Bench {
            gpu,
            terrain,
            scene_lod,
            headless,
            target_bytes: gpu.device.memory_in_use() - before,
            renderers: Vec::new(),
            warm_up: WARM_UP,
            gpu_warm: std::time::Duration::ZERO,
            timed_frames: TIMED_FRAMES,
        };
        for (path, occlusion) in [
            (RenderPath::Brute, false),
            (RenderPath::Tess, false),
            (RenderPath::Geomip, false),
            (RenderPath::Tess, true),
            (RenderPath::Geomip, true),
        ] {
            if !configs
                .iter()
                .any(|c| c.render_path() == path && c.occlusion() == occlusion)
            {
                continue;
            }
            let before = gpu.device.memory_in_use();
            let renderer = TerrainRenderer::new(
                gpu,
                terrain,
                OFFSCREEN_COLOR_FORMAT,
                1,
                &RendererOptions::single_sample(vec![path]),
            )?;
            bench.renderers.push(PathRenderer {
                path,
                occlusion,
                renderer,
                bytes: gpu.device.memory_in_use() - before,
            });
        }
        Ok(bench)
    }

    /// Renders `config` from `camera`, waits for it and reads it back.
    fn render(
        &mut self,
        camera: &Camera,
        config: &Config,
        levels: Option<&[u8]>,
    ) -> anyhow::Result<HeadlessFrame> {
        self.draw(config, levels, |headless, renderer, terrain, settings| {
            headless.render(renderer, terrain, camera, settings)
        })
    }

    /// Draws `config` from `camera` and waits for it, reading nothing
    /// back (a frame as a render loop draws it).
    fn time(
        &mut self,
        camera: &Camera,
        config: &Config,
        levels: Option<&[u8]>,
    ) -> anyhow::Result<TimedFrame> {
        self.draw(config, levels, |headless, renderer, terrain, settings| {
            headless.time(renderer, terrain, camera, settings)
        })
    }

    /// `frame` with `config`'s renderer, its geomip levels set to `levels`
    /// (the oracle's), and its settings.
    fn draw<T>(
        &mut self,
        config: &Config,
        levels: Option<&[u8]>,
        frame: impl FnOnce(
            &mut Headless,
            &mut TerrainRenderer,
            &Terrain,
            &RenderSettings,
        ) -> crate::render::Result<T>,
    ) -> anyhow::Result<T> {
        let terrain = self.terrain;
        let settings = config.settings(self.scene_lod);
        let target = renderer_for(&mut self.renderers, config);
        if settings.path == RenderPath::Geomip {
            target.renderer.set_geomip_levels(terrain, levels)?;
        }
        Ok(frame(
            &mut self.headless,
            &mut target.renderer,
            terrain,
            &settings,
        )?)
    }

    /// Renders `config` once from `camera`, reads it back and counts it,
    /// and with `timed_sample` (its index in the configuration's
    /// sequence) times it too: a single-frame view's or a flythrough's
    /// frame. Fixed views with several samples time theirs in rounds
    /// (`time_sample`) and read back one more frame here.
    fn render_counted(
        &mut self,
        camera: &Camera,
        config: &Config,
        levels: Option<&[u8]>,
        timed_sample: Option<usize>,
        gathered: &mut Gathered,
    ) -> anyhow::Result<HeadlessFrame> {
        let frame = self.render(camera, config, levels)?;
        self.gather_choice(config, frame.lod_ms, gathered);
        if let Some(sample) = timed_sample {
            let timed = TimedFrame {
                measurements: frame.measurements,
                cpu_ms: frame.cpu_ms,
                lod_ms: frame.lod_ms,
            };
            self.keep_timed(sample, &timed, gathered);
        }
        gathered.counted.push(frame.figures());
        if let Some(s) = frame.measurements.statistics {
            gathered.fragment_invocations.push(s.fragment_invocations);
            let covered = frame.covered_pixels();
            gathered.covered_pixels.push(covered as u64);
        }
        if let Some(o) = frame.measurements.occlusion {
            gathered
                .patches_occluded
                .push(u64::from(o.patches_occluded));
        }
        Ok(frame)
    }

    /// Draws `config` from `camera` untimed, frame after frame, for the
    /// run's `gpu_warm` (nothing with none): the GPU is kept busy just
    /// before a frame is timed. The choices it makes count towards the
    /// row's largest.
    fn hold_clock(
        &mut self,
        camera: &Camera,
        config: &Config,
        levels: Option<&[u8]>,
        gathered: &mut Gathered,
    ) -> anyhow::Result<()> {
        let start = std::time::Instant::now();
        while start.elapsed() < self.gpu_warm {
            let timed = self.time(camera, config, levels)?;
            self.gather_choice(config, timed.lod_ms, gathered);
        }
        Ok(())
    }

    /// Times one frame of `config` from `camera`, nothing read back: sample
    /// `sample` of its sequence, kept past the warm-up.
    fn time_sample(
        &mut self,
        camera: &Camera,
        config: &Config,
        levels: Option<&[u8]>,
        sample: usize,
        gathered: &mut Gathered,
    ) -> anyhow::Result<()> {
        let timed = self.time(camera, config, levels)?;
        self.gather_choice(config, timed.lod_ms, gathered);
        self.keep_timed(sample, &timed, gathered);
        Ok(())
    }

    /// Times more frames of `config` from `camera` straight after a
    /// single-frame view's read-back frame, which began at `since`: up to
    /// the run's timed frames in all, while within `SINGLE_FRAME_TIMING`.
    fn time_while_cheap(
        &mut self,
        camera: &Camera,
        config: &Config,
        levels: Option<&[u8]>,
        (since, sample): (std::time::Instant, usize),
        gathered: &mut Gathered,
    ) -> anyhow::Result<()> {
        for _ in 1..self.timed_frames {
            if since.elapsed() >= SINGLE_FRAME_TIMING {
                break;
            }
            self.time_sample(camera, config, levels, sample, gathered)?;
        }
        Ok(())
    }

    /// A timed frame's figures, unless sample `sample` of its sequence is
    /// a warm-up one.
    fn keep_timed(&self, sample: usize, timed: &TimedFrame, gathered: &mut Gathered) {
        if sample < self.warm_up {
            return;
        }
        gathered.timed.push((sample, timed.figures()));
        let culling = timed.measurements.occlusion.and_then(|o| o.culling_ms);
        gathered.culling_ms.extend(culling);
    }

    /// What the level choice of `config`'s last frame expected, and took.
    fn gather_choice(&mut self, config: &Config, lod_ms: Option<f64>, gathered: &mut Gathered) {
        let renderer = &renderer_for(&mut self.renderers, config).renderer;
        for (px, into) in [
            (renderer.predicted_max_px(), &mut gathered.predicted_max_px),
            (renderer.predicted_p99_px(), &mut gathered.predicted_p99_px),
        ] {
            if let Some(px) = px {
                let px = f64::from(px);
                *into = Some(into.map_or(px, |m| m.max(px)));
            }
        }
        if let Some(ms) = lod_ms {
            log::trace!("level choice of {}: {ms:.3} ms", config.label());
            gathered.lod_ms_max = Some(gathered.lod_ms_max.map_or(ms, |m| m.max(ms)));
        }
    }

    /// Renders the oracle's uniform levels from `camera` and picks, for
    /// each tau and each patch, the coarsest level at which at most
    /// `ORACLE_EXCEED_FRACTION` of the patch's pixels are over tau pixels.
    /// A pixel belongs to the patch under its reference surface point (or
    /// the tested one where the reference shows sky); a patch no pixel
    /// belongs to gets the coarsest level.
    fn oracle_levels(
        &mut self,
        camera: &Camera,
        (reference, reference_patch): (&HeadlessFrame, &[Option<usize>]),
        taus: &[f32],
        progress: &mut dyn Progress,
        message: &str,
    ) -> anyhow::Result<Vec<Vec<u8>>> {
        let terrain = self.terrain;
        let grid = terrain.grid();
        let patches = grid.patch_count();
        let count = geomip::level_count(grid.cells_per_patch());
        let k = f64::from(reference.view.pixels_per_radian);
        let reference_view = DepthView::of(reference);
        // [patch][level]: pixels, and pixels over each tau.
        let mut pixels = vec![0u32; patches * count];
        let mut over = vec![0u32; patches * count * taus.len()];
        for level in 0..count {
            let uniform = vec![level as u8; patches];
            let frame = self.render(camera, &Config::Oracle(0.0), Some(&uniform))?;
            progress.advance(message);
            let tested = DepthView::of(&frame);
            let tested_patch = pixel_patches(terrain, camera, &tested);
            for e in pixel_errors(&tested, &reference_view, k) {
                let Some(p) = reference_patch[e.index].or(tested_patch[e.index]) else {
                    continue;
                };
                let cell = p * count + level;
                pixels[cell] += 1;
                for (t, &tau) in taus.iter().enumerate() {
                    if e.px > f64::from(tau) {
                        over[cell * taus.len() + t] += 1;
                    }
                }
            }
        }
        Ok((0..taus.len())
            .map(|t| {
                (0..patches)
                    .map(|p| {
                        (0..count)
                            .rev()
                            .find(|&l| {
                                let cell = p * count + l;
                                f64::from(over[cell * taus.len() + t])
                                    <= ORACLE_EXCEED_FRACTION * f64::from(pixels[cell])
                            })
                            .unwrap_or(0) as u8
                    })
                    .collect()
            })
            .collect())
    }

    /// Every configuration over one camera sequence: `repeats` renders of
    /// each camera (the first `WARM_UP` samples of a configuration are not
    /// timed), errors pooled over the sequence.
    fn sequence(
        &mut self,
        name: &str,
        cameras: &[Camera],
        repeats: usize,
        configs: &[Config],
        progress: &mut dyn Progress,
    ) -> anyhow::Result<Vec<(Config, Gathered)>> {
        let mut gathered: Vec<(Config, Gathered)> =
            configs.iter().map(|&c| (c, Gathered::default())).collect();
        let oracle_taus: Vec<f32> = configs
            .iter()
            .filter_map(|c| match c {
                Config::Oracle(t) => Some(*t),
                _ => None,
            })
            .collect();
        // The flythrough's later passes draw each frame's oracle levels
        // again.
        let passes = passes_over(cameras.len());
        let mut oracle_by_frame: Vec<Vec<Vec<u8>>> = Vec::new();
        for (f, camera) in cameras.iter().enumerate() {
            let first_sample = f * repeats;
            let message = if cameras.len() > 1 {
                format!("{name} {}/{}", f + 1, cameras.len())
            } else {
                name.to_string()
            };
            // Several samples of a fixed view are timed in rounds, one frame
            // of every configuration (brute included) a round, so that
            // whatever slows the machine down over the run slows every row
            // alike, and the rows' ratios hold; each configuration then
            // draws one more frame, read back for its error and counts. A
            // single sample is timed as it is read back.
            let rounds = repeats > 1;
            let timed_sample = (!rounds).then_some(first_sample);
            // A fixed view's frame timed as it is read back is drawn after
            // the warm frames (`hold_clock`); the flythrough's are not.
            let hold_before_read = timed_sample.is_some() && cameras.len() == 1;
            // The reference first; its own error row is measured too (0).
            let brute = gathered
                .iter()
                .position(|(c, _)| *c == Config::Brute)
                .expect("brute is always configured");
            if hold_before_read {
                self.hold_clock(camera, &Config::Brute, None, &mut gathered[brute].1)?;
            }
            let since = std::time::Instant::now();
            let reference = self.render_counted(
                camera,
                &Config::Brute,
                None,
                timed_sample,
                &mut gathered[brute].1,
            )?;
            if hold_before_read {
                self.time_while_cheap(
                    camera,
                    &Config::Brute,
                    None,
                    (since, first_sample),
                    &mut gathered[brute].1,
                )?;
            }
            progress.advance(&message);
            let reference_view = DepthView::of(&reference);
            let k = f64::from(reference.view.pixels_per_radian);
            gathered[brute]
                .1
                .errors
                .add(&pixel_errors(&reference_view, &reference_view, k));
            // The patch under each of the reference's pixels: for the
            // oracle, and for the patches the occluded rows draw hidden.
            let reference_patch =
                if oracle_taus.is_empty() && !configs.iter().any(Config::occlusion) {
                    Vec::new()
                } else {
                    pixel_patches(self.terrain, camera, &reference_view)
                };
            let oracle = if oracle_taus.is_empty() {
                Vec::new()
            } else {
                self.oracle_levels(
                    camera,
                    (&reference, &reference_patch),
                    &oracle_taus,
                    progress,
                    &message,
                )?
            };
            let levels_of = |config: &Config| oracle_levels_of(config, &oracle_taus, &oracle);
            // A fixed view is a camera cut for an occluded row: its first
            // frame starts from the last view's visibility. That frame is
            // compared too, and not timed, against the first frame of the
            // row without culling, which draws one as well: a choice that
            // reads earlier frames of its view (`render::seen`) draws a
            // view's first frame unlike its later ones, culled or not.
            let mut cuts: Vec<Option<HeadlessFrame>> = Vec::with_capacity(gathered.len());
            for (config, g) in gathered.iter_mut() {
                let cut = match config.draws_cut_frame(configs) && cameras.len() == 1 {
                    true => Some(self.render(camera, config, levels_of(config))?),
                    false => None,
                };
                if let Some(cut) = &cut {
                    progress.advance(&message);
                    if let Some(ms) = cut.lod_ms {
                        g.lod_ms_max = Some(g.lod_ms_max.map_or(ms, |m| m.max(ms)));
                    }
                }
                cuts.push(cut);
            }
            if rounds {
                for r in 0..repeats {
                    for (config, g) in gathered.iter_mut() {
                        let levels = levels_of(config);
                        self.hold_clock(camera, config, levels, g)?;
                        self.time_sample(camera, config, levels, first_sample + r, g)?;
                        progress.advance(&message);
                    }
                }
            }
            // The images of each configuration an occluded one must equal,
            // from this camera: its cut frame's, if any, and its last.
            let mut unoccluded: Vec<(Config, Vec<Vec<u8>>)> = Vec::new();
            let visible_patches = {
                let mut seen = vec![false; self.terrain.grid().patch_count()];
                for &p in reference_patch.iter().flatten() {
                    seen[p] = true;
                }
                seen.iter().filter(|&&s| s).count() as u64
            };
            for ((config, g), cut) in gathered.iter_mut().zip(&cuts) {
                if *config == Config::Brute {
                    continue;
                }
                let levels = levels_of(config);
                if hold_before_read {
                    // The clock is held first, so that the frames after it,
                    // those whose times occlusion culling's turns compare
                    // included, are drawn at a busy application's clock.
                    self.hold_clock(camera, config, levels, g)?;
                    // A single frame is drawn as a still camera's: after the
                    // frames whose counts its choice reads.
                    if config.reads_earlier_frames() {
                        for _ in 0..STILL_FRAMES {
                            let timed = self.time(camera, config, levels)?;
                            self.gather_choice(config, timed.lod_ms, g);
                        }
                    }
                }
                let since = std::time::Instant::now();
                let frame = self.render_counted(camera, config, levels, timed_sample, g)?;
                if hold_before_read {
                    self.time_while_cheap(camera, config, levels, (since, first_sample), g)?;
                }
                progress.advance(&message);
                let errors = pixel_errors(&DepthView::of(&frame), &reference_view, k);
                if let Some(tau) = config.tau() {
                    g.over_tau += errors.iter().filter(|e| e.px > f64::from(tau)).count();
                }
                g.errors.add(&errors);
                let renderer = &renderer_for(&mut self.renderers, config).renderer;
                g.predicted_over_share
                    .extend(renderer.predicted_over_share().map(f64::from));
                let images: Vec<&Vec<u8>> = cut
                    .iter()
                    .chain([&frame])
                    .map(|f| &f.readback.rgba)
                    .collect();
                if config.has_occluded_row(configs) {
                    unoccluded.push((*config, images.into_iter().cloned().collect()));
                } else if let Some(off) = config.unoccluded() {
                    let Some((_, off_images)) = unoccluded.iter().find(|(c, _)| *c == off) else {
                        anyhow::bail!("{} runs without {}", config.label(), off.label());
                    };
                    if off_images.len() != images.len() {
                        anyhow::bail!(
                            "{} and {} drew different frames",
                            config.label(),
                            off.label()
                        );
                    }
                    for (image, off_image) in images.into_iter().zip(off_images) {
                        *g.differing_pixels.get_or_insert(0) += differing_pixels(image, off_image);
                    }
                }
                if let Some(o) = frame.measurements.occlusion {
                    let drawn = frame.patches_in_frustum as u64 - u64::from(o.patches_occluded);
                    g.patches_drawn_hidden
                        .push(drawn.saturating_sub(visible_patches));
                }
            }
            if passes > 1 {
                oracle_by_frame.push(oracle);
            }
        }
        // The loop flown again, each frame of every row timed and nothing
        // read back; each row's renderer goes on from the frame before, as
        // a camera flying the loop round would.
        for _ in 1..passes {
            for (f, camera) in cameras.iter().enumerate() {
                for (config, g) in gathered.iter_mut() {
                    let levels = oracle_levels_of(config, &oracle_taus, &oracle_by_frame[f]);
                    self.time_sample(camera, config, levels, f * repeats, g)?;
                    progress.advance(&format!("{name} {}/{} again", f + 1, cameras.len()));
                }
            }
        }
        Ok(gathered)
    }

    /// Runs every configuration over the named views (one with `quick`) and
    /// the flythrough.
    pub fn run(
        &mut self,
        scene: &str,
        configs: &[Config],
        options: &BenchOptions,
        progress: &mut dyn Progress,
    ) -> anyhow::Result<Vec<Row>> {
        let info = self.terrain.info();
        self.timed_frames = options.timed_frames.max(1);
        let repeats = if options.single_frame {
            1
        } else {
            WARM_UP + self.timed_frames
        };
        self.warm_up = if options.single_frame { 0 } else { WARM_UP };
        self.gpu_warm = std::time::Duration::from_millis(u64::from(options.gpu_warm_ms));
        let mut views: Vec<(String, Vec<Camera>, usize)> = named_views(info)
            .into_iter()
            .map(|v| (v.name.to_string(), vec![v.camera], repeats))
            .collect();
        if !options.views.is_empty() {
            views.retain(|(name, _, _)| options.views.contains(name));
        } else if options.quick {
            views.truncate(1);
        }
        let flythrough_wanted =
            options.views.is_empty() || options.views.iter().any(|v| v == FLYTHROUGH);
        if options.flythrough_frames > 0 && flythrough_wanted {
            views.push((
                FLYTHROUGH.to_string(),
                flythrough(info, options.flythrough_frames),
                1,
            ));
        }
        let level_count = geomip::level_count(self.terrain.grid().cells_per_patch()) as u64;
        let oracles = configs
            .iter()
            .filter(|c| matches!(c, Config::Oracle(_)))
            .count() as u64;
        // Occluded rows and the rows they are compared with.
        let occluded = configs
            .iter()
            .filter(|c| c.draws_cut_frame(configs))
            .count() as u64;
        // With more than one repeat, each configuration draws one more
        // frame, read back for its error.
        let per_frame = |repeats: u64| {
            let draws = if repeats > 1 { repeats + 1 } else { repeats };
            draws * configs.len() as u64 + if oracles > 0 { level_count } else { 0 }
        };
        // Those rows render a fixed view once more (its cut frame).
        progress.start(
            views
                .iter()
                .map(|(_, cams, repeats)| {
                    let cut = if cams.len() == 1 { occluded } else { 0 };
                    let again = (passes_over(cams.len()) - 1) * cams.len() * configs.len();
                    cams.len() as u64 * per_frame(*repeats as u64) + cut + again as u64
                })
                .sum(),
        );
        let caps = &self.gpu.device.caps;
        let (device, driver) = (
            caps.device_name.clone(),
            format!("{} ({})", caps.driver_name, caps.driver_info),
        );
        let mut rows = Vec::new();
        for (name, cameras, repeats) in &views {
            for (config, mut g) in self.sequence(name, cameras, *repeats, configs, progress)? {
                let stats = g.errors.stats();
                let (timed, frame_ms) = per_sample(&g.timed);
                let bytes = renderer_for(&mut self.renderers, &config).bytes + self.target_bytes;
                rows.push(Row {
                    scene: scene.to_string(),
                    device: device.clone(),
                    driver: driver.clone(),
                    width: options.width,
                    height: options.height,
                    camera: name.clone(),
                    frames: cameras.len(),
                    path: config.path(),
                    lod: config.lod(),
                    tau: config.tau(),
                    config: config.label(),
                    figures: FrameFigures::summary(&timed, &g.counted),
                    lod_ms_max: g.lod_ms_max,
                    frame_ms,
                    fragment_invocations: mean_count(&g.fragment_invocations),
                    covered_pixels: mean_count(&g.covered_pixels),
                    gpu_memory_bytes: bytes,
                    predicted_max_px: g.predicted_max_px,
                    predicted_p99_px: g.predicted_p99_px,
                    predicted_over_share: (!g.predicted_over_share.is_empty()).then(|| {
                        g.predicted_over_share.iter().sum::<f64>()
                            / g.predicted_over_share.len() as f64
                    }),
                    over_share: config
                        .tau()
                        .map(|_| g.over_tau as f64 / stats.pixels.max(1) as f64),
                    max_px: stats.max_px,
                    p99_px: stats.p99_px,
                    mean_px: stats.mean_px,
                    error_pixels: stats.pixels,
                    mismatched_pixels: stats.mismatched,
                    occlusion: config.occlusion(),
                    patches_occluded: mean_count(&g.patches_occluded),
                    patches_drawn_hidden: mean_count(&g.patches_drawn_hidden),
                    culling_gpu_ms: median(&mut g.culling_ms),
                    differing_pixels: g.differing_pixels,
                });
            }
        }
        Ok(rows)
    }
}

/// How many times a sequence of `cameras` cameras is drawn: a fixed view
/// once, the flythrough's loop `FLYTHROUGH_PASSES` times.
fn passes_over(cameras: usize) -> usize {
    if cameras > 1 {
        FLYTHROUGH_PASSES
    } else {
        1
    }
}

/// The timed frames of a row, one for each sample of its sequence: each
/// time the median of that sample's frames (the flythrough's passes over
/// one camera; a single-frame view's frames drawn back to back), and the
/// median over the samples of their CPU plus GPU time, each sample's
/// itself a median.
fn per_sample(timed: &[(usize, FrameFigures)]) -> (Vec<FrameFigures>, Option<f64>) {
    let mut samples: std::collections::BTreeMap<usize, Vec<FrameFigures>> = Default::default();
    for &(sample, figures) in timed {
        samples.entry(sample).or_default().push(figures);
    }
    let mut frame_ms = Vec::with_capacity(samples.len());
    let figures = samples
        .values()
        .map(|frames| {
            let mut ms: Vec<f64> = frames.iter().filter_map(FrameFigures::frame_ms).collect();
            frame_ms.extend(median(&mut ms));
            FrameFigures::summary(frames, frames)
        })
        .collect();
    (figures, median(&mut frame_ms))
}

/// The oracle's levels at tau `t` for an oracle row (`levels`, in the
/// order of `taus`); None for any other row.
fn oracle_levels_of<'l>(config: &Config, taus: &[f32], levels: &'l [Vec<u8>]) -> Option<&'l [u8]> {
    match config {
        Config::Oracle(t) => {
            let i = taus.iter().position(|x| x == t).expect("listed");
            Some(levels[i].as_slice())
        }
        _ => None,
    }
}

fn renderer_for<'r>(renderers: &'r mut [PathRenderer], config: &Config) -> &'r mut PathRenderer {
    let (path, occlusion) = (config.render_path(), config.occlusion());
    renderers
        .iter_mut()
        .find(|r| r.path == path && r.occlusion == occlusion)
        .expect("a renderer is built for every configuration's path")
}

/// The patch under each pixel's surface point (None for sky).
fn pixel_patches(terrain: &Terrain, camera: &Camera, view: &DepthView) -> Vec<Option<usize>> {
    let info = terrain.info();
    let grid = terrain.grid();
    let inverse: DMat4 = view.view_proj.inverse();
    (0..view.width * view.height)
        .map(|i| {
            let p = camera.eye + view.position(&inverse, i)?;
            let g = info.world_to_grid(p.x, p.z);
            Some(grid.patch_index(grid.patch_at(g.x, g.y)))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(cpu_ms: f64, gpu_ms: f64) -> FrameFigures {
        FrameFigures {
            cpu_ms,
            lod_ms: Some(cpu_ms / 2.0),
            gpu_ms: Some(gpu_ms),
            triangles: Some(100),
            tes_invocations: None,
        }
    }

    #[test]
    fn a_slow_draw_of_one_pass_does_not_move_its_frame() {
        // Three passes over two frames; the second pass drew frame 0 25 ms
        // slower, and frame 1 was timed twice.
        let timed = [
            (0, frame(1.0, 40.0)),
            (1, frame(2.0, 60.0)),
            (0, frame(1.0, 65.0)),
            (1, frame(4.0, 62.0)),
            (0, frame(3.0, 41.0)),
        ];
        let (figures, frame_ms) = per_sample(&timed);
        assert_eq!(figures.len(), 2);
        assert_eq!(figures[0].gpu_ms, Some(41.0));
        assert_eq!(figures[0].cpu_ms, 1.0);
        assert_eq!(figures[0].lod_ms, Some(0.5));
        assert_eq!(figures[1].gpu_ms, Some(61.0));
        assert_eq!(figures[1].cpu_ms, 3.0);
        // Frame 0 costs 44 ms (the median of 41, 66 and 44), frame 1 64
        // (of 62 and 66).
        assert_eq!(frame_ms, Some(54.0));
        // One sample a frame, as a fixed view's rounds give: the median
        // over them, as before.
        let rounds = [
            (0, frame(1.0, 10.0)),
            (1, frame(1.0, 30.0)),
            (2, frame(1.0, 12.0)),
        ];
        let (figures, frame_ms) = per_sample(&rounds);
        assert_eq!(figures.len(), 3);
        assert_eq!(frame_ms, Some(13.0));
    }
}
