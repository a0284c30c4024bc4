//! The `vkterrain` command line: argument parsing, commands, JSON output.
//! Errors reach `main` as `anyhow` chains that name the file and the problem.

pub mod args;
pub mod assets;
pub mod progress;

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use glam::DVec2;
use serde::Serialize;

use crate::scene::Scene;
use crate::terrain::grid::validate_cells_per_patch;
use crate::terrain::{PatchGrid, PatchId, Placement, Terrain};
use args::{parse_point, TerrainArgs};

pub mod bench;
pub mod demo;
pub mod import;
pub mod render;
pub mod soak;
pub mod stream;

#[derive(Parser, Debug)]
#[command(
    name = "vkterrain",
    version,
    about = "Heightmap terrain renderer on Vulkan",
    after_help = "Without a command: the default scene in a window, or, with no display \
                  (DISPLAY and WAYLAND_DISPLAY unset), rendered headless to vkterrain-default.png."
)]
pub struct Cli {
    /// Without a command: the default scene in a window, or headless to
    /// vkterrain-default.png when there is no display.
    #[command(subcommand)]
    pub command: Option<Command>,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// The default scene (or any) in a window: fly, walk, debug views.
    Demo(demo::DemoCmd),
    /// Render one frame headless to a PNG (and optionally stats as JSON).
    Render(render::RenderCmd),
    /// The Vulkan device and driver, and which optional features are used.
    Info(render::InfoCmd),
    /// Surface heights at points, as a JSON array in input order.
    Height(HeightCmd),
    /// Size, height range and patch grid of a heightmap, as JSON.
    Inspect(InspectCmd),
    /// Speed against error: every path from the same cameras, measured
    /// against the brute reference (results.csv/json, pareto.png,
    /// BENCHMARKS.md).
    Bench(bench::BenchCmd),
    /// A long headless flythrough that switches paths and LOD modes,
    /// checking that memory stays flat and validation stays clean.
    Soak(soak::SoakCmd),
    /// Generate a fractal, eroded heightmap as a 16-bit PNG (the default
    /// scene's heightmap is `generate --out assets/heightmaps/default.png`).
    Generate(render::GenerateCmd),
    /// Cut a heightmap, or a mosaic of SRTM .hgt tiles, into a tiled
    /// terrain file that --heightmap opens on every command, reading only
    /// the tiles it needs where it can; prints what it wrote as JSON.
    Import(import::ImportCmd),
    /// A streamed flythrough of a tiled terrain that never waits on the
    /// disk: per-frame uploads, evictions and CPU time, holes and cracks,
    /// and optionally its error against the whole-terrain renderer (JSON
    /// report).
    Stream(stream::StreamCmd),
    /// Generate the default layer textures (tileable colour, normal and
    /// height maps for sand, grass, dirt, rock and snow).
    GenerateTextures(assets::GenerateTexturesCmd),
    /// Bake a rules-mode scene's layer weights into blend maps.
    GenerateBlendMap(assets::GenerateBlendMapCmd),
}

#[derive(clap::Args, Debug)]
pub struct HeightCmd {
    #[command(flatten)]
    pub terrain: TerrainArgs,

    /// A world point X,Z to query; repeat for more.
    #[arg(long = "at", value_name = "X,Z", value_parser = parse_point, allow_hyphen_values = true,
          required_unless_present = "points", conflicts_with = "points")]
    pub at: Vec<DVec2>,

    /// A file with one "x z" pair per line (blank lines and lines starting
    /// with '#' are skipped).
    #[arg(long, value_name = "FILE")]
    pub points: Option<PathBuf>,
}

#[derive(clap::Args, Debug)]
pub struct InspectCmd {
    #[command(flatten)]
    pub terrain: TerrainArgs,

    /// Cells per patch side: a power of two from 2 to 64 (default: the
    /// scene's, 32).
    #[arg(long, value_name = "N")]
    pub cells_per_patch: Option<u32>,

    /// List every patch with its extent and Y bounds.
    #[arg(long)]
    pub patches: bool,
}

