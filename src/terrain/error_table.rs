//! Per-patch geometric error of each power-of-two tessellation level.
//!
//! At level L a patch is cut into L x L equal quads (the evaluation shader's
//! bilinear interpolation of the patch corners) whose vertices take the
//! surface height at their position (`Heightmap::interpolate`, what the
//! displacement in the evaluation shader samples). How the tessellator
//! splits each quad into two triangles is up to the driver, so the error
//! must hold for either diagonal.
//!
//! Only levels below the patch's cell count (its smaller side) are ever
//! tessellated: a patch that needs more is drawn with the reference's own
//! triangles, exactly, so those levels have error 0 here. Below it:
//!
//! - **Exact**, where the level's quads are square runs of whole cells (the
//!   patch's sides are multiples of L and equal, as on every patch but the
//!   remainders at the far edges). Each quad's vertices are samples, and
//!   both of its triangulations are planar pieces whose difference from the
//!   reference (the heightmap split as `height_at` splits it) is piecewise
//!   linear. Its extremes lie where the two meshes' edges cross: at the
//!   samples, and for the diagonal that runs against the reference's, at
//!   the centres of the cells it crosses. The error is the larger of the
//!   two diagonals' largest differences there.
//! - **A bound** elsewhere (remainder patches whose vertices fall between
//!   samples): either split differs from the bilinear interpolation of the
//!   quad's four vertex heights by at most a quarter of the quad's twist
//!   |v00 + v11 - v01 - v10|, so the level's error is at most the largest
//!   |surface(p) - bilinear(p)| + |twist of p's quad| / 4 over every sample,
//!   cell centre and quad centre p. That is the seed article's "max-error
//!   vertex" height, made to hold whatever the triangulation.
//!
//! `ErrorTable::compute_pair` also gives the geomip path's table: geomip
//! draws every quad split like the reference, so its exact error is the
//! first diagonal's alone, and its level 0 is the reference itself.
//!
//! A coarser level can measure less than a finer one on some data (a sample
//! may happen to sit near a coarse interpolation and away from a finer one),
//! which would make an error-bounded choice pick the coarse level over a
//! finer one it rejected. The stored value of each level is therefore the
//! largest raw error of that level and every finer one that is still
//! tessellated: the table is non-increasing as the level rises.
//!
//! Vertex positions are rational (`k * cells / L`), so their cell indices
//! and fractions come from exact integer arithmetic.

use rayon::prelude::*;

use super::grid::{PatchGrid, SampleRect};
use super::heightmap::Heightmap;

use crate::shader_constants::{ERROR_LEVEL_COUNT, MAX_TESS_FACTOR};

/// Levels per patch in the table; GLSL reads the same count
/// (`ERROR_LEVEL_COUNT`, shared through shader_constants).
pub const LEVEL_COUNT: usize = ERROR_LEVEL_COUNT as usize;

/// The tessellation levels the table covers: 1, 2, 4, ..., 64.
pub const ERROR_LEVELS: [u32; LEVEL_COUNT] = {
    let mut levels = [0u32; LEVEL_COUNT];
    let mut k = 0;
    while k < LEVEL_COUNT {
        levels[k] = 1 << k;
        k += 1;
    }
    levels
};
// The last level is the largest factor a control shader may output.
const _: () = assert!(ERROR_LEVELS[LEVEL_COUNT - 1] as f32 == MAX_TESS_FACTOR);

/// One patch's errors, one per level.
pub type PatchErrors = [f32; LEVEL_COUNT];

/// Errors of every patch at every level, flat: patch `p`, level index `k`
/// (level `ERROR_LEVELS[k]`) is `errors[p * LEVEL_COUNT + k]`. Patches are row-major,
/// as in the patch grid.
#[derive(Clone, Debug, PartialEq)]
pub struct ErrorTable {
    errors: Vec<f32>,
}

impl ErrorTable {
    pub const LEVELS: usize = LEVEL_COUNT;

    /// The tess path's table: either diagonal.
    pub fn compute(heightmap: &Heightmap, grid: &PatchGrid) -> ErrorTable {
        Self::compute_pair(heightmap, grid).0
    }

