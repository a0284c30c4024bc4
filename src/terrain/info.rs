//! `TerrainInfo`: a heightmap placed in the world.
//!
//! The terrain is centred on its origin. With `W = (cols - 1) * dx` and
//! `D = (rows - 1) * dz`, sample (row, col) sits at local
//! `x = -W/2 + col * dx`, `z = +D/2 - row * dz`: row 0 is the far (+z) edge,
//! column 0 the left (-x) edge. World coordinates add the origin.
//!
//! World positions are f64 so a terrain can sit far from the world origin
//! without losing precision; local positions (relative to the terrain's own
//! origin) are small and are what reaches the GPU as f32.

use glam::DVec2;

use super::error::TerrainError;
use super::error_table::ErrorTable;
use super::grid::{validate_cells_per_patch, PatchGrid, MAX_CELLS_PER_PATCH};
use super::heightmap::Heightmap;
use super::placement::Placement;
use super::tiled::{StoredTables, TiledHeightmap};

/// Cells per patch when the caller does not choose.
pub const DEFAULT_CELLS_PER_PATCH: u32 = 32;

#[derive(Clone, Debug, PartialEq)]
pub struct TerrainInfo {
    samples: Samples,
    /// Lowest and highest height.
    range: (f32, f32),
    cells_per_patch: u32,
    placement: Placement,
    /// Error tables that came with the heightmap (a tiled terrain stores
    /// them), for `cells_per_patch`: tess, geomip.
    error_tables: Option<std::sync::Arc<(ErrorTable, ErrorTable)>>,
    /// Per-patch Y bounds that came with a tiled terrain.
    y_bounds: Option<std::sync::Arc<Vec<[f32; 2]>>>,
}

/// Where a terrain's heights are: in memory whole, or in a tiled terrain
/// file read a tile at a time (a terrain larger than memory, streamed).
#[derive(Clone, Debug)]
pub enum Samples {
    Whole(Heightmap),
    Tiled(std::sync::Arc<TiledHeightmap>),
}

impl PartialEq for Samples {
    /// Whole heightmaps by their samples; tiled ones by the file.
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (Samples::Whole(a), Samples::Whole(b)) => a == b,
            (Samples::Tiled(a), Samples::Tiled(b)) => a.path() == b.path(),
            _ => false,
        }
    }
}

impl TerrainInfo {
    /// `spacing` is (dx, dz) (glam's `y` holds dz), the world distance between neighbouring samples
    /// along x and z; `origin` is the world (x, z) of the terrain's centre.
    pub fn new(
        heightmap: Heightmap,
        spacing: DVec2,
        cells_per_patch: u32,
        origin: DVec2,
    ) -> Result<Self, TerrainError> {
        validate_cells_per_patch(cells_per_patch)?;
        let placement = Placement::new(heightmap.width(), heightmap.depth(), spacing, origin)?;
        Ok(TerrainInfo {
            range: heightmap.min_max(),
            samples: Samples::Whole(heightmap),
            cells_per_patch,
            placement,
            error_tables: None,
            y_bounds: None,
        })
    }

    /// A tiled terrain, read a tile at a time, with what it stores for
    /// `cells_per_patch`-cell patches (which must be `tables`' size): the
    /// error tables and Y bounds a `Terrain` would otherwise compute from
    /// every sample.
    pub fn tiled(
        tiled: std::sync::Arc<TiledHeightmap>,
        tables: StoredTables,
        spacing: DVec2,
        origin: DVec2,
    ) -> Result<Self, TerrainError> {
        let cells_per_patch = tables.cells_per_patch;
        validate_cells_per_patch(cells_per_patch)?;
        let placement = Placement::new(tiled.width(), tiled.depth(), spacing, origin)?;
        let info = TerrainInfo {
            range: tiled.min_max(),
            samples: Samples::Tiled(tiled),
            cells_per_patch,
            placement,
            error_tables: None,
            y_bounds: None,
        };
        let patches = info.patch_grid().patch_count();
        assert_eq!(
            tables.y_bounds.len(),
            patches,
            "stored bounds have one row per patch"
        );
        Ok(TerrainInfo {
            y_bounds: Some(std::sync::Arc::new(tables.y_bounds)),
            ..info.with_error_tables(tables.tess, tables.geomip)
        })
    }

    /// Takes the error tables (tess, geomip) of this heightmap and patch
    /// size as they were computed and stored elsewhere, instead of having
    /// `Terrain` compute them. They must be `ErrorTable::compute_pair`'s
    /// result for it.
    pub fn with_error_tables(self, tess: ErrorTable, geomip: ErrorTable) -> Self {
        let patches = self.patch_grid().patch_count();
        assert_eq!(
            (tess.as_slice().len(), geomip.as_slice().len()),
            (patches * ErrorTable::LEVELS, patches * ErrorTable::LEVELS),
            "stored tables have one row per patch"
        );
        TerrainInfo {
            error_tables: Some(std::sync::Arc::new((tess, geomip))),
            ..self
        }
    }

    /// The error tables that came with the heightmap, if any.
    pub fn stored_error_tables(&self) -> Option<&(ErrorTable, ErrorTable)> {
        self.error_tables.as_deref()
    }

