//! What the picture costs: a scene's own view drawn with and without each
//! addition to the terrain's shading (triplanar projection of steep
//! ground, the sky, multisample anti-aliasing), GPU time side by side in
//! one run.

use serde::{Deserialize, Serialize};

use crate::gpu::Gpu;
use crate::render::figures::median;
use crate::render::{offscreen, RenderSettings, RendererOptions, DEFAULT_SAMPLES};
use crate::render::{LoadedScene, Loading};
use crate::scene::Scene;

/// One way of drawing the scene's view, and what it cost.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LookRow {
    pub scene: String,
    pub device: String,
    pub driver: String,
    pub width: u32,
    pub height: u32,
    /// "plain", "+ triplanar", "+ sky", "+ 4x MSAA" or "all".
    pub config: String,
    pub triplanar: bool,
    pub sky: bool,
    pub samples: u32,
    /// Frames timed (after one untimed), in turn with the other looks.
    pub frames: usize,
    /// Median GPU time; null without timestamps.
    pub gpu_ms: Option<f64>,
}

/// The looks measured: none of the additions, each alone, and all.
fn looks(samples: u32) -> Vec<(String, bool, bool, u32)> {
    let msaa = format!("+ {samples}x MSAA");
    vec![
        ("plain".into(), false, false, 1),
        ("+ triplanar".into(), true, false, 1),
        ("+ sky".into(), false, true, 1),
        (msaa, false, false, samples),
        ("all".into(), true, true, samples),
    ]
}

/// Draws `scene` from its camera with the tess path and its own LOD, at
/// `width` x `height`, in every look: once each untimed, then `frames`
/// rounds of one frame of each look in turn, so that drift in the
/// machine's speed falls on every look alike. Multisampling uses
/// `DEFAULT_SAMPLES`, or is left out where the device cannot draw them.
pub fn measure(
    gpu: &Gpu,
    scene: &Scene,
    name: &str,
    (width, height): (u32, u32),
    frames: usize,
) -> anyhow::Result<Vec<LookRow>> {
    let caps = &gpu.device.caps;
    // Loaded once: the looks differ only in what the renderer and its
    // shader variants make of it.
    let LoadedScene {
        terrain,
        appearance: loaded,
        ..
    } = LoadedScene::load(
        scene,
        Loading {
            stream: false,
            appearance: true,
        },
    )?;
    let camera = scene.camera_for(terrain.info());
    let scene_settings = RenderSettings::for_scene(scene, terrain.info());
    let mut looks_built = Vec::new();
    for (config, triplanar, sky, samples) in looks(DEFAULT_SAMPLES) {
        if !caps.supports_samples(samples) {
            continue;
        }
        let mut appearance = loaded.clone();
        if let Some(m) = appearance.material.as_mut() {
            m.triplanar = triplanar;
        }
        let settings = RenderSettings {
            sky,
            ..scene_settings
        };
        let settings = crate::render::with_fallback(settings, caps, &mut Vec::new());
        let options = RendererOptions {
            paths: vec![settings.path],
            wireframe: false,
            samples,
            stream: None,
        };
        let (renderer, headless) =
            offscreen(gpu, &terrain, &appearance, &options, (width, height))?;
        let row = LookRow {
            scene: name.to_string(),
            device: caps.device_name.clone(),
            driver: format!("{} ({})", caps.driver_name, caps.driver_info),
            width,
            height,
            config,
            triplanar,
            sky,
            samples,
            frames,
            gpu_ms: None,
        };
        looks_built.push((row, settings, renderer, headless, Vec::new()));
    }
    for round in 0..=frames {
        for (_, settings, renderer, headless, times) in &mut looks_built {
            let frame = headless.render(renderer, &terrain, &camera, settings)?;
            if round > 0 {
                times.extend(frame.measurements.gpu_ms);
            }
        }
    }
    Ok(looks_built
        .into_iter()
        .map(|(row, .., mut times)| LookRow {
            gpu_ms: median(&mut times),
            ..row
        })
        .collect())
}

/// Each row's GPU time over the same scene and device's plain row, as a
/// percentage more (0 for the plain row); None without times.
pub fn extra_percent(rows: &[LookRow], row: &LookRow) -> Option<f64> {
    let plain = rows
        .iter()
        .find(|r| r.scene == row.scene && r.device == row.device && r.config == "plain")?;
    Some(100.0 * (row.gpu_ms? / plain.gpu_ms? - 1.0))
}
