//! The CPU half of the geomip path: index lists, stitching, balancing,
//! levels and morph targets.

mod common;

use common::*;
use glam::{DVec2, DVec3, Vec3};
use vkterrain::lod::geomip::*;
use vkterrain::lod::geomip_choice::ChosenPatches;
use vkterrain::lod::hierarchy::{Hierarchy, NodeId};
use vkterrain::lod::plan::{patches_in_view, PlanInputs, Planner, SightReading};
use vkterrain::lod::view::{LodView, Tau};
use vkterrain::render::FrameView;
use vkterrain::terrain::camera::Camera;
use vkterrain::terrain::{Heightmap, PatchId, Terrain, TerrainInfo};

/// (row, column) of a template vertex index.
fn rc(n: usize, v: u32) -> (i64, i64) {
    ((v as usize / (n + 1)) as i64, (v as usize % (n + 1)) as i64)
}

fn twice_area(n: usize, t: &[u32]) -> i64 {
    let [a, b, c] = [rc(n, t[0]), rc(n, t[1]), rc(n, t[2])];
    ((b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)).abs()
}

#[test]
fn every_variant_covers_the_patch_exactly() {
    for n in [2usize, 4, 8, 16, 32, 64] {
        let variants = IndexVariants::build(n);
        for level in 0..level_count(n) {
            let s = 1usize << level;
            for mask in 0..16u8 {
                let (first, count) = variants.range(level, mask);
                let list = &variants.indices[first as usize..(first + count) as usize];
                assert_eq!(list.len() % 3, 0);
                // Areas add up to the patch, and no triangle is degenerate.
                let total: i64 = list.chunks(3).map(|t| twice_area(n, t)).sum();
                assert_eq!(total, 2 * (n * n) as i64, "n={n} level={level} mask={mask}");
                assert!(list.chunks(3).all(|t| twice_area(n, t) > 0));
                for &v in list {
                    let (r, c) = rc(n, v);
                    assert!(
                        r % s as i64 == 0 && c % s as i64 == 0,
                        "vertex off the level's grid"
                    );
                    // A stitched side uses only the coarser level's vertices.
                    let coarse = 2 * s as i64;
                    let on = |bit: u8, yes: bool, along: i64| {
                        mask & bit != 0 && yes && along % coarse != 0
                    };
                    let n = n as i64;
                    assert!(
                        !(on(LEFT, c == 0, r) || on(RIGHT, c == n, r) || on(TOP, r == 0, c) || on(BOTTOM, r == n, c))
                            || level + 1 == level_count(n as usize),
                        "n={n} level={level} mask={mask}: vertex ({r},{c}) is missing on the coarser side"
                    );
                }
            }
        }
    }
}

#[test]
fn level_zero_without_stitching_is_the_brute_split() {
    let n = 4;
    let list = patch_indices(n, 0, 0);
    let mut expected = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let v = |r: usize, c: usize| (r * (n + 1) + c) as u32;
            expected.extend([
                v(i, j),
                v(i, j + 1),
                v(i + 1, j),
                v(i + 1, j + 1),
                v(i + 1, j),
                v(i, j + 1),
            ]);
        }
    }
    assert_eq!(list, expected);
}

#[test]
fn levels_by_distance_and_morph_factors() {
    assert_eq!(level_for_distance(0.0, 100.0, 6), 0);
    assert_eq!(level_for_distance(199.9, 100.0, 6), 0);
    assert_eq!(level_for_distance(200.0, 100.0, 6), 1);
    assert_eq!(level_for_distance(399.0, 100.0, 6), 1);
    assert_eq!(level_for_distance(1e9, 100.0, 6), 5);
    assert_eq!(level_for_distance(f32::NAN, 100.0, 6), 0);
    assert_eq!(level_for_distance(500.0, 0.0, 6), 5);
    // Morph reaches 1 exactly where the next level takes over.
    assert_eq!(morph_factor(400.0, 100.0, 1), 1.0);
    assert_eq!(morph_factor(280.0, 100.0, 1), 0.0);
    assert!((morph_factor(340.0, 100.0, 1) - 0.5).abs() < 1e-6);
}

#[test]
fn morph_targets_lie_on_the_coarser_triangles() {
    assert_eq!(morph_target(4, 4, 2), None);
    assert_eq!(morph_target(4, 6, 2), Some([(4, 4), (4, 8)]));
    assert_eq!(morph_target(6, 4, 2), Some([(4, 4), (8, 4)]));
    // The centre of a coarse cell: on its upper-right to lower-left diagonal.
    assert_eq!(morph_target(6, 6, 2), Some([(4, 8), (8, 4)]));
}

