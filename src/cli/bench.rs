//! `bench`: speed against error, every path from the same cameras.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};

use super::args::{FeatureArgs, SizeArgs, TerrainArgs};
use crate::bench::cameras::FLYTHROUGH;
use crate::bench::report::{self, check_targets};
use crate::bench::run::{configs, default_timed_frames, Bench, BenchOptions, Progress};
use crate::render::{LoadedScene, Loading};
use crate::scene::HeightmapSource;
use crate::terrain::Terrain;

fn parse_frames(s: &str) -> Result<usize, String> {
    let n: usize = s
        .parse()
        .map_err(|_| format!("{s:?} is not a frame count"))?;
    if n == 1 || n == 2 {
        return Err(format!(
            "{n} flythrough frames leave none to time after the warm-up: give 0 or at least 3"
        ));
    }
    if n > 100_000 {
        return Err(format!("{n} flythrough frames is more than 100000"));
    }
    Ok(n)
}

#[derive(clap::Args, Debug)]
pub struct BenchCmd {
    #[command(flatten)]
    pub terrain: TerrainArgs,

    #[command(flatten)]
    pub size: SizeArgs,

    /// One view and a short sweep, without the flythrough: a few minutes on
    /// lavapipe.
    #[arg(long)]
    pub quick: bool,

    /// Render and measure each fixed view once, without warm-up, timing each
    /// row by that frame and those drawn straight after it (up to 30 within
    /// 2.5 s), and leave the flythrough out: for terrains whose brute frame
    /// takes seconds.
    #[arg(long)]
    pub single_frame: bool,

    /// Measure only this view: grazing, overview, valley or flythrough
    /// (repeat the option for several). --quick, --single-frame and
    /// --frames 0 leave the flythrough out, so naming it alone with them is
    /// an error.
    #[arg(long = "view", value_name = "NAME", value_parser = ["grazing", "overview", "valley", "flythrough"])]
    pub views: Vec<String>,

    /// Before each timed frame of a fixed view, draw the same frame untimed
    /// for this many milliseconds: for a GPU that lowers its clock when
    /// lightly loaded (an NVIDIA data-centre card drops to a sixth of it
    /// between one-at-a-time frames), so that rows are timed at the clock
    /// of a busy application. The flythrough is not warmed. 0 (the
    /// default) draws nothing extra.
    #[arg(long, value_name = "MS", default_value = "0", value_parser = clap::value_parser!(u32).range(0..=10_000))]
    pub gpu_warm_ms: u32,

    /// Frames timed per row of a fixed view, whose median the row reports:
    /// 10 by default, after 2 untimed ones; with --single-frame 30 by
    /// default, as many of them as fit in 2.5 s, at least one.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub timed_frames: Option<u32>,

    /// Frames of the flythrough (0 leaves it out).
    #[arg(long, value_name = "N", default_value = "200", value_parser = parse_frames)]
    pub frames: usize,

    /// Directory for results.csv, results.json, pareto.png and
    /// BENCHMARKS.md. Rows already there for other scenes or devices are
    /// kept in the report.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,

    /// Also write BENCHMARKS.md to this path, with its link to the plot
    /// made relative to it (scripts/bench uses the repository root).
    #[arg(long, value_name = "PATH")]
    pub publish: Option<PathBuf>,

    /// Markdown appended after the targets (the explanations of misses).
    #[arg(long, value_name = "PATH")]
    pub notes: Option<PathBuf>,

    /// Name of the scene in the results (default: the scene or heightmap
    /// file's name, or "default").
    #[arg(long, value_name = "NAME")]
    pub name: Option<String>,

    /// Render nothing: rewrite the report, plot and CSV from DIR's
    /// results.json (after editing the notes, say).
    #[arg(long)]
    pub report_only: bool,

    /// Also time the scene's own view drawn plain and with each addition
    /// to the picture (triplanar projection, the sky, multisampling):
    /// look.json and a table in BENCHMARKS.md.
    #[arg(long)]
    pub look: bool,

    /// Turn on the Vulkan validation layer (slows every figure down).
    #[arg(long)]
    pub validate: bool,

