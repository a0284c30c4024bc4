//! Height queries on the triangulated surface.
//!
//! Each cell is split along the diagonal from its upper-right sample B to its
//! lower-left sample C, giving the triangles ABC (upper-left) and DCB
//! (lower-right):
//!
//! ```text
//!   A ---- B     row r
//!   |    / |
//!   |  /   |
//!   C ---- D     row r + 1
//!  col c   col c + 1
//! ```
//!
//! The interpolation itself is `Heightmap::interpolate`, which the shaders
//! mirror: heights are barycentric in the triangle, so a query on a sample
//! returns that sample exactly (weights 1, 0, 0), and the cell lookup clamps
//! to the last cell instead of reading past the last row or column.

use glam::{DVec2, Vec3};

use super::info::{Samples, TerrainInfo};
use super::placement::Placement;

/// How far outside the grid (in cells) a query may land and still count as
/// on the terrain. It absorbs the rounding of world -> grid conversion, so the
/// far edge's own samples are not reported as outside.
const EDGE_TOLERANCE_CELLS: f64 = 1e-7;

impl Placement {
    /// Continuous sample coordinates (column, row) of world (x, z), or
    /// None outside the terrain (or for a non-finite coordinate).
    #[inline]
    pub fn grid_on_terrain(&self, x: f64, z: f64) -> Option<DVec2> {
        let g = self.world_to_grid(x, z);
        let max_c = (self.cols() - 1) as f64;
        let max_r = (self.rows() - 1) as f64;
        // Written so NaN fails every comparison and lands in None.
        let inside = g.x >= -EDGE_TOLERANCE_CELLS
            && g.x <= max_c + EDGE_TOLERANCE_CELLS
            && g.y >= -EDGE_TOLERANCE_CELLS
            && g.y <= max_r + EDGE_TOLERANCE_CELLS;
        inside.then_some(g)
    }
}

impl TerrainInfo {
    /// Height of the surface at world (x, z), or None outside the terrain
    /// (or for a non-finite coordinate).
    #[inline]
    pub fn height_at(&self, x: f64, z: f64) -> Option<f32> {
        let g = self.placement().grid_on_terrain(x, z)?;
        self.interpolate(g)
    }

    /// The surface at continuous sample coordinates g (column, row). A
    /// tiled terrain reads the tile it needs; a tile that cannot be read
    /// (the file changed or broke since it was opened) is logged and gives
    /// None.
    fn interpolate(&self, g: DVec2) -> Option<f32> {
        match self.samples() {
            Samples::Whole(h) => Some(h.interpolate(g.x, g.y) as f32),
            Samples::Tiled(t) => match t.interpolate(g.x, g.y) {
                Ok(h) => Some(h as f32),
                Err(e) => {
                    log::error!("{e}");
                    None
                }
            },
        }
    }

    /// Height at the point of the terrain nearest to world (x, z): the
    /// position is clamped to the terrain's rectangle first, so walking off
    /// an edge keeps following the border. A non-finite coordinate is taken
    /// as the terrain's centre on that axis. NaN where a tiled terrain's
    /// tile cannot be read (logged).
    pub fn clamped_height_at(&self, x: f64, z: f64) -> f32 {
        let p = self.clamp_to_terrain(DVec2::new(x, z));
        let g = self.world_to_grid(p.x, p.y);
        self.interpolate(g).unwrap_or(f32::NAN)
    }

    /// World (x, z) clamped into the terrain's rectangle; non-finite
    /// coordinates become the centre.
    pub fn clamp_to_terrain(&self, p: DVec2) -> DVec2 {
        let half = DVec2::new(0.5 * self.world_width(), 0.5 * self.world_depth());
        let origin = self.origin();
        let axis = |v: f64, o: f64, h: f64| {
            if v.is_finite() {
                v.clamp(o - h, o + h)
            } else {
                o
            }
        };
        DVec2::new(axis(p.x, origin.x, half.x), axis(p.y, origin.y, half.y))
    }

    /// Unit surface normal at world (x, z) by central differences of the
    /// surface one cell either side, falling back to one-sided differences
    /// where the stencil would leave the terrain.
    pub fn normal_at(&self, x: f64, z: f64) -> Vec3 {
        let p = self.clamp_to_terrain(DVec2::new(x, z));
        let sp = self.spacing();
        let left = self.clamp_to_terrain(p - DVec2::new(sp.x, 0.0));
        let right = self.clamp_to_terrain(p + DVec2::new(sp.x, 0.0));
        let near = self.clamp_to_terrain(p + DVec2::new(0.0, sp.y));
        let far = self.clamp_to_terrain(p - DVec2::new(0.0, sp.y));
        let h = |q: DVec2| f64::from(self.clamped_height_at(q.x, q.y));
        // Both stencils span at least one cell: the terrain is >= 2x2.
        let dhdx = (h(right) - h(left)) / (right.x - left.x);
        let dhdz = (h(near) - h(far)) / (near.y - far.y);
        Vec3::new(-dhdx as f32, 1.0, -dhdz as f32).normalize()
    }
}