#[test]
fn balanced_levels_differ_by_at_most_one() {
    let info =
        TerrainInfo::new(noise_map(257, 257, 3), DVec2::splat(10.0), 16, DVec2::ZERO).unwrap();
    let terrain = Terrain::new(info, 0.0).unwrap();
    let grid = terrain.grid();
    for eye in [
        Vec3::new(0.0, 50.0, 0.0),
        Vec3::new(-1200.0, 10.0, 1200.0),
        Vec3::new(5000.0, 3000.0, 0.0),
    ] {
        let levels = select_levels_by_distance(&terrain, eye, 20.0).levels;
        let mut differing = 0;
        for p in 0..grid.patch_count() {
            let id = grid.patch_id(p);
            let (coarser, finer) = neighbour_masks(&levels, grid, id);
            assert_eq!(coarser & finer, 0);
            for (dr, dc) in [(0i64, 1i64), (1, 0)] {
                let (r, c) = (id.row as i64 + dr, id.col as i64 + dc);
                if r < grid.patch_rows() as i64 && c < grid.patch_cols() as i64 {
                    let q = grid.patch_index(vkterrain::terrain::PatchId {
                        row: r as usize,
                        col: c as usize,
                    });
                    let diff = (i16::from(levels[p]) - i16::from(levels[q])).abs();
                    assert!(
                        diff <= 1,
                        "neighbours {p} and {q}: {} vs {}",
                        levels[p],
                        levels[q]
                    );
                    differing += usize::from(diff == 1);
                }
            }
        }
        if eye.y < 100.0 {
            assert!(
                differing > 0,
                "a close eye gives neighbours at different levels"
            );
        }
    }
}

#[test]
fn levels_by_projected_error() {
    // A plane has no error at any level: the coarsest everywhere, no morph.
    let plane =
        vkterrain::terrain::Heightmap::from_fn(129, 129, |r, c| 0.5 * r as f32 + 0.25 * c as f32)
            .unwrap();
    let terrain = Terrain::new(
        TerrainInfo::new(plane, DVec2::ONE, 32, DVec2::ZERO).unwrap(),
        0.0,
    )
    .unwrap();
    let table = terrain.error_table();
    let all = vec![true; terrain.grid().patch_count()];
    let chosen = select_levels_by_error(
        &terrain,
        &table,
        Vec3::new(0.0, 10.0, 0.0),
        1000.0,
        1.0,
        &all,
        None,
    );
    assert!(chosen.levels.iter().all(|&l| l == 5), "{:?}", chosen.levels);
    assert!(chosen.morph.iter().all(|&m| m == 0.0));

    // Rough ground: finer near the eye, coarser with a larger tolerance or a
    // smaller screen, never finer.
    let rolling = vkterrain::terrain::Heightmap::from_fn(257, 257, |r, c| {
        let (x, z) = (c as f32, r as f32);
        20.0 * (x / 9.0).sin() * (z / 13.0).cos() + 2.0 * (x / 2.3).sin()
    })
    .unwrap();
    let info = TerrainInfo::new(rolling, DVec2::splat(2.0), 32, DVec2::ZERO).unwrap();
    let terrain = Terrain::new(info, 0.0).unwrap();
    let table = terrain.error_table();
    let eye = Vec3::new(-200.0, 60.0, -200.0);
    let all = vec![true; terrain.grid().patch_count()];
    let strict = select_levels_by_error(&terrain, &table, eye, 200.0, 1.0, &all, None);
    let loose = select_levels_by_error(&terrain, &table, eye, 200.0, 8.0, &all, None);
    let small = select_levels_by_error(&terrain, &table, eye, 50.0, 1.0, &all, None);
    let sum = |l: &PatchLevels| l.levels.iter().map(|&v| u32::from(v)).sum::<u32>();
    assert!(sum(&loose) > sum(&strict) && sum(&small) > sum(&strict));
    assert!(strict.levels.iter().zip(&loose.levels).all(|(s, l)| s <= l));
    // The eye hangs over the (-x, -z) corner patch: row 7, column 0.
    assert_eq!(
        strict.levels[7 * 8],
        0,
        "the patch under the eye at full resolution"
    );
    assert!(strict.levels[7] > 0, "the far corner coarser");
    assert!(strict.morph.iter().all(|m| (0.0..=1.0).contains(m)));
    // A patch that is not drawn takes the finest level of its drawn
    // neighbours: their sides with it can be on screen, and none of them
    // is stitched to it.
    let mut drawn = all.clone();
    drawn[7 * 8] = false;
    let culled = select_levels_by_error(&terrain, &table, eye, 200.0, 1.0, &drawn, None);
    let grid = terrain.grid();
    let beside: Vec<usize> = grid.neighbours(7 * 8).into_iter().flatten().collect();
    let finest = beside.iter().map(|&q| culled.levels[q]).min().unwrap();
    assert_eq!(culled.levels[7 * 8], finest);
    for q in beside {
        let (coarser, _) = neighbour_masks(&culled.levels, grid, grid.patch_id(q));
        let side = [LEFT, TOP, RIGHT, BOTTOM][grid
            .neighbours(q)
            .iter()
            .position(|&n| n == Some(7 * 8))
            .unwrap()];
        assert_eq!(coarser & side, 0, "patch {q} stitched to the culled one");
    }
}

