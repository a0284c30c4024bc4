//! The window demo: winit, a swapchain, fly and walk cameras, debug toggles,
//! and scripted runs for tests. It draws with the same renderer as the
//! headless path; only the target differs.

pub mod camera;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};
use ash::vk;
use raw_window_handle::{HasDisplayHandle, HasWindowHandle};
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{DeviceEvent, DeviceId, ElementState, KeyEvent, MouseButton, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

use crate::render::{
    FrameMeasurements, FrameView, RenderPath, RenderSettings, RendererOptions, Shading,
    TerrainRenderer,
};
use crate::terrain::camera::Camera;
use crate::terrain::{DistanceMode, Terrain};
use crate::vk::memory::{transition_images, Buffer, BufferDesc, Transition};
use crate::vk::swapchain::{surface_extensions, Acquired, Surface, Swapchain};
use crate::vk::{Device, DisabledFeatures, Gpu, Instance};
use camera::{CameraController, Mode, Movement};

/// Frames the CPU may record ahead of the GPU.
pub const FRAMES_IN_FLIGHT: usize = 2;

pub const HELP: &str = "\
vkterrain controls
  W A S D        move            E / Q   up / down (fly)
  right mouse    look around     Shift   faster
  2 / 3          walk / fly
  F1  this help                  F2  wireframe (when the device supports it)
  F3  LOD colours                F4  freeze culling (keep the current frustum)
  F5  LOD debug mode             F6  render path (tess, geomip, brute)
  - / =   LOD distances down / up
  F12 screenshot                 Esc     quit";

/// What the demo runs.
#[derive(Clone, Debug)]
pub struct DemoOptions {
    pub terrain: Terrain,
    /// The scene's material layers and lightmap.
    pub appearance: crate::material::Appearance,
    pub camera: Camera,
    pub settings: RenderSettings,
    pub width: u32,
    pub height: u32,
    pub present_mode: vk::PresentModeKHR,
    pub validate: bool,
    /// Eye height above the ground when walking.
    pub walk_height: f64,
    /// Features to behave as if the device lacked.
    pub disabled: DisabledFeatures,
    /// Largest GPU memory to allocate, in bytes.
    pub memory_budget: Option<u64>,
    /// A failure to inject (`--inject-fault`).
    pub fault: Option<crate::vk::Fault>,
    /// Stop after this many rendered frames.
    pub frames: Option<u64>,
    /// Resize at this frame, then to a tiny size two frames later, then back.
    pub resize_at: Option<u64>,
    /// Request this many window sizes, one per redraw, including tiny ones
    /// and a minimise every 25th, then go back to the starting size.
    pub resize_storm: Option<u64>,
    /// Write the last frame here (with `frames`).
    pub screenshot: Option<PathBuf>,
}

/// What a finished run reports.
#[derive(Clone, Debug, Default)]
pub struct DemoSummary {
    pub frames: u64,
    pub seconds: f64,
    pub validation_messages: u32,
    pub first_messages: Vec<String>,
    pub last: FrameMeasurements,
    pub device: String,
    /// Swapchains built, the first one included.
    pub swapchains_built: u32,
    /// Distinct swapchain sizes seen, in order.
    pub sizes: Vec<(u32, u32)>,
}

/// Opens the window and runs until it closes or the scripted frames are done.
pub fn run(options: DemoOptions) -> Result<DemoSummary> {
    let event_loop = EventLoop::new().context("opening the window system")?;
    event_loop.set_control_flow(ControlFlow::Poll);
    let mut app = App {
        options,
        running: None,
        error: None,
        summary: None,
    };
    event_loop.run_app(&mut app).context("running the window")?;
    if let Some(e) = app.error {
        return Err(e);
    }
    app.summary
        .ok_or_else(|| anyhow!("the window closed before it was shown"))
}

struct App {
    options: DemoOptions,
    running: Option<Running>,
    error: Option<anyhow::Error>,
    summary: Option<DemoSummary>,
}

/// Per-frame-in-flight synchronisation.
struct FrameSync {
    cmd: vk::CommandBuffer,
    /// Signalled when this slot's last submission finished.
    fence: vk::Fence,
    image_available: vk::Semaphore,
    submitted: bool,
}

#[derive(Default)]
struct Keys {
    forward: bool,
    back: bool,
    left: bool,
    right: bool,
    up: bool,
    down: bool,
    fast: bool,
    looking: bool,
}

struct Running {
    // Vulkan objects are torn down explicitly in `shutdown`; the window is
    // the last field so it outlives the surface made from it.
    gpu: Gpu,
    surface: Option<Surface>,
    swapchain: Option<Swapchain>,
    renderer: Option<TerrainRenderer>,
    pool: vk::CommandPool,
    frames: Vec<FrameSync>,
    screenshot_buffer: Option<Buffer>,
    frame: u64,
    rebuild: bool,
    /// Resize-storm requests made so far.
    storm_step: u64,
    controller: CameraController,
    keys: Keys,
    settings: RenderSettings,
    frozen: Option<FrameView>,
    last_tick: Instant,
    started: Instant,
    fps_window: (Instant, u64),
    fps: f64,
    last: FrameMeasurements,
    patches_drawn: usize,
    screenshots: u32,
    swapchains_built: u32,
    sizes: Vec<(u32, u32)>,
    window: Window,
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.running.is_some() {
            return;
        }
        match Running::start(event_loop, &self.options) {
            Ok(running) => self.running = Some(running),
            Err(e) => {
                self.error = Some(e);
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let Some(running) = self.running.as_mut() else {
            return;
        };
        let result = match event {
            WindowEvent::CloseRequested => {
                event_loop.exit();
                Ok(())
            }
            WindowEvent::Resized(_) => {
                running.rebuild = true;
                Ok(())
            }
            WindowEvent::KeyboardInput { event, .. } => {
                running.key(event_loop, &event, &self.options)
            }
            WindowEvent::MouseInput {
                button: MouseButton::Right,
                state,
                ..
            } => {
                running.keys.looking = state == ElementState::Pressed;
                Ok(())
            }
            WindowEvent::RedrawRequested => running.redraw(event_loop, &self.options),
            _ => Ok(()),
        };
        if let Err(e) = result {
            self.error = Some(e);
            event_loop.exit();
        }
    }

    fn device_event(&mut self, _event_loop: &ActiveEventLoop, _id: DeviceId, event: DeviceEvent) {
        if let (Some(running), DeviceEvent::MouseMotion { delta }) = (self.running.as_mut(), event)
        {
            if running.keys.looking {
                running.controller.look(delta.0, delta.1);
            }
        }
    }

    fn about_to_wait(&mut self, _event_loop: &ActiveEventLoop) {
        if let Some(running) = &self.running {
            running.window.request_redraw();
        }
    }

    fn exiting(&mut self, _event_loop: &ActiveEventLoop) {
        if let Some(running) = self.running.take() {
            match running.shutdown() {
                Ok(summary) => self.summary = Some(summary),
                Err(e) => {
                    if self.error.is_none() {
                        self.error = Some(e);
                    }
                }
            }
        }
    }
}

impl Running {
    fn start(event_loop: &ActiveEventLoop, options: &DemoOptions) -> Result<Running> {
        let window = event_loop
            .create_window(
                Window::default_attributes()
                    .with_title("vkterrain")
                    .with_inner_size(PhysicalSize::new(options.width, options.height)),
            )
            .context("creating the window")?;
        let display = window
            .display_handle()
            .context("reading the display handle")?
            .as_raw();
        let handle = window
            .window_handle()
            .context("reading the window handle")?
            .as_raw();
        let validate =
            options.validate || std::env::var(crate::vk::VALIDATE_ENV).is_ok_and(|v| v == "1");
        let instance =
            Instance::new(validate, surface_extensions(display)?).context("starting Vulkan")?;
        let surface = Surface::new(&instance, display, handle)?;
        let device = match Device::new(&instance, &[ash::khr::swapchain::NAME], &options.disabled) {
            Ok(d) => d,
            Err(e) => {
                surface.destroy();
                return Err(e).context("opening the Vulkan device");
            }
        };
        device.set_memory_budget(options.memory_budget);
        device.set_fault(options.fault);
        let gpu = Gpu { device, instance };
        if let Err(e) = surface.check_support(&gpu.device) {
            surface.destroy();
            return Err(e.into());
        }
        let mut running = Running {
            surface: Some(surface),
            swapchain: None,
            renderer: None,
            pool: vk::CommandPool::null(),
            frames: Vec::new(),
            screenshot_buffer: None,
            frame: 0,
            rebuild: true,
            controller: CameraController {
                eye_height: options.walk_height,
                ..CameraController::new(&options.camera, speed_for(&options.terrain))
            },
            keys: Keys::default(),
            settings: options.settings,
            frozen: None,
            last_tick: Instant::now(),
            started: Instant::now(),
            fps_window: (Instant::now(), 0),
            fps: 0.0,
            last: FrameMeasurements::default(),
            patches_drawn: 0,
            screenshots: 0,
            swapchains_built: 0,
            sizes: Vec::new(),
            storm_step: 0,
            window,
            gpu,
        };
        if let Err(e) = running.create_frame_resources(options) {
            let _ = running.shutdown();
            return Err(e);
        }
        let mut notes = Vec::new();
        running.settings =
            crate::render::with_fallback(running.settings, &running.gpu.device.caps, &mut notes);
        for note in notes {
            println!("{note}");
        }
        if running.settings.wireframe && !running.gpu.device.caps.fill_mode_non_solid {
            running.settings.wireframe = false;
            log::warn!("wireframe needs fillModeNonSolid, which this device lacks");
        }
        println!("{HELP}");
        Ok(running)
    }

    fn create_frame_resources(&mut self, options: &DemoOptions) -> Result<()> {
        // The swapchain's format is needed for the pipeline: make it first.
        self.rebuild_swapchain(options)?;
        let format = self
            .swapchain
            .as_ref()
            .map(|s| s.format.format)
            .unwrap_or(vk::Format::B8G8R8A8_SRGB);
        let wireframe = self.gpu.device.caps.fill_mode_non_solid;
        self.renderer = Some(
            TerrainRenderer::with_appearance(
                &self.gpu,
                &options.terrain,
                &options.appearance,
                format,
                FRAMES_IN_FLIGHT as u32,
                // Brute adds pipelines only (no buffers): cheap to have ready
                // for the path key.
                &RendererOptions {
                    paths: self.paths(),
                    wireframe,
                },
            )
            .context("preparing the terrain for the GPU")?,
        );
        let device = &self.gpu.device;
        self.pool = device.create_command_pool("demo.command_pool")?;
        let cmds =
            device.allocate_command_buffers(self.pool, FRAMES_IN_FLIGHT as u32, "demo.commands")?;
        for (i, cmd) in cmds.into_iter().enumerate() {
            self.frames.push(FrameSync {
                cmd,
                fence: device.create_fence(&format!("demo.frame_fence[{i}]"), true)?,
                image_available: device.create_semaphore(&format!("demo.image_available[{i}]"))?,
                submitted: false,
            });
        }
        Ok(())
    }

    /// Rebuilds the swapchain for the window's current size; a zero-sized
    /// (minimised) window leaves none, and drawing pauses.
    fn rebuild_swapchain(&mut self, options: &DemoOptions) -> Result<()> {
        let size = self.window.inner_size();
        self.gpu.device.wait_idle()?;
        let old = self.swapchain.take();
        if size.width == 0 || size.height == 0 {
            if let Some(old) = old {
                old.destroy(&self.gpu.device);
            }
            return Ok(());
        }
        let surface = self.surface.as_ref().expect("surface lives while running");
        let swapchain = Swapchain::new(
            &self.gpu.instance,
            &self.gpu.device,
            surface,
            vk::Extent2D {
                width: size.width,
                height: size.height,
            },
            options.present_mode,
            old,
        )
        .context("building the swapchain")?;
        if let Some(renderer) = &self.renderer {
            if renderer.color_format() != swapchain.format.format {
                bail!(
                    "the swapchain changed format from {:?} to {:?}",
                    renderer.color_format(),
                    swapchain.format.format
                );
            }
        }
        self.swapchains_built += 1;
        let size = (swapchain.extent.width, swapchain.extent.height);
        if self.sizes.last() != Some(&size) {
            self.sizes.push(size);
        }
        self.swapchain = Some(swapchain);
        self.rebuild = false;
        Ok(())
    }

    fn key(
        &mut self,
        event_loop: &ActiveEventLoop,
        event: &KeyEvent,
        options: &DemoOptions,
    ) -> Result<()> {
        let PhysicalKey::Code(code) = event.physical_key else {
            return Ok(());
        };
        let pressed = event.state == ElementState::Pressed;
        let keys = &mut self.keys;
        match code {
            KeyCode::KeyW => keys.forward = pressed,
            KeyCode::KeyS => keys.back = pressed,
            KeyCode::KeyA => keys.left = pressed,
            KeyCode::KeyD => keys.right = pressed,
            KeyCode::KeyE => keys.up = pressed,
            KeyCode::KeyQ => keys.down = pressed,
            KeyCode::ShiftLeft | KeyCode::ShiftRight => keys.fast = pressed,
            _ if !pressed || event.repeat => {}
            KeyCode::Escape => event_loop.exit(),
            KeyCode::Digit2 => self.controller.set_mode(Mode::Walk, options.terrain.info()),
            KeyCode::Digit3 => self.controller.set_mode(Mode::Fly, options.terrain.info()),
            KeyCode::F1 => println!("{HELP}"),
            KeyCode::F2 => {
                if self.gpu.device.caps.fill_mode_non_solid {
                    self.settings.wireframe = !self.settings.wireframe;
                } else {
                    println!("wireframe is unavailable: the device lacks fillModeNonSolid");
                }
            }
            KeyCode::F3 => {
                self.settings.shading = match self.settings.shading {
                    Shading::LodColors => Shading::Lit,
                    _ => Shading::LodColors,
                }
            }
            KeyCode::F4 => {
                self.frozen = match self.frozen {
                    Some(_) => None,
                    None => Some(self.view(&options.terrain)),
                }
            }
            KeyCode::F6 => {
                let paths = self.paths();
                let next = paths
                    .iter()
                    .position(|&p| p == self.settings.path)
                    .map_or(0, |i| (i + 1) % paths.len());
                self.settings.path = paths[next];
                println!("render path: {:?}", self.settings.path);
            }
            KeyCode::F5 => {
                self.settings.lod_mode = match self.settings.lod_mode {
                    DistanceMode::Smooth => DistanceMode::Debug,
                    DistanceMode::Debug => DistanceMode::Smooth,
                }
            }
            KeyCode::Minus | KeyCode::Equal => {
                let scale = if code == KeyCode::Equal { 1.25 } else { 0.8 };
                self.settings.lod.min_dist *= scale;
                self.settings.lod.max_dist *= scale;
                println!(
                    "LOD distances {:.0}..{:.0}",
                    self.settings.lod.min_dist, self.settings.lod.max_dist
                );
            }
            KeyCode::F12 => {
                self.screenshots += 1;
                let path = PathBuf::from(format!("vkterrain-screenshot-{}.png", self.screenshots));
                self.screenshot(&path, options)?;
                println!("wrote {}", path.display());
            }
            _ => {}
        }
        Ok(())
    }

    /// The paths this device can draw, in the order F6 cycles through them.
    fn paths(&self) -> Vec<RenderPath> {
        let mut paths = vec![RenderPath::Geomip, RenderPath::Brute];
        if self.gpu.device.caps.tessellation_shader {
            paths.insert(0, RenderPath::Tess);
        }
        paths
    }

    fn view(&self, terrain: &Terrain) -> FrameView {
        let extent = self.swapchain.as_ref().map_or(
            vk::Extent2D {
                width: 1,
                height: 1,
            },
            |s| s.extent,
        );
        FrameView::new(
            terrain,
            &self.controller.camera(),
            extent.width,
            extent.height,
        )
    }

    /// One step of `--resize-storm`: a new size (from 1x1 up to about twice
    /// the starting size, by a fixed pseudo-random sequence) or, every 25th
    /// step, a minimise that the next step undoes; after `count` steps, the
    /// starting size again.
    fn storm(&mut self, count: u64, options: &DemoOptions) {
        let step = self.storm_step;
        if step > count {
            return;
        }
        self.storm_step += 1;
        self.rebuild = true;
        if step == count {
            self.window.set_minimized(false);
            let _ = self
                .window
                .request_inner_size(PhysicalSize::new(options.width, options.height));
            return;
        }
        if step % 25 == 24 {
            self.window.set_minimized(true);
            return;
        }
        if step % 25 == 0 && step > 0 {
            self.window.set_minimized(false);
        }
        let mut x = step.wrapping_add(1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        x ^= x >> 31;
        let w = 1 + (x % u64::from(2 * options.width)) as u32;
        let h = 1 + ((x >> 32) % u64::from(2 * options.height)) as u32;
        let _ = self.window.request_inner_size(PhysicalSize::new(w, h));
    }

    fn redraw(&mut self, event_loop: &ActiveEventLoop, options: &DemoOptions) -> Result<()> {
        let now = Instant::now();
        let dt = (now - self.last_tick).as_secs_f64().min(0.25);
        self.last_tick = now;
        let k = &self.keys;
        let axis = |a: bool, b: bool| f64::from(u8::from(a)) - f64::from(u8::from(b));
        let movement = Movement {
            forward: axis(k.forward, k.back),
            right: axis(k.right, k.left),
            up: axis(k.up, k.down),
            fast: k.fast,
        };
        self.controller.update(dt, movement, options.terrain.info());

        if let Some(resize_at) = options.resize_at {
            let size = match self.frame {
                f if f == resize_at => Some((options.width * 2 / 3, options.height * 2 / 3)),
                f if f == resize_at + 2 => Some((16, 12)),
                f if f == resize_at + 4 => Some((options.width, options.height)),
                _ => None,
            };
            if let Some((w, h)) = size {
                let _ = self.window.request_inner_size(PhysicalSize::new(w, h));
                self.rebuild = true;
            }
        }
        if let Some(count) = options.resize_storm {
            self.storm(count, options);
        }
        if self.rebuild {
            self.rebuild_swapchain(options)?;
        }
        if self.swapchain.is_none() {
            // Minimised: nothing to draw into until the window comes back.
            return Ok(());
        }
        let last_scripted = options.frames.is_some_and(|n| self.frame + 1 >= n);
        let drawn = self.draw(options, last_scripted && options.screenshot.is_some())?;
        if !drawn {
            return Ok(());
        }
        self.frame += 1;
        self.update_title(options);
        if last_scripted {
            if let (Some(path), Some(buffer)) = (&options.screenshot, &self.screenshot_buffer) {
                self.gpu.device.wait_idle()?;
                let swapchain = self.swapchain.as_ref().expect("drawn into a swapchain");
                save_swapchain_copy(buffer, swapchain, path)?;
            }
            event_loop.exit();
        }
        Ok(())
    }

    /// Renders one frame; false when the swapchain had to be rebuilt first.
    fn draw(&mut self, options: &DemoOptions, capture: bool) -> Result<bool> {
        let slot = (self.frame % FRAMES_IN_FLIGHT as u64) as usize;
        let device = &self.gpu.device;
        let renderer = self
            .renderer
            .as_mut()
            .expect("renderer lives while running");
        let sync = &mut self.frames[slot];
        // This slot's uniforms, queries and command buffer were last used two
        // frames ago; wait for that frame before touching them.
        device.wait_fence(sync.fence)?;
        if sync.submitted {
            self.last = renderer.measurements(device, slot)?;
        }
        let swapchain = self.swapchain.as_ref().expect("checked by the caller");
        let (index, suboptimal) = match swapchain.acquire(sync.image_available)? {
            Acquired::Image { index, suboptimal } => (index, suboptimal),
            Acquired::OutOfDate => {
                self.rebuild = true;
                return Ok(false);
            }
        };
        let extent = swapchain.extent;
        let mut view = FrameView::new(
            &options.terrain,
            &self.controller.camera(),
            extent.width,
            extent.height,
        );
        if let Some(frozen) = &self.frozen {
            view = view.with_frustum_of(frozen);
        }
        renderer.prepare(slot, &options.terrain, &view, &self.settings)?;
        // Every path draws what the frustum test keeps, or all with culling off.
        self.patches_drawn = if self.settings.cull {
            view.patches_in_frustum(&options.terrain)
        } else {
            options.terrain.grid().patch_count()
        };

        if capture && swapchain.readable && self.screenshot_buffer.is_none() {
            self.screenshot_buffer = Some(device.create_buffer(
                BufferDesc {
                    size: u64::from(extent.width) * u64::from(extent.height) * 4,
                    usage: vk::BufferUsageFlags::TRANSFER_DST,
                    location: gpu_allocator::MemoryLocation::GpuToCpu,
                },
                "demo.screenshot",
            )?);
        }
        let capture_into = if capture {
            self.screenshot_buffer.as_ref()
        } else {
            None
        };
        if capture && capture_into.is_none() {
            bail!("this swapchain's images cannot be read back for a screenshot");
        }

        let views = swapchain.views(index);
        let rec = device.begin_commands(sync.cmd)?;
        use vk::{AccessFlags2 as A, ImageLayout as L, PipelineStageFlags2 as S};
        transition_images(
            rec.device,
            rec.cmd,
            &[
                Transition {
                    image: views.color_image,
                    aspect: vk::ImageAspectFlags::COLOR,
                    // Ordered after the acquire semaphore's wait stage.
                    from: (L::UNDEFINED, S::COLOR_ATTACHMENT_OUTPUT, A::NONE),
                    to: (
                        L::COLOR_ATTACHMENT_OPTIMAL,
                        S::COLOR_ATTACHMENT_OUTPUT,
                        A::COLOR_ATTACHMENT_WRITE,
                    ),
                },
                Transition {
                    image: views.depth_image,
                    aspect: vk::ImageAspectFlags::DEPTH,
                    // The depth image is shared by the frames in flight: the
                    // previous frame's depth writes must finish first.
                    from: (
                        L::UNDEFINED,
                        S::EARLY_FRAGMENT_TESTS | S::LATE_FRAGMENT_TESTS,
                        A::DEPTH_STENCIL_ATTACHMENT_WRITE,
                    ),
                    to: (
                        L::DEPTH_ATTACHMENT_OPTIMAL,
                        S::EARLY_FRAGMENT_TESTS | S::LATE_FRAGMENT_TESTS,
                        A::DEPTH_STENCIL_ATTACHMENT_READ | A::DEPTH_STENCIL_ATTACHMENT_WRITE,
                    ),
                },
            ],
        );
        renderer.record(&rec, slot, &views, &self.settings)?;
        let to_present = |from| Transition {
            image: views.color_image,
            aspect: vk::ImageAspectFlags::COLOR,
            from,
            // Presentation waits on the semaphore, which covers all commands.
            to: (L::PRESENT_SRC_KHR, S::NONE, A::NONE),
        };
        match capture_into {
            Some(buffer) => {
                transition_images(
                    rec.device,
                    rec.cmd,
                    &[Transition::color_output_to_copy(views.color_image)],
                );
                rec.copy_color_to_buffer(views.color_image, extent, buffer.raw);
                transition_images(
                    rec.device,
                    rec.cmd,
                    &[to_present((L::TRANSFER_SRC_OPTIMAL, S::COPY, A::NONE))],
                );
            }
            None => transition_images(
                rec.device,
                rec.cmd,
                &[to_present((
                    L::COLOR_ATTACHMENT_OPTIMAL,
                    S::COLOR_ATTACHMENT_OUTPUT,
                    A::COLOR_ATTACHMENT_WRITE,
                ))],
            ),
        }
        let cmd = rec.finish()?;
        device.reset_fence(sync.fence)?;
        device.submit_frame(
            cmd,
            sync.image_available,
            swapchain.render_finished(index),
            sync.fence,
        )?;
        sync.submitted = true;
        if swapchain.present(device, index)? || suboptimal {
            self.rebuild = true;
        }
        Ok(true)
    }

    fn update_title(&mut self, options: &DemoOptions) {
        let (since, frames) = self.fps_window;
        let elapsed = since.elapsed().as_secs_f64();
        if elapsed >= 0.5 {
            self.fps = (self.frame - frames) as f64 / elapsed;
            self.fps_window = (Instant::now(), self.frame);
        }
        let gpu = self
            .last
            .gpu_ms
            .map_or("n/a".into(), |ms| format!("{ms:.1} ms"));
        let triangles = self
            .last
            .statistics
            .map_or("n/a".into(), |s| s.clipping_primitives.to_string());
        let mut title = format!(
            "vkterrain | {:?} | {:.1} fps | GPU {gpu} | {triangles} triangles | {}/{} patches",
            self.settings.path,
            self.fps,
            self.patches_drawn,
            options.terrain.grid().patch_count()
        );
        if self.controller.mode == Mode::Walk {
            title.push_str(" | walking");
        }
        if self.frozen.is_some() {
            title.push_str(" | culling frozen");
        }
        self.window.set_title(&title);
    }

    /// F12: renders nothing new; copies the image last presented is not
    /// possible, so the next frame is captured.
    fn screenshot(&mut self, path: &std::path::Path, options: &DemoOptions) -> Result<()> {
        if self.swapchain.is_none() {
            bail!("no window contents to capture while minimised");
        }
        if !self.draw(options, true)? {
            return Ok(());
        }
        self.frame += 1;
        self.gpu.device.wait_idle()?;
        let (Some(buffer), Some(swapchain)) = (&self.screenshot_buffer, &self.swapchain) else {
            bail!("this swapchain's images cannot be read back");
        };
        save_swapchain_copy(buffer, swapchain, path)?;
        // The buffer matches one size only; the next capture makes its own.
        let buffer = self.screenshot_buffer.take().expect("checked above");
        self.gpu.device.destroy_buffer(buffer);
        Ok(())
    }

    /// Waits for the GPU, then destroys everything in reverse creation
    /// order. The surface goes before the instance (which `gpu` owns).
    fn shutdown(mut self) -> Result<DemoSummary> {
        let idle = self.gpu.device.wait_idle();
        let device = &self.gpu.device;
        for sync in self.frames.drain(..) {
            device.destroy_fence(sync.fence);
            device.destroy_semaphore(sync.image_available);
        }
        if self.pool != vk::CommandPool::null() {
            device.destroy_command_pool(self.pool);
        }
        if let Some(buffer) = self.screenshot_buffer.take() {
            device.destroy_buffer(buffer);
        }
        if let Some(renderer) = self.renderer.take() {
            renderer.destroy(device);
        }
        if let Some(swapchain) = self.swapchain.take() {
            swapchain.destroy(device);
        }
        if let Some(surface) = self.surface.take() {
            surface.destroy();
        }
        idle?;
        let log = self.gpu.instance.validation_log();
        Ok(DemoSummary {
            frames: self.frame,
            seconds: self.started.elapsed().as_secs_f64(),
            validation_messages: log.count(),
            first_messages: log.messages(),
            last: self.last,
            device: device.caps.device_name.clone(),
            swapchains_built: self.swapchains_built,
            sizes: self.sizes,
        })
    }
}

/// Flying speed: crossing the terrain takes about 40 seconds.
fn speed_for(terrain: &Terrain) -> f64 {
    let info = terrain.info();
    info.world_width().max(info.world_depth()) / 40.0
}

/// Writes a copied swapchain image as an RGBA PNG (swizzling BGRA formats).
fn save_swapchain_copy(
    buffer: &Buffer,
    swapchain: &Swapchain,
    path: &std::path::Path,
) -> Result<()> {
    let bytes = buffer
        .mapped()
        .ok_or_else(|| anyhow!("screenshot memory is not host-mapped"))?;
    let extent = swapchain.extent;
    let mut rgba = bytes[..(extent.width * extent.height * 4) as usize].to_vec();
    if matches!(
        swapchain.format.format,
        vk::Format::B8G8R8A8_SRGB | vk::Format::B8G8R8A8_UNORM
    ) {
        for px in rgba.chunks_exact_mut(4) {
            px.swap(0, 2);
        }
    }
    let image = image::RgbaImage::from_raw(extent.width, extent.height, rgba)
        .ok_or_else(|| anyhow!("screenshot size mismatch"))?;
    crate::output::save_png(&image, path)
}
