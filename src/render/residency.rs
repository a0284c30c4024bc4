//! Which tiles of a streamed terrain are resident on the GPU: the policy
//! behind `streaming`, in plain Rust so it can be tested without a device.
//!
//! A streamed terrain is drawn from two sources. The **base level** keeps
//! every `2^base_level`-th sample of the whole terrain and is always
//! resident. A **page pool** of a fixed number of layers holds tiles at
//! full resolution, one tile a layer. Each frame, every tile in the view
//! gets a priority: the error, in pixels, of drawing it from the base level
//! seen from its nearest point (the tile file's per-level error over the
//! distance). Tiles are loaded in priority order into free layers, or into
//! the layer of the least useful resident tile when that one's priority is
//! clearly lower, so the pool converges on the tiles whose absence shows
//! most. A tile that is evicted keeps drawing from its layer until the tile
//! replacing it has arrived: the swap happens in one frame.
//!
//! Nothing here waits: `plan` says what to load, and `arrived` says where
//! a loaded tile goes and which tile it displaces.

use crate::shader_constants::PAGE_NOT_RESIDENT;
use crate::terrain::tiled::{level_side, level_surface, tile_count};

/// A loaded tile takes the layer of a resident one only when its priority
/// is this many times the resident's, so two tiles of nearly equal need do
/// not swap back and forth as the camera moves.
pub const EVICTION_MARGIN: f32 = 1.5;

/// How a streamed terrain is cut: its samples, its tiles and its base
/// level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StreamShape {
    /// Samples across and down.
    pub cols: u32,
    pub rows: u32,
    /// Cells a tile side (a power of two); a tile holds its border samples.
    pub tile_cells: u32,
    pub tiles_x: u32,
    pub tiles_z: u32,
    /// The base level keeps every `2^base_level`-th sample and the last.
    pub base_level: u32,
}

impl StreamShape {
    /// The shape of a `cols` x `rows` terrain in tiles of `tile_cells`
    /// cells, with the finest base level whose sides are at most
    /// `base_max_side` samples (but never coarser than a tile).
    pub fn new(cols: u32, rows: u32, tile_cells: u32, base_max_side: u32) -> Self {
        let max_level = tile_cells.trailing_zeros();
        let base_level = (0..=max_level)
            .find(|&l| {
                level_side(cols - 1, l) <= base_max_side && level_side(rows - 1, l) <= base_max_side
            })
            .unwrap_or(max_level);
        StreamShape {
            cols,
            rows,
            tile_cells,
            tiles_x: tile_count(cols, tile_cells),
            tiles_z: tile_count(rows, tile_cells),
            base_level,
        }
    }

    pub fn tile_total(&self) -> usize {
        self.tiles_x as usize * self.tiles_z as usize
    }

    /// The base level's samples across and down.
    pub fn base_size(&self) -> (u32, u32) {
        (
            level_side(self.cols - 1, self.base_level),
            level_side(self.rows - 1, self.base_level),
        )
    }

    /// Samples a page pool layer holds across and down.
    pub fn page_side(&self) -> u32 {
        self.tile_cells + 1
    }

    /// The tile whose value a sample takes: a sample on a border between
    /// tiles belongs to the tile before it (left, above). Mirror: the
    /// choice in glsl/terrain_common.glsl `fetch_sample`.
    pub fn owner(&self, col: u32, row: u32) -> (u32, u32) {
        let t = self.tile_cells;
        (
            (col.saturating_sub(1) / t).min(self.tiles_x - 1),
            (row.saturating_sub(1) / t).min(self.tiles_z - 1),
        )
    }

    /// Tile (tx, tz)'s first sample and its cells across and down.
    pub fn tile_rect(&self, tx: u32, tz: u32) -> ((u32, u32), (u32, u32)) {
        let t = self.tile_cells;
        let (c0, r0) = (tx * t, tz * t);
        (
            (c0, r0),
            (
                (c0 + t).min(self.cols - 1) - c0,
                (r0 + t).min(self.rows - 1) - r0,
            ),
        )
    }

    pub fn tile_index(&self, tx: u32, tz: u32) -> usize {
        tz as usize * self.tiles_x as usize + tx as usize
    }

    /// The (tx, tz) of tile `index` (`tile_index`'s inverse).
    pub fn tile_coords(&self, index: usize) -> (u32, u32) {
        let across = self.tiles_x as usize;
        ((index % across) as u32, (index / across) as u32)
    }

