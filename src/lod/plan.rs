//! The frame plan: from a terrain, its hierarchy and one view, what the
//! tess path draws and at which levels, chosen in time that grows with the
//! nodes in view, not with the terrain's samples.
//!
//! The hierarchy is walked from its top node down. A node outside the
//! frustum is left with everything under it. A node whose patches, and
//! the patches around it, would all be drawn with one segment is drawn as
//! one merged patch (`patch_merge`), by the same rule as patches, from its
//! precomputed largest one-segment error seen from its nearest point. The
//! rest is refined down to patches.
//!
//! **A patch's level.** The error table bounds each level's largest
//! vertical error anywhere on the patch; seen face-on from the patch's
//! nearest point, the coarsest level it keeps within tau is the bound's
//! choice, and no patch is drawn finer. Where the terrain has a view model
//! (`terrain::sight`), the frame may let a share of its terrain's pixels
//! exceed tau (`EXCEED_SHARE`): each patch's pixels over tau at each
//! coarser level are read off the model from the direction the patch is
//! seen, and the share is spent greedily on the patches and levels that
//! save the most triangles for it (the same exchange as the view measure's,
//! on the model's figures). Patches without a model (the far remainders)
//! and patches the eye is inside keep the bound's choice.
//!
//! The control shader reads a patch's levels as errors: the bound's own
//! row, or for a level the greedy chose, zero from that level on and an
//! infinite error below it. Edges take the larger errors of the two
//! patches sharing them, so both sides still agree.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use glam::{Vec2, Vec3};

use super::factors::{box_distance, error_tess_factor, patch_box_distance, within_tolerance};
use super::hierarchy::{node_footprint, Hierarchy, NodeId};
use super::patch_merge::{node_errors, MergedNode, MAX_MERGE_LEVEL};
use super::view::LodView;
use crate::terrain::error_table::{ErrorTable, PatchErrors, LEVEL_COUNT};
use crate::terrain::sight::{LatticePoint, SightTable};
use crate::terrain::Terrain;

/// Share of the frame's terrain pixels the view model's choice may put
/// over tau: half the 1 % a 99th percentile allows, the other half left to
/// what the model does not see (hidden ground, silhouettes, the
/// tessellator's transitions, the lattice's interpolation).
pub const EXCEED_SHARE: f64 = 0.005;

/// An error no distance brings within tolerance: the control shader then
/// takes a finer level.
pub const REJECTED: f32 = f32::MAX;

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
}

/// A patch the frame draws on its own.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlannedPatch {
    /// Its index in the grid.
    pub index: u32,
    /// The errors the control shader reads for it.
    pub errors: PatchErrors,
    /// Drawn with the reference's own triangles.
    pub full_resolution: bool,
    /// Its error bound at its level, face-on from its box's nearest point,
    /// in pixels (0 at full resolution).
    pub predicted_px: f32,
    /// The level chosen for its inside: the error table's level index, or
    /// the full-resolution index.
    pub level: u8,
}

/// What one frame of the tess path draws.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FramePlan {
    /// Patches in view drawn on their own, in grid order.
    pub patches: Vec<PlannedPatch>,
    /// Merged nodes in view.
    pub merged: Vec<MergedNode>,
    /// Nodes of the hierarchy the walk visited.
    pub nodes_visited: usize,
    /// The largest of the drawn patches' and nodes' predicted errors.
    pub predicted_max_px: f32,
}

/// A patch whose level the greedy share decides.
struct Candidate {
    /// Index into the plan's patches.
    slot: usize,
    /// Pixels over tau at each level index up to `bound`.
    over: [f32; LEVEL_COUNT + 1],
    /// The bound's level: nothing over tau from there on.
    bound: usize,
    /// The full-resolution level index.
    full: usize,
    /// Triangles at full resolution.
    full_triangles: f32,
}

