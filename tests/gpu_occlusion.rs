//! Occlusion culling on a real Vulkan device: frames drawn with it equal
//! frames drawn without it, pixel for pixel, along a flythrough with a
//! camera cut; a patch behind a ridge is culled and one peeking over it is
//! not. Validation (synchronization included) on; any message fails.

mod common;

use common::gpu::*;
use common::*;
use glam::DVec2;
use vkterrain::bench::cameras::flythrough;
use vkterrain::bench::error::differing_pixels;
use vkterrain::render::occlusion::{pyramid_levels, IDLE_AFTER_NOTHING_HIDDEN, WORTH_CULLING};
use vkterrain::render::{HeadlessFrame, LodMetric, RenderPath, RenderSettings};
use vkterrain::terrain::camera::Camera;
use vkterrain::terrain::{Heightmap, Terrain, TerrainInfo};

fn settings(path: RenderPath, occlusion: bool) -> RenderSettings {
    RenderSettings {
        path,
        lod_metric: LodMetric::Error(1.0),
        occlusion,
        ..RenderSettings::default()
    }
}

/// Draws `camera` unculled until the error LOD's counts of a still view
/// (`render::seen`: four frames, each read a frame or two late) are all
/// taken in, so that the frames after it have one plan, and two of them
/// differ only by what culling does.
fn settle_counts(scene: &mut GpuScene, camera: &Camera, settings: &RenderSettings) {
    let plain = RenderSettings {
        occlusion: false,
        ..*settings
    };
    for _ in 0..8 {
        scene.render(camera, &plain);
    }
}

fn occluded(frame: &HeadlessFrame) -> u32 {
    frame
        .measurements
        .occlusion
        .expect("the frame was drawn with occlusion culling")
        .patches_occluded
}

/// Along 12 frames of the DEM's flythrough, cut in the middle to the far
/// side of the loop, each path's frame with occlusion culling equals the
/// frame without, exactly; culling does hide patches on the way.
fn flythrough_matches(samples: u32, frames: usize) {
    if skip_gpu() {
        return;
    }
    let terrain = dem_terrain(16, DVec2::ZERO);
    let loop_frames = 96;
    let path_cameras = flythrough(terrain.info(), loop_frames);
    let half = frames / 2;
    // Consecutive frames, then a cut half the loop away.
    let cameras: Vec<_> = (0..half)
        .chain(loop_frames / 2..loop_frames / 2 + frames - half)
        .map(|i| path_cameras[i])
        .collect();
    let mut scene = GpuScene::with_samples(terrain, 320, 180, samples);
    for path in [RenderPath::Tess, RenderPath::Geomip] {
        let mut hidden = 0;
        let every_frame = RenderSettings {
            occlusion_every_frame: true,
            ..settings(path, true)
        };
        for (i, camera) in cameras.iter().enumerate() {
            let off = scene.render(camera, &settings(path, false));
            let on = scene.render(camera, &every_frame);
            assert!(off.measurements.occlusion.is_none());
            hidden += occluded(&on);
            assert_images_match(
                &format!("occlusion-{path:?}-{samples}x-frame{i}"),
                &on.rgba_image(),
                &off.rgba_image(),
                0,
                0.0,
            );
        }
        assert!(hidden > 0, "{path:?}: no patch was ever culled");
    }
    scene.finish();
}

