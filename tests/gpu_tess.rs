//! The tessellation pipeline on a real Vulkan device (lavapipe in CI):
//! golden images, cracks, culling, CPU/GPU agreement, precision far from
//! the origin. Validation is on and any message fails the test.

mod common;

use std::collections::BTreeSet;

use common::gpu::*;
use common::*;
use glam::{DVec2, DVec3, Vec3};
use vkterrain::appearance::Appearance;
use vkterrain::bench::error::enclosed_background;
use vkterrain::bench::error::{measure, DepthView};
use vkterrain::lod::{choose_tess_error, patch_tess_factors};
use vkterrain::render::{ErrorMeasure, LodMetric, RenderPath, RenderSettings, Shading};
use vkterrain::scene::Scene;
use vkterrain::terrain::camera::Camera;
use vkterrain::terrain::{DistanceLod, DistanceMode, Heightmap, Terrain, TerrainInfo};

fn default_terrain(cells_per_patch: u32) -> Terrain {
    let mut scene = Scene::default_scene();
    scene.cells_per_patch = cells_per_patch;
    Terrain::new(scene.terrain_info().unwrap(), 0.0).unwrap()
}

/// A step from 0 to 300 halfway across a 129x97 map: vertical walls between
/// patches at different levels.
fn cliff_terrain() -> Terrain {
    let info = TerrainInfo::new(
        cliff_map(129, 97, 300.0),
        DVec2::new(4.0, 5.0),
        16,
        DVec2::ZERO,
    )
    .unwrap();
    Terrain::new(info, 0.0).unwrap()
}

/// World-space centre, size and top of a terrain.
fn extent(terrain: &Terrain) -> (DVec3, f64, f64) {
    let info = terrain.info();
    let (lo, hi) = info.min_max();
    let o = info.origin();
    let size = info.world_width().max(info.world_depth());
    (
        DVec3::new(o.x, f64::from(lo + hi) / 2.0, o.y),
        size,
        f64::from(hi),
    )
}

/// Straight down, from high enough to see everything; and two oblique views.
fn crack_cameras(terrain: &Terrain) -> Vec<(&'static str, Camera)> {
    let (c, size, top) = extent(terrain);
    vec![
        (
            "top",
            camera([c.x, top + size * 1.2, c.z], [c.x, c.y, c.z], 50.0),
        ),
        (
            "oblique-sw",
            camera(
                [c.x - 0.6 * size, top + 0.35 * size, c.z - 0.7 * size],
                [c.x, c.y, c.z],
                55.0,
            ),
        ),
        (
            "oblique-ne-low",
            camera(
                [c.x + 0.45 * size, top + 0.08 * size, c.z + 0.55 * size],
                [c.x - 0.1 * size, c.y, c.z - 0.1 * size],
                70.0,
            ),
        ),
    ]
}

/// The distance LOD at one factor, 2^`exp`, for every edge and inside at
/// any distance.
fn one_factor(exp: f32) -> DistanceLod {
    DistanceLod {
        min_dist: 0.0,
        max_dist: 0.0,
        min_exp: exp,
        max_exp: exp,
    }
}

fn flat_settings(terrain: &Terrain, mode: DistanceMode) -> RenderSettings {
    let (_, size, _) = extent(terrain);
    RenderSettings {
        lod: DistanceLod {
            min_dist: (0.1 * size) as f32,
            max_dist: (1.5 * size) as f32,
            min_exp: 0.0,
            max_exp: 6.0,
        },
        lod_mode: mode,
        shading: Shading::Flat,
        clear_color: [0.0; 3],
        ..RenderSettings::default()
    }
}

/// Distinct tessellation factors (edges and insides) over the patches the
/// CPU frustum test keeps, from the Rust mirror of the control shader.
fn distinct_factors(
    terrain: &Terrain,
    camera: &Camera,
    settings: &RenderSettings,
    eye_local: Vec3,
) -> BTreeSet<u32> {
    let grid = terrain.grid();
    let frustum = vkterrain::render::FrameView::new(terrain, camera, 384, 256).frustum;
    let mut factors = BTreeSet::new();
    for p in 0..grid.patch_count() {
        let id = grid.patch_id(p);
        let (centre, extents) = terrain.patch_aabb(id);
        if frustum.aabb_outside(centre - eye_local, extents) {
            continue;
        }
        let corners = terrain.patch_corners(id).map(|c| c - eye_local);
        let f = patch_tess_factors(corners, &settings.lod, settings.lod_mode);
        factors.extend(f.edges.iter().chain(&f.inside).map(|v| v.to_bits()));
    }
    factors
}

fn check_cracks(name: &str, terrain: Terrain) {
    if skip_gpu() {
        return;
    }
    let (w, h) = (384, 256);
    let cameras = crack_cameras(&terrain);
    let mut scene = GpuScene::new(terrain, w, h, false);
    for mode in [DistanceMode::Debug, DistanceMode::Smooth] {
        let settings = flat_settings(&scene.terrain, mode);
        for (view, cam) in &cameras {
            let frame = scene.render(cam, &settings);
            let factors = distinct_factors(&scene.terrain, cam, &settings, frame.view.eye_local);
            assert!(
                factors.len() >= 3,
                "{name}/{view}/{mode:?}: only {} distinct factors in use",
                factors.len()
            );
            let rgba = &frame.readback.rgba;
            let terrain_pixels = rgba.chunks_exact(4).filter(|p| p[0] > 128).count();
            assert!(
                terrain_pixels > (w * h / 20) as usize,
                "{name}/{view}: the terrain covers only {terrain_pixels} pixels"
            );
            let holes = enclosed_background(rgba, w as usize, h as usize, |p| p[0] < 128);
            if !holes.is_empty() {
                frame
                    .rgba_image()
                    .save(format!("{name}-{view}-cracks.png"))
                    .unwrap();
            }
            assert!(
                holes.is_empty(),
                "{name}/{view}/{mode:?}: {} background pixels inside the terrain, first at {:?}",
                holes.len(),
                &holes[..holes.len().min(5)]
            );
        }
    }
    scene.finish();
}

#[test]
fn no_cracks_on_the_default_scene() {
    check_cracks("default", default_terrain(32));
}

#[test]
fn no_cracks_on_the_real_dem() {
    check_cracks("dem", dem_terrain(16, DVec2::ZERO));
}

#[test]
fn no_cracks_on_a_cliff() {
    check_cracks("cliff", cliff_terrain());
}

#[test]
fn default_scene_matches_its_golden_image() {
    if skip_gpu() {
        return;
    }
    let scene_def = Scene::default_scene();
    let mut scene = GpuScene::for_golden(default_terrain(32), &Appearance::default(), 320, 180);
    let settings = RenderSettings {
        lod: scene_def
            .lod
            .expect("the default scene names its distances"),
        ..RenderSettings::default()
    };
    let frame = scene.render(&scene_def.camera.unwrap(), &settings);
    assert_golden("default-scene", &frame.rgba_image(), 12, 0.005);
    let lod_colors = scene.render(
        &scene_def.camera.unwrap(),
        &RenderSettings {
            shading: Shading::LodColors,
            ..settings
        },
    );
    assert_golden(
        "default-scene-lod-colors",
        &lod_colors.rgba_image(),
        12,
        0.005,
    );
    scene.finish();
}

#[test]
fn wireframe_draws_edges_only() {
    if skip_gpu() {
        return;
    }
    let terrain = dem_terrain(32, DVec2::ZERO);
    let cams = crack_cameras(&terrain);
    let mut scene = GpuScene::new(terrain, 256, 256, true);
    // Factor 1 (2 with even spacing): a coarse mesh, easy to see through.
    let fill = RenderSettings {
        lod: one_factor(0.0),
        ..flat_settings(&scene.terrain, DistanceMode::Smooth)
    };
    let lines = RenderSettings {
        wireframe: true,
        ..fill
    };
    let solid = scene.render(&cams[0].1, &fill);
    let wire = scene.render(&cams[0].1, &lines);
    let lit = |rgba: &[u8]| rgba.chunks_exact(4).filter(|p| p[0] > 128).count();
    let (solid_px, wire_px) = (lit(&solid.readback.rgba), lit(&wire.readback.rgba));
    assert!(
        wire_px > 0 && wire_px * 2 < solid_px,
        "wireframe {wire_px} vs solid {solid_px} pixels"
    );
    scene.finish();
}

