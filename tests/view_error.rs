//! The view's error table: the viewshed it hides samples with, and the
//! levels it gives patches against the error table's bounds.

mod common;

use common::gpu::camera;
use common::*;
use glam::{DVec2, Vec3};
use vkterrain::lod::view_measure::{view_error_table, Diagonal, ViewErrors, ViewLod};
use vkterrain::lod::viewshed::Viewshed;
use vkterrain::render::FrameView;
use vkterrain::terrain::camera::{look_at, perspective, Frustum};
use vkterrain::terrain::{ErrorTable, Heightmap, Terrain, TerrainInfo};

/// A terrain of `map` with unit spacing and 16-cell patches, centred on 0.
fn terrain(map: Heightmap) -> Terrain {
    let info = TerrainInfo::new(map, DVec2::ONE, 16, DVec2::ZERO).expect("valid terrain");
    Terrain::new(info, 0.0).expect("valid margin")
}

/// The view table of `terrain` from `eye` looking at `target` (world
/// coordinates), 1280x720, every patch wanted.
fn view_table(terrain: &Terrain, eye: [f64; 3], target: [f64; 3], tau: f32) -> ViewErrors {
    view_table_for(terrain, eye, target, tau, Diagonal::Either)
}

fn view_table_for(
    terrain: &Terrain,
    eye: [f64; 3],
    target: [f64; 3],
    tau: f32,
    diagonal: Diagonal,
) -> ViewErrors {
    let view = FrameView::new(terrain, &camera(eye, target, 55.0), 1280, 720);
    let lod = ViewLod {
        eye_local: view.eye_local,
        pixels_per_radian: view.pixels_per_radian,
        viewport_pixels: 1280.0 * 720.0,
        frustum: view.frustum,
        pixel_error: tau,
    };
    let wanted = vec![true; terrain.grid().patch_count()];
    let (bound, _) = terrain.error_tables();
    let heightmap = terrain.info().heightmap().expect("held whole");
    view_error_table(terrain, heightmap, bound, diagonal, &lod, &wanted)
}

/// 65 x 65 samples, flat at 0 but for a wall `height` high along row 20.
fn wall_map(height: f32) -> Heightmap {
    Heightmap::from_fn(65, 65, |r, _| if r == 20 { height } else { 0.0 }).expect("valid size")
}

/// Local position of sample (row, col) of a 65 x 65 unit-spaced map.
fn local(row: usize, col: usize, y: f32) -> Vec3 {
    Vec3::new(col as f32 - 32.0, y, 32.0 - row as f32)
}

/// The viewshed of a 65 x 65 unit-spaced `map` (see `local`) from `eye`,
/// with `margin` and an optional frustum, swept to the map's edge.
fn viewshed(map: &Heightmap, eye: Vec3, margin: f64, frustum: Option<&Frustum>) -> Viewshed {
    let mut shed = Viewshed::default();
    shed.sweep(
        terrain(map.clone()).info(),
        map,
        eye,
        margin,
        usize::MAX,
        frustum,
    );
    shed
}

#[test]
fn a_wall_hides_the_ground_behind_it_and_not_in_front() {
    let map = wall_map(10.0);
    // Eye 2 above the ground at row 5, in the middle column.
    let shed = viewshed(&map, local(5, 32, 2.0), 0.0, None);
    for c in 0..65 {
        assert!(!shed.hidden(10, c), "in front of the wall, column {c}");
        assert!(!shed.hidden(20, c), "the wall itself, column {c}");
    }
    // Straight behind the wall, the ground is hidden all the way back.
    for r in 21..65 {
        assert!(shed.hidden(r, 32), "behind the wall, row {r}");
    }
    // A wall no higher than the eye hides only what its line of sight
    // crosses below it: the ground just behind it.
    let low = wall_map(1.0);
    let shed = viewshed(&low, local(5, 32, 2.0), 0.0, None);
    assert!(shed.hidden(21, 32));
    assert!(
        !shed.hidden(64, 32),
        "far ground rises above the line of sight"
    );
}