#[test]
fn a_morph_limit_holds_for_the_sides_a_same_level_neighbour_shares() {
    // Four patches in a row (16-cell patches, 5 levels), all at level 1
    // but the last at level 2; every morph factor 0.9. The second patch's
    // limit is 0.25 for the level it chose (table index 4 - 1 = 3).
    let grid = vkterrain::terrain::PatchGrid::for_size(65, 17, 16);
    let mut chosen = PatchLevels {
        levels: vec![1, 1, 1, 2],
        morph: vec![0.9; 4],
    };
    let limits = [None, Some((3, 0.25)), None, Some((3, 0.5))];
    limit_morph(&mut chosen, &limits, &[true; 4], &grid);
    // Its own factor, and its same-level neighbours' (a side takes the
    // larger of the two), are capped; the limit for a level the last
    // patch did not choose is not applied, and a coarser neighbour's
    // side does not morph, so it is not capped by it.
    assert_eq!(chosen.morph, [0.25, 0.25, 0.25, 0.9]);
    for p in 0..3 {
        let (interior, sides) = patch_morph(&chosen, &grid, grid.patch_id(p));
        assert!(
            interior <= 0.25 && sides.iter().all(|&s| s <= 0.25),
            "patch {p}"
        );
    }
    // A patch not drawn does not morph, and caps no neighbour.
    let mut chosen = PatchLevels {
        levels: vec![1, 1, 1, 1],
        morph: vec![0.9; 4],
    };
    limit_morph(&mut chosen, &[None; 4], &[true, false, true, true], &grid);
    assert_eq!(chosen.morph, [0.9, 0.0, 0.9, 0.9]);
}

/// A culled patch beside a drawn one takes the drawn one's level, so the
/// drawn patch stitches none of its sides to it; patches beside nothing
/// drawn keep the coarsest level until balancing lowers them.
#[test]
fn culled_patches_beside_drawn_ones_match_them() {
    // 4x4 patches of 16 cells: levels 0 (full) to 4 (one quad).
    let grid = vkterrain::terrain::PatchGrid::for_size(65, 65, 16);
    let at = |row, col| grid.patch_index(vkterrain::terrain::PatchId { row, col });
    let mut levels = vec![4u8; grid.patch_count()];
    let mut drawn = vec![false; grid.patch_count()];
    // Drawn: (1, 1) at full resolution and (1, 2) at level 1.
    levels[at(1, 1)] = 0;
    levels[at(1, 2)] = 1;
    drawn[at(1, 1)] = true;
    drawn[at(1, 2)] = true;
    let mut lowered: Vec<usize> = refine_beside_drawn(&mut levels, &grid, &drawn)
        .into_iter()
        .map(|q| grid.patch_index(q))
        .collect();
    lowered.sort_unstable();
    lowered.dedup();
    let mut expected: Vec<usize> = [(0, 1), (2, 1), (1, 0), (0, 2), (2, 2), (1, 3)]
        .map(|(r, c)| at(r, c))
        .to_vec();
    expected.sort_unstable();
    assert_eq!(lowered, expected);
    for (r, c, l) in [
        (0, 1, 0),
        (2, 1, 0),
        (1, 0, 0),
        (0, 2, 1),
        (2, 2, 1),
        (1, 3, 1),
    ] {
        assert_eq!(levels[at(r, c)], l, "patch ({r}, {c})");
    }
    assert_eq!(levels[at(3, 3)], 4, "a patch beside nothing drawn");
    balance(&mut levels, &grid);
    // (1, 2) is one level coarser than (1, 1): that side is the one
    // stitched, by the drawn pair's own choice; no side of either is
    // stitched to a culled patch.
    assert_eq!(
        neighbour_masks(&levels, &grid, grid.patch_id(at(1, 1))).0,
        RIGHT
    );
    assert_eq!(
        neighbour_masks(&levels, &grid, grid.patch_id(at(1, 2))).0,
        0
    );
}

