//! The real-time frame plan on the CPU: how many nodes it visits, that it
//! covers what is in view once, that no level is finer than the bound
//! asks, and the view model's block entries and cache encoding.

mod common;

use common::*;
use glam::{DVec2, DVec3, Vec3};
use vkterrain::lod::hierarchy::{Hierarchy, NodeId};
use vkterrain::lod::plan::{
    patches_in_view, plan, view_patches, FramePlan, PlanInputs, PlannedBlock, SightReading,
};
use vkterrain::lod::seen::{SeenPixels, NOT_DRAWN};
use vkterrain::lod::view::{LodView, Tau};
use vkterrain::render::FrameView;
use vkterrain::terrain::camera::Camera;
use vkterrain::terrain::error_table::LEVEL_COUNT;
use vkterrain::terrain::sight::{Block, BlockShares, LatticePoint, SightTable, LEVELS};
use vkterrain::terrain::{ErrorTable, Heightmap, PatchGrid, Terrain, TerrainInfo};

fn view_of(terrain: &Terrain, eye: DVec3, target: DVec3, tau: f32) -> LodView {
    let camera = Camera {
        eye,
        target,
        fov_y_deg: 55.0,
    };
    FrameView::new(terrain, &camera, 1280, 720).lod_view(Tau::new(tau).unwrap())
}

/// The DEM seen from far beyond its corner, 500 m over its highest point:
/// most of it small on screen, decided in blocks.
fn distant_view(terrain: &Terrain, tau: f32) -> LodView {
    let (_, hi) = terrain.info().min_max();
    let eye = DVec3::new(-18_000.0, f64::from(hi) + 500.0, -12_000.0);
    view_of(terrain, eye, DVec3::new(5_000.0, 0.0, 5_000.0), tau)
}

fn planned(
    terrain: &Terrain,
    table: &ErrorTable,
    sight: Option<&SightTable>,
    view: &LodView,
) -> FramePlan {
    let hierarchy = Hierarchy::new(terrain, table);
    planned_seen(terrain, (&hierarchy, table, sight), view, None)
}

/// The tess path's plan of `view`, merging and culling, with `seen`'s
/// counts.
fn planned_seen(
    terrain: &Terrain,
    (hierarchy, table, sight): (&Hierarchy, &ErrorTable, Option<&SightTable>),
    view: &LodView,
    seen: Option<&SeenPixels>,
) -> FramePlan {
    plan(
        terrain,
        hierarchy,
        view,
        &PlanInputs {
            table,
            sight,
            merge: true,
            cull: true,
            reading: SightReading::Tessellated,
            seen,
        },
    )
}

/// The block of `frame` that holds patch `p`.
fn block_holding<'f>(frame: &'f FramePlan, grid: &PatchGrid, p: usize) -> Option<&'f PlannedBlock> {
    frame
        .blocks
        .iter()
        .find(|b| b.patches(grid).any(|q| q == p))
}

/// A grid of 512 x 512 patches, as many as a 32769^2 terrain's 64-cell
/// patches, 32 km across: 1025^2 samples 32 m apart in 2-cell patches,
/// rolling hills a few hundred metres high with a little roughness. The
/// plan's walk depends on the grid and the errors, not on what a patch
/// holds.
fn wide_grid() -> Terrain {
    let rough = noise_map(1025, 1025, 11);
    let map = Heightmap::from_fn(1025, 1025, |r, c| {
        let (x, z) = (c as f32 / 90.0, r as f32 / 70.0);
        300.0 * (x.sin() * z.cos()) + 80.0 * (0.37 * x + 1.3 * z).sin() + 0.02 * rough.get(r, c)
    })
    .unwrap();
    let info = TerrainInfo::new(map, DVec2::splat(32.0), 2, DVec2::ZERO).unwrap();
    Terrain::new(info, 0.0).unwrap()
}

/// From the ground up to far above, looking across and down, the plan of a
/// 512 x 512 patch grid visits a few thousand nodes, however many patches
/// it sees: a few hundred when smooth ground merges, and no more than
/// about one per block of 8 x 8 patches when nothing merges.
#[test]
fn the_plan_visits_a_few_thousand_nodes_of_a_512_by_512_patch_grid() {
    let terrain = wide_grid();
    let table = terrain.error_table();
    let hierarchy = Hierarchy::new(&terrain, &table);
    assert_eq!(terrain.grid().patch_count(), 512 * 512);
    let (lo, hi) = terrain.info().min_max();
    let mut most_seen = 0;
    for height in [2.0, 30.0, 300.0, 3_000.0, 30_000.0] {
        let eye = DVec3::new(-14_000.0, f64::from(hi) + height, -14_000.0);
        for target in [
            DVec3::new(14_000.0, f64::from(lo), 14_000.0),
            DVec3::new(0.0, f64::from(lo), 0.0),
            DVec3::new(-13_000.0, f64::from(lo), -13_000.0),
        ] {
            let view = view_of(&terrain, eye, target, 1.0);
            for (merge, most) in [(true, 1_000), (false, 6_000)] {
                let inputs = PlanInputs {
                    table: &table,
                    sight: None,
                    merge,
                    cull: true,
                    reading: SightReading::Tessellated,
                    seen: None,
                };
                let frame = plan(&terrain, &hierarchy, &view, &inputs);
                assert!(
                    frame.nodes_visited <= most,
                    "{height} m up, looking at {target}, merging {merge}: {} nodes visited for {} patches",
                    frame.nodes_visited,
                    frame.patches_in_view
                );
                most_seen = most_seen.max(frame.patches_in_view);
            }
        }
    }
    // The views see hundreds of thousands of patches: the walk visits far
    // fewer nodes than that.
    assert!(most_seen > 200_000, "{most_seen}");
}