/// The tess path's batches drawn in one indirect call (multiDrawIndirect)
/// and one call each give the same frames, culled and unculled, with the
/// error LOD and the distance LOD, along a flythrough.
#[test]
fn batches_drawn_in_one_call_match_batches_drawn_one_by_one() {
    if skip_gpu() {
        return;
    }
    let terrain = || dem_terrain(16, DVec2::ZERO);
    let cameras = flythrough(terrain().info(), 96);
    let mut at_once = GpuScene::new(terrain(), 320, 180, false);
    assert!(
        at_once.gpu().device.caps.lists_geomip_draws(),
        "this check needs a device with multiDrawIndirect and drawIndirectFirstInstance"
    );
    let mut one_by_one = GpuScene::without(
        vkterrain::gpu::DisabledFeatures {
            multi_draw_indirect: true,
            ..Default::default()
        },
        terrain(),
        (320, 180),
    );
    assert!(!one_by_one.gpu().device.caps.multi_draw_indirect);
    assert!(!one_by_one.gpu().device.caps.lists_geomip_draws());
    let mut culled = 0;
    // The tess path's batches and full-resolution patches, and the geomip
    // path's patches (listed, each reading its constants by its first
    // instance, against pushed one by one).
    for (i, camera) in cameras.iter().step_by(12).enumerate() {
        for (path, lod_metric) in [
            (RenderPath::Tess, LodMetric::Error(1.0)),
            (RenderPath::Tess, LodMetric::Distance),
            (RenderPath::Geomip, LodMetric::Error(1.0)),
            (RenderPath::Geomip, LodMetric::Distance),
        ] {
            for occlusion_every_frame in [false, true] {
                let settings = RenderSettings {
                    lod_metric,
                    occlusion: occlusion_every_frame,
                    occlusion_every_frame,
                    ..settings(path, false)
                };
                let a = at_once.render(camera, &settings);
                let b = one_by_one.render(camera, &settings);
                culled += u32::from(a.measurements.occlusion.is_some());
                // The same vertices, tessellation and primitives reach the
                // clipper, and the same pixels are shaded. What the clipper
                // outputs is left out: Vulkan lets a device count a
                // triangle wholly outside the view volume or not, and
                // lavapipe counts some of them for draws that push their
                // constants and none for listed ones.
                let counted = |f: &vkterrain::render::HeadlessFrame| {
                    f.measurements.statistics.map(|s| {
                        (
                            s.vertex_invocations,
                            s.tcs_patches,
                            s.tes_invocations,
                            s.clipping_invocations,
                            s.fragment_invocations,
                        )
                    })
                };
                assert_eq!(
                    counted(&a),
                    counted(&b),
                    "frame {i}, {path:?}, {lod_metric:?}"
                );
                assert_images_match(
                    &format!("batches-{path:?}-{lod_metric:?}-{occlusion_every_frame}-frame{i}"),
                    &a.rgba_image(),
                    &b.rgba_image(),
                    0,
                    0.0,
                );
            }
        }
    }
    assert_eq!(
        culled, 32,
        "every frame asked to cull every frame was culled"
    );
    at_once.finish();
    one_by_one.finish();
}

#[test]
fn occlusion_culling_changes_no_pixel_along_a_flythrough_with_a_cut() {
    flythrough_matches(1, 12);
}

#[test]
fn occlusion_culling_changes_no_pixel_when_multisampled() {
    flythrough_matches(4, 4);
}

/// A flat 129x129 plain (1 m spacing) in 8-cell patches, with heights
/// `height(row, column)`.
fn plain(height: impl Fn(usize, usize) -> f32 + Sync) -> Terrain {
    let map = Heightmap::from_fn(129, 129, height).expect("valid size");
    let info = TerrainInfo::new(map, DVec2::ONE, 8, DVec2::ZERO).expect("valid terrain");
    Terrain::new(info, 0.0).expect("valid margin")
}

/// The plain with a 30 m wall across it at rows 40 to 44, and a pillar of
/// `pillar` m on rows 100 to 103, columns 60 to 63, behind the wall as the
/// camera sees it.
fn ridge_terrain(pillar: f32) -> Terrain {
    plain(|r, c| {
        if (40..=44).contains(&r) {
            30.0
        } else if (100..=103).contains(&r) && (60..=63).contains(&c) {
            pillar
        } else {
            0.0
        }
    })
}

/// The ridge scene's plain with its wall cut to columns `cols`, and no
/// pillar.
fn wall_terrain(cols: std::ops::RangeInclusive<usize>) -> Terrain {
    plain(|r, c| {
        if (40..=44).contains(&r) && cols.contains(&c) {
            30.0
        } else {
            0.0
        }
    })
}