/// Drawn in blocks that share a level, only the patches on the blocks'
/// sides can lower a neighbour: refining from them alone and balancing
/// from them alone gives the levels that refining from every drawn
/// patch and balancing the whole grid give.
#[test]
fn block_sides_alone_refine_and_balance_as_every_patch_does() {
    // 16x16 patches of 16 cells: levels 0 to 4.
    let grid = vkterrain::terrain::PatchGrid::for_size(257, 257, 16);
    let cols = grid.patch_cols();
    // (first column, first row, patches a side, level)
    let blocks = [
        (4, 4, 4, 1),
        (8, 4, 2, 2),
        (8, 6, 2, 0),
        (2, 8, 1, 0),
        (4, 8, 4, 3),
        // At the grid's near and far corners.
        (0, 0, 2, 2),
        (12, 12, 4, 0),
    ];
    let mut levels = vec![4u8; grid.patch_count()];
    let mut drawn = vec![false; grid.patch_count()];
    let mut edges = Vec::new();
    for (c0, r0, span, level) in blocks {
        for r in r0..r0 + span {
            for c in c0..c0 + span {
                let p = r * cols + c;
                levels[p] = level;
                drawn[p] = true;
                if r == r0 || r + 1 == r0 + span || c == c0 || c + 1 == c0 + span {
                    edges.push(vkterrain::terrain::PatchId { row: r, col: c });
                }
            }
        }
    }
    let interior = drawn.iter().filter(|&&d| d).count() - edges.len();
    assert!(interior >= 8, "{interior} patches inside blocks");
    let mut every = levels.clone();
    let mut by_blocks = levels.clone();
    let mut by_sides = levels.clone();
    refine_beside_drawn(&mut every, &grid, &drawn);
    balance(&mut every, &grid);
    let beside = refine_beside(&mut levels, &grid, &drawn, &edges);
    assert!(!beside.is_empty());
    let seeds: Vec<_> = edges.iter().chain(&beside).copied().collect();
    balance_from(&mut levels, &grid, &seeds);
    assert_eq!(levels, every);
    // Looking only beyond the blocks' sides gives them too.
    let rects: Vec<_> = blocks
        .iter()
        .map(|&(c0, r0, span, _)| ([c0, c0 + span], [r0, r0 + span]))
        .collect();
    let stitched = vec![[true; 4]; rects.len()];
    refine_and_balance_blocks(&mut by_blocks, &grid, &drawn, &rects, |i| stitched[i]);
    assert_eq!(by_blocks, every);
    // So does balancing only from the sides finer than the coarsest but one.
    refine_and_balance(&mut by_sides, &grid, &drawn, &edges);
    assert_eq!(by_sides, every);
    // Something moved: culled patches were refined, and balancing lowered
    // patches beyond them.
    assert!(every.iter().filter(|&&l| l < 4).count() > drawn.iter().filter(|&&d| d).count());
}

/// Refining and balancing change no level further than `balance_reach`
/// from a drawn patch, and do change one that far: a lone patch drawn at
/// the finest level lowers a diamond of patches around it, each ring a
/// level coarser, out to the ring before the coarsest.
#[test]
fn refining_and_balancing_reach_no_further_than_balance_reach() {
    for cells in [4usize, 16, 32] {
        let samples = 24 * cells + 1;
        let grid = vkterrain::terrain::PatchGrid::for_size(samples, samples, cells as u32);
        let (cols, coarsest) = (grid.patch_cols(), (level_count(cells) - 1) as u8);
        let reach = balance_reach(cells);
        for (c, r) in [(12usize, 12usize), (0, 0), (23, 5)] {
            let mut levels = vec![coarsest; grid.patch_count()];
            let mut drawn = vec![false; grid.patch_count()];
            let p = r * cols + c;
            levels[p] = 0;
            drawn[p] = true;
            let block = [([c, c + 1], [r, r + 1])];
            refine_and_balance_blocks(&mut levels, &grid, &drawn, &block, |_| [true; 4]);
            let farthest = (0..grid.patch_count())
                .filter(|&q| levels[q] < coarsest)
                .map(|q| (q % cols).abs_diff(c) + (q / cols).abs_diff(r))
                .max();
            assert_eq!(farthest, Some(reach), "{cells} cells, patch ({c}, {r})");
        }
    }
}

