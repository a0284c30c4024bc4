//! Rendering one frame into an offscreen target and reading it back: the
//! same draw code the window uses, with an image the CPU can inspect.

use std::time::Instant;

use ash::vk;

use super::renderer::{FrameMeasurements, TerrainRenderer};
use super::uniforms::{FrameView, RenderSettings};
use crate::terrain::camera::Camera;
use crate::terrain::Terrain;
use crate::vk::target::{OffscreenTarget, Readback};
use crate::vk::{Gpu, Result};

/// One rendered frame.
pub struct HeadlessFrame {
    pub readback: Readback,
    pub measurements: FrameMeasurements,
    /// CPU time to prepare and record the frame (not waiting for the GPU).
    pub cpu_ms: f64,
    pub view: FrameView,
    pub patches_in_frustum: usize,
}

impl HeadlessFrame {
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

pub struct Headless {
    target: OffscreenTarget,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
}

impl Headless {
    pub fn new(gpu: &Gpu, width: u32, height: u32) -> Result<Self> {
        let device = &gpu.device;
        let target = OffscreenTarget::new(device, &gpu.instance, width, height)?;
        let pool = match device.create_command_pool("headless.command_pool") {
            Ok(p) => p,
            Err(e) => {
                target.destroy(device);
                return Err(e);
            }
        };
        let rest = device
            .allocate_command_buffers(pool, 1, "headless.commands")
            .and_then(|cmds| Ok((cmds[0], device.create_fence("headless.fence", false)?)));
        match rest {
            Ok((cmd, fence)) => Ok(Headless {
                target,
                pool,
                cmd,
                fence,
            }),
            Err(e) => {
                device.destroy_command_pool(pool);
                target.destroy(device);
                Err(e)
            }
        }
    }

    /// Renders `terrain` from `camera` and waits for the result.
    pub fn render(
        &mut self,
        gpu: &Gpu,
        renderer: &mut TerrainRenderer,
        terrain: &Terrain,
        camera: &Camera,
        settings: &RenderSettings,
    ) -> Result<HeadlessFrame> {
        let device = &gpu.device;
        let start = Instant::now();
        let views = self.target.views();
        let view = FrameView::new(terrain, camera, views.extent.width, views.extent.height);
        let patches_in_frustum = view.patches_in_frustum(terrain);
        renderer.prepare(0, terrain, &view, settings)?;
        let rec = device.begin_commands(self.cmd)?;
        self.target.record_begin(rec.device, rec.cmd);
        renderer.record(&rec, 0, &views, settings)?;
        self.target.record_readback(&rec);
        let cmd = rec.finish()?;
        let cpu_ms = start.elapsed().as_secs_f64() * 1e3;
        device.reset_fence(self.fence)?;
        device.submit(cmd, self.fence)?;
        device.wait_fence(self.fence)?;
        Ok(HeadlessFrame {
            readback: self.target.read()?,
            measurements: renderer.measurements(device, 0)?,
            cpu_ms,
            view,
            patches_in_frustum,
        })
    }

    pub fn destroy(self, gpu: &Gpu) {
        let device = &gpu.device;
        device.destroy_fence(self.fence);
        device.destroy_command_pool(self.pool);
        self.target.destroy(device);
    }
}
