//! `stream`: a flythrough of a streamed (tiled) terrain that never waits on
//! the disk, measured frame by frame: what each frame uploaded and evicted,
//! its CPU time, holes and cracks (background enclosed by the terrain in a
//! flat white render), and, with `--against-resident`, its screen-space
//! error against the same frame drawn by the whole-terrain renderer.

use std::io::Write;

use anyhow::{bail, Context, Result};
use serde::Serialize;

use super::args::{FeatureArgs, SizeArgs, TerrainArgs};
use crate::appearance::Appearance;
use crate::bench::cameras::flythrough;
use crate::bench::error::{enclosed_background, measure, DepthView};
use crate::render::{
    offscreen, ErrorMeasure, FrameFigures, LodMetric, RenderPath, RenderSettings, RendererOptions,
    Shading, StreamStats,
};
use crate::render::{LoadedScene, Loading};

#[derive(clap::Args, Debug)]
pub struct StreamCmd {
    #[command(flatten)]
    pub terrain: TerrainArgs,

    #[command(flatten)]
    pub size: SizeArgs,

    #[command(flatten)]
    pub features: FeatureArgs,

    /// Frames of the flythrough (one loop round the terrain).
    #[arg(long, value_name = "N", default_value_t = 600)]
    pub frames: usize,

    /// Samples per pixel of the render target: 1, 2, 4 or 8, as the device
    /// allows. The target's memory counts against --gpu-memory-budget
    /// before the page pool takes what is left.
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = super::args::parse_samples)]
    pub samples: u32,

    /// Largest projected error of the error LOD, in pixels.
    #[arg(long, value_name = "PX", default_value_t = 1.0)]
    pub pixel_error: f32,

    /// Also draw every frame with the whole terrain uploaded (on a second
    /// device, outside the memory budget) and measure the streamed frame's
    /// error against it. The terrain must fit in memory whole.
    #[arg(long)]
    pub against_resident: bool,

    /// Where to write the report as JSON (every frame, and a summary).
    #[arg(long, value_name = "PATH")]
    pub report: Option<std::path::PathBuf>,

    /// Turn on the Vulkan validation layer.
    #[arg(long)]
    pub validate: bool,
}

/// One frame of the flythrough.
#[derive(Serialize, Debug, Clone)]
pub struct StreamFrame {
    pub frame: usize,
    #[serde(flatten)]
    pub figures: FrameFigures,
    pub stream: StreamStats,
    /// Background pixels enclosed by the terrain: holes and cracks.
    pub holes: usize,
    /// Error against the whole-terrain renderer, in pixels.
    pub error_max_px: Option<f64>,
    pub error_p99_px: Option<f64>,
}

/// The flythrough's report.
#[derive(Serialize, Debug)]
pub struct StreamReport {
    pub device: String,
    pub width: u32,
    pub height: u32,
    /// Samples per pixel of the render target.
    pub samples: u32,
    pub samples_across: usize,
    pub samples_down: usize,
    pub tile_cells: u32,
    pub base_level: u32,
    pub pool_layers: u32,
    pub gpu_memory_budget: Option<u64>,
    /// GPU memory in use while drawing, and resident memory at the end.
    pub gpu_memory_bytes: u64,
    pub resident_bytes: u64,
    pub frames: usize,
    pub holes: usize,
    pub max_cpu_ms: f64,
    /// The level choice's median and largest milliseconds over the frames.
    pub lod_ms: Option<f64>,
    pub max_lod_ms: Option<f64>,
    pub max_upload_bytes: u64,
    pub upload_bytes: u64,
    pub uploaded_pages: u64,
    pub evicted_pages: u64,
    pub max_pop_px: f32,
    pub max_missing_px: f32,
    /// The median of the frames' GPU times, and the load they were taken
    /// under (`bench::report::GPU_CLOCK_NOTE`).
    pub gpu_ms: Option<f64>,
    pub gpu_timing: &'static str,
    pub error_max_px: Option<f64>,
    /// The largest of the frames' p99 errors.
    pub error_p99_px: Option<f64>,
    pub validation_enabled: bool,
    pub validation_messages: u32,
    pub per_frame: Vec<StreamFrame>,
}