/// A geomip level and its error table index name the same number of
/// segments a side (level l: n / 2^l; index k: 2^k), and each mapping
/// undoes the other.
#[test]
fn a_level_and_its_table_index_have_the_same_segments() {
    for n in [2usize, 4, 8, 16, 32, 64] {
        let count = level_count(n);
        for level in 0..count {
            let k = table_index(level, count);
            assert_eq!(1usize << k, n >> level, "n={n} level={level}");
            assert_eq!(level_of_index(k, count), level);
        }
    }
}

/// A patch whose box holds the eye is predicted from its ground: its
/// error seen from the ground's distance less that error, infinite where
/// the drawn surface may reach the eye, and 0 without its ground (the
/// choice keeps such a patch at level 0); from outside its box, from the
/// box's nearest point as before.
#[test]
fn a_patch_holding_the_eye_is_predicted_from_its_ground() {
    let error = |level: usize| [0.0, 2.0, 10.0, 40.0][level];
    let patch = |level, ground| DrawnPatch {
        lo: Vec3::new(-100.0, 0.0, -100.0),
        hi: Vec3::new(100.0, 200.0, 100.0),
        level,
        morph: 0.0,
        coarser: 0,
        fans: [0.0; 4],
        ground,
    };
    let eye = Vec3::new(10.0, 60.0, -20.0);
    let px = |level, ground| predicted_px(error, &patch(level, ground), eye, 1000.0);
    assert_eq!(px(2, Some(50.0)), 10.0 * 1000.0 / 40.0);
    assert_eq!(px(3, Some(50.0)), 40.0 * 1000.0 / 10.0);
    assert_eq!(px(3, Some(30.0)), f32::INFINITY);
    assert_eq!(px(2, None), 0.0);
    assert_eq!(px(0, Some(50.0)), 0.0);
    // Above the box: its own distance, whatever the ground says.
    let above = Vec3::new(10.0, 250.0, -20.0);
    let from_box = predicted_px(error, &patch(2, Some(1.0)), above, 1000.0);
    assert_eq!(from_box, 10.0 * 1000.0 / 50.0);
}

/// A side stitched to a coarser neighbour is predicted at that level's
/// error, or at its fans' where they stray further, from the side's
/// nearest point, at full resolution too.
#[test]
fn a_stitched_side_is_predicted_at_its_fans_error() {
    let error = |level: usize| [0.0, 2.0, 10.0, 40.0][level];
    let patch = |level, fans| DrawnPatch {
        lo: Vec3::new(0.0, 0.0, 0.0),
        hi: Vec3::new(100.0, 10.0, 100.0),
        level,
        morph: 0.0,
        coarser: RIGHT,
        fans,
        ground: None,
    };
    // The eye 20 beyond the right side (x = 100), 100 from the patch's
    // near side, level with the box's top.
    let eye = Vec3::new(120.0, 10.0, 50.0);
    let px = |level, fans| predicted_px(error, &patch(level, fans), eye, 1000.0);
    // Full resolution: the coarser neighbour's level, then the fans'.
    assert_eq!(px(0, [0.0; 4]), 2.0 * 1000.0 / 20.0);
    assert_eq!(px(0, [0.0, 0.0, 30.0, 0.0]), 30.0 * 1000.0 / 20.0);
    // Fans beside a side that is not stitched count for nothing.
    assert_eq!(px(0, [30.0, 0.0, 0.0, 0.0]), 2.0 * 1000.0 / 20.0);
    // Level 1: its own error from the box, the side's from the side.
    assert_eq!(px(1, [0.0; 4]), 10.0 * 1000.0 / 20.0);
    assert_eq!(px(1, [0.0, 0.0, 30.0, 0.0]), 30.0 * 1000.0 / 20.0);
}

