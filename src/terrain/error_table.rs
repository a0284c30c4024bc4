//! Per-patch geometric error of each power-of-two tessellation level.
//!
//! At level L a patch is cut into L x L equal quads (the evaluation shader's
//! bilinear interpolation of the patch corners) whose vertices take the
//! surface height at their position (`Heightmap::interpolate`, what the
//! displacement in the evaluation shader samples). Between vertices the
//! surface is taken as the bilinear interpolation of the four vertex heights:
//! how the tessellator splits each quad into triangles is up to the driver,
//! and bilinear is the symmetric choice between its two diagonals.
//!
//! The error of a level is the largest vertical distance, over every sample
//! the patch covers, between the sample's height and that surface: the
//! height of the seed article's "max-error vertex".
//!
//! A coarser level can measure less than a finer one on some data (a sample
//! may happen to sit near a coarse interpolation and away from a finer one),
//! which would make an error-bounded choice pick the coarse level over a
//! finer one it rejected. The stored value of each level is therefore the
//! largest raw error of that level and every finer one: the table is
//! non-increasing as the level rises, and bounds the error of every level at
//! or above it.
//!
//! Sample and vertex positions are rational (`k * cells / L`), so cell indices
//! and fractions come from exact integer arithmetic.

use rayon::prelude::*;

use super::grid::{PatchGrid, SampleRect};
use super::heightmap::Heightmap;

/// The tessellation levels the table covers: 1, 2, 4, ..., 64.
pub const ERROR_LEVELS: [u32; 7] = [1, 2, 4, 8, 16, 32, 64];

/// Errors of every patch at every level, flat: patch `p`, level index `k`
/// (level `ERROR_LEVELS[k]`) is `errors[p * 7 + k]`. Patches are row-major,
/// as in the patch grid.
#[derive(Clone, Debug, PartialEq)]
pub struct ErrorTable {
    errors: Vec<f32>,
}

impl ErrorTable {
    pub const LEVELS: usize = ERROR_LEVELS.len();

    pub fn compute(heightmap: &Heightmap, grid: &PatchGrid) -> ErrorTable {
        let mut errors = vec![0.0f32; grid.patch_count() * Self::LEVELS];
        errors
            .par_chunks_mut(Self::LEVELS)
            .enumerate()
            .for_each(|(p, out)| {
                let rect = grid.sample_rect(grid.patch_id(p));
                let mut finer_max = 0.0f64;
                for (k, &level) in ERROR_LEVELS.iter().enumerate().rev() {
                    let raw = level_error(heightmap, rect, level as usize);
                    finer_max = finer_max.max(raw);
                    out[k] = finer_max as f32;
                }
            });
        ErrorTable { errors }
    }

    /// The flat table, ready for upload.
    pub fn as_slice(&self) -> &[f32] {
        &self.errors
    }

    /// Error of `patch` at level index `k` (level `ERROR_LEVELS[k]`).
    pub fn error(&self, patch: usize, k: usize) -> f32 {
        self.errors[patch * Self::LEVELS + k]
    }

    /// All levels of one patch, coarsest first.
    pub fn patch(&self, patch: usize) -> &[f32] {
        &self.errors[patch * Self::LEVELS..(patch + 1) * Self::LEVELS]
    }
}

/// Splits `k * cells / level` into its integer part and numerator over
/// `level`.
#[inline]
fn split(k: usize, cells: usize, level: usize) -> (usize, usize) {
    let n = k * cells;
    (n / level, n % level)
}

/// Largest |sample - level surface| over the samples of one patch.
fn level_error(map: &Heightmap, rect: SampleRect, level: usize) -> f64 {
    let (nx, nz) = (rect.cells_x(), rect.cells_z());
    if level % nx == 0 && level % nz == 0 {
        // Every sample is a vertex of this level, whose height is the sample.
        return 0.0;
    }
    // Vertex heights of the level, (level + 1)^2, row-major.
    let stride = level + 1;
    let mut vertices = Vec::with_capacity(stride * stride);
    for i in 0..=level {
        let (ri, rn) = split(i, nz, level);
        for j in 0..=level {
            let (ci, cn) = split(j, nx, level);
            let col = (rect.col0 + ci) as f64 + cn as f64 / level as f64;
            let row = (rect.row0 + ri) as f64 + rn as f64 / level as f64;
            vertices.push(map.interpolate(col, row));
        }
    }
    let mut worst = 0.0f64;
    for r in 0..=nz {
        // Sample row r sits at vertex row r * level / nz.
        let (vi, vn) = split(r, level, nz);
        let (vi, fv) = if vi == level {
            (level - 1, 1.0)
        } else {
            (vi, vn as f64 / nz as f64)
        };
        let row = map.row(rect.row0 + r);
        let top = &vertices[vi * stride..(vi + 1) * stride];
        let bottom = &vertices[(vi + 1) * stride..(vi + 2) * stride];
        for c in 0..=nx {
            let (vj, un) = split(c, level, nx);
            let (vj, fu) = if vj == level {
                (level - 1, 1.0)
            } else {
                (vj, un as f64 / nx as f64)
            };
            let t = top[vj] + fu * (top[vj + 1] - top[vj]);
            let b = bottom[vj] + fu * (bottom[vj + 1] - bottom[vj]);
            let surface = t + fv * (b - t);
            worst = worst.max((f64::from(row[rect.col0 + c]) - surface).abs());
        }
    }
    worst
}