/// Runs a parsed command, writing its output to `out`.
pub fn run(cli: Cli, out: &mut dyn Write) -> Result<()> {
    match cli.command {
        None => demo::run_default(out),
        Some(Command::Demo(cmd)) => demo::demo(cmd, out),
        Some(Command::Render(cmd)) => render::render(cmd, out),
        Some(Command::Info(cmd)) => render::info(cmd, out),
        Some(Command::Height(cmd)) => height(cmd, out),
        Some(Command::Inspect(cmd)) => inspect(cmd, out),
        Some(Command::Generate(cmd)) => render::generate(cmd, out),
        Some(Command::Import(cmd)) => import::import(cmd, out),
        Some(Command::GenerateTextures(cmd)) => assets::generate_textures(cmd, out),
        Some(Command::GenerateBlendMap(cmd)) => assets::generate_blend_map(cmd, out),
        Some(Command::Bench(cmd)) => bench::bench(cmd, out),
        Some(Command::Soak(cmd)) => soak::soak(cmd, out),
        Some(Command::Stream(cmd)) => stream::stream(cmd, out),
    }
}

/// The scene the arguments name, with `cells_per_patch` in place of its
/// own when given.
fn scene_with_patches(args: &TerrainArgs, cells_per_patch: Option<u32>) -> Result<Scene> {
    let mut scene = args.scene()?;
    if let Some(n) = cells_per_patch {
        // Checked first: a bad patch size shouldn't wait for a large file.
        validate_cells_per_patch(n)?;
        scene.cells_per_patch = n;
    }
    Ok(scene)
}

#[derive(Serialize)]
struct HeightAnswer {
    x: f64,
    z: f64,
    height: Option<f32>,
}

fn height(cmd: HeightCmd, out: &mut dyn Write) -> Result<()> {
    let points = match &cmd.points {
        Some(path) => read_points(path)?,
        None => cmd.at.clone(),
    };
    let scene = cmd.terrain.scene()?;
    let answers: Vec<HeightAnswer> = match scene.open_tiled()? {
        // Only the tiles the points fall in are read.
        Some((map, placement)) => points
            .iter()
            .map(|p| {
                Ok(HeightAnswer {
                    x: p.x,
                    z: p.y,
                    height: map.height_at(&placement, p.x, p.y)?,
                })
            })
            .collect::<Result<_>>()?,
        None => {
            let info = scene.terrain_info()?;
            points
                .iter()
                .map(|p| HeightAnswer {
                    x: p.x,
                    z: p.y,
                    height: info.height_at(p.x, p.y),
                })
                .collect()
        }
    };
    serde_json::to_writer_pretty(&mut *out, &answers)?;
    writeln!(out)?;
    Ok(())
}

/// Reads "x z" pairs, one per line.
fn read_points(path: &Path) -> Result<Vec<DVec2>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read points file", path.display()))?;
    let mut points = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split_whitespace().collect();
        let parsed = match fields[..] {
            [x, z] => args::parse_finite(x).and_then(|x| Ok(DVec2::new(x, args::parse_finite(z)?))),
            _ => Err(format!("expected two numbers \"x z\", found {line:?}")),
        };
        let p = parsed.map_err(|e| anyhow::anyhow!("{}:{}: {e}", path.display(), n + 1))?;
        points.push(p);
    }
    Ok(points)
}

#[derive(Serialize)]
struct InspectReport {
    width: usize,
    depth: usize,
    min_height: f32,
    max_height: f32,
    cell_spacing: [f64; 2],
    world_width: f64,
    world_depth: f64,
    cells_per_patch: u32,
    patch_rows: usize,
    patch_cols: usize,
    control_points: usize,
    indices: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    patches: Option<Vec<PatchReport>>,
}

#[derive(Serialize)]
struct PatchReport {
    row: usize,
    col: usize,
    x_min: f64,
    x_max: f64,
    z_min: f64,
    z_max: f64,
    min_y: f32,
    max_y: f32,
}