    /// Features to behave as if the device lacked (without tessellation
    /// there are no tess rows; without timestamps or statistics those
    /// columns are empty).
    #[command(flatten)]
    pub features: FeatureArgs,
}

/// The progress bar; where stderr is no terminal (a log file, CI) the bar
/// is hidden and a line is printed every 5 % instead.
struct Bar {
    bar: ProgressBar,
    last_logged: u64,
}

impl Progress for Bar {
    fn start(&mut self, total: u64) {
        self.bar.set_length(total);
    }

    fn advance(&mut self, message: &str) {
        self.bar.set_message(message.to_string());
        self.bar.inc(1);
        if self.bar.is_hidden() {
            let (done, total) = (self.bar.position(), self.bar.length().unwrap_or(0).max(1));
            let percent = done * 100 / total;
            if percent >= self.last_logged + 5 || done == total {
                self.last_logged = percent;
                eprintln!(
                    "bench: {done}/{total} renders ({percent} %), {message}, {:.0} s",
                    self.bar.elapsed().as_secs_f64()
                );
            }
        }
    }
}

pub fn bench(cmd: BenchCmd, out: &mut dyn Write) -> Result<()> {
    let no_flythrough = cmd.quick || cmd.single_frame || cmd.frames == 0;
    if no_flythrough && !cmd.views.is_empty() && cmd.views.iter().all(|v| v == FLYTHROUGH) {
        bail!(
            "--view flythrough measures nothing with --quick, --single-frame or --frames 0, \
             which leave the flythrough out"
        );
    }
    let scene = cmd.terrain.scene()?;
    let name = cmd.name.clone().unwrap_or_else(|| {
        let file = cmd.terrain.scene.as_ref().or(match &scene.heightmap {
            HeightmapSource::File(p) => Some(p),
            HeightmapSource::Embedded { .. } => None,
        });
        file.and_then(|p| p.file_stem())
            .map_or("default".into(), |s| s.to_string_lossy().into_owned())
    });
    let notes = match &cmd.notes {
        Some(path) => std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read the notes", path.display()))?,
        None => String::new(),
    };
    // Refuse unusable results files before the long run, not after.
    let earlier = report::merge(&cmd.out, Vec::new())?;
    let earlier_look = report::merge_look(&cmd.out, Vec::new())?;
    if cmd.report_only {
        if earlier.is_empty() {
            bail!("{}: no results.json to report on", cmd.out.display());
        }
        let results = report::Results {
            rows: &earlier,
            look: &earlier_look,
        };
        report::write_all(&cmd.out, &results, &notes, cmd.publish.as_deref())?;
        writeln!(
            out,
            "rewrote the report of {} rows in {}",
            earlier.len(),
            cmd.out.display()
        )?;
        return Ok(());
    }
    let terrain = LoadedScene::load(&scene, Loading::WHOLE_TERRAIN)?.terrain;
    // Validation is counted after the device is destroyed, so leaked
    // objects count.
    let (((rows, device_name, options), look), validation) =
        cmd.features.with_gpu(cmd.validate, |gpu| {
            let measured = measure(gpu, &cmd, &scene, &terrain, &name, out)?;
            let look = match cmd.look {
                false => Vec::new(),
                true => {
                    // A handful of frames whatever the run: one look is
                    // a few seconds even on lavapipe.
                    let frames = 7;
                    crate::bench::look::measure(
                        gpu,
                        &scene,
                        &name,
                        (cmd.size.width, cmd.size.height),
                        frames,
                    )?
                }
            };
            Ok((measured, look))
        })?;
    let all = report::merge(&cmd.out, rows.clone())?;
    let all_look = report::merge_look(&cmd.out, look.clone())?;
    let results = report::Results {
        rows: &all,
        look: &all_look,
    };
    report::write_all(&cmd.out, &results, &notes, cmd.publish.as_deref())?;
    writeln!(
        out,
        "{} rows on {} ({}x{}, {}), {} validation messages{}",
        rows.len(),
        name,
        options.width,
        options.height,
        device_name,
        validation.count,
        if validation.enabled {
            ""
        } else {
            " (validation off)"
        }
    )?;
    for camera in report::first_seen(&rows, |r| r.camera.clone()) {
        let group: Vec<_> = rows.iter().filter(|r| r.camera == camera).collect();
        let c = check_targets(&group);
        let f = |v: Option<f64>| v.map_or("n/a".into(), |v| format!("{v:.2}"));
        let f3 = |v: Option<f64>| v.map_or("n/a".into(), |v| format!("{v:.3}"));
        writeln!(
            out,
            "  {camera}: tess error p99 {} / {} / {} px at tau 0.5 / 1 / 2, level choice at most \
             {} ms (geomip {} ms); at 1 px: frame {} ms, tess/fastest {}x (fastest at p99 <= 1 px: \
             {}), tess/brute triangles {}x, tess/fewest {}x (fewest: {}); geomip p99 {} / {} / {} px",
            f(c.tess_p99[0]),
            f(c.tess_p99[1]),
            f(c.tess_p99[2]),
            f3(c.tess_lod_ms_max),
            f3(c.geomip_lod_ms_max),
            f(c.tess_frame_ms),
            f(c.tess_vs_fastest),
            c.fastest_config.as_deref().unwrap_or("none"),
            f(c.tess_vs_brute_triangles),
            f(c.tess_vs_fewest),
            c.fewest_config.as_deref().unwrap_or("none"),
            f(c.geomip_p99[0]),
            f(c.geomip_p99[1]),
            f(c.geomip_p99[2]),
        )?;
    }
    for r in &look {
        writeln!(
            out,
            "  look {}: GPU {} ms ({})",
            r.config,
            r.gpu_ms.map_or("n/a".into(), |v| format!("{v:.2}")),
            crate::bench::look::extra_percent(&look, r)
                .map_or("n/a".into(), |p| format!("{p:+.1} % over plain")),
        )?;
    }
    writeln!(
        out,
        "wrote {}/results.csv, results.json, pareto.png and BENCHMARKS.md{}",
        cmd.out.display(),
        cmd.publish
            .as_ref()
            .map_or(String::new(), |p| format!(", and {}", p.display()))
    )?;
    Ok(())
}