    /// The height a streamed terrain draws at sample (col, row): the
    /// full-resolution sample `full(row, col)` where the sample's owner
    /// tile is resident, else the base level's surface there.
    /// Mirror: glsl/terrain_common.glsl `fetch_sample`.
    pub fn streamed_sample(
        &self,
        resident: impl Fn(usize) -> bool,
        full: impl Fn(u32, u32) -> f32,
        (col, row): (u32, u32),
    ) -> f32 {
        let (tx, tz) = self.owner(col, row);
        if resident(self.tile_index(tx, tz)) {
            return full(row, col);
        }
        level_surface(
            (self.cols - 1, self.rows - 1),
            self.base_level,
            (col, row),
            full,
        ) as f32
    }
}

/// A tile to read from disk, and the layer it will go into.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Load {
    pub tile: usize,
    pub layer: u32,
}

/// The page pool's occupancy and the loads in flight.
#[derive(Clone, Debug)]
pub struct Residency {
    /// Per tile: its layer, or `PAGE_NOT_RESIDENT`. This is the page table.
    layer_of_tile: Vec<u32>,
    /// Per layer: the tile drawn from it.
    tile_of_layer: Vec<Option<usize>>,
    /// Per layer: the tile being loaded into it.
    incoming: Vec<Option<usize>>,
    /// Per tile: whether a load for it is in flight.
    loading: Vec<bool>,
    /// Per tile: the priority `plan` last gave it.
    priority: Vec<f32>,
    evictions: u64,
}

impl Residency {
    /// Nothing resident, for `tiles` tiles and a pool of `layers` layers.
    pub fn new(tiles: usize, layers: u32) -> Self {
        Residency {
            layer_of_tile: vec![PAGE_NOT_RESIDENT; tiles],
            tile_of_layer: vec![None; layers as usize],
            incoming: vec![None; layers as usize],
            loading: vec![false; tiles],
            priority: vec![0.0; tiles],
            evictions: 0,
        }
    }

    /// The page table's entries: one per tile, its layer or
    /// `PAGE_NOT_RESIDENT`.
    pub fn page_table(&self) -> &[u32] {
        &self.layer_of_tile
    }

    pub fn layers(&self) -> u32 {
        self.tile_of_layer.len() as u32
    }

    pub fn resident_tiles(&self) -> usize {
        self.tile_of_layer.iter().flatten().count()
    }

    pub fn is_resident(&self, tile: usize) -> bool {
        self.layer_of_tile[tile] != PAGE_NOT_RESIDENT
    }

    pub fn loads_in_flight(&self) -> usize {
        self.loading.iter().filter(|&&l| l).count()
    }

    /// Tiles sent back to the base level since the start.
    pub fn evictions(&self) -> u64 {
        self.evictions
    }

    /// Takes this frame's priorities (one per tile; 0 for a tile the view
    /// does not need) and returns the loads to start, at most `max_new`,
    /// most needed first. Each load has a layer reserved: a free one, or
    /// that of the resident tile with the lowest priority when the load's
    /// priority is `EVICTION_MARGIN` times that.
    pub fn plan(&mut self, priorities: &[f32], max_new: usize) -> Vec<Load> {
        assert_eq!(priorities.len(), self.priority.len(), "one priority a tile");
        self.priority.copy_from_slice(priorities);
        let mut wanted: Vec<usize> = (0..priorities.len())
            .filter(|&t| priorities[t] > 0.0 && !self.is_resident(t) && !self.loading[t])
            .collect();
        wanted.sort_by(|&a, &b| priorities[b].total_cmp(&priorities[a]).then(a.cmp(&b)));
        // Layers that could take a load, least useful first: free ones,
        // then resident tiles by priority.
        let mut open: Vec<(f32, u32)> = (0..self.layers())
            .filter(|&l| self.incoming[l as usize].is_none())
            .map(|l| {
                let useful = self.tile_of_layer[l as usize].map_or(-1.0, |t| priorities[t]);
                (useful, l)
            })
            .collect();
        open.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut loads = Vec::new();
        for (tile, (useful, layer)) in wanted.into_iter().zip(open) {
            if loads.len() == max_new
                || (useful >= 0.0 && priorities[tile] <= EVICTION_MARGIN * useful)
            {
                break;
            }
            self.incoming[layer as usize] = Some(tile);
            self.loading[tile] = true;
            loads.push(Load { tile, layer });
        }
        loads
    }

