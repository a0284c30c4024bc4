//! The node hierarchy the level choice walks: a quadtree over the patch
//! grid, built once per terrain from its Y bounds and error table.
//!
//! A node of level m is an aligned block of up to 2^m x 2^m patches (the
//! blocks along the grid's far sides are cut short). Level 0 is the patches
//! themselves; the single node of the top level holds the whole grid. Each
//! node keeps what a frame needs to decide, without visiting its patches,
//! whether it is out of view or can be drawn as one merged patch
//! (`patch_merge`): its height bounds, the largest error of its patches at
//! each level, and the largest one-segment error of its patches and of the
//! patches around it.

use glam::Vec3;

use crate::terrain::error_table::{ErrorTable, PatchErrors, LEVEL_COUNT};
use crate::terrain::{PatchId, Terrain};

/// One level of nodes, row-major.
#[derive(Clone, Debug, PartialEq)]
struct NodeLevel {
    cols: usize,
    rows: usize,
    nodes: Vec<Node>,
}

/// What a node knows of its patches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// Lowest and highest height of its patches (their Y bounds).
    pub bounds: [f32; 2],
    /// The largest error of its patches, level by level.
    pub patch_max: PatchErrors,
    /// The largest one-segment error of its patches and of every patch
    /// beside or diagonally next to the block: where this is within
    /// tolerance, every patch of the block and every side it shares is
    /// drawn with one segment by the patches' own rule.
    pub flat_error: f32,
    /// Whether it is a whole 2^m x 2^m block of full-size patches, the
    /// shape a merged node needs.
    pub whole: bool,
    /// Its footprint in local x and z: the lower-left and upper-right
    /// corners of its patches' corners.
    pub footprint: [[f32; 2]; 2],
}

impl Node {
    /// Its box, terrain-local: its footprint's x and z, its bounds' y, as
    /// its lowest and highest corners.
    pub fn aabb(&self) -> (Vec3, Vec3) {
        let [lo, hi] = self.footprint;
        let [y_lo, y_hi] = self.bounds;
        (Vec3::new(lo[0], y_lo, lo[1]), Vec3::new(hi[0], y_hi, hi[1]))
    }

    /// Distance from `eye` (terrain-local) to the nearest point of its box.
    pub fn distance(&self, eye: Vec3) -> f32 {
        let (lo, hi) = self.aabb();
        super::box_distance(lo - eye, hi - eye)
    }
}

/// The quadtree over one terrain's patches.
#[derive(Clone, Debug, PartialEq)]
pub struct Hierarchy {
    levels: Vec<NodeLevel>,
    /// The terrain's lowest and highest height.
    height_range: [f32; 2],
}

/// A node's place: its level and its column and row among that level's
/// nodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct NodeId {
    pub level: u32,
    pub col: u32,
    pub row: u32,
}

impl NodeId {
    /// The level-0 node of patch `id`.
    pub fn patch(id: PatchId) -> NodeId {
        NodeId {
            level: 0,
            col: id.col as u32,
            row: id.row as u32,
        }
    }
}

impl Hierarchy {
    /// Builds the tree of `terrain` from `table`, its per-patch errors.
    pub fn new(terrain: &Terrain, table: &ErrorTable) -> Hierarchy {
        let grid = terrain.grid();
        let (cols, rows) = (grid.patch_cols(), grid.patch_rows());
        let n = grid.cells_per_patch();
        let errors = |p: usize| -> PatchErrors {
            table
                .patch(p)
                .try_into()
                .expect("LEVEL_COUNT levels a patch")
        };
        // Each patch's one-segment error, widened by its eight neighbours'.
        let flat_with_ring: Vec<f32> = (0..grid.patch_count())
            .map(|p| {
                let id = grid.patch_id(p);
                let mut e = 0.0f32;
                for r in id.row.saturating_sub(1)..=(id.row + 1).min(rows - 1) {
                    for c in id.col.saturating_sub(1)..=(id.col + 1).min(cols - 1) {
                        e = e.max(table.error(r * cols + c, 0));
                    }
                }
                e
            })
            .collect();
        let patches = NodeLevel {
            cols,
            rows,
            nodes: (0..grid.patch_count())
                .map(|p| {
                    let id = grid.patch_id(p);
                    let rect = grid.sample_rect(id);
                    let (lo, hi) =
                        node_footprint(terrain, [id.col, id.col + 1], [id.row, id.row + 1]);
                    Node {
                        bounds: terrain.y_bounds()[p],
                        patch_max: errors(p),
                        flat_error: flat_with_ring[p],
                        whole: rect.cells_x() == n && rect.cells_z() == n,
                        footprint: [lo, hi],
                    }
                })
                .collect(),
        };
        let mut levels = vec![patches];
        while levels.last().is_some_and(|l| l.cols > 1 || l.rows > 1) {
            let below = levels.last().expect("level 0");
            let (c_cols, c_rows) = (below.cols.div_ceil(2), below.rows.div_ceil(2));
            let mut nodes = Vec::with_capacity(c_cols * c_rows);
            for r in 0..c_rows {
                for c in 0..c_cols {
                    let mut node = Node {
                        bounds: [f32::INFINITY, f32::NEG_INFINITY],
                        patch_max: [0.0; LEVEL_COUNT],
                        flat_error: 0.0,
                        whole: true,
                        footprint: [[f32::INFINITY; 2], [f32::NEG_INFINITY; 2]],
                    };
                    let mut children = 0;
                    for (dc, dr) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let (cc, cr) = (2 * c + dc, 2 * r + dr);
                        if cc >= below.cols || cr >= below.rows {
                            continue;
                        }
                        children += 1;
                        let child = &below.nodes[cr * below.cols + cc];
                        node.bounds = [
                            node.bounds[0].min(child.bounds[0]),
                            node.bounds[1].max(child.bounds[1]),
                        ];
                        for (m, e) in node.patch_max.iter_mut().zip(&child.patch_max) {
                            *m = m.max(*e);
                        }
                        node.flat_error = node.flat_error.max(child.flat_error);
                        node.whole &= child.whole;
                        let [lo, hi] = &mut node.footprint;
                        for a in 0..2 {
                            lo[a] = lo[a].min(child.footprint[0][a]);
                            hi[a] = hi[a].max(child.footprint[1][a]);
                        }
                    }
                    node.whole &= children == 4;
                    nodes.push(node);
                }
            }
            levels.push(NodeLevel {
                cols: c_cols,
                rows: c_rows,
                nodes,
            });
        }
        let (lo, hi) = terrain.info().min_max();
        Hierarchy {
            levels,
            height_range: [lo, hi],
        }
    }

    /// The top level's index (its one node holds the grid).
    pub fn top(&self) -> u32 {
        (self.levels.len() - 1) as u32
    }

    /// The top level's one node, where a walk starts.
    pub fn root(&self) -> NodeId {
        NodeId {
            level: self.top(),
            col: 0,
            row: 0,
        }
    }

    /// The terrain's lowest and highest height.
    pub fn height_range(&self) -> [f32; 2] {
        self.height_range
    }

    pub fn node(&self, id: NodeId) -> &Node {
        let level = &self.levels[id.level as usize];
        &level.nodes[id.row as usize * level.cols + id.col as usize]
    }

    /// Calls `f` with each of the node's children that exist and its node,
    /// in the order (upper-left, upper-right, lower-left, lower-right):
    /// the level below is looked up once.
    pub fn for_each_child(&self, id: NodeId, mut f: impl FnMut(NodeId, &Node)) {
        let Some(level) = id.level.checked_sub(1) else {
            return;
        };
        let below = &self.levels[level as usize];
        for (dc, dr) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let (col, row) = (2 * id.col + dc, 2 * id.row + dr);
            if (col as usize) < below.cols && (row as usize) < below.rows {
                let node = &below.nodes[row as usize * below.cols + col as usize];
                f(NodeId { level, col, row }, node);
            }
        }
    }

    /// The patches a node covers: columns and rows, end exclusive.
    pub fn patch_range(&self, id: NodeId) -> ([usize; 2], [usize; 2]) {
        let span = 1usize << id.level;
        square_range(
            [self.levels[0].cols, self.levels[0].rows],
            [id.col as usize * span, id.row as usize * span],
            span,
        )
    }
}