pub fn stream(cmd: StreamCmd, out: &mut dyn Write) -> Result<()> {
    if cmd.frames < 3 {
        bail!("--frames {} must be at least 3", cmd.frames);
    }
    if !(cmd.pixel_error > 0.0 && cmd.pixel_error.is_finite()) {
        bail!("--pixel-error {} must be positive", cmd.pixel_error);
    }
    let scene = cmd.terrain.scene()?;
    let loaded = LoadedScene::load(
        &scene,
        Loading {
            stream: true,
            appearance: false,
        },
    )?;
    let (terrain, Some(stream)) = (loaded.terrain, loaded.stream) else {
        bail!(
            "the stream flythrough needs a tiled terrain (from `vkterrain import`) as --heightmap"
        );
    };
    let cameras = flythrough(terrain.info(), cmd.frames);
    let settings = RenderSettings {
        path: RenderPath::Tess,
        lod_metric: LodMetric::Error(cmd.pixel_error),
        shading: Shading::Flat,
        sky: false,
        clear_color: [0.0; 3],
        ..RenderSettings::for_scene(&scene, terrain.info())
    };
    let size = (cmd.size.width, cmd.size.height);
    // The resident renderer's device, outside the budget.
    let resident = cmd
        .against_resident
        .then(|| -> Result<_> {
            let whole = LoadedScene::load(&scene, Loading::WHOLE_TERRAIN)?.terrain;
            let gpu = crate::gpu::Gpu::open(&crate::gpu::GpuOptions {
                memory_budget: None,
                ..cmd.features.gpu_options(cmd.validate)
            })
            .context("starting Vulkan for the resident renderer")?;
            Ok((whole, gpu))
        })
        .transpose()?;
    let mut resident_parts = match &resident {
        Some((whole, gpu)) => Some((
            whole,
            offscreen(
                gpu,
                whole,
                &Appearance::default(),
                &RendererOptions::single_sample(vec![RenderPath::Tess]),
                size,
            )
            .context("preparing the whole terrain for the GPU")?,
        )),
        None => None,
    };
    let budget = cmd.features.gpu_memory_budget;
    let (mut report, validation) = cmd.features.with_gpu(cmd.validate, |gpu| {
        let samples =
            crate::render::sample_count(Some(cmd.samples), &gpu.device.caps, &mut Vec::new())?;
        let options = RendererOptions {
            stream: Some(stream.clone()),
            samples,
            ..RendererOptions::single_sample(vec![RenderPath::Tess])
        };
        let (mut renderer, mut headless) =
            offscreen(gpu, &terrain, &Appearance::default(), &options, size)
                .context("preparing the terrain for the GPU")?;
        headless.wait_for_residency = false;
        let bar = super::progress::progress_bar(cmd.frames as u64, "frames");
        let mut frames = Vec::with_capacity(cmd.frames);
        let mut gpu_memory_bytes = 0;
        for (i, camera) in cameras.iter().enumerate() {
            let frame = headless
                .render(&mut renderer, &terrain, camera, &settings)
                .with_context(|| format!("frame {i}"))?;
            let (w, h) = (
                frame.readback.width as usize,
                frame.readback.height as usize,
            );
            let holes = enclosed_background(&frame.readback.rgba, w, h, |p| p[0] < 128).len();
            let error = match &mut resident_parts {
                Some((whole, (r, target))) => {
                    // The streamed terrain's CPU does not hold the heights
                    // the view's error measure needs, so its LOD keeps the
                    // error bounds: the reference is drawn on them too, and
                    // the two frames differ only by what streaming does.
                    let bound = RenderSettings {
                        error_measure: ErrorMeasure::Bound,
                        ..settings
                    };
                    let reference = target
                        .render(r, whole, camera, &bound)
                        .with_context(|| format!("frame {i}, resident"))?;
                    Some(measure(
                        &DepthView::of(&frame),
                        &DepthView::of(&reference),
                        f64::from(frame.view.pixels_per_radian),
                    ))
                }
                None => None,
            };
            if i == 0 {
                gpu_memory_bytes = gpu.device.memory_in_use();
            }
            let stats = renderer
                .stream_stats()
                .context("the renderer streams this terrain")?;
            frames.push(StreamFrame {
                frame: i,
                figures: frame.figures(),
                stream: stats,
                holes,
                error_max_px: error.map(|e| e.max_px),
                error_p99_px: error.map(|e| e.p99_px),
            });
            bar.inc(1);
        }
        bar.finish_and_clear();
        let first = frames[0].stream;
        let shape = renderer
            .stream_shape()
            .context("the renderer streams this terrain")?;
        let max_f64 = |v: &mut dyn Iterator<Item = f64>| {
            v.fold(None, |m: Option<f64>, x| Some(m.map_or(x, |m| m.max(x))))
        };
        let figures: Vec<FrameFigures> = frames.iter().map(|f| f.figures).collect();
        let summary = FrameFigures::summary(&figures, &figures);
        Ok(StreamReport {
            device: gpu.device.caps.device_name.clone(),
            width: size.0,
            height: size.1,
            samples: cmd.samples,
            samples_across: terrain.info().cols(),
            samples_down: terrain.info().rows(),
            tile_cells: shape.tile_cells,
            base_level: shape.base_level,
            pool_layers: first.layers,
            gpu_memory_budget: budget,
            gpu_memory_bytes,
            resident_bytes: super::render::resident_bytes().unwrap_or(0),
            frames: frames.len(),
            holes: frames.iter().map(|f| f.holes).sum(),
            max_cpu_ms: figures.iter().map(|f| f.cpu_ms).fold(0.0, f64::max),
            lod_ms: summary.lod_ms,
            max_lod_ms: max_f64(&mut figures.iter().filter_map(|f| f.lod_ms)),
            max_upload_bytes: frames
                .iter()
                .map(|f| f.stream.upload_bytes)
                .max()
                .unwrap_or(0),
            upload_bytes: frames.iter().map(|f| f.stream.upload_bytes).sum(),
            uploaded_pages: frames
                .iter()
                .map(|f| u64::from(f.stream.uploaded_pages))
                .sum(),
            evicted_pages: frames
                .iter()
                .map(|f| u64::from(f.stream.evicted_pages))
                .sum(),
            max_pop_px: frames.iter().map(|f| f.stream.pop_px).fold(0.0, f32::max),
            max_missing_px: frames
                .iter()
                .map(|f| f.stream.missing_px)
                .fold(0.0, f32::max),
            gpu_ms: summary.gpu_ms,
            gpu_timing: crate::bench::report::GPU_CLOCK_NOTE,
            error_max_px: max_f64(&mut frames.iter().filter_map(|f| f.error_max_px)),
            error_p99_px: max_f64(&mut frames.iter().filter_map(|f| f.error_p99_px)),
            validation_enabled: false,
            validation_messages: 0,
            per_frame: frames,
        })
    })?;
    drop(resident_parts);
    if let Some((_, gpu)) = resident {
        let report = gpu.shutdown();
        if report.count > 0 {
            bail!(
                "the resident renderer's validation reported {} messages; the first: {}",
                report.count,
                report.messages.first().cloned().unwrap_or_default()
            );
        }
    }
    report.validation_enabled = validation.enabled;
    report.validation_messages = validation.count;
    if let Some(path) = &cmd.report {
        let json = serde_json::to_string_pretty(&report)?;
        crate::output::write_atomically(path, |tmp| {
            std::fs::write(tmp, json + "\n")
                .with_context(|| format!("{}: cannot write the report", path.display()))
        })?;
    }
    let error = match (report.error_max_px, report.error_p99_px) {
        (Some(max), Some(p99)) => {
            format!(", error against resident max {max:.2} px, p99 {p99:.2} px")
        }
        _ => String::new(),
    };
    writeln!(
        out,
        "{} frames on {}: {} holes, {} pages uploaded ({} bytes, at most {} a frame), {} evicted, \
         CPU at most {:.1} ms a frame, GPU {} ms (median, one frame in flight at a time, so at \
         whatever clock that load keeps), level choice {} ms (median, at most {} ms), largest pop {:.2} px{error}, {} \
         validation messages{}",
        report.frames,
        report.device,
        report.holes,
        report.uploaded_pages,
        report.upload_bytes,
        report.max_upload_bytes,
        report.evicted_pages,
        report.max_cpu_ms,
        report.gpu_ms.map_or("n/a".into(), |v| format!("{v:.2}")),
        report.lod_ms.map_or("n/a".into(), |v| format!("{v:.3}")),
        report
            .max_lod_ms
            .map_or("n/a".into(), |v| format!("{v:.3}")),
        report.max_pop_px,
        report.validation_messages,
        if report.validation_enabled {
            ""
        } else {
            " (validation off)"
        }
    )?;
    if report.holes > 0 {
        bail!(
            "{} background pixels showed through the terrain",
            report.holes
        );
    }
    Ok(())
}
