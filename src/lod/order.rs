//! Front-to-back draw order.
//!
//! An eye above a heightfield sees a point only past the ground between
//! them in plan, and that ground is nearer the eye in plan. Drawn nearest
//! first, the nearer ground's depth is in place before what it hides
//! arrives, so a device that tests depth before shading drops the hidden
//! fragments unshaded. Patches are ordered by the plan distance from the
//! eye to their nearest point. A run of consecutive patches is one draw in
//! index order, which left of the eye comes towards it; so a row's runs are
//! split at the eye's column and kept to [`MAX_RUN`] patches, and a run is
//! placed by its nearest patch.

use glam::{DVec2, Vec3};

use crate::terrain::grid::PatchGrid;
use crate::terrain::info::TerrainInfo;

/// Longest run of consecutive patches drawn together.
pub const MAX_RUN: u32 = 8;

/// The eye's place over a patch grid, for ordering its patches.
#[derive(Clone, Copy, Debug)]
pub struct DrawOrder {
    grid: PatchGrid,
    /// The eye in sample coordinates (column, row).
    eye: DVec2,
    /// World distance between samples along x and z.
    spacing: DVec2,
}

impl DrawOrder {
    /// The order of `grid`'s patches seen from `eye_local` (relative to
    /// the terrain's centre).
    pub fn new(info: &TerrainInfo, grid: &PatchGrid, eye_local: Vec3) -> Self {
        let origin = info.origin();
        DrawOrder {
            grid: *grid,
            eye: info.world_to_grid(
                origin.x + f64::from(eye_local.x),
                origin.y + f64::from(eye_local.z),
            ),
            spacing: info.spacing(),
        }
    }

    /// The grid ordered.
    pub fn grid(&self) -> &PatchGrid {
        &self.grid
    }

    /// Sort key of patch `index` (row-major): its nearest point's plan
    /// distance from the eye, as bits that order like the distance.
    pub fn key(&self, index: u32) -> u32 {
        let rect = self.grid.sample_rect(self.grid.patch_id(index as usize));
        let outside = |e: f64, lo: usize, hi: usize| (lo as f64 - e).max(e - hi as f64).max(0.0);
        let d = DVec2::new(
            outside(self.eye.x, rect.col0, rect.col1) * self.spacing.x,
            outside(self.eye.y, rect.row0, rect.row1) * self.spacing.y,
        );
        // Non-negative floats order as their bits do.
        (d.length() as f32).to_bits()
    }

    /// `patches` (row-major indices, increasing) as runs of consecutive
    /// patches (first, count), nearest run first: each row's runs split at
    /// the eye's column and into runs of at most `MAX_RUN`, ordered by
    /// their nearest patch, ties in index order.
    pub fn runs(&self, patches: impl IntoIterator<Item = u32>) -> Vec<(u32, u32)> {
        let cols = self.grid.patch_cols() as u32;
        // The patch column the eye is over (outside the grid: its nearest).
        let eye_col = (self.eye.x / self.grid.cells_per_patch() as f64)
            .floor()
            .clamp(0.0, f64::from(cols - 1)) as u32;
        let mut runs: Vec<(u32, u32)> = Vec::new();
        for p in patches {
            let joins = runs.last().is_some_and(|&(first, n)| {
                first + n == p && p % cols != 0 && n < MAX_RUN && p % cols != eye_col
            });
            match joins {
                true => runs.last_mut().expect("joins a run").1 += 1,
                false => runs.push((p, 1)),
            }
        }
        let mut keyed: Vec<(u32, (u32, u32))> = runs
            .into_iter()
            .map(|(first, n)| (self.key(first).min(self.key(first + n - 1)), (first, n)))
            .collect();
        keyed.sort_unstable();
        keyed.into_iter().map(|(_, run)| run).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::heightmap::Heightmap;

    /// A 33x33-sample map of 1 m cells and 4-cell patches (8x8 patches),
    /// centred on the origin.
    fn order(eye: Vec3) -> DrawOrder {
        let heightmap = Heightmap::from_heights(33, 33, vec![0.0; 33 * 33]).expect("valid");
        let info = TerrainInfo::new(heightmap, DVec2::ONE, 4, DVec2::ZERO).expect("valid");
        DrawOrder::new(&info, &info.patch_grid(), eye)
    }

    #[test]
    fn runs_cover_every_patch_once_nearest_first() {
        // The eye over patch (row 2, col 5): 16 m right and 16 m up of
        // the centre is sample (32, 0); this is sample (22, 10).
        let order = order(Vec3::new(6.0, 50.0, 6.0));
        let all: Vec<u32> = (0..64).filter(|p| p % 3 != 1).collect();
        let runs = order.runs(all.iter().copied());
        let mut covered: Vec<u32> = runs.iter().flat_map(|&(f, n)| f..f + n).collect();
        covered.sort_unstable();
        assert_eq!(covered, all);
        // The first run holds the patch under the eye, and no run's nearest
        // patch is nearer than an earlier run's.
        assert!(runs[0].0 <= 2 * 8 + 5 && 2 * 8 + 5 < runs[0].0 + runs[0].1);
        let nearest: Vec<u32> = runs
            .iter()
            .map(|&(f, n)| (f..f + n).map(|p| order.key(p)).min().expect("run"))
            .collect();
        assert!(nearest.windows(2).all(|w| w[0] <= w[1]), "{nearest:?}");
        // No run crosses a row, the eye's column or `MAX_RUN`.
        for &(f, n) in &runs {
            assert!(n <= MAX_RUN && f / 8 == (f + n - 1) / 8);
            assert!(!(f % 8 < 5 && 5 < f % 8 + n), "{f} {n} spans column 5");
        }
    }

    #[test]
    fn keys_grow_with_plan_distance() {
        // An eye off the grid's left edge, level with row 0's middle.
        let order = order(Vec3::new(-30.0, 10.0, 14.0));
        let row0: Vec<u32> = (0..8).map(|c| order.key(c)).collect();
        assert!(row0.windows(2).all(|w| w[0] < w[1]), "{row0:?}");
        // 14 m from the edge, in f32.
        assert_eq!(f32::from_bits(order.key(0)), 14.0);
        assert!(order.key(8) > order.key(0));
    }
}
