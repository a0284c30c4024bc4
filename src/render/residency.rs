//! Which pages of a streamed terrain are resident on the GPU: the policy
//! behind `streaming`, in plain Rust so it can be tested without a device.
//!
//! A streamed terrain is drawn from one **page pool**, an array image of
//! equal layers. A level-L page is the level-L samples (every `2^L`-th) of
//! a block of `2^L x 2^L` tiles, so every page, from a full-resolution tile
//! (level 0) to the **base level**, is `tile_cells + 1` samples a side.
//! The base level's pages, every `2^base_level`-th sample of the whole
//! terrain, hold the pool's first layers for good; the levels finer than
//! the base stream into the rest. A sample is drawn from the finest
//! resident page over its tile, else from the base.
//!
//! Each frame, every page in the view gets a priority: the error, in
//! pixels, of drawing its area one level coarser, seen from its nearest
//! point (the tile file's per-level errors over the distance). A coarser
//! page covers a finer one's area with a larger error, so pages tend to
//! arrive coarse to fine. Pages are loaded in priority order into free
//! layers, or into the layer of the least useful resident page when that
//! one's priority is clearly lower, so the pool converges on the pages
//! whose absence shows most. A page that is evicted keeps drawing from its
//! layer until the page replacing it has arrived: the swap happens in one
//! frame.
//!
//! Nothing here waits: `plan` says what to load, and `arrived` says where
//! a loaded page goes and which page it displaces.

use crate::shader_constants::PAGE_LEVEL_SHIFT;
use crate::terrain::tiled::{level_side, level_surface, tile_count};

/// A streamed page's layer in `Residency::page_layers` where it has none
/// (never in the shaders' page table, where every tile names a page).
pub const PAGE_NOT_RESIDENT: u32 = 0xFFFF_FFFF;

