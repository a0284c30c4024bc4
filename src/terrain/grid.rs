//! The patch grid: quad patches of `cells_per_patch` cells that together
//! cover every cell of the heightmap exactly once.
//!
//! **Remainders.** When `cols - 1` is not a multiple of the patch size N,
//! there are `ceil((cols - 1) / N)` patch columns; all but the last cover N
//! cells and the last covers the remaining `(cols - 1) mod N` cells, so its
//! control points sit on the last sample column rather than past it. Rows
//! work the same way. Patch boundaries therefore always fall on samples:
//! sample column `min(j * N, cols - 1)` for boundary j. A 403x344 map with
//! N = 32 has 13 patch columns (12 of 32 cells, one of 18) and 11 patch rows
//! (10 of 32 cells, one of 23).

use rayon::prelude::*;

use super::error::TerrainError;
use super::heightmap::{min_max_of, Heightmap};
use super::placement::Placement;

/// A patch's place in the grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PatchId {
    pub row: usize,
    pub col: usize,
}

/// The samples a patch covers, borders included: rows `row0..=row1`,
/// columns `col0..=col1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SampleRect {
    pub row0: usize,
    pub row1: usize,
    pub col0: usize,
    pub col1: usize,
}

impl SampleRect {
    /// Cells across (columns).
    pub fn cells_x(&self) -> usize {
        self.col1 - self.col0
    }

    /// Cells down (rows).
    pub fn cells_z(&self) -> usize {
        self.row1 - self.row0
    }
}

/// Largest cells per patch: one patch at the maximum tessellation factor
/// (64) then still has a vertex at every sample.
pub const MAX_CELLS_PER_PATCH: u32 = 64;

