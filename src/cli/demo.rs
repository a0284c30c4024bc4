//! `vkterrain demo`: the window, and the bare command's choice between a
//! window and a headless render.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{bail, Result};
use ash::vk;
use clap::ValueEnum;

use super::args::{parse_args, SizeArgs, TerrainArgs};
use super::render::{render, RenderCmd, ViewArgs, DEFAULT_OUTPUT};
use crate::app::{self, DemoOptions};
use crate::render::{LoadedScene, Loading};

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum PresentModeArg {
    /// Wait for vertical blank; always available.
    #[default]
    Fifo,
    /// Replace the queued image; no tearing, no waiting.
    Mailbox,
    /// Present at once; may tear.
    Immediate,
}

#[derive(clap::Args, Debug)]
pub struct DemoCmd {
    #[command(flatten)]
    pub terrain: TerrainArgs,

    #[command(flatten)]
    pub view: ViewArgs,

    #[command(flatten)]
    pub size: SizeArgs,

    /// How frames reach the screen (FIFO when the one asked for is missing).
    #[arg(long, value_enum, default_value_t = PresentModeArg::Fifo)]
    pub present_mode: PresentModeArg,

    /// Render this many frames (with --exit).
    #[arg(long, value_name = "N", requires = "exit")]
    pub frames: Option<u64>,

    /// Resize the window at frame K, to a tiny size two frames later, and back.
    #[arg(long, value_name = "K", requires = "frames")]
    pub resize_at: Option<u64>,

    /// Request N window sizes in a row, one per redraw (tiny ones and
    /// minimises included), then go back to the starting size.
    #[arg(long, value_name = "N", requires = "frames")]
    pub resize_storm: Option<u64>,

    /// Write the last frame to this PNG.
    #[arg(long, value_name = "PATH", requires = "frames")]
    pub screenshot: Option<PathBuf>,

    /// Exit after --frames frames.
    #[arg(long, requires = "frames")]
    pub exit: bool,

    /// Eye height above the ground when walking (keys 2 / 3).
    #[arg(long, value_name = "H", default_value_t = 1.8, value_parser = positive)]
    pub walk_height: f64,

    /// Turn on the Vulkan validation layer (also VKTERRAIN_VALIDATE=1).
    #[arg(long)]
    pub validate: bool,
}

fn positive(s: &str) -> Result<f64, String> {
    let v = super::args::parse_finite(s)?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{s:?} must be positive"))
    }
}

pub fn demo(cmd: DemoCmd, out: &mut dyn Write) -> Result<()> {
    if cmd.frames == Some(0) {
        bail!("--frames must be at least 1");
    }
    let mut scene = cmd.terrain.scene()?;
    cmd.view.apply_to_scene(&mut scene)?;
    let LoadedScene {
        terrain,
        appearance,
        stream,
        ..
    } = LoadedScene::load(
        &scene,
        Loading {
            stream: !cmd.view.features.no_streaming,
            appearance: true,
        },
    )?;
    let settings = cmd.view.settings(&scene, terrain.info());
    let camera = cmd
        .view
        .camera_override()
        .apply(scene.camera_for(terrain.info()))?;
    writeln!(out, "{}", app::HELP)?;
    let summary = app::run(DemoOptions {
        terrain,
        stream,
        appearance,
        camera,
        settings,
        width: cmd.size.width,
        height: cmd.size.height,
        present_mode: match cmd.present_mode {
            PresentModeArg::Fifo => vk::PresentModeKHR::FIFO,
            PresentModeArg::Mailbox => vk::PresentModeKHR::MAILBOX,
            PresentModeArg::Immediate => vk::PresentModeKHR::IMMEDIATE,
        },
        samples: cmd.view.samples,
        gpu: cmd.view.features.gpu_options(cmd.validate),
        walk_height: cmd.walk_height,
        frames: cmd.frames,
        resize_at: cmd.resize_at,
        resize_storm: cmd.resize_storm,
        screenshot: cmd.screenshot.clone(),
    })?;
    let fps = summary.frames as f64 / summary.seconds.max(1e-9);
    writeln!(
        out,
        "rendered {} frames in {:.2} s ({fps:.1} fps) on {}; last frame: GPU {}, {} triangles; {} validation messages",
        summary.frames,
        summary.seconds,
        summary.device,
        summary.last.gpu_ms.map_or("n/a".into(), |ms| format!("{ms:.2} ms")),
        summary
            .last
            .statistics
            .map_or("n/a".into(), |s| s.clipping_primitives.to_string()),
        summary.validation.count,
    )?;
    let sizes: Vec<String> = summary
        .sizes
        .iter()
        .map(|(w, h)| format!("{w}x{h}"))
        .collect();
    writeln!(
        out,
        "swapchain built {} times; sizes {}",
        summary.swapchains_built,
        sizes.join(" -> ")
    )?;
    writeln!(
        out,
        "renderer planned again {} times for a larger window; GPU memory in use at the end: {:.1} MiB",
        summary.replans,
        summary.memory_in_use as f64 / (1u64 << 20) as f64
    )?;
    if let Some(path) = &cmd.screenshot {
        writeln!(out, "wrote {}", path.display())?;
    }
    summary.validation.check()?;
    Ok(())
}

/// True when a window system is there to open a window on.
pub fn display_available() -> bool {
    ["DISPLAY", "WAYLAND_DISPLAY"]
        .iter()
        .any(|v| std::env::var_os(v).is_some_and(|s| !s.is_empty()))
}

/// The bare command: the default scene in a window, or, with no display,
/// headless to vkterrain-default.png.
pub fn run_default(out: &mut dyn Write) -> Result<()> {
    if display_available() {
        return demo(parse_args::<DemoCmd>(&[])?, out);
    }
    writeln!(
        out,
        "no display (DISPLAY and WAYLAND_DISPLAY are unset): rendering the default scene headless instead"
    )?;
    render(parse_args::<RenderCmd>(&["--out", DEFAULT_OUTPUT])?, out)
}