/// The plan's blocks and merged nodes hold every patch in view exactly
/// once; the patches outside it they hold are those their blocks reach.
#[test]
fn blocks_and_merged_nodes_cover_the_patches_in_view_once() {
    let terrain = dem_terrain(16, DVec2::ZERO);
    let table = terrain.error_table();
    let sight = terrain.sight_table();
    assert!(sight.is_some());
    let hierarchy = Hierarchy::new(&terrain, &table);
    let grid = terrain.grid();
    let (_, hi) = terrain.info().min_max();
    let mut sizes = [false; 2];
    for (eye, tau) in [
        (DVec3::new(-20_000.0, f64::from(hi) + 200.0, -15_000.0), 1.0),
        (DVec3::new(0.0, 60_000.0, -40_000.0), 2.0),
        (DVec3::new(5_000.0, f64::from(hi) + 3_000.0, 0.0), 0.5),
    ] {
        let view = view_of(&terrain, eye, DVec3::ZERO, tau);
        let frame = planned(&terrain, &table, sight, &view);
        let mut covered = vec![0u32; grid.patch_count()];
        for block in &frame.blocks {
            for p in block.patches(grid) {
                covered[p] += 1;
            }
        }
        let cols = grid.patch_cols();
        for node in &frame.merged {
            for r in node.row..node.row + node.span() {
                for c in node.col..node.col + node.span() {
                    covered[r as usize * cols + c as usize] += 1;
                }
            }
        }
        // A patch outside the frustum may ride along in a block or node
        // that reaches into it; no patch is covered twice, and every patch
        // in view is covered.
        let (visible, _) = patches_in_view(&terrain, &hierarchy, &view, true);
        let mut riders = 0;
        for (p, &n) in covered.iter().enumerate() {
            let seen = visible.binary_search(&(p as u32)).is_ok();
            assert!(n <= 1, "patch {p} from {eye} covered {n} times");
            assert!(
                !seen || n == 1,
                "patch {p} from {eye} in view but not covered"
            );
            riders += usize::from(!seen && n == 1);
        }
        assert_eq!(frame.patches_in_view, visible.len() + riders);
        let singles = frame.blocks.iter().filter(|b| b.level == 0).count();
        sizes[0] |= singles > 0;
        sizes[1] |= frame.blocks.len() > singles;
    }
    // Single patches and blocks of several: the first view's plan fills
    // its room (`BLOCK_BUDGET`); the others have room to split every
    // block down to its patches.
    assert_eq!(sizes, [true, true], "blocks of one size only");
}

/// The patches in view, found by taking nodes wholly inside the frustum
/// whole, are those whose own boxes the frustum does not exclude, in grid
/// order, and the walk visits fewer nodes than there are patches in view
/// when most of the terrain is: on the DEM and the 512 x 512 grid, from
/// low, high and outside, and every patch without culling. The patches
/// the frustum's boundary crosses (`view_patches`) are those in view whose
/// boxes are not wholly inside it.
#[test]
fn patches_in_view_are_those_whose_boxes_are_not_outside() {
    for terrain in [dem_terrain(16, DVec2::ZERO), wide_grid()] {
        let table = terrain.error_table();
        let hierarchy = Hierarchy::new(&terrain, &table);
        let grid = terrain.grid();
        let (lo, hi) = terrain.info().min_max();
        let size = terrain
            .info()
            .world_width()
            .max(terrain.info().world_depth());
        let mut fewer_visits = false;
        let mut some_crossing = false;
        for (eye, target) in [
            (
                DVec3::new(-0.4 * size, f64::from(hi) + 200.0, -0.3 * size),
                DVec3::ZERO,
            ),
            (
                DVec3::new(0.0, f64::from(hi) + size, -0.8 * size),
                DVec3::new(0.0, f64::from(lo), 0.0),
            ),
            (
                DVec3::new(0.1 * size, f64::from(hi) + 50.0, 0.05 * size),
                DVec3::new(0.5 * size, f64::from(lo), 0.3 * size),
            ),
        ] {
            let view = view_of(&terrain, eye, target, 1.0);
            let (visible, visited) = patches_in_view(&terrain, &hierarchy, &view, true);
            // Each patch's box, eye-relative, as centre and half extents.
            let patch_box = |p: usize| {
                let cols = grid.patch_cols();
                let node = hierarchy.node(NodeId {
                    level: 0,
                    col: (p % cols) as u32,
                    row: (p / cols) as u32,
                });
                let [a, b] = node.footprint;
                let [y0, y1] = node.bounds;
                let (min, max) = (Vec3::new(a[0], y0, a[1]), Vec3::new(b[0], y1, b[1]));
                (0.5 * (min + max) - view.eye_local, 0.5 * (max - min))
            };
            let expected: Vec<u32> = (0..grid.patch_count())
                .filter(|&p| {
                    let (centre, half) = patch_box(p);
                    !view.frustum.aabb_outside(centre, half)
                })
                .map(|p| p as u32)
                .collect();
            assert!(!expected.is_empty(), "{eye}: nothing in view");
            assert_eq!(visible, expected, "{eye}");
            // The patches the frustum's boundary crosses: those in view
            // whose boxes are not wholly inside it.
            let in_view = view_patches(&terrain, &hierarchy, &view, true);
            assert_eq!(in_view.patches, visible);
            assert_eq!(in_view.visited, visited);
            let crossing: Vec<u32> = expected
                .iter()
                .copied()
                .filter(|&p| {
                    let (centre, half) = patch_box(p as usize);
                    !view.frustum.aabb_inside(centre, half)
                })
                .collect();
            some_crossing |= !crossing.is_empty() && crossing.len() < visible.len();
            assert_eq!(in_view.crossing, crossing, "{eye}");
            assert!(view_patches(&terrain, &hierarchy, &view, false)
                .crossing
                .is_empty());
            fewer_visits |= visited < visible.len();
            let (all, visited) = patches_in_view(&terrain, &hierarchy, &view, false);
            assert_eq!(all, (0..grid.patch_count() as u32).collect::<Vec<_>>());
            assert_eq!(visited, 1);
        }
        assert!(fewer_visits, "no view took a node whole");
        assert!(
            some_crossing,
            "no view's boundary crossed some patches and not others"
        );
    }
}

