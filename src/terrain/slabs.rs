//! Each patch's ground in `SLAB_SIDE` x `SLAB_SIDE` equal parts of its
//! cells: each part's footprint, and the lowest, highest and mean height
//! of its samples. Computed once per terrain whose heights are held
//! whole, beside its view model (`Terrain::sight_table`).
//!
//! The error LOD's horizon (`lod::horizon`) takes a box of ground as
//! solid up to its mean height. A patch large on screen is much wider
//! than the ridges in it: its mean lies below its ridges and above its
//! valleys, and one slab at that height hides neither what a ridge in it
//! hides nor lets through what its valleys do. Its parts, each solid up
//! to its own mean, follow the ground more closely (notes section 61).

use glam::Vec3;
use rayon::prelude::*;

use super::grid::PatchGrid;
use super::heightmap::Heightmap;
use super::placement::Placement;

/// Parts a side of each patch.
pub const SLAB_SIDE: usize = 4;
/// Parts of each patch.
pub const SLABS_PER_PATCH: usize = SLAB_SIDE * SLAB_SIDE;

/// One part of a patch: its box in local coordinates (footprint, lowest
/// and highest sample) and its samples' mean height.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slab {
    pub min: Vec3,
    pub max: Vec3,
    pub mean: f32,
}

/// Every patch's parts, `SLABS_PER_PATCH` a patch in patch order, each
/// patch's row-major from its first row and column of samples.
#[derive(Clone, Debug, PartialEq)]
pub struct PatchSlabs {
    slabs: Vec<Slab>,
}

impl PatchSlabs {
    /// The parts of every patch of `grid` over `map`, placed by
    /// `placement`. A part's samples run from its first row and column to
    /// its last, both included, so neighbouring parts share the samples
    /// between them; on a patch with fewer cells a side than
    /// `SLAB_SIDE`, some parts are a line of samples wide.
    pub fn compute(map: &Heightmap, grid: &PatchGrid, placement: &Placement) -> Self {
        let slabs = (0..grid.patch_count())
            .into_par_iter()
            .flat_map_iter(|p| {
                let rect = grid.sample_rect(grid.patch_id(p));
                let (nx, nz) = (rect.cells_x(), rect.cells_z());
                (0..SLABS_PER_PATCH).map(move |s| {
                    let (i, j) = (s / SLAB_SIDE, s % SLAB_SIDE);
                    let rows = [
                        rect.row0 + i * nz / SLAB_SIDE,
                        rect.row0 + (i + 1) * nz / SLAB_SIDE,
                    ];
                    let cols = [
                        rect.col0 + j * nx / SLAB_SIDE,
                        rect.col0 + (j + 1) * nx / SLAB_SIDE,
                    ];
                    let (mut lowest, mut highest, mut sum) =
                        (f32::INFINITY, f32::NEG_INFINITY, 0.0f64);
                    for r in rows[0]..=rows[1] {
                        for &h in &map.row(r)[cols[0]..=cols[1]] {
                            lowest = lowest.min(h);
                            highest = highest.max(h);
                            sum += f64::from(h);
                        }
                    }
                    let count = (rows[1] - rows[0] + 1) * (cols[1] - cols[0] + 1);
                    let x = cols.map(|c| placement.local_x(c) as f32);
                    let z = rows.map(|r| placement.local_z(r) as f32);
                    Slab {
                        min: Vec3::new(x[0].min(x[1]), lowest, z[0].min(z[1])),
                        max: Vec3::new(x[0].max(x[1]), highest, z[0].max(z[1])),
                        mean: (sum / count as f64) as f32,
                    }
                })
            })
            .collect();
        PatchSlabs { slabs }
    }

    /// Patch `p`'s parts (its index in the grid).
    pub fn of(&self, p: usize) -> &[Slab] {
        &self.slabs[p * SLABS_PER_PATCH..][..SLABS_PER_PATCH]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;

    /// Parts tile the patch, each with its own samples' lowest, highest
    /// and mean height, in local coordinates.
    #[test]
    fn parts_hold_their_own_samples() {
        // 9 x 9 samples, 2 m apart: one 8-cell patch; height 10 * row +
        // column.
        let map = Heightmap::from_fn(9, 9, |r, c| (10 * r + c) as f32).unwrap();
        let placement = Placement::new(9, 9, DVec2::new(2.0, 2.0), DVec2::ZERO).unwrap();
        let grid = PatchGrid::for_size(9, 9, 8);
        let slabs = PatchSlabs::compute(&map, &grid, &placement);
        let parts = slabs.of(0);
        assert_eq!(parts.len(), SLABS_PER_PATCH);
        // Part (1, 2): rows 2 to 4, columns 4 to 6.
        let part = parts[SLAB_SIDE + 2];
        assert_eq!(part.min.y, 24.0);
        assert_eq!(part.max.y, 46.0);
        assert_eq!(part.mean, 35.0);
        let (x0, x1) = (placement.local_x(4) as f32, placement.local_x(6) as f32);
        let (z0, z1) = (placement.local_z(2) as f32, placement.local_z(4) as f32);
        assert_eq!([part.min.x, part.max.x], [x0.min(x1), x0.max(x1)]);
        assert_eq!([part.min.z, part.max.z], [z0.min(z1), z0.max(z1)]);
        assert_eq!(part.max.x - part.min.x, 4.0);
        // Together they cover the patch's footprint and heights.
        let lo = parts.iter().fold(Vec3::INFINITY, |a, s| a.min(s.min));
        let hi = parts.iter().fold(Vec3::NEG_INFINITY, |a, s| a.max(s.max));
        assert_eq!(hi - lo, Vec3::new(16.0, 88.0, 16.0));
    }
}