#[test]
fn culling_skips_patches_outside_the_frustum() {
    if skip_gpu() {
        return;
    }
    let terrain = dem_terrain(32, DVec2::ZERO);
    let total = terrain.grid().patch_count();
    let (c, size, top) = extent(&terrain);
    let mut scene = GpuScene::new(terrain, 256, 256, false);
    // Every patch gets factor 8, so each visible patch costs the same;
    // one pass. The CPU's frustum test decides which patches are drawn at
    // all; the control shader repeats it per patch.
    let settings = RenderSettings {
        lod: one_factor(3.0),
        occlusion: false,
        ..RenderSettings::default()
    };

    let away = scene.render(
        &camera(
            [c.x, top + 100.0, c.z],
            [c.x, top + 1000.0, c.z + 10.0],
            60.0,
        ),
        &settings,
    );
    let stats = away
        .measurements
        .statistics
        .expect("lavapipe has pipeline statistics");
    assert_eq!(away.patches_in_frustum, 0);
    assert_eq!(
        stats.tcs_patches, 0,
        "no patch outside the frustum reaches the control shader"
    );
    assert_eq!(stats.tes_invocations, 0);
    assert_eq!(stats.clipping_primitives, 0);

    let all = scene.render(
        &camera([c.x, top + 1.5 * size, c.z], [c.x, c.y, c.z], 60.0),
        &settings,
    );
    assert_eq!(all.patches_in_frustum, total);
    let all_stats = all.measurements.statistics.unwrap();
    assert_eq!(all_stats.tcs_patches, total as u64);
    assert_eq!(all_stats.tes_invocations % total as u64, 0);
    let per_patch = all_stats.tes_invocations / total as u64;
    assert!(
        per_patch >= 81,
        "factor 8 makes at least 9x9 vertices, got {per_patch}"
    );

    // Looking at one corner from close by: some patches in, some out.
    let corner = camera(
        [c.x - 0.45 * size, top + 0.05 * size, c.z - 0.45 * size],
        [c.x - 0.2 * size, c.y, c.z - 0.3 * size],
        40.0,
    );
    let part = scene.render(&corner, &settings);
    let part_stats = part.measurements.statistics.unwrap();
    assert!(
        part.patches_in_frustum > 0 && part.patches_in_frustum < total,
        "{} of {total}",
        part.patches_in_frustum
    );
    assert_eq!(
        part_stats.tes_invocations,
        per_patch * part.patches_in_frustum as u64,
        "TES work only for the CPU's in-frustum patches"
    );
    assert_eq!(
        part_stats.tcs_patches, part.patches_in_frustum as u64,
        "only they reach the control shader"
    );
    let culling_off = scene.render(
        &corner,
        &RenderSettings {
            cull: false,
            ..settings
        },
    );
    let off_stats = culling_off.measurements.statistics.unwrap();
    assert_eq!(off_stats.tcs_patches, total as u64);
    assert_eq!(off_stats.tes_invocations, per_patch * total as u64);
    assert_eq!(
        part.readback.rgba, culling_off.readback.rgba,
        "culling changes no pixel"
    );
    scene.finish();
}

/// How close a render must come to `height_at`: a fraction of the height
/// range, or what the device's precision allows
/// (`surface_height_tolerance`) for a surface that is exactly the
/// reference's.
#[derive(Clone, Copy)]
enum HeightTolerance {
    OfRange(f64),
    Precision,
}

/// The precision of the device `scene` renders on (depth is D32_SFLOAT).
fn raster_precision(scene: &GpuScene) -> RasterPrecision {
    RasterPrecision {
        sub_pixel_bits: scene.gpu().device.caps.sub_pixel_precision_bits,
        depth_significand_bits: 24,
    }
}

/// Top-down view of a small area at maximum tessellation: the depth buffer,
/// turned back into world positions, lies on `height_at`.
fn check_depth_against_height_at(
    name: &str,
    terrain: Terrain,
    view_cells: f64,
    (path, lod_metric): (RenderPath, LodMetric),
    tolerance: HeightTolerance,
) {
    if skip_gpu() {
        return;
    }
    let info = terrain.info().clone();
    let (lo, hi) = info.min_max();
    let range = f64::from(hi - lo);
    let spacing = info.spacing().max_element();
    let centre = info.sample_position(info.rows() / 3, info.cols() / 3);
    let fov = 30.0f32;
    // High enough that `view_cells` cells fill the view.
    let height =
        f64::from(hi) + view_cells * spacing / 2.0 / (f64::from(fov).to_radians() / 2.0).tan();
    let cam = camera(
        [centre.x, height, centre.y],
        [centre.x, f64::from(lo), centre.y],
        fov,
    );
    let settings = RenderSettings {
        lod: one_factor(6.0),
        path,
        lod_metric,
        // A tiny tolerance on the bounds: every patch at full resolution.
        error_measure: ErrorMeasure::Bound,
        ..RenderSettings::default()
    };
    let width = 200u32;
    let mut scene = GpuScene::new(terrain, width, width, false);
    let allowed = match tolerance {
        HeightTolerance::OfRange(fraction) => fraction * range,
        HeightTolerance::Precision => surface_height_tolerance(
            raster_precision(&scene),
            view_cells * spacing / f64::from(width),
            max_slope(&info),
            height - f64::from(lo),
        ),
    };
    let frame = scene.render(&cam, &settings);
    let mut worst = 0.0f64;
    let mut checked = 0;
    for p in world_positions(&frame, &cam).into_iter().flatten() {
        let Some(h) = info.height_at(p.x, p.z) else {
            continue;
        };
        worst = worst.max((p.y - f64::from(h)).abs());
        checked += 1;
    }
    assert!(
        checked > 30_000,
        "{name}: only {checked} pixels on the terrain"
    );
    assert!(
        worst <= allowed,
        "{name}/{path:?}: depth disagrees with height_at by {worst}, over the {allowed} allowed (range {range})"
    );
    eprintln!("{name}/{path:?}: worst |GPU - height_at| = {worst:.5} of {allowed:.5} allowed, over {checked} pixels (range {range})");
    scene.finish();
}