/// A stitched side's fans keep the level's vertices but not its
/// triangles: each 2x2 block along the side is fanned from its centre, so
/// half its cells are split along the other diagonal. On a plane that
/// changes nothing; beside a spike one cell inside a full-resolution
/// patch's right side, the cells that touch the spike are split away from
/// it, and their centres stand half the spike's height off the reference.
#[test]
fn stitch_errors_find_a_spike_beside_a_side() {
    let plane = |r: usize, c: usize| 0.5 * c as f32 + 0.2 * r as f32;
    let spike = 60.0;
    let map = vkterrain::terrain::Heightmap::from_fn(33, 33, |r, c| {
        plane(r, c) + if (r, c) == (8, 15) { spike } else { 0.0 }
    })
    .unwrap();
    let grid = vkterrain::terrain::PatchGrid::for_size(33, 33, 16);
    let (_, errors) = vkterrain::terrain::ErrorTable::compute_pair(&map, &grid);
    let stitch = StitchErrors::compute(&map, &grid, &errors);
    let sides = [LEFT, TOP, RIGHT, BOTTOM];
    for level in 0..level_count(16) {
        // Patches (1, 0), (0, 1) and (1, 1) are planes, as is every side of
        // patch (0, 0) but its right.
        for p in 1..4 {
            for side in sides {
                let e = stitch.excess(p, level, side);
                assert!(e < 1e-4, "patch {p}, level {level}, side {side}: {e}");
            }
        }
        for side in [LEFT, TOP, BOTTOM] {
            let e = stitch.excess(0, level, side);
            assert!(e < 1e-4, "level {level}, side {side}: {e}");
        }
    }
    // Full resolution is the reference itself: its fans stray by all they
    // stray. At level 1 the spike is not a vertex: the level strays by all
    // of it, and its fans by no more.
    let right = stitch.excess(0, 0, RIGHT);
    assert!((right - spike / 2.0).abs() < 1e-3, "{right}");
    assert_eq!(stitch.excess(0, 1, RIGHT), 0.0);
    // A block reads its sides' patches at once: patch (0, 0) alone has
    // the spike on its right side; the 2x2 block of all four has it inside.
    let block = |level: u32| vkterrain::lod::plan::PlannedBlock {
        col: 0,
        row: 0,
        level,
        patch_level: 4,
        full_resolution: true,
        chosen: false,
        predicted_px: 0.0,
        coarser_over_px: 0.0,
    };
    let [left, right, top, bottom] = stitch.block_excess(&block(0), 0);
    assert!(
        [left, top, bottom].iter().all(|&e| e < 1e-4),
        "{left} {top} {bottom}"
    );
    assert!((right - spike / 2.0).abs() < 1e-3, "{right}");
    let whole = stitch.block_excess(&block(1), 0);
    assert!(whole.iter().all(|&e| e < 1e-4), "{whole:?}");
    // The plane alone strays nowhere.
    let flat = vkterrain::terrain::Heightmap::from_fn(33, 33, plane).unwrap();
    let (_, flat_errors) = vkterrain::terrain::ErrorTable::compute_pair(&flat, &grid);
    let none = StitchErrors::compute(&flat, &grid, &flat_errors);
    for p in 0..4 {
        for level in 0..level_count(16) {
            for side in sides {
                assert!(none.excess(p, level, side) < 1e-4);
            }
        }
    }
}

/// A drawn patch beyond a side that may not be stitched takes the
/// block's own level, as a culled one does; beyond the others it may be
/// one coarser, and balancing goes on from there.
#[test]
fn a_side_that_may_not_be_stitched_keeps_its_neighbour_at_its_level() {
    let grid = vkterrain::terrain::PatchGrid::for_size(4 * 4 + 1, 4 + 1, 4);
    let coarsest = (level_count(4) - 1) as u8;
    let drawn = vec![true; 4];
    let blocks: Vec<_> = (0..4).map(|c| ([c, c + 1], [0, 1])).collect();
    for (left, expected) in [(true, [1, 0, 1, 2]), (false, [0, 0, 1, 2])] {
        let mut levels = vec![coarsest, 0, coarsest, coarsest];
        let mut sides = [[true; 4]; 4];
        sides[1][0] = left;
        refine_and_balance_blocks(&mut levels, &grid, &drawn, &blocks, |i| sides[i]);
        assert_eq!(levels, expected, "left side stitchable: {left}");
    }
}