/// A loaded page takes the layer of a resident one only when its priority
/// is this many times the resident's, so two pages of nearly equal need do
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
        self.page_rect(0, tx, tz)
    }

    pub fn tile_index(&self, tx: u32, tz: u32) -> usize {
        tz as usize * self.tiles_x as usize + tx as usize
    }

    /// The (tx, tz) of tile `index` (`tile_index`'s inverse).
    pub fn tile_coords(&self, index: usize) -> (u32, u32) {
        let across = self.tiles_x as usize;
        ((index % across) as u32, (index / across) as u32)
    }

    /// Levels whose pages stream: full resolution up to the one before
    /// the base level. The base level's own pages are always resident.
    pub fn page_levels(&self) -> u32 {
        self.base_level
    }

    /// The base level's pages: `pages_across(base_level)`, row-major, in
    /// the pool's first layers for good.
    pub fn base_pages(&self) -> u32 {
        let (x, z) = self.pages_across(self.base_level);
        x * z
    }

    /// Pages across and down at `level`: one for each `2^level x 2^level`
    /// tiles, the last row and column of them partial.
    pub fn pages_across(&self, level: u32) -> (u32, u32) {
        (
            self.tiles_x.div_ceil(1 << level),
            self.tiles_z.div_ceil(1 << level),
        )
    }

    /// Where `level`'s pages start in the page table: the levels follow one
    /// another finest first, each row-major, so level 0's page indices are
    /// the tile indices.
    fn level_offset(&self, level: u32) -> usize {
        (0..level)
            .map(|l| {
                let (x, z) = self.pages_across(l);
                x as usize * z as usize
            })
            .sum()
    }

    /// Pages of every streamed level.
    pub fn page_total(&self) -> usize {
        self.level_offset(self.page_levels())
    }

    /// The index of page (px, pz) at `level`.
    pub fn page_index(&self, level: u32, px: u32, pz: u32) -> usize {
        let (across, _) = self.pages_across(level);
        self.level_offset(level) + pz as usize * across as usize + px as usize
    }

    /// The level and (px, pz) of page `index` (`page_index`'s inverse).
    pub fn page_coords(&self, index: usize) -> (u32, u32, u32) {
        let mut first = 0;
        for level in 0..self.page_levels() {
            let (x, z) = self.pages_across(level);
            let count = x as usize * z as usize;
            if index < first + count {
                let i = index - first;
                return (level, (i % x as usize) as u32, (i / x as usize) as u32);
            }
            first += count;
        }
        panic!("page {index} of {first}");
    }

    /// The page over tile (tx, tz) at `level`.
    pub fn page_of_tile(&self, level: u32, tx: u32, tz: u32) -> usize {
        self.page_index(level, tx >> level, tz >> level)
    }

    /// The tiles page (px, pz) at `level` covers: columns and rows of
    /// tiles.
    pub fn page_tiles(
        &self,
        level: u32,
        px: u32,
        pz: u32,
    ) -> (std::ops::Range<u32>, std::ops::Range<u32>) {
        let n = 1 << level;
        (
            px * n..((px + 1) * n).min(self.tiles_x),
            pz * n..((pz + 1) * n).min(self.tiles_z),
        )
    }

    /// Page (px, pz) at `level`: its first sample and the full-resolution
    /// cells it spans across and down.
    pub fn page_rect(&self, level: u32, px: u32, pz: u32) -> ((u32, u32), (u32, u32)) {
        let span = self.tile_cells << level;
        let (c0, r0) = (px * span, pz * span);
        (
            (c0, r0),
            (
                (c0 + span).min(self.cols - 1) - c0,
                (r0 + span).min(self.rows - 1) - r0,
            ),
        )
    }

    /// Samples page (px, pz) at `level` holds across and down: every
    /// `2^level`-th of its span and its last, at most `page_side` each.
    pub fn page_size(&self, level: u32, px: u32, pz: u32) -> (u32, u32) {
        let (_, (w, d)) = self.page_rect(level, px, pz);
        (level_side(w, level), level_side(d, level))
    }

    /// The level tile (tx, tz) is drawn at where `resident` says which
    /// pages are resident: the finest resident page over it, else the base
    /// level.
    pub fn drawn_level(&self, resident: impl Fn(usize) -> bool, (tx, tz): (u32, u32)) -> u32 {
        (0..self.page_levels())
            .find(|&level| resident(self.page_of_tile(level, tx, tz)))
            .unwrap_or(self.base_level)
    }

    /// The page table the shaders read: per tile, the finest resident
    /// page over it (`page_entry`), where `page_layers` gives each streamed
    /// page's layer among those after the base pages
    /// (`Residency::page_layers`), else its base page.
    pub fn page_table(&self, page_layers: &[u32], table: &mut [u32]) {
        let (base_across, _) = self.pages_across(self.base_level);
        for (tile, entry) in table.iter_mut().enumerate() {
            let (tx, tz) = self.tile_coords(tile);
            *entry = (0..self.page_levels())
                .find_map(|level| {
                    let layer = page_layers[self.page_of_tile(level, tx, tz)];
                    (layer != PAGE_NOT_RESIDENT)
                        .then(|| page_entry(level, self.base_pages() + layer))
                })
                .unwrap_or_else(|| {
                    let (bx, bz) = (tx >> self.base_level, tz >> self.base_level);
                    page_entry(self.base_level, bz * base_across + bx)
                });
        }
    }

    /// The height a streamed terrain draws at sample (col, row) with page
    /// table `table` (`page_table`): the level surface
    /// (`tiled::level_surface`) of the level the sample's owner tile is
    /// drawn at, where `full(row, col)` gives the full-resolution samples.
    /// Every level's samples are the whole terrain's lattice, so a page's
    /// surface is the whole level's over the page. Mirror:
    /// glsl/terrain_common.glsl `fetch_sample`.
    pub fn streamed_sample(
        &self,
        table: &[u32],
        full: impl Fn(u32, u32) -> f32,
        (col, row): (u32, u32),
    ) -> f32 {
        let (tx, tz) = self.owner(col, row);
        match entry_level(table[self.tile_index(tx, tz)]) {
            0 => full(row, col),
            level => level_surface((self.cols - 1, self.rows - 1), level, (col, row), full) as f32,
        }
    }
}