/// The derivation covers what each device was seen to do. On an NVIDIA
/// H100 (subPixelPrecisionBits 8, D32_SFLOAT), brute's DEM render in
/// `brute_surface_is_height_at` lay up to 0.025644 m from `height_at`; the
/// fixed 2e-5 of the 840 m range (0.0168 m) that the test allowed before
/// failed it. A pixel there spans 40 cells of 92.15 m over 200 pixels
/// (18.4 m), and 1/256 of that on the DEM's steepest triangles is a few
/// centimetres: 0.057 m allowed. lavapipe reports the same 8 bits and
/// was seen 0.0043 m off. Two renders of one surface compared pixel for
/// pixel (`pair_height_tolerance`, as `full_resolution_tess_is_the_reference`
/// compares tess with brute) may differ by what both snaps move the hit
/// along each pixel's ray.
#[test]
fn height_tolerance_follows_the_device_limits() {
    let info = dem_info_at(32, DVec2::ZERO);
    let (lo, hi) = info.min_max();
    let spacing = info.spacing().max_element();
    let slope = max_slope(&info);
    assert!(
        (0.1..10.0).contains(&slope),
        "the DEM's steepest rise {slope}"
    );
    let height = f64::from(hi) + 40.0 * spacing / 2.0 / 15f64.to_radians().tan();
    let allowed = |sub_pixel_bits| {
        surface_height_tolerance(
            RasterPrecision {
                sub_pixel_bits,
                depth_significand_bits: 24,
            },
            40.0 * spacing / 200.0,
            slope,
            height - f64::from(lo),
        )
    };
    let (lavapipe, h100) = (allowed(8), allowed(8));
    assert!(h100 >= 0.025644, "H100: {h100} m allowed");
    assert!(
        lavapipe >= 2e-5 * f64::from(hi - lo),
        "lavapipe: {lavapipe} m"
    );
    // Still tight: well under a centimetre per metre of the pixel, and
    // finer snapping allows less.
    assert!(h100 < 0.01 * 40.0 * spacing / 200.0, "{h100} m");
    assert!(allowed(4) > 10.0 * allowed(8) && allowed(12) < allowed(8));
    // Two renders of one surface, at a pixel 3 km off whose ray falls 0.3
    // onto ground at 45 degrees, 256 pixels a radian: with 8 bits each
    // render may move the hit a few centimetres; face-on, nothing but the
    // depth's rounding; grazing, without limit.
    let precision = RasterPrecision {
        sub_pixel_bits: 8,
        depth_significand_bits: 24,
    };
    let eye = DVec3::new(0.0, 900.0, 0.0);
    let ray = DVec3::new(0.954, -0.3, 0.0).normalize();
    let point = eye + 3000.0 * ray;
    let pair = |normal: DVec3| pair_height_tolerance(precision, (eye, 256.0), point, normal);
    let slanted = pair(DVec3::new(-1.0, 1.0, 0.0).normalize());
    assert!((0.005..0.05).contains(&slanted), "{slanted} m");
    assert!(pair(-ray) < 1e-3 && pair(-ray) > 0.0);
    let grazing = pair(DVec3::new(ray.y, -ray.x, 0.0).normalize());
    assert!(grazing > 1e3, "{grazing} m");
    assert!(
        pair_height_tolerance(
            RasterPrecision {
                sub_pixel_bits: 4,
                ..precision
            },
            (eye, 256.0),
            point,
            DVec3::new(-1.0, 1.0, 0.0).normalize()
        ) > 10.0 * slanted
    );
}

#[test]
fn depth_matches_height_at_on_the_dem() {
    check_depth_against_height_at(
        "dem",
        dem_terrain(4, DVec2::ZERO),
        40.0,
        (RenderPath::Tess, LodMetric::Distance),
        HeightTolerance::OfRange(1e-3),
    );
}

/// Brute draws height_at's own triangles: only depth precision separates them.
#[test]
fn brute_surface_is_height_at() {
    check_depth_against_height_at(
        "dem",
        dem_terrain(32, DVec2::ZERO),
        40.0,
        (RenderPath::Brute, LodMetric::Distance),
        HeightTolerance::Precision,
    );
    check_depth_against_height_at(
        "default",
        default_terrain(32),
        60.0,
        (RenderPath::Brute, LodMetric::Distance),
        HeightTolerance::Precision,
    );
}

#[test]
fn brute_has_no_cracks() {
    if skip_gpu() {
        return;
    }
    for (name, terrain) in [
        ("dem", dem_terrain(32, DVec2::ZERO)),
        ("cliff", cliff_terrain()),
    ] {
        let cameras = crack_cameras(&terrain);
        let mut scene = GpuScene::new(terrain, 256, 192, false);
        let settings = RenderSettings {
            path: RenderPath::Brute,
            ..flat_settings(&scene.terrain, DistanceMode::Smooth)
        };
        for (view, cam) in &cameras {
            let frame = scene.render(cam, &settings);
            let stats = frame.measurements.statistics.unwrap();
            assert_eq!(
                stats.tes_invocations, 0,
                "no tessellation on the brute path"
            );
            assert!(stats.clipping_primitives > 0);
            let holes = enclosed_background(&frame.readback.rgba, 256, 192, |p| p[0] < 128);
            assert!(holes.is_empty(), "{name}/{view}: {} holes", holes.len());
        }
        scene.finish();
    }
}

#[test]
fn depth_matches_height_at_on_the_default_scene() {
    check_depth_against_height_at(
        "default",
        default_terrain(4),
        60.0,
        (RenderPath::Tess, LodMetric::Distance),
        HeightTolerance::OfRange(1e-3),
    );
}

#[test]
fn far_from_the_origin_renders_the_same() {
    if skip_gpu() {
        return;
    }
    let shift = DVec3::new(1e6, 0.0, 1e6);
    let near = dem_terrain(32, DVec2::ZERO);
    let far = dem_terrain(32, DVec2::new(shift.x, shift.z));
    let cams = crack_cameras(&near);
    let settings = RenderSettings::default();
    let mut near_scene = GpuScene::new(near, 320, 200, false);
    let mut far_scene = GpuScene::new(far, 320, 200, false);
    for (view, cam) in &cams {
        let a = near_scene.render(cam, &settings);
        let shifted = Camera {
            eye: cam.eye + shift,
            target: cam.target + shift,
            ..*cam
        };
        let b = far_scene.render(&shifted, &settings);
        let differing = a
            .readback
            .rgba
            .chunks_exact(4)
            .zip(b.readback.rgba.chunks_exact(4))
            .filter(|(p, q)| (0..3).any(|c| p[c].abs_diff(q[c]) > 12))
            .count();
        assert!(
            differing * 1000 <= 320 * 200,
            "{view}: {differing} pixels differ 1e6 units out"
        );
    }
    near_scene.finish();
    far_scene.finish();
}

#[test]
fn straight_down_onto_a_patch_corner() {
    if skip_gpu() {
        return;
    }
    // The eye exactly above a control point, looking straight down.
    let terrain = dem_terrain(32, DVec2::ZERO);
    let info = terrain.info().clone();
    let p = info.sample_position(64, 96);
    let h = f64::from(info.height_at(p.x, p.y).unwrap());
    let cam = camera([p.x, h + 300.0, p.y], [p.x, h - 10.0, p.y], 60.0);
    let mut scene = GpuScene::new(terrain, 128, 128, false);
    let frame = scene.render(&cam, &RenderSettings::default());
    assert!(
        frame.readback.depth.iter().all(|&d| d > 0.0),
        "the terrain fills the view"
    );
    // The centre pixel sees the control point's own height.
    let positions = world_positions(&frame, &cam);
    let centre = positions[64 * 128 + 64].unwrap();
    assert!((centre.y - f64::from(info.height_at(centre.x, centre.z).unwrap())).abs() < 0.5);
    // Eye exactly on the surface, looking along it: still renders cleanly,
    // and what it sees (ground rising ahead) lies on `height_at`'s surface.
    let on = camera([p.x, h, p.y], [p.x + 1000.0, h, p.y], 60.0);
    let brute = RenderSettings {
        path: RenderPath::Brute,
        ..RenderSettings::default()
    };
    let frame = scene.render(&on, &brute);
    let seen: Vec<DVec3> = world_positions(&frame, &on).into_iter().flatten().collect();
    assert!(seen.len() > 100, "{} pixels of ground", seen.len());
    for q in &seen {
        let ground = f64::from(info.height_at(q.x, q.z).unwrap());
        let tolerance = 0.5 + 1e-3 * (*q - on.eye).length();
        assert!((q.y - ground).abs() < tolerance, "{q} against {ground}");
    }
    scene.finish();
}

#[test]
fn flat_terrain_at_minimum_tessellation() {
    if skip_gpu() {
        return;
    }
    let flat = Heightmap::from_fn(65, 65, |_, _| 10.0).unwrap();
    let terrain = Terrain::new(
        TerrainInfo::new(flat, DVec2::ONE, 32, DVec2::ZERO).unwrap(),
        0.0,
    )
    .unwrap();
    let cams = crack_cameras(&terrain);
    let mut scene = GpuScene::new(terrain, 128, 128, false);
    let settings = RenderSettings {
        lod: one_factor(0.0),
        shading: Shading::Flat,
        clear_color: [0.0; 3],
        occlusion: false,
        ..RenderSettings::default()
    };
    let frame = scene.render(&cams[0].1, &settings);
    let stats = frame.measurements.statistics.unwrap();
    // Factor 1 rounds up to 2 with fractional_even spacing: 4 patches of 2x2 quads.
    assert_eq!(stats.tcs_patches, 4);
    assert!(enclosed_background(&frame.readback.rgba, 128, 128, |p| p[0] < 128).is_empty());
    scene.finish();
}