/// Every configuration of `cmd` on every view of the terrain, on `gpu`.
/// Returns the rows, the device's name and the options they were taken
/// with.
fn measure(
    gpu: &crate::gpu::Gpu,
    cmd: &BenchCmd,
    scene: &crate::scene::Scene,
    terrain: &Terrain,
    name: &str,
    out: &mut dyn Write,
) -> Result<(Vec<crate::bench::run::Row>, String, BenchOptions)> {
    let tessellation = gpu.device.caps.tessellation_shader;
    if !tessellation {
        writeln!(
            out,
            "{}: tessellationShader is unavailable, so the tess rows are left out",
            gpu.device.caps.device_name
        )?;
    }
    let scene_lod = scene.distance_lod(terrain.info());
    let configs = configs(scene_lod, cmd.quick, tessellation);
    let options = BenchOptions {
        width: cmd.size.width,
        height: cmd.size.height,
        quick: cmd.quick,
        flythrough_frames: if cmd.quick || cmd.single_frame {
            0
        } else {
            cmd.frames
        },
        single_frame: cmd.single_frame,
        views: cmd.views.clone(),
        gpu_warm_ms: cmd.gpu_warm_ms,
        timed_frames: cmd
            .timed_frames
            .map_or(default_timed_frames(cmd.single_frame), |n| n as usize),
    };
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:40}] {pos}/{len} renders, {msg}")
            .expect("a valid template")
            .progress_chars("=> "),
    );
    let mut progress = Bar {
        bar,
        last_logged: 0,
    };
    let mut bench = Bench::new(
        gpu,
        terrain,
        scene_lod,
        &configs,
        options.width,
        options.height,
    )?;
    let rows = bench.run(name, &configs, &options, &mut progress);
    progress.bar.finish_and_clear();
    Ok((rows?, gpu.device.caps.device_name.clone(), options))
}