/// The page table entry of a page at `level` in pool layer `layer`.
/// Mirror: the decoding in glsl/terrain_common.glsl `fetch_sample`.
pub fn page_entry(level: u32, layer: u32) -> u32 {
    debug_assert!(layer < 1 << PAGE_LEVEL_SHIFT);
    level << PAGE_LEVEL_SHIFT | layer
}

/// The level a page table entry draws its tile at.
pub fn entry_level(entry: u32) -> u32 {
    entry >> PAGE_LEVEL_SHIFT
}

/// The pool layer a page table entry reads.
pub fn entry_layer(entry: u32) -> u32 {
    entry & ((1 << PAGE_LEVEL_SHIFT) - 1)
}

/// A page to read from disk, and the layer it will go into.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Load {
    pub page: usize,
    pub layer: u32,
}

/// The page pool's occupancy and the loads in flight.
#[derive(Clone, Debug)]
pub struct Residency {
    /// Per page: its layer, or `PAGE_NOT_RESIDENT`.
    layer_of_page: Vec<u32>,
    /// Per layer: the page drawn from it.
    page_of_layer: Vec<Option<usize>>,
    /// Per layer: the page being loaded into it.
    incoming: Vec<Option<usize>>,
    /// Per page: whether a load for it is in flight.
    loading: Vec<bool>,
    evictions: u64,
}

impl Residency {
    /// Nothing resident, for `pages` pages and a pool of `layers` layers.
    pub fn new(pages: usize, layers: u32) -> Self {
        Residency {
            layer_of_page: vec![PAGE_NOT_RESIDENT; pages],
            page_of_layer: vec![None; layers as usize],
            incoming: vec![None; layers as usize],
            loading: vec![false; pages],
            evictions: 0,
        }
    }

    /// Per page, its layer or `PAGE_NOT_RESIDENT`.
    pub fn page_layers(&self) -> &[u32] {
        &self.layer_of_page
    }

    pub fn layers(&self) -> u32 {
        self.page_of_layer.len() as u32
    }

    pub fn resident_pages(&self) -> usize {
        self.page_of_layer.iter().flatten().count()
    }

    /// The page drawn from layer `layer`, if any.
    pub fn page_in_layer(&self, layer: u32) -> Option<usize> {
        self.page_of_layer[layer as usize]
    }

    pub fn is_resident(&self, page: usize) -> bool {
        self.layer_of_page[page] != PAGE_NOT_RESIDENT
    }

    pub fn loads_in_flight(&self) -> usize {
        self.loading.iter().filter(|&&l| l).count()
    }

    /// Pages evicted since the start.
    pub fn evictions(&self) -> u64 {
        self.evictions
    }

    /// Takes this frame's priorities (one per page; 0 for a page the view
    /// does not need) and returns the loads to start, at most `max_new`,
    /// most needed first. Each load has a layer reserved: a free one, or
    /// that of the resident page with the lowest priority when the load's
    /// priority is `EVICTION_MARGIN` times that.
    pub fn plan(&mut self, priorities: &[f32], max_new: usize) -> Vec<Load> {
        assert_eq!(
            priorities.len(),
            self.layer_of_page.len(),
            "one priority a page"
        );
        let mut wanted: Vec<usize> = (0..priorities.len())
            .filter(|&p| priorities[p] > 0.0 && !self.is_resident(p) && !self.loading[p])
            .collect();
        wanted.sort_by(|&a, &b| priorities[b].total_cmp(&priorities[a]).then(a.cmp(&b)));
        // Layers that could take a load, least useful first: free ones,
        // then resident pages by priority.
        let mut open: Vec<(f32, u32)> = (0..self.layers())
            .filter(|&l| self.incoming[l as usize].is_none())
            .map(|l| {
                let useful = self.page_of_layer[l as usize].map_or(-1.0, |p| priorities[p]);
                (useful, l)
            })
            .collect();
        open.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut loads = Vec::new();
        for (page, (useful, layer)) in wanted.into_iter().zip(open) {
            if loads.len() == max_new
                || (useful >= 0.0 && priorities[page] <= EVICTION_MARGIN * useful)
            {
                break;
            }
            self.incoming[layer as usize] = Some(page);
            self.loading[page] = true;
            loads.push(Load { page, layer });
        }
        loads
    }