#[test]
fn the_top_of_a_wall_that_hides_ground_is_a_crest_and_open_ground_is_not() {
    let map = wall_map(10.0);
    let shed = viewshed(&map, local(5, 32, 2.0), 0.0, None);
    // The wall's samples in front of the eye hide the ground behind them.
    for c in 28..=36 {
        assert!(shed.crest(20, c).is_some(), "the wall at column {c}");
    }
    // Ground in front of the wall, and the hidden ground behind it, are not.
    for r in [6, 10, 19, 21, 40] {
        assert!(shed.crest(r, 32).is_none(), "row {r}");
    }
    // With no wall nothing is hidden, so nothing is a crest.
    let flat = wall_map(0.0);
    let shed = viewshed(&flat, local(5, 32, 2.0), 0.0, None);
    assert!((0..65).all(|r| (0..65).all(|c| shed.crest(r, c).is_none())));
}

#[test]
fn behind_a_crest_ground_within_the_margin_leaves_the_silhouette_on_the_crest() {
    // The wall's top (row 20, 8 above the eye 15 away: 0.533) sets the
    // horizon; row 21 behind it (7.5 above the eye 16 away: 0.469) lies
    // below that horizon but within a 0.1 margin, so it counts as seen;
    // the ground from row 22 on is hidden. The outline is the wall's top,
    // which the hidden run is charged to, not the sample tucked behind it.
    let map = Heightmap::from_fn(65, 65, |r, _| match r {
        20 => 10.0,
        21 => 9.5,
        _ => 0.0,
    })
    .expect("valid size");
    let shed = viewshed(&map, local(5, 32, 2.0), 0.1, None);
    assert!(!shed.hidden(21, 32) && shed.hidden(22, 32));
    assert!(shed.crest(20, 32).is_some(), "the wall's top is the crest");
    assert!(
        shed.crest(21, 32).is_none(),
        "below its horizon, no outline"
    );
}

#[test]
fn a_lone_peak_hides_only_its_own_line_and_the_margin_uncovers_the_horizon() {
    let spike = Heightmap::from_fn(65, 65, |r, c| if (r, c) == (20, 32) { 50.0 } else { 0.0 })
        .expect("valid size");
    let shed = viewshed(&spike, local(5, 32, 2.0), 0.0, None);
    // Only samples on the very line of sight through the peak are hidden
    // (column 32 behind it); one sample is never a wall on both sides of
    // any other ray.
    for i in 0..65 * 65 {
        let (r, c) = (i / 65, i % 65);
        assert!(
            !shed.hidden(r, c) || (c == 32 && r > 20),
            "({r}, {c}) hidden"
        );
    }
    // Behind a wall, ground within the margin of its horizon counts as
    // seen: the wall's top at row 20 is 8 above the eye 15 away (0.53);
    // the ground at row 40 is 2 below the eye 35 away (-0.057).
    let map = wall_map(10.0);
    let shed = viewshed(&map, local(5, 32, 2.0), 0.5, None);
    assert!(
        shed.hidden(40, 32),
        "0.59 below its horizon, past a 0.5 margin"
    );
    let shed = viewshed(&map, local(5, 32, 2.0), 0.7, None);
    assert!(!shed.hidden(40, 32), "within a 0.7 margin");
}

#[test]
fn an_eye_outside_the_map_sweeps_from_beyond_its_edge() {
    let map = wall_map(10.0);
    // 40 beyond the near edge (row 0 is at local z = 32), 3 above ground.
    let shed = viewshed(&map, Vec3::new(0.0, 3.0, 72.0), 0.0, None);
    assert!(!shed.hidden(0, 32) && !shed.hidden(19, 32));
    assert!(shed.hidden(30, 32), "behind the wall from outside too");
    // The near edge is the outline of the map's edge; nothing else is.
    assert!((0..65).all(|c| shed.edge(0, c)), "row 0, towards the eye");
    assert!((1..65).all(|r| (0..65).all(|c| !shed.edge(r, c))));
    // Seen from over the map, no sample is.
    let shed = viewshed(&map, local(5, 32, 2.0), 0.0, None);
    assert!((0..65).all(|r| (0..65).all(|c| !shed.edge(r, c))));
}

