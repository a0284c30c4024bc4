//! The window demo: winit, a swapchain, fly and walk cameras, debug toggles,
//! and scripted runs for tests. It draws with the same renderer as the
//! headless path; only the target differs.

pub mod camera;

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};
use ash::vk;
use raw_window_handle::HasDisplayHandle;
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{DeviceEvent, DeviceId, ElementState, KeyEvent, MouseButton, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

use crate::gpu::commands::CommandSlots;
use crate::gpu::memory::{Buffer, BufferDesc};
use crate::gpu::owned::Semaphore;
use crate::gpu::swapchain::{surface_extensions, Acquired, Surface, Swapchain};
use crate::gpu::{Gpu, GpuOptions, ValidationReport};
use crate::lod::view::Tau;
use crate::lod::PeerPolicy;
use crate::render::{
    ErrorMeasure, FrameMeasurements, FrameView, LodMetric, RenderPath, RenderSettings,
    RendererOptions, Shading, TerrainRenderer,
};
use crate::terrain::camera::Camera;
use crate::terrain::{DistanceMode, Terrain};
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
  F7  occlusion culling on / off F8  show occlusion-culled patches
  F9  LOD policy (error, distance, sphere, edge length, CDLOD)
  F10 error measure (sight, view, bound)
  - / =   LOD distances down / up      [ / ]   pixel error down / up
  F12 screenshot                 Esc     quit";

/// What the demo runs.
#[derive(Clone, Debug)]
pub struct DemoOptions {
    pub terrain: Terrain,
    /// How a tiled terrain streams (see `render::streaming`); frames never
    /// wait for it.
    pub stream: Option<crate::render::StreamConfig>,
    /// The scene's material layers and lightmap.
    pub appearance: crate::appearance::Appearance,
    pub camera: Camera,
    pub settings: RenderSettings,
    pub width: u32,
    pub height: u32,
    pub present_mode: vk::PresentModeKHR,
    /// Samples per pixel; None: `render::DEFAULT_SAMPLES` where the device
    /// can draw them.
    pub samples: Option<u32>,
    /// Validation, disabled features, memory budget and injected faults
    /// (the window adds its surface's extensions).
    pub gpu: GpuOptions,
    /// Eye height above the ground when walking.
    pub walk_height: f64,
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
    /// Counted after the device was destroyed.
    pub validation: ValidationReport,
    pub last: FrameMeasurements,
    pub device: String,
    /// Swapchains built, the first one included.
    pub swapchains_built: u32,
    /// Distinct swapchain sizes seen, in order.
    pub sizes: Vec<(u32, u32)>,
    /// Times the renderer was planned again for a window larger than any
    /// before, under a memory budget.
    pub replans: u32,
    /// GPU memory allocated at the end, before anything was freed.
    pub memory_in_use: u64,
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
        // Validation was counted when the device went; name it beside the
        // error.
        return Err(match &app.summary {
            Some(summary) => with_validation(e, &summary.validation),
            None => e,
        });
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

/// The window's GPU objects. They free themselves; fields drop in
/// declaration order, so the frames' work is waited for (by the renderer
/// and swapchain, which wait for idle) before the surface goes, and the
/// device goes last.
struct Graphics {
    /// One command buffer and fence per frame in flight.
    commands: CommandSlots,
    /// Per frame in flight: signalled when its swapchain image is ready.
    image_available: Vec<Semaphore>,
    /// Where a screenshot is copied (one swapchain size).
    screenshot_buffer: Option<Buffer>,
    /// None only while it is built again (`Running::replan`).
    renderer: Option<TerrainRenderer>,
    /// The largest window, in pixels, the renderer's layout was planned
    /// beside. Under a memory budget a streamed terrain's pool takes what
    /// the targets leave, so larger targets are made only after the
    /// renderer is planned again.
    planned_pixels: u64,
    swapchain: Option<Swapchain>,
    surface: Arc<Surface>,
    gpu: Gpu,
}

/// Keys held down.
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

/// The camera and what moves it.
struct Input {
    controller: CameraController,
    keys: Keys,
    /// The frustum culling keeps while frozen (F4).
    frozen: Option<FrameView>,
    last_tick: Instant,
}

/// What the title bar and the summary report.
struct Stats {
    frame: u64,
    started: Instant,
    fps_window: (Instant, u64),
    fps: f64,
    last: FrameMeasurements,
    /// CPU milliseconds of the last frame's preparing and recording, and
    /// of its level choice alone.
    cpu_ms: f64,
    lod_ms: Option<f64>,
    patches_drawn: usize,
    screenshots: u32,
    swapchains_built: u32,
    sizes: Vec<(u32, u32)>,
    /// Times the renderer was planned again for a larger window.
    replans: u32,
    /// Resize-storm requests made so far.
    storm_step: u64,
}

struct Running {
    graphics: Graphics,
    input: Input,
    stats: Stats,
    settings: RenderSettings,
    /// The error LOD's tolerance, kept while another policy is shown.
    tau: f32,
    rebuild: bool,
    /// Also held by the surface made from it.
    window: Arc<Window>,
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
                running.input.keys.looking = state == ElementState::Pressed;
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
            if running.input.keys.looking {
                running.input.controller.look(delta.0, delta.1);
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
            self.summary = Some(running.shutdown());
        }
    }
}

/// What `Graphics::build` makes on the device, in the order it is made:
/// the surface, the swapchain, the renderer, the frames' semaphores and
/// command slots.
type GraphicsParts = (
    Arc<Surface>,
    Swapchain,
    TerrainRenderer,
    Vec<Semaphore>,
    CommandSlots,
);

impl Graphics {
    /// The device, the window's surface, a first swapchain (its format is
    /// the pipelines'), the renderer and the frames in flight.
    fn new(window: &Arc<Window>, options: &DemoOptions) -> Result<Graphics> {
        let display = window
            .display_handle()
            .context("reading the display handle")?
            .as_raw();
        let gpu = Gpu::open(&GpuOptions {
            instance_extensions: surface_extensions(display)?.to_vec(),
            device_extensions: vec![ash::khr::swapchain::NAME],
            ..options.gpu.clone()
        })
        .context("starting Vulkan")?;
        match Self::build(&gpu, window, options) {
            Ok((surface, swapchain, renderer, image_available, commands)) => Ok(Graphics {
                commands,
                image_available,
                screenshot_buffer: None,
                renderer: Some(renderer),
                planned_pixels: pixels(swapchain.extent),
                swapchain: Some(swapchain),
                surface,
                gpu,
            }),
            // What was built is gone by now; validation is counted after the
            // device goes, so a leak on this path is reported too.
            Err(e) => Err(with_validation(e, &gpu.shutdown())),
        }
    }

    /// Everything but the device, in the order it is made.
    fn build(gpu: &Gpu, window: &Arc<Window>, options: &DemoOptions) -> Result<GraphicsParts> {
        let size = window.inner_size();
        let device = &gpu.device;
        let surface = Arc::new(Surface::new(device, Arc::clone(window))?);
        let mut notes = Vec::new();
        let samples = crate::render::sample_count(options.samples, &device.caps, &mut notes)?;
        for note in notes {
            log::warn!("{note}");
        }
        let swapchain = Swapchain::new(
            device,
            &surface,
            vk::Extent2D {
                width: size.width.max(1),
                height: size.height.max(1),
            },
            options.present_mode,
            samples,
            None,
        )
        .context("building the swapchain")?;
        let renderer = Self::build_renderer(gpu, options, swapchain.format.format, samples)?;
        let image_available = (0..FRAMES_IN_FLIGHT)
            .map(|i| device.create_semaphore(&format!("demo.image_available[{i}]")))
            .collect::<crate::gpu::Result<Vec<_>>>()?;
        let commands = device.create_command_slots(FRAMES_IN_FLIGHT as u32, "demo.commands")?;
        Ok((surface, swapchain, renderer, image_available, commands))
    }

    /// The renderer, laid out within what the budget leaves beside the
    /// memory already in use (the swapchain's targets).
    fn build_renderer(
        gpu: &Gpu,
        options: &DemoOptions,
        format: vk::Format,
        samples: u32,
    ) -> Result<TerrainRenderer> {
        let caps = &gpu.device.caps;
        TerrainRenderer::with_appearance(
            gpu,
            &options.terrain,
            &options.appearance,
            format,
            FRAMES_IN_FLIGHT as u32,
            &RendererOptions {
                paths: paths(caps),
                // Line pipelines are cheap to have ready for F2.
                wireframe: caps.fill_mode_non_solid,
                samples,
                stream: options.stream.clone(),
            },
        )
        .context("preparing the terrain for the GPU")
    }

    fn renderer(&self) -> &TerrainRenderer {
        self.renderer.as_ref().expect("built but while replanning")
    }

    /// Drops every object in field order, then the device, and reports
    /// validation counted after its destruction.
    fn shutdown(self) -> ValidationReport {
        let Graphics {
            commands,
            image_available,
            screenshot_buffer,
            renderer,
            planned_pixels: _,
            swapchain,
            surface,
            gpu,
        } = self;
        // A tuple drops front to back: the field order, before the device.
        drop((
            commands,
            image_available,
            screenshot_buffer,
            renderer,
            swapchain,
            surface,
        ));
        gpu.shutdown()
    }
}

/// The LOD policy after `metric` in F9's cycle: the error LOD at `tau`,
/// distance, then each peer's policy.
fn next_policy(metric: LodMetric, tau: f32) -> LodMetric {
    match metric {
        LodMetric::Error(_) => LodMetric::Distance,
        LodMetric::Distance => LodMetric::Peer(PeerPolicy::ALL[0]),
        LodMetric::Peer(p) => match PeerPolicy::ALL.iter().position(|&q| q == p) {
            Some(i) if i + 1 < PeerPolicy::ALL.len() => LodMetric::Peer(PeerPolicy::ALL[i + 1]),
            _ => LodMetric::Error(tau),
        },
    }
}

/// The LOD policy as the title shows it.
fn policy_name(settings: &RenderSettings) -> String {
    match settings.lod_metric {
        LodMetric::Error(tau) => {
            let measure = match settings.error_measure {
                ErrorMeasure::Sight => "sight",
                ErrorMeasure::View => "view measure",
                ErrorMeasure::Bound => "bound",
            };
            format!("error {tau:.2} px ({measure})")
        }
        LodMetric::Distance => "distance".into(),
        LodMetric::Peer(p) => p.name().into(),
    }
}

/// The paths a device can draw, in the order F6 cycles through them.
fn paths(caps: &crate::gpu::Capabilities) -> Vec<RenderPath> {
    let mut paths = vec![RenderPath::Geomip, RenderPath::Brute];
    if caps.tessellation_shader {
        paths.insert(0, RenderPath::Tess);
    }
    paths
}

impl Running {
    fn start(event_loop: &ActiveEventLoop, options: &DemoOptions) -> Result<Running> {
        let window = Arc::new(
            event_loop
                .create_window(
                    Window::default_attributes()
                        .with_title("vkterrain")
                        .with_inner_size(PhysicalSize::new(options.width, options.height)),
                )
                .context("creating the window")?,
        );
        let graphics = Graphics::new(&window, options)?;
        let mut notes = Vec::new();
        let settings =
            crate::render::with_fallback(options.settings, &graphics.gpu.device.caps, &mut notes);
        for note in notes {
            log::warn!("{note}");
        }
        let mut running = Running {
            input: Input {
                controller: CameraController {
                    eye_height: options.walk_height,
                    ..CameraController::new(&options.camera, speed_for(&options.terrain))
                },
                keys: Keys::default(),
                frozen: None,
                last_tick: Instant::now(),
            },
            stats: Stats {
                frame: 0,
                started: Instant::now(),
                fps_window: (Instant::now(), 0),
                fps: 0.0,
                last: FrameMeasurements::default(),
                cpu_ms: 0.0,
                lod_ms: None,
                patches_drawn: 0,
                screenshots: 0,
                swapchains_built: 0,
                sizes: Vec::new(),
                replans: 0,
                storm_step: 0,
            },
            tau: match settings.lod_metric {
                LodMetric::Error(tau) => tau,
                _ => Tau::DEFAULT.px(),
            },
            settings,
            rebuild: false,
            graphics,
            window,
        };
        if let Some(swapchain) = &running.graphics.swapchain {
            let size = (swapchain.extent.width, swapchain.extent.height);
            running.stats.swapchains_built = 1;
            running.stats.sizes.push(size);
        }
        Ok(running)
    }

    /// Rebuilds the swapchain for the window's current size; a zero-sized
    /// (minimised) window leaves none, and drawing pauses. A window larger
    /// than any the renderer was planned beside, under a memory budget,
    /// plans the renderer again (`replan`).
    fn rebuild_swapchain(&mut self, options: &DemoOptions) -> Result<()> {
        let size = self.window.inner_size();
        let extent = vk::Extent2D {
            width: size.width,
            height: size.height,
        };
        let graphics = &mut self.graphics;
        let old = graphics.swapchain.take();
        if size.width == 0 || size.height == 0 {
            // Dropping the old swapchain waits for its frames.
            drop(old);
            return Ok(());
        }
        let replan = needs_replan(graphics, extent);
        let samples = graphics.renderer().samples();
        let old = if replan {
            // The old targets and the renderer go before the new targets
            // are made, so the budget sees neither.
            drop(old);
            graphics.gpu.device.wait_idle()?;
            graphics.renderer = None;
            None
        } else {
            old
        };
        let swapchain = Swapchain::new(
            &graphics.gpu.device,
            &graphics.surface,
            extent,
            options.present_mode,
            samples,
            old,
        )
        .context("building the swapchain")?;
        if replan {
            self.replan(options, &swapchain, samples)?;
        }
        let graphics = &mut self.graphics;
        if graphics.renderer().color_format() != swapchain.format.format {
            bail!(
                "the swapchain changed format from {:?} to {:?}",
                graphics.renderer().color_format(),
                swapchain.format.format
            );
        }
        self.stats.swapchains_built += 1;
        let size = (swapchain.extent.width, swapchain.extent.height);
        if self.stats.sizes.last() != Some(&size) {
            self.stats.sizes.push(size);
        }
        graphics.swapchain = Some(swapchain);
        self.rebuild = false;
        Ok(())
    }

    /// Builds the renderer again beside `swapchain`'s targets, by the rule
    /// it was first built by: its pool takes what the budget leaves, and a
    /// budget below its smallest layout is refused, naming the smallest
    /// that works. The frames' command slots start afresh, since the old
    /// renderer's queries are gone.
    fn replan(&mut self, options: &DemoOptions, swapchain: &Swapchain, samples: u32) -> Result<()> {
        let graphics = &mut self.graphics;
        let renderer =
            Graphics::build_renderer(&graphics.gpu, options, swapchain.format.format, samples)
                .with_context(|| {
                    format!(
                        "planning the renderer again for a {}x{} window",
                        swapchain.extent.width, swapchain.extent.height
                    )
                })?;
        graphics.commands = graphics
            .gpu
            .device
            .create_command_slots(FRAMES_IN_FLIGHT as u32, "demo.commands")?;
        graphics.renderer = Some(renderer);
        graphics.planned_pixels = pixels(swapchain.extent);
        self.stats.replans += 1;
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
        let keys = &mut self.input.keys;
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
            KeyCode::Digit2 => self
                .input
                .controller
                .set_mode(Mode::Walk, options.terrain.info()),
            KeyCode::Digit3 => self
                .input
                .controller
                .set_mode(Mode::Fly, options.terrain.info()),
            KeyCode::F1 => log::info!("{HELP}"),
            KeyCode::F2 => {
                if self.graphics.gpu.device.caps.fill_mode_non_solid {
                    self.settings.wireframe = !self.settings.wireframe;
                } else {
                    log::warn!("wireframe is unavailable: the device lacks fillModeNonSolid");
                }
            }
            KeyCode::F3 => {
                self.settings.shading = match self.settings.shading {
                    Shading::LodColors => Shading::Lit,
                    _ => Shading::LodColors,
                }
            }
            KeyCode::F4 => {
                self.input.frozen = match self.input.frozen {
                    Some(_) => None,
                    None => Some(self.view(&options.terrain)),
                }
            }
            KeyCode::F6 => {
                let paths = paths(&self.graphics.gpu.device.caps);
                let next = paths
                    .iter()
                    .position(|&p| p == self.settings.path)
                    .map_or(0, |i| (i + 1) % paths.len());
                self.settings.path = paths[next];
                log::info!("render path: {:?}", self.settings.path);
            }
            KeyCode::F7 => {
                self.settings.occlusion = !self.settings.occlusion;
                if self.settings.occlusion && !self.graphics.renderer().can_cull_occluded() {
                    log::warn!(
                        "occlusion culling is unavailable: the device cannot sample its depth attachments"
                    );
                }
                log::info!(
                    "occlusion culling {}",
                    if self.settings.occlusion { "on" } else { "off" }
                );
            }
            KeyCode::F9 => {
                self.settings.lod_metric = next_policy(self.settings.lod_metric, self.tau);
                log::info!("LOD policy: {}", policy_name(&self.settings));
            }
            KeyCode::F10 => {
                self.settings.error_measure = match self.settings.error_measure {
                    ErrorMeasure::Sight => ErrorMeasure::View,
                    ErrorMeasure::View => ErrorMeasure::Bound,
                    ErrorMeasure::Bound => ErrorMeasure::Sight,
                };
                log::info!("error measure: {:?}", self.settings.error_measure);
            }
            KeyCode::BracketLeft | KeyCode::BracketRight => {
                let scale = if code == KeyCode::BracketRight {
                    1.25
                } else {
                    0.8
                };
                let tau = (self.tau * scale).clamp(Tau::MIN_PX, 64.0);
                self.tau = Tau::new(tau).map_or(self.tau, Tau::px);
                if let LodMetric::Error(_) = self.settings.lod_metric {
                    self.settings.lod_metric = LodMetric::Error(self.tau);
                }
                log::info!("pixel error {:.2} px", self.tau);
            }
            KeyCode::F8 => {
                self.settings.show_culled = !self.settings.show_culled;
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
                log::info!(
                    "LOD distances {:.0}..{:.0}",
                    self.settings.lod.min_dist,
                    self.settings.lod.max_dist
                );
            }
            KeyCode::F12 => {
                self.stats.screenshots += 1;
                let path = PathBuf::from(format!(
                    "vkterrain-screenshot-{}.png",
                    self.stats.screenshots
                ));
                self.screenshot(&path, options)?;
                log::info!("wrote {}", path.display());
            }
            _ => {}
        }
        Ok(())
    }

    fn view(&self, terrain: &Terrain) -> FrameView {
        let extent = self.graphics.swapchain.as_ref().map_or(
            vk::Extent2D {
                width: 1,
                height: 1,
            },
            |s| s.extent,
        );
        FrameView::new(
            terrain,
            &self.input.controller.camera(),
            extent.width,
            extent.height,
        )
    }

    /// One step of `--resize-storm`: a new size (from 1x1 up to about twice
    /// the starting size, by a fixed pseudo-random sequence) or, every 25th
    /// step, a minimise that the next step undoes; after `count` steps, the
    /// starting size again.
    fn storm(&mut self, count: u64, options: &DemoOptions) {
        let step = self.stats.storm_step;
        if step > count {
            return;
        }
        self.stats.storm_step += 1;
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
        let dt = (now - self.input.last_tick).as_secs_f64().min(0.25);
        self.input.last_tick = now;
        let k = &self.input.keys;
        let axis = |a: bool, b: bool| f64::from(u8::from(a)) - f64::from(u8::from(b));
        let movement = Movement {
            forward: axis(k.forward, k.back),
            right: axis(k.right, k.left),
            up: axis(k.up, k.down),
            fast: k.fast,
        };
        self.input
            .controller
            .update(dt, movement, options.terrain.info());

        if let Some(resize_at) = options.resize_at {
            let size = match self.stats.frame {
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
        if self.graphics.swapchain.is_none() {
            // Minimised: nothing to draw into until the window comes back.
            return Ok(());
        }
        let last_scripted = options.frames.is_some_and(|n| self.stats.frame + 1 >= n);
        let drawn = self.draw(options, last_scripted && options.screenshot.is_some())?;
        if !drawn {
            return Ok(());
        }
        self.stats.frame += 1;
        self.update_title(options);
        if last_scripted {
            if let Some(path) = &options.screenshot {
                self.save_screenshot(path)?;
            }
            event_loop.exit();
        }
        Ok(())
    }

    /// Renders one frame; false when the swapchain had to be rebuilt first.
    fn draw(&mut self, options: &DemoOptions, capture: bool) -> Result<bool> {
        let slot = (self.stats.frame % FRAMES_IN_FLIGHT as u64) as usize;
        let graphics = &mut self.graphics;
        let device = &graphics.gpu.device;
        // This slot's uniforms, queries and command buffer were last used
        // two frames ago; wait for that frame before touching them.
        let renderer = graphics
            .renderer
            .as_mut()
            .expect("built again before drawing");
        if graphics.commands.wait(slot)? {
            self.stats.last = renderer.measurements(slot)?;
        }
        let swapchain = graphics.swapchain.as_ref().expect("checked by the caller");
        let (index, suboptimal) = match swapchain.acquire(&graphics.image_available[slot])? {
            Acquired::Image { index, suboptimal } => (index, suboptimal),
            Acquired::OutOfDate => {
                self.rebuild = true;
                return Ok(false);
            }
        };
        let extent = swapchain.extent;
        let mut view = FrameView::new(
            &options.terrain,
            &self.input.controller.camera(),
            extent.width,
            extent.height,
        );
        if let Some(frozen) = &self.input.frozen {
            view = view.with_frustum_of(frozen);
        }
        let start = Instant::now();
        renderer.prepare(slot, &options.terrain, &view, &self.settings)?;
        self.stats.lod_ms = renderer.lod_ms();
        self.stats.patches_drawn = renderer.patches_in_view();

        if capture && !swapchain.readable {
            bail!("this swapchain's images cannot be read back for a screenshot");
        }
        if capture && graphics.screenshot_buffer.is_none() {
            graphics.screenshot_buffer = Some(device.create_buffer(
                BufferDesc {
                    size: u64::from(extent.width) * u64::from(extent.height) * 4,
                    usage: vk::BufferUsageFlags::TRANSFER_DST,
                    location: gpu_allocator::MemoryLocation::GpuToCpu,
                },
                "demo.screenshot",
            )?);
        }
        let capture_into = graphics.screenshot_buffer.as_ref().filter(|_| capture);

        let views = swapchain.views(index);
        let rec = graphics.commands.begin(slot)?;
        swapchain.record_begin(&rec, index);
        renderer.record(&rec, slot, &views)?;
        swapchain.record_present(&rec, index, capture_into);
        self.stats.cpu_ms = start.elapsed().as_secs_f64() * 1e3;
        rec.submit_frame(
            &graphics.image_available[slot],
            swapchain.render_finished(index),
        )?;
        if swapchain.present(index)? || suboptimal {
            self.rebuild = true;
        }
        Ok(true)
    }

    fn update_title(&mut self, options: &DemoOptions) {
        let stats = &mut self.stats;
        let (since, frames) = stats.fps_window;
        let elapsed = since.elapsed().as_secs_f64();
        if elapsed >= 0.5 {
            stats.fps = (stats.frame - frames) as f64 / elapsed;
            stats.fps_window = (Instant::now(), stats.frame);
        }
        let gpu = stats
            .last
            .gpu_ms
            .map_or("n/a".into(), |ms| format!("{ms:.1} ms"));
        let triangles = stats
            .last
            .statistics
            .map_or("n/a".into(), |s| s.clipping_primitives.to_string());
        let lod = stats
            .lod_ms
            .map_or("n/a".into(), |ms| format!("{ms:.2} ms"));
        let mut title = format!(
            "vkterrain | {:?} | {} | {:.1} fps | LOD {lod} | CPU {:.1} ms | GPU {gpu} | {triangles} triangles | {}/{} patches",
            self.settings.path,
            policy_name(&self.settings),
            stats.fps,
            stats.cpu_ms,
            stats.patches_drawn,
            options.terrain.grid().patch_count()
        );
        if self.input.controller.mode == Mode::Walk {
            title.push_str(" | walking");
        }
        if self.input.frozen.is_some() {
            title.push_str(" | culling frozen");
        }
        if let Some(o) = stats.last.occlusion {
            let _ = write!(title, " | {} occluded", o.patches_occluded);
        }
        self.window.set_title(&title);
    }

    /// F12: the image last presented cannot be read back, so the next
    /// frame is drawn and captured.
    fn screenshot(&mut self, path: &std::path::Path, options: &DemoOptions) -> Result<()> {
        if self.graphics.swapchain.is_none() {
            bail!("no window contents to capture while minimised");
        }
        if !self.draw(options, true)? {
            return Ok(());
        }
        self.stats.frame += 1;
        self.save_screenshot(path)?;
        // The buffer matches one size only; the next capture makes its own.
        self.graphics.screenshot_buffer = None;
        Ok(())
    }

    /// Writes the last captured frame, once the GPU has finished it.
    fn save_screenshot(&self, path: &std::path::Path) -> Result<()> {
        let graphics = &self.graphics;
        graphics.gpu.device.wait_idle()?;
        let (Some(buffer), Some(swapchain)) = (&graphics.screenshot_buffer, &graphics.swapchain)
        else {
            bail!("this swapchain's images cannot be read back");
        };
        save_swapchain_copy(buffer, swapchain, path)
    }

    /// Tears the GPU objects down (they free themselves, waiting for the
    /// GPU first) and reports the run, with validation counted after the
    /// device is destroyed.
    fn shutdown(self) -> DemoSummary {
        let Running {
            graphics, stats, ..
        } = self;
        let device = graphics.gpu.device.caps.device_name.clone();
        let memory_in_use = graphics.gpu.device.memory_in_use();
        let validation = graphics.shutdown();
        DemoSummary {
            frames: stats.frame,
            seconds: stats.started.elapsed().as_secs_f64(),
            validation,
            last: stats.last,
            device,
            swapchains_built: stats.swapchains_built,
            sizes: stats.sizes,
            replans: stats.replans,
            memory_in_use,
        }
    }
}

/// `error`, naming beside it what validation reported by the device's
/// destruction, if anything.
pub fn with_validation(error: anyhow::Error, report: &ValidationReport) -> anyhow::Error {
    match report.check() {
        Ok(()) => error,
        Err(validation) => error.context(validation.to_string()),
    }
}

/// An extent's pixels.
fn pixels(extent: vk::Extent2D) -> u64 {
    u64::from(extent.width) * u64::from(extent.height)
}

/// Whether targets of `extent` call for the renderer to be planned again:
/// a streamed terrain's pool under a memory budget was sized beside
/// smaller ones. Smaller targets leave it as it is: the pool stays within
/// the budget, and a window dragged about does not rebuild it each time.
fn needs_replan(graphics: &Graphics, extent: vk::Extent2D) -> bool {
    graphics.gpu.device.memory_budget().is_some()
        && graphics
            .renderer
            .as_ref()
            .is_some_and(|r| r.stream_shape().is_some())
        && pixels(extent) > graphics.planned_pixels
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