#[test]
fn levels_by_error_keep_a_neighbour_where_stitching_would_cut_a_spike() {
    // Patch (0, 0) holds a spike one cell inside its right side, patch
    // (0, 1) beyond it is a plane. Seen from just beside the side, the
    // spike's patch is drawn at full resolution and the plane, balanced,
    // one level coarser: the side between them is stitched, and its fans
    // cut the spike's near faces to half its height.
    let spike = 60.0;
    let map = vkterrain::terrain::Heightmap::from_fn(33, 33, |r, c| {
        0.5 * c as f32 + 0.2 * r as f32 + if (r, c) == (8, 15) { spike } else { 0.0 }
    })
    .unwrap();
    let terrain = Terrain::new(
        TerrainInfo::new(map.clone(), DVec2::ONE, 16, DVec2::ZERO).unwrap(),
        0.0,
    )
    .unwrap();
    let grid = terrain.grid();
    let (_, table) = terrain.error_tables();
    let stitch = StitchErrors::compute(&map, grid, table);
    let all = vec![true; grid.patch_count()];
    // Local x = column - 16, z = 16 - row: the spike stands at (-1, 8).
    let eye = Vec3::new(0.5, 20.0, 8.0);
    let unguarded = select_levels_by_error(&terrain, table, eye, 600.0, 1.0, &all, None);
    assert_eq!(unguarded.levels[..2], [0, 1], "{:?}", unguarded.levels);
    let guarded = select_levels_by_error(&terrain, table, eye, 600.0, 1.0, &all, Some(&stitch));
    assert_eq!(guarded.levels[..2], [0, 0], "{:?}", guarded.levels);
    // Far off, the fans' 30 m is within tau and the side stays stitched.
    let far = Vec3::new(0.5, 20.0, 30_000.0);
    let coarse = select_levels_by_error(&terrain, table, far, 600.0, 1.0, &all, Some(&stitch));
    let plain = select_levels_by_error(&terrain, table, far, 600.0, 1.0, &all, None);
    assert_eq!(coarse.levels, plain.levels);
}

/// The distance LOD's levels, morph factors and drawn patches decided
/// patch by patch: each patch in view at its own distance's level,
/// refined and balanced from every drawn patch, then morphed at its
/// balanced level.
fn by_distance_patch_by_patch(
    terrain: &Terrain,
    hierarchy: &Hierarchy,
    view: &LodView,
    (cull, d0): (bool, f32),
) -> (PatchLevels, Vec<u32>) {
    let grid = terrain.grid();
    let count = level_count(grid.cells_per_patch());
    let visible = patches_in_view(terrain, hierarchy, view, cull).0;
    let edges: Vec<PatchId> = visible.iter().map(|&p| grid.patch_id(p as usize)).collect();
    let distance = |id: PatchId| hierarchy.node(NodeId::patch(id)).distance(view.eye_local);
    let mut levels = vec![(count - 1) as u8; grid.patch_count()];
    let mut morph = vec![0.0; grid.patch_count()];
    let mut drawn = vec![false; grid.patch_count()];
    for &id in &edges {
        let p = grid.patch_index(id);
        levels[p] = level_for_distance(distance(id), d0, count) as u8;
        drawn[p] = true;
    }
    refine_and_balance(&mut levels, grid, &drawn, &edges);
    for &id in &edges {
        let p = grid.patch_index(id);
        let level = usize::from(levels[p]);
        if level + 1 < count {
            morph[p] = morph_factor(distance(id), d0, level);
        }
    }
    (PatchLevels { levels, morph }, visible)
}