/// The share of pixels over tau only ever coarsens: no block is drawn finer
/// than the bound's level from its nearest point, and a block the share
/// chose is drawn coarser than that.
#[test]
fn the_share_only_coarsens_the_bounds_choice() {
    let terrain = dem_terrain(16, DVec2::ZERO);
    let table = terrain.error_table();
    let sight = terrain.sight_table();
    let mut chosen = 0;
    for tau in [0.5, 1.0, 4.0] {
        let view = distant_view(&terrain, tau);
        let bound = planned(&terrain, &table, None, &view);
        let shared = planned(&terrain, &table, sight, &view);
        // Without the model every block is a single patch at the bound's
        // level; with it, each patch of a block is drawn at most as fine.
        let level_of = |frame: &FramePlan, p: usize| {
            frame
                .blocks
                .iter()
                .find(|b| b.patches(terrain.grid()).any(|q| q == p))
                .map(|b| b.patch_level)
        };
        for block in &shared.blocks {
            chosen += usize::from(block.chosen);
            for p in block.patches(terrain.grid()) {
                if let (Some(own), Some(by_bound)) = (level_of(&shared, p), level_of(&bound, p)) {
                    if block.level == 0 {
                        assert!(
                            own <= by_bound,
                            "patch {p} at tau {tau}: {own} > {by_bound}"
                        );
                    }
                }
            }
        }
    }
    assert!(chosen > 0, "the share coarsened nothing");
}

/// The pixels each patch showed (`lod::seen`) only ever coarsen a block
/// that showed fewer than the view model gives it: against counts above
/// every block's modelled pixels, a block whose patches showed nothing
/// takes its coarsest level, and with half the patches hidden, those
/// blocks are drawn no finer, some coarser. (Without counts, the plan
/// finds hidden ground from its boxes instead: `lod::horizon`.)
#[test]
fn counted_pixels_coarsen_only_the_blocks_that_showed_fewer() {
    let terrain = dem_terrain(16, DVec2::ZERO);
    let table = terrain.error_table();
    let sight = terrain.sight_table();
    let hierarchy = Hierarchy::new(&terrain, &table);
    let grid = terrain.grid();
    let view = distant_view(&terrain, 1.0);
    let with = |seen: Option<&SeenPixels>| {
        planned_seen(&terrain, (&hierarchy, &table, sight), &view, seen)
    };
    let level_of = |frame: &FramePlan, p: usize| {
        block_holding(frame, grid, p).map(|b| (b.patch_level, b.full_resolution))
    };
    // Counted at full resolution: no pixel lost to a coarser level.
    let full = vec![LEVEL_COUNT as u8; grid.patch_count()];
    let counts = |f: &dyn Fn(usize) -> u32| -> SeenPixels {
        SeenPixels::new(
            grid,
            &(0..grid.patch_count()).map(f).collect::<Vec<_>>(),
            &full,
        )
        .unwrap()
    };
    let unseen = with(Some(&counts(&|_| 1 << 24)));
    let places = |f: &FramePlan| f.blocks.iter().map(|b| b.node()).collect::<Vec<_>>();
    assert_eq!(places(&with(None)), places(&unseen));
    let nothing = with(Some(&counts(&|_| 0)));
    assert_eq!(nothing.blocks.len(), unseen.blocks.len());
    let mut coarsened = 0;
    for (block, before) in nothing.blocks.iter().zip(&unseen.blocks) {
        if block.chosen || before.chosen {
            assert_eq!(block.patch_level, 0, "{block:?}");
        }
        assert!(block.patch_level <= before.patch_level);
        coarsened += usize::from(block.patch_level < before.patch_level);
    }
    assert!(coarsened > 0, "nothing coarsened");
    // Half the patch columns hidden.
    let hidden = |p: usize| grid.patch_id(p).col % 2 == 0;
    let half = with(Some(&counts(&|p| if hidden(p) { 0 } else { 1 << 24 })));
    let mut coarser = 0;
    for block in half.blocks.iter().filter(|b| b.level == 0) {
        let p = block.patches(grid).next().unwrap();
        let (Some(own), Some(before)) = (level_of(&half, p), level_of(&unseen, p)) else {
            continue;
        };
        if hidden(p) {
            assert!(
                own.0 <= before.0 && (!own.1 || before.1),
                "patch {p}: {own:?} > {before:?}"
            );
            coarser += usize::from(own.0 < before.0);
        }
    }
    assert!(coarser > 0, "no hidden patch was drawn coarser");
}

