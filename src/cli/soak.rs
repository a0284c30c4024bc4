//! `soak`: a long headless flythrough that switches paths and LOD modes on
//! the way, watching resident memory and the allocator for growth.

use std::io::Write;

use anyhow::{bail, Context, Result};
use serde::Serialize;

use super::args::{FeatureArgs, SizeArgs, TerrainArgs};
use crate::bench::cameras::flythrough;
use crate::render::{
    offscreen, with_fallback, ErrorMeasure, LodMetric, RenderPath, RenderSettings, RendererOptions,
};
use crate::render::{LoadedScene, Loading};

fn parse_soak_frames(s: &str) -> Result<u64, String> {
    let n: u64 = s
        .parse()
        .map_err(|_| format!("--frames {s:?} is not a frame count"))?;
    if n == 0 {
        return Err("--frames must be at least 1".into());
    }
    Ok(n)
}

#[derive(clap::Args, Debug)]
pub struct SoakCmd {
    #[command(flatten)]
    pub terrain: TerrainArgs,

    #[command(flatten)]
    pub size: SizeArgs,

    #[command(flatten)]
    pub features: FeatureArgs,

    /// Frames to render.
    #[arg(long, value_name = "N", value_parser = parse_soak_frames)]
    pub frames: u64,

    /// Frames of the looping flythrough.
    #[arg(long, value_name = "N", default_value_t = 400)]
    pub loop_frames: usize,

    /// Where memory is first measured; growth is counted from here.
    #[arg(long, value_name = "N", default_value_t = 1000)]
    pub baseline_frame: u64,

    /// Largest allowed growth of resident and allocator memory, percent.
    #[arg(long, value_name = "PERCENT", default_value_t = 1.0)]
    pub max_growth: f64,

    /// Where to write the report as JSON.
    #[arg(long, value_name = "PATH")]
    pub report: Option<std::path::PathBuf>,

    /// Turn on the Vulkan validation layer.
    #[arg(long)]
    pub validate: bool,
}

/// What a soak run measured.
#[derive(Serialize, Debug, Clone, PartialEq)]
pub struct SoakReport {
    pub device: String,
    pub frames: u64,
    pub baseline_frame: u64,
    /// Resident memory in the first and the second half of the frames
    /// after the baseline: each half's largest at a phase's last frame
    /// (`resident_halves`).
    pub resident_bytes_at_baseline: u64,
    pub resident_bytes_at_end: u64,
    pub allocator_bytes_at_baseline: u64,
    pub allocator_bytes_at_end: u64,
    pub resident_growth_percent: f64,
    pub allocator_growth_percent: f64,
    pub validation_enabled: bool,
    pub validation_messages: u32,
    pub seconds: f64,
}

fn resident_bytes() -> Result<u64> {
    super::render::resident_bytes().context("reading VmRSS from /proc/self/status")
}

/// Frames of one phase: one path and LOD mode (`settings_for`).
const PHASE_FRAMES: u64 = 50;

/// Resident memory at the baseline and at the end, from `samples` (frame,
/// bytes: the baseline frame's, then each later phase's last frame's):
/// the largest sample of each half of the frames from `baseline` to
/// `last`, where each half holds every one of the `paths`' phases at least
/// once. Phases hold different amounts of driver memory (brute's several
/// MB more than the others' on lavapipe), so two single frames in phases
/// of different paths differ by more than a leak would add: the default
/// scene's 2000-frame soak read +1.05 % and -2.51 % in two runs of the same
/// code between its baseline frame (a brute phase) and its last (a tess
/// phase). Each half's largest is its largest phase's, the same phase in
/// both, and memory that grows raises the second half's. Where the
/// halves are too short, the baseline frame's and the last frame's.
fn resident_halves(samples: &[(u64, u64)], (baseline, last): (u64, u64), paths: u64) -> (u64, u64) {
    let at = |frame: u64| samples.iter().find(|s| s.0 == frame).map_or(0, |s| s.1);
    let half = (last - baseline) / 2;
    if half < paths * PHASE_FRAMES + PHASE_FRAMES {
        return (at(baseline), at(last));
    }
    let middle = baseline + half;
    let largest = |range: std::ops::RangeInclusive<u64>| {
        samples
            .iter()
            .filter(|s| range.contains(&s.0))
            .map(|s| s.1)
            .max()
            .unwrap_or(0)
    };
    (largest(baseline..=middle), largest(middle + 1..=last))
}

/// The settings of frame `i`: the path and LOD mode change every 50 frames,
/// cycling through every combination the device supports; the error LOD
/// takes each of its measures in turn (the real-time view model, the view
/// measured sample by sample, the bound).
fn settings_for(i: u64, paths: &[RenderPath], base: &RenderSettings) -> RenderSettings {
    let phase = i / PHASE_FRAMES;
    let path = paths[(phase as usize) % paths.len()];
    let round = phase / paths.len() as u64;
    let lod_metric = match round % 3 {
        0 => LodMetric::Distance,
        1 => LodMetric::Error(1.0),
        _ => LodMetric::Error(4.0),
    };
    let error_measure = match (round / 3) % 3 {
        0 => ErrorMeasure::Sight,
        1 => ErrorMeasure::View,
        _ => ErrorMeasure::Bound,
    };
    RenderSettings {
        path,
        lod_metric,
        error_measure,
        geomorph: phase % 2 == 0,
        ..*base
    }
}

fn growth(from: u64, to: u64) -> f64 {
    if from == 0 {
        return 0.0;
    }
    100.0 * (to as f64 - from as f64) / from as f64
}