/// The patches of a square `span` patches a side from patch `first`
/// (column, row), cut by the far sides of a grid of `size` (columns, rows):
/// its columns and rows, end exclusive. A node's, a merged node's and a
/// planned block's patches.
pub fn square_range(size: [usize; 2], first: [usize; 2], span: usize) -> ([usize; 2], [usize; 2]) {
    let [c0, r0] = first;
    (
        [c0, (c0 + span).min(size[0])],
        [r0, (r0 + span).min(size[1])],
    )
}

/// The indices of the patches of columns `c0..c1` and rows `r0..r1` of a
/// grid `cols` patches wide, one range a row, rows in order: a rectangle
/// of a row-major per-patch array, filled or listed row by row.
pub fn rect_rows(
    cols: usize,
    ([c0, c1], [r0, r1]): ([usize; 2], [usize; 2]),
) -> impl Iterator<Item = std::ops::Range<usize>> {
    (r0..r1).map(move |r| r * cols + c0..r * cols + c1)
}

/// The smallest rectangle of patches (columns, rows, end exclusive)
/// holding every one of `rects`; None for none.
pub fn rect_bounds(
    rects: impl IntoIterator<Item = ([usize; 2], [usize; 2])>,
) -> Option<([usize; 2], [usize; 2])> {
    rects
        .into_iter()
        .reduce(|([a0, a1], [b0, b1]), ([c0, c1], [d0, d1])| {
            ([a0.min(c0), a1.max(c1)], [b0.min(d0), b1.max(d1)])
        })
}

/// A node's footprint in local x and z: (lower-left, upper-right) corners,
/// from its first and last patches' corners.
pub fn node_footprint(
    terrain: &Terrain,
    cols: [usize; 2],
    rows: [usize; 2],
) -> ([f32; 2], [f32; 2]) {
    let first = terrain.patch_corners(PatchId {
        row: rows[0],
        col: cols[0],
    });
    let last = terrain.patch_corners(PatchId {
        row: rows[1] - 1,
        col: cols[1] - 1,
    });
    // Upper-left has the smallest x and largest z, lower-right the reverse.
    ([first[0].x, last[3].z], [last[3].x, first[0].z])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square cut by the grid's far sides, and its rows as ranges of a
    /// row-major array: every patch of the rectangle once, in index
    /// order, and none outside it.
    #[test]
    fn a_cut_square_lists_its_patches_row_by_row() {
        let rect = square_range([5, 4], [3, 2], 4);
        assert_eq!(rect, ([3, 5], [2, 4]));
        let rows: Vec<_> = rect_rows(5, rect).collect();
        assert_eq!(rows, vec![13..15, 18..20]);
        let listed: Vec<usize> = rect_rows(5, rect).flatten().collect();
        let expected: Vec<usize> = (0..20)
            .filter(|p| (3..5).contains(&(p % 5)) && (2..4).contains(&(p / 5)))
            .collect();
        assert_eq!(listed, expected);
        assert_eq!(rect_rows(5, ([2, 2], [0, 4])).flatten().count(), 0);
    }
}