/// Culling goes on where it hides at least `WORTH_CULLING` of the patches
/// in view, and sits out after a frame that hid fewer, though it hid
/// some: a wall across the whole plain hides most of what lies behind it,
/// a short stretch of it a narrow wedge. Without timestamps, the share
/// alone decides (with them, the frame after two culled ones is drawn
/// unculled to be timed: `culling_is_timed_unculled_after_two_culled_frames`).
#[test]
fn culling_sits_out_where_it_hides_too_little_to_pay() {
    if skip_gpu() {
        return;
    }
    let camera = camera([-2.5, 5.0, 54.0], [-2.5, 20.0, -38.0], 50.0);
    let every_frame = RenderSettings {
        occlusion_every_frame: true,
        ..settings(RenderPath::Tess, true)
    };
    for (cols, worth) in [(0..=128, true), (60..=67, false)] {
        let mut scene = GpuScene::without_timestamps(wall_terrain(cols.clone()), 256, 192);
        scene.render(&camera, &every_frame);
        let culled = scene.render(&camera, &every_frame);
        let found = culled
            .measurements
            .occlusion
            .expect("culled every frame")
            .found;
        assert!(found.hidden > 0, "wall {cols:?}: {found:?}");
        assert!(found.hidden < found.in_view, "wall {cols:?}: {found:?}");
        let share = found.hidden as f32 / found.in_view as f32;
        assert_eq!(share >= WORTH_CULLING, worth, "wall {cols:?}: {found:?}");
        assert_eq!(found.worth_culling(), worth, "wall {cols:?}: {found:?}");
        // The next frame knows what the last one found.
        let next = scene.render(&camera, &settings(RenderPath::Tess, true));
        assert_eq!(
            next.measurements.occlusion.is_some(),
            worth,
            "wall {cols:?}: {found:?}"
        );
        scene.finish();
    }
}

/// With timestamps, culling is also judged by its time: after two culled
/// frames in a row, one frame that asks for culling is drawn without it,
/// and timed (`CullingTurns`); what follows depends on the two times. The
/// image is the same.
#[test]
fn culling_is_timed_unculled_after_two_culled_frames() {
    if skip_gpu() {
        return;
    }
    let camera = camera([-2.5, 5.0, 54.0], [-2.5, 20.0, -38.0], 50.0);
    let mut scene = GpuScene::new(wall_terrain(0..=128), 256, 192, false);
    let on = settings(RenderPath::Tess, true);
    settle_counts(&mut scene, &camera, &on);
    let frames: Vec<HeadlessFrame> = (0..3).map(|_| scene.render(&camera, &on)).collect();
    let culled: Vec<bool> = frames
        .iter()
        .map(|f| f.measurements.occlusion.is_some())
        .collect();
    assert_eq!(culled, vec![true, true, false]);
    assert!(frames.iter().all(|f| f.measurements.gpu_ms.is_some()));
    let found = frames[1].measurements.occlusion.expect("culled").found;
    assert!(found.worth_culling(), "{found:?}");
    assert_images_match(
        "occlusion-timed",
        &frames[2].rgba_image(),
        &frames[1].rgba_image(),
        0,
        0.0,
    );
    scene.finish();
}

/// Renders the ridge scene from low on the near side (row 10), looking
/// across the wall at the pillar; returns the patches culled once the
/// visibility has settled, and the frame.
fn ridge_view(pillar: f32) -> (u32, HeadlessFrame, HeadlessFrame) {
    let mut scene = GpuScene::new(ridge_terrain(pillar), 256, 192, false);
    // Row r lies at z = 64 - r, column c at x = c - 64.
    let camera = camera([-2.5, 5.0, 54.0], [-2.5, 20.0, -38.0], 50.0);
    let settings = settings(RenderPath::Tess, true);
    settle_counts(&mut scene, &camera, &settings);
    // The first frame draws every patch first; the second has last
    // frame's visibility to start from.
    scene.render(&camera, &settings);
    let on = scene.render(&camera, &settings);
    let off = scene.render(
        &camera,
        &RenderSettings {
            occlusion: false,
            ..settings
        },
    );
    // What was culled, drawn over the frame.
    let shown = scene.render(
        &camera,
        &RenderSettings {
            show_culled: true,
            ..settings
        },
    );
    let magenta = |f: &HeadlessFrame| {
        f.readback
            .rgba
            .chunks_exact(4)
            .filter(|p| p[0] > 240 && p[1] < 140 && p[2] > 160)
            .count()
    };
    assert_eq!(magenta(&on), 0, "magenta without show_culled");
    assert!(
        magenta(&shown) > 100,
        "the culled patches cover only {} pixels",
        magenta(&shown)
    );
    scene.finish();
    (occluded(&on), on, off)
}