    /// A load finished: its tile now draws from its layer, and the tile
    /// that drew from there (if any, returned) goes back to the base level.
    pub fn arrived(&mut self, load: Load) -> Option<usize> {
        let layer = load.layer as usize;
        assert_eq!(self.incoming[layer], Some(load.tile), "a load `plan` made");
        self.incoming[layer] = None;
        self.loading[load.tile] = false;
        let evicted = self.tile_of_layer[layer].replace(load.tile);
        if let Some(old) = evicted {
            self.layer_of_tile[old] = PAGE_NOT_RESIDENT;
            self.evictions += 1;
        }
        self.layer_of_tile[load.tile] = load.layer;
        evicted
    }

    /// A load that failed or was dropped: its layer is free to plan again.
    pub fn cancelled(&mut self, load: Load) {
        self.incoming[load.layer as usize] = None;
        self.loading[load.tile] = false;
    }

    /// The largest priority of a tile the view needs that is not resident:
    /// the worst error, in pixels, the base level adds to this frame (0
    /// when every needed tile is resident).
    pub fn missing_px(&self) -> f32 {
        (0..self.priority.len())
            .filter(|&t| !self.is_resident(t))
            .map(|t| self.priority[t])
            .fold(0.0, f32::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shape_picks_the_finest_base_that_fits_and_owns_borders_before() {
        let s = StreamShape::new(8193, 4097, 256, 2049);
        assert_eq!((s.tiles_x, s.tiles_z, s.base_level), (32, 16, 2));
        assert_eq!(s.base_size(), (2049, 1025));
        let s = StreamShape::new(100, 70, 16, 8);
        // Level 4 gives 8 x 6 samples (every 16th and the last).
        assert_eq!((s.tiles_x, s.tiles_z, s.base_level), (7, 5, 4));
        assert_eq!(s.base_size(), (8, 6));
        assert_eq!(s.owner(0, 0), (0, 0));
        assert_eq!(s.owner(16, 16), (0, 0));
        assert_eq!(s.owner(17, 32), (1, 1));
        assert_eq!(s.owner(99, 69), (6, 4));
        assert_eq!(s.tile_rect(6, 4), ((96, 64), (3, 5)));
    }

    #[test]
    fn loads_go_by_priority_and_evict_only_clearly_less_needed_tiles() {
        let mut r = Residency::new(5, 2);
        let loads = r.plan(&[1.0, 5.0, 0.0, 3.0, 2.0], 8);
        assert_eq!(
            loads,
            vec![Load { tile: 1, layer: 0 }, Load { tile: 3, layer: 1 }]
        );
        // Nothing changes until they arrive; nothing else is planned
        // while every layer has a load coming.
        assert!(r.plan(&[1.0, 5.0, 0.0, 3.0, 2.0], 8).is_empty());
        for l in loads {
            assert_eq!(r.arrived(l), None);
        }
        assert_eq!(
            r.page_table(),
            &[
                PAGE_NOT_RESIDENT,
                0,
                PAGE_NOT_RESIDENT,
                1,
                PAGE_NOT_RESIDENT
            ]
        );
        assert_eq!(r.missing_px(), 2.0);
        // Tile 4 at 4 px is not 1.5x tile 3's 3 px: no swap.
        assert!(r.plan(&[1.0, 5.0, 0.0, 3.0, 4.0], 8).is_empty());
        // At 5 px it is, and it takes tile 3's layer when it arrives.
        let loads = r.plan(&[1.0, 6.0, 0.0, 3.0, 5.0], 8);
        assert_eq!(loads, vec![Load { tile: 4, layer: 1 }]);
        assert!(
            r.is_resident(3),
            "an evicted tile draws until its successor arrives"
        );
        assert_eq!(r.arrived(loads[0]), Some(3));
        assert!(!r.is_resident(3) && r.is_resident(4));
        assert_eq!(r.evictions(), 1);
        // A cancelled load frees its layer for the next plan.
        let loads = r.plan(&[0.0, 0.0, 9.0, 0.0, 0.0], 1);
        assert_eq!(loads, vec![Load { tile: 2, layer: 0 }]);
        r.cancelled(loads[0]);
        assert_eq!(r.plan(&[0.0, 0.0, 9.0, 0.0, 0.0], 1), loads);
    }
}
