//! The frame plan: from a terrain, its hierarchy and one view, what the
//! tess path draws and at which levels, chosen in time that grows with the
//! nodes in view, not with the terrain's samples.
//!
//! The hierarchy is walked from its top node down. A node outside the
//! frustum is left with everything under it. A node whose patches, and
//! the patches around it, would all be drawn with one segment is drawn as
//! one merged patch (`patch_merge`), by the same rule as patches, from its
//! precomputed largest one-segment error seen from its nearest point.
//!
//! **Blocks.** Where the terrain has a view model (`terrain::sight`), a
//! node of up to 2^`BLOCK_LEVELS` x 2^`BLOCK_LEVELS` whole patches that is
//! small on screen (at most `BLOCK_EXTENT_PX` across) and about as far at
//! its far side as at its near one (`BLOCK_DEPTH_RATIO`) is decided at
//! once: every patch in it takes the same level, from the block's entry
//! seen from its nearest point. Nearer ground is refined down to patches.
//! Where the plan has room (`BLOCK_BUDGET` blocks), the blocks largest on
//! screen are then split into their quarters, down to
//! `BLOCK_EXTENT_MIN_PX` across, each decided from its own nearest point.
//! So the choice visits a few thousand nodes however large the terrain,
//! while each decision still sees its ground from where it lies.
//!
//! **A block's level.** The error table bounds each level's largest
//! vertical error anywhere on a patch; seen face-on from the block's
//! nearest point, the coarsest level that keeps all of its patches within
//! tau is the bound's choice, and no block is drawn finer. The frame may
//! let a share of its terrain's pixels exceed tau (`EXCEED_SHARE`): each
//! block's pixels over tau at each coarser level are read off the view
//! model from the direction the block is seen (its rays falling to its
//! mean height, or for the geomip path to its bottom: `SightReading`;
//! the tess path reads a block's shares pooled over its patches' pixels,
//! the geomip path each share's largest over its patches: `BlockShares`),
//! and the share is spent greedily on the blocks and levels
//! that save the most triangles for it (the same exchange as the view
//! measure's, on the model's figures). A patch much deeper than it is
//! near (one near the eye) is read in parts, each from its own nearest
//! point and direction, the parts outside the frustum left out
//! (`model_parts`). A patch whose box holds the eye has no nearest point
//! there: it is seen from the nearest its ground comes instead (its cells'
//! boxes, `Terrain::surface_distances`), both by the bound, each level
//! from the nearest its drawn surface can come, and by the model, no part
//! nearer than its ground; a level coarser than its own errors draw from
//! inside its box is told to the control shader as chosen. Once earlier
//! frames of the view have counted the pixels each patch shows
//! (`lod::seen`), a block is read at the share of its pixels that
//! showed, taken of those the level it was drawn at kept
//! (what that level put over tau may have been drawn away, not hidden),
//! and the frame's pixels include those of ground whose model is not read,
//! which the bound keeps within tau (`unread_pixels`). A block that showed
//! no pixel, drawn at a level that kept some of its pixels within tau, is
//! over tau nowhere, and its model is not read (`place_parts`, checked
//! against a per-block figure derived from the model,
//! `SightTable::keeps_some_within`). A frame without
//! counts (a moving camera's, a view's first) reads
//! each block at the share of its azimuth bins where the plan's nearer
//! boxes do not hide it, each block with a model taken as solid up to its
//! mean height, and a patch at least `PARTS_HIDE_EXTENT_PX` across also
//! as its parts higher than its mean, each solid up to its own mean
//! (`lod::horizon`, `terrain::slabs`); a block hidden in every bin it spans
//! shows no pixel at any level, and its model is not read (`place_parts`).
//! Patches without a model (the far remainders, or a terrain without
//! one) keep the bound's choice, made by the control shader from their
//! own errors as before.
//!
//! A level the share chose is told to the control shader by a byte per
//! patch (`ChosenLevel`): its errors read as zero from that level on, and
//! as its own below it (`chosen_errors`). The block's level is the one its
//! roughest, nearest patch needs; a patch whose own bound, from its own
//! box, accepts a coarser level is drawn at that one, within tau, so it
//! adds no pixel over tau to what the share counted. Edges take the larger
//! errors of the two patches sharing them, so both sides still agree.

use std::collections::BinaryHeap;

use glam::{Vec2, Vec3};

use super::buffers::touched;
use super::factors::{box_distance, error_tess_factor, footprint_distance, within_tolerance};
use super::hierarchy::{rect_bounds, rect_rows, square_range, Hierarchy, Node, NodeId};
use super::horizon::Horizon;
use super::patch_merge::{node_errors, MergedNode, MAX_MERGE_LEVEL};
use super::seen::{SeenPixels, NOT_DRAWN};
use super::view::LodView;
use crate::terrain::error_table::{ErrorTable, PatchErrors, LEVEL_COUNT};
use crate::terrain::sight::{
    Block, BlockShares, BlockView, LatticePoint, SightTable, BLOCK_LEVELS,
};
use crate::terrain::slabs::SLABS_PER_PATCH;
use crate::terrain::{PatchGrid, PatchId, Terrain};

/// Share of the frame's terrain pixels the view model's choice may put
/// over tau: half the 1 % a 99th percentile allows, the other half left to
/// what the model does not see (hidden ground, silhouettes, the
/// tessellator's transitions, the lattice's interpolation).
pub const EXCEED_SHARE: f64 = 0.005;

/// The largest block decided at once, in pixels across on screen (its
/// box's diagonal, footprint and heights, seen face-on from its nearest
/// point). The bound that sizes the blocks on every bench view: the
/// fewer and larger the blocks, the cheaper the plan, and the more
/// triangles its uniform levels draw (notes section 37).
pub const BLOCK_EXTENT_PX: f32 = 128.0;

/// The smallest block split further while the plan has room
/// (`BLOCK_BUDGET`), in pixels across as `BLOCK_EXTENT_PX`.
pub const BLOCK_EXTENT_MIN_PX: f32 = 32.0;

/// The smallest patch, in pixels across as `BLOCK_EXTENT_PX`, that the
/// horizon also takes as its parts (`terrain::slabs`), each solid up to
/// its own mean (`lod::horizon`). A part hides only in the azimuth bins
/// wholly inside its span (20 to 40 px each, `horizon::BINS`): a part a
/// quarter of this across spans about two. From 128 px (a part about a
/// bin) the DEM's flythrough drew as many triangles, with more boxes in
/// the horizon (notes section 61).
pub const PARTS_HIDE_EXTENT_PX: f32 = 256.0;

/// The most blocks (patches included) a plan splits its blocks up to:
/// blocks found at `BLOCK_EXTENT_PX` are split, largest on screen first,
/// while their parts fit. A block decides its patches at one level, read
/// from its nearest point; its quarters decide theirs each from their
/// own, and the share spends its pixels on them more closely. The plan's
/// cost grows with its blocks, the model's entries read for each: the
/// 4097^2 terrain's views find 272 to 783 blocks at `BLOCK_EXTENT_PX`,
/// and their largest choices took 0.3 to 0.47 ms.
pub const BLOCK_BUDGET: usize = 512;

/// The most a block's far side may be further than its near side, for
/// the block to be decided at once: its entry is read at its nearest
/// point's distance. A guard for boxes much deeper than they are wide:
/// on the 9 fixed views of the bench's terrains the extent binds first
/// (1.5, 2 and 3 decide the same blocks).
pub const BLOCK_DEPTH_RATIO: f32 = 1.5;

/// The blocks a frame slot's planner holds room for from the start
/// (`Planner::with_capacity`): more than any bench view's plan decides
/// (783 on the 4097^2 terrain's grazing view); a larger plan grows the
/// buffers as it goes. About 3.7 MB a planner.
pub const PLANNED_BLOCKS: usize = 4096;

/// What the choice keeps within tau, and how.
#[derive(Clone, Copy, Debug)]
pub struct PlanInputs<'a> {
    /// Per-patch errors: the terrain's bound, or a table measured for
    /// this view.
    pub table: &'a ErrorTable,
    /// The view model that lets a share of the frame exceed tau; None:
    /// every patch within its table's bound.
    pub sight: Option<&'a SightTable>,
    /// Draw flat blocks as merged nodes.
    pub merge: bool,
    /// Leave out what lies outside the frustum.
    pub cull: bool,
    /// How the view model is read.
    pub reading: SightReading,
    /// The pixels each patch showed in earlier frames of this view; None:
    /// every block shows all its modelled pixels.
    pub seen: Option<&'a SeenPixels>,
}

/// How the path a plan is for draws a level, which decides how the view
/// model is read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SightReading {
    /// The tess path: the model's layout. A block's rays fall to its mean
    /// height, where the rays that show it land on average, and the
    /// narrower far patches read their own entries.
    Tessellated,
    /// The geomip path, whose template lays a narrower patch's levels out
    /// differently (clamped to its far sides): those patches keep the
    /// bound. Its stitched edges and glides between levels are errors the
    /// model does not see, and a block's rays fall to the bottom of its box,
    /// the steepest fall any of them can have and so the largest gaps,
    /// which leaves them a margin: on the default scene's overview at 2 px,
    /// rays landing at the mean put its p99 at 2.05 px, at the bottom 1.97.
    Template,
}

impl SightReading {
    /// Which of a block's errors the path reads: the tess path the shares
    /// pooled over the block's pixels; the geomip path, whose stitched
    /// edges and glides the model does not see, each share's largest over
    /// its patches, which keeps their margin.
    fn shares(self) -> BlockShares {
        match self {
            SightReading::Tessellated => BlockShares::Pooled,
            SightReading::Template => BlockShares::Largest,
        }
    }
}

/// A square of patches the frame draws one by one, all decided at once: a
/// single patch, or an aligned block of 2^`level` x 2^`level` whole
/// patches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlannedBlock {
    /// Its first (upper-left) patch.
    pub col: u32,
    pub row: u32,
    /// 2^level patches a side.
    pub level: u32,
    /// The level index its patches' insides take (the full-resolution
    /// index at full resolution).
    pub patch_level: u8,
    /// Drawn with the reference's own triangles.
    pub full_resolution: bool,
    /// Whether the share chose its level, below the bound's: told to the
    /// control shader by `ChosenLevel`. Otherwise the patches' own table
    /// rows decide, each from its own box.
    pub chosen: bool,
    /// Its error bound at its level, face-on from its nearest point, in
    /// pixels (0 at full resolution).
    pub predicted_px: f32,
    /// The pixels the view model puts over tau at the next coarser level
    /// where the share did not choose the level: what a block drawn part
    /// of the way towards that level (the geomip path's glide) risks. 0
    /// where the share chose the level, at the coarsest level, and where
    /// the model was not read.
    pub coarser_over_px: f32,
}