/// A block that showed fewer pixels than the model gives it may have been
/// hidden, or drawn at a level that lost them (a spike drawn away shows
/// what lies behind it). The pixels the model put over tau at the level a
/// count was taken at are taken as lost, not hidden. A third of the patch
/// columns show a few pixels: counted at full resolution, some of their
/// patches are coarsened; the same counts taken at the coarsest level
/// leave some of them finer, their levels more in all, and almost none
/// coarser (the greedy share's margin, at most a level). Counts of
/// patches not drawn read as taken at full resolution.
#[test]
fn pixels_a_coarser_level_lost_are_not_taken_as_hidden() {
    let terrain = dem_terrain(16, DVec2::ZERO);
    let table = terrain.error_table();
    let sight = terrain.sight_table();
    let hierarchy = Hierarchy::new(&terrain, &table);
    let grid = terrain.grid();
    let view = distant_view(&terrain, 1.0);
    let unseen = planned_seen(&terrain, (&hierarchy, &table, sight), &view, None);
    // A third of the patch columns show a few pixels, the rest more than
    // any patch covers.
    let counts: Vec<u32> = (0..grid.patch_count())
        .map(|p| {
            if grid.patch_id(p).col % 3 == 0 {
                40
            } else {
                1 << 24
            }
        })
        .collect();
    let counted_at = |level: u8| {
        let seen = SeenPixels::new(grid, &counts, &vec![level; counts.len()]).unwrap();
        planned_seen(&terrain, (&hierarchy, &table, sight), &view, Some(&seen))
    };
    let (at_full, at_coarsest) = (counted_at(LEVEL_COUNT as u8), counted_at(0));
    assert_eq!(at_full.blocks.len(), unseen.blocks.len());
    assert_eq!(at_coarsest.blocks.len(), unseen.blocks.len());
    let (mut finer, mut coarser, mut counted, mut coarsened) = (0, 0, 0, 0);
    let mut levels = [0u32; 2];
    for ((full, coarsest), before) in at_full
        .blocks
        .iter()
        .zip(&at_coarsest.blocks)
        .zip(&unseen.blocks)
    {
        assert_eq!((full.col, full.row), (coarsest.col, coarsest.row));
        if full.level > 0 || full.col % 3 != 0 {
            continue;
        }
        coarsened += usize::from(full.patch_level < before.patch_level);
        assert!(
            coarsest.patch_level + 1 >= full.patch_level,
            "{coarsest:?} more than a level coarser than {full:?}"
        );
        counted += 1;
        finer += usize::from(coarsest.patch_level > full.patch_level);
        coarser += usize::from(coarsest.patch_level < full.patch_level);
        levels[0] += u32::from(full.patch_level);
        levels[1] += u32::from(coarsest.patch_level);
    }
    assert!(coarsened > 0, "the counts hid nothing");
    assert!(finer > 0, "no block kept finer by its lost pixels");
    // The greedy share is not monotone in what it is given: a block whose
    // step was among the last taken can fall outside when the steps before
    // it relieve more (1 of 104 here, against 42 drawn finer).
    assert!(
        coarser * 50 <= counted && coarser * 10 <= finer,
        "{coarser} of {counted} counted blocks coarser, {finer} finer"
    );
    assert!(levels[1] > levels[0], "levels {levels:?}");
    // Not drawn when counted: its shortfall is all hidden.
    assert_eq!(counted_at(NOT_DRAWN).blocks, at_full.blocks);
}

/// Ground the view model does not read still counts towards the frame's
/// share over tau. A merged node is drawn within tau by its bound, and its
/// model is never read; counts say how many of the frame's pixels it
/// shows (every other patch here shows 100). With those pixels counted
/// the frame may put more pixels over tau elsewhere: it draws fewer
/// triangles than with the same counts less the node's, and some blocks
/// are coarser. (Not every block: the budget a greedy share's last step
/// leaves is spent taking refinements back, and a smaller budget can
/// leave more of it, so one block may end finer with the larger budget.)
#[test]
fn pixels_of_ground_held_within_tau_count_towards_the_frames_share() {
    let terrain = dem_terrain(16, DVec2::ZERO);
    let table = terrain.error_table();
    let sight = terrain.sight_table();
    let hierarchy = Hierarchy::new(&terrain, &table);
    let grid = terrain.grid();
    // The DEM's grazing view merges smooth far ground from 4 px on.
    let camera = vkterrain::bench::cameras::named_views(terrain.info())
        .into_iter()
        .find(|v| v.name == "grazing")
        .expect("the grazing view")
        .camera;
    let view = FrameView::new(&terrain, &camera, 1280, 720).lod_view(Tau::new(4.0).unwrap());
    let node = *planned_seen(&terrain, (&hierarchy, &table, sight), &view, None)
        .merged
        .first()
        .expect("a merged node");
    let (cols, rows) = node.patch_range(grid);
    let in_node = |p: usize| {
        let id = grid.patch_id(p);
        (cols[0]..cols[1]).contains(&id.col) && (rows[0]..rows[1]).contains(&id.row)
    };
    let with = |node_shows: u32| {
        let counts: Vec<u32> = (0..grid.patch_count())
            .map(|p| if in_node(p) { node_shows } else { 100 })
            .collect();
        let seen = SeenPixels::new(grid, &counts, &vec![0; counts.len()]).unwrap();
        planned_seen(&terrain, (&hierarchy, &table, sight), &view, Some(&seen))
    };
    let (hidden, shown) = (with(0), with(200_000));
    for frame in [&hidden, &shown] {
        assert!(frame.merged.contains(&node), "the node is merged");
    }
    assert_eq!(hidden.blocks.len(), shown.blocks.len());
    let mut coarser = 0;
    for (after, before) in shown.blocks.iter().zip(&hidden.blocks) {
        assert_eq!(
            (after.col, after.row, after.level),
            (before.col, before.row, before.level)
        );
        coarser += usize::from(after.patch_level < before.patch_level);
    }
    assert!(
        coarser > 0,
        "no block coarser with the node's pixels counted"
    );
    let (drawn_shown, drawn_hidden) = (
        planned_triangles(&shown, grid),
        planned_triangles(&hidden, grid),
    );
    assert!(
        drawn_shown < drawn_hidden,
        "{drawn_shown} triangles with the node's pixels counted, {drawn_hidden} without"
    );
}

