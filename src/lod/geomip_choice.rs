//! The geomip path's level choice: every patch's level and morph factor
//! for one view, by distance or by the error plan, balanced so that
//! neighbours differ by at most one level, and the list of patches drawn.
//! Its buffers are kept from frame to frame, and only what the last choice
//! wrote is reset, so a choice costs what is in view, not the grid.

use glam::Vec3;

use super::buffers::touched;
use super::factors::box_distance;
use super::geomip::{self, Balancing, PatchLevels, PatchRect as Rect, StitchErrors};
use super::hierarchy::{rect_bounds, rect_rows, Hierarchy, NodeId};
use super::plan::{PlanInputs, PlannedBlock, Planner};
use super::view::LodView;
use crate::terrain::grid::{PatchGrid, PatchId};
use crate::terrain::Terrain;

/// A choice of levels for every patch (`by_distance`, `by_error`), which
/// the geomip path turns into draws: a frame slot's, kept from its last
/// frame so that a choice fills memory it filled before.
#[derive(Debug, Default)]
pub struct ChosenPatches {
    /// Every patch's level and morph factor.
    levels: geomip::PatchLevels,
    /// One flag per patch: whether it is drawn.
    drawn: Vec<bool>,
    /// The drawn patches, in grid order.
    visible: Vec<u32>,
    /// The error LOD's blocks as columns and rows of patches.
    rects: Vec<Rect>,
    /// The distance LOD's blocks' levels and their boxes' farthest
    /// distances, one per block of `rects`.
    decided: Vec<(u8, f32)>,
    /// The distance LOD's walk: nodes still to visit, and whether each is
    /// known to lie wholly in view.
    stack: Vec<(NodeId, bool)>,
    /// Refining and balancing's buffers.
    balancing: Balancing,
    /// Where the last choice may have left entries unlike `reset`'s;
    /// None: anywhere.
    written: Option<Written>,
}

/// The patches a choice may have changed from `ChosenPatches::reset`'s
/// state, on the grid it was sized for (its columns, its coarsest level).
#[derive(Clone, Copy, Debug)]
struct Written {
    cols: usize,
    coarsest: u8,
    rect: Rect,
    /// Within `rect`, where morph factors may have been written.
    morph: Rect,
}

impl ChosenPatches {
    /// Room for the levels, morph factors and flags of `patches` patches,
    /// the list of those drawn, and `blocks` blocks, their memory written
    /// once (`buffers::touched`): the first choice's `reset` sizes them to
    /// the grid, and finds its pages already the process's.
    pub fn with_capacity(patches: usize, blocks: usize) -> Self {
        let mut chosen = ChosenPatches::default();
        touched(&mut chosen.levels.levels, patches);
        touched(&mut chosen.levels.morph, patches);
        touched(&mut chosen.drawn, patches);
        touched(&mut chosen.visible, patches);
        touched(&mut chosen.rects, blocks);
        touched(&mut chosen.decided, blocks);
        chosen
    }

    /// Every patch of `grid` at level `coarsest`, with no morph and not
    /// drawn. Where the last choice was on the same grid, only the patches
    /// it wrote are reset (`Written`), so a frame's choice costs what is
    /// in view, not the grid.
    fn reset(&mut self, grid: &PatchGrid, coarsest: u8) {
        let (patches, cols) = (grid.patch_count(), grid.patch_cols());
        let PatchLevels { levels, morph } = &mut self.levels;
        match self.written.take() {
            Some(w) if w.cols == cols && w.coarsest == coarsest && levels.len() == patches => {
                for row in rect_rows(cols, w.rect) {
                    levels[row.clone()].fill(coarsest);
                    self.drawn[row].fill(false);
                }
                for row in rect_rows(cols, w.morph) {
                    morph[row].fill(0.0);
                }
            }
            _ => {
                levels.clear();
                levels.resize(patches, coarsest);
                morph.clear();
                morph.resize(patches, 0.0);
                self.drawn.clear();
                self.drawn.resize(patches, false);
            }
        }
        self.visible.clear();
        self.rects.clear();
        self.decided.clear();
    }