impl PlannedBlock {
    /// Its node in the hierarchy.
    pub fn node(&self) -> NodeId {
        NodeId {
            level: self.level,
            col: self.col >> self.level,
            row: self.row >> self.level,
        }
    }

    /// Patches a side.
    pub fn span(&self) -> u32 {
        1 << self.level
    }

    /// The columns and rows of its patches in `grid` (a block at the
    /// grid's far sides may be cut by them).
    pub fn patch_range(&self, grid: &PatchGrid) -> ([usize; 2], [usize; 2]) {
        square_range(
            [grid.patch_cols(), grid.patch_rows()],
            [self.col as usize, self.row as usize],
            self.span() as usize,
        )
    }

    /// Its patches' indices in `grid`, row by row (a patch-level block
    /// has one).
    pub fn patches<'g>(&self, grid: &'g PatchGrid) -> impl Iterator<Item = usize> + 'g {
        rect_rows(grid.patch_cols(), self.patch_range(grid)).flatten()
    }
}

/// What the control shader reads of a patch's errors (`own`, its row of
/// the table) given the byte the plan wrote for it (`chosen`: 0 where its
/// own errors decide, else the level index the share chose plus one): zero
/// from the chosen level on, so the patch is drawn no finer; its own below
/// it, so that a patch whose own bound accepts a coarser level (a smooth or
/// farther patch of a block chosen as one) is drawn at that level. Its own
/// bound keeps such a patch within tau, so the pixels the share let over
/// tau are no more than the plan counted.
/// Mirror: `chosen_error` in glsl/terrain_common.glsl.
pub fn chosen_errors(own: &PatchErrors, chosen: u8) -> PatchErrors {
    std::array::from_fn(|k| {
        if chosen != 0 && k + 1 >= usize::from(chosen) {
            0.0
        } else {
            own[k]
        }
    })
}

/// What one frame of the tess path draws.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FramePlan {
    /// Patches in view drawn one by one, in blocks decided at once.
    pub blocks: Vec<PlannedBlock>,
    /// Merged nodes in view.
    pub merged: Vec<MergedNode>,
    /// Nodes of the hierarchy the walk visited.
    pub nodes_visited: usize,
    /// Patches in view, drawn in blocks or merged nodes.
    pub patches_in_view: usize,
    /// The largest of the blocks' and merged nodes' predicted errors.
    pub predicted_max_px: f32,
    /// The share of the frame's terrain pixels the view model puts over
    /// tau at the levels chosen: what the greedy share spent of its
    /// budget (`EXCEED_SHARE`) over the pixels it took the budget of.
    /// None where the model was not read.
    pub predicted_over_share: Option<f32>,
}

impl FramePlan {
    /// The level index each patch of `grid` is drawn at (row-major): its
    /// block's (the full-resolution index at full resolution), 0 in a
    /// merged node, `seen::NOT_DRAWN` outside the plan. What a frame that
    /// counts its pixels keeps beside them (`SeenPixels`).
    pub fn patch_levels(&self, grid: &PatchGrid, levels: &mut Vec<u8>) {
        let cols = grid.patch_cols();
        levels.clear();
        levels.resize(grid.patch_count(), NOT_DRAWN);
        let mut fill = |rect, level: u8| {
            for row in rect_rows(cols, rect) {
                levels[row].fill(level);
            }
        };
        for block in &self.blocks {
            fill(block.patch_range(grid), block.patch_level);
        }
        for node in &self.merged {
            fill(node.patch_range(grid), 0);
        }
    }
}

/// A block whose level the greedy share decides.
#[derive(Debug)]
struct Candidate {
    /// Index into the plan's blocks.
    slot: usize,
    /// Pixels over tau at each level index up to `bound`.
    over: [f32; LEVEL_COUNT + 1],
    /// The bound's level: nothing over tau from there on.
    bound: usize,
    /// The full-resolution level index.
    full: usize,
    /// Its patches.
    patches: f32,
    /// Triangles of one patch at full resolution.
    full_triangles: f32,
    /// Pixels a unit of length covers face-on at its nearest point.
    scale: f32,
    /// Its patches' largest errors at each level (its node's).
    errors: PatchErrors,
}

impl Candidate {
    fn triangles(&self, k: usize) -> f32 {
        self.patches
            * if k >= self.full {
                self.full_triangles
            } else {
                // 2^k x 2^k quads of two triangles.
                (2u32 << (2 * k)) as f32
            }
    }

    /// The best finer level from `from`: (pixels relieved per triangle
    /// added, level).
    fn best_step(&self, from: usize) -> Option<(f32, usize)> {
        (from + 1..=self.bound)
            .filter_map(|k| {
                let relief = self.over[from] - self.over[k];
                let added = (self.triangles(k) - self.triangles(from)).max(1.0);
                (relief > 0.0).then_some((relief / added, k))
            })
            .max_by(|a, b| a.0.total_cmp(&b.0))
    }

    /// The coarsest level below `k` whose pixels over tau exceed those at
    /// `k` by at most `slack`, if any.
    fn coarsest_within(&self, k: usize, slack: f32) -> Option<usize> {
        (0..k).find(|&j| self.over[j] - self.over[k] <= slack)
    }
}

/// A node's box: its footprint's x and z, its heights' y.
#[derive(Clone, Copy, Debug)]
struct NodeBox {
    min: Vec3,
    max: Vec3,
}

impl NodeBox {
    /// `node`'s box.
    fn of(node: &Node) -> NodeBox {
        let (min, max) = node.aabb();
        NodeBox { min, max }
    }

    /// A node with its box, for a walk's stack.
    fn entry(hierarchy: &Hierarchy, id: NodeId) -> (NodeId, NodeBox) {
        (id, NodeBox::of(hierarchy.node(id)))
    }

    /// Pushes `id`'s children with their boxes: their nodes are read
    /// together, as they are pushed, so the memory lines a cold walk
    /// misses are fetched four at a time instead of one per node popped.
    fn push_children(hierarchy: &Hierarchy, id: NodeId, stack: &mut Vec<(NodeId, NodeBox)>) {
        stack.reserve(4);
        hierarchy.for_each_child(id, |c, node| stack.push((c, NodeBox::of(node))));
    }

    /// Its extent on screen in pixels, its diagonal seen face-on from its
    /// nearest point, `near` away (`BLOCK_EXTENT_PX`).
    fn extent(&self, view: &LodView, near: f32) -> f32 {
        (self.max - self.min).length() * view.scale(near)
    }

    /// Whether it lies outside the view's frustum.
    fn outside(&self, view: &LodView) -> bool {
        let (centre, half) = (0.5 * (self.min + self.max), 0.5 * (self.max - self.min));
        view.frustum.aabb_outside(centre - view.eye_local, half)
    }

    /// Its nearest and farthest points' distances from the eye (the
    /// origin, `eye` subtracted).
    fn distances(&self, eye: Vec3) -> (f32, f32) {
        let (lo, hi) = (self.min - eye, self.max - eye);
        let far = lo.abs().max(hi.abs()).length();
        (box_distance(lo, hi), far)
    }
}

/// Plans one frame of the tess path's error LOD (see the module
/// documentation). A frame loop keeps a `Planner` instead, whose buffers
/// outlive the frame.
pub fn plan(
    terrain: &Terrain,
    hierarchy: &Hierarchy,
    view: &LodView,
    inputs: &PlanInputs,
) -> FramePlan {
    let mut planner = Planner::default();
    planner.plan(terrain, hierarchy, view, inputs);
    planner.plan
}

/// The error LOD's choice with the buffers it fills, kept from one frame
/// to the next: once they have grown to a view's size, a frame's plan
/// allocates nothing, and writes into memory it wrote the frame before
/// instead of fresh pages.
#[derive(Debug, Default)]
pub struct Planner {
    /// The last frame's plan.
    plan: FramePlan,
    /// The walk's buffers.
    walker: Walker,
    /// The blocks whose view model is read, in the order of their parts.
    pending: Vec<Pending>,
    /// The parts of every pending block, in order (`model_parts`).
    parts: Vec<Part>,
    /// Each part's reading of the model, where it has an entry.
    views: Vec<Option<BlockView>>,
    candidates: Vec<Candidate>,
    /// Per block of the plan, whether its model was read.
    read: Vec<bool>,
    share: GreedyShare,
    /// The boxes of the plan's ground, where no counts tell what shows.
    horizon: Horizon,
    /// Each box's share shown (`Horizon::shown`).
    shown: Vec<f32>,
}

impl Planner {
    /// A planner whose buffers hold a plan of up to `blocks` blocks
    /// without growing, their memory written once: a frame's plan then
    /// neither copies a buffer that outgrew its memory nor waits on the
    /// pages of new memory, which cost the first plan a planner made up
    /// to 0.2 ms more than its later ones on the 4097^2 terrain.
    pub fn with_capacity(blocks: usize) -> Planner {
        let mut planner = Planner::default();
        let plan = &mut planner.plan;
        touched(&mut plan.blocks, blocks);
        touched(&mut plan.merged, blocks);
        planner.walker.reserve(blocks);
        touched(&mut planner.pending, blocks);
        // Most blocks are read in one part.
        touched(&mut planner.parts, 2 * blocks);
        touched(&mut planner.views, 2 * blocks);
        touched(&mut planner.candidates, blocks);
        touched(&mut planner.read, blocks);
        touched(&mut planner.shown, 2 * blocks);
        let share = &mut planner.share;
        touched(&mut share.steps, LEVEL_COUNT * blocks);
        touched(&mut share.levels, blocks);
        touched(&mut share.trims, blocks);
        // Room for a few hundred patches large on screen, each hiding as
        // its parts too.
        planner
            .horizon
            .reserve(2 * blocks + SLABS_PER_PATCH * blocks.min(256));
        planner
    }

    /// The plan of the last frame planned.
    pub fn last_plan(&self) -> &FramePlan {
        &self.plan
    }

