//! The GLSL formulas against their Rust mirrors, on a grid of inputs and
//! degenerate ones, through a compute shader that includes the same shared
//! GLSL file the terrain stages use.

mod common;

use common::gpu::*;
use common::*;
use glam::{DVec2, Vec2, Vec3};
use vkterrain::lod::plan::chosen_errors;
use vkterrain::lod::{
    box_distance, cdlod_tess_factor, edge_distance, edge_length_tess_factor, error_tess_factor,
    sphere_tess_factor, tess_factor,
};
use vkterrain::render::mirror::{run_mirror_check, MirrorCase};
use vkterrain::render::{FrameView, LodMetric, RenderSettings};
use vkterrain::terrain::camera::aabb_outside_frustum;
use vkterrain::terrain::{DistanceLod, DistanceMode};

#[test]
fn glsl_formulas_match_their_rust_mirrors() {
    if skip_gpu() {
        return;
    }
    let gpu = open_gpu(None);
    let terrain = dem_terrain(32, DVec2::ZERO);
    let map = terrain.info().whole().clone();
    let (lo, hi) = map.min_max();
    let view = FrameView::new(
        &terrain,
        &camera([-8000.0, 3000.0, -9000.0], [0.0, 500.0, 0.0], 55.0),
        640,
        480,
    );

    let lods = [
        DistanceLod {
            min_dist: 100.0,
            max_dist: 5000.0,
            min_exp: 0.0,
            max_exp: 6.0,
        },
        DistanceLod {
            min_dist: 700.0,
            max_dist: 700.0,
            min_exp: 1.0,
            max_exp: 5.0,
        },
        DistanceLod {
            min_dist: 0.0,
            max_dist: 0.0,
            min_exp: 3.0,
            max_exp: 3.0,
        },
    ];
    // Distances on a grid, exactly on the bounds, and degenerate positions.
    let mut positions: Vec<Vec3> = (0..200)
        .map(|k| Vec3::new(k as f32 * 37.0, -(k as f32) * 11.0, k as f32 * 5.0))
        .collect();
    positions.extend([
        Vec3::new(100.0, 0.0, 0.0),
        Vec3::new(5000.0, 0.0, 0.0),
        Vec3::new(700.0, 0.0, 0.0),
        Vec3::ZERO,
    ]);
    positions.extend([
        Vec3::splat(f32::INFINITY),
        Vec3::splat(f32::MAX),
        Vec3::new(-1e30, 0.0, 1e30),
    ]);
    // Boxes just inside and just outside each frustum plane.
    let mut boxes = Vec::new();
    for plane in view.frustum.planes {
        let n = plane.truncate();
        let on = -n * plane.w; // the plane's point nearest the origin
        let extents = Vec3::new(3.0, 2.0, 1.0);
        let r = extents.dot(n.abs());
        boxes.push((on - n * (r + 0.5), extents));
        boxes.push((on - n * (r - 0.5), extents));
    }
    // Sample coordinates: every corner and far edge, exact samples, random.
    let (w, d) = ((map.width() - 1) as f32, (map.depth() - 1) as f32);
    let mut grid = vec![
        Vec2::ZERO,
        Vec2::new(w, 0.0),
        Vec2::new(0.0, d),
        Vec2::new(w, d),
        Vec2::new(w, d / 2.0),
        Vec2::new(w / 2.0, d),
    ];
    grid.extend((0..300).map(|k| Vec2::new((k * 37 % 403) as f32, (k * 13 % 344) as f32)));
    grid.extend((0..300).map(|k| Vec2::new((k as f32 * 1.337) % w, (k as f32 * 0.9137) % d)));
    grid.extend([Vec2::new(-5.0, 3.0), Vec2::new(w + 10.0, d + 10.0)]);

    // Per-level errors: a real patch's, a flat one's, one with equal levels,
    // and a tiny one.
    let table = terrain.error_table();
    let patch = |p: usize| -> [f32; 7] { table.patch(p).try_into().unwrap() };
    let error_sets = [
        patch(40),
        patch(77),
        [0.0; 7],
        [5.0, 5.0, 5.0, 2.0, 0.5, 0.0, 0.0],
        [1e-3; 7],
    ];
    let count = positions.len().max(boxes.len()).max(grid.len());
    let mut cases: Vec<MirrorCase> = (0..count)
        .map(|k| MirrorCase {
            position: if k < boxes.len() {
                boxes[k].0
            } else {
                positions[k % positions.len()]
            },
            // Also a long edge, and a degenerate one (a point) for the
            // distance checks.
            extents: if k < boxes.len() {
                boxes[k].1
            } else {
                [Vec3::ONE, Vec3::new(400.0, 30.0, -250.0), Vec3::ZERO][k % 3]
            },
            grid: grid[k % grid.len()],
            errors: error_sets[k % error_sets.len()],
            // Whole and remainder patches, the smallest, and the largest.
            cells: [32, 23, 1, 2, 64, 18][k % 6],
            // No level chosen, each level chosen, and one past the table.
            chosen: (k % 9) as u8,
        })
        .collect();
    // An eye inside a patch's box: the levels a view accepts there are
    // told by zero errors, which no infinite scale may reject.
    let inside = [9.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert_eq!(
        error_tess_factor(&inside, 0.0, view.pixels_per_radian, 1.0, 32),
        4.0
    );
    cases.push(MirrorCase {
        position: Vec3::ZERO,
        extents: Vec3::ONE,
        grid: grid[0],
        errors: inside,
        cells: 32,
        chosen: 0,
    });

    // Distinct values of each peer's factor, so the agreement is not only
    // at the clamps.
    let mut peer_values: [std::collections::BTreeSet<u32>; 3] = Default::default();
    // Cases a chosen level made coarser than the bound alone would.
    let mut chosen_coarser = 0;
    for (lod, pixels) in lods.into_iter().zip([1.0f32, 0.25, 8.0]) {
        for mode in [DistanceMode::Smooth, DistanceMode::Debug] {
            let settings = RenderSettings {
                lod,
                lod_mode: mode,
                lod_metric: LodMetric::Error(pixels),
                ..RenderSettings::default()
            };
            let results = run_mirror_check(&gpu, &terrain, &view, &settings, &cases)
                .expect("mirror check runs");
            for (k, (case, got)) in cases.iter().zip(&results).enumerate() {
                // Factor: the position's factor (box cases too: any position serves).
                let want = tess_factor(case.position, &lod, mode);
                assert!(
                    (1.0..=64.0).contains(&got.tess_factor),
                    "case {k}: GPU factor {} out of range",
                    got.tess_factor
                );
                let finite = case.position.is_finite() && case.position.length().is_finite();
                if finite {
                    assert!(
                        (got.tess_factor - want).abs() <= 1e-5 * want,
                        "case {k} {:?} {mode:?} at {}: GLSL {} vs Rust {want}",
                        lod,
                        case.position,
                        got.tess_factor
                    );
                }
                let want = error_tess_factor(
                    &case.errors,
                    case.position.length(),
                    view.pixels_per_radian,
                    pixels,
                    case.cells,
                );
                assert!(
                    (1.0..=64.0).contains(&got.error_tess_factor),
                    "case {k}: error factor {}",
                    got.error_tess_factor
                );
                let chosen = error_tess_factor(
                    &chosen_errors(&case.errors, case.chosen),
                    case.position.length(),
                    view.pixels_per_radian,
                    pixels,
                    case.cells,
                );
                if finite {
                    // Whole factors: both sides pick the same level.
                    assert!(
                        got.error_tess_factor == want,
                        "case {k} at {} with {:?}, {pixels} px: GLSL {} vs Rust {want}",
                        case.position,
                        case.errors,
                        got.error_tess_factor
                    );
                    assert!(
                        got.chosen_tess_factor == chosen,
                        "case {k} at {} with {:?} chosen {}, {pixels} px: GLSL {} vs Rust {chosen}",
                        case.position,
                        case.errors,
                        case.chosen,
                        got.chosen_tess_factor
                    );
                    // The chosen level is the finest drawn, and none is
                    // drawn finer than the patch's own errors ask.
                    assert!(chosen <= want, "case {k}: {chosen} over {want}");
                    if case.chosen != 0 {
                        let level = f32::from(1u8 << (case.chosen - 1).min(6));
                        assert!(chosen <= level.max(1.0), "case {k}: {chosen} over {level}");
                    }
                    chosen_coarser += usize::from(chosen < want);
                }
                if finite && case.extents.is_finite() {
                    // The peers' factors, in [1, 64] and as in Rust.
                    let (a, b) = (case.position, case.position + case.extents);
                    let screen = view.screen();
                    let peers = [
                        (
                            "sphere",
                            got.sphere_tess_factor,
                            sphere_tess_factor(a, b, &screen, &settings.peer),
                        ),
                        (
                            "edge length",
                            got.edge_length_tess_factor,
                            edge_length_tess_factor(a, b, &screen, &settings.peer),
                        ),
                        (
                            "cdlod",
                            got.cdlod_tess_factor,
                            cdlod_tess_factor(a, &lod, &settings.peer),
                        ),
                    ];
                    for (i, &(_, got, _)) in peers.iter().enumerate() {
                        peer_values[i].insert(got.to_bits());
                    }
                    for (name, got, want) in peers {
                        assert!(
                            (got - want).abs() <= 1e-3 * want,
                            "case {k}: {name} at {a} - {b} with {lod:?}: GLSL {got} vs Rust {want}"
                        );
                    }
                    let (p, e) = (case.position, case.extents);
                    let want = box_distance(p - e, p + e);
                    assert!(
                        (got.box_distance - want).abs() <= 1e-5 * want.max(1.0),
                        "case {k}: box distance at {p} +- {e}: GLSL {} vs Rust {want}",
                        got.box_distance
                    );
                    let xz = Vec2::new(p.x, p.z);
                    let want = edge_distance(xz, xz + Vec2::new(e.x, e.z), p.y - e.y, p.y + e.y);
                    assert!(
                        (got.edge_distance - want).abs() <= 1e-5 * want.max(1.0),
                        "case {k}: edge distance at {p}, {e}: GLSL {} vs Rust {want}",
                        got.edge_distance
                    );
                }
                let outside =
                    aabb_outside_frustum(case.position, case.extents, &view.frustum.planes);
                assert_eq!(
                    got.outside_frustum, outside,
                    "case {k}: frustum test at {}",
                    case.position
                );
                let height = map.interpolate(f64::from(case.grid.x), f64::from(case.grid.y)) as f32;
                assert!(
                    (got.height - height).abs() <= 1e-6 * (hi - lo).max(hi.abs()),
                    "case {k}: height at {}: GLSL {} vs Rust {height}",
                    case.grid,
                    got.height
                );
                let patches = terrain.grid();
                let patch = patches.patch_at(f64::from(case.grid.x), f64::from(case.grid.y));
                assert_eq!(
                    got.patch as usize,
                    patches.patch_index(patch),
                    "case {k}: patch at {}",
                    case.grid
                );
                if case.grid.fract() == Vec2::ZERO
                    && case.grid.cmple(Vec2::new(w, d)).all()
                    && case.grid.cmpge(Vec2::ZERO).all()
                {
                    assert_eq!(got.height, height, "case {k}: a sample is exact");
                }
            }
        }
    }
    for (name, values) in ["sphere", "edge length", "cdlod"].iter().zip(&peer_values) {
        assert!(
            values.len() >= 20,
            "{name}: only {} distinct factors",
            values.len()
        );
    }
    assert!(
        chosen_coarser >= 20,
        "only {chosen_coarser} chosen cases coarser"
    );
    assert_eq!(gpu.device.memory_in_use(), 0);
    let report = gpu.shutdown();
    assert_eq!(report.count, 0, "{:#?}", report.messages);
}