#[test]
fn exposures_add_up_to_the_ground_seen_and_nothing_hidden() {
    // Flat ground seen from 2 above its centre: the exposures add up to the
    // square's solid angle, 4 asin(a^2 / (a^2 + h^2)) for half side a at
    // depth h.
    let flat = wall_map(0.0);
    let shed = viewshed(&flat, local(32, 32, 2.0), 0.0, None);
    let total: f64 = (0..65)
        .flat_map(|r| (0..65).map(move |c| (r, c)))
        .map(|(r, c)| shed.exposure(r, c).expect("swept"))
        .sum();
    let square = 4.0 * (32.0f64 * 32.0 / (32.0 * 32.0 + 4.0)).asin();
    assert!(
        (total - square).abs() < 0.02 * square,
        "{total} sr against {square}"
    );
    // Behind a wall, ground it hides adds nothing, and the wall's face adds
    // what rises above the ground in front of it.
    let map = wall_map(10.0);
    let shed = viewshed(&map, local(5, 32, 2.0), 0.0, None);
    assert!((21..65).all(|r| shed.exposure(r, 32) == Some(0.0)));
    let ground = shed.exposure(19, 32).expect("swept");
    assert!(shed.exposure(20, 32).expect("swept") > 10.0 * ground);
    // A frustum looking up above the horizon sees no ground at all.
    let view = perspective(0.5, 1.0, 0.1, 1000.0)
        * look_at(Vec3::ZERO, Vec3::new(0.0, 1.0, -1.0), Vec3::Y);
    let up = Frustum::from_view_proj(view);
    let shed = viewshed(&flat, local(32, 32, 2.0), 0.0, Some(&up));
    assert!((0..65).all(|r| (0..65).all(|c| shed.exposure(r, c) == Some(0.0))));
    // Looking level, it sees the ground from its lower plane, 0.25 below
    // the horizon, on: from 2 / tan(0.25) = 7.8 ahead.
    let level = perspective(0.5, 1.0, 0.1, 1000.0) * look_at(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y);
    let level = Frustum::from_view_proj(level);
    let shed = viewshed(&flat, local(32, 32, 2.0), 0.0, Some(&level));
    assert_eq!(shed.exposure(37, 32), Some(0.0), "5 ahead, below the view");
    assert!(shed.exposure(52, 32).expect("swept") > 0.0, "20 ahead");
}

#[test]
fn a_crest_knows_how_far_its_line_of_sight_falls_behind_it() {
    // A wall 1 high seen from 2 high, 15 rows in front of it: the line of
    // sight over it falls 1 in 15 and meets the ground (height 0) again 30
    // rows from the eye, 1 below the wall's top.
    let low = wall_map(1.0);
    let shed = viewshed(&low, local(5, 32, 2.0), 0.0, None);
    let crest = shed.crest(20, 32).expect("the wall's top is a crest");
    assert!((crest.fall - 1.0).abs() < 1e-6, "{crest:?}");
    // It rises above the ground in front of it by the sines of elevation
    // of -1/15 (its own) and -2/14 (the ground's in front).
    let sine = |e: f64| e / (1.0 + e * e).sqrt();
    assert!(
        (crest.rise - (sine(-1.0 / 15.0) - sine(-2.0 / 14.0))).abs() < 1e-3,
        "{crest:?}"
    );
    // Swept only to ring 20, past the wall but short of where the ground
    // shows again (ring 30), the crest follows its line of sight there.
    let mut short = Viewshed::default();
    short.sweep(
        terrain(low.clone()).info(),
        &low,
        local(5, 32, 2.0),
        0.0,
        20,
        None,
    );
    let crest = short.crest(20, 32).expect("the wall's top is a crest");
    assert!((crest.fall - 1.0).abs() < 1e-6, "{crest:?}");
    // Over a wall above the eye the line of sight rises into the sky.
    let high = wall_map(10.0);
    let shed = viewshed(&high, local(5, 32, 2.0), 0.0, None);
    assert_eq!(shed.crest(20, 32).map(|c| c.fall), Some(f64::INFINITY));
}

/// Rolling hills on a slope rising to the far rows, 0 to 23 high.
fn rough() -> Terrain {
    terrain(
        Heightmap::from_fn(65, 65, |r, c| {
            let (r, c) = (r as f32, c as f32);
            10.0 + 10.0 * (c / 5.0).sin() * (r / 7.0).cos() + 0.05 * r
        })
        .expect("valid size"),
    )
}