#[test]
fn gpu_tests_fail_without_a_device_unless_skipped() {
    if std::env::var_os("VKTERRAIN_CHILD").is_some() {
        return;
    }
    // Runs one GPU test of this binary again with no Vulkan driver.
    let run = |skip: bool| {
        let mut cmd = std::process::Command::new(std::env::current_exe().unwrap());
        cmd.args([
            "--exact",
            "flat_terrain_at_minimum_tessellation",
            "--test-threads",
            "1",
        ])
        .env("VKTERRAIN_CHILD", "1")
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
        .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .env_remove("VKTERRAIN_SKIP_GPU");
        if skip {
            cmd.env("VKTERRAIN_SKIP_GPU", "1");
        }
        cmd.output().unwrap()
    };
    let without = run(false);
    assert!(
        !without.status.success(),
        "a GPU test passed with no device"
    );
    let output = format!(
        "{}{}",
        String::from_utf8_lossy(&without.stdout),
        String::from_utf8_lossy(&without.stderr)
    );
    assert!(output.contains("no Vulkan device found"), "{output}");
    let skipped = run(true);
    assert!(skipped.status.success());
    // The skip shows even with the harness capturing output.
    let said = String::from_utf8_lossy(&skipped.stderr);
    assert!(
        said.contains("SKIPPED flat_terrain_at_minimum_tessellation: VKTERRAIN_SKIP_GPU=1"),
        "{said}"
    );
}

#[test]
fn error_bounded_tessellation_is_crack_free_and_follows_the_screen() {
    if skip_gpu() {
        return;
    }
    for (name, terrain) in [
        ("dem", dem_terrain(16, DVec2::ZERO)),
        ("cliff", cliff_terrain()),
        ("default", default_terrain(32)),
    ] {
        let cams = crack_cameras(&terrain);
        let mut small = GpuScene::new(terrain.clone(), 192, 128, false);
        let mut large = GpuScene::new(terrain, 384, 256, false);
        // Both measures' levels follow the screen. Merged nodes are left
        // out: a node drawn as one patch trades draws for triangles at a
        // distance that moves with the resolution (tests/patch_merge.rs).
        // The view model's frames are a still camera's, whose counts say
        // what shows: without counts the plan finds hidden ground from its
        // blocks' boxes (`lod::horizon`), and a smaller screen's blocks are
        // larger, so it proves less ground hidden (on the cliff's top
        // view, 2,833 triangles at 192 x 128 against 2,306 at 384 x 256 at
        // 0.5 px; 2,976 and 3,360 without the horizon).
        for by in [ErrorMeasure::Bound, ErrorMeasure::Sight] {
            let frames = match by {
                ErrorMeasure::Sight => 1 + vkterrain::bench::run::STILL_FRAMES,
                _ => 1,
            };
            for (view, cam) in &cams {
                let mut last = u64::MAX;
                for pixels in [0.5f32, 2.0, 8.0] {
                    // Culled every frame: whether culling pays for itself
                    // on a view (`WORTH_CULLING`) is decided from the frame
                    // before, which would make the counts depend on the
                    // order of the frames.
                    let settings = RenderSettings {
                        lod_metric: vkterrain::render::LodMetric::Error(pixels),
                        error_measure: by,
                        merge_patches: false,
                        occlusion_every_frame: true,
                        ..flat_settings(&large.terrain, DistanceMode::Smooth)
                    };
                    // A still camera's last frame, after `frames - 1` before it.
                    let still = |scene: &mut GpuScene| {
                        (1..frames).fold(scene.render(cam, &settings), |_, _| {
                            scene.render(cam, &settings)
                        })
                    };
                    let frame = still(&mut large);
                    let holes = enclosed_background(&frame.readback.rgba, 384, 256, |p| p[0] < 128);
                    assert!(
                        holes.is_empty(),
                        "{name}/{view}/{pixels} px/{by:?}: {} holes",
                        holes.len()
                    );
                    let tris = frame.measurements.statistics.unwrap().clipping_primitives;
                    assert!(
                        tris <= last,
                        "{name}/{view}/{by:?}: {pixels} px made {tris} triangles, more than {last}"
                    );
                    last = tris;
                    // Half the pixels each way: the same error budget needs
                    // fewer triangles.
                    let smaller = still(&mut small)
                        .measurements
                        .statistics
                        .unwrap()
                        .clipping_primitives;
                    assert!(
                        smaller <= tris,
                        "{name}/{view}/{pixels} px/{by:?}: {smaller} at 192x128 vs {tris} at 384x256"
                    );
                }
            }
        }
        small.finish();
        large.finish();
    }
}

/// A renderer reads the view model only for the error LOD's real-time
/// measure, and only then asks the terrain for it (an 8193^2 terrain's is
/// 497 MB): distance frames, and error frames by the bound, leave it
/// unbuilt, on both paths; the first frame that reads it builds it, before
/// its choice is timed, and the time joins the tables'.
#[test]
fn the_view_model_is_built_by_the_first_frame_that_reads_it() {
    if skip_gpu() {
        return;
    }
    let mut scene = GpuScene::new(cliff_terrain(), 96, 64, false);
    let cam = crack_cameras(&scene.terrain)[0].1;
    let error = |path, error_measure| RenderSettings {
        path,
        lod_metric: LodMetric::Error(1.0),
        error_measure,
        ..RenderSettings::default()
    };
    for path in [RenderPath::Tess, RenderPath::Geomip, RenderPath::Brute] {
        let distance = RenderSettings {
            path,
            ..RenderSettings::default()
        };
        scene.render(&cam, &distance);
        scene.render(&cam, &error(path, ErrorMeasure::Bound));
        assert!(!scene.terrain.sight_table_asked(), "{path:?}");
    }
    scene.render(&cam, &error(RenderPath::Brute, ErrorMeasure::Sight));
    assert!(!scene.terrain.sight_table_asked(), "brute reads no model");
    let tables_ms = scene.renderer().error_table_ms();
    scene.render(&cam, &error(RenderPath::Geomip, ErrorMeasure::Sight));
    assert!(scene.terrain.sight_table_asked());
    assert!(scene.terrain.sight_table().is_some());
    assert!(scene.renderer().error_table_ms() > tables_ms);
    scene.finish();
}

#[test]
fn error_bounded_factors_grow_with_zoom_and_shrink_with_tolerance() {
    use vkterrain::lod::{patch_error_factors, Across};
    let terrain = dem_terrain(32, DVec2::ZERO);
    let table = terrain.error_table();
    let grid = terrain.grid();
    let id = grid.patch_id(grid.patch_count() / 2);
    let own: [f32; 7] = table.patch(grid.patch_index(id)).try_into().unwrap();
    let eye = Vec3::new(0.0, 3000.0, -9000.0);
    let corners = terrain.patch_corners(id).map(|c| c - eye);
    let bounds = terrain.y_bounds()[grid.patch_index(id)].map(|y| y - eye.y);
    let range = {
        let (lo, hi) = terrain.info().min_max();
        [lo - eye.y, hi - eye.y]
    };
    let cells = [32, 32];
    let inside = |ppr: f32, px: f32| {
        patch_error_factors(
            corners,
            bounds,
            range,
            &own,
            [Across::Border; 4],
            cells,
            ppr,
            px,
        )
        .inside[0]
    };
    // Narrower field of view or more pixels: more pixels per radian. The
    // factors are whole levels, so small changes may keep the level.
    let zoom: Vec<f32> = (0..40).map(|e| inside(2f32.powi(e), 1.0)).collect();
    let tolerance: Vec<f32> = (0..40).map(|e| inside(1000.0, 2f32.powi(20 - e))).collect();
    for sweep in [&zoom, &tolerance] {
        assert!(sweep.windows(2).all(|w| w[0] <= w[1]), "{sweep:?}");
        let mut levels = sweep.clone();
        levels.dedup();
        assert!(levels.len() >= 4, "{sweep:?}");
    }
    // At an enormous scale no tessellation will do: the patch's cell count,
    // drawn at full resolution, never more than the data has.
    assert_eq!(inside(1e9, 1.0), 32.0);
    // A full-resolution neighbour gets a vertex on every sample of the
    // shared edge whatever this patch's own level, and a merged node one
    // segment whatever the errors.
    let left: [f32; 7] = table.patch(grid.patch_index(id) - 1).try_into().unwrap();
    let across = [
        Across::Merged,
        Across::Patch(&left),
        Across::FullResolution,
        Across::Border,
    ];
    let near = patch_error_factors(corners, bounds, range, &own, across, cells, 1e9, 1.0);
    assert_eq!(near.edges, [1.0, 32.0, 32.0, 32.0]);
    let far = patch_error_factors(corners, bounds, range, &own, across, cells, 1e-3, 1.0);
    assert_eq!(far.edges, [1.0, 1.0, 32.0, 1.0]);
    assert_eq!(inside(1e-3, 1.0), 1.0);
}