    /// Plans one frame (see `plan`).
    pub fn plan(
        &mut self,
        terrain: &Terrain,
        hierarchy: &Hierarchy,
        view: &LodView,
        inputs: &PlanInputs,
    ) -> &FramePlan {
        let plan = &mut self.plan;
        plan.blocks.clear();
        plan.merged.clear();
        (
            plan.nodes_visited,
            plan.patches_in_view,
            plan.predicted_max_px,
            plan.predicted_over_share,
        ) = (0, 0, 0.0, None);
        self.pending.clear();
        self.horizon.clear();
        // Without counts, what nearer ground hides is found from the
        // plan's own boxes.
        let horizon =
            (inputs.seen.is_none() && inputs.sight.is_some()).then_some(&mut self.horizon);
        let horizon_used = horizon.is_some();
        walk(
            terrain,
            hierarchy,
            view,
            inputs,
            (plan, &mut self.walker, horizon),
            &mut self.pending,
        );
        let shown = if horizon_used {
            self.horizon.shown(&mut self.shown);
            Some(self.shown.as_slice())
        } else {
            None
        };
        let tau = view.tau.px();
        let counted = inputs.sight.zip(inputs.seen).map(|(sight, seen)| Counted {
            sight,
            seen,
            tau,
            shares: inputs.reading.shares(),
        });
        place_parts(
            &mut self.pending,
            view,
            (inputs.cull, shown, counted),
            &mut self.parts,
        );
        let mut frame_pixels = match inputs.sight {
            Some(sight) => read_model(
                sight,
                (&self.pending, &self.parts),
                (tau, inputs.reading.shares()),
                view.viewport_pixels() as f32,
                (inputs.seen, shown),
                (&mut self.views, &mut self.candidates),
            ),
            None => {
                self.candidates.clear();
                0.0
            }
        };
        if let Some(seen) = inputs.seen {
            frame_pixels +=
                unread_pixels(plan, &self.pending, terrain.grid(), seen, &mut self.read);
        }
        let pixels = frame_pixels.min(view.viewport_pixels());
        let mut over = 0.0f64;
        if !self.candidates.is_empty() {
            let budget = EXCEED_SHARE * pixels;
            let levels = self.share.levels(&self.candidates, budget as f32);
            for (c, &level) in self.candidates.iter().zip(levels) {
                over += f64::from(c.over[level]);
                let block = &mut plan.blocks[c.slot];
                block.patch_level = level as u8;
                block.full_resolution = level >= c.full;
                // A patch holding the eye was chosen at its bound already
                // (`plan_block`): its own errors would draw it finer.
                block.chosen |= level < c.bound;
                block.coarser_over_px = match block.chosen || level == 0 {
                    true => 0.0,
                    false => c.over[level - 1],
                };
                block.predicted_px = if block.full_resolution {
                    0.0
                } else {
                    c.errors[level] * c.scale
                };
            }
        }
        plan.predicted_over_share = inputs.sight.map(|_| {
            if pixels > 0.0 {
                (over / pixels) as f32
            } else {
                0.0
            }
        });
        plan.predicted_max_px = plan
            .blocks
            .iter()
            .map(|b| b.predicted_px)
            .fold(plan.predicted_max_px, f32::max);
        &self.plan
    }
}

/// A block the walk found small enough to decide at once, which may yet
/// be decided in parts (`BLOCK_BUDGET`).
#[derive(Clone, Copy, Debug)]
struct Splittable {
    /// Its box's extent on screen, in pixels (`BLOCK_EXTENT_PX`).
    extent: f32,
    id: NodeId,
    bounds: NodeBox,
}

impl PartialEq for Splittable {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == std::cmp::Ordering::Equal
    }
}

impl Eq for Splittable {}

impl PartialOrd for Splittable {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

/// The larger on screen first.
impl Ord for Splittable {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.extent.total_cmp(&other.extent)
    }
}

/// The walk's buffers, kept from frame to frame, and its budget.
#[derive(Debug)]
struct Walker {
    /// Nodes still to visit.
    stack: Vec<(NodeId, NodeBox)>,
    /// Blocks the model reads, to decide whole or in parts, in the walk's
    /// order.
    splittable: Vec<Splittable>,
    /// The most blocks splitting may lead to (`BLOCK_BUDGET`).
    budget: usize,
}

impl Default for Walker {
    fn default() -> Self {
        Walker {
            stack: Vec::new(),
            splittable: Vec::new(),
            budget: BLOCK_BUDGET,
        }
    }
}

impl Walker {
    fn reserve(&mut self, blocks: usize) {
        touched(&mut self.stack, blocks);
        touched(&mut self.splittable, blocks);
    }
}

/// Walks the hierarchy from its top node down, adding to `plan` its
/// merged nodes and its blocks at the bound's levels, and to `pending`
/// the blocks whose view model is to be read. The blocks the model reads
/// are found at most `BLOCK_EXTENT_PX` across, then split, largest on
/// screen first, down to `BLOCK_EXTENT_MIN_PX` while their parts fit in
/// `BLOCK_BUDGET`. Parts are not merged.
fn walk(
    terrain: &Terrain,
    hierarchy: &Hierarchy,
    view: &LodView,
    inputs: &PlanInputs,
    (plan, walker, mut horizon): (&mut FramePlan, &mut Walker, Option<&mut Horizon>),
    pending: &mut Vec<Pending>,
) {
    let Walker {
        stack,
        splittable,
        budget,
    } = walker;
    let budget = *budget;
    splittable.clear();
    let tau = view.tau.px();
    let grid = terrain.grid();
    let n = grid.cells_per_patch() as u32;
    let eye = view.eye_local;
    let [range_lo, range_hi] = hierarchy.height_range();
    // A full-size patch's extent along x and z.
    let spacing = terrain.info().spacing();
    let patch_size = Vec2::new(
        (f64::from(n) * spacing.x) as f32,
        (f64::from(n) * spacing.y) as f32,
    );
    // Adds a node found at its distances to the plan (`decide`).
    let mut decide_found = |found: (NodeId, &NodeBox, (f32, f32), Option<&SightTable>),
                            plan: &mut FramePlan,
                            horizon: &mut Option<&mut Horizon>| {
        decide(
            terrain,
            hierarchy,
            view,
            inputs,
            found,
            (plan, horizon),
            pending,
        )
    };
    stack.clear();
    stack.push(NodeBox::entry(hierarchy, hierarchy.root()));
    while let Some((id, bounds)) = stack.pop() {
        plan.nodes_visited += 1;
        let node = hierarchy.node(id);
        if inputs.cull && bounds.outside(view) {
            continue;
        }
        let (pc, pr) = hierarchy.patch_range(id);
        if inputs.merge && id.level >= 1 && id.level <= MAX_MERGE_LEVEL && node.whole {
            // Seen from the nearest point of the node's footprint between
            // the terrain's lowest and highest heights: nearer than any of
            // its patches' boxes and any side's strip. Its one-segment
            // error covers the patches around it too, each seen from no
            // nearer than the footprint grown by a patch.
            let d = box_distance(
                Vec3::new(bounds.min.x, range_lo, bounds.min.z) - eye,
                Vec3::new(bounds.max.x, range_hi, bounds.max.z) - eye,
            );
            let ring = box_distance(
                Vec3::new(
                    bounds.min.x - patch_size.x,
                    range_lo,
                    bounds.min.z - patch_size.y,
                ) - eye,
                Vec3::new(
                    bounds.max.x + patch_size.x,
                    range_hi,
                    bounds.max.z + patch_size.y,
                ) - eye,
            );
            let scale = view.scale(d);
            if within_tolerance(node.flat_error, view.scale(ring), tau) {
                let own = node_errors(&node.patch_max, node.bounds[1] - node.bounds[0], id.level);
                let span = 1u32 << id.level;
                let inside = error_tess_factor(&own, d, view.pixels_per_radian, tau, n << id.level);
                if inside <= span as f32 {
                    let k = (inside as u32).trailing_zeros() as usize;
                    let predicted_px = own[k] * scale;
                    plan.predicted_max_px = plan.predicted_max_px.max(predicted_px);
                    plan.patches_in_view += (span * span) as usize;
                    if let Some(h) = horizon.as_deref_mut() {
                        h.add_occluder(bounds.min - eye, bounds.max - eye);
                    }
                    plan.merged.push(MergedNode {
                        col: pc[0] as u32,
                        row: pr[0] as u32,
                        level: id.level,
                        errors: own,
                        predicted_px,
                    });
                    continue;
                }
            }
        }
        let block = Block {
            level: id.level,
            col: id.col as usize,
            row: id.row as usize,
        };
        // Every patch has an entry in the model, and every whole block of
        // full-size patches (`node.whole`).
        let modelled = inputs.sight.filter(|s| {
            let has = id.level == 0 || node.whole;
            debug_assert!(id.level > BLOCK_LEVELS || has == s.has(block));
            id.level <= BLOCK_LEVELS
                && has
                && (node.whole || inputs.reading == SightReading::Tessellated)
        });
        // A block small and shallow on screen is decided at once. Without
        // the model, only whole blocks whose bound needs no patch at full
        // resolution: the tessellator still sets each edge's factor itself,
        // and a full-resolution flag would spread from one patch to all.
        let (near, far) = bounds.distances(eye);
        let compact = || {
            near > 0.0
                && far <= BLOCK_DEPTH_RATIO * near
                && bounds.extent(view, near) <= BLOCK_EXTENT_PX
        };
        let decided = id.level == 0
            || match modelled {
                Some(_) => compact(),
                None => id.level <= BLOCK_LEVELS && node.whole && compact(),
            };
        if !decided {
            NodeBox::push_children(hierarchy, id, stack);
            continue;
        }
        if modelled.is_some() && id.level > 0 {
            let extent = bounds.extent(view, near);
            splittable.push(Splittable { extent, id, bounds });
            continue;
        }
        let found = (id, &bounds, (near, far), modelled);
        if !decide_found(found, plan, &mut horizon) {
            NodeBox::push_children(hierarchy, id, stack);
        }
    }
    // Split the largest on screen first while the parts fit: each split
    // adds up to three blocks.
    if plan.blocks.len() + splittable.len() + 3 <= budget {
        let mut heap = BinaryHeap::from(std::mem::take(splittable));
        while let Some(&top) = heap.peek() {
            if top.extent <= BLOCK_EXTENT_MIN_PX || plan.blocks.len() + heap.len() + 3 > budget {
                break;
            }
            heap.pop();
            NodeBox::push_children(hierarchy, top.id, stack);
            while let Some((id, bounds)) = stack.pop() {
                plan.nodes_visited += 1;
                if inputs.cull && bounds.outside(view) {
                    continue;
                }
                let (near, far) = bounds.distances(eye);
                if id.level == 0 {
                    let found = (id, &bounds, (near, far), inputs.sight);
                    decide_found(found, plan, &mut horizon);
                } else if near > 0.0 && far <= BLOCK_DEPTH_RATIO * near {
                    let extent = bounds.extent(view, near);
                    heap.push(Splittable { extent, id, bounds });
                } else {
                    NodeBox::push_children(hierarchy, id, stack);
                }
            }
        }
        // Decided in the order of the model's entries (by level, then
        // row-major), which the heap's order scatters over memory.
        *splittable = heap.into_vec();
        splittable.sort_unstable_by_key(|b| (b.id.level, b.id.row, b.id.col));
    }
    for block in splittable.iter() {
        let (near, far) = block.bounds.distances(eye);
        let found = (block.id, &block.bounds, (near, far), inputs.sight);
        decide_found(found, plan, &mut horizon);
    }
}