/// Every entry finite and not negative, and a patch's entries never rising
/// with the level. An entry may pass the bound's: the bound projects the
/// vertical error face-on, and a ray running on down ground that falls
/// away from the eye shows more.
fn assert_well_formed(view: &ViewErrors) {
    for p in 0..view.table.as_slice().len() / ErrorTable::LEVELS {
        let seen = view.table.patch(p);
        for k in 0..ErrorTable::LEVELS {
            assert!(seen[k] >= 0.0 && seen[k].is_finite(), "patch {p} level {k}");
            if k + 1 < ErrorTable::LEVELS {
                assert!(seen[k] >= seen[k + 1], "patch {p}: rises at level {k}");
            }
        }
    }
}

#[test]
fn never_rising_with_the_level_and_within_tau_as_the_choice_expects() {
    let t = rough();
    for (eye, target) in [
        ([-30.0, 60.0, 40.0], [0.0, 30.0, 0.0]),
        ([-31.0, 25.0, 31.0], [31.0, 25.0, -31.0]),
        ([0.0, 200.0, 0.5], [0.0, 0.0, 0.0]),
        ([100.0, 40.0, 100.0], [0.0, 20.0, 0.0]),
    ] {
        for tau in [0.5, 1.0, 4.0] {
            let view = view_table(&t, eye, target, tau);
            assert_well_formed(&view);
            // The levels the bound accepts are measured too, so the choice
            // keeps what it models within tau at its 99th percentile.
            assert!(
                view.predicted_p99_px <= tau,
                "from {eye:?} at {tau} px: the choice expects p99 {}",
                view.predicted_p99_px
            );
        }
    }
}

#[test]
fn grazing_views_relax_levels_that_views_from_above_do_not() {
    let t = rough();
    let (bound, _) = t.error_tables();
    let sum = |table: &ErrorTable| table.as_slice().iter().map(|&e| f64::from(e)).sum::<f64>();
    // Low over one corner, looking level across the slope rising away.
    // (0.61 of the bound's sum, counting the crests' moved silhouettes.)
    let grazing = view_table(&t, [-31.0, 25.0, 31.0], [31.0, 25.0, -31.0], 1.0);
    assert!(
        sum(&grazing.table) < 0.7 * sum(bound),
        "grazing: {} of the bound's {}",
        sum(&grazing.table),
        sum(bound)
    );
}

#[test]
fn a_patch_behind_a_wall_has_no_error_and_one_in_front_keeps_its_own() {
    // Rough ground with a wall across row 20, seen from over the ground but
    // below the wall's top, in front of it.
    let noise = noise_map(65, 65, 3);
    let map = Heightmap::from_fn(65, 65, |r, c| if r == 20 { 300.0 } else { noise.get(r, c) })
        .expect("valid size");
    assert!(noise.min_max().1 < 150.0);
    let t = terrain(map);
    let view = view_table(&t, [0.0, 150.0, 31.0], [0.0, 150.0, -31.0], 1.0);
    let grid = t.grid();
    // Patch rows cover sample rows 0-16, 16-32, 32-48, 48-64: rows 2 and 3
    // lie wholly behind the wall.
    for p in 0..grid.patch_count() {
        let id = grid.patch_id(p);
        if id.row >= 2 {
            assert!(
                view.table.patch(p).iter().all(|&e| e == 0.0),
                "patch {id:?} is hidden: {:?}",
                view.table.patch(p)
            );
        }
    }
    let (bound, _) = t.error_tables();
    // The patch holding the wall straight ahead keeps an error at its
    // coarsest level.
    let front = grid.patch_index(vkterrain::terrain::PatchId { row: 1, col: 2 });
    assert!(
        view.table.patch(front)[0] > 0.0 && bound.patch(front)[0] > 0.0,
        "{:?} against {:?}",
        view.table.patch(front),
        bound.patch(front)
    );
}