/// A rough map with cliffs: hills, terraces 60 m high in a checkerboard of
/// 17x23-sample blocks, and per-sample noise, 120x91 samples 4 m apart in
/// 8-cell patches (remainder patches at both far edges).
fn rough_cliff_terrain() -> Terrain {
    let map = Heightmap::from_fn(120, 91, |r, c| {
        let hills = 40.0 * (c as f32 * 0.21).sin() * (r as f32 * 0.17).cos();
        let terrace = if (c / 17 + r / 23) % 2 == 0 {
            0.0
        } else {
            60.0
        };
        let mut x = (r as u64) << 32 | c as u64;
        x = x.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        x ^= x >> 29;
        hills + terrace + (x % 1000) as f32 * 0.003
    })
    .unwrap();
    let info = TerrainInfo::new(map, DVec2::splat(4.0), 8, DVec2::ZERO).unwrap();
    Terrain::new(info, 0.0).unwrap()
}

/// Low views across the terrain, where the nearest patches need the data's
/// full resolution and the far ones far less.
fn low_cameras(terrain: &Terrain) -> Vec<(&'static str, Camera)> {
    let (c, size, top) = extent(terrain);
    let mut cams = crack_cameras(terrain);
    cams.push((
        "low-grazing",
        camera(
            [c.x - 0.55 * size, top + 0.02 * size, c.z - 0.4 * size],
            [c.x + 0.3 * size, c.y, c.z + 0.2 * size],
            60.0,
        ),
    ));
    cams
}

fn error_settings(pixels: f32) -> RenderSettings {
    RenderSettings {
        lod_metric: LodMetric::Error(pixels),
        ..RenderSettings::default()
    }
}

/// The error LOD holding every patch's bound within `pixels`: at a tiny
/// tolerance, every patch at full resolution.
fn bound_settings(pixels: f32) -> RenderSettings {
    RenderSettings {
        error_measure: ErrorMeasure::Bound,
        ..error_settings(pixels)
    }
}

/// The tess error LOD has no error floor: where the data's full resolution
/// is needed it draws the reference's own triangles, so at tau = 1 px its
/// p99 is within 1 px of brute, with no more triangles than brute.
#[test]
fn error_lod_has_no_floor_on_a_rough_cliff_map() {
    if skip_gpu() {
        return;
    }
    let terrain = rough_cliff_terrain();
    let cams = low_cameras(&terrain);
    let (w, h) = (640, 360);
    let mut scene = GpuScene::new(terrain, w, h, false);
    let brute_settings = RenderSettings {
        path: RenderPath::Brute,
        ..RenderSettings::default()
    };
    for (view, cam) in &cams {
        let reference = scene.render(cam, &brute_settings);
        let brute_tris = reference
            .measurements
            .statistics
            .unwrap()
            .clipping_invocations;
        // The measure that holds every patch's error within tau: the view's
        // measure spends 1 % of pixels where it saves most, which this
        // map's terraces can overdraw (see BENCHMARKS.md).
        let frame = scene.render(cam, &bound_settings(1.0));
        // Triangles made, before frustum and back-face culling: which
        // faces an edge-on triangle shows turns on its vertices' last bits,
        // which the paths' vertex shaders round differently.
        let tris = frame.measurements.statistics.unwrap().clipping_invocations;
        let k = f64::from(reference.view.pixels_per_radian);
        let stats = measure(&DepthView::of(&frame), &DepthView::of(&reference), k);
        eprintln!(
            "rough/{view}: p99 {:.3} px, max {:.3} px, {tris} triangles against brute's {brute_tris}",
            stats.p99_px, stats.max_px
        );
        assert!(stats.pixels > 10_000, "{view}: {} pixels", stats.pixels);
        assert!(
            stats.p99_px <= 1.0,
            "{view}: p99 {} px at tau = 1 px",
            stats.p99_px
        );
        assert!(
            tris <= brute_tris,
            "{view}: {tris} triangles, more than brute's {brute_tris}"
        );
    }
    scene.finish();
}

/// With every patch at full resolution the tess error LOD is the reference:
/// its surface lies on height_at as brute's does, and its depth equals
/// brute's.
#[test]
fn full_resolution_tess_is_the_reference() {
    check_depth_against_height_at(
        "dem",
        dem_terrain(16, DVec2::ZERO),
        40.0,
        (RenderPath::Tess, LodMetric::Error(1e-6)),
        HeightTolerance::Precision,
    );
    if skip_gpu() {
        return;
    }
    for (name, terrain) in [
        ("dem", dem_terrain(16, DVec2::ZERO)),
        ("rough", rough_cliff_terrain()),
    ] {
        let (lo, hi) = terrain.info().min_max();
        let range = f64::from(hi - lo);
        let cams = crack_cameras(&terrain);
        let mut scene = GpuScene::new(terrain, 256, 192, false);
        for (view, cam) in &cams {
            let brute = scene.render(
                cam,
                &RenderSettings {
                    path: RenderPath::Brute,
                    ..RenderSettings::default()
                },
            );
            let tess = scene.render(cam, &bound_settings(1e-6));
            let stats = tess.measurements.statistics.unwrap();
            assert_eq!(
                stats.tes_invocations, 0,
                "{name}/{view}: nothing tessellated"
            );
            // Triangles made (see `error_lod_has_no_floor_on_a_rough_cliff_map`).
            let brute_stats = brute.measurements.statistics.unwrap();
            assert!(
                stats.clipping_invocations <= brute_stats.clipping_invocations,
                "{name}/{view}: {stats:?} against brute's {brute_stats:?}"
            );
            // Per pixel, what the device's precision allows two renders
            // of one surface (`pair_height_tolerance`).
            let precision = raster_precision(&scene);
            let k = f64::from(brute.view.pixels_per_radian);
            let info = scene.terrain.info();
            let (b, t) = (world_positions(&brute, cam), world_positions(&tess, cam));
            let (mut worst, mut worst_share, mut checked) = (0.0f64, 0.0f64, 0);
            for (b, t) in b.iter().zip(&t) {
                match (b, t) {
                    (Some(b), Some(t)) => {
                        let Some(normal) = surface_normal(info, b.x, b.z) else {
                            continue;
                        };
                        let allowed = pair_height_tolerance(precision, (cam.eye, k), *b, normal);
                        let d = (b.y - t.y).abs();
                        worst = worst.max(d);
                        worst_share = worst_share.max(d / allowed.max(f64::MIN_POSITIVE));
                        checked += 1;
                    }
                    (None, None) => {}
                    _ => panic!("{name}/{view}: terrain in one render and sky in the other"),
                }
            }
            assert!(checked > 10_000, "{name}/{view}: {checked} pixels checked");
            assert!(
                worst_share <= 1.0,
                "{name}/{view}: tess and brute heights differ by up to {worst} m, {worst_share:.2} of \
                 what the device's precision allows at a pixel (range {range})"
            );
            eprintln!(
                "{name}/{view}: worst |tess - brute| {worst:.5} m, {worst_share:.3} of the allowed"
            );
        }
        scene.finish();
    }
}