    /// Notes what a choice on `grid` drew (`drawn`: the bounds of its drawn
    /// patches, None for none) for the next `reset`: those patches, and
    /// those refining and balancing can have lowered around them
    /// (`geomip::balance_reach`); and the bounds of the blocks it wrote
    /// morph factors in (`morph`), all within the drawn ones.
    fn wrote(
        &mut self,
        grid: &PatchGrid,
        coarsest: u8,
        (drawn, morph): (Option<Rect>, Option<Rect>),
    ) {
        let reach = geomip::balance_reach(grid.cells_per_patch());
        let rect = drawn.map_or(([0, 0], [0, 0]), |([c0, c1], [r0, r1])| {
            (
                [
                    c0.saturating_sub(reach),
                    (c1 + reach).min(grid.patch_cols()),
                ],
                [
                    r0.saturating_sub(reach),
                    (r1 + reach).min(grid.patch_rows()),
                ],
            )
        });
        self.written = Some(Written {
            cols: grid.patch_cols(),
            coarsest,
            rect,
            morph: morph.unwrap_or_default(),
        });
    }

    /// `visible` from the drawn flags of the patches in `within` (of a grid
    /// `cols` patches wide; none are drawn outside it), in grid order,
    /// eight flags at a time: a run of eight patches all drawn or none
    /// drawn costs one test.
    fn list_drawn(&mut self, cols: usize, within: Rect) {
        let visible = &mut self.visible;
        visible.clear();
        for row in rect_rows(cols, within) {
            let flags: &[u8] = bytemuck::cast_slice(&self.drawn[row.clone()]);
            let words = flags.chunks_exact(8);
            let rest = words.remainder();
            let mut first = row.start as u32;
            for word in words {
                let bits = u64::from_le_bytes(word.try_into().expect("eight flags"));
                match bits {
                    0 => {}
                    ALL_DRAWN => visible.extend(first..first + 8),
                    _ => push_flagged(visible, first, word),
                }
                first += 8;
            }
            push_flagged(visible, first, rest);
        }
    }
}

/// Pushes `first + i` for each flag `i` of `flags` that is set.
fn push_flagged(out: &mut Vec<u32>, first: u32, flags: &[u8]) {
    out.extend(
        (first..)
            .zip(flags)
            .filter(|(_, &flag)| flag != 0)
            .map(|(p, _)| p),
    );
}

/// Eight drawn flags (`true` is 1) read as one little-endian word.
const ALL_DRAWN: u64 = 0x0101_0101_0101_0101;

impl ChosenPatches {
    /// Every patch's level and morph factor.
    pub fn levels(&self) -> &PatchLevels {
        &self.levels
    }

    /// The drawn patches, in grid order.
    pub fn visible(&self) -> &[u32] {
        &self.visible
    }

    /// Levels by distance (`geomip::level_for_distance` from `min_dist`,
    /// the finest level's reach) for the patches in `view` (all of them
    /// without `cull`), refined and balanced, with their morph factors.
    ///
    /// The hierarchy is walked from its top node down, as far as it takes
    /// to find blocks in view whose patches all share one level: a node
    /// wholly in the frustum whose box's nearest and farthest points are at
    /// the same level is drawn whole, at that level, since every patch's
    /// distance lies between the two. Balancing then looks only beyond the
    /// blocks' sides (`refine_and_balance_blocks`), and morph factors are
    /// found patch by patch only in blocks where one can be above 0: a
    /// patch balancing lowered, or one whose box reaches 70 % of its
    /// level's far distance (`geomip::morph_factor`). The levels, morph
    /// factors and drawn patches are those of deciding every patch in view
    /// on its own, in time that grows with the blocks, not the patches.
    pub fn by_distance(
        &mut self,
        terrain: &Terrain,
        hierarchy: &Hierarchy,
        view: &LodView,
        (cull, min_dist): (bool, f32),
    ) {
        let grid = terrain.grid();
        let count = geomip::level_count(grid.cells_per_patch());
        // Every patch starts at the coarsest level, and those in view get
        // theirs; the coarsest constrains no neighbour.
        let coarsest = (count - 1) as u8;
        self.reset(grid, coarsest);
        let cols = grid.patch_cols();
        let eye = view.eye_local;
        let level_at = |d: f32| geomip::level_for_distance(d, min_dist, count) as u8;
        let PatchLevels { levels, morph } = &mut self.levels;
        // Nodes still to visit, each with whether it is known to lie wholly
        // in view (every node without `cull`).
        let stack = &mut self.stack;
        stack.clear();
        stack.push((hierarchy.root(), !cull));
        while let Some((id, known_inside)) = stack.pop() {
            let (lo, hi) = hierarchy.node(id).aabb();
            let (lo, hi) = (lo - eye, hi - eye);
            let inside = known_inside || {
                let (centre, half) = (0.5 * (lo + hi), 0.5 * (hi - lo));
                if view.frustum.aabb_outside(centre, half) {
                    continue;
                }
                // A patch not outside is drawn, as `patches_in_view` finds.
                id.level == 0 || view.frustum.aabb_inside(centre, half)
            };
            let (near, far) = (box_distance(lo, hi), lo.abs().max(hi.abs()).length());
            let level = level_at(near);
            if !inside || (id.level > 0 && level_at(far) != level) {
                hierarchy.for_each_child(id, |c, _| stack.push((c, inside)));
                continue;
            }
            let rect = hierarchy.patch_range(id);
            let at = (level, coarsest, 0.0);
            draw_block((levels, morph, &mut self.drawn), cols, rect, at);
            self.rects.push(rect);
            self.decided.push((level, far));
        }
        // A block's patches share its level: only its sides can lower a
        // neighbour.
        let (drawn, rects) = (&self.drawn, &self.rects);
        self.balancing.blocks(levels, grid, (drawn, rects), |_| {
            [true; geomip::BLOCK_SIDES]
        });
        // Morph factors follow the balanced levels. A block whose patches
        // kept its level and whose farthest point has no morph at it has
        // none anywhere: the factor grows with distance.
        let mut morphed = None;
        for (&rect, &(level, far)) in self.rects.iter().zip(&self.decided) {
            let kept = rect_rows(cols, rect).all(|row| levels[row].iter().all(|&l| l == level));
            let l = usize::from(level);
            if kept && (l + 1 >= count || geomip::morph_factor(far, min_dist, l) <= 0.0) {
                continue;
            }
            morphed = rect_bounds(morphed.into_iter().chain([rect]));
            let ([c0, c1], [r0, r1]) = rect;
            for row in r0..r1 {
                for col in c0..c1 {
                    let p = row * cols + col;
                    let l = usize::from(levels[p]);
                    if l + 1 < count {
                        let d = patch_distance(hierarchy, PatchId { row, col }, eye);
                        morph[p] = geomip::morph_factor(d, min_dist, l);
                    }
                }
            }
        }
        let drawn = rect_bounds(self.rects.iter().copied());
        self.list_drawn(cols, drawn.unwrap_or_default());
        self.wrote(grid, coarsest, (drawn, morphed));
    }