#[test]
fn a_plane_has_no_error_from_anywhere() {
    let plane =
        Heightmap::from_fn(65, 65, |r, c| 0.3 * c as f32 - 0.2 * r as f32).expect("valid size");
    let t = terrain(plane);
    for eye in [[-31.0, 5.0, 31.0], [0.0, 100.0, 0.0], [50.0, 30.0, -50.0]] {
        let view = view_table(&t, eye, [0.0, 0.0, 0.0], 1.0);
        // Heights are f32, so the plane is flat to rounding only.
        assert!(view.table.as_slice().iter().all(|&e| e < 1e-5));
        assert!(view.predicted_p99_px < 1e-3, "{}", view.predicted_p99_px);
    }
}

#[test]
fn geomip_morph_limits_are_factors_for_the_level_each_patch_expects() {
    let t = rough();
    let eye = [-30.0, 60.0, 40.0];
    let target = [0.0, 30.0, 0.0];
    let tess = view_table(&t, eye, target, 1.0);
    assert!(
        tess.morph_limits.iter().all(Option::is_none),
        "the tessellator does not morph between levels"
    );
    let geomip = view_table_for(&t, eye, target, 1.0, Diagonal::Reference);
    assert_well_formed(&geomip);
    let limits: Vec<(usize, f32)> = geomip.morph_limits.iter().flatten().copied().collect();
    assert!(
        !limits.is_empty(),
        "some patch morphs towards a measured level"
    );
    let grid = t.grid();
    let scale = |p: usize| {
        let view = FrameView::new(&t, &camera(eye, target, 55.0), 1280, 720);
        let corners = t
            .patch_corners(grid.patch_id(p))
            .map(|c| c - view.eye_local);
        let [lo, hi] = t.y_bounds()[p];
        let d = vkterrain::lod::patch_box_distance(
            corners,
            [lo - view.eye_local.y, hi - view.eye_local.y],
        );
        view.pixels_per_radian / d
    };
    for (p, limit) in geomip.morph_limits.iter().enumerate() {
        let Some((k, m)) = *limit else { continue };
        assert!((0.0..=1.0).contains(&m), "patch {p}: factor {m}");
        // The level it expects is the coarsest within tau, and the next
        // coarser one is not.
        let levels = geomip.table.patch(p);
        assert!(
            k >= 1 && levels[k - 1] * scale(p) > 1.0,
            "patch {p} level {k}"
        );
        if k < ErrorTable::LEVELS {
            assert!(levels[k] * scale(p) <= 1.0 + 1e-4, "patch {p} level {k}");
        }
    }
    // Somewhere the blend would go over: not every factor is free.
    assert!(limits.iter().any(|&(_, m)| m < 1.0), "{limits:?}");
}

#[test]
fn the_far_remainders_are_measured_as_their_path_lays_them() {
    // 59 x 71 samples in 16-cell patches: the last column of patches is 10
    // cells wide and the last row 6 deep.
    let hills = |r: usize, c: usize| {
        let (r, c) = (r as f32, c as f32);
        10.0 + 10.0 * (c / 5.0).sin() * (r / 7.0).cos() + 0.05 * r
    };
    let t = terrain(Heightmap::from_fn(59, 71, hills).expect("valid size"));
    let grid = t.grid();
    let remainders: Vec<usize> = (0..grid.patch_count())
        .filter(|&p| {
            let rect = grid.sample_rect(grid.patch_id(p));
            rect.cells_x() != 16 || rect.cells_z() != 16
        })
        .collect();
    assert_eq!(remainders.len(), 4 + 5 - 1);
    // `view_table_for` measures against the tess path's bound.
    let (bound, _) = t.error_tables();
    for diagonal in [Diagonal::Either, Diagonal::Reference] {
        // Low over the near corner, looking across to the far remainders.
        let view = view_table_for(&t, [-29.0, 25.0, 35.0], [29.0, 20.0, -35.0], 1.0, diagonal);
        assert_well_formed(&view);
        let relaxed = remainders
            .iter()
            .filter(|&&p| {
                (0..ErrorTable::LEVELS).any(|k| view.table.patch(p)[k] < bound.patch(p)[k])
            })
            .count();
        assert!(
            relaxed >= remainders.len() / 2,
            "{diagonal:?}: {relaxed} of {} remainders relaxed",
            remainders.len()
        );
    }
    // A plane is drawn exactly at every level, vertices between samples
    // included.
    let plane = terrain(
        Heightmap::from_fn(59, 71, |r, c| 0.3 * c as f32 - 0.2 * r as f32).expect("valid size"),
    );
    for diagonal in [Diagonal::Either, Diagonal::Reference] {
        let view = view_table_for(&plane, [-29.0, 5.0, 35.0], [0.0, 0.0, 0.0], 1.0, diagonal);
        assert!(
            view.table.as_slice().iter().all(|&e| e < 1e-4),
            "{diagonal:?}"
        );
        assert!(view.predicted_p99_px < 1e-3, "{}", view.predicted_p99_px);
    }
}