/// Edges between full-resolution and tessellated patches are watertight:
/// views where the error LOD mixes the two, on the DEM, the cliff maps and
/// the default scene, show no background inside the terrain that brute's
/// render of the view does not show too (steep walls can enclose real
/// pockets of sky).
#[test]
fn no_cracks_between_full_resolution_and_tessellated_patches() {
    if skip_gpu() {
        return;
    }
    for (name, terrain, pixels) in [
        ("dem", dem_terrain(16, DVec2::ZERO), 0.5f32),
        ("cliff", cliff_terrain(), 1.0),
        ("rough", rough_cliff_terrain(), 4.0),
        ("default", default_terrain(32), 1.0),
    ] {
        let table = terrain.error_table();
        let cams = low_cameras(&terrain);
        let (w, h) = (384, 256);
        let mut scene = GpuScene::new(terrain, w, h, false);
        let settings = RenderSettings {
            lod_metric: LodMetric::Error(pixels),
            ..flat_settings(&scene.terrain, DistanceMode::Smooth)
        };
        let mut mixed = 0;
        for (view, cam) in &cams {
            let frame = scene.render(cam, &settings);
            let choice = choose_tess_error(
                &scene.terrain,
                &table,
                frame.view.eye_local,
                frame.view.pixels_per_radian,
                pixels,
            );
            let count = scene.terrain.grid().patch_count();
            let full = (0..count).filter(|&p| choice.is_full_resolution(p)).count();
            if full > 0 && full < count {
                mixed += 1;
            }
            let brute = scene.render(
                cam,
                &RenderSettings {
                    path: RenderPath::Brute,
                    ..settings
                },
            );
            assert_no_holes(
                &format!("{name}/{view} ({full} of {count} patches at full resolution)"),
                &frame,
                &holes_in(&brute),
            );
        }
        assert!(
            mixed >= 2,
            "{name}: only {mixed} views mix full-resolution and tessellated patches"
        );
        scene.finish();
    }
}

/// The peers' policies, run as published, are crack-free too: each edge's
/// factor comes from its own ends or midpoint, which both patches share.
#[test]
fn peer_policies_are_crack_free() {
    if skip_gpu() {
        return;
    }
    let terrain = dem_terrain(16, DVec2::ZERO);
    let cams = crack_cameras(&terrain);
    let (w, h) = (384, 256);
    let mut scene = GpuScene::new(terrain, w, h, false);
    for metric in vkterrain::lod::PeerPolicy::ALL.map(LodMetric::Peer) {
        let settings = RenderSettings {
            lod_metric: metric,
            ..flat_settings(&scene.terrain, DistanceMode::Smooth)
        };
        for (view, cam) in &cams {
            let frame = scene.render(cam, &settings);
            let stats = frame.measurements.statistics.unwrap();
            assert!(stats.tes_invocations > 0, "{metric:?}/{view}: tessellated");
            assert_no_holes(&format!("{metric:?}/{view}"), &frame, &[]);
        }
    }
    scene.finish();
}

/// Background pixels enclosed by terrain in a flat-shaded frame.
fn holes_in(frame: &vkterrain::render::HeadlessFrame) -> Vec<(usize, usize)> {
    let (w, h) = (
        frame.readback.width as usize,
        frame.readback.height as usize,
    );
    enclosed_background(&frame.readback.rgba, w, h, |p| p[0] < 128)
}

/// No enclosed background in `frame` beyond the `pockets` the reference
/// shows too, and beyond pixels that touch background reaching the border
/// corner to corner: a notch in the outline that a one-pixel sliver of
/// terrain closes, not a crack, which opens inside the terrain (on failure
/// the frame is saved as NAME-cracks.png).
fn assert_no_holes(
    name: &str,
    frame: &vkterrain::render::HeadlessFrame,
    pockets: &[(usize, usize)],
) {
    let (w, h) = (
        frame.readback.width as usize,
        frame.readback.height as usize,
    );
    let enclosed = holes_in(frame);
    let outside = |x: usize, y: usize| {
        frame.readback.rgba[4 * (y * w + x)] < 128 && !enclosed.contains(&(x, y))
    };
    let on_outline = |&(x, y): &(usize, usize)| {
        (y.saturating_sub(1)..=(y + 1).min(h - 1))
            .any(|qy| (x.saturating_sub(1)..=(x + 1).min(w - 1)).any(|qx| outside(qx, qy)))
    };
    let holes: Vec<_> = enclosed
        .iter()
        .copied()
        .filter(|p| !pockets.contains(p) && !on_outline(p))
        .collect();
    if !holes.is_empty() {
        let file = format!("{}-cracks.png", name.replace(['/', ' ', '(', ')'], "_"));
        frame.rgba_image().save(file).unwrap();
    }
    assert!(
        holes.is_empty(),
        "{name}: {} background pixels inside the terrain, first at {:?}",
        holes.len(),
        &holes[..holes.len().min(5)]
    );
}

/// Popping of the tess error LOD: as the camera sinks slowly, looking
/// straight down, levels switch and patches go to full resolution, and each
/// pixel's error against brute
/// (signed, in pixels) jumps between frames by no more than twice tau, the
/// most two surfaces each within tau of the reference can differ.
#[test]
fn error_lod_popping_stays_within_twice_tau() {
    if skip_gpu() {
        return;
    }
    let terrain = dem_terrain(16, DVec2::ZERO);
    let table = terrain.error_table();
    let (w, h) = (320, 240);
    let mut scene = GpuScene::new(terrain, w, h, false);
    let tau = 2.0f32;
    let settings = error_settings(tau);
    let brute_settings = RenderSettings {
        path: RenderPath::Brute,
        ..RenderSettings::default()
    };
    let mut previous: Option<Vec<Option<f64>>> = None;
    let (mut worst, mut switches, mut compared) = (0.0f64, 0usize, 0usize);
    let mut last_full: Option<Vec<bool>> = None;
    // Straight down, as a top-down view has no silhouettes for a level
    // switch to move.
    for k in 0..30 {
        let height = 5000.0 - 120.0 * f64::from(k);
        let cam = camera([1000.0, height, 1500.0], [1000.0, 0.0, 1500.001], 50.0);
        let frame = scene.render(&cam, &settings);
        let reference = scene.render(&cam, &brute_settings);
        let choice = choose_tess_error(
            &scene.terrain,
            &table,
            frame.view.eye_local,
            frame.view.pixels_per_radian,
            tau,
        );
        let full: Vec<bool> = (0..scene.terrain.grid().patch_count())
            .map(|p| choice.is_full_resolution(p))
            .collect();
        if let Some(last) = &last_full {
            switches += last.iter().zip(&full).filter(|(a, b)| a != b).count();
        }
        last_full = Some(full);
        let k_px = f64::from(frame.view.pixels_per_radian);
        let errors: Vec<Option<f64>> = world_positions(&frame, &cam)
            .into_iter()
            .zip(world_positions(&reference, &cam))
            .map(|(t, r)| match (t, r) {
                (Some(t), Some(r)) => Some((t.y - r.y) * k_px / (r - cam.eye).length()),
                _ => None,
            })
            .collect();
        if let Some(prev) = &previous {
            for (a, b) in prev.iter().zip(&errors) {
                if let (Some(a), Some(b)) = (a, b) {
                    worst = worst.max((a - b).abs());
                    compared += 1;
                }
            }
        }
        previous = Some(errors);
    }
    eprintln!(
        "tess error {tau} px: largest per-pixel error jump {worst:.3} px between frames \
         over {compared} pixel pairs, {switches} full-resolution switches"
    );
    assert!(
        switches > 0,
        "the descent switches patches to full resolution"
    );
    assert!(compared > 500_000);
    assert!(
        worst <= 2.0 * f64::from(tau),
        "a pixel's error jumped {worst} px between frames"
    );
    scene.finish();
}