/// Cells per patch must be a power of two in 2..=64.
pub fn validate_cells_per_patch(n: u32) -> Result<(), TerrainError> {
    if n.is_power_of_two() && (2..=MAX_CELLS_PER_PATCH).contains(&n) {
        Ok(())
    } else {
        Err(TerrainError::CellsPerPatch(n))
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PatchGrid {
    sample_rows: usize,
    sample_cols: usize,
    cells_per_patch: usize,
    patch_rows: usize,
    patch_cols: usize,
}

impl PatchGrid {
    /// The grid of a `cols` x `rows` terrain (at least 2x2) in patches of
    /// `cells_per_patch` cells, whether or not its heights are in memory.
    pub fn for_size(cols: usize, rows: usize, cells_per_patch: u32) -> Self {
        let n = cells_per_patch as usize;
        PatchGrid {
            sample_rows: rows,
            sample_cols: cols,
            cells_per_patch: n,
            patch_rows: (rows - 1).div_ceil(n),
            patch_cols: (cols - 1).div_ceil(n),
        }
    }

    pub fn patch_rows(&self) -> usize {
        self.patch_rows
    }

    pub fn patch_cols(&self) -> usize {
        self.patch_cols
    }

    pub fn patch_count(&self) -> usize {
        self.patch_rows * self.patch_cols
    }

    pub fn cells_per_patch(&self) -> usize {
        self.cells_per_patch
    }

    /// Control points per row: one per patch column boundary.
    pub fn control_cols(&self) -> usize {
        self.patch_cols + 1
    }

    /// Control points per column: one per patch row boundary.
    pub fn control_rows(&self) -> usize {
        self.patch_rows + 1
    }

    pub fn control_point_count(&self) -> usize {
        self.control_rows() * self.control_cols()
    }

    /// Index of a patch in row-major order; the Y bounds and error table use
    /// the same order.
    pub fn patch_index(&self, id: PatchId) -> usize {
        id.row * self.patch_cols + id.col
    }

    pub fn patch_id(&self, index: usize) -> PatchId {
        PatchId {
            row: index / self.patch_cols,
            col: index % self.patch_cols,
        }
    }

    /// The patches beside patch `index` (row-major), as indices: left, top,
    /// right and bottom, in the order of the geomip side bits; None past
    /// the grid's edge.
    pub fn neighbours(&self, index: usize) -> [Option<usize>; 4] {
        self.neighbours_of(self.patch_id(index))
            .map(|q| q.map(|q| self.patch_index(q)))
    }

    /// `neighbours` of a patch known by its place, found without dividing
    /// by the grid's width: for walks that visit many patches a frame.
    pub fn neighbours_of(&self, id: PatchId) -> [Option<PatchId>; 4] {
        let PatchId { row, col } = id;
        [
            (col > 0).then(|| PatchId { row, col: col - 1 }),
            (row > 0).then(|| PatchId { row: row - 1, col }),
            (col + 1 < self.patch_cols).then(|| PatchId { row, col: col + 1 }),
            (row + 1 < self.patch_rows).then(|| PatchId { row: row + 1, col }),
        ]
    }

    /// Sample column of patch column boundary `j` (0..=patch_cols).
    pub fn boundary_col(&self, j: usize) -> usize {
        (j * self.cells_per_patch).min(self.sample_cols - 1)
    }

    /// Sample row of patch row boundary `i` (0..=patch_rows).
    pub fn boundary_row(&self, i: usize) -> usize {
        (i * self.cells_per_patch).min(self.sample_rows - 1)
    }

    pub fn sample_rect(&self, id: PatchId) -> SampleRect {
        SampleRect {
            row0: self.boundary_row(id.row),
            row1: self.boundary_row(id.row + 1),
            col0: self.boundary_col(id.col),
            col1: self.boundary_col(id.col + 1),
        }
    }

    /// The patch that owns cell (row, col), the cell whose upper-left sample
    /// is (row, col).
    pub fn patch_of_cell(&self, row: usize, col: usize) -> PatchId {
        PatchId {
            row: row / self.cells_per_patch,
            col: col / self.cells_per_patch,
        }
    }

    /// The patch owning the cell under continuous sample coordinates
    /// (`col`, `row`), clamped to the grid: the patch a pixel whose
    /// surface point lies there is counted for. Mirror: `patch_of_grid`
    /// in glsl/terrain_common.glsl.
    pub fn patch_at(&self, col: f64, row: f64) -> PatchId {
        let c = (col.floor().max(0.0) as usize).min(self.sample_cols - 2);
        let r = (row.floor().max(0.0) as usize).min(self.sample_rows - 2);
        self.patch_of_cell(r, c)
    }

    /// Control point index of boundary (i, j).
    pub fn control_index(&self, i: usize, j: usize) -> usize {
        i * self.control_cols() + j
    }

    /// Four indices per patch, in the order upper-left, upper-right,
    /// lower-left, lower-right, patches row-major.
    pub fn indices(&self) -> Vec<u32> {
        let mut indices = Vec::with_capacity(self.patch_count() * 4);
        for i in 0..self.patch_rows {
            for j in 0..self.patch_cols {
                for (di, dj) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                    let index = self.control_index(i + di, j + dj);
                    indices.push(u32::try_from(index).expect("control point index fits u32"));
                }
            }
        }
        indices
    }
}

/// Min and max height over every sample each patch covers (borders
/// included), widened by `margin` on both sides; `[min, max]` per patch in
/// row-major patch order.
///
/// The heightmap is read in row order, one band of patch rows per task, so
/// memory streams instead of striding patch by patch.
pub fn patch_y_bounds(heightmap: &Heightmap, grid: &PatchGrid, margin: f32) -> Vec<[f32; 2]> {
    let cols = grid.patch_cols();
    let mut bounds = vec![[f32::INFINITY, f32::NEG_INFINITY]; grid.patch_count()];
    bounds
        .par_chunks_mut(cols)
        .enumerate()
        .for_each(|(patch_row, band)| {
            let rect_rows = grid.sample_rect(PatchId {
                row: patch_row,
                col: 0,
            });
            for r in rect_rows.row0..=rect_rows.row1 {
                let row = heightmap.row(r);
                for (j, b) in band.iter_mut().enumerate() {
                    let (c0, c1) = (grid.boundary_col(j), grid.boundary_col(j + 1));
                    let (lo, hi) = min_max_of(&row[c0..=c1]);
                    b[0] = b[0].min(lo);
                    b[1] = b[1].max(hi);
                }
            }
        });
    for b in &mut bounds {
        b[0] -= margin;
        b[1] += margin;
    }
    bounds
}

/// Control points `(x, z, minY, maxY)` in local coordinates. A patch's Y
/// bounds sit in its upper-left control point; points that are no patch's
/// upper-left corner (the last row and column) carry zero bounds.
pub fn control_points(
    placement: &Placement,
    grid: &PatchGrid,
    y_bounds: &[[f32; 2]],
) -> Vec<[f32; 4]> {
    let mut points = Vec::with_capacity(grid.control_point_count());
    for i in 0..grid.control_rows() {
        let z = placement.local_z(grid.boundary_row(i)) as f32;
        for j in 0..grid.control_cols() {
            let x = placement.local_x(grid.boundary_col(j)) as f32;
            let [min_y, max_y] = if i < grid.patch_rows() && j < grid.patch_cols() {
                y_bounds[grid.patch_index(PatchId { row: i, col: j })]
            } else {
                [0.0, 0.0]
            };
            points.push([x, z, min_y, max_y]);
        }
    }
    points
}

/// The height under each control point (row-major, as `control_points`),
/// from `sample(row, col)`.
pub fn control_heights<E>(
    grid: &PatchGrid,
    mut sample: impl FnMut(usize, usize) -> Result<f32, E>,
) -> Result<Vec<f32>, E> {
    let mut heights = Vec::with_capacity(grid.control_point_count());
    for i in 0..grid.control_rows() {
        for j in 0..grid.control_cols() {
            heights.push(sample(grid.boundary_row(i), grid.boundary_col(j))?);
        }
    }
    Ok(heights)
}