/// The triangles `frame`'s blocks draw: each patch 2 x 4^level, or its
/// cells' two triangles each at full resolution.
fn planned_triangles(frame: &FramePlan, grid: &PatchGrid) -> u64 {
    frame
        .blocks
        .iter()
        .flat_map(|b| b.patches(grid).map(move |p| (b, p)))
        .map(|(b, p)| {
            let rect = grid.sample_rect(grid.patch_id(p));
            match b.full_resolution {
                true => 2 * (rect.cells_x() * rect.cells_z()) as u64,
                false => 2 << (2 * u64::from(b.patch_level)),
            }
        })
        .sum()
}

/// A block's entry adds its patches' areas and, read by its largest
/// shares, keeps their largest errors: seen from anywhere, it puts at least
/// as large a share of its pixels over any error as each of them. The
/// cache's bytes give the same table.
#[test]
fn block_entries_bound_their_patches_and_survive_the_cache() {
    let terrain = dem_terrain(16, DVec2::ZERO);
    let sight = terrain.sight_table().expect("the DEM is held whole");
    let grid = terrain.grid();
    let bytes = sight.to_bytes();
    assert_eq!(bytes.len(), SightTable::encoded_len(grid));
    let again = SightTable::from_bytes(grid, &bytes).expect("its own bytes");
    assert_eq!(&again, sight);
    assert!(SightTable::from_bytes(grid, &bytes[1..]).is_none());

    let mut compared = 0;
    for at in [
        LatticePoint::new(1.0, 0.3, 0.02),
        LatticePoint::new(-0.4, 1.0, 0.3),
        LatticePoint::new(0.2, -1.0, 1.5),
    ] {
        for (col, row) in [(0usize, 0usize), (2, 4), (4, 2)] {
            let block = Block { level: 1, col, row };
            let Some(whole) = sight
                .view(block, &at, 5.0, BlockShares::Largest)
                .map(|v| sight.codes(&v))
            else {
                continue;
            };
            let children: Vec<_> = [(0, 0), (1, 0), (0, 1), (1, 1)]
                .map(|(dc, dr)| Block {
                    level: 0,
                    col: 2 * col + dc,
                    row: 2 * row + dr,
                })
                .iter()
                .map(|&b| {
                    sight.codes(
                        &sight
                            .view(b, &at, 5.0, BlockShares::Largest)
                            .expect("a whole block's patch"),
                    )
                })
                .collect();
            let area: f32 = children.iter().map(|c| c.area()).sum();
            assert!((whole.area() - area).abs() <= 1e-3 * area, "{block:?}");
            for k in 0..LEVELS {
                for child in &children {
                    assert!(whole.over_fraction(k) >= child.over_fraction(k) - 1e-6);
                }
                // Finer levels never put more over.
                if k + 1 < LEVELS {
                    assert!(whole.over_fraction(k + 1) <= whole.over_fraction(k) + 1e-6);
                }
            }
            compared += 1;
        }
    }
    assert!(compared >= 6);
}

/// Read by its pooled shares, a block of one rough patch among three flat
/// ones puts the rough patch's own pixels over an error, within a stored
/// share's step of them either way (the reading runs between the two
/// stored shares around the error, and so does the truth); its largest
/// shares, which take the rough patch's share for the whole block, put
/// more there.
#[test]
fn pooled_block_shares_count_a_rough_patch_for_its_own_pixels() {
    // 33 x 33 samples in 16-cell patches: a 2x2 block; ridges run across
    // half of the upper-left patch, the rest a plane.
    let map = Heightmap::from_fn(33, 33, |r, c| {
        let plane = 0.5 * c as f32 + 0.2 * r as f32;
        match (r < 16, c < 8) {
            (true, true) => plane + if (r + c) % 2 == 0 { 3.0 } else { 0.0 },
            _ => plane,
        }
    })
    .unwrap();
    let info = TerrainInfo::new(map, DVec2::splat(10.0), 16, DVec2::ZERO).unwrap();
    let terrain = Terrain::new(info, 0.0).unwrap();
    let sight = terrain.sight_table().unwrap();
    let block = Block {
        level: 1,
        col: 0,
        row: 0,
    };
    let patch = |col, row| Block { level: 0, col, row };
    let (mut compared, mut below_largest) = (0, 0);
    for at in [
        LatticePoint::new(1.0, 0.0, 0.07),
        LatticePoint::new(-0.3, 1.0, 0.36),
    ] {
        for error in [0.05, 0.2, 0.8] {
            let read =
                |b, shares| sight.codes(&sight.view(b, &at, error, shares).expect("an entry"));
            let rough = read(patch(0, 0), BlockShares::Pooled);
            let pooled = read(block, BlockShares::Pooled);
            let largest = read(block, BlockShares::Largest);
            let rough_share = rough.area() / pooled.area();
            for k in 0..3 {
                let r = rough.over_fraction(k);
                if r < 1e-3 {
                    continue;
                }
                for flat in [patch(1, 0), patch(0, 1), patch(1, 1)] {
                    let f = read(flat, BlockShares::Pooled).over_fraction(k);
                    assert!(f < 1e-6, "a plane is drawn exactly at level {k}: {f}");
                }
                // Within a stored share's step (a factor of 4) of the rough
                // patch's own pixels, either way.
                let own = r * rough_share;
                let p = pooled.over_fraction(k);
                assert!(
                    p >= own / 4.0 - 1e-6 && p <= 4.0 * own + 1e-6,
                    "level {k}, error {error}: pooled {p}, the rough patch's {own}"
                );
                assert!(largest.over_fraction(k) >= r - 1e-6, "level {k}");
                below_largest += usize::from(p < largest.over_fraction(k) - 1e-6);
                compared += 1;
            }
        }
    }
    assert!(compared >= 6, "{compared}");
    assert!(
        below_largest >= compared / 2,
        "{below_largest} of {compared}"
    );
}