/// Adds node `id` to the plan, decided at once; false, adding nothing,
/// for a block without the model (`sight`) whose bound needs a patch at
/// full resolution: the tessellator still sets each edge's factor itself,
/// and a full-resolution flag would spread from one patch to all.
#[inline]
fn decide(
    terrain: &Terrain,
    hierarchy: &Hierarchy,
    view: &LodView,
    inputs: &PlanInputs,
    (id, bounds, (near, far), sight): (NodeId, &NodeBox, (f32, f32), Option<&SightTable>),
    (plan, horizon): (&mut FramePlan, &mut Option<&mut Horizon>),
    pending: &mut Vec<Pending>,
) -> bool {
    let eye = view.eye_local;
    let slot = plan.blocks.len();
    let (planned, to_read) = plan_block(
        terrain,
        hierarchy,
        (id, bounds, (near, far)),
        view,
        (inputs, sight),
        slot,
    );
    if id.level > 0 && sight.is_none() && planned.full_resolution {
        return false;
    }
    let (pc, pr) = hierarchy.patch_range(id);
    plan.patches_in_view += (pc[1] - pc[0]) * (pr[1] - pr[0]);
    plan.blocks.push(planned);
    let boxed = horizon.as_deref_mut().and_then(|h| {
        let (lo, hi) = (bounds.min - eye, bounds.max - eye);
        match &to_read {
            // Solid up to its mean height, where the model's rays
            // land, where the model has one.
            Some(p) => {
                let at = h.add(lo, hi, p.mean.map_or(lo.y, |m| m - eye.y));
                // A patch large on screen also hides as its parts, each
                // solid up to its own mean (`terrain::slabs`): those
                // higher than the patch's, which hide what it does not.
                let large = id.level == 0 && bounds.extent(view, near) >= PARTS_HIDE_EXTENT_PX;
                if let (Some(slabs), Some(mean)) = (terrain.patch_slabs().filter(|_| large), p.mean)
                {
                    let parts = slabs.of(terrain.grid().patch_index(PatchId {
                        col: pc[0],
                        row: pr[0],
                    }));
                    for s in parts.iter().filter(|s| s.mean > mean) {
                        h.add_part(s.min - eye, s.max - eye, s.mean - eye.y);
                    }
                }
                Some(at)
            }
            None => {
                h.add_occluder(lo, hi);
                None
            }
        }
    });
    pending.extend(to_read.map(|p| Pending { boxed, ..p }));
    true
}

/// Block `id`'s entry in the plan at the bound's level, and, where the
/// view model (`sight`) may coarsen it, what to read of the model.
fn plan_block(
    terrain: &Terrain,
    hierarchy: &Hierarchy,
    (id, bounds, (near, far)): (NodeId, &NodeBox, (f32, f32)),
    view: &LodView,
    (inputs, sight): (&PlanInputs, Option<&SightTable>),
    slot: usize,
) -> (PlannedBlock, Option<Pending>) {
    let grid = terrain.grid();
    let (pc, pr) = hierarchy.patch_range(id);
    // A single patch is read from the table; a block takes its patches'
    // largest errors. Either is seen from its own box: its footprint, its
    // heights.
    let d = near;
    let (row, cells) = if id.level == 0 {
        let patch = grid.patch_id(pr[0] * grid.patch_cols() + pc[0]);
        let p = grid.patch_index(patch);
        let rect = grid.sample_rect(patch);
        let row: PatchErrors = inputs
            .table
            .patch(p)
            .try_into()
            .expect("LEVEL_COUNT levels a patch");
        (row, [rect.cells_x() as u32, rect.cells_z() as u32])
    } else {
        let n = grid.cells_per_patch() as u32;
        (hierarchy.node(id).patch_max, [n, n])
    };
    let scale = view.scale(d);
    let tau = view.tau.px();
    // The first level index whose segments reach the smaller side.
    let side = cells[0].min(cells[1]);
    let full = (0..LEVEL_COUNT)
        .find(|&k| (1u32 << k) >= side)
        .unwrap_or(LEVEL_COUNT);
    let bound = (0..full)
        .find(|&k| within_tolerance(row[k], scale, tau))
        .unwrap_or(full);
    let mut predicted_px = if bound >= full {
        0.0
    } else {
        row[bound] * scale
    };
    // A patch whose box holds the eye is seen from no distance at all by
    // its box, and its own errors take it to full resolution on the GPU.
    // Its ground lies some way off all the same: each level is tried from
    // the nearest its drawn surface can come, by its bound's errors (the
    // hierarchy's), and a coarser one is told to the control shader as
    // chosen.
    let mut chosen = false;
    let eye_patch = match (d == 0.0 && bound > 0, id.level) {
        (true, 0) => eye_patch_level(
            terrain,
            (pc[0], pr[0]),
            view,
            &hierarchy.node(id).patch_max,
            full,
        ),
        _ => None,
    };
    let (ground, eye_level) = eye_patch.unwrap_or((d, None));
    let bound = match eye_level {
        Some((k, px)) if k < bound => {
            (chosen, predicted_px) = (true, px);
            k
        }
        _ => bound,
    };
    let planned = PlannedBlock {
        col: pc[0] as u32,
        row: pr[0] as u32,
        level: id.level,
        patch_level: bound as u8,
        full_resolution: bound >= full,
        chosen,
        predicted_px,
        coarser_over_px: 0.0,
    };
    // The view model reads a block from its parts' nearest points, none
    // nearer than its ground (the patch holding the eye: the nearest its
    // surface comes).
    let (d, scale) = (ground, view.scale(ground));
    let Some(sight) = sight.filter(|_| d > 0.0) else {
        return (planned, None);
    };
    let block = Block {
        level: id.level,
        col: id.col as usize,
        row: id.row as usize,
    };
    let mean = sight.mean_height(block);
    let landing = match inputs.reading {
        SightReading::Tessellated => mean,
        SightReading::Template => None,
    };
    let patches = ((pc[1] - pc[0]) * (pr[1] - pr[0])) as f32;
    let pending = Pending {
        block,
        patches: (pc, pr),
        seen_from: (*bounds, (d, far), landing),
        parts: 0,
        hidden: false,
        mean,
        boxed: None,
        candidate: Candidate {
            slot,
            over: [0.0; LEVEL_COUNT + 1],
            bound,
            full,
            patches,
            full_triangles: 2.0 * (cells[0] * cells[1]) as f32,
            scale,
            errors: hierarchy.node(id).patch_max,
        },
    };
    (planned, Some(pending))
}

/// Where patch (`col`, `row`), whose errors are `errors` and whose box
/// holds the eye, lies from the eye: the nearest its surface comes, and
/// the coarsest level below `full` within tau seen from the nearest its
/// drawn surface can come at that level, with its error in pixels seen
/// from there (None where no level is). None where the terrain's samples
/// are not held (`Terrain::surface_distances`).
fn eye_patch_level(
    terrain: &Terrain,
    (col, row): (usize, usize),
    view: &LodView,
    errors: &PatchErrors,
    full: usize,
) -> Option<(f32, Option<(usize, f32)>)> {
    let mut grows = [0.0; LEVEL_COUNT + 1];
    grows[1..].copy_from_slice(errors);
    let nearest = terrain.surface_distances(PatchId { row, col }, view.eye_local, &grows)?;
    let level = (0..full).find_map(|k| {
        let d = nearest[k + 1];
        let px = errors[k] * view.scale(d);
        (d > 0.0 && px <= view.tau.px()).then_some((k, px))
    });
    Some((nearest[0], level))
}

/// The most parts a side a block is read in (`model_parts`).
pub const MAX_PARTS_SIDE: u32 = 4;

/// Where a block is seen from, for reading its view model: one part, or,
/// for a block whose far side is more than `BLOCK_DEPTH_RATIO` times as
/// far as its near side (a patch near the eye), a square of up to
/// `MAX_PARTS_SIDE` x `MAX_PARTS_SIDE` equal parts, each read from its own
/// nearest point and direction, each its share of the block's pixels.
/// The model's figures are the block's as a whole, so each part is taken
/// to hold the block's spread of errors; what the parts add is where the
/// block's ground lies: nearer ground covers more pixels and shows larger
/// errors, farther ground fewer and smaller, and ground outside the
/// frustum (`cull`) none. Every ray is taken to fall to the block's mean
/// height (`mean`; the bottom of its box without one). The parts are
/// added to `parts`.
fn model_parts(
    (bounds, (near, far)): (&NodeBox, (f32, f32)),
    view: &LodView,
    cull: bool,
    mean: Option<f32>,
    parts: &mut Vec<Part>,
) {
    let eye = view.eye_local;
    let side = parts_side(near, far);
    let landing = mean.unwrap_or(bounds.min.y);
    let step = (bounds.max - bounds.min) / side as f32;
    let share = 1.0 / (side * side) as f32;
    for i in 0..side {
        for j in 0..side {
            let lo = Vec3::new(
                bounds.min.x + i as f32 * step.x,
                bounds.min.y,
                bounds.min.z + j as f32 * step.z,
            );
            let hi = Vec3::new(lo.x + step.x, bounds.max.y, lo.z + step.z);
            let (lo, hi) = (lo - eye, hi - eye);
            if cull && side > 1 && view.frustum.aabb_outside(0.5 * (lo + hi), 0.5 * (hi - lo)) {
                continue;
            }
            let d = box_distance(lo, hi).max(near);
            // The horizontal run to the part's nearest point, and the fall
            // over it to where the rays land.
            let run = footprint_distance(lo, hi);
            let fall = if run > 0.0 {
                (eye.y - landing) / run
            } else {
                f32::INFINITY
            };
            let centre = 0.5 * (lo + hi);
            parts.push(Part {
                at: LatticePoint::new(centre.x, centre.z, fall),
                scale: view.scale(d),
                share,
            });
        }
    }
}

