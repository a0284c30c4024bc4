//! The CPU terrain model: heightmaps, the patch grid, Y bounds, the error
//! table, height queries, and the camera and LOD maths the shaders mirror.
//!
//! Nothing here knows about Vulkan; everything is testable on any machine.

pub mod camera;
pub mod error;
pub mod error_table;
pub mod generate;
pub mod grid;
pub mod heightmap;
pub mod info;
pub mod load;
pub mod lod_params;
pub mod placement;
mod query;
pub mod shading;
pub mod sight;
pub mod slabs;
pub mod tiled;

pub use camera::{look_at, perspective, Frustum};
pub use error::{HeightmapError, TerrainError};
pub use error_table::{ErrorTable, PatchErrors, ERROR_LEVELS};
pub use grid::{PatchGrid, PatchId, SampleRect};
pub use heightmap::{Heightmap, HeightmapFormat, LoadOptions};
pub use info::{TerrainInfo, DEFAULT_CELLS_PER_PATCH};
pub use lod_params::{DistanceLod, DistanceMode, LodError};
pub use placement::Placement;

use glam::Vec3;

/// A terrain ready to feed the GPU: its parameters, patch grid, Y bounds,
/// control points and indices.
#[derive(Clone, Debug)]
pub struct Terrain {
    info: TerrainInfo,
    grid: PatchGrid,
    y_bounds: Vec<[f32; 2]>,
    control_points: Vec<[f32; 4]>,
    /// The height of the sample under each control point.
    control_heights: Vec<f32>,
    indices: Vec<u32>,
    /// The tess and geomip error tables, computed on first use and kept:
    /// every renderer of this terrain shares them.
    /// Shared with the info's stored tables where it has them.
    error_tables: std::sync::OnceLock<std::sync::Arc<(ErrorTable, ErrorTable)>>,
    /// The error LOD's view model (`sight`), computed on first use and
    /// kept; None for a terrain whose heights the CPU does not hold whole.
    sight: std::sync::OnceLock<Option<std::sync::Arc<sight::SightTable>>>,
    /// Each patch's parts (`slabs`), computed with the view model; None
    /// where the heights are not held whole.
    slabs: std::sync::OnceLock<Option<std::sync::Arc<slabs::PatchSlabs>>>,
}

/// The height under each control point of a tiled terrain, from each
/// tile's level whose step is the patch size (it keeps every patch
/// boundary sample, exactly).
fn tiled_control_heights(
    tiled: &tiled::TiledHeightmap,
    grid: &PatchGrid,
) -> Result<Vec<f32>, TerrainError> {
    let t = tiled.header().tile_cells as usize;
    let n = grid.cells_per_patch();
    let level = n.trailing_zeros();
    // One tile level at a time, in the order the rows ask for them.
    let (tiles_x, _) = tiled.header().tiles();
    let mut row_tiles: Vec<Option<std::sync::Arc<tiled::TileLevel>>> = vec![None; tiles_x as usize];
    let mut row_tz = u32::MAX;
    grid::control_heights(grid, |r, c| {
        let tz = (r.saturating_sub(1) / t) as u32;
        let tx = (c.saturating_sub(1) / t) as u32;
        if tz != row_tz {
            row_tiles.iter_mut().for_each(|l| *l = None);
            row_tz = tz;
        }
        let slot = &mut row_tiles[tx as usize];
        if slot.is_none() {
            *slot = Some(tiled.tile(tx, tz, level)?);
        }
        let tile = slot.as_ref().expect("read above");
        // The level's index of a boundary sample: a multiple of the patch
        // size, or the terrain's last sample, which is the level's last.
        let (lr, lc) = (r - tz as usize * t, c - tx as usize * t);
        let index = |v: usize, side: u32| {
            if v % n == 0 {
                v / n
            } else {
                side as usize - 1
            }
        };
        Ok(tile.get(index(lr, tile.rows) as u32, index(lc, tile.cols) as u32))
    })
    .map_err(|e: tiled::TiledError| TerrainError::Tiled(e.to_string()))
}