/// The far remainders (patches narrower than the rest) have entries laid
/// out as the tessellator cuts them, their vertices between samples: on a
/// plane every level is the surface and no pixel is over any error; on a
/// curved map the coarse levels put pixels over a small error and full
/// resolution none. No block of patches decided at once holds a narrower
/// one.
#[test]
fn narrower_patches_have_entries_of_their_own() {
    // 57 x 37 samples in 16-cell patches: a last column 8 cells wide and
    // a last row 4 cells deep.
    let sight_of = |height: fn(f32, f32) -> f32| {
        let map = Heightmap::from_fn(57, 37, |r, c| height(c as f32, r as f32)).unwrap();
        let info = TerrainInfo::new(map, DVec2::splat(10.0), 16, DVec2::ZERO).unwrap();
        let terrain = Terrain::new(info, 0.0).unwrap();
        let sight = terrain.sight_table().unwrap().clone();
        (terrain, sight)
    };
    let (terrain, plane) = sight_of(|x, z| 3.0 * x - 2.0 * z + 100.0);
    let (_, curved) = sight_of(|x, z| 0.4 * (x - 20.0).powi(2) + 0.3 * (z - 18.0).powi(2));
    let grid = terrain.grid();
    assert_eq!((grid.patch_cols(), grid.patch_rows()), (4, 3));
    let at = LatticePoint::new(1.0, 0.4, 0.3);
    let narrower = [(3usize, 0usize, 8usize), (0, 2, 4), (3, 2, 4)];
    for (col, row, side) in narrower {
        let block = Block { level: 0, col, row };
        let flat = plane.codes(
            &plane
                .view(block, &at, 1e-3, BlockShares::Pooled)
                .expect("a narrower patch's entry"),
        );
        let bent = curved.codes(
            &curved
                .view(block, &at, 1e-3, BlockShares::Pooled)
                .expect("a narrower patch's entry"),
        );
        // Level k has 2^k segments; from the first reaching the smaller
        // side on, full resolution.
        let full = side.trailing_zeros() as usize;
        for k in 0..LEVELS {
            assert_eq!(flat.over_fraction(k), 0.0, "{block:?} level {k} on a plane");
            if k < full {
                assert!(bent.over_fraction(k) > 0.0, "{block:?} level {k} curved");
            } else {
                assert_eq!(bent.over_fraction(k), 0.0, "{block:?} level {k}");
            }
        }
    }
    // Of the blocks of 2x2 patches, the first holds four full-size ones;
    // the one beside it two of the narrower last column.
    let block = |col| Block {
        level: 1,
        col,
        row: 0,
    };
    assert!(curved.has(block(0)));
    assert!(!curved.has(block(1)));
}

/// A planner kept from frame to frame plans each frame as a fresh one
/// does: its buffers, grown on one view or path, carry nothing into the
/// next. The DEM's bench views in turn, each read for both paths, then
/// the same frames backwards.
#[test]
fn a_planner_kept_across_frames_plans_each_frame_as_a_fresh_one() {
    use vkterrain::bench::cameras::named_views;
    use vkterrain::lod::plan::Planner;
    let terrain = dem_terrain(32, DVec2::ZERO);
    let table = terrain.error_table();
    let sight = terrain.sight_table().expect("a heightmap's view model");
    let hierarchy = Hierarchy::new(&terrain, &table);
    let mut frames = Vec::new();
    for view in named_views(terrain.info()) {
        for tau in [0.5, 2.0] {
            let view =
                FrameView::new(&terrain, &view.camera, 1280, 720).lod_view(Tau::new(tau).unwrap());
            for reading in [SightReading::Tessellated, SightReading::Template] {
                frames.push((view, reading));
            }
        }
    }
    let mut planner = Planner::default();
    let mut blocks = 0;
    for (view, reading) in frames.iter().chain(frames.iter().rev()) {
        let inputs = PlanInputs {
            table: &table,
            sight: Some(sight),
            merge: *reading == SightReading::Tessellated,
            cull: true,
            reading: *reading,
            seen: None,
        };
        let fresh = plan(&terrain, &hierarchy, view, &inputs);
        assert_eq!(planner.plan(&terrain, &hierarchy, view, &inputs), &fresh);
        assert!(fresh.blocks.iter().any(|b| b.chosen), "{reading:?}");
        blocks += fresh.blocks.len();
    }
    assert!(blocks >= 2 * frames.len() * 20, "{blocks} blocks planned");
}