/// The parts a side a block whose nearest and farthest points are `near`
/// and `far` away is read in (`model_parts`).
fn parts_side(near: f32, far: f32) -> u32 {
    if far > BLOCK_DEPTH_RATIO * near {
        ((far / (BLOCK_DEPTH_RATIO * near)).ceil() as u32)
            .next_power_of_two()
            .min(MAX_PARTS_SIDE)
    } else {
        1
    }
}

/// Places every pending block's parts (`model_parts`) in `parts`, in the
/// blocks' order, except those of a block that nearer ground hides, whose
/// entry is not read:
/// - without counts, one hidden in every azimuth bin it spans (`shown` 0,
///   `lod::horizon`): it shows no pixel at any level. On the 4097^2
///   terrain's grazing view, 590 of the 783 blocks the plan reads.
/// - with counts, one that showed no pixel at the level it was drawn at,
///   where that level kept some of its pixels within tau (`Counted`):
///   reading it would scale every pixel it puts over tau by the share of
///   those kept that showed, none. On the same view's counted frames,
///   about 550 of the 783 blocks (tess) and 690 (geomip).
///
/// Such a block is marked `hidden` where a part of it is in view (`cull`).
fn place_parts(
    pending: &mut [Pending],
    view: &LodView,
    (cull, shown, counted): (bool, Option<&[f32]>, Option<Counted>),
    parts: &mut Vec<Part>,
) {
    parts.clear();
    if let Some(counted) = counted {
        // Each block's line of the model's figures, fetched many at a
        // time before any is used.
        let touched = pending.iter().fold(0, |acc, p| {
            acc ^ counted.sight.touch_within(p.block, counted.shares)
        });
        std::hint::black_box(touched);
    }
    for p in pending {
        let (bounds, (near, far), landing) = &p.seen_from;
        let hidden = matches!((shown, p.boxed), (Some(shown), Some(at)) if shown[at] == 0.0);
        let before = parts.len();
        // A block read in one part has it in view (it passed the frustum);
        // one read in several, where a part of it is.
        p.hidden = if hidden && parts_side(*near, *far) == 1 {
            true
        } else {
            model_parts((bounds, (*near, *far)), view, cull, *landing, parts);
            let placed = &parts[before..];
            !placed.is_empty() && (hidden || counted.is_some_and(|counted| counted.hid(p, placed)))
        };
        if p.hidden {
            parts.truncate(before);
        }
        p.parts = parts.len() - before;
    }
}

/// What a frame with counts (`lod::seen`) needs to find the blocks nearer
/// ground hid in them (`place_parts`).
#[derive(Clone, Copy)]
struct Counted<'a> {
    sight: &'a SightTable,
    seen: &'a SeenPixels,
    tau: f32,
    shares: BlockShares,
}

impl Counted<'_> {
    /// Whether block `p`, read in `parts`, showed no pixel when counted,
    /// drawn at a level that kept some of its pixels within tau, or at a
    /// level within tau, or not drawn: each pixel it puts over tau is then
    /// taken at the share of those the drawn level kept that showed
    /// (`read_model`), which is none. Where the level it was drawn at put
    /// every pixel over tau, what it lost may be what is missing, and it
    /// is read.
    fn hid(&self, p: &Pending, parts: &[Part]) -> bool {
        let (cols, rows) = p.patches;
        if self.seen.block_pixels(cols, rows) > 0 {
            return false;
        }
        match self.seen.drawn_level(cols[0], rows[0]) {
            Some(k) if usize::from(k) < p.candidate.bound => parts.iter().all(|part| {
                let error = self.tau / part.scale;
                let k = usize::from(k);
                self.sight
                    .keeps_some_within(p.block, k, part.at.slopes, error, self.shares)
            }),
            // Within tau at its level, or not drawn: nothing lost.
            _ => true,
        }
    }
}

/// One part of a block as its view model is read (`model_parts`).
#[derive(Clone, Copy, Debug)]
struct Part {
    /// The direction it is seen from.
    at: LatticePoint,
    /// Pixels a unit of length covers face-on at its nearest point.
    scale: f32,
    /// Its share of the block's area.
    share: f32,
}

/// A block whose view model is still to be read: where it is seen from,
/// and its candidate, whose pixels over tau the reading fills in.
#[derive(Debug)]
struct Pending {
    block: Block,
    /// Its patches' columns and rows.
    patches: ([usize; 2], [usize; 2]),
    /// Where it is read from: its box, its nearest and farthest points'
    /// distances (its nearest, none nearer than its ground), and the height
    /// its rays land at (`model_parts`).
    seen_from: (NodeBox, (f32, f32), Option<f32>),
    /// How many of the parts, following those of the blocks before it
    /// (`place_parts`).
    parts: usize,
    /// In view, and hidden by nearer ground in every bin it spans, or
    /// counted dark at a level that kept some of its pixels within tau: it
    /// is over tau nowhere, and its model is not read (`place_parts`).
    hidden: bool,
    /// Its mean height (`SightTable::mean_height`).
    mean: Option<f32>,
    /// Its box's index in the frame's horizon, where there is one.
    boxed: Option<usize>,
    candidate: Candidate,
}

/// Fills `candidates` with those of `pending`, each block's pixels over
/// tau read off the view model (`tau` pixels, `viewport` pixels at most a
/// block). Every entry is found first (`views`), and each memory line of
/// its codes read once, in a loop of independent reads, so the lines are
/// fetched many at a time (copying the codes out instead moved 200 bytes
/// a view for it). Returns the pixels the model sees of them all.
fn read_model(
    sight: &SightTable,
    (pending, parts): (&[Pending], &[Part]),
    (tau, shares): (f32, BlockShares),
    viewport: f32,
    (seen, shown): (Option<&SeenPixels>, Option<&[f32]>),
    (views, candidates): (&mut Vec<Option<BlockView>>, &mut Vec<Candidate>),
) -> f64 {
    views.clear();
    let mut at = 0;
    for p in pending {
        for part in &parts[at..at + p.parts] {
            views.push(sight.view(p.block, &part.at, tau / part.scale, shares));
        }
        at += p.parts;
    }
    let mut touched = 0;
    for view in views.iter().flatten() {
        touched ^= sight.touch(view);
    }
    std::hint::black_box(touched);
    let mut frame_pixels = 0.0f64;
    candidates.clear();
    let mut views = views.iter().zip(parts);
    for p in pending {
        let c = &p.candidate;
        let mut over = [0.0f32; LEVEL_COUNT + 1];
        if p.hidden {
            // Over tau nowhere at any level, where it has an entry.
            if c.bound > 0 && sight.has(p.block) {
                candidates.push(Candidate { over, ..*c });
            }
            continue;
        }
        let mut modelled = false;
        let mut block_pixels = 0.0f64;
        for (view, part) in views.by_ref().take(p.parts) {
            let Some(view) = view else {
                continue;
            };
            modelled = true;
            let pixels = (view.area() * part.share * part.scale * part.scale).min(viewport);
            block_pixels += f64::from(pixels);
            let codes = sight.codes(view);
            for (k, o) in over.iter_mut().enumerate().take(c.bound) {
                *o += pixels * codes.over_fraction(k);
            }
        }
        // Pixels nearer ground hid in earlier frames of this view are
        // none of the block's: each share of its pixels over tau is
        // taken of the share of its pixels that showed. A block drawn
        // coarser than the reference also shows fewer pixels where what
        // the coarser level lost (a spike drawn away) shows the ground or
        // sky behind: those are not hidden, and they are the pixels over
        // tau. So the share shown is taken of the pixels the level it was
        // drawn at when counted kept: its modelled pixels less those the
        // model put over tau there. A block the model does not see is
        // over tau nowhere, and its pixels are the ones it showed.
        if let Some(seen) = seen {
            let (cols, rows) = p.patches;
            let shown = seen.block_pixels(cols, rows) as f64;
            if !modelled {
                block_pixels = shown;
            } else if shown < block_pixels {
                let lost = seen.drawn_level(cols[0], rows[0]).map_or(0.0, |k| {
                    f64::from(over.get(usize::from(k)).copied().unwrap_or(0.0))
                });
                let kept = match block_pixels - lost {
                    drawn if drawn > shown => (shown / drawn) as f32,
                    _ => 1.0,
                };
                over.iter_mut().for_each(|o| *o *= kept);
                block_pixels = shown;
            }
        } else if let (Some(shown), Some(at)) = (shown, p.boxed) {
            // Without counts, the share of its bins nearer ground does not
            // hide (`lod::horizon`).
            let share = shown[at];
            over.iter_mut().for_each(|o| *o *= share);
            block_pixels *= f64::from(share);
        }
        frame_pixels += block_pixels;
        if modelled && c.bound > 0 {
            candidates.push(Candidate { over, ..*c });
        }
    }
    frame_pixels
}

/// The pixels counted of the blocks whose view model was not read (the
/// patch the eye is over where its ground is not known, those without a
/// model) and of the merged nodes:
/// ground drawn within tau by its bound, whose pixels are the frame's all
/// the same, so a 99th percentile over the frame allows its share of them
/// over tau elsewhere. Only counts tell them: the model does not see them.
fn unread_pixels(
    plan: &FramePlan,
    pending: &[Pending],
    grid: &PatchGrid,
    seen: &SeenPixels,
    read: &mut Vec<bool>,
) -> f64 {
    read.clear();
    read.resize(plan.blocks.len(), false);
    for p in pending {
        read[p.candidate.slot] = true;
    }
    let blocks = plan
        .blocks
        .iter()
        .zip(read.iter())
        .filter(|(_, &read)| !read)
        .map(|(b, _)| b.patch_range(grid));
    let merged = plan.merged.iter().map(|m| m.patch_range(grid));
    blocks
        .chain(merged)
        .map(|(cols, rows)| seen.block_pixels(cols, rows) as f64)
        .sum()
}