#[test]
fn a_patch_behind_a_ridge_is_culled_and_one_peeking_over_it_is_not() {
    if skip_gpu() {
        return;
    }
    // Seen from 5 m up at row 10, the wall's top (30 m at row 44) hides
    // everything at row 100 below 5 + 25 * 90 / 34 = 71 m.
    let (without, _, _) = ridge_view(0.0);
    let (with_hidden, hidden_on, hidden_off) = ridge_view(20.0);
    let (_, peeking_on, peeking_off) = ridge_view(120.0);
    assert!(
        without >= 20,
        "only {without} patches culled behind the wall"
    );
    // A 20 m pillar is culled with its patch, as the flat ground there is.
    assert_eq!(with_hidden, without);
    assert_images_match(
        "ridge-hidden",
        &hidden_on.rgba_image(),
        &hidden_off.rgba_image(),
        0,
        0.0,
    );
    // A 120 m one shows over the wall, in the same pixels with occlusion
    // culling as without.
    assert_images_match(
        "ridge-peeking",
        &peeking_on.rgba_image(),
        &peeking_off.rgba_image(),
        0,
        0.0,
    );
    let pillar_pixels = differing_pixels(&peeking_on.readback.rgba, &hidden_on.readback.rgba);
    assert!(
        pillar_pixels > 20,
        "the pillar covers only {pillar_pixels} pixels"
    );
}

/// The pyramid reduced on the CPU from `depth` (`width` x `height`,
/// row-major): every texel the farthest (smallest, reversed Z) depth of
/// the 2x2 under it, the last row or column read again past an odd edge.
fn cpu_pyramid(depth: &[f32], width: u32, height: u32) -> Vec<f32> {
    let mut pyramid = Vec::new();
    let (mut below, mut w, mut h) = (depth.to_vec(), width, height);
    for [lw, lh] in pyramid_levels(width, height) {
        let at = |x: u32, y: u32| below[(y.min(h - 1) * w + x.min(w - 1)) as usize];
        let level: Vec<f32> = (0..lh)
            .flat_map(|y| (0..lw).map(move |x| (x, y)))
            .map(|(x, y)| {
                let (x, y) = (2 * x, 2 * y);
                at(x, y)
                    .min(at(x + 1, y))
                    .min(at(x, y + 1))
                    .min(at(x + 1, y + 1))
            })
            .collect();
        pyramid.extend_from_slice(&level);
        (below, w, h) = (level, lw, lh);
    }
    pyramid
}

/// The pyramid the occlusion test reads equals the first pass's depth
/// reduced on the CPU, texel for texel, at a target odd in both sizes (so
/// every level has an odd edge somewhere, and the levels take two
/// dispatches). A first frame draws every patch in its first pass, so the
/// depth read back at the end is the depth the pyramid was built from.
#[test]
fn the_depth_pyramid_is_the_first_pass_depth_reduced_exactly() {
    if skip_gpu() {
        return;
    }
    let (width, height) = (333, 191);
    let terrain = dem_terrain(16, DVec2::ZERO);
    let camera = flythrough(terrain.info(), 96)[0];
    let mut scene = GpuScene::new(terrain, width, height, false);
    let before = scene.renderer().occlusion_pyramid(0);
    assert!(
        matches!(before, Ok(None)),
        "a pyramid before any culled frame"
    );
    let frame = scene.render(&camera, &settings(RenderPath::Tess, true));
    let gpu = scene
        .renderer()
        .occlusion_pyramid(0)
        .expect("reading the pyramid back")
        .expect("the frame was culled");
    let depth = &frame.readback.depth;
    let sky = depth.iter().filter(|&&d| d == 0.0).count();
    assert!(
        sky > 0 && sky < depth.len() / 2,
        "{sky} of {} pixels are sky: the view should show both",
        depth.len()
    );
    let cpu = cpu_pyramid(depth, width, height);
    assert_eq!(pyramid_levels(width, height).len(), 9);
    assert_eq!(gpu.len(), cpu.len(), "pyramid texels");
    let differing: Vec<_> = gpu
        .iter()
        .zip(&cpu)
        .enumerate()
        .filter(|(_, (g, c))| g != c)
        .take(5)
        .collect();
    assert!(
        differing.is_empty(),
        "texels (index, (gpu, cpu)): {differing:?}"
    );
    scene.finish();
}