impl Terrain {
    /// Builds the patch grid; each patch's Y bounds are widened by
    /// `y_margin` (for displacement the heightmap doesn't account for).
    pub fn new(info: TerrainInfo, y_margin: f32) -> Result<Self, TerrainError> {
        if !(y_margin >= 0.0 && y_margin.is_finite()) {
            return Err(TerrainError::Margin(y_margin));
        }
        let grid = info.patch_grid();
        let (y_bounds, control_heights) = match info.samples() {
            info::Samples::Whole(h) => (
                grid::patch_y_bounds(h, &grid, y_margin),
                grid::control_heights(&grid, |r, c| Ok(h.get(r, c)))?,
            ),
            info::Samples::Tiled(t) => {
                let stored = info
                    .stored_y_bounds()
                    .expect("a tiled terrain info has its bounds");
                (
                    stored
                        .iter()
                        .map(|&[lo, hi]| [lo - y_margin, hi + y_margin])
                        .collect(),
                    tiled_control_heights(t, &grid)?,
                )
            }
        };
        let control_points = grid::control_points(info.placement(), &grid, &y_bounds);
        let indices = grid.indices();
        let error_tables = match info.stored_error_tables_shared() {
            Some(tables) => std::sync::OnceLock::from(tables),
            None => std::sync::OnceLock::new(),
        };
        Ok(Terrain {
            info,
            grid,
            y_bounds,
            control_points,
            control_heights,
            indices,
            error_tables,
            sight: std::sync::OnceLock::new(),
            slabs: std::sync::OnceLock::new(),
        })
    }

    pub fn info(&self) -> &TerrainInfo {
        &self.info
    }

    pub fn grid(&self) -> &PatchGrid {
        &self.grid
    }

    /// `[min, max]` height per patch, row-major.
    pub fn y_bounds(&self) -> &[[f32; 2]] {
        &self.y_bounds
    }

    /// `(x, z, minY, maxY)` per control point, local coordinates.
    pub fn control_points(&self) -> &[[f32; 4]] {
        &self.control_points
    }

    /// Four control point indices per patch.
    pub fn indices(&self) -> &[u32] {
        &self.indices
    }

    /// The per-patch error table (computed on each call; it is the expensive
    /// part of preparing a terrain). A tiled terrain's is the stored one.
    pub fn error_table(&self) -> ErrorTable {
        match self.info.heightmap() {
            Some(h) => ErrorTable::compute(h, &self.grid),
            None => self.error_tables().0.clone(),
        }
    }

    /// The tess path's error table and the geomip path's, computed together
    /// (see `ErrorTable::compute_pair`) the first time they are asked for.
    /// A tiled terrain's come with it (`TerrainInfo::tiled`).
    pub fn error_tables(&self) -> &(ErrorTable, ErrorTable) {
        self.error_tables.get_or_init(|| {
            let h = self
                .info
                .heightmap()
                .expect("a tiled terrain's info holds its stored tables");
            std::sync::Arc::new(ErrorTable::compute_pair(h, &self.grid))
        })
    }

    /// The error LOD's view model of every full-size patch (see `sight`),
    /// computed the first time it is asked for, with each patch's parts
    /// (`patch_slabs`), so a frame reads both ready; None where the
    /// heights are not held whole (a tiled terrain read a tile at a time).
    pub fn sight_table(&self) -> Option<&sight::SightTable> {
        self.sight
            .get_or_init(|| {
                let map = self.info.heightmap()?;
                self.patch_slabs();
                let spacing = self.info.spacing();
                let compute = || {
                    sight::SightTable::compute(map, &self.grid, (spacing.x, spacing.y)).to_bytes()
                };
                // Kept on disk by a hash of everything it depends on: the
                // heights, the spacing and the patch size.
                let key = crate::cache::key((
                    sight::MODEL_VERSION,
                    bytemuck::cast_slice::<f32, u8>(map.heights()),
                    self.info.cols(),
                    self.info.rows(),
                    [spacing.x, spacing.y].map(f64::to_bits),
                    self.grid.cells_per_patch(),
                ));
                let len = sight::SightTable::encoded_len(&self.grid);
                let bytes = crate::cache::load_or_compute(
                    crate::cache::dir().as_deref(),
                    "sight",
                    key,
                    len,
                    compute,
                );
                sight::SightTable::from_bytes(&self.grid, &bytes).map(std::sync::Arc::new)
            })
            .as_deref()
    }

    /// Each patch's parts (see `slabs`), computed the first time they
    /// are asked for (`sight_table` asks); None where the heights are not
    /// held whole.
    pub fn patch_slabs(&self) -> Option<&slabs::PatchSlabs> {
        self.slabs
            .get_or_init(|| {
                let map = self.info.heightmap()?;
                let slabs = slabs::PatchSlabs::compute(map, &self.grid, self.info.placement());
                Some(std::sync::Arc::new(slabs))
            })
            .as_deref()
    }

    /// Whether `sight_table` has been asked for: only then does the
    /// terrain hold its view model.
    pub fn sight_table_asked(&self) -> bool {
        self.sight.get().is_some()
    }