    /// A load finished: its page now draws from its layer, and the page
    /// that drew from there (if any, returned) is no longer resident.
    pub fn arrived(&mut self, load: Load) -> Option<usize> {
        let layer = load.layer as usize;
        assert_eq!(self.incoming[layer], Some(load.page), "a load `plan` made");
        self.incoming[layer] = None;
        self.loading[load.page] = false;
        let evicted = self.page_of_layer[layer].replace(load.page);
        if let Some(old) = evicted {
            self.layer_of_page[old] = PAGE_NOT_RESIDENT;
            self.evictions += 1;
        }
        self.layer_of_page[load.page] = load.layer;
        evicted
    }

    /// A load that failed or was dropped: its layer is free to plan again.
    pub fn cancelled(&mut self, load: Load) {
        self.incoming[load.layer as usize] = None;
        self.loading[load.page] = false;
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
    fn every_level_pages_the_tiles_and_indices_round_trip() {
        // 7 x 5 tiles of 16 cells, base level 4: pages at levels 0 to 3.
        let s = StreamShape::new(100, 70, 16, 8);
        assert_eq!(s.page_levels(), 4);
        let across: Vec<_> = (0..4).map(|l| s.pages_across(l)).collect();
        assert_eq!(across, vec![(7, 5), (4, 3), (2, 2), (1, 1)]);
        assert_eq!(s.page_total(), 35 + 12 + 4 + 1);
        for i in 0..s.page_total() {
            let (level, px, pz) = s.page_coords(i);
            assert_eq!(s.page_index(level, px, pz), i);
            let (w, h) = s.page_size(level, px, pz);
            assert!(w <= s.page_side() && h <= s.page_side(), "page {i}");
        }
        // Level 0's pages are the tiles.
        assert_eq!(s.page_of_tile(0, 4, 3), s.tile_index(4, 3));
        assert_eq!(s.tile_rect(6, 4), s.page_rect(0, 6, 4));
        // Every tile lies in one page a level, and that page covers it.
        for level in 0..4 {
            for tz in 0..5 {
                for tx in 0..7 {
                    let (_, px, pz) = s.page_coords(s.page_of_tile(level, tx, tz));
                    let (xs, zs) = s.page_tiles(level, px, pz);
                    assert!(xs.contains(&tx) && zs.contains(&tz));
                }
            }
        }
        // The last page of level 1: tile (6, 4) alone, 3 x 5 cells, every
        // other sample and the last.
        assert_eq!(s.page_tiles(1, 3, 2), (6..7, 4..5));
        assert_eq!(s.page_rect(1, 3, 2), ((96, 64), (3, 5)));
        assert_eq!(s.page_size(1, 3, 2), (3, 4));
        // Level 3's one page is the whole terrain at every 8th sample.
        assert_eq!(s.page_rect(3, 0, 0), ((0, 0), (99, 69)));
        assert_eq!(s.page_size(3, 0, 0), (14, 10));
    }

    #[test]
    fn a_sample_takes_the_finest_resident_level_over_its_owner_tile() {
        let s = StreamShape::new(100, 70, 16, 8);
        let full = |r: u32, c: u32| ((r * 7 + c * 13) % 11) as f32 + 0.25 * (c % 3) as f32;
        let cells = (99, 69);
        // Tile (1, 0) at full resolution in layer 5, the level-2 page over
        // tiles (0..4, 0..4) in layer 2, nothing else: the rest is the
        // base level's.
        let mut layers = vec![PAGE_NOT_RESIDENT; s.page_total()];
        layers[s.tile_index(1, 0)] = 5;
        layers[s.page_index(2, 0, 0)] = 2;
        let is_resident = |p: usize| layers[p] != PAGE_NOT_RESIDENT;
        assert_eq!(s.drawn_level(is_resident, (1, 0)), 0);
        assert_eq!(s.drawn_level(is_resident, (3, 3)), 2);
        assert_eq!(s.drawn_level(is_resident, (5, 4)), 4);
        let mut table = vec![0; s.tile_total()];
        s.page_table(&layers, &mut table);
        // One base page (level 4 is one page here) in layer 0 first.
        assert_eq!(s.base_pages(), 1);
        assert_eq!(table[s.tile_index(1, 0)], 6);
        assert_eq!(table[s.tile_index(3, 3)], 2 << PAGE_LEVEL_SHIFT | 3);
        assert_eq!(table[s.tile_index(5, 4)], 4 << PAGE_LEVEL_SHIFT);
        assert_eq!(
            (
                entry_level(table[s.tile_index(3, 3)]),
                entry_layer(table[s.tile_index(3, 3)])
            ),
            (2, 3)
        );
        for (t, &entry) in table.iter().enumerate() {
            let level = entry_level(entry);
            assert_eq!(level, s.drawn_level(is_resident, s.tile_coords(t)));
        }
        let level = |l: u32, c: u32, r: u32| level_surface(cells, l, (c, r), full) as f32;
        let drawn = |c: u32, r: u32| s.streamed_sample(&table, full, (c, r));
        assert_eq!(drawn(20, 3), full(3, 20));
        assert_eq!(drawn(5, 5), level(2, 5, 5));
        assert_ne!(drawn(5, 5), full(5, 5), "the test's surface is rough");
        assert_eq!(drawn(90, 67), level(4, 90, 67));
        // Column 16 is the border of tiles 0 and 1: it belongs to tile 0,
        // drawn at level 2 whichever tile's cell reads it.
        assert_eq!(drawn(16, 3), level(2, 16, 3));
        assert_ne!(drawn(16, 3), full(3, 16));
        // Column 17 is tile 1's: full resolution.
        assert_eq!(drawn(17, 3), full(3, 17));
        // The terrain's last row and column are a lattice's last samples.
        assert_eq!(drawn(99, 69), full(69, 99));
    }

    #[test]
    fn loads_go_by_priority_and_evict_only_clearly_less_needed_pages() {
        let mut r = Residency::new(5, 2);
        let loads = r.plan(&[1.0, 5.0, 0.0, 3.0, 2.0], 8);
        assert_eq!(
            loads,
            vec![Load { page: 1, layer: 0 }, Load { page: 3, layer: 1 }]
        );
        // Nothing changes until they arrive; nothing else is planned
        // while every layer has a load coming.
        assert!(r.plan(&[1.0, 5.0, 0.0, 3.0, 2.0], 8).is_empty());
        for l in loads {
            assert_eq!(r.arrived(l), None);
        }
        assert_eq!(
            r.page_layers(),
            &[
                PAGE_NOT_RESIDENT,
                0,
                PAGE_NOT_RESIDENT,
                1,
                PAGE_NOT_RESIDENT
            ]
        );
        // Page 4 at 4 px is not 1.5x page 3's 3 px: no swap.
        assert!(r.plan(&[1.0, 5.0, 0.0, 3.0, 4.0], 8).is_empty());
        // At 5 px it is, and it takes tile 3's layer when it arrives.
        let loads = r.plan(&[1.0, 6.0, 0.0, 3.0, 5.0], 8);
        assert_eq!(loads, vec![Load { page: 4, layer: 1 }]);
        assert!(
            r.is_resident(3),
            "an evicted page draws until its successor arrives"
        );
        assert_eq!(r.arrived(loads[0]), Some(3));
        assert!(!r.is_resident(3) && r.is_resident(4));
        assert_eq!(r.evictions(), 1);
        // A cancelled load frees its layer for the next plan.
        let loads = r.plan(&[0.0, 0.0, 9.0, 0.0, 0.0], 1);
        assert_eq!(loads, vec![Load { page: 2, layer: 0 }]);
        r.cancelled(loads[0]);
        assert_eq!(r.plan(&[0.0, 0.0, 9.0, 0.0, 0.0], 1), loads);
    }
}