#[test]
fn a_spike_just_off_the_side_of_the_view_is_measured_by_the_faces_it_shows() {
    // Flat ground with one spike, 30 high, beside the eye: the sample
    // itself lies just right of the view, but the faces falling from it
    // to its neighbours reach into it.
    let (row, col) = (34, 31);
    let map = Heightmap::from_fn(65, 65, |r, c| if (r, c) == (row, col) { 30.0 } else { 0.0 })
        .expect("valid size");
    let t = terrain(map);
    let (eye, target) = ([0.0, 3.0, 0.0], [-50.0, 1.0, -8.0]);
    let frame = FrameView::new(&t, &camera(eye, target, 55.0), 1280, 720);
    let sample = local(row, col, 30.0) - frame.eye_local;
    assert!(
        frame.frustum.planes[..2]
            .iter()
            .any(|p| p.truncate().dot(sample) + p.w < 0.0),
        "the spike's sample lies beside the view"
    );
    let view = view_table(&t, eye, target, 1.0);
    let grid = t.grid();
    let spike = grid.patch_index(vkterrain::terrain::PatchId {
        row: row / 16,
        col: col / 16,
    });
    // Drawn at its coarsest level the spike is gone: its faces, a large
    // part of the view this near, are off by up to its height.
    let coarsest = view.table.patch(spike)[0];
    assert!(coarsest > 1.0, "{:?}", view.table.patch(spike));
}

#[test]
fn the_maps_near_edge_seen_from_outside_moves_its_outline_with_the_level() {
    // Flat ground but for spikes 20 high on the odd columns of row 0, the
    // map's edge towards an eye 40 beyond it and 30 up: the spikes' faces
    // fall away from the eye, so what shows of them is the edge's outline
    // against the background below it. A level that drops every other
    // sample draws the spikes away and moves that outline by their height.
    let map = Heightmap::from_fn(65, 65, |r, c| if r == 0 && c % 2 == 1 { 20.0 } else { 0.0 })
        .expect("valid size");
    let t = terrain(map);
    let view = view_table(&t, [0.0, 30.0, 72.0], [0.0, 0.0, 0.0], 1.0);
    let grid = t.grid();
    let edge = grid.patch_index(vkterrain::terrain::PatchId { row: 0, col: 2 });
    let coarsest = view.table.patch(edge)[0];
    assert!(coarsest > 1.0, "{:?}", view.table.patch(edge));
    // The patches behind the edge, flat, have none.
    let inner = grid.patch_index(vkterrain::terrain::PatchId { row: 2, col: 2 });
    assert!(view.table.patch(inner).iter().all(|&e| e == 0.0));
}

#[test]
fn ground_beside_the_near_edge_seen_from_outside_rises_from_the_edge_not_along_it() {
    // Flat ground but for a spike 30 high on the near edge (row 0), seen
    // from 5 beyond that edge and 20 up. A line of sight to flat ground
    // far along the edge enters the map well past the spike: nothing in
    // front of it rises above the ground, which shows.
    let map = Heightmap::from_fn(65, 65, |r, c| if (r, c) == (0, 20) { 30.0 } else { 0.0 })
        .expect("valid size");
    let eye = Vec3::new(12.0 - 32.0, 20.0, 32.0 + 5.0);
    let shed = viewshed(&map, eye, 0.0, None);
    for (r, c) in [(1, 50), (2, 60), (3, 45)] {
        assert!(!shed.hidden(r, c), "({r}, {c})");
        let exposure = shed.exposure(r, c).expect("swept");
        assert!(exposure > 0.0, "({r}, {c}): {exposure}");
    }
    // The edge towards the eye is the map's outline all along.
    assert!((0..65).all(|c| shed.edge(0, c)));
}