    /// Widens each patch's Y bounds to those of the square block of
    /// `block_cells` cells (aligned to multiples of it) that holds it. A
    /// surface drawn from every `block_cells`-th sample then still lies
    /// inside every patch's bounds: its cells span whole blocks, and their
    /// corners are samples of the block. A no-op for blocks no larger than
    /// a patch.
    pub fn widen_y_bounds_to_blocks(&mut self, block_cells: u32) {
        let cpp = self.grid.cells_per_patch();
        let per_block = block_cells as usize / cpp;
        if per_block <= 1 {
            return;
        }
        let (cols, rows) = (self.grid.patch_cols(), self.grid.patch_rows());
        let (blocks_x, blocks_z) = (cols.div_ceil(per_block), rows.div_ceil(per_block));
        let mut blocks = vec![[f32::INFINITY, f32::NEG_INFINITY]; blocks_x * blocks_z];
        let block_of = |p: usize| (p / cols / per_block) * blocks_x + (p % cols) / per_block;
        for (p, b) in self.y_bounds.iter().enumerate() {
            let block = &mut blocks[block_of(p)];
            *block = [block[0].min(b[0]), block[1].max(b[1])];
        }
        for (p, b) in self.y_bounds.iter_mut().enumerate() {
            *b = blocks[block_of(p)];
        }
        self.control_points =
            grid::control_points(self.info.placement(), &self.grid, &self.y_bounds);
    }

    /// A patch's corners in local coordinates at their sample heights, in
    /// index order: upper-left, upper-right, lower-left, lower-right. This
    /// is what the vertex stage produces for the four control points.
    pub fn patch_corners(&self, id: PatchId) -> [Vec3; 4] {
        let p = self.grid.patch_index(id);
        let corner = |k: usize| {
            let i = self.indices[4 * p + k] as usize;
            let [x, z, _, _] = self.control_points[i];
            Vec3::new(x, self.control_heights[i], z)
        };
        [corner(0), corner(1), corner(2), corner(3)]
    }

    /// Lower bounds on the distance from `eye` (terrain-local) to any point
    /// of patch `id` that lies within `grows[k]` above or below its
    /// surface, one for each grow: the nearest of its cells' boxes, each
    /// grown by that much up and down. A cell's surface lies between the
    /// lowest and highest of its corners, whichever diagonal splits it, so
    /// a patch drawn within an error of its surface lies in its cells'
    /// boxes grown by that error. 0 where the eye is in a grown box. None
    /// for a tiled terrain, whose samples are not held.
    pub fn surface_distances<const N: usize>(
        &self,
        id: PatchId,
        eye: Vec3,
        grows: &[f32; N],
    ) -> Option<[f32; N]> {
        let map = self.info.heightmap()?;
        let rect = self.grid.sample_rect(id);
        // How far `v` lies outside the span between `a` and `b`.
        let gap = |v: f32, a: f32, b: f32| (a.min(b) - v).max(v - a.max(b)).max(0.0);
        let xs: Vec<f32> = (rect.col0..=rect.col1)
            .map(|c| self.info.local_x(c) as f32)
            .collect();
        let mut nearest = [f32::INFINITY; N];
        for r in rect.row0..rect.row1 {
            let (z0, z1) = (self.info.local_z(r) as f32, self.info.local_z(r + 1) as f32);
            let dz = gap(eye.z, z0, z1);
            if nearest.iter().all(|&n| dz * dz >= n) {
                continue;
            }
            let (above, below) = (map.row(r), map.row(r + 1));
            for (i, c) in (rect.col0..rect.col1).enumerate() {
                let dx = gap(eye.x, xs[i], xs[i + 1]);
                let across = dx * dx + dz * dz;
                if nearest.iter().all(|&n| across >= n) {
                    continue;
                }
                let corners = [above[c], above[c + 1], below[c], below[c + 1]];
                let lo = corners.into_iter().fold(f32::INFINITY, f32::min);
                let hi = corners.into_iter().fold(f32::NEG_INFINITY, f32::max);
                for (n, &g) in nearest.iter_mut().zip(grows) {
                    let dy = gap(eye.y, lo - g, hi + g);
                    *n = n.min(across + dy * dy);
                }
            }
        }
        Some(nearest.map(f32::sqrt))
    }

    /// A patch's bounding box in local coordinates as (centre, half extents).
    pub fn patch_aabb(&self, id: PatchId) -> (Vec3, Vec3) {
        let [ul, _, _, lr] = self.patch_corners(id);
        let [min_y, max_y] = self.y_bounds[self.grid.patch_index(id)];
        let lo = Vec3::new(ul.x, min_y, lr.z);
        let hi = Vec3::new(lr.x, max_y, ul.z);
        (0.5 * (lo + hi), 0.5 * (hi - lo))
    }
}