/// A target made after another is destroyed is told apart from it, though
/// the driver may give its depth view the old one's handle: the occlusion
/// pass keys its descriptors on the image's serial number.
#[test]
fn a_new_target_is_never_taken_for_a_destroyed_one() {
    if skip_gpu() {
        return;
    }
    let gpu = open_gpu(None);
    let mut seen = Vec::new();
    for samples in [1, 1, 4, 4, 1] {
        let target =
            vkterrain::gpu::target::OffscreenTarget::new(&gpu.device, 64, 48, samples).unwrap();
        let id = target.views().depth_identity();
        assert!(
            !seen.contains(&id),
            "depth image {id} seen before: {seen:?}"
        );
        seen.push(id);
    }
    let report = gpu.shutdown();
    assert_eq!(report.count, 0, "{:?}", report.messages);
}

/// Culling sits out the frames after one that found nothing hidden, then
/// tries again, or at once after a cut (the eye placed more than a
/// patch's width from where it stood);
/// where it finds hidden patches it runs every frame. Images are the same
/// either way.
#[test]
fn culling_sits_out_after_a_frame_that_hid_nothing() {
    if skip_gpu() {
        return;
    }
    // From high above the DEM's centre, looking straight down: no patch
    // hides another.
    let terrain = dem_terrain(16, DVec2::ZERO);
    let mut scene = GpuScene::new(terrain, 128, 96, false);
    let above = camera([0.0, 60000.0, 1.0], [0.0, 0.0, 0.0], 40.0);
    let runs: Vec<Option<u32>> = (0..2 + IDLE_AFTER_NOTHING_HIDDEN as usize + 1)
        .map(|_| {
            let frame = scene.render(&above, &settings(RenderPath::Tess, true));
            frame.measurements.occlusion.map(|o| o.patches_occluded)
        })
        .collect();
    // The first frame culls and finds nothing hidden; the idle frames
    // follow (one frame in flight: each frame knows the last one's
    // result), then a try.
    let idle = IDLE_AFTER_NOTHING_HIDDEN as usize;
    assert_eq!(runs[0], Some(0), "{runs:?}");
    assert!(runs[1..=idle].iter().all(Option::is_none), "{runs:?}");
    assert_eq!(runs[idle + 1], Some(0), "{runs:?}");
    let off = scene.render(&above, &settings(RenderPath::Tess, false));
    let sat_out = scene.render(&above, &settings(RenderPath::Tess, true));
    assert!(sat_out.measurements.occlusion.is_none());
    assert_images_match(
        "occlusion-idle",
        &sat_out.rgba_image(),
        &off.rgba_image(),
        0,
        0.0,
    );
    // An eye placed more than a patch's width (16 cells, 1.5 km here)
    // from a still one ends the idle frames: a cut is culled at once.
    let moved = camera([3000.0, 60000.0, 1.0], [3000.0, 0.0, 0.0], 40.0);
    let after_cut = scene.render(&moved, &settings(RenderPath::Tess, true));
    assert_eq!(
        after_cut.measurements.occlusion.map(|o| o.patches_occluded),
        Some(0)
    );
    scene.finish();

    // Behind the ridge, patches are hidden: every frame after the first
    // culls.
    let (culled, _, _) = ridge_view(0.0);
    assert!(culled > 0);
}
