//! Merged patches on the CPU: which blocks the frame plan merges, what
//! their sides compute from both sides, and the errors a node carries.

mod common;

use common::*;
use glam::{DVec2, Vec3};
use vkterrain::lod::hierarchy::Hierarchy;
use vkterrain::lod::patch_merge::{
    node_across, node_error_factors, node_errors, NodeAcross, PatchMerge, MAX_MERGE_LEVEL,
};
use vkterrain::lod::plan::{plan, FramePlan, PlanInputs, SightReading};
use vkterrain::lod::view::{LodView, Tau};
use vkterrain::lod::{patch_error_factors, Across};
use vkterrain::terrain::camera::Frustum;
use vkterrain::terrain::{PatchId, Terrain, TerrainInfo};

/// Pixels per radian of a 1280-pixel-wide view with a 60 degree field.
const PPR: f32 = 1108.5;

/// The frame plan from `eye` at `pixels`, every patch in view (no
/// frustum), by the terrain's bound.
fn planned(terrain: &Terrain, eye: Vec3, pixels: f32) -> FramePlan {
    let table = terrain.error_table();
    let hierarchy = Hierarchy::new(terrain, &table);
    let view = LodView {
        eye_local: eye,
        pixels_per_radian: PPR,
        // Planes that cull nothing.
        frustum: Frustum {
            planes: [glam::Vec4::W; 6],
        },
        viewport: glam::Vec2::new(1280.0, 720.0),
        tau: Tau::new(pixels).unwrap(),
    };
    plan(
        terrain,
        &hierarchy,
        &view,
        &PlanInputs {
            table: &table,
            sight: None,
            merge: true,
            cull: false,
            reading: SightReading::Tessellated,
            seen: None,
        },
    )
}

/// The plan's merged nodes, and the level of the node holding each patch
/// (0 for a patch drawn on its own).
fn merged(terrain: &Terrain, eye: Vec3, pixels: f32) -> PatchMerge {
    let cols = terrain.grid().patch_cols();
    let nodes = planned(terrain, eye, pixels).merged;
    let mut levels = vec![0u8; terrain.grid().patch_count()];
    for n in &nodes {
        for r in n.row..n.row + n.span() {
            for c in n.col..n.col + n.span() {
                levels[r as usize * cols + c as usize] = n.level as u8;
            }
        }
    }
    PatchMerge { levels, nodes }
}

/// The noise map in 8-cell patches: 257x193 samples, 32x24 patches, all
/// full-size.
fn noise_terrain() -> Terrain {
    let info = TerrainInfo::new(noise_map(257, 193, 7), DVec2::splat(10.0), 8, DVec2::ZERO)
        .expect("valid terrain");
    Terrain::new(info, 0.0).expect("valid margin")
}

#[test]
fn node_errors_shift_the_patches_levels_and_bound_the_rest_by_the_heights() {
    let patch_max = [8.0, 4.0, 2.0, 1.0, 0.5, 0.25, 0.0];
    assert_eq!(node_errors(&patch_max, 30.0, 0), patch_max);
    // Level 2: 4 segments across are one a patch, the patches' level 0.
    assert_eq!(
        node_errors(&patch_max, 30.0, 2),
        [30.0, 30.0, 8.0, 4.0, 2.0, 1.0, 0.5]
    );
    // A height span below the patches' own level-0 error never lowers it.
    assert_eq!(node_errors(&patch_max, 3.0, 1)[0], 8.0);
}

#[test]
fn far_away_everything_merges_into_aligned_nodes_with_full_size_patches() {
    let terrain = noise_terrain();
    let eye = Vec3::new(0.0, 1e6, -4e6);
    let merge = merged(&terrain, eye, 1.0);
    assert!(!merge.nodes.is_empty());
    assert!(merge.levels.iter().all(|&l| l > 0), "every patch merged");
    let mut covered = vec![0u32; merge.levels.len()];
    let cols = terrain.grid().patch_cols();
    for node in &merge.nodes {
        assert!(node.level >= 1 && node.level <= MAX_MERGE_LEVEL);
        let span = node.span();
        assert_eq!(node.col % span, 0, "aligned");
        assert_eq!(node.row % span, 0, "aligned");
        for r in node.row..node.row + span {
            for c in node.col..node.col + span {
                let p = r as usize * cols + c as usize;
                covered[p] += 1;
                assert_eq!(u32::from(merge.levels[p]), node.level);
            }
        }
    }
    assert!(covered.iter().all(|&n| n == 1), "each patch in one node");
    // 32x24 patches: the largest aligned blocks that fit are two of 16x16
    // over the first 16 rows and four of 8x8 under them.
    let mut levels: Vec<u32> = merge.nodes.iter().map(|n| n.level).collect();
    levels.sort();
    assert_eq!(levels, [3, 3, 3, 3, 4, 4]);
}

#[test]
fn remainder_patches_and_near_ground_are_never_merged() {
    // The DEM in 16-cell patches has remainders in its last column and row.
    let terrain = dem_terrain(16, DVec2::ZERO);
    let grid = terrain.grid();
    let far = merged(&terrain, Vec3::new(0.0, 2e6, -6e6), 1.0);
    assert!(!far.nodes.is_empty());
    for p in 0..grid.patch_count() {
        let rect = grid.sample_rect(grid.patch_id(p));
        if rect.cells_x() != 16 || rect.cells_z() != 16 {
            assert_eq!(far.levels[p], 0, "remainder patch {p} merged");
        }
    }
    // From close above the middle at a fine tolerance nothing is flat.
    let near = merged(&terrain, Vec3::new(0.0, 600.0, 0.0), 0.5);
    assert!(near.nodes.is_empty(), "{} nodes", near.nodes.len());
}

