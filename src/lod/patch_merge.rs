//! Merged patches: the tess path's error LOD draws smooth or distant
//! ground with fewer, larger patches.
//!
//! A patch the error LOD draws with one segment on every side and inside
//! still costs the control and evaluation shaders a patch. Seen from afar,
//! a whole terrain can be that: 252,658 patches of a 32769^2 map in view,
//! every one two triangles. A **node** of level m is an aligned block of
//! 2^m x 2^m patches drawn as one patch whose control points are the
//! block's corners. Its factors follow the same rules as a patch's, with
//! two changes on its sides:
//!
//! - towards a node of its own level (aligned, so the sides coincide) an
//!   edge takes the larger errors of the two, from the strip on it, as
//!   between patches;
//! - towards anything else (a patch, or a node of another level) an edge
//!   has one segment per patch along it: 2^m. A patch next to a node puts
//!   one segment on that edge, and a node of another level one per patch,
//!   so every vertex on the shared side is a patch corner both draw. Equal
//!   spacing with whole factors puts those vertices on samples, and the
//!   surface stays watertight.
//!
//! **Errors of a node**, per level k (2^k segments across it): at k >= m
//! the lattice is each patch's at level k - m, so the error is the largest
//! of its patches' at that level. Below, one segment spans several patches;
//! the drawn surface and the reference then both lie within the node's
//! heights (its patches' Y bounds), so the height range bounds the error.
//! Levels stay non-increasing as k rises, as in the error table.
//!
//! **Which nodes** (`lod::plan`, walking `lod::hierarchy` from the top).
//! A node of whole full-size patches (the far remainders are not) is
//! merged when its patches' and the surrounding patches' largest
//! one-segment error is within tolerance from the nearest point of its
//! footprint grown by a patch, between the terrain's lowest and highest
//! heights: then every patch in or around it would be drawn with one
//! segment on every side and inside (`patch_error_factors`), none at full
//! resolution. And its own inside factor, seen from its box (its corners'
//! x and z, the terrain's whole height range, what the control shader
//! knows of it), must be at most 2^m: no more segments than its patches
//! would have had. The largest such nodes are drawn, up to level
//! `MAX_MERGE_LEVEL`, where one segment per patch along a side is the
//! largest factor a control shader may output.
//!
//! Why that keeps the error bound: every patch in a merged node was
//! within tolerance at one segment from its own box, and the node's inside
//! level is within tolerance from the node's nearer box. An edge towards a
//! same-level node is chosen as between patches; the edges with one segment
//! per patch are the patches' own level-0 edges, which both sides accepted
//! (each patch on the node's side was flat, so the edge they share with
//! the patch outside had one segment by the patches' own rule).

use glam::Vec3;

use super::factors::{
    error_tess_factor, patch_box_distance, shared_edge_errors, strip_distance, PatchTessFactors,
};
use super::hierarchy::square_range;
use crate::terrain::error_table::{PatchErrors, LEVEL_COUNT};
use crate::terrain::{PatchGrid, PatchId};

/// The coarsest node: 2^6 x 2^6 patches, whose sides towards other levels
/// need 64 segments, the largest factor.
pub const MAX_MERGE_LEVEL: u32 = (LEVEL_COUNT - 1) as u32;

/// One merged node: an aligned block of 2^level x 2^level patches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MergedNode {
    /// Its first (upper-left) patch.
    pub col: u32,
    pub row: u32,
    pub level: u32,
    /// Its errors at 1, 2, ..., 64 segments across it.
    pub errors: PatchErrors,
    /// Its error bound at the level chosen for its inside, in pixels from
    /// its box's nearest point.
    pub predicted_px: f32,
}

impl MergedNode {
    /// Patches a side.
    pub fn span(&self) -> u32 {
        1 << self.level
    }

    /// The columns and rows of its patches in `grid` (a node at the
    /// grid's far sides may be cut by them).
    pub fn patch_range(&self, grid: &PatchGrid) -> ([usize; 2], [usize; 2]) {
        square_range(
            [grid.patch_cols(), grid.patch_rows()],
            [self.col as usize, self.row as usize],
            self.span() as usize,
        )
    }

