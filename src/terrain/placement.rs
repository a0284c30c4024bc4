//! `Placement`: where a grid of samples lies in the world. Below both the
//! terrain in memory (`TerrainInfo`) and the tiled file's height queries,
//! which place their samples the same way.

use glam::DVec2;

use super::error::TerrainError;

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

    /// World (x, z) of the grid's centre.
    pub fn origin(&self) -> DVec2 {
        self.origin
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
