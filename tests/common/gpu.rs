//! GPU test harness: validation always on, any message fails the test, and
//! no device is a failure unless VKTERRAIN_SKIP_GPU=1 says to skip.

use std::cell::RefCell;
use std::path::PathBuf;
use std::sync::{Mutex, MutexGuard, PoisonError};

use glam::DVec3;
use vkterrain::appearance::Appearance;
use vkterrain::gpu::{Gpu, GpuOptions};
use vkterrain::render::{
    offscreen, Headless, HeadlessFrame, RenderPath, RenderSettings, RendererOptions, StreamConfig,
    TerrainRenderer,
};
use vkterrain::terrain::camera::Camera;
use vkterrain::terrain::Terrain;

/// True when the environment explicitly asks to skip GPU tests. The test
/// then returns early and says so; without the variable a missing device
/// fails the test.
pub fn skip_gpu() -> bool {
    let skip = std::env::var("VKTERRAIN_SKIP_GPU").as_deref() == Ok("1");
    if skip {
        // Straight to the process's stderr, past the harness's capture, so
        // the skip shows beside the test's "ok".
        use std::io::Write;
        let name = std::thread::current()
            .name()
            .unwrap_or("a GPU test")
            .to_string();
        let _ = writeln!(
            std::io::stderr(),
            "SKIPPED {name}: VKTERRAIN_SKIP_GPU=1 (no GPU check ran)"
        );
    }
    skip
}

/// Taken by a test's thread before it opens its first device, and held
/// until the thread ends, after every device it opened is destroyed: one
/// test binary's GPU tests run one at a time. The validation layer keeps
/// every instance and device in one process-wide map that each call reads
/// and that creating or destroying one writes, without a lock (1.3.239,
/// Debian 12's; KhronosGroup/Vulkan-ValidationLayers#4391). A test opening
/// or closing its device while another test's thread drew has crashed the
/// process inside the layer. gpu_harness.rs checks the lock holds.
static DEVICES: Mutex<()> = Mutex::new(());

thread_local! {
    static HELD: RefCell<Option<MutexGuard<'static, ()>>> = const { RefCell::new(None) };
}

/// Takes `DEVICES` for this thread, unless it has it already (a test may
/// open several devices).
fn hold_devices() {
    HELD.with(|held| {
        held.borrow_mut().get_or_insert_with(|| {
            // A test that panicked while holding the lock still destroyed
            // its devices on the way out.
            DEVICES.lock().unwrap_or_else(PoisonError::into_inner)
        });
    });
}

/// The device golden images were made on, picked by name for every test
/// that compares against one: lavapipe's rasteriser, not whichever device
/// ranks best here.
pub const GOLDEN_DEVICE: &str = "llvmpipe";

/// Opens the device golden images are compared on, saying why a test needs
/// it when it is missing: every other GPU test runs on whatever device
/// VKTERRAIN_DEVICE names.
pub fn open_golden_gpu() -> Gpu {
    hold_devices();
    Gpu::open(&GpuOptions {
        validate: true,
        device: Some(GOLDEN_DEVICE.to_string()),
        ..GpuOptions::default()
    })
    .unwrap_or_else(|e| {
        panic!(
            "this test compares against images rendered by lavapipe ({GOLDEN_DEVICE}), or \
             relies on what lavapipe can and cannot draw, so it needs that device whatever \
             VKTERRAIN_DEVICE says: {e} (scripts/install-deps installs it; \
             VKTERRAIN_SKIP_GPU=1 skips GPU tests)"
        )
    })
}

/// Opens the GPU for a test: validation on, the device named by
/// `device` or VKTERRAIN_DEVICE (otherwise the best one).
pub fn open_gpu(device: Option<&str>) -> Gpu {
    open_gpu_with(GpuOptions {
        device: device.map(str::to_string),
        ..GpuOptions::default()
    })
}

/// Opens the GPU for a test with `options`, validation on.
fn open_gpu_with(options: GpuOptions) -> Gpu {
    hold_devices();
    Gpu::open(&GpuOptions {
        validate: true,
        ..options
    })
    .unwrap_or_else(|e| {
        panic!(
            "GPU tests need a Vulkan device with tessellation and the validation layer: {e} \
             (set VKTERRAIN_SKIP_GPU=1 to skip them)"
        )
    })
}

/// A terrain on the GPU with an offscreen target. Dropping it (or
/// `finish`) tears everything down and fails the test unless memory is all
/// freed and validation reported nothing by the device's destruction.
pub struct GpuScene {
    gpu: Option<Gpu>,
    pub terrain: Terrain,
    renderer: Option<TerrainRenderer>,
    headless: Option<Headless>,
}

impl GpuScene {
    pub fn new(terrain: Terrain, width: u32, height: u32, wireframe: bool) -> Self {
        Self::with_appearance(terrain, &Appearance::default(), width, height, wireframe)
    }