    /// The tess path's table (either diagonal) and the geomip path's (the
    /// reference's diagonal), in one pass over the samples.
    pub fn compute_pair(heightmap: &Heightmap, grid: &PatchGrid) -> (ErrorTable, ErrorTable) {
        let n = grid.patch_count() * Self::LEVELS;
        let (mut tess, mut geomip) = (vec![0.0f32; n], vec![0.0f32; n]);
        tess.par_chunks_mut(Self::LEVELS)
            .zip(geomip.par_chunks_mut(Self::LEVELS))
            .enumerate()
            .for_each(|(p, (tess, geomip))| {
                let rect = grid.sample_rect(grid.patch_id(p));
                let side = rect.cells_x().min(rect.cells_z());
                let (mut tess_max, mut geomip_max) = (0.0f64, 0.0f64);
                for (k, &level) in ERROR_LEVELS.iter().enumerate().rev() {
                    let level = level as usize;
                    if level >= side {
                        // Drawn with the reference's own triangles.
                        continue;
                    }
                    let (either, reference) = match exact_level_error(heightmap, rect, level) {
                        Some(errors) => errors,
                        None => {
                            let bound = bound_level_error(heightmap, rect, level);
                            (bound, bound)
                        }
                    };
                    tess_max = tess_max.max(either);
                    geomip_max = geomip_max.max(reference);
                    tess[k] = tess_max as f32;
                    geomip[k] = geomip_max as f32;
                }
            });
        (ErrorTable { errors: tess }, ErrorTable { errors: geomip })
    }