    /// The stored error tables, shared rather than copied.
    pub fn stored_error_tables_shared(&self) -> Option<std::sync::Arc<(ErrorTable, ErrorTable)>> {
        self.error_tables.clone()
    }

    /// Where the samples lie in the world.
    pub fn placement(&self) -> &Placement {
        &self.placement
    }

    /// The heightmap, when it is in memory whole (not for a tiled terrain
    /// from `tiled`).
    pub fn heightmap(&self) -> Option<&Heightmap> {
        match &self.samples {
            Samples::Whole(h) => Some(h),
            Samples::Tiled(_) => None,
        }
    }

    /// The heightmap of a terrain held whole, for what is made from every
    /// sample at once (the lightmap, blend maps from rules; a streamed
    /// terrain's scene is refused them up front).
    ///
    /// # Panics
    /// For a tiled terrain from `tiled`.
    pub fn whole(&self) -> &Heightmap {
        self.heightmap()
            .expect("made from the whole heightmap, which a streamed terrain does not hold")
    }

    /// The tiled terrain file the heights are read from, for one from
    /// `tiled`.
    pub fn tiled_samples(&self) -> Option<&std::sync::Arc<TiledHeightmap>> {
        match &self.samples {
            Samples::Tiled(t) => Some(t),
            Samples::Whole(_) => None,
        }
    }

    pub fn samples(&self) -> &Samples {
        &self.samples
    }

    /// The Y bounds of every patch stored with a tiled terrain.
    pub fn stored_y_bounds(&self) -> Option<&[[f32; 2]]> {
        self.y_bounds.as_deref().map(Vec::as_slice)
    }

    /// Lowest and highest height.
    pub fn min_max(&self) -> (f32, f32) {
        self.range
    }

    /// Number of sample columns.
    pub fn cols(&self) -> usize {
        self.placement.cols()
    }

    /// Number of sample rows.
    pub fn rows(&self) -> usize {
        self.placement.rows()
    }

    /// (dx, dz).
    pub fn spacing(&self) -> DVec2 {
        self.placement.spacing()
    }

    pub fn cells_per_patch(&self) -> u32 {
        self.cells_per_patch
    }

    /// The terrain's grid of patches of `cells_per_patch` cells.
    pub fn patch_grid(&self) -> PatchGrid {
        PatchGrid::for_size(self.cols(), self.rows(), self.cells_per_patch)
    }

    /// World (x, z) of the terrain's centre.
    pub fn origin(&self) -> DVec2 {
        self.placement.origin()
    }

    /// World extent along x: (cols - 1) * dx.
    pub fn world_width(&self) -> f64 {
        self.placement.world_width()
    }

    /// World extent along z: (rows - 1) * dz.
    pub fn world_depth(&self) -> f64 {
        self.placement.world_depth()
    }

    /// Local x of a sample column (relative to the terrain's centre).
    pub fn local_x(&self, col: usize) -> f64 {
        self.placement.local_x(col)
    }

    /// Local z of a sample row (relative to the terrain's centre).
    pub fn local_z(&self, row: usize) -> f64 {
        self.placement.local_z(row)
    }

    /// World (x, z) of sample (row, col).
    pub fn sample_position(&self, row: usize, col: usize) -> DVec2 {
        self.placement.sample_position(row, col)
    }

    /// Converts a world (x, z) to continuous sample coordinates
    /// (column, row) (`Placement::world_to_grid`).
    #[inline]
    pub fn world_to_grid(&self, x: f64, z: f64) -> DVec2 {
        self.placement.world_to_grid(x, z)
    }
}

/// Largest patch grid side a tiled terrain's stored tables are made for
/// unless told otherwise (see `stored_cells_per_patch`).
pub const STORED_PATCHES_PER_SIDE: usize = 256;

/// The patch size whose tables a tiled terrain of `width` x `depth`
/// samples stores unless told: `DEFAULT_CELLS_PER_PATCH`, doubled (up to
/// `MAX_CELLS_PER_PATCH`) while the grid would have more than
/// `STORED_PATCHES_PER_SIDE` patches a side. Every patch in view costs the
/// control shader whatever its factor, so a terrain past 8193^2 samples
/// gets larger patches rather than more of them.
pub fn stored_cells_per_patch(width: usize, depth: usize) -> u32 {
    let cells = width.max(depth).saturating_sub(1);
    let mut n = DEFAULT_CELLS_PER_PATCH;
    while n < MAX_CELLS_PER_PATCH && cells.div_ceil(n as usize) > STORED_PATCHES_PER_SIDE {
        n *= 2;
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stored_patches_grow_past_256_a_side_up_to_64_cells() {
        assert_eq!(stored_cells_per_patch(1025, 1025), 32);
        assert_eq!(stored_cells_per_patch(403, 344), 32);
        // 8193 samples: 256 patches of 32 cells, still the default.
        assert_eq!(stored_cells_per_patch(8193, 8193), 32);
        assert_eq!(stored_cells_per_patch(8194, 100), 64);
        assert_eq!(stored_cells_per_patch(100, 16385), 64);
        // No larger than a patch that still reaches every sample.
        assert_eq!(stored_cells_per_patch(32769, 32769), 64);
        assert_eq!(stored_cells_per_patch(1, 1), 32);
        assert_eq!(stored_cells_per_patch(0, 0), 32);
    }
}