    /// Levels from the error plan (`Planner::plan` with `inputs`): a
    /// block's patches take its level (`geomip::level_of_index`) and glide
    /// towards the next coarser one (`geomip::block_glide`); a block's
    /// sides that may not be stitched (`geomip::stitchable_sides`, from
    /// `stitch`) keep a drawn neighbour at its level; then the levels are
    /// refined and balanced. Returns the plan's predicted share of pixels
    /// over tau (`FramePlan::predicted_over_share`).
    pub fn by_error(
        &mut self,
        terrain: &Terrain,
        hierarchy: &Hierarchy,
        view: &LodView,
        (planner, inputs): (&mut Planner, &PlanInputs),
        stitch: Option<&StitchErrors>,
    ) -> Option<f32> {
        let grid = terrain.grid();
        let count = geomip::level_count(grid.cells_per_patch());
        let coarsest = (count - 1) as u8;
        self.reset(grid, coarsest);
        let PatchLevels { levels, morph } = &mut self.levels;
        let frame_plan = planner.plan(terrain, hierarchy, view, inputs);
        let cols = grid.patch_cols();
        // A block's level index (2^k segments a patch side).
        let index = |block: &PlannedBlock| usize::from(block.patch_level).min(count - 1);
        let mut morphed = None;
        for block in &frame_plan.blocks {
            let k = index(block);
            let level = geomip::level_of_index(k, count) as u8;
            let glide = geomip::block_glide(block, k, hierarchy, view);
            let rect = block.patch_range(grid);
            if glide > 0.0 {
                morphed = rect_bounds(morphed.into_iter().chain([rect]));
            }
            let at = (level, coarsest, glide);
            draw_block((levels, morph, &mut self.drawn), cols, rect, at);
            self.rects.push(rect);
        }
        // A block's patches share its level: only its sides can lower a
        // neighbour.
        let blocks = &frame_plan.blocks;
        let (drawn, rects) = (&self.drawn, &self.rects);
        self.balancing.blocks(levels, grid, (drawn, rects), |i| {
            geomip::stitchable_sides(
                (&blocks[i], index(&blocks[i])),
                (hierarchy, grid),
                view,
                stitch,
            )
        });
        let drawn = rect_bounds(self.rects.iter().copied());
        self.list_drawn(cols, drawn.unwrap_or_default());
        self.wrote(grid, coarsest, (drawn, morphed));
        frame_plan.predicted_over_share
    }
}