/// The greedy share's buffers, kept from frame to frame.
#[derive(Debug, Default)]
struct GreedyShare {
    /// Every candidate's steps, keyed (`step_key`), with the pixels over
    /// tau each relieves.
    steps: Vec<(u64, f32)>,
    /// Each candidate's level so far.
    levels: Vec<usize>,
    /// Refinements that can be taken back within the budget, keyed by the
    /// triangles they save (`step_key`).
    trims: Vec<u64>,
}

/// Below this many steps, the ones still undecided are sorted and taken
/// in order rather than split again.
const SORTED_STEPS: usize = 24;

impl GreedyShare {
    /// Each candidate's level: from every one at its coarsest, the step
    /// that relieves the most pixels over tau per triangle added goes
    /// first, until what remains over tau fits `budget`. A step is all or
    /// nothing, and the last can overshoot (a block sent to full resolution
    /// for a few pixels more than the rest could give), so what is left of
    /// the budget then takes refinements back: those that save the most
    /// triangles first, each to the coarsest level the budget still
    /// allows.
    fn levels(&mut self, candidates: &[Candidate], budget: f32) -> &[usize] {
        self.refine(candidates, budget);
        let over: f64 = candidates
            .iter()
            .zip(self.levels.iter())
            .map(|(c, &k)| f64::from(c.over[k]))
            .sum();
        let mut slack = budget - over as f32;
        let GreedyShare { levels, trims, .. } = self;
        if slack > 0.0 {
            trims.clear();
            trims.extend(candidates.iter().zip(levels.iter()).enumerate().filter_map(
                |(i, (c, &k))| {
                    let j = c.coarsest_within(k, slack)?;
                    Some(step_key(c.triangles(k) - c.triangles(j), i, 0))
                },
            ));
            trims.sort_unstable_by(|a, b| b.cmp(a));
            for &key in trims.iter() {
                let i = step_candidate(key);
                let (c, k) = (&candidates[i], levels[i]);
                if let Some(j) = c.coarsest_within(k, slack) {
                    slack -= c.over[j] - c.over[k];
                    levels[i] = j;
                }
            }
        }
        levels
    }

    /// The greedy steps alone, into `levels`: from every candidate at its
    /// coarsest, the steps in order of gain until what remains over tau
    /// fits `budget`.
    ///
    /// A candidate's steps, each to its best finer level from the last
    /// (`Candidate::best_step`), follow the hull of its pixels over tau
    /// against its triangles, so their gains never rise. The greedy order
    /// is then every candidate's steps sorted by gain, and the steps taken
    /// are the fewest first ones of that order that relieve enough: found
    /// by splitting the steps around a middle one until the last step is
    /// known, in time that grows with the steps (a heap's grows faster, with
    /// the steps taken times their logarithm).
    fn refine(&mut self, candidates: &[Candidate], budget: f32) {
        let GreedyShare { steps, levels, .. } = self;
        steps.clear();
        let mut total = 0.0f64;
        for (i, c) in candidates.iter().enumerate() {
            total += f64::from(c.over[0]);
            let (mut from, mut last) = (0, f32::INFINITY);
            while let Some((gain, k)) = c.best_step(from) {
                // Rounding aside, a hull's gains fall; kept so, a
                // candidate's steps sort in their order.
                last = gain.min(last);
                steps.push((step_key(last, i, k), c.over[from] - c.over[k]));
                from = k;
            }
        }
        let taken = first_relieving(steps, total - f64::from(budget));
        levels.clear();
        levels.resize(candidates.len(), 0);
        for &(key, _) in &steps[..taken] {
            let (i, k) = (step_candidate(key), step_level(key));
            levels[i] = levels[i].max(k);
        }
    }
}

/// Reorders `steps` so that the steps in greatest-key order up to the
/// first whose reliefs, summed with those before it, reach `need` come
/// first, in that order; returns how many (all of them if they never
/// reach it, none if nothing is needed).
fn first_relieving(steps: &mut [(u64, f32)], mut need: f64) -> usize {
    let by_key = |a: &(u64, f32), b: &(u64, f32)| b.0.cmp(&a.0);
    // Steps before `lo` are taken, steps from `hi` on are not; the last
    // one taken lies between.
    let (mut lo, mut hi) = (0, steps.len());
    while need > 0.0 && hi - lo > SORTED_STEPS {
        let mid = (hi - lo) / 2;
        steps[lo..hi].select_nth_unstable_by(mid, by_key);
        let relief: f64 = steps[lo..=lo + mid].iter().map(|s| f64::from(s.1)).sum();
        if relief >= need {
            hi = lo + mid + 1;
        } else {
            need -= relief;
            lo += mid + 1;
        }
    }
    steps[lo..hi].sort_unstable_by(by_key);
    for &(_, relief) in &steps[lo..hi] {
        if need <= 0.0 {
            break;
        }
        need -= f64::from(relief);
        lo += 1;
    }
    lo
}

/// A greedy step's key: greater for a larger `gain` (ordered as
/// `f32::total_cmp` orders it), then for an earlier `candidate`, then for
/// a coarser `level` (candidates below 2^24, levels below 256).
fn step_key(gain: f32, candidate: usize, level: usize) -> u64 {
    debug_assert!(candidate < 1 << 24 && level < 1 << 8);
    let bits = gain.to_bits();
    // Negative floats order reversed, below every positive one.
    let ordered = if bits >> 31 == 1 {
        !bits
    } else {
        bits | 1 << 31
    };
    let rank = (0xff_ffff - candidate as u32) << 8 | (0xff - level as u32);
    u64::from(ordered) << 32 | u64::from(rank)
}

/// The candidate a `step_key` is of.
fn step_candidate(key: u64) -> usize {
    (0xff_ffff - (key as u32 >> 8)) as usize
}

/// The level a `step_key` steps to.
fn step_level(key: u64) -> usize {
    (0xff - (key as u32 & 0xff)) as usize
}

/// The patches whose boxes are not outside the frustum (all of them
/// without `cull`), in grid order, found by walking the hierarchy; and
/// the nodes visited. A node wholly inside the frustum is taken whole,
/// its patches unvisited.
pub fn patches_in_view(
    terrain: &Terrain,
    hierarchy: &Hierarchy,
    view: &LodView,
    cull: bool,
) -> (Vec<u32>, usize) {
    let in_view = walk_view(terrain, hierarchy, view, cull, false);
    (in_view.patches, in_view.visited)
}

/// What `view_patches` finds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InView {
    /// The patches whose boxes are not outside the frustum, in grid order.
    pub patches: Vec<u32>,
    /// Those of them whose boxes are not wholly inside it either (the
    /// frustum's boundary crosses them), in grid order; none without
    /// culling.
    pub crossing: Vec<u32>,
    /// The hierarchy's nodes visited.
    pub visited: usize,
}

/// `patches_in_view`, with the patches the frustum's boundary crosses:
/// the patches the walk reaches one by one (in nodes that cross it) and
/// does not find wholly inside.
pub fn view_patches(
    terrain: &Terrain,
    hierarchy: &Hierarchy,
    view: &LodView,
    cull: bool,
) -> InView {
    walk_view(terrain, hierarchy, view, cull, true)
}

/// `view_patches`; the crossing patches are listed only where
/// `list_crossing` asks for them (`patches_in_view` drops them).
fn walk_view(
    terrain: &Terrain,
    hierarchy: &Hierarchy,
    view: &LodView,
    cull: bool,
    list_crossing: bool,
) -> InView {
    // The patch rectangles (columns, rows) of the nodes taken whole.
    let mut taken: Vec<([usize; 2], [usize; 2])> = Vec::new();
    let mut crossing = Vec::new();
    let mut visited = 0;
    let cols = terrain.grid().patch_cols();
    let mut stack = vec![NodeBox::entry(hierarchy, hierarchy.root())];
    while let Some((id, bounds)) = stack.pop() {
        visited += 1;
        let mut whole = !cull || id.level == 0;
        if cull {
            let (centre, half) = (
                0.5 * (bounds.min + bounds.max) - view.eye_local,
                0.5 * (bounds.max - bounds.min),
            );
            if view.frustum.aabb_outside(centre, half) {
                continue;
            }
            let inside = view.frustum.aabb_inside(centre, half);
            if list_crossing && id.level == 0 && !inside {
                crossing.push((id.row as usize * cols + id.col as usize) as u32);
            }
            whole = whole || inside;
        }
        match whole {
            true => taken.push(hierarchy.patch_range(id)),
            false => NodeBox::push_children(hierarchy, id, &mut stack),
        }
    }
    crossing.sort_unstable();
    InView {
        patches: in_grid_order(&taken, cols),
        crossing,
        visited,
    }
}

/// The patches of disjoint rectangles (columns, rows) of a grid `cols`
/// patches wide, in grid order: marked over the rectangles' bounding box
/// and read off it row by row, in time that grows with that box, not with
/// the grid.
fn in_grid_order(rects: &[([usize; 2], [usize; 2])], cols: usize) -> Vec<u32> {
    let Some(([c0, c1], [r0, r1])) = rect_bounds(rects.iter().copied()) else {
        return Vec::new();
    };
    let width = c1 - c0;
    let mut marked = vec![false; width * (r1 - r0)];
    let mut count = 0;
    for &([a, b], [c, d]) in rects {
        for r in c..d {
            marked[(r - r0) * width + a - c0..][..b - a].fill(true);
        }
        count += (b - a) * (d - c);
    }
    let mut patches = Vec::with_capacity(count);
    for (i, row) in marked.chunks_exact(width).enumerate() {
        let first = (r0 + i) * cols + c0;
        patches.extend(
            row.iter()
                .enumerate()
                .filter(|&(_, &m)| m)
                .map(|(j, _)| (first + j) as u32),
        );
    }
    patches
}

#[cfg(test)]
mod tests {
    use glam::{Mat4, Vec2, Vec3};
    use proptest::prelude::*;

    use super::*;
    use crate::lod::view::Tau;
    use crate::terrain::camera::Frustum;

    /// A candidate of `patches` patches whose bound is its second level,
    /// with `over` pixels over tau at its first two.
    fn candidate(over: [f32; 2], patches: f32) -> Candidate {
        let mut levels = [0.0; LEVEL_COUNT + 1];
        levels[..2].copy_from_slice(&over);
        Candidate {
            slot: 0,
            over: levels,
            bound: 1,
            full: 5,
            patches,
            full_triangles: 2048.0,
            scale: 1.0,
            errors: [0.0; LEVEL_COUNT],
        }
    }