    /// A scene drawn with material layers and a lightmap; `terrain` must
    /// allow for the displacement (`Appearance::y_margin`).
    pub fn with_appearance(
        terrain: Terrain,
        appearance: &Appearance,
        width: u32,
        height: u32,
        wireframe: bool,
    ) -> Self {
        let gpu = open_gpu(None);
        Self::on(gpu, terrain, appearance, (width, height, wireframe, 1))
    }

    /// A plain scene on a device treated as having no timestamp queries:
    /// no GPU times, so occlusion culling's turns follow the share of
    /// patches it hides alone (`CullingTurns`).
    pub fn without_timestamps(terrain: Terrain, width: u32, height: u32) -> Self {
        Self::without(
            vkterrain::gpu::DisabledFeatures {
                timestamps: true,
                ..Default::default()
            },
            terrain,
            (width, height),
        )
    }

    /// A plain scene on a device treated as lacking the `disabled`
    /// features.
    pub fn without(
        disabled: vkterrain::gpu::DisabledFeatures,
        terrain: Terrain,
        (width, height): (u32, u32),
    ) -> Self {
        let gpu = open_gpu_with(GpuOptions {
            disabled,
            ..GpuOptions::default()
        });
        Self::on(
            gpu,
            terrain,
            &Appearance::default(),
            (width, height, false, 1),
        )
    }

    /// A plain scene drawn with `samples` samples per pixel.
    pub fn with_samples(terrain: Terrain, width: u32, height: u32, samples: u32) -> Self {
        let gpu = open_gpu(None);
        let appearance = Appearance::default();
        Self::on(gpu, terrain, &appearance, (width, height, false, samples))
    }

    /// As `with_appearance`, on the device golden images were made on.
    pub fn for_golden(terrain: Terrain, appearance: &Appearance, width: u32, height: u32) -> Self {
        Self::for_golden_samples(terrain, appearance, (width, height), 1)
    }

    /// As `for_golden`, drawn with `samples` samples per pixel.
    pub fn for_golden_samples(
        terrain: Terrain,
        appearance: &Appearance,
        (width, height): (u32, u32),
        samples: u32,
    ) -> Self {
        let gpu = open_golden_gpu();
        Self::on(gpu, terrain, appearance, (width, height, false, samples))
    }

    /// Every path's renderer and a target of (width, height), with line
    /// pipelines when `wireframe`, of `samples` samples per pixel.
    fn on(
        gpu: Gpu,
        terrain: Terrain,
        appearance: &Appearance,
        target: (u32, u32, bool, u32),
    ) -> Self {
        let (width, height, wireframe, samples) = target;
        // Every path the device can draw.
        let paths = match gpu.device.caps.tessellation_shader {
            true => vec![RenderPath::Tess, RenderPath::Geomip, RenderPath::Brute],
            false => vec![RenderPath::Geomip, RenderPath::Brute],
        };
        let options = RendererOptions {
            paths,
            wireframe,
            samples,
            stream: None,
        };
        Self::with_options(gpu, terrain, appearance, &options, (width, height))
    }

    /// A plain scene streamed as `stream` says, drawn single-sampled.
    pub fn streamed(terrain: Terrain, stream: StreamConfig, width: u32, height: u32) -> Self {
        let options = RendererOptions {
            stream: Some(stream),
            ..RendererOptions::single_sample(vec![
                RenderPath::Tess,
                RenderPath::Geomip,
                RenderPath::Brute,
            ])
        };
        let gpu = open_gpu(None);
        Self::with_options(
            gpu,
            terrain,
            &Appearance::default(),
            &options,
            (width, height),
        )
    }

    /// As `streamed`, under a GPU memory budget of `budget` bytes: the
    /// renderer's error where it refuses the budget.
    pub fn streamed_within(
        terrain: Terrain,
        stream: StreamConfig,
        (width, height): (u32, u32),
        budget: u64,
    ) -> Result<Self, vkterrain::render::RenderError> {
        let options = RendererOptions {
            stream: Some(stream),
            ..RendererOptions::single_sample(vec![RenderPath::Tess])
        };
        let gpu = open_gpu(None);
        gpu.device.set_memory_budget(Some(budget));
        let (renderer, headless) = offscreen(
            &gpu,
            &terrain,
            &Appearance::default(),
            &options,
            (width, height),
        )?;
        Ok(GpuScene {
            gpu: Some(gpu),
            terrain,
            renderer: Some(renderer),
            headless: Some(headless),
        })
    }

    fn with_options(
        gpu: Gpu,
        terrain: Terrain,
        appearance: &Appearance,
        options: &RendererOptions,
        (width, height): (u32, u32),
    ) -> Self {
        let (renderer, headless) = offscreen(&gpu, &terrain, appearance, options, (width, height))
            .expect("renderer and offscreen target");
        GpuScene {
            gpu: Some(gpu),
            terrain,
            renderer: Some(renderer),
            headless: Some(headless),
        }
    }

    pub fn render(&mut self, camera: &Camera, settings: &RenderSettings) -> HeadlessFrame {
        let frame = self
            .headless
            .as_mut()
            .unwrap()
            .render(
                self.renderer.as_mut().unwrap(),
                &self.terrain,
                camera,
                settings,
            )
            .expect("render");
        self.assert_clean("rendering");
        frame
    }

