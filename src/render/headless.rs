//! Rendering one frame into an offscreen target and reading it back: the
//! same draw code the window uses, with an image the CPU can inspect.

use std::time::Instant;

use super::figures::FrameFigures;
use super::renderer::{FrameMeasurements, RendererOptions, TerrainRenderer};
use super::settings::RenderSettings;
use super::view::FrameView;
use crate::appearance::Appearance;
use crate::gpu::commands::CommandSlots;
use crate::gpu::target::{OffscreenTarget, Readback, OFFSCREEN_COLOR_FORMAT};
use crate::gpu::{Device, Gpu};
use crate::render::error::Result;
use crate::terrain::camera::Camera;
use crate::terrain::Terrain;

/// One rendered frame.
pub struct HeadlessFrame {
    pub readback: Readback,
    pub measurements: FrameMeasurements,
    /// CPU time to prepare and record the frame (not waiting for the GPU).
    pub cpu_ms: f64,
    /// Of that, the level choice's (`TerrainRenderer::lod_ms`).
    pub lod_ms: Option<f64>,
    pub view: FrameView,
    pub patches_in_frustum: usize,
}

impl HeadlessFrame {
    /// What the frame cost and drew.
    pub fn figures(&self) -> FrameFigures {
        FrameFigures::new(&self.measurements, self.cpu_ms, self.lod_ms)
    }

    /// Pixels that show terrain (depth above 0, the far plane in reversed
    /// Z).
    pub fn covered_pixels(&self) -> usize {
        self.readback.depth.iter().filter(|&&d| d > 0.0).count()
    }

    /// The colour image (sRGB, as stored).
    pub fn rgba_image(&self) -> image::RgbaImage {
        image::RgbaImage::from_raw(
            self.readback.width,
            self.readback.height,
            self.readback.rgba.clone(),
        )
        .expect("readback holds width * height RGBA pixels")
    }
}

/// A renderer of `options` for offscreen targets, and a `width` x `height`
/// target to draw into: what one-shot renders, the soak and the tests use.
pub fn offscreen(
    gpu: &Gpu,
    terrain: &Terrain,
    appearance: &Appearance,
    options: &RendererOptions,
    (width, height): (u32, u32),
) -> Result<(TerrainRenderer, Headless)> {
    // The target first: a streamed terrain's pool takes what the memory
    // budget leaves.
    let headless = Headless::new(gpu, width, height, options.samples)?;
    let renderer = TerrainRenderer::with_appearance(
        gpu,
        terrain,
        appearance,
        OFFSCREEN_COLOR_FORMAT,
        1,
        options,
    )?;
    Ok((renderer, headless))
}

/// An offscreen target and the command buffer that draws into it. Dropping
/// it waits for the device to go idle first.
pub struct Headless {
    /// Whether a frame of a streamed terrain first waits until what its
    /// view needs is resident (one-shot renders); off, frames draw with
    /// what has arrived, as the window does (flythroughs).
    pub wait_for_residency: bool,
    commands: CommandSlots,
    target: OffscreenTarget,
    device: Device,
}

impl Headless {
    /// A `width` x `height` target of `samples` samples per pixel.
    pub fn new(gpu: &Gpu, width: u32, height: u32, samples: u32) -> Result<Self> {
        let device = &gpu.device;
        Ok(Headless {
            wait_for_residency: true,
            target: OffscreenTarget::new(device, width, height, samples)?,
            commands: device.create_command_slots(1, "headless.commands")?,
            device: device.clone(),
        })
    }

    /// Renders `terrain` from `camera`, waits for the result and reads
    /// the image back.
    pub fn render(
        &mut self,
        renderer: &mut TerrainRenderer,
        terrain: &Terrain,
        camera: &Camera,
        settings: &RenderSettings,
    ) -> Result<HeadlessFrame> {
        let (timed, view) = self.draw(renderer, terrain, camera, settings, true)?;
        // Counted for the frame's statistics, after its time is taken.
        let patches_in_frustum = view.patches_in_frustum(terrain);
        Ok(HeadlessFrame {
            readback: self.target.read()?,
            measurements: timed.measurements,
            cpu_ms: timed.cpu_ms,
            lod_ms: timed.lod_ms,
            view,
            patches_in_frustum,
        })
    }

    /// Renders `terrain` from `camera` and waits for it, reading nothing
    /// back: a frame as a render loop draws it, for timing.
    pub fn time(
        &mut self,
        renderer: &mut TerrainRenderer,
        terrain: &Terrain,
        camera: &Camera,
        settings: &RenderSettings,
    ) -> Result<TimedFrame> {
        Ok(self.draw(renderer, terrain, camera, settings, false)?.0)
    }

    fn draw(
        &mut self,
        renderer: &mut TerrainRenderer,
        terrain: &Terrain,
        camera: &Camera,
        settings: &RenderSettings,
        read_back: bool,
    ) -> Result<(TimedFrame, FrameView)> {
        let views = self.target.views();
        let view = FrameView::new(terrain, camera, views.extent.width, views.extent.height);
        // The one slot's last frame has completed: `render` waits for it.
        if self.wait_for_residency {
            renderer.settle(0, &view)?;
        }
        let start = Instant::now();
        renderer.prepare(0, terrain, &view, settings)?;
        let rec = self.commands.begin(0)?;
        self.target.record_begin(&rec);
        renderer.record(&rec, 0, &views)?;
        if read_back {
            self.target.record_readback(&rec);
        }
        let cpu_ms = start.elapsed().as_secs_f64() * 1e3;
        rec.submit_and_wait()?;
        let timed = TimedFrame {
            measurements: renderer.measurements(0)?,
            cpu_ms,
            lod_ms: renderer.lod_ms(),
        };
        Ok((timed, view))
    }
}

/// What a frame drawn for timing measured.
pub struct TimedFrame {
    pub measurements: FrameMeasurements,
    /// CPU time to prepare and record the frame (not waiting for the GPU).
    pub cpu_ms: f64,
    /// Of that, the level choice's (`TerrainRenderer::lod_ms`).
    pub lod_ms: Option<f64>,
}

impl TimedFrame {
    /// What the frame cost and drew.
    pub fn figures(&self) -> FrameFigures {
        FrameFigures::new(&self.measurements, self.cpu_ms, self.lod_ms)
    }
}

impl Drop for Headless {
    fn drop(&mut self) {
        // A failed frame may have left work in flight.
        let _ = self.device.wait_idle();
    }
}