/// The plan takes a node to have a view-model entry exactly where it is a
/// patch, or a whole block of full-size patches no larger than the
/// model's blocks (the rule `walk` follows instead of a lookup, which
/// debug builds assert and release builds do not): on the DEM, whose
/// last column and row of patches are narrower, every node of every
/// block level agrees with the table.
#[test]
fn the_model_has_an_entry_for_every_patch_and_every_whole_block() {
    use vkterrain::terrain::sight::BLOCK_LEVELS;
    let terrain = dem_terrain(32, DVec2::ZERO);
    let table = terrain.error_table();
    let sight = terrain.sight_table().expect("a heightmap's view model");
    let hierarchy = Hierarchy::new(&terrain, &table);
    let (mut whole, mut cut) = ([0usize; BLOCK_LEVELS as usize + 1], 0);
    let mut stack = vec![hierarchy.root()];
    while let Some(id) = stack.pop() {
        hierarchy.for_each_child(id, |child, _| stack.push(child));
        if id.level > BLOCK_LEVELS {
            continue;
        }
        let node = hierarchy.node(id);
        let block = Block {
            level: id.level,
            col: id.col as usize,
            row: id.row as usize,
        };
        let expected = id.level == 0 || node.whole;
        assert_eq!(sight.has(block), expected, "{id:?}");
        match node.whole {
            true => whole[id.level as usize] += 1,
            false => cut += usize::from(id.level > 0),
        }
    }
    // Both kinds occur at every block level: the test sees the rule.
    assert!(whole.iter().all(|&n| n > 0), "{whole:?}");
    assert!(
        cut >= BLOCK_LEVELS as usize,
        "{cut} blocks cut by the far sides"
    );
}

/// The geomip path glides a block towards its next coarser level only
/// where the view model puts no pixel over tau there. On terraces seen
/// from a low eye the face-on bound accepts coarser levels that the model,
/// which sees the walls' risers, does not: those blocks keep their level
/// whole (`block_glide` 0) though the bound alone would glide them. Without
/// the model every block the bound places glides as the bound says.
#[test]
fn geomip_blocks_glide_only_where_the_model_counts_nothing_over_tau() {
    let map = Heightmap::from_fn(129, 129, |r, c| {
        let (x, z) = (c as f32 - 64.0, r as f32 - 64.0);
        let cone = (120.0 - 2.0 * (x * x + z * z).sqrt()).max(0.0);
        10.0 * (cone / 10.0).floor() + 0.5 * (0.7 * z).sin() * (0.5 * x).cos()
    })
    .unwrap();
    let info = TerrainInfo::new(map, DVec2::splat(10.0), 16, DVec2::ZERO).unwrap();
    let terrain = Terrain::new(info, 0.0).unwrap();
    let table = terrain.error_table();
    let hierarchy = Hierarchy::new(&terrain, &table);
    let sight = terrain.sight_table().expect("a view model");
    let view = view_of(
        &terrain,
        DVec3::new(-700.0, 60.0, -500.0),
        DVec3::new(200.0, 0.0, 300.0),
        1.0,
    );
    let levels = vkterrain::lod::geomip::level_count(16);
    let glide = |b: &PlannedBlock| {
        let k = usize::from(b.patch_level).min(levels - 1);
        vkterrain::lod::geomip::block_glide(b, k, &hierarchy, &view)
    };
    let template = |sight| {
        plan(
            &terrain,
            &hierarchy,
            &view,
            &PlanInputs {
                table: &table,
                sight,
                merge: false,
                cull: true,
                reading: SightReading::Template,
                seen: None,
            },
        )
    };
    let modelled = template(Some(sight));
    let (mut held, mut gliding) = (0, 0);
    for b in &modelled.blocks {
        let bound_alone = glide(&PlannedBlock {
            coarser_over_px: 0.0,
            ..*b
        });
        if b.chosen {
            assert_eq!(b.coarser_over_px, 0.0, "{b:?}");
            assert_eq!(glide(b), 0.0, "{b:?}");
        } else if b.coarser_over_px > 0.0 {
            assert_eq!(glide(b), 0.0, "{b:?}");
            held += usize::from(bound_alone > 0.0);
        } else {
            assert_eq!(glide(b), bound_alone, "{b:?}");
            gliding += usize::from(bound_alone > 0.0);
        }
    }
    assert!(held >= 1, "{held} blocks held, {gliding} gliding");
    let bound = template(None);
    assert!(bound.blocks.iter().all(|b| b.coarser_over_px == 0.0));
    assert!(
        bound.blocks.iter().filter(|b| glide(b) > 0.0).count() >= held,
        "the bound alone glides"
    );
}

/// One 16-cell patch 400 m across: flat ground with bumps a metre high,
/// and along its far side a ridge rising 400 m, which puts an eye over the
/// flat ground inside the patch's box.
fn ridge_patch() -> Terrain {
    let map = Heightmap::from_fn(17, 17, |r, c| {
        let bumps = ((r * 7 + c * 3) % 5) as f32 * 0.25;
        bumps
            + if c >= 12 {
                100.0 * (c - 12) as f32
            } else {
                0.0
            }
    })
    .unwrap();
    let info = TerrainInfo::new(map, DVec2::splat(25.0), 16, DVec2::ZERO).unwrap();
    Terrain::new(info, 0.0).unwrap()
}