impl Candidate {
    fn triangles(&self, k: usize) -> f32 {
        if k >= self.full {
            self.full_triangles
        } else {
            2.0 * 4f32.powi(k as i32)
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
}

/// Plans one frame of the tess path's error LOD (see the module
/// documentation).
pub fn plan(
    terrain: &Terrain,
    hierarchy: &Hierarchy,
    view: &LodView,
    inputs: &PlanInputs,
) -> FramePlan {
    let mut plan = FramePlan::default();
    let mut candidates = Vec::new();
    let mut frame_pixels = 0.0f64;
    let tau = view.tau.px();
    let n = terrain.grid().cells_per_patch() as u32;
    let cols = terrain.grid().patch_cols();
    let eye = view.eye_local;
    let [range_lo, range_hi] = hierarchy.height_range();
    let mut stack = vec![NodeId {
        level: hierarchy.top(),
        col: 0,
        row: 0,
    }];
    while let Some(id) = stack.pop() {
        plan.nodes_visited += 1;
        let node = hierarchy.node(id);
        let (pc, pr) = hierarchy.patch_range(id);
        let (lo, hi) = node_footprint(terrain, pc, pr);
        if inputs.cull {
            let min = Vec3::new(lo[0], node.bounds[0], lo[1]);
            let max = Vec3::new(hi[0], node.bounds[1], hi[1]);
            let (centre, half) = (0.5 * (min + max), 0.5 * (max - min));
            if view.frustum.aabb_outside(centre - eye, half) {
                continue;
            }
        }
        if inputs.merge && id.level >= 1 && id.level <= MAX_MERGE_LEVEL && node.whole {
            // Seen from the nearest point of the node's footprint between
            // the terrain's lowest and highest heights: nearer than any of
            // its patches' boxes and any side's strip.
            let d = box_distance(
                Vec3::new(lo[0], range_lo, lo[1]) - eye,
                Vec3::new(hi[0], range_hi, hi[1]) - eye,
            );
            let scale = view.scale(d);
            if within_tolerance(node.flat_error, scale, tau) {
                let own = node_errors(&node.patch_max, node.bounds[1] - node.bounds[0], id.level);
                let span = 1u32 << id.level;
                let inside = error_tess_factor(&own, d, view.pixels_per_radian, tau, n << id.level);
                if inside <= span as f32 {
                    let k = (inside as u32).trailing_zeros() as usize;
                    let predicted_px = own[k] * scale;
                    plan.predicted_max_px = plan.predicted_max_px.max(predicted_px);
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
        if id.level > 0 {
            // Children nearer the eye last, so they are visited first.
            stack.extend(hierarchy.children(id));
            continue;
        }
        let p = pr[0] * cols + pc[0];
        let slot = plan.patches.len();
        let (patch, candidate) = plan_patch(terrain, view, inputs, p, slot, &mut frame_pixels);
        plan.patches.push(patch);
        candidates.extend(candidate);
    }
    if !candidates.is_empty() {
        let budget = EXCEED_SHARE * frame_pixels.min(view.viewport_pixels());
        let levels = share_greedily(&candidates, budget as f32);
        for (c, level) in candidates.iter().zip(levels) {
            let patch = &mut plan.patches[c.slot];
            let scale = patch.predicted_px;
            patch.level = level as u8;
            patch.full_resolution = level >= c.full;
            let row = inputs.table.patch(patch.index as usize);
            patch.predicted_px = if patch.full_resolution {
                0.0
            } else {
                row[level] * scale
            };
            patch.errors = std::array::from_fn(|k| if k < level { REJECTED } else { 0.0 });
            if patch.full_resolution {
                patch.errors.copy_from_slice(row);
            }
        }
    }
    plan.patches.sort_unstable_by_key(|p| p.index);
    plan.predicted_max_px = plan
        .patches
        .iter()
        .map(|p| p.predicted_px)
        .fold(plan.predicted_max_px, f32::max);
    plan
}

/// Patch `p`'s entry in the plan at the bound's level, and, where the view
/// model may coarsen it, its candidate (whose `PlannedPatch::predicted_px`
/// holds the patch's scale until the share is spent). Adds the pixels the
/// model sees of it to `frame_pixels`.
fn plan_patch(
    terrain: &Terrain,
    view: &LodView,
    inputs: &PlanInputs,
    p: usize,
    slot: usize,
    frame_pixels: &mut f64,
) -> (PlannedPatch, Option<Candidate>) {
    let grid = terrain.grid();
    let id = grid.patch_id(p);
    let rect = grid.sample_rect(id);
    let (cx, cz) = (rect.cells_x() as u32, rect.cells_z() as u32);
    let side = cx.min(cz);
    // The first level index whose segments reach the smaller side.
    let full = (0..LEVEL_COUNT)
        .find(|&k| (1u32 << k) >= side)
        .unwrap_or(LEVEL_COUNT);
    let eye = view.eye_local;
    let corners = terrain.patch_corners(id).map(|c| c - eye);
    let [y_lo, y_hi] = terrain.y_bounds()[p];
    let d = patch_box_distance(corners, [y_lo - eye.y, y_hi - eye.y]);
    let scale = view.scale(d);
    let tau = view.tau.px();
    let row: PatchErrors = inputs
        .table
        .patch(p)
        .try_into()
        .expect("LEVEL_COUNT levels a patch");
    let bound = (0..full)
        .find(|&k| within_tolerance(row[k], scale, tau))
        .unwrap_or(full);
    let planned = PlannedPatch {
        index: p as u32,
        errors: row,
        full_resolution: bound >= full,
        predicted_px: if bound >= full {
            0.0
        } else {
            row[bound] * scale
        },
        level: bound as u8,
    };
    let Some(sight) = inputs.sight.filter(|s| s.has(p) && d > 0.0) else {
        return (planned, None);
    };
    // Seen from the patch's centre direction, falling as the ray to its
    // box's nearest point falls.
    let [ul, _, _, lr] = corners;
    let centre = 0.5 * (Vec2::new(ul.x, ul.z) + Vec2::new(lr.x, lr.z));
    let reach = (d * d - {
        let below = (y_lo - eye.y).max(eye.y - y_hi).max(0.0);
        below * below
    })
    .max(0.0)
    .sqrt();
    let fall = if reach > 0.0 {
        (eye.y - y_lo) / reach
    } else {
        f32::INFINITY
    };
    let at = LatticePoint::new(centre.x, centre.y, fall);
    let pixels =
        (sight.area(p, &at).unwrap_or(0.0) * scale * scale).min(view.viewport_pixels() as f32);
    *frame_pixels += f64::from(pixels);
    if bound == 0 {
        return (planned, None);
    }
    let threshold = tau / scale;
    let mut over = [0.0f32; LEVEL_COUNT + 1];
    for (k, o) in over.iter_mut().enumerate().take(bound) {
        *o = pixels * sight.over_fraction(p, k, &at, threshold).unwrap_or(1.0);
    }
    let candidate = Candidate {
        slot,
        over,
        bound,
        full,
        full_triangles: 2.0 * (cx * cz) as f32,
    };
    (
        PlannedPatch {
            predicted_px: scale,
            ..planned
        },
        Some(candidate),
    )
}

/// Each candidate's level: from every one at its coarsest, the step that
/// relieves the most pixels over tau per triangle added goes first, until
/// what remains over tau fits `budget`.
fn share_greedily(candidates: &[Candidate], budget: f32) -> Vec<usize> {
    #[derive(PartialEq)]
    struct Step(f32, usize, usize);
    impl Eq for Step {}
    impl PartialOrd for Step {
        fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
            Some(self.cmp(other))
        }
    }
    impl Ord for Step {
        fn cmp(&self, other: &Self) -> Ordering {
            self.0.total_cmp(&other.0).then(other.1.cmp(&self.1))
        }
    }
    let mut levels = vec![0usize; candidates.len()];
    let mut over: f32 = candidates.iter().map(|c| c.over[0]).sum();
    let mut heap: BinaryHeap<Step> = candidates
        .iter()
        .enumerate()
        .filter_map(|(i, c)| c.best_step(0).map(|(g, k)| Step(g, i, k)))
        .collect();
    while over > budget {
        let Some(Step(_, i, k)) = heap.pop() else {
            break;
        };
        let c = &candidates[i];
        over -= c.over[levels[i]] - c.over[k];
        levels[i] = k;
        if let Some((g, next)) = c.best_step(k) {
            heap.push(Step(g, i, next));
        }
    }
    levels
}

/// The patches whose boxes are not outside the frustum (all of them
/// without `cull`), in grid order, found by walking the hierarchy.
pub fn patches_in_view(
    terrain: &Terrain,
    hierarchy: &Hierarchy,
    view: &LodView,
    cull: bool,
) -> (Vec<u32>, usize) {
    let cols = terrain.grid().patch_cols();
    let mut patches = Vec::new();
    let mut visited = 0;
    let mut stack = vec![NodeId {
        level: hierarchy.top(),
        col: 0,
        row: 0,
    }];
    while let Some(id) = stack.pop() {
        visited += 1;
        let node = hierarchy.node(id);
        let (pc, pr) = hierarchy.patch_range(id);
        if cull {
            let (lo, hi) = node_footprint(terrain, pc, pr);
            let min = Vec3::new(lo[0], node.bounds[0], lo[1]);
            let max = Vec3::new(hi[0], node.bounds[1], hi[1]);
            let (centre, half) = (0.5 * (min + max), 0.5 * (max - min));
            if view.frustum.aabb_outside(centre - view.eye_local, half) {
                continue;
            }
        }
        if id.level > 0 {
            stack.extend(hierarchy.children(id));
            continue;
        }
        patches.push((pr[0] * cols + pc[0]) as u32);
    }
    patches.sort_unstable();
    (patches, visited)
}