pub fn soak(cmd: SoakCmd, out: &mut dyn Write) -> Result<()> {
    if cmd.loop_frames < 3 {
        bail!("--loop-frames {} must be at least 3", cmd.loop_frames);
    }
    let scene = cmd.terrain.scene()?;
    // The scene's look too: its textures and lightmap are resources to
    // keep, and to free.
    let LoadedScene {
        terrain,
        appearance,
        stream,
        ..
    } = LoadedScene::load(
        &scene,
        Loading {
            stream: !cmd.features.no_streaming,
            appearance: true,
        },
    )?;
    let cameras = flythrough(terrain.info(), cmd.loop_frames);
    let base = RenderSettings::for_scene(&scene, terrain.info());
    let start = std::time::Instant::now();
    let baseline_frame = cmd.baseline_frame.min(cmd.frames - 1);
    // Leaked objects count: validation is counted after the device goes.
    let (report, validation) = cmd.features.with_gpu(cmd.validate, |gpu| {
        let mut paths = vec![RenderPath::Geomip, RenderPath::Brute];
        if gpu.device.caps.tessellation_shader {
            paths.insert(0, RenderPath::Tess);
        }
        let mut notes = Vec::new();
        let _ = with_fallback(RenderSettings::default(), &gpu.device.caps, &mut notes);
        for note in notes {
            writeln!(out, "{note}")?;
        }
        let options = RendererOptions {
            stream,
            ..RendererOptions::single_sample(paths.clone())
        };
        let (mut renderer, mut headless) = offscreen(
            gpu,
            &terrain,
            &appearance,
            &options,
            (cmd.size.width, cmd.size.height),
        )
        .context("preparing the terrain for the GPU")?;
        // A flythrough: a streamed terrain's frames never wait for tiles.
        headless.wait_for_residency = false;
        let mut baseline_allocator = 0;
        // Resident memory at the baseline frame, at the last frame of each
        // phase after it, and at the last frame.
        let mut resident = Vec::new();
        for i in 0..cmd.frames {
            let camera = &cameras[(i % cameras.len() as u64) as usize];
            let settings = settings_for(i, &paths, &base);
            headless
                .render(&mut renderer, &terrain, camera, &settings)
                .with_context(|| format!("frame {i}"))?;
            if i == baseline_frame {
                baseline_allocator = gpu.device.memory_in_use();
            }
            let phase_end = (i + 1) % PHASE_FRAMES == 0 || i + 1 == cmd.frames;
            if i == baseline_frame || (i > baseline_frame && phase_end) {
                resident.push((i, resident_bytes()?));
            }
        }
        let (resident_baseline, resident_end) = resident_halves(
            &resident,
            (baseline_frame, cmd.frames - 1),
            paths.len() as u64,
        );
        let baseline = (resident_baseline, baseline_allocator);
        let end = (resident_end, gpu.device.memory_in_use());
        Ok(SoakReport {
            device: gpu.device.caps.device_name.clone(),
            frames: cmd.frames,
            baseline_frame,
            resident_bytes_at_baseline: baseline.0,
            resident_bytes_at_end: end.0,
            allocator_bytes_at_baseline: baseline.1,
            allocator_bytes_at_end: end.1,
            resident_growth_percent: growth(baseline.0, end.0),
            allocator_growth_percent: growth(baseline.1, end.1),
            validation_enabled: gpu.validation_enabled(),
            validation_messages: 0,
            seconds: 0.0,
        })
    })?;
    let report = SoakReport {
        validation_messages: validation.count,
        seconds: start.elapsed().as_secs_f64(),
        ..report
    };
    if let Some(path) = &cmd.report {
        let json = serde_json::to_string_pretty(&report)? + "\n";
        crate::output::write_atomically(path, |tmp| {
            std::fs::write(tmp, json)
                .with_context(|| format!("{}: cannot write the report", path.display()))
        })?;
    }
    writeln!(
        out,
        "{} frames in {:.0} s on {}: resident {} -> {} bytes ({:+.3} %), allocator {} -> {} bytes ({:+.3} %) from frame {}, {} validation messages{}",
        report.frames,
        report.seconds,
        report.device,
        report.resident_bytes_at_baseline,
        report.resident_bytes_at_end,
        report.resident_growth_percent,
        report.allocator_bytes_at_baseline,
        report.allocator_bytes_at_end,
        report.allocator_growth_percent,
        report.baseline_frame,
        report.validation_messages,
        if report.validation_enabled { "" } else { " (validation off)" }
    )?;
    for (what, g) in [
        ("resident memory", report.resident_growth_percent),
        ("allocator memory", report.allocator_growth_percent),
    ] {
        if g >= cmd.max_growth {
            bail!(
                "{what} grew by {g:.3} % from frame {} to the end, over the {} % allowed",
                report.baseline_frame,
                cmd.max_growth
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_half_after_the_baseline_is_read_at_its_largest_phase() {
        // Phases of three paths, the third holding 10 more; flat memory
        // reads flat whichever phase the baseline and the last frame are in.
        let phase_bytes = |frame: u64| {
            100 + if (frame / PHASE_FRAMES) % 3 == 2 {
                10
            } else {
                0
            }
        };
        let samples = |grow: u64| -> Vec<(u64, u64)> {
            std::iter::once(1000)
                .chain((1049..2000).step_by(50))
                .map(|f| (f, phase_bytes(f) + grow * (f - 1000) / 1000))
                .collect()
        };
        assert_eq!(resident_halves(&samples(0), (1000, 1999), 3), (110, 110));
        // Growth shows in the second half's largest.
        let (a, b) = resident_halves(&samples(20), (1000, 1999), 3);
        assert!(b >= a + 8, "{a} -> {b}");
        // Too short to hold every path twice: the two frames themselves.
        let short = [(600, 110), (649, 110), (699, 100)];
        assert_eq!(resident_halves(&short, (600, 699), 3), (110, 100));
    }
}