/// Every side two units share gets the same vertices from both: between
/// same-level nodes the same factor, and towards anything else one segment
/// a patch on the node's side and one on each patch's.
#[test]
fn shared_sides_agree_from_both_sides() {
    let terrain = dem_terrain(16, DVec2::ZERO);
    let table = terrain.error_table();
    let grid = terrain.grid();
    let (cols, rows) = (grid.patch_cols(), grid.patch_rows());
    let (lo, hi) = terrain.info().min_max();
    let mut mixed = 0;
    for (eye, pixels) in [
        (Vec3::new(-60_000.0, 15_000.0, -60_000.0), 2.0f32),
        (Vec3::new(-50_000.0, 8_000.0, 10_000.0), 4.0),
        (Vec3::new(5_000.0, 12_000.0, 40_000.0), 4.0),
        (Vec3::new(0.0, 120_000.0, 0.0), 1.0),
        (Vec3::new(0.0, 60_000.0, 0.0), 4.0),
        (Vec3::new(-90_000.0, 20_000.0, -20_000.0), 1.0),
    ] {
        let frame = planned(&terrain, eye, pixels);
        let merge = merged(&terrain, eye, pixels);
        let full_resolution: Vec<usize> = frame
            .blocks
            .iter()
            .filter(|b| b.full_resolution)
            .flat_map(|b| b.patches(grid).collect::<Vec<_>>())
            .collect();
        let range = [lo - eye.y, hi - eye.y];
        let levels: std::collections::BTreeSet<u8> = merge.levels.iter().copied().collect();
        if levels.len() >= 3 {
            mixed += 1;
        }
        let node_corners = |n: &vkterrain::lod::patch_merge::MergedNode| {
            let s = n.span() as usize;
            let (c, r) = (n.col as usize, n.row as usize);
            let at = |c: usize, r: usize, k: usize| {
                terrain.patch_corners(PatchId { row: r, col: c })[k] - eye
            };
            [
                at(c, r, 0),
                at(c + s - 1, r, 1),
                at(c, r + s - 1, 2),
                at(c + s - 1, r + s - 1, 3),
            ]
        };
        let factors: Vec<_> = merge
            .nodes
            .iter()
            .map(|n| {
                node_error_factors(
                    node_corners(n),
                    range,
                    &n.errors,
                    node_across(&merge, n, cols, rows),
                    n.level,
                    16,
                    PPR,
                    pixels,
                )
            })
            .collect();
        for (n, f) in merge.nodes.iter().zip(&factors) {
            let span = n.span() as f32;
            assert!(f.inside[0] <= span, "{n:?}: inside {}", f.inside[0]);
            for (e, across) in node_across(&merge, n, cols, rows).iter().enumerate() {
                match across {
                    NodeAcross::Other => assert_eq!(f.edges[e], span),
                    NodeAcross::Border => {}
                    NodeAcross::Same(_) => {
                        // The node across, and its side facing this one.
                        let s = n.span();
                        let (dc, dr): (i64, i64) = [(-1, 0), (0, -1), (1, 0), (0, 1)][e];
                        let (oc, or) = (
                            i64::from(n.col) + dc * i64::from(s),
                            i64::from(n.row) + dr * i64::from(s),
                        );
                        let o = merge
                            .nodes
                            .iter()
                            .position(|m| i64::from(m.col) == oc && i64::from(m.row) == or)
                            .expect("the same-level node across");
                        assert_eq!(factors[o].edges[(e + 2) % 4], f.edges[e], "{n:?} side {e}");
                        assert!(f.edges[e] <= span);
                    }
                }
            }
        }
        // A patch drawn on its own next to a node puts one segment there,
        // and its own rule agrees: that edge was within tolerance at one.
        for p in 0..grid.patch_count() {
            if merge.levels[p] != 0 || full_resolution.contains(&p) {
                continue;
            }
            let id = grid.patch_id(p);
            for (e, (dc, dr)) in [(-1i64, 0i64), (0, -1), (1, 0), (0, 1)]
                .into_iter()
                .enumerate()
            {
                let (qc, qr) = (id.col as i64 + dc, id.row as i64 + dr);
                if qc < 0 || qr < 0 || qc >= cols as i64 || qr >= rows as i64 {
                    continue;
                }
                let q = qr as usize * cols + qc as usize;
                if merge.levels[q] == 0 {
                    continue;
                }
                let own: [f32; 7] = table.patch(p).try_into().unwrap();
                let theirs: [f32; 7] = table.patch(q).try_into().unwrap();
                let corners = terrain.patch_corners(id).map(|c| c - eye);
                let bounds = terrain.y_bounds()[p].map(|y| y - eye.y);
                let rect = grid.sample_rect(id);
                let cells = [rect.cells_x() as u32, rect.cells_z() as u32];
                let mut across = [Across::Border; 4];
                across[e] = Across::Merged;
                let merged_side =
                    patch_error_factors(corners, bounds, range, &own, across, cells, PPR, pixels);
                assert_eq!(merged_side.edges[e], 1.0);
                across[e] = Across::Patch(&theirs);
                let by_errors =
                    patch_error_factors(corners, bounds, range, &own, across, cells, PPR, pixels);
                assert_eq!(by_errors.edges[e], 1.0, "patch {p} side {e}");
            }
        }
    }
    assert!(
        mixed >= 2,
        "only {mixed} views mix nodes of two levels with patches"
    );
}