    pub fn renderer(&self) -> &TerrainRenderer {
        self.renderer
            .as_ref()
            .expect("the renderer lives until the scene drops")
    }

    /// Whether frames of a streamed terrain first wait until what their
    /// view needs is resident (one-shot renders do; flythroughs don't).
    pub fn wait_for_residency(&mut self, wait: bool) {
        self.headless.as_mut().unwrap().wait_for_residency = wait;
    }

    pub fn gpu(&self) -> &Gpu {
        self.gpu
            .as_ref()
            .expect("the GPU lives until the scene drops")
    }

    pub fn assert_clean(&self, when: &str) {
        assert_eq!(
            self.gpu().validation_messages(),
            0,
            "validation messages while {when}"
        );
    }

    /// Tears down and checks that teardown was clean (see `Drop`).
    pub fn finish(self) {
        drop(self);
    }
}

impl Drop for GpuScene {
    /// Checks that teardown was clean too: no memory left allocated, and
    /// no validation message by the time the device is destroyed (objects
    /// left alive are reported then). Skipped while a test is already
    /// failing.
    fn drop(&mut self) {
        drop(self.headless.take());
        drop(self.renderer.take());
        let Some(gpu) = self.gpu.take() else {
            return;
        };
        if std::thread::panicking() {
            return;
        }
        assert_eq!(
            gpu.device.memory_in_use(),
            0,
            "GPU memory left allocated: {:?}",
            gpu.device.memory_report()
        );
        let report = gpu.shutdown();
        assert_eq!(
            report.count, 0,
            "validation messages by device destruction: {:#?}",
            report.messages
        );
    }
}

pub fn camera(eye: [f64; 3], target: [f64; 3], fov: f32) -> Camera {
    Camera {
        eye: DVec3::from(eye),
        target: DVec3::from(target),
        fov_y_deg: fov,
    }
}

/// World position seen at each pixel centre, from the depth buffer; None
/// where the pixel shows the background (depth 0 with reversed Z).
pub fn world_positions(frame: &HeadlessFrame, camera: &Camera) -> Vec<Option<DVec3>> {
    let view = vkterrain::bench::error::DepthView::of(frame);
    let inverse = view.view_proj.inverse();
    (0..view.depth.len())
        .map(|i| view.position(&inverse, i).map(|p| camera.eye + p))
        .collect()
}

/// Compares against tests/golden/NAME.png: a pixel differs when any
/// channel differs by more than `channel_tolerance`; at most
/// `max_differing_fraction` of pixels may differ. On mismatch writes
/// NAME-actual.png and NAME-difference.png next to the golden. With
/// VKTERRAIN_BLESS=1 the golden is (re)written instead.
pub fn assert_golden(
    name: &str,
    image: &image::RgbaImage,
    channel_tolerance: u8,
    max_differing_fraction: f64,
) {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden");
    let golden_path = dir.join(format!("{name}.png"));
    if std::env::var("VKTERRAIN_BLESS").as_deref() == Ok("1") {
        image.save(&golden_path).expect("write golden");
        eprintln!("blessed {}", golden_path.display());
        return;
    }
    let golden = image::open(&golden_path)
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e} (VKTERRAIN_BLESS=1 writes it)",
                golden_path.display()
            )
        })
        .to_rgba8();
    assert_images_match(
        name,
        image,
        &golden,
        channel_tolerance,
        max_differing_fraction,
    );
}

/// Two images agree when at most `max_differing_fraction` of pixels differ
/// by more than `channel_tolerance` in a channel. On mismatch writes
/// NAME-actual.png and NAME-difference.png to tests/golden/.
pub fn assert_images_match(
    name: &str,
    image: &image::RgbaImage,
    golden: &image::RgbaImage,
    channel_tolerance: u8,
    max_differing_fraction: f64,
) {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden");
    assert_eq!(
        golden.dimensions(),
        image.dimensions(),
        "{name}: sizes differ"
    );
    let mut difference = image::RgbaImage::new(image.width(), image.height());
    let mut differing = 0usize;
    for (x, y, a) in image.enumerate_pixels() {
        let b = golden.get_pixel(x, y);
        let worst = (0..3).map(|c| a[c].abs_diff(b[c])).max().unwrap();
        if worst > channel_tolerance {
            differing += 1;
        }
        let v = worst.saturating_mul(4);
        difference.put_pixel(x, y, image::Rgba([v, v, v, 255]));
    }
    let fraction = differing as f64 / (image.width() * image.height()) as f64;
    if fraction > max_differing_fraction {
        let actual = dir.join(format!("{name}-actual.png"));
        let diff = dir.join(format!("{name}-difference.png"));
        image.save(&actual).unwrap();
        difference.save(&diff).unwrap();
        panic!(
            "{name}: {:.3}% of pixels differ by more than {channel_tolerance} (allowed {:.3}%); wrote {} and {}",
            fraction * 100.0,
            max_differing_fraction * 100.0,
            actual.display(),
            diff.display()
        );
    }
}