/// The distance LOD decides whole blocks of patches at a level where it
/// can, and gives every patch the level, morph factor and drawn flag it
/// gets decided on its own: from the ground, from above and from beyond
/// the edge, culled or not, at a short and a long reach of the finest
/// level, with one kept set of buffers, as a frame slot keeps them.
#[test]
fn the_distance_lod_in_blocks_decides_as_patch_by_patch() {
    let wide = {
        let map = Heightmap::from_fn(513, 513, |r, c| {
            let (x, z) = (c as f32 / 40.0, r as f32 / 31.0);
            200.0 * x.sin() * z.cos() + 0.05 * (((r * 7919 + c * 104_729) % 97) as f32)
        })
        .unwrap();
        let info = TerrainInfo::new(map, DVec2::splat(8.0), 4, DVec2::ZERO).unwrap();
        Terrain::new(info, 0.0).unwrap()
    };
    let mut chosen = ChosenPatches::default();
    let mut morphing = 0;
    for terrain in [dem_terrain(16, DVec2::ZERO), wide] {
        let hierarchy = Hierarchy::new(&terrain, &terrain.error_table());
        let (lo, hi) = terrain.info().min_max();
        let (lo, hi) = (f64::from(lo), f64::from(hi));
        let size = terrain.info().world_width();
        for (eye, target) in [
            (
                DVec3::new(0.1 * size, hi + 20.0, 0.05 * size),
                DVec3::new(0.5 * size, lo, 0.3 * size),
            ),
            (
                DVec3::new(0.0, hi + size, -0.8 * size),
                DVec3::new(0.0, lo, 0.0),
            ),
            (
                DVec3::new(-0.9 * size, hi + 300.0, -0.7 * size),
                DVec3::ZERO,
            ),
        ] {
            let camera = Camera {
                eye,
                target,
                fov_y_deg: 55.0,
            };
            let view = FrameView::new(&terrain, &camera, 1280, 720).lod_view(Tau::DEFAULT);
            for cull in [true, false] {
                for d0 in [0.005 * size as f32, 0.08 * size as f32] {
                    chosen.by_distance(&terrain, &hierarchy, &view, (cull, d0));
                    let (expected, visible) =
                        by_distance_patch_by_patch(&terrain, &hierarchy, &view, (cull, d0));
                    let at = format!("eye {eye}, cull {cull}, d0 {d0}");
                    assert_eq!(chosen.visible(), visible, "{at}");
                    assert_eq!(chosen.levels().levels, expected.levels, "{at}");
                    assert_eq!(chosen.levels().morph, expected.morph, "{at}");
                    morphing += expected.morph.iter().filter(|&&m| m > 0.0).count();
                }
            }
        }
    }
    // The views put patches in the middle of their glides too.
    assert!(morphing > 100, "{morphing}");
}

/// The error LOD's choice into one kept set of buffers, frame after frame
/// with the view, tau and policy changing between them, gives every patch
/// the level, morph factor and drawn flag a fresh set gives it: each
/// choice resets what the one before wrote, morph factors included, and
/// only that.
#[test]
fn the_error_lod_in_kept_buffers_chooses_as_in_fresh_ones() {
    let terrain = dem_terrain(16, DVec2::ZERO);
    let (tess_table, table) = terrain.error_tables();
    let hierarchy = Hierarchy::new(&terrain, tess_table);
    let map = terrain.info().heightmap().expect("a whole terrain");
    let stitch = StitchErrors::compute(map, terrain.grid(), table);
    let (lo, hi) = terrain.info().min_max();
    let (lo, hi) = (f64::from(lo), f64::from(hi));
    let size = terrain.info().world_width();
    let mut kept = (ChosenPatches::default(), Planner::default());
    let mut morphing = 0;
    for (eye, target) in [
        (
            DVec3::new(0.1 * size, hi + 20.0, 0.05 * size),
            DVec3::new(0.5 * size, lo, 0.3 * size),
        ),
        (
            DVec3::new(0.0, hi + size, -0.8 * size),
            DVec3::new(0.0, lo, 0.0),
        ),
        (
            DVec3::new(-0.3 * size, hi + 100.0, 0.4 * size),
            DVec3::new(0.2 * size, lo, -0.1 * size),
        ),
    ] {
        let camera = Camera {
            eye,
            target,
            fov_y_deg: 55.0,
        };
        for (tau, cull) in [(0.5, true), (4.0, false), (1.0, true)] {
            let view = FrameView::new(&terrain, &camera, 1280, 720)
                .lod_view(Tau::new(tau).expect("a valid tau"));
            let inputs = PlanInputs {
                table,
                sight: None,
                merge: false,
                cull,
                reading: SightReading::Template,
                seen: None,
            };
            let (chosen, planner) = &mut kept;
            chosen.by_error(
                &terrain,
                &hierarchy,
                &view,
                (planner, &inputs),
                Some(&stitch),
            );
            let mut fresh = ChosenPatches::default();
            let mut planner = Planner::default();
            let stitch = Some(&stitch);
            fresh.by_error(&terrain, &hierarchy, &view, (&mut planner, &inputs), stitch);
            let at = format!("eye {eye}, tau {tau}, cull {cull}");
            assert!(!fresh.visible().is_empty(), "{at}");
            assert_eq!(chosen.visible(), fresh.visible(), "{at}");
            assert_eq!(chosen.levels(), fresh.levels(), "{at}");
            morphing += fresh.levels().morph.iter().filter(|&&m| m > 0.0).count();
            // The distance LOD between two error frames, as a user
            // switching policies leaves it.
            chosen.by_distance(&terrain, &hierarchy, &view, (cull, 0.02 * size as f32));
        }
    }
    // Blocks glide towards their coarser levels on some of the views.
    assert!(morphing > 0, "{morphing}");
}