    /// Whether patch `id` lies in the node.
    pub fn holds(&self, id: PatchId) -> bool {
        let (c, r, s) = (self.col as usize, self.row as usize, self.span() as usize);
        (c..c + s).contains(&id.col) && (r..r + s).contains(&id.row)
    }
}

/// A frame's merged nodes and, per patch, the level of the node holding
/// it (0 where it is drawn on its own).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PatchMerge {
    pub levels: Vec<u8>,
    pub nodes: Vec<MergedNode>,
}

impl PatchMerge {
    /// No patch merged.
    pub fn none(patch_count: usize) -> Self {
        PatchMerge {
            levels: vec![0; patch_count],
            nodes: Vec::new(),
        }
    }
}

/// What lies across a merged node's side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NodeAcross<'a> {
    /// The terrain's border: the side is the node's own.
    Border,
    /// A node of the same level, with its errors.
    Same(&'a PatchErrors),
    /// A patch, or a node of another level: one segment per patch.
    Other,
}

/// Errors of a level-`level` node whose patches' largest errors, level by
/// level, are `patch_max`, and whose heights span `height_span`.
pub fn node_errors(patch_max: &PatchErrors, height_span: f32, level: u32) -> PatchErrors {
    let m = level as usize;
    std::array::from_fn(|k| {
        if k >= m {
            patch_max[k - m]
        } else {
            height_span.max(patch_max[0])
        }
    })
}

/// Error-bounded factors of a merged node of level `level` in patches of
/// `cells_per_patch` cells: each side by what lies across it (`NodeAcross`),
/// from the strip on it; the inside from the node's box, its corners' x
/// and z and the terrain's whole height range. `corners` (the node's, in
/// control point order) and `height_range` are eye-relative. Mirror: the
/// merged branch of glsl/terrain.tesc.
#[allow(clippy::too_many_arguments)]
pub fn node_error_factors(
    corners: [Vec3; 4],
    height_range: [f32; 2],
    own: &PatchErrors,
    across: [NodeAcross; 4],
    level: u32,
    cells_per_patch: u32,
    pixels_per_radian: f32,
    pixel_error: f32,
) -> PatchTessFactors {
    let cells = cells_per_patch << level;
    let ends = super::factors::patch_edges(corners);
    let edges = std::array::from_fn(|i| {
        let errors = match across[i] {
            NodeAcross::Other => return (1u32 << level) as f32,
            NodeAcross::Border => *own,
            NodeAcross::Same(theirs) => shared_edge_errors(own, Some(theirs)),
        };
        let d = strip_distance(ends[i], height_range);
        error_tess_factor(&errors, d, pixels_per_radian, pixel_error, cells)
    });
    let distance = patch_box_distance(corners, height_range);
    let inside = error_tess_factor(own, distance, pixels_per_radian, pixel_error, cells);
    PatchTessFactors {
        edges,
        inside: [inside, inside],
    }
}

/// What lies across each side of `node` in `merge` (left, top, right,
/// bottom), as the control shader finds it: the patch just past the side's
/// first patch, and the level of the node holding it.
pub fn node_across<'m>(
    merge: &'m PatchMerge,
    node: &MergedNode,
    cols: usize,
    rows: usize,
) -> [NodeAcross<'m>; 4] {
    let span = node.span() as isize;
    let (c, r) = (node.col as isize, node.row as isize);
    [(-1, 0), (0, -1), (span, 0), (0, span)].map(|(dc, dr)| {
        let (qc, qr) = (c + dc, r + dr);
        if qc < 0 || qr < 0 || qc >= cols as isize || qr >= rows as isize {
            return NodeAcross::Border;
        }
        let q = qr as usize * cols + qc as usize;
        if u32::from(merge.levels[q]) != node.level {
            return NodeAcross::Other;
        }
        let id = PatchId {
            row: qr as usize,
            col: qc as usize,
        };
        merge
            .nodes
            .iter()
            .find(|n| n.level == node.level && n.holds(id))
            .map_or(NodeAcross::Other, |n| NodeAcross::Same(&n.errors))
    })
}