    /// The greedy share's last step can overshoot the budget; what is
    /// left of it takes back the refinements it can afford.
    #[test]
    fn budget_left_after_the_last_step_takes_refinements_back() {
        // The first relieves 30 pixels for 6 triangles, the second 100 for
        // 60: the first is refined first, leaving 100 over a budget of 80,
        // and the second's step then leaves none, 80 under the budget.
        let candidates = [candidate([30.0, 0.0], 1.0), candidate([100.0, 0.0], 10.0)];
        let mut share = GreedyShare::default();
        assert_eq!(share.levels(&candidates, 80.0), &[0, 1]);
        // With 10 left, neither refinement can be taken back.
        assert_eq!(share.levels(&candidates, 10.0), &[1, 1]);
    }

    /// A 1280x720 view from `eye` (terrain-local) looking along `forward`,
    /// 60 degrees high.
    fn view(eye: Vec3, forward: Vec3) -> LodView {
        let fov = 60f32.to_radians();
        let proj = Mat4::perspective_rh(fov, 1280.0 / 720.0, 1.0, 1.0e5);
        let look = Mat4::look_to_rh(Vec3::ZERO, forward, Vec3::Y);
        LodView {
            eye_local: eye,
            pixels_per_radian: 720.0 / (2.0 * (0.5 * fov).tan()),
            frustum: Frustum::from_view_proj(proj * look),
            viewport: Vec2::new(1280.0, 720.0),
            tau: Tau::default(),
        }
    }

    /// A 256 m square patch, 0 to 40 m high.
    fn patch(x: f32, z: f32) -> NodeBox {
        NodeBox {
            min: Vec3::new(x, 0.0, z),
            max: Vec3::new(x + 256.0, 40.0, z + 256.0),
        }
    }

    fn parts_of(bounds: &NodeBox, view: &LodView, cull: bool) -> Vec<Part> {
        let mut parts = Vec::new();
        model_parts(
            (bounds, bounds.distances(view.eye_local)),
            view,
            cull,
            Some(20.0),
            &mut parts,
        );
        parts
    }

    /// A patch far off and about as deep as it is near is read as one
    /// part, whole, from its nearest point.
    #[test]
    fn a_shallow_patch_is_one_part() {
        let v = view(Vec3::new(0.0, 60.0, 0.0), Vec3::X);
        let bounds = patch(4000.0, -128.0);
        let parts = parts_of(&bounds, &v, true);
        assert_eq!(parts.len(), 1);
        assert_eq!(parts[0].share, 1.0);
        let near = bounds.distances(v.eye_local).0;
        assert_eq!(parts[0].scale, v.scale(near));
    }

    /// The patch under a low eye is read in the most parts; each is a
    /// share of the patch, and nearer parts cover more pixels per unit
    /// than farther ones. The half behind the eye is left out, and without
    /// culling it is kept.
    #[test]
    fn a_deep_patch_is_read_in_parts_and_the_unseen_ones_are_left_out() {
        let eye = Vec3::new(128.0, 60.0, 128.0);
        let ahead = view(eye, Vec3::new(1.0, -0.3, 0.0).normalize());
        let bounds = patch(0.0, 0.0);
        let all = parts_of(&bounds, &ahead, false);
        let side = MAX_PARTS_SIDE as usize;
        assert_eq!(all.len(), side * side);
        for part in &all {
            assert_eq!(part.share, 1.0 / (side * side) as f32);
        }
        // Parts run along z within each step along x: the one just ahead
        // of the eye, and the one a step beyond it.
        let (near, beyond) = (&all[2 * side + 2], &all[3 * side + 2]);
        assert!(near.scale > 3.0 * beyond.scale, "{near:?} {beyond:?}");
        // Culled: the half behind the eye goes, the half ahead stays.
        let seen = parts_of(&bounds, &ahead, true);
        assert_eq!(seen.len(), all.len() / 2);
        assert_eq!(seen[0].scale, all[2 * side].scale);
        let behind = view(eye, Vec3::new(-1.0, -0.3, 0.0).normalize());
        let seen = parts_of(&bounds, &behind, true);
        assert_eq!(seen.len(), all.len() / 2);
        assert_eq!(seen[0].scale, all[0].scale);
    }

    /// A planner made with room for n blocks holds n in each buffer a
    /// block fills.
    #[test]
    fn a_planner_with_capacity_has_room_for_its_blocks() {
        let planner = Planner::with_capacity(500);
        for capacity in [
            planner.plan.blocks.capacity(),
            planner.pending.capacity(),
            planner.candidates.capacity(),
            planner.parts.capacity(),
            planner.views.capacity(),
            planner.share.levels.capacity(),
        ] {
            assert!(capacity >= 500, "{capacity}");
        }
        assert!(planner.plan.blocks.is_empty() && planner.parts.is_empty());
    }

    /// A pending block of `bounds` seen from `view`, box `boxed` of the
    /// frame's horizon.
    fn pending(bounds: NodeBox, view: &LodView, boxed: usize) -> Pending {
        Pending {
            block: Block {
                level: 0,
                col: boxed,
                row: 0,
            },
            patches: ([boxed, boxed + 1], [0, 1]),
            seen_from: (bounds, bounds.distances(view.eye_local), Some(20.0)),
            parts: 0,
            hidden: false,
            mean: Some(20.0),
            boxed: Some(boxed),
            candidate: Candidate {
                slot: boxed,
                ..candidate([0.0; 2], 1.0)
            },
        }
    }

    /// Blocks the horizon hides in every bin get no parts and are marked
    /// hidden; the others get the parts `model_parts` gives them, in
    /// order. Without a horizon or counts none is hidden.
    #[test]
    fn blocks_hidden_in_every_bin_are_not_read() {
        let eye = Vec3::new(128.0, 60.0, 128.0);
        let v = view(eye, Vec3::new(1.0, -0.3, 0.0).normalize());
        let (under_eye, far) = (patch(0.0, 0.0), patch(4000.0, -128.0));
        let blocks = [far, under_eye, far, under_eye];
        let expected: Vec<Vec<Part>> = blocks.iter().map(|b| parts_of(b, &v, true)).collect();
        assert_eq!(expected[0].len(), 1);
        assert!(expected[1].len() > 1);
        let shown = [0.0, 0.0, 0.5, 1.0];
        let mut pending: Vec<Pending> = (0..4).map(|i| pending(blocks[i], &v, i)).collect();
        let mut parts = Vec::new();
        place_parts(&mut pending, &v, (true, Some(&shown), None), &mut parts);
        let placed: Vec<(usize, bool)> = pending.iter().map(|p| (p.parts, p.hidden)).collect();
        assert_eq!(
            placed,
            [(0, true), (0, true), (1, false), (expected[3].len(), false)]
        );
        let at: Vec<LatticePoint> = parts.iter().map(|p| p.at).collect();
        let wanted: Vec<LatticePoint> = expected[2..].iter().flatten().map(|p| p.at).collect();
        assert_eq!(at, wanted);
        // Neither a horizon nor counts: every block is read.
        place_parts(&mut pending, &v, (true, None, None), &mut parts);
        let all: usize = expected.iter().map(Vec::len).sum();
        assert_eq!(parts.len(), all);
        assert!(pending.iter().all(|p| !p.hidden));
    }

    /// Rough ridged ground of `samples` x `samples` samples 4 m apart in
    /// 16-cell patches, its error table and its view model.
    fn rough_ridged(samples: usize) -> (Terrain, ErrorTable, SightTable) {
        let map = crate::terrain::Heightmap::from_fn(samples, samples, |r, c| {
            let (x, z) = (c as f32, r as f32);
            let rough = ((x * 12.9898 + z * 78.233).sin() * 43758.547).fract();
            40.0 * (x / 23.0).sin() * (z / 17.0).cos() + 6.0 * rough + 0.2 * x
        })
        .expect("a heightmap");
        let info =
            crate::terrain::TerrainInfo::new(map, glam::DVec2::splat(4.0), 16, glam::DVec2::ZERO)
                .expect("a terrain");
        let terrain = Terrain::new(info, 0.0).expect("a margin");
        let table = terrain.error_table();
        let sight = SightTable::compute(
            terrain.info().heightmap().expect("samples"),
            terrain.grid(),
            (4.0, 4.0),
        );
        (terrain, table, sight)
    }