/// Marks the patches of `rect` (of a grid `cols` patches wide) drawn at
/// `level`, each gliding `glide` towards the next coarser level. Every
/// patch starts at the `coarsest` level with no glide (`reset`), so a
/// block at the coarsest level, or with no glide, leaves those as they
/// are.
fn draw_block(
    (levels, morph, drawn): (&mut [u8], &mut [f32], &mut [bool]),
    cols: usize,
    rect: Rect,
    (level, coarsest, glide): (u8, u8, f32),
) {
    for row in rect_rows(cols, rect) {
        if level != coarsest {
            levels[row.clone()].fill(level);
        }
        if glide > 0.0 {
            morph[row.clone()].fill(glide);
        }
        drawn[row].fill(true);
    }
}

/// Distance from `eye_local` to the nearest point of patch `p`'s box (its
/// node's in `hierarchy`: one read, where the terrain's box is three).
fn patch_distance(hierarchy: &Hierarchy, p: PatchId, eye_local: Vec3) -> f32 {
    hierarchy.node(NodeId::patch(p)).distance(eye_local)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every drawn patch is listed once, in grid order, whatever runs of
    /// drawn and not drawn the flags hold within the rectangle read, the
    /// last short word of each row included.
    #[test]
    fn list_drawn_lists_each_drawn_patch_in_grid_order() {
        let (cols, rows) = (67usize, 3usize);
        let mut chosen = ChosenPatches::default();
        for within in [
            ([0, 0], [0, 0]),
            ([0, 5], [1, 2]),
            ([3, 11], [0, 3]),
            ([0, 67], [0, 3]),
            ([30, 59], [1, 3]),
        ] {
            let ([c0, c1], [r0, r1]) = within;
            // Runs of all, none and some drawn, inside the rectangle only.
            let drawn: Vec<bool> = (0..cols * rows)
                .map(|p| {
                    let (c, r) = (p % cols, p / cols);
                    (c0..c1).contains(&c)
                        && (r0..r1).contains(&r)
                        && match (p / 8) % 3 {
                            0 => true,
                            1 => false,
                            _ => p % 3 == 0,
                        }
                })
                .collect();
            chosen.drawn = drawn.clone();
            chosen.list_drawn(cols, within);
            let expected: Vec<u32> = (0..(cols * rows) as u32)
                .filter(|&p| drawn[p as usize])
                .collect();
            assert_eq!(chosen.visible, expected, "{within:?}");
        }
    }

    /// A reset after a choice leaves every patch as a reset of a fresh
    /// choice does, where the choice wrote only within the reach of what
    /// it drew; on another grid, or at another coarsest level, the whole
    /// grid is reset.
    #[test]
    fn a_reset_restores_what_the_last_choice_wrote() {
        // 32 x 16 patches of 16 cells: levels 0 to 4.
        let grid = PatchGrid::for_size(513, 257, 16);
        let (cols, coarsest) = (grid.patch_cols(), 4u8);
        let reach = geomip::balance_reach(grid.cells_per_patch());
        let mut fresh = ChosenPatches::default();
        fresh.reset(&grid, coarsest);
        let mut chosen = ChosenPatches::default();
        chosen.reset(&grid, coarsest);
        // A block drawn at the finest level, near the grid's first
        // corner, and what refining and balancing can lower around it.
        let block: Rect = ([2, 6], [1, 3]);
        for p in 0..grid.patch_count() {
            let (c, r) = (p % cols, p / cols);
            let (dc, dr) = (
                (block.0[0].saturating_sub(c)).max(c.saturating_sub(block.0[1] - 1)),
                (block.1[0].saturating_sub(r)).max(r.saturating_sub(block.1[1] - 1)),
            );
            if dc + dr == 0 {
                chosen.levels.levels[p] = 0;
                chosen.levels.morph[p] = 0.5;
                chosen.drawn[p] = true;
            } else if dc + dr <= reach {
                chosen.levels.levels[p] = (dc + dr - 1) as u8;
            }
        }
        chosen.wrote(&grid, coarsest, (Some(block), Some(block)));
        chosen.reset(&grid, coarsest);
        assert_eq!(chosen.levels.levels, fresh.levels.levels);
        assert_eq!(chosen.levels.morph, fresh.levels.morph);
        assert_eq!(chosen.drawn, fresh.drawn);
        // Another coarsest level, then another grid: everything anew.
        chosen.wrote(&grid, coarsest, (Some(block), Some(block)));
        chosen.reset(&grid, 3);
        assert!(chosen.levels.levels.iter().all(|&l| l == 3));
        let other = PatchGrid::for_size(257, 257, 16);
        chosen.wrote(&grid, 3, (None, None));
        chosen.reset(&other, 3);
        assert_eq!(chosen.levels.levels.len(), other.patch_count());
        assert_eq!(chosen.drawn.len(), other.patch_count());
    }
}