/// A renderer built for the geomip path alone draws the tess path, and
/// wireframe, when a frame asks for them: `prepare` builds what is missing,
/// so a frame's settings cannot disagree with the renderer. The pictures
/// equal those of a renderer built with every path up front.
#[test]
fn paths_a_renderer_lacks_are_built_when_a_frame_asks() {
    if skip_gpu() {
        return;
    }
    let terrain = dem_terrain(16, DVec2::ZERO);
    let cam = crack_cameras(&terrain)[0].1;
    let mut full = GpuScene::new(terrain.clone(), 96, 64, true);
    let gpu = open_gpu(None);
    let options = vkterrain::render::RendererOptions::single_sample(vec![RenderPath::Geomip]);
    let (mut renderer, mut headless) =
        vkterrain::render::offscreen(&gpu, &terrain, &Appearance::default(), &options, (96, 64))
            .expect("a geomip renderer");
    let before = gpu.device.memory_report();
    assert!(!before.iter().any(|(n, _)| n == "terrain.error_table"));
    for (path, lod_metric, wireframe) in [
        (RenderPath::Tess, LodMetric::Distance, false),
        (RenderPath::Tess, LodMetric::Error(1.0), true),
        (RenderPath::Brute, LodMetric::Distance, true),
    ] {
        let settings = RenderSettings {
            path,
            lod_metric,
            wireframe,
            ..RenderSettings::default()
        };
        let lazy = headless
            .render(&mut renderer, &terrain, &cam, &settings)
            .expect("built on demand");
        let eager = full.render(&cam, &settings);
        assert_eq!(
            lazy.measurements.statistics, eager.measurements.statistics,
            "{path:?} {lod_metric:?}"
        );
        assert!(
            lazy.readback.rgba == eager.readback.rgba,
            "{path:?} {lod_metric:?} wireframe {wireframe}: the images differ"
        );
    }
    let after = gpu.device.memory_report();
    assert!(after.iter().any(|(n, _)| n == "terrain.view_errors[0]"));
    drop((renderer, headless));
    let report = gpu.shutdown();
    assert_eq!(report.count, 0, "{:#?}", report.messages);
    full.finish();
}

/// Merged nodes (`lod::patch_merge`) on the DEM, whose last patch
/// column and row are remainders, from views where nodes of two or more
/// levels meet patches drawn on their own: no cracks against brute's
/// outline, the p99 of the per-pixel error against brute within tau or
/// within 10 % of the same view unmerged, and fewer patches reaching the
/// control shader than without merging.
#[test]
fn merged_nodes_are_watertight_and_keep_the_error_bound() {
    if skip_gpu() {
        return;
    }
    let terrain = dem_terrain(16, DVec2::ZERO);
    let (w, h) = (480, 320);
    let mut scene = GpuScene::new(terrain, w, h, false);
    let top = f64::from(scene.terrain.info().min_max().1);
    let views = [
        ([-60_000.0, 15_000.0, -60_000.0], 2.0f32),
        ([-50_000.0, 8_000.0, 10_000.0], 4.0),
        ([5_000.0, 12_000.0, 40_000.0], 4.0),
        ([0.0, 60_000.0, 0.0], 4.0),
    ];
    for (eye, tau) in views {
        let cam = camera([eye[0], eye[1] + top, eye[2]], [0.0, 0.0, 0.0], 25.0);
        let flat = RenderSettings {
            shading: Shading::Flat,
            clear_color: [0.0; 3],
            ..bound_settings(tau)
        };
        let reference = scene.render(
            &cam,
            &RenderSettings {
                path: RenderPath::Brute,
                ..flat
            },
        );
        let unmerged = scene.render(
            &cam,
            &RenderSettings {
                merge_patches: false,
                ..flat
            },
        );
        let frame = scene.render(&cam, &flat);
        let nodes = scene.renderer().merged_nodes();
        let name = format!("{eye:?} at {tau} px ({nodes} nodes)");
        assert!(nodes >= 2, "{name}");
        assert_no_holes(&name, &frame, &holes_in(&reference));
        let k = f64::from(reference.view.pixels_per_radian);
        let stats = measure(&DepthView::of(&frame), &DepthView::of(&reference), k);
        let before = measure(&DepthView::of(&unmerged), &DepthView::of(&reference), k);
        let patches =
            |f: &vkterrain::render::HeadlessFrame| f.measurements.statistics.unwrap().tcs_patches;
        eprintln!(
            "{name}: p99 {:.3} px (unmerged {:.3}), max {:.3} px (unmerged {:.3}), \
             {} patches shaded against {}",
            stats.p99_px,
            before.p99_px,
            stats.max_px,
            before.max_px,
            patches(&frame),
            patches(&unmerged)
        );
        assert!(stats.pixels > 5_000, "{name}: {} pixels", stats.pixels);
        // The bound is face-on from each patch's nearest point, which
        // these distant, oblique views can exceed at silhouettes without
        // merging too: merging must not add to it.
        assert!(
            stats.p99_px <= f64::from(tau).max(1.1 * before.p99_px),
            "{name}: p99 {} px against {} px unmerged",
            stats.p99_px,
            before.p99_px
        );
        assert!(patches(&frame) < patches(&unmerged), "{name}");
    }
    scene.finish();
}

/// A rough generated map: 257^2 eroded fractal samples 8 m apart, up to
/// 400 m high, in 16-cell patches.
fn rough_terrain() -> Terrain {
    let map =
        vkterrain::terrain::generate::generate(&vkterrain::terrain::generate::GeneratorParams {
            size: 257,
            seed: 5,
            droplets: 20_000,
        })
        .unwrap();
    let map = Heightmap::from_fn(257, 257, |r, c| 400.0 * map.get(r, c)).unwrap();
    let info = TerrainInfo::new(map, DVec2::splat(8.0), 16, DVec2::ZERO).unwrap();
    Terrain::new(info, 0.0).unwrap()
}

/// What the plan predicts for each patch it draws: the chosen blocks' and
/// merged nodes' own errors, full resolution's none, and tau for blocks
/// the control shader tessellates by the bound.
fn predicted_per_patch(
    terrain: &Terrain,
    plan: &vkterrain::lod::plan::FramePlan,
    tau: f32,
) -> Vec<Option<f32>> {
    let grid = terrain.grid();
    let mut predicted = vec![None; grid.patch_count()];
    for block in &plan.blocks {
        let px = if block.full_resolution {
            0.0
        } else if block.chosen {
            block.predicted_px
        } else {
            tau
        };
        for p in block.patches(grid) {
            predicted[p] = Some(px);
        }
    }
    for node in &plan.merged {
        for r in node.row..node.row + node.span() {
            for c in node.col..node.col + node.span() {
                predicted[r as usize * grid.patch_cols() + c as usize] = Some(node.predicted_px);
            }
        }
    }
    predicted
}

/// Height of the reference's own triangles at world (x, z): each cell
/// split along its upper-right to lower-left diagonal, as brute and the
/// full-resolution path draw it. None off the terrain.
fn reference_height(info: &TerrainInfo, x: f64, z: f64) -> Option<f64> {
    let g = info.world_to_grid(x, z);
    let (cols, rows) = (info.cols(), info.rows());
    if !(g.x >= 0.0 && g.y >= 0.0 && g.x <= (cols - 1) as f64 && g.y <= (rows - 1) as f64) {
        return None;
    }
    let (c, r) = ((g.x as usize).min(cols - 2), (g.y as usize).min(rows - 2));
    let (u, v) = (g.x - c as f64, g.y - r as f64);
    let heights = info.heightmap().expect("the heights are in memory");
    let at = |r: usize, c: usize| f64::from(heights.get(r, c));
    let (a, b, cc, d) = (at(r, c), at(r, c + 1), at(r + 1, c), at(r + 1, c + 1));
    Some(if u + v <= 1.0 {
        a + u * (b - a) + v * (cc - a)
    } else {
        d + (1.0 - u) * (cc - d) + (1.0 - v) * (b - d)
    })
}