    /// Blocks are split largest on screen first while the plan has room:
    /// with no room the walk's blocks stand; with room for a few more,
    /// every block split was at least as large on screen as every block
    /// left whole, and the plan stays within its budget; with room for
    /// all, no block larger than `BLOCK_EXTENT_MIN_PX` is left whole. The
    /// blocks cover the same patches however many are split, but for those
    /// outside the frustum that whole blocks took along. Rough
    /// ground, 16-cell patches, seen from low and from high by both
    /// readings.
    #[test]
    fn blocks_largest_on_screen_are_split_while_the_plan_has_room() {
        let (terrain, table, sight) = rough_ridged(513);
        let hierarchy = Hierarchy::new(&terrain, &table);
        let grid = terrain.grid();
        let mut some_left_whole = false;
        for (eye, forward) in [
            (Vec3::new(-300.0, 120.0, -300.0), Vec3::new(1.0, -0.15, 1.0)),
            (
                Vec3::new(-1500.0, 1600.0, 1000.0),
                Vec3::new(1.0, -0.9, 0.0),
            ),
        ] {
            let v = view(eye, forward.normalize());
            for reading in [SightReading::Tessellated, SightReading::Template] {
                let inputs = PlanInputs {
                    table: &table,
                    sight: Some(&sight),
                    merge: true,
                    cull: true,
                    reading,
                    seen: None,
                };
                let walked = |budget: usize| {
                    let mut planner = Planner::default();
                    planner.walker.budget = budget;
                    let pending = &mut planner.pending;
                    let walked = (&mut planner.plan, &mut planner.walker, None);
                    walk(&terrain, &hierarchy, &v, &inputs, walked, pending);
                    planner.plan
                };
                let extent = |b: &PlannedBlock| {
                    let id = NodeId {
                        level: b.level,
                        col: b.col >> b.level,
                        row: b.row >> b.level,
                    };
                    let bounds = NodeBox::of(hierarchy.node(id));
                    bounds.extent(&v, bounds.distances(v.eye_local).0)
                };
                let covered = |plan: &FramePlan| {
                    let mut levels = Vec::new();
                    plan.patch_levels(grid, &mut levels);
                    levels.iter().map(|&l| l != NOT_DRAWN).collect::<Vec<_>>()
                };
                let whole = walked(0);
                let found = whole.blocks.len();
                let large = whole.blocks.iter().filter(|b| b.level > 0).count();
                assert!(large >= 8, "{eye}: {large} blocks of several patches");
                let budget = found + 3 * (large / 2);
                for (room, plan) in [(budget, walked(budget)), (usize::MAX, walked(usize::MAX))] {
                    // Parts outside the frustum are left out: the patches
                    // the whole blocks took along.
                    for (p, (&now, &before)) in
                        covered(&plan).iter().zip(&covered(&whole)).enumerate()
                    {
                        let patch = NodeId::patch(grid.patch_id(p));
                        let outside = NodeBox::of(hierarchy.node(patch)).outside(&v);
                        assert!(
                            now == before || (before && outside),
                            "{eye}, room for {room}: patch {p} covered {now}, before {before}"
                        );
                    }
                    assert!(
                        plan.blocks.len() <= room,
                        "{eye}: {} blocks",
                        plan.blocks.len()
                    );
                    let kept = |b: &&PlannedBlock| {
                        plan.blocks
                            .iter()
                            .any(|p| (p.level, p.col, p.row) == (b.level, b.col, b.row))
                    };
                    let (left, split): (Vec<&PlannedBlock>, Vec<&PlannedBlock>) =
                        whole.blocks.iter().filter(|b| b.level > 0).partition(kept);
                    assert!(!split.is_empty(), "{eye}, room for {room}: none split");
                    let smallest_split = split.iter().map(|b| extent(b)).fold(f32::MAX, f32::min);
                    for b in &left {
                        let e = extent(b);
                        assert!(
                            e <= smallest_split || e <= BLOCK_EXTENT_MIN_PX,
                            "{eye}: a block {e} px across left whole, one {smallest_split} px split"
                        );
                        if room == usize::MAX {
                            assert!(e <= BLOCK_EXTENT_MIN_PX, "{eye}: {e} px left whole");
                        }
                    }
                    some_left_whole |= room == budget && !left.is_empty();
                    for b in plan.blocks.iter().filter(|b| b.level > 0) {
                        assert!(extent(b) <= BLOCK_EXTENT_PX, "{eye}: {} px", extent(b));
                    }
                }
            }
        }
        assert!(some_left_whole, "the budget never bound");
    }

    /// With counts, a block that showed no pixel is not read where the
    /// level it was drawn at kept some of its pixels within tau, was
    /// within tau, or was not drawn: the candidates and the frame's pixels
    /// are those reading every block gives. Blocks whose level put every
    /// pixel over tau are read. Rough ridged ground, 16-cell patches, seen
    /// from low and from high at three tolerances by both readings; the
    /// counts leave groups of 4 x 4 patches dark, counted at the coarsest
    /// level, a middle one, full resolution or not drawn.
    #[test]
    fn blocks_counted_dark_are_read_as_reading_them_gives() {
        let (terrain, table, sight) = rough_ridged(257);
        let hierarchy = Hierarchy::new(&terrain, &table);
        let grid = terrain.grid();
        let (mut hid, mut dark_read) = (0, 0);
        for (eye, forward) in [
            (Vec3::new(-600.0, 50.0, -600.0), Vec3::new(1.0, -0.08, 1.0)),
            (Vec3::new(-900.0, 700.0, 0.0), Vec3::new(1.0, -0.6, 0.1)),
        ] {
            for tau in [0.5, 1.0, 4.0] {
                let mut v = view(eye, forward.normalize());
                v.tau = Tau::new(tau).expect("a tolerance");
                for reading in [SightReading::Tessellated, SightReading::Template] {
                    let inputs = PlanInputs {
                        table: &table,
                        sight: Some(&sight),
                        merge: true,
                        cull: true,
                        reading,
                        seen: None,
                    };
                    let mut planner = Planner::default();
                    let pending = &mut planner.pending;
                    let walked = (&mut planner.plan, &mut planner.walker, None);
                    walk(&terrain, &hierarchy, &v, &inputs, walked, pending);
                    for pattern in 0..4 {
                        let group = |p: usize| {
                            let id = grid.patch_id(p);
                            id.col / 4 + 3 * (id.row / 4) + pattern
                        };
                        let (counts, levels): (Vec<u32>, Vec<u8>) = (0..grid.patch_count())
                            .map(|p| {
                                let level = [0, 2, LEVEL_COUNT as u8, NOT_DRAWN][group(p) % 4];
                                (if group(p) % 3 == 0 { 50 } else { 0 }, level)
                            })
                            .unzip();
                        let seen = SeenPixels::new(grid, &counts, &levels).expect("counts");
                        let counted = Counted {
                            sight: &sight,
                            seen: &seen,
                            tau,
                            shares: reading.shares(),
                        };
                        let read = |pending: &mut [Pending], counted: Option<Counted>| {
                            let mut parts = Vec::new();
                            place_parts(pending, &v, (true, None, counted), &mut parts);
                            let (mut views, mut candidates) = (Vec::new(), Vec::new());
                            let pixels = read_model(
                                &sight,
                                (pending, &parts),
                                (tau, reading.shares()),
                                v.viewport_pixels() as f32,
                                (Some(&seen), None),
                                (&mut views, &mut candidates),
                            );
                            let over: Vec<_> =
                                candidates.iter().map(|c| (c.slot, c.over)).collect();
                            (pixels, over)
                        };
                        let all_read = read(pending, None);
                        assert!(pending.iter().all(|p| !p.hidden));
                        let skipping = read(pending, Some(counted));
                        assert_eq!(skipping, all_read, "tau {tau} {reading:?}");
                        for p in pending.iter() {
                            let (cols, rows) = p.patches;
                            if seen.block_pixels(cols, rows) == 0 {
                                hid += usize::from(p.hidden);
                                dark_read += usize::from(!p.hidden && p.parts > 0);
                            }
                        }
                    }
                }
            }
        }
        assert!(hid > 100, "{hid} dark blocks not read");
        assert!(dark_read > 10, "{dark_read} dark blocks read");
    }

    /// The rays fall to the mean height given, not to the bottom of the
    /// box: a part level with the eye's mean-height ground reads a
    /// shallower fall than the box's bottom would give.
    #[test]
    fn rays_fall_to_the_mean_height() {
        let v = view(Vec3::new(0.0, 60.0, 0.0), Vec3::X);
        let bounds = patch(4000.0, -128.0);
        let mut at_mean = Vec::new();
        let distances = bounds.distances(v.eye_local);
        model_parts((&bounds, distances), &v, true, Some(40.0), &mut at_mean);
        let mut at_bottom = Vec::new();
        model_parts((&bounds, distances), &v, true, None, &mut at_bottom);
        let run = 4000.0;
        assert_eq!(at_mean[0].at, LatticePoint::new(4128.0, 0.0, 20.0 / run));
        assert_eq!(at_bottom[0].at, LatticePoint::new(4128.0, 0.0, 60.0 / run));
    }

    /// The greedy share's steps taken one at a time: each time, of every
    /// candidate's next step, the one with the largest gain (the earlier
    /// candidate between equal gains), until what remains fits `budget`.
    fn greedy_by_scanning(candidates: &[Candidate], budget: f32) -> Vec<usize> {
        let mut levels = vec![0; candidates.len()];
        let mut over: f64 = candidates.iter().map(|c| f64::from(c.over[0])).sum();
        while over > f64::from(budget) {
            let best = candidates
                .iter()
                .enumerate()
                .filter_map(|(i, c)| c.best_step(levels[i]).map(|(g, k)| (g, i, k)))
                .max_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)));
            let Some((_, i, k)) = best else {
                break;
            };
            over -= f64::from(candidates[i].over[levels[i]] - candidates[i].over[k]);
            levels[i] = k;
        }
        levels
    }

    /// A candidate with whole pixels over tau falling from `first` by
    /// the fractions `falls` at each finer level, to none at its bound.
    /// Whole pixels and few sizes make equal gains common.
    fn falling(first: f32, falls: &[f32], patches: f32) -> Candidate {
        let mut over = [0.0; LEVEL_COUNT + 1];
        over[0] = first.floor();
        for (k, f) in falls.iter().enumerate() {
            over[k + 1] = (over[k] * f).floor();
        }
        Candidate {
            slot: 0,
            over,
            bound: falls.len() + 1,
            full: 5,
            patches,
            full_triangles: 2048.0,
            scale: 1.0,
            errors: [0.0; LEVEL_COUNT],
        }
    }

    proptest! {
        /// The greedy share's key orders steps as their gains do under
        /// `total_cmp`, then the earlier candidate, then the coarser level,
        /// and gives its candidate and level back.
        #[test]
        fn step_keys_order_as_gains_then_earlier_candidates(
            a in any::<f32>(),
            b in any::<f32>(),
            i in 0usize..100_000,
            j in 0usize..100_000,
            k in 0usize..8,
        ) {
            let expected = a.total_cmp(&b).then(j.cmp(&i));
            prop_assert_eq!(step_key(a, i, k).cmp(&step_key(b, j, k)), expected);
            prop_assert_eq!(step_candidate(step_key(a, i, k)), i);
            prop_assert_eq!(step_level(step_key(a, i, k)), k);
            prop_assert_eq!(step_key(a, i, k).cmp(&step_key(a, i + 1, 0)), std::cmp::Ordering::Greater);
            prop_assert_eq!(step_key(a, i, k).cmp(&step_key(a, i, k + 1)), std::cmp::Ordering::Greater);
        }

        /// The steps found by splitting are those taken one at a time,
        /// whatever the candidates and the budget.
        #[test]
        fn refining_by_splitting_takes_the_steps_one_at_a_time_would(
            blocks in prop::collection::vec(
                (0.0f32..64.0, prop::collection::vec(0.0f32..1.0, 0..LEVEL_COUNT - 2), 1.0f32..4.0),
                0..300,
            ),
            budget_share in 0.0f32..1.2,
        ) {
            let candidates: Vec<Candidate> = blocks
                .iter()
                .map(|(first, falls, patches)| falling(*first, falls, patches.floor()))
                .collect();
            let total: f32 = candidates.iter().map(|c| c.over[0]).sum();
            let budget = budget_share * total;
            let mut share = GreedyShare::default();
            share.refine(&candidates, budget);
            prop_assert_eq!(&share.levels, &greedy_by_scanning(&candidates, budget));
        }
    }
}