    /// A table from its flat errors (`as_slice`'s layout), as a tiled
    /// terrain stores it; None unless every error is finite and not
    /// negative and the levels fill whole patches.
    pub fn from_flat(errors: Vec<f32>) -> Option<ErrorTable> {
        (errors.len() % Self::LEVELS == 0 && errors.iter().all(|e| e.is_finite() && *e >= 0.0))
            .then_some(ErrorTable { errors })
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

/// The height at (u, v) in a quad [A upper-left, B upper-right, C
/// lower-left, D lower-right] split along B-C, the reference's diagonal:
/// on ABC where `upper` (u + v <= 1), else on DCB. The caller decides the
/// side, exactly where it can.
#[inline]
pub(crate) fn split_bc([a, b, c, d]: [f64; 4], u: f64, v: f64, upper: bool) -> f64 {
    if upper {
        a + u * (b - a) + v * (c - a)
    } else {
        d + (1.0 - u) * (c - d) + (1.0 - v) * (b - d)
    }
}

/// The same quad split along A-D: on ABD where `right` (u >= v), else on
/// ACD.
#[inline]
pub(crate) fn split_ad([a, b, c, d]: [f64; 4], u: f64, v: f64, right: bool) -> f64 {
    if right {
        a + u * (b - a) + v * (d - b)
    } else {
        a + v * (c - a) + u * (d - c)
    }
}

/// The heights of a quad's two triangulations at its lattice point (row
/// `i`, column `j`) of `s` a side (`split_bc`, `split_ad`), the sides
/// decided in whole numbers.
#[inline]
fn quad_splits(corners: [f64; 4], (i, j): (usize, usize), s: usize) -> (f64, f64) {
    let inv = 1.0 / s as f64;
    let (u, v) = (j as f64 * inv, i as f64 * inv);
    (
        split_bc(corners, u, v, i + j <= s),
        split_ad(corners, u, v, j >= i),
    )
}

/// Exact errors of one level over one patch whose quads are square runs of
/// whole cells: (either diagonal, the reference's diagonal); None where the
/// quads are not (see the module documentation).
fn exact_level_error(map: &Heightmap, rect: SampleRect, level: usize) -> Option<(f64, f64)> {
    let (nx, nz) = (rect.cells_x(), rect.cells_z());
    if nx != nz || nx % level != 0 {
        return None;
    }
    let s = nx / level;
    let h = |r: usize, c: usize| f64::from(map.get(rect.row0 + r, rect.col0 + c));
    let (mut either, mut reference) = (0.0f64, 0.0f64);
    for qi in 0..level {
        for qj in 0..level {
            let (r0, c0) = (qi * s, qj * s);
            // A upper-left, B upper-right, C lower-left, D lower-right.
            let (a, b) = (h(r0, c0), h(r0, c0 + s));
            let (c, d) = (h(r0 + s, c0), h(r0 + s, c0 + s));
            let inv = 1.0 / s as f64;
            let (mut along, mut against) = (0.0f64, 0.0f64);
            for i in 0..=s {
                for j in 0..=s {
                    let here = h(r0 + i, c0 + j);
                    let (bc, ad) = quad_splits([a, b, c, d], (i, j), s);
                    along = along.max((here - bc).abs());
                    against = against.max((here - ad).abs());
                }
            }
            // A-D crosses each cell on its way through the centre, where
            // the reference's diagonal of that cell meets it.
            for t in 0..s {
                let centre = 0.5 * (h(r0 + t, c0 + t + 1) + h(r0 + t + 1, c0 + t));
                let w = (t as f64 + 0.5) * inv;
                against = against.max((centre - (a + w * (d - a))).abs());
            }
            either = either.max(along.max(against));
            reference = reference.max(along);
        }
    }
    Some((either, reference))
}

/// Error bound of one level over one patch: the largest, over the
/// evaluation points, of |surface - bilinear| + |twist| / 4 (see the module
/// documentation).
fn bound_level_error(map: &Heightmap, rect: SampleRect, level: usize) -> f64 {
    let (nx, nz) = (rect.cells_x(), rect.cells_z());
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
    let (l, fx, fz) = (level as f64, nx as f64, nz as f64);
    // Quad index and fraction of a patch-relative coordinate along an axis
    // of `cells` cells.
    let locate = |x: f64, cells: f64| {
        let u = x * l / cells;
        let k = (u as usize).min(level - 1);
        (k, u - k as f64)
    };
    // The bound at a point in quad (i, j) at fractions (fu, fv), whose
    // surface height is `surface`.
    let bound = |(i, fv): (usize, f64), (j, fu): (usize, f64), surface: f64| {
        let v00 = vertices[i * stride + j];
        let v01 = vertices[i * stride + j + 1];
        let v10 = vertices[(i + 1) * stride + j];
        let v11 = vertices[(i + 1) * stride + j + 1];
        let top = v00 + fu * (v01 - v00);
        let bottom = v10 + fu * (v11 - v10);
        let bilinear = top + fv * (bottom - top);
        (surface - bilinear).abs() + 0.25 * (v00 + v11 - v01 - v10).abs()
    };
    let sample_cols: Vec<_> = (0..=nx).map(|c| locate(c as f64, fx)).collect();
    let centre_cols: Vec<_> = (0..nx).map(|c| locate(c as f64 + 0.5, fx)).collect();
    let mut worst = 0.0f64;
    for r in 0..=nz {
        let at = locate(r as f64, fz);
        let row = &map.row(rect.row0 + r)[rect.col0..=rect.col1];
        for (&h, &col) in row.iter().zip(&sample_cols) {
            worst = worst.max(bound(at, col, f64::from(h)));
        }
    }
    for r in 0..nz {
        let at = locate(r as f64 + 0.5, fz);
        let top = &map.row(rect.row0 + r)[rect.col0..=rect.col1];
        let below = &map.row(rect.row0 + r + 1)[rect.col0..=rect.col1];
        for (c, &col) in centre_cols.iter().enumerate() {
            // A cell's centre lies on its split from upper-right to
            // lower-left (`Heightmap::interpolate`).
            let surface = 0.5 * (f64::from(top[c + 1]) + f64::from(below[c]));
            worst = worst.max(bound(at, col, surface));
        }
    }
    for i in 0..level {
        for j in 0..level {
            let (col, row) = ((j as f64 + 0.5) * fx / l, (i as f64 + 0.5) * fz / l);
            let surface = map.interpolate(rect.col0 as f64 + col, rect.row0 as f64 + row);
            worst = worst.max(bound(locate(row, fz), locate(col, fx), surface));
        }
    }
    worst
}
