//! What the picture adds around the terrain: multisample anti-aliasing and
//! the sky. Validation is on and any message fails the test.

mod common;

use common::gpu::*;
use common::*;
use glam::{Vec3, Vec4};
use vkterrain::appearance::Appearance;
use vkterrain::render::{RenderSettings, Shading, DEFAULT_SAMPLES};
use vkterrain::scene::Scene;
use vkterrain::terrain::Terrain;

fn default_terrain() -> Terrain {
    Terrain::new(Scene::default_scene().terrain_info().unwrap(), 0.0).unwrap()
}

/// The default view, unlit white on black: every pixel is all terrain
/// (255), all background (0), or partly covered.
fn silhouette(samples: u32) -> image::RgbaImage {
    let scene_def = Scene::default_scene();
    let mut scene = GpuScene::for_golden_samples(
        default_terrain(),
        &Appearance::default(),
        (320, 180),
        samples,
    );
    let settings = RenderSettings {
        lod: scene_def.lod.unwrap(),
        shading: Shading::Flat,
        clear_color: [0.0; 3],
        ..RenderSettings::default()
    };
    let image = scene
        .render(&scene_def.camera.unwrap(), &settings)
        .rgba_image();
    scene.finish();
    image
}

/// Pixels whose grey level is neither background nor terrain.
fn partial(image: &image::RgbaImage) -> Vec<(u32, u32)> {
    image
        .enumerate_pixels()
        .filter(|(_, _, p)| (8..=247).contains(&p[0]))
        .map(|(x, y, _)| (x, y))
        .collect()
}

/// Pixels of a two-level image with a 4-neighbour of the other level.
fn edges(image: &image::RgbaImage) -> Vec<(u32, u32)> {
    let (w, h) = image.dimensions();
    let on = |x: u32, y: u32| image.get_pixel(x, y)[0] > 127;
    image
        .enumerate_pixels()
        .filter(|&(x, y, _)| {
            let v = on(x, y);
            (x > 0 && on(x - 1, y) != v)
                || (x + 1 < w && on(x + 1, y) != v)
                || (y > 0 && on(x, y - 1) != v)
                || (y + 1 < h && on(x, y + 1) != v)
        })
        .map(|(x, y, _)| (x, y))
        .collect()
}

#[test]
fn silhouettes_are_anti_aliased_at_the_default_sample_count() {
    if skip_gpu() {
        return;
    }
    let single = silhouette(1);
    let multi = silhouette(DEFAULT_SAMPLES);
    // One sample per pixel: every pixel is all in or all out.
    assert_eq!(partial(&single), Vec::new(), "1 sample: no partial pixels");
    let outline = edges(&single);
    assert!(
        outline.len() > 500,
        "the view has an outline: {} edge pixels",
        outline.len()
    );
    // With the default samples, the outline's pixels blend terrain and
    // background, and nothing away from the outline does.
    let blended = partial(&multi);
    assert!(
        blended.len() * 3 >= outline.len(),
        "{} blended pixels along an outline of {} pixels",
        blended.len(),
        outline.len()
    );
    let near_outline = |&(x, y): &(u32, u32)| {
        outline
            .iter()
            .any(|&(ex, ey)| ex.abs_diff(x) <= 1 && ey.abs_diff(y) <= 1)
    };
    let stray = blended.iter().filter(|p| !near_outline(p)).count();
    assert!(
        stray * 100 <= blended.len(),
        "{stray} of {} blended pixels are away from the outline",
        blended.len()
    );
    assert_golden(&format!("silhouette-{DEFAULT_SAMPLES}x"), &multi, 12, 0.005);
}

#[test]
fn the_default_scene_at_the_default_sample_count_matches_its_golden_image() {
    if skip_gpu() {
        return;
    }
    let scene_def = Scene::default_scene();
    let mut scene = GpuScene::for_golden_samples(
        default_terrain(),
        &Appearance::default(),
        (320, 180),
        DEFAULT_SAMPLES,
    );
    let settings = RenderSettings {
        lod: scene_def.lod.unwrap(),
        ..RenderSettings::default()
    };
    let frame = scene.render(&scene_def.camera.unwrap(), &settings);
    // Depth still reads back, resolved from each pixel's sample 0: the
    // terrain covers the lower part of the view and not the top row.
    let depth = &frame.readback.depth;
    assert!(depth[..320].iter().all(|&d| d == 0.0), "top row is sky");
    assert!(
        depth[depth.len() - 320..].iter().all(|&d| d > 0.0),
        "bottom row is terrain"
    );
    assert_golden(
        &format!("default-scene-{DEFAULT_SAMPLES}x"),
        &frame.rgba_image(),
        12,
        0.005,
    );
    scene.finish();
}

/// sRGB encoding of a linear value in [0, 1], as the target stores it.
fn srgb(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    255.0
        * if v <= 0.003_130_8 {
            12.92 * v
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        }
}

