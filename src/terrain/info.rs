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
use super::heightmap::Heightmap;

/// Cells per patch when the caller does not choose.
pub const DEFAULT_CELLS_PER_PATCH: u32 = 32;
/// Largest cells per patch: one patch at the maximum tessellation factor
/// (64) then still has a vertex at every sample.
pub const MAX_CELLS_PER_PATCH: u32 = 64;

#[derive(Clone, Debug, PartialEq)]
pub struct TerrainInfo {
    heightmap: Heightmap,
    cells_per_patch: u32,
    placement: Placement,
    /// Error tables that came with the heightmap (a tiled terrain stores
    /// them), for `cells_per_patch`: tess, geomip.
    error_tables: Option<std::sync::Arc<(ErrorTable, ErrorTable)>>,
}

/// Where a grid of samples lies in the world: its size, spacing and
/// centre. `TerrainInfo` places a heightmap in memory with it, and height
/// queries on a tiled terrain place its samples the same way.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    cols: usize,
    rows: usize,
    spacing: DVec2,
    origin: DVec2,
    /// Derived once for `world_to_grid`, the hot path of height queries:
    /// world position of sample (0, 0) and 1 / spacing.
    grid_origin: DVec2,
    inv_spacing: DVec2,
}

impl Placement {
    /// `cols` x `rows` samples `spacing` (dx, dz) apart, centred on world
    /// (x, z) `origin`.
    pub fn new(
        cols: usize,
        rows: usize,
        spacing: DVec2,
        origin: DVec2,
    ) -> Result<Self, TerrainError> {
        if !(spacing.x > 0.0 && spacing.y > 0.0 && spacing.is_finite()) {
            return Err(TerrainError::CellSpacing {
                x: spacing.x,
                z: spacing.y,
            });
        }
        if !origin.is_finite() {
            return Err(TerrainError::Origin {
                x: origin.x,
                z: origin.y,
            });
        }
        let half = DVec2::new(
            0.5 * (cols - 1) as f64 * spacing.x,
            0.5 * (rows - 1) as f64 * spacing.y,
        );
        Ok(Placement {
            cols,
            rows,
            spacing,
            origin,
            grid_origin: DVec2::new(origin.x - half.x, origin.y + half.y),
            inv_spacing: spacing.recip(),
        })
    }

    pub fn cols(&self) -> usize {
        self.cols
    }

    pub fn rows(&self) -> usize {
        self.rows
    }

    /// (dx, dz).
    pub fn spacing(&self) -> DVec2 {
        self.spacing
    }

    /// World extent along x: (cols - 1) * dx.
    pub fn world_width(&self) -> f64 {
        (self.cols - 1) as f64 * self.spacing.x
    }

    /// World extent along z: (rows - 1) * dz.
    pub fn world_depth(&self) -> f64 {
        (self.rows - 1) as f64 * self.spacing.y
    }

    /// Local x of a sample column (relative to the terrain's centre).
    pub fn local_x(&self, col: usize) -> f64 {
        -0.5 * self.world_width() + col as f64 * self.spacing.x
    }

    /// Local z of a sample row (relative to the terrain's centre).
    pub fn local_z(&self, row: usize) -> f64 {
        0.5 * self.world_depth() - row as f64 * self.spacing.y
    }

    /// World (x, z) of sample (row, col).
    pub fn sample_position(&self, row: usize, col: usize) -> DVec2 {
        self.origin + DVec2::new(self.local_x(col), self.local_z(row))
    }

    /// Converts a world (x, z) to continuous sample coordinates
    /// (column, row): sample (r, c) is at exactly (c, r).
    ///
    /// Multiplies by the reciprocal spacing rather than dividing: the result
    /// may differ from the quotient in its last bit, which moves a query on a
    /// sample by ~1e-16 cells, far below what the f32 height can show.
    #[inline]
    pub fn world_to_grid(&self, x: f64, z: f64) -> DVec2 {
        DVec2::new(
            (x - self.grid_origin.x) * self.inv_spacing.x,
            (self.grid_origin.y - z) * self.inv_spacing.y,
        )
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
            heightmap,
            cells_per_patch,
            placement,
            error_tables: None,
        })
    }

    /// Takes the error tables (tess, geomip) of this heightmap and patch
    /// size as they were computed and stored elsewhere, instead of having
    /// `Terrain` compute them. They must be `ErrorTable::compute_pair`'s
    /// result for it.
    pub fn with_error_tables(self, tess: ErrorTable, geomip: ErrorTable) -> Self {
        let patches = super::grid::PatchGrid::new(&self).patch_count();
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

    /// Where the samples lie in the world.
    pub fn placement(&self) -> &Placement {
        &self.placement
    }

    pub fn heightmap(&self) -> &Heightmap {
        &self.heightmap
    }

    /// Number of sample columns.
    pub fn cols(&self) -> usize {
        self.heightmap.width()
    }

    /// Number of sample rows.
    pub fn rows(&self) -> usize {
        self.heightmap.depth()
    }

    /// (dx, dz).
    pub fn spacing(&self) -> DVec2 {
        self.placement.spacing
    }

    pub fn cells_per_patch(&self) -> u32 {
        self.cells_per_patch
    }

    /// World (x, z) of the terrain's centre.
    pub fn origin(&self) -> DVec2 {
        self.placement.origin
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

/// Cells per patch must be a power of two in 2..=64.
pub fn validate_cells_per_patch(n: u32) -> Result<(), TerrainError> {
    if n.is_power_of_two() && (2..=MAX_CELLS_PER_PATCH).contains(&n) {
        Ok(())
    } else {
        Err(TerrainError::CellsPerPatch(n))
    }
}