/// The patch whose box holds the eye is seen from where its ground lies,
/// not from inside its box: from 100 m over its flat ground it is drawn
/// coarser than full resolution, told to the control shader as chosen,
/// within tau as its error is seen from the nearest its drawn surface can
/// come; from 2 m over the bumps, at full resolution.
#[test]
fn the_patch_holding_the_eye_is_seen_from_its_ground() {
    let terrain = ridge_patch();
    let table = terrain.error_table();
    let info = terrain.info();
    let (x, z) = (info.local_x(4), info.local_z(8));
    let tau = 16.0;
    for (height, coarser) in [(100.0, true), (2.0, false)] {
        let eye = DVec3::new(x, height, z);
        let view = view_of(&terrain, eye, DVec3::new(info.local_x(16), 0.0, z), tau);
        let (lo, hi) = info.min_max();
        assert!(
            lo < eye.y as f32 && (eye.y as f32) < hi,
            "the box holds the eye"
        );
        for sight in [None, terrain.sight_table()] {
            let frame = planned(&terrain, &table, sight, &view);
            let block = block_holding(&frame, terrain.grid(), 0).expect("the patch is drawn");
            assert_eq!(
                !block.full_resolution, coarser,
                "eye {height} m up: level {}",
                block.patch_level
            );
            if coarser {
                assert!(block.chosen && usize::from(block.patch_level) < LEVEL_COUNT - 1);
                assert!(block.predicted_px > 0.0 && block.predicted_px <= tau);
            }
        }
    }
}

/// 257 x 257 samples 10 m apart in 16-cell patches: a plain at 0 with
/// bumps up to 2.5 m, and, where `wall`, a 200 m wall across its whole
/// width over sample rows 60 to 84 (patch row 4 whole).
fn walled_plain(wall: bool) -> Terrain {
    plain_with_wall(wall.then_some(60..=84), 16)
}

/// 257 x 257 samples 10 m apart in `cells`-cell patches: a plain at 0 with
/// bumps up to 2.5 m, and a 200 m wall across its whole width over the
/// sample rows `wall`.
fn plain_with_wall(wall: Option<std::ops::RangeInclusive<usize>>, cells: u32) -> Terrain {
    let map = Heightmap::from_fn(257, 257, |r, c| {
        let bumps = ((r * 7 + c * 13) % 11) as f32 * 0.25;
        match wall.as_ref().is_some_and(|w| w.contains(&r)) {
            true => 200.0,
            false => bumps,
        }
    })
    .unwrap();
    let info = TerrainInfo::new(map, DVec2::splat(10.0), cells, DVec2::ZERO).unwrap();
    Terrain::new(info, 0.0).unwrap()
}

/// The plan at 1 px of `terrain` (a `plain_with_wall`) from `height` m up
/// at local z `z` over its middle column, looking down the plain towards
/// its last row.
fn planned_down_the_plain(terrain: &Terrain, height: f64, z: f64) -> FramePlan {
    let info = terrain.info();
    let x = info.local_x(128);
    let view = view_of(
        terrain,
        DVec3::new(x, height, z),
        DVec3::new(x, 0.0, info.local_z(256)),
        1.0,
    );
    let table = terrain.error_table();
    planned(terrain, &table, terrain.sight_table(), &view)
}

/// The blocks of `frame` wholly in patch rows `row` on.
fn blocks_from_row<'f>(
    frame: &'f FramePlan,
    grid: &PatchGrid,
    row: usize,
) -> Vec<&'f PlannedBlock> {
    frame
        .blocks
        .iter()
        .filter(|b| b.patches(grid).all(|p| grid.patch_id(p).row >= row))
        .collect()
}

/// A ridge inside a patch large on screen hides the ground behind it
/// without counts, though the patch's mean lies far below it: the patch
/// also hides as its parts, each solid up to its own mean
/// (`terrain::slabs`). From 60 m over the plain, 100 m before its edge,
/// a 40 m-wide, 200 m ridge 400 m in, inside the first row of 640 m
/// patches (its mean 17 m), leaves every block beyond that row at the
/// coarsest level; without the ridge, they need finer ones.
#[test]
fn a_ridge_inside_a_near_patch_hides_the_ground_behind_it() {
    let coarsest_beyond = |ridge: bool| {
        let terrain = plain_with_wall(ridge.then_some(40..=44), 64);
        let z = terrain.info().local_z(0) + 100.0;
        let frame = planned_down_the_plain(&terrain, 60.0, z);
        let beyond = blocks_from_row(&frame, terrain.grid(), 1);
        assert!(beyond.len() >= 4, "{} blocks beyond", beyond.len());
        beyond.iter().all(|b| b.patch_level == 0)
    };
    assert!(
        !coarsest_beyond(false),
        "the bumps need finer levels in view"
    );
    assert!(coarsest_beyond(true), "ground behind the ridge is refined");
}

/// Without counts, ground that nearer ground hides is not
/// refined (`lod::horizon`): from 20 m over a bumpy plain, the bumps 1 to
/// 2.4 km off need finer levels than the coarsest at 1 px, but behind a
/// 200 m wall every block of them takes the coarsest level. The wall's
/// own blocks, and the ground before it, are refined as before.
#[test]
fn ground_behind_a_wall_is_not_refined_without_counts() {
    let coarsest_behind = |wall: bool| {
        let terrain = walled_plain(wall);
        let frame = planned_down_the_plain(&terrain, 20.0, terrain.info().local_z(20));
        let grid = terrain.grid();
        // Blocks wholly in patch rows 8 on: 1.1 km and more from the eye.
        let behind = blocks_from_row(&frame, grid, 8);
        assert!(behind.len() >= 10, "{} blocks behind", behind.len());
        let before = frame
            .blocks
            .iter()
            .filter(|b| b.patches(grid).all(|p| grid.patch_id(p).row == 2))
            .map(|b| b.patch_level)
            .max();
        (behind.iter().all(|b| b.patch_level == 0), before)
    };
    let (open, open_before) = coarsest_behind(false);
    let (walled, walled_before) = coarsest_behind(true);
    assert!(
        !open,
        "the bumps need finer levels where nothing hides them"
    );
    assert!(walled, "hidden bumps are refined");
    assert_eq!(open_before, walled_before);
    assert!(open_before > Some(0));
}