#[test]
fn the_sky_rises_from_the_horizon_to_a_sun_disc_in_the_light_direction() {
    if skip_gpu() {
        return;
    }
    let scene_def = Scene::default_scene();
    let terrain = default_terrain();
    let sky = RenderSettings::for_scene(&scene_def, terrain.info());
    assert!(sky.sky, "scenes draw the sky");
    let sun = sky.lighting.active()[0];
    let towards_sun = sun.direction.normalize();
    let (w, h) = (240u32, 160u32);
    let eye = [0.0, 1500.0, 0.0];
    let look = towards_sun - Vec3::Y * 0.25;
    let cam = camera(
        eye,
        [
            eye[0] + f64::from(look.x) * 1000.0,
            eye[1] + f64::from(look.y) * 1000.0,
            eye[2] + f64::from(look.z) * 1000.0,
        ],
        55.0,
    );
    let mut scene = GpuScene::with_appearance(terrain, &Appearance::default(), w, h, false);
    let with_sky = scene.render(&cam, &sky);
    let flat = scene.render(&cam, &RenderSettings { sky: false, ..sky });
    scene.finish();

    // The sun's pixel: the light direction's vanishing point.
    let clip = with_sky.view.view_proj * Vec4::from((towards_sun, 0.0));
    let (sx, sy) = (
        ((clip.x / clip.w * 0.5 + 0.5) * w as f32) as u32,
        ((clip.y / clip.w * 0.5 + 0.5) * h as f32) as u32,
    );
    assert!(
        sx < w && sy < h / 2,
        "the sun is in the upper half: {sx},{sy}"
    );
    let image = with_sky.rgba_image();
    let disc = image.get_pixel(sx, sy);
    let radiance = sun.radiance;
    let hue = radiance / radiance.max_element();
    for (c, expected) in hue.to_array().into_iter().enumerate() {
        let got = f32::from(disc[c]);
        assert!(
            (got - srgb(expected)).abs() <= 3.0,
            "sun disc channel {c}: {got}, expected {:.0}",
            srgb(expected)
        );
    }

    // Away from the sun, the sky darkens and deepens upwards from the
    // horizon colour: red falls row by row up the left edge above the
    // terrain.
    let depth = &with_sky.readback.depth;
    let column = 2u32;
    let mut previous: Option<u8> = None;
    let mut rows = 0;
    for y in (0..h).rev() {
        if depth[(y * w + column) as usize] > 0.0 {
            continue;
        }
        let red = image.get_pixel(column, y)[0];
        if let Some(below) = previous {
            assert!(red <= below, "row {y}: red {red} above a row of {below}");
        }
        previous = Some(red);
        rows += 1;
    }
    assert!(rows > h / 2, "{rows} sky rows on the left edge");
    let top = image.get_pixel(column, 0);
    let clear = sky.clear_color.map(srgb);
    assert!(
        f32::from(top[0]) < clear[0] - 10.0,
        "the top is darker in red than the horizon colour: {top:?} vs {clear:?}"
    );

    // The sky fills only what the terrain leaves: terrain pixels are the
    // same with and without it, and without it the background is flat.
    let flat_image = flat.rgba_image();
    let background: [u8; 3] = sky.clear_color.map(|c| srgb(c).round() as u8);
    let mut terrain_pixels = 0;
    for (i, &d) in depth.iter().enumerate() {
        let (x, y) = (i as u32 % w, i as u32 / w);
        let (a, b) = (image.get_pixel(x, y), flat_image.get_pixel(x, y));
        if d > 0.0 {
            terrain_pixels += 1;
            assert_eq!(a, b, "terrain pixel {x},{y} changed under the sky");
        } else {
            for c in 0..3 {
                assert!(
                    b[c].abs_diff(background[c]) <= 1,
                    "flat background at {x},{y}: {b:?}"
                );
            }
        }
    }
    assert!(terrain_pixels > 0, "the view shows terrain");
}

#[test]
fn sample_counts_the_device_cannot_draw_are_refused_by_name() {
    if skip_gpu() {
        return;
    }
    // lavapipe's sample counts are known (1 and 4); the refusal is checked
    // there.
    drop(open_golden_gpu());
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.png");
    let out = out.to_str().unwrap();
    let run = |samples: &str| {
        vkterrain_in(
            dir.path(),
            &[
                "render",
                "--device",
                GOLDEN_DEVICE,
                "--width",
                "32",
                "--height",
                "32",
                "--samples",
                samples,
                "--out",
                out,
            ],
        )
    };
    for (samples, says) in [
        ("3", "expected 1, 2, 4 or 8 samples per pixel"),
        // lavapipe draws 1 or 4.
        ("8", "cannot draw 8 samples per pixel (--samples 1, 4)"),
    ] {
        let output = run(samples);
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success(), "--samples {samples} succeeded");
        assert!(stderr.contains(says), "--samples {samples}: {stderr}");
        assert!(!dir.path().join("x.png").exists(), "nothing is written");
    }
}

#[test]
fn the_default_sample_count_falls_back_where_a_device_lacks_it() {
    use vkterrain::render::sample_count;
    let caps = |counts: Vec<u32>| vkterrain::gpu::Capabilities {
        sample_counts: counts.clone(),
        occlusion_sample_counts: counts,
        ..test_capabilities()
    };
    let mut notes = Vec::new();
    let full = caps(vec![1, 2, 4, 8]);
    assert_eq!(
        sample_count(None, &full, &mut notes).unwrap(),
        DEFAULT_SAMPLES
    );
    assert_eq!(sample_count(Some(8), &full, &mut notes).unwrap(), 8);
    assert!(notes.is_empty(), "{notes:?}");
    let single = caps(vec![1]);
    assert_eq!(sample_count(None, &single, &mut notes).unwrap(), 1);
    assert_eq!(notes.len(), 1, "the fallback is said");
    assert!(
        notes[0].contains("drawing without anti-aliasing"),
        "{notes:?}"
    );
    let refused = sample_count(Some(4), &single, &mut notes).unwrap_err();
    assert!(
        refused
            .to_string()
            .contains("cannot draw 4 samples per pixel (--samples 1)"),
        "{refused}"
    );
}