/// Each patch's measured error stays within what the plan predicted for
/// it, on the DEM and a rough generated map, from above, obliquely and
/// low, at 0.5 to 2 px.
///
/// The prediction bounds the drawn surface's vertical distance from the
/// reference's triangles, in pixels seen face-on from the patch's nearest
/// point. That is measured at every pixel the LOD draws: the drawn
/// point's height against the reference's beneath it, over the drawn
/// point's distance. (How far apart the two renders' hits along one ray
/// lie is a further matter of the angle between the ray and the ground:
/// at most that vertical error where the ground faces the eye, unbounded
/// near silhouettes, as the README says.)
///
/// The slack: 0.02 px for positions rebuilt from 32-bit depth at pixel
/// centres (a full-resolution patch on the rough map reads 0.011 px), and
/// 15 % for the tessellator's transition rings. Where an edge's factor is
/// finer than the inside's, the triangles joining the two are of no
/// level's regular grid, so no table row measured them: 11.7 % over the
/// prediction is the most seen here (the rough map, straight down, 2 px,
/// a patch at four segments inside three of whose neighbours are at
/// eight; the DEM obliquely at 0.5 px, a patch at two segments inside
/// whose four neighbours are all finer, so that every triangle of it is a
/// transition's, 8.0 %). It was 7.3 % before the view model read ground
/// falling away along the ray at its face-on error and chose coarser
/// levels beside finer ones, and 4.8 % before it read each path's own
/// diagonal.
#[test]
fn each_patch_stays_within_its_predicted_error() {
    use vkterrain::lod::hierarchy::Hierarchy;
    use vkterrain::lod::plan::{plan, PlanInputs, SightReading};
    use vkterrain::lod::view::Tau;
    if skip_gpu() {
        return;
    }
    let (w, h) = (480u32, 320u32);
    let mut checked = 0usize;
    let mut worst = (0.0f64, String::new());
    for (name, terrain) in [
        ("dem", dem_terrain(16, DVec2::ZERO)),
        ("rough", rough_terrain()),
    ] {
        let (table, _) = terrain.error_tables();
        let sight = terrain.sight_table();
        let hierarchy = Hierarchy::new(&terrain, table);
        let info = terrain.info();
        let grid = terrain.grid();
        let patch_at = |p: DVec3| {
            let g = info.world_to_grid(p.x, p.z);
            grid.patch_index(grid.patch_at(g.x, g.y))
        };
        let mut scene = GpuScene::new(terrain.clone(), w, h, false);
        for (view_name, cam) in &crack_cameras(&terrain) {
            for tau in [0.5f32, 1.0, 2.0] {
                let settings = RenderSettings {
                    lod_metric: LodMetric::Error(tau),
                    error_measure: ErrorMeasure::Sight,
                    ..RenderSettings::default()
                };
                let tested = scene.render(cam, &settings);
                let ppr = f64::from(tested.view.pixels_per_radian);
                let lod_view = tested.view.lod_view(Tau::new(tau).unwrap());
                let inputs = PlanInputs {
                    table,
                    sight,
                    merge: settings.merge_patches,
                    cull: true,
                    reading: SightReading::Tessellated,
                    // What the frame's choice read of earlier frames.
                    seen: scene.renderer().seen_pixels(),
                };
                let frame = plan(&terrain, &hierarchy, &lod_view, &inputs);
                let predicted = predicted_per_patch(&terrain, &frame, tau);
                let mut measured = vec![None::<f64>; grid.patch_count()];
                for t in world_positions(&tested, cam).into_iter().flatten() {
                    let Some(surface) = reference_height(info, t.x, t.z) else {
                        continue;
                    };
                    let px = (t.y - surface).abs() * ppr / (t - cam.eye).length();
                    let m = &mut measured[patch_at(t)];
                    *m = Some(m.map_or(px, |m| m.max(px)));
                }
                for (p, m) in measured.iter().enumerate() {
                    let Some(m) = *m else { continue };
                    let Some(pred) = predicted[p] else {
                        panic!("{name}/{view_name}/{tau}: patch {p} drawn but not planned");
                    };
                    let over = m - f64::from(pred);
                    assert!(
                        over <= 0.02 + 0.15 * f64::from(pred),
                        "{name}/{view_name}/{tau} px: patch {p} measured {m:.4} px, predicted {pred:.4}"
                    );
                    if over > worst.0 {
                        worst = (
                            over,
                            format!("{name}/{view_name}/{tau}: patch {p} {m:.4} > {pred:.4}"),
                        );
                    }
                    checked += 1;
                }
            }
        }
        scene.finish();
    }
    eprintln!("{checked} patches measured; largest excess {worst:?}");
    assert!(checked > 1000, "only {checked} patches measured");
}

/// The tessellator splits a patch's quads as the error LOD's view model
/// expects (`sight::tess_splits_bc`). The map's heights at the level's
/// vertices alternate +10 and -10, so each quad's A and D corners (upper
/// left, lower right) share one height and its B and C corners the other:
/// its centre lies at A's height under the A-D diagonal and at B's under
/// B-C. Looked at from straight above, every quad's centre shows which.
/// The patch is drawn by the distance LOD at factor 2^level: fractional
/// even spacing at an even whole factor lays out the same points and
/// rings as the error LOD's equal spacing at a power of two (a wireframe
/// of the error LOD on the DEM shows the same quadrants).
#[test]
fn the_tessellator_splits_quads_as_the_view_model_expects() {
    if skip_gpu() {
        return;
    }
    let cells = 32usize;
    for level in 1..=4u32 {
        let segments = 1usize << level;
        let step = cells / segments;
        let vertex = |r: usize, c: usize| {
            if (r / step + c / step) % 2 == 0 {
                10.0f32
            } else {
                -10.0
            }
        };
        let map = Heightmap::from_fn(cells + 1, cells + 1, vertex).unwrap();
        let info = TerrainInfo::new(map, DVec2::ONE, cells as u32, DVec2::ZERO).unwrap();
        let terrain = Terrain::new(info.clone(), 0.0).unwrap();
        let centre = info.sample_position(cells / 2, cells / 2);
        let cam = camera([centre.x, 200.0, centre.y], [centre.x, 0.0, centre.y], 12.0);
        let mut scene = GpuScene::new(terrain, 1024, 1024, false);
        let settings = RenderSettings {
            lod: one_factor(level as f32),
            shading: Shading::Flat,
            clear_color: [0.0; 3],
            occlusion: false,
            ..RenderSettings::default()
        };
        let frame = scene.render(&cam, &settings);
        let stats = frame.measurements.statistics.unwrap();
        assert_eq!(
            stats.clipping_invocations,
            2 * (segments * segments) as u64,
            "level {level}: one patch of {segments}^2 quads"
        );
        // Per quad: the pixels seen within a fifth of a cell of its centre,
        // and how many lie on the side of A's height.
        let mut seen = vec![[0usize; 2]; segments * segments];
        for p in world_positions(&frame, &cam).into_iter().flatten() {
            let g = info.world_to_grid(p.x, p.z);
            let (qj, qi) = ((g.x / step as f64) as usize, (g.y / step as f64) as usize);
            if qi >= segments || qj >= segments {
                continue;
            }
            let middle = DVec2::new(
                (qj as f64 + 0.5) * step as f64,
                (qi as f64 + 0.5) * step as f64,
            );
            if (g - middle).abs().max_element() > 0.2 {
                continue;
            }
            let a = f64::from(vertex(qi * step, qj * step));
            let cell = &mut seen[qi * segments + qj];
            cell[0] += 1;
            cell[1] += usize::from(p.y * a > 0.0);
        }
        for qi in 0..segments {
            for qj in 0..segments {
                let [pixels, at_a] = seen[qi * segments + qj];
                assert!(
                    pixels >= 4,
                    "level {level} quad ({qi}, {qj}): {pixels} pixels"
                );
                let bc = vkterrain::terrain::sight::tess_splits_bc(qi, qj, segments);
                let expected = if bc { 0 } else { pixels };
                assert_eq!(
                    at_a, expected,
                    "level {level} quad ({qi}, {qj}): {at_a} of {pixels} pixels at A's height, split B-C: {bc}"
                );
            }
        }
        scene.finish();
    }
}