fn inspect(cmd: InspectCmd, out: &mut dyn Write) -> Result<()> {
    let scene = scene_with_patches(&cmd.terrain, cmd.cells_per_patch)?;
    let report = match scene.open_tiled()? {
        // Read a tile at a time: any size.
        Some((map, placement)) => {
            validate_cells_per_patch(scene.cells_per_patch)?;
            let grid = PatchGrid::for_size(map.width(), map.depth(), scene.cells_per_patch);
            let bounds = cmd.patches.then(|| map.patch_y_bounds(&grid)).transpose()?;
            inspect_report(&placement, &grid, map.min_max(), bounds.as_deref())
        }
        None => {
            let info = scene.terrain_info()?;
            let range = info.min_max();
            let terrain = Terrain::new(info, 0.0)?;
            let bounds = cmd.patches.then(|| terrain.y_bounds());
            inspect_report(terrain.info().placement(), terrain.grid(), range, bounds)
        }
    };
    serde_json::to_writer_pretty(&mut *out, &report)?;
    writeln!(out)?;
    Ok(())
}

/// What `inspect` reports, from the terrain's placement, grid and height
/// range, and each patch's Y bounds when they are listed.
fn inspect_report(
    placement: &Placement,
    grid: &PatchGrid,
    (min_height, max_height): (f32, f32),
    y_bounds: Option<&[[f32; 2]]>,
) -> InspectReport {
    let patches = y_bounds.map(|y_bounds| {
        (0..grid.patch_count())
            .map(|p| {
                let id: PatchId = grid.patch_id(p);
                let rect = grid.sample_rect(id);
                let upper_left = placement.sample_position(rect.row0, rect.col0);
                let lower_right = placement.sample_position(rect.row1, rect.col1);
                let [min_y, max_y] = y_bounds[p];
                PatchReport {
                    row: id.row,
                    col: id.col,
                    x_min: upper_left.x,
                    x_max: lower_right.x,
                    z_min: lower_right.y,
                    z_max: upper_left.y,
                    min_y,
                    max_y,
                }
            })
            .collect()
    });
    InspectReport {
        width: placement.cols(),
        depth: placement.rows(),
        min_height,
        max_height,
        cell_spacing: placement.spacing().to_array(),
        world_width: placement.world_width(),
        world_depth: placement.world_depth(),
        cells_per_patch: grid.cells_per_patch() as u32,
        patch_rows: grid.patch_rows(),
        patch_cols: grid.patch_cols(),
        control_points: grid.control_point_count(),
        indices: grid.patch_count() * 4,
        patches,
    }
}

/// Feeds untrusted `text` to every numeric argument parser, and as a whole
/// command line (split at whitespace) to clap, checking that what parses is
/// finite. The fuzz target (fuzz/) and its regression tests call this.
pub fn fuzz_parse(text: &str) {
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    if let Ok(v) = args::parse_finite(text) {
        assert!(v.is_finite());
    }
    if let Ok((w, d)) = args::parse_size(text) {
        assert!(w >= 2 && d >= 2);
    }
    for parsed in [args::parse_point(text), args::parse_spacing(text)]
        .into_iter()
        .flatten()
    {
        assert!(finite(&[parsed.x, parsed.y]));
    }
    if let Ok(p) = args::parse_dvec3(text) {
        assert!(finite(&[p.x, p.y, p.z]));
    }
    if let Ok((a, b)) = args::parse_range(text) {
        assert!(a.is_finite() && b.is_finite() && a <= b);
    }
    if let Ok(c) = args::parse_color(text) {
        assert!(c.iter().all(|v| (0.0..=1.0).contains(v)));
    }
    if let Ok(f) = args::parse_fov(text) {
        assert!(f > 0.0 && f < 180.0);
    }
    if let Ok(p) = args::parse_pixels(text) {
        assert!(p > 0);
    }
    if let Ok(b) = args::parse_budget(text) {
        assert!(b >= 1 << 20);
    }
    match args::parse_fault(text) {
        Ok(crate::gpu::Fault::DeviceLost { submission: n })
        | Ok(crate::gpu::Fault::OutOfDeviceMemory { allocation: n }) => assert!(n >= 1),
        Err(_) => {}
    }
    let args = std::iter::once("vkterrain").chain(text.split_whitespace());
    let _ = Cli::try_parse_from(args);
}
