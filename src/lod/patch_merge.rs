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
//! **Which nodes.** A patch may be merged when the error LOD would draw it
//! with one segment on every side and inside (`patch_error_factors`),
//! neither it nor a neighbour at full resolution, and it has the full cell
//! count both ways (the far remainders do not). A node is merged when all
//! four of its children may be and its own inside factor, seen from its
//! box (its corners' x and z, the terrain's whole height range, what the
//! control shader knows of it), is at most 2^m: no more segments than its
//! patches would have had. The largest such nodes are drawn, up to level
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
use rayon::prelude::*;

use super::factors::{
    error_tess_factor, patch_box_distance, patch_error_factors, shared_edge_errors, strip_distance,
    Across, PatchTessFactors, TessErrorChoice,
};
use crate::terrain::error_table::{ErrorTable, PatchErrors, LEVEL_COUNT};
use crate::terrain::{PatchId, Terrain};

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

    /// The levels packed four to a word, first patch in the low byte, as
    /// the control shader reads them.
    pub fn level_words(&self) -> Vec<u32> {
        self.levels
            .chunks(4)
            .map(|c| c.iter().rev().fold(0u32, |w, &l| w << 8 | u32::from(l)))
            .collect()
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

/// The corners of the aligned block of `span` x `span` patches from
/// (`col`, `row`), eye-relative, in control point order.
fn block_corners(
    terrain: &Terrain,
    (col, row): (usize, usize),
    span: usize,
    eye: Vec3,
) -> [Vec3; 4] {
    let corner =
        |c: usize, r: usize, k: usize| terrain.patch_corners(PatchId { row: r, col: c })[k] - eye;
    let (last_c, last_r) = (col + span - 1, row + span - 1);
    [
        corner(col, row, 0),
        corner(last_c, row, 1),
        corner(col, last_r, 2),
        corner(last_c, last_r, 3),
    ]
}

/// One level of candidate nodes, row-major over the aligned blocks that
/// fit in the grid.
struct Candidates {
    cols: usize,
    rows: usize,
    /// The largest error of the block's patches, level by level.
    patch_max: Vec<PatchErrors>,
    /// The block's lowest and highest height.
    bounds: Vec<[f32; 2]>,
    /// The node the block may be drawn as, where it may be merged; at
    /// level 0 a block is one patch, and its node the patch itself.
    nodes: Vec<Option<MergedNode>>,
}

/// Chooses the frame's merged nodes for the error LOD at `pixel_error`
/// pixels, seen from `eye_local`: the largest blocks the module's rule
/// allows. `table` is the errors the control shader reads, `choice` the
/// frame's full-resolution patches.
pub fn merge_patches(
    terrain: &Terrain,
    table: &ErrorTable,
    choice: &TessErrorChoice,
    eye_local: Vec3,
    pixels_per_radian: f32,
    pixel_error: f32,
) -> PatchMerge {
    let grid = terrain.grid();
    let (cols, rows) = (grid.patch_cols(), grid.patch_rows());
    let n = grid.cells_per_patch();
    let (lo, hi) = terrain.info().min_max();
    let range = [lo - eye_local.y, hi - eye_local.y];
    let errors =
        |p: usize| -> &PatchErrors { table.patch(p).try_into().expect("LEVEL_COUNT levels") };
    // Level 0: the patches that may be merged.
    let flat: Vec<Option<MergedNode>> = (0..grid.patch_count())
        .into_par_iter()
        .map(|p| {
            let id = grid.patch_id(p);
            let rect = grid.sample_rect(id);
            if rect.cells_x() != n || rect.cells_z() != n || choice.is_full_resolution(p) {
                return None;
            }
            let mut neighbours = [Across::Border; 4];
            let offsets = [(-1, 0), (0, -1), (1, 0), (0, 1)];
            for (across, (dc, dr)) in neighbours.iter_mut().zip(offsets) {
                let (c, r) = (id.col as isize + dc, id.row as isize + dr);
                if c < 0 || r < 0 || c >= cols as isize || r >= rows as isize {
                    continue;
                }
                let q = r as usize * cols + c as usize;
                if choice.is_full_resolution(q) {
                    return None;
                }
                *across = Across::Patch(errors(q));
            }
            let corners = terrain.patch_corners(id).map(|c| c - eye_local);
            let [b_lo, b_hi] = terrain.y_bounds()[p];
            let factors = patch_error_factors(
                corners,
                [b_lo - eye_local.y, b_hi - eye_local.y],
                range,
                errors(p),
                neighbours,
                [n as u32; 2],
                pixels_per_radian,
                pixel_error,
            );
            let one_segment = factors
                .edges
                .iter()
                .chain(&factors.inside)
                .all(|&f| f == 1.0);
            one_segment.then_some(MergedNode {
                col: id.col as u32,
                row: id.row as u32,
                level: 0,
                errors: *errors(p),
                predicted_px: choice.predicted_px[p],
            })
        })
        .collect();
    let mut levels = vec![Candidates {
        cols,
        rows,
        patch_max: (0..grid.patch_count()).map(|p| *errors(p)).collect(),
        bounds: terrain.y_bounds().to_vec(),
        nodes: flat,
    }];
    for level in 1..=MAX_MERGE_LEVEL {
        let below = levels.last().expect("level 0");
        let (c_cols, c_rows) = (below.cols / 2, below.rows / 2);
        if c_cols == 0 || c_rows == 0 {
            break;
        }
        let span = 1usize << level;
        let blocks: Vec<(PatchErrors, [f32; 2], Option<MergedNode>)> = (0..c_cols * c_rows)
            .into_par_iter()
            .map(|b| {
                let (bc, br) = (b % c_cols, b / c_cols);
                let children = [(0, 0), (1, 0), (0, 1), (1, 1)]
                    .map(|(dc, dr)| (2 * br + dr) * below.cols + 2 * bc + dc);
                let mut patch_max = [0.0f32; LEVEL_COUNT];
                let mut bounds = [f32::INFINITY, f32::NEG_INFINITY];
                for &c in &children {
                    for (m, e) in patch_max.iter_mut().zip(&below.patch_max[c]) {
                        *m = m.max(*e);
                    }
                    bounds = [
                        bounds[0].min(below.bounds[c][0]),
                        bounds[1].max(below.bounds[c][1]),
                    ];
                }
                let node = children
                    .iter()
                    .all(|&c| below.nodes[c].is_some())
                    .then(|| {
                        let (col, row) = (bc * span, br * span);
                        let own = node_errors(&patch_max, bounds[1] - bounds[0], level);
                        let corners = block_corners(terrain, (col, row), span, eye_local);
                        let distance = patch_box_distance(corners, range);
                        let inside = error_tess_factor(
                            &own,
                            distance,
                            pixels_per_radian,
                            pixel_error,
                            (n as u32) << level,
                        );
                        let k = (inside as u32).trailing_zeros() as usize;
                        (inside <= span as f32).then_some(MergedNode {
                            col: col as u32,
                            row: row as u32,
                            level,
                            errors: own,
                            predicted_px: own[k] * pixels_per_radian
                                / distance.max(f32::MIN_POSITIVE),
                        })
                    })
                    .flatten();
                (patch_max, bounds, node)
            })
            .collect();
        levels.push(Candidates {
            cols: c_cols,
            rows: c_rows,
            patch_max: blocks.iter().map(|b| b.0).collect(),
            bounds: blocks.iter().map(|b| b.1).collect(),
            nodes: blocks.into_iter().map(|b| b.2).collect(),
        });
    }
    // The largest mergeable blocks, coarsest first; a block inside a
    // chosen one is already taken.
    let mut merge = PatchMerge::none(grid.patch_count());
    for candidates in levels.iter().skip(1).rev() {
        for node in candidates.nodes.iter().flatten() {
            let (col, row, span) = (node.col as usize, node.row as usize, node.span() as usize);
            if merge.levels[row * cols + col] != 0 {
                continue;
            }
            for r in row..row + span {
                merge.levels[r * cols + col..r * cols + col + span].fill(node.level as u8);
            }
            merge.nodes.push(*node);
        }
    }
    merge
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
