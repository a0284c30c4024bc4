//! Reading a tiled terrain: the header and directory when it is opened,
//! tile levels on demand through a bounded cache.

use std::collections::HashMap;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use super::format::{Encoding, Entry, Header, ENTRY_BYTES, HEADER_BYTES, MAGIC};
use crate::terrain::error::{HeightmapError, TiledError};
use crate::terrain::heightmap::{blend_cell, locate_cell, Heightmap, LoadOptions};
use crate::terrain::ErrorTable;

/// Decoded tile levels a reader keeps by default: 64 MiB, 256 full tiles
/// of 257^2 samples.
pub const DEFAULT_CACHE_BYTES: usize = 64 << 20;

/// Error tables as stored: (cells per patch, tess table, geomip table).
/// What a tiled terrain stores for one patch size: the error tables and
/// each patch's Y bounds, as a terrain of that size computes them.
#[derive(Clone, Debug, PartialEq)]
pub struct StoredTables {
    pub cells_per_patch: u32,
    pub tess: ErrorTable,
    pub geomip: ErrorTable,
    /// `[min, max]` height per patch, row-major.
    pub y_bounds: Vec<[f32; 2]>,
}

/// What a reader reads from: a file, or bytes in memory (tests, fuzzing).
trait Source: Read + Seek + Send {}
impl<T: Read + Seek + Send> Source for T {}

/// One tile level's heights, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct TileLevel {
    pub cols: u32,
    pub rows: u32,
    pub heights: Vec<f32>,
}

impl TileLevel {
    #[inline]
    pub fn get(&self, row: u32, col: u32) -> f32 {
        self.heights[row as usize * self.cols as usize + col as usize]
    }
}

/// Tile levels read recently, least recently used first out.
struct Cache {
    budget: usize,
    bytes: usize,
    tick: u64,
    levels: HashMap<(u32, u32, u32), (u64, Arc<TileLevel>)>,
}

impl Cache {
    fn get(&mut self, key: (u32, u32, u32)) -> Option<Arc<TileLevel>> {
        self.tick += 1;
        let tick = self.tick;
        self.levels.get_mut(&key).map(|(used, level)| {
            *used = tick;
            Arc::clone(level)
        })
    }

    fn insert(&mut self, key: (u32, u32, u32), level: Arc<TileLevel>) {
        let size = level.heights.len() * 4;
        while self.bytes + size > self.budget && !self.levels.is_empty() {
            let oldest = *self
                .levels
                .iter()
                .min_by_key(|(_, (used, _))| *used)
                .map(|(k, _)| k)
                .expect("not empty");
            let (_, gone) = self.levels.remove(&oldest).expect("present");
            self.bytes -= gone.heights.len() * 4;
        }
        if size <= self.budget {
            self.tick += 1;
            self.bytes += size;
            self.levels.insert(key, (self.tick, level));
        }
    }
}

/// An open tiled terrain. Its header and directory are in memory; tile
/// levels are read when asked for and kept in a cache of bounded size.
pub struct TiledHeightmap {
    path: PathBuf,
    header: Header,
    entries: Vec<Entry>,
    source: Mutex<Box<dyn Source>>,
    cache: Mutex<Cache>,
}

impl std::fmt::Debug for TiledHeightmap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TiledHeightmap")
            .field("path", &self.path)
            .field("header", &self.header)
            .finish_non_exhaustive()
    }
}

impl TiledHeightmap {
    /// Whether `path` starts with a tiled terrain's magic number. False for
    /// files that cannot be read: the loader that takes them reports why.
    pub fn is_tiled(path: &Path) -> bool {
        let mut magic = [0u8; 8];
        std::fs::File::open(path)
            .and_then(|mut f| f.read_exact(&mut magic))
            .is_ok_and(|()| magic == MAGIC)
    }

    /// The patch size whose error tables the tiled terrain at `path`
    /// stores, read from its header alone. None for a terrain that stores
    /// none, and for a file that is not a readable tiled terrain (opening
    /// it reports why).
    pub fn stored_patch_size(path: &Path) -> Option<u32> {
        let mut file = std::fs::File::open(path).ok()?;
        let len = file.metadata().ok()?.len();
        let mut b = [0u8; HEADER_BYTES];
        file.read_exact(&mut b).ok()?;
        let header = Header::decode(&b, len, path).ok()?;
        header.tables.map(|t| t.cells_per_patch)
    }

    /// Opens a tiled terrain, checking its header and directory.
    pub fn open(path: &Path) -> Result<Self, TiledError> {
        let io = |source| TiledError::io(path, source);
        let file = std::fs::File::open(path).map_err(io)?;
        let len = file.metadata().map_err(io)?.len();
        Self::from_source(Box::new(std::io::BufReader::new(file)), len, path)
    }

    /// Reads a tiled terrain from bytes in memory; `path` only names it in
    /// errors.
    pub fn from_bytes(bytes: Vec<u8>, path: &Path) -> Result<Self, TiledError> {
        let len = bytes.len() as u64;
        Self::from_source(Box::new(std::io::Cursor::new(bytes)), len, path)
    }

    fn from_source(mut source: Box<dyn Source>, len: u64, path: &Path) -> Result<Self, TiledError> {
        let io = |source| TiledError::io(path, source);
        let mut head = vec![0u8; HEADER_BYTES.min(len as usize)];
        source.read_exact(&mut head).map_err(io)?;
        let header = Header::decode(&head, len, path)?;
        let directory_bytes =
            usize::try_from(header.directory_bytes()).map_err(|_| TiledError::Directory {
                path: path.to_path_buf(),
                what: "too large for this machine".into(),
            })?;
        let mut directory = vec![0u8; directory_bytes];
        source
            .seek(SeekFrom::Start(header.directory_offset))
            .map_err(io)?;
        source.read_exact(&mut directory).map_err(io)?;
        if crc32fast::hash(&directory) != header.directory_crc {
            return Err(TiledError::Directory {
                path: path.to_path_buf(),
                what: "checksum mismatch".into(),
            });
        }
        let (tiles_x, tiles_z) = header.tiles();
        let mut entries = Vec::with_capacity(header.entry_count() as usize);
        for tz in 0..tiles_z {
            for tx in 0..tiles_x {
                for level in 0..header.levels {
                    let i = header.entry_index(tx, tz, level);
                    let bad = |what: String| TiledError::Tile {
                        path: path.to_path_buf(),
                        tx,
                        tz,
                        level,
                        what,
                    };
                    let entry = Entry::decode(&directory[i * ENTRY_BYTES..(i + 1) * ENTRY_BYTES])
                        .map_err(bad)?;
                    let (cols, rows) = header.level_size(tx, tz, level);
                    let expected =
                        u64::from(cols) * u64::from(rows) * entry.encoding.sample_bytes();
                    if u64::from(entry.bytes) != expected {
                        return Err(bad(format!(
                            "{} bytes stored, but {cols}x{rows} samples need {expected}",
                            entry.bytes
                        )));
                    }
                    let end = entry.offset.checked_add(u64::from(entry.bytes));
                    if entry.offset < HEADER_BYTES as u64
                        || !end.is_some_and(|end| end <= header.directory_offset)
                    {
                        return Err(bad(format!(
                            "its {} bytes at offset {} lie outside the tile data (bytes {HEADER_BYTES} to {})",
                            entry.bytes, entry.offset, header.directory_offset
                        )));
                    }
                    entries.push(entry);
                }
            }
        }
        Ok(TiledHeightmap {
            path: path.to_path_buf(),
            header,
            entries,
            source: Mutex::new(source),
            cache: Mutex::new(Cache {
                budget: DEFAULT_CACHE_BYTES,
                bytes: 0,
                tick: 0,
                levels: HashMap::new(),
            }),
        })
    }

    /// Keeps at most `bytes` of decoded tile levels.
    pub fn with_cache_bytes(self, bytes: usize) -> Self {
        self.cache.lock().expect("cache lock").budget = bytes;
        self
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn header(&self) -> &Header {
        &self.header
    }

    /// Sample columns.
    pub fn width(&self) -> usize {
        self.header.width as usize
    }

    /// Sample rows.
    pub fn depth(&self) -> usize {
        self.header.depth as usize
    }

    /// Smallest and largest height of the whole terrain.
    pub fn min_max(&self) -> (f32, f32) {
        (self.header.min_height, self.header.max_height)
    }

    /// The directory entry of a tile level.
    pub fn entry(&self, tx: u32, tz: u32, level: u32) -> &Entry {
        &self.entries[self.header.entry_index(tx, tz, level)]
    }

    /// Bytes of decoded tile levels the cache holds now.
    pub fn cached_bytes(&self) -> usize {
        self.cache.lock().expect("cache lock").bytes
    }

    /// `len` bytes of the file from `offset` (which the header or the
    /// directory placed inside it).
    fn read_at(&self, offset: u64, len: usize) -> std::io::Result<Vec<u8>> {
        let mut bytes = vec![0u8; len];
        let mut source = self.source.lock().expect("source lock");
        source.seek(SeekFrom::Start(offset))?;
        source.read_exact(&mut bytes)?;
        Ok(bytes)
    }

    /// Tile (tx, tz) at `level`, read and checked on first use.
    pub fn tile(&self, tx: u32, tz: u32, level: u32) -> Result<Arc<TileLevel>, TiledError> {
        let key = (tx, tz, level);
        if let Some(level) = self.cache.lock().expect("cache lock").get(key) {
            return Ok(level);
        }
        let decoded = Arc::new(self.read_uncached(tx, tz, level)?);
        self.cache
            .lock()
            .expect("cache lock")
            .insert(key, Arc::clone(&decoded));
        Ok(decoded)
    }

    /// Tile (tx, tz) at `level`, read and checked now, past the cache and
    /// not kept in it: for readers that hold what they read elsewhere (the
    /// GPU's tile pool and base level).
    pub fn read_uncached(&self, tx: u32, tz: u32, level: u32) -> Result<TileLevel, TiledError> {
        let (tiles_x, tiles_z) = self.header.tiles();
        assert!(
            tx < tiles_x && tz < tiles_z && level < self.header.levels,
            "tile ({tx}, {tz}) level {level} out of range"
        );
        let bad = |what: String| TiledError::Tile {
            path: self.path.clone(),
            tx,
            tz,
            level,
            what,
        };
        let entry = *self.entry(tx, tz, level);
        let bytes = self
            .read_at(entry.offset, entry.bytes as usize)
            .map_err(|e| bad(format!("cannot read its samples: {e}")))?;
        if crc32fast::hash(&bytes) != entry.crc {
            return Err(bad("checksum mismatch in its samples".into()));
        }
        let heights: Vec<f32> = match entry.encoding {
            Encoding::F32 => bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
            Encoding::Codes { base, mapping } => bytes
                .chunks_exact(2)
                .map(|b| {
                    mapping.height(i64::from(base) + i64::from(u16::from_le_bytes([b[0], b[1]])))
                })
                .collect(),
        };
        let (cols, rows) = self.header.level_size(tx, tz, level);
        for (i, &h) in heights.iter().enumerate() {
            let (r, c) = (i / cols as usize, i % cols as usize);
            if !h.is_finite() {
                return Err(bad(format!(
                    "sample at row {r}, column {c} is {h}, not a finite number"
                )));
            }
            if h < entry.min || h > entry.max {
                return Err(bad(format!(
                    "sample at row {r}, column {c} is {h}, outside the range {}..{} its directory entry gives",
                    entry.min, entry.max
                )));
            }
        }
        Ok(TileLevel {
            cols,
            rows,
            heights,
        })
    }

    /// The tile holding the cell whose upper-left sample is (row, col), and
    /// that sample's place in it. A sample on a border between tiles is in
    /// both; the one with the sample as its upper-left side is chosen.
    fn locate(&self, row: usize, col: usize) -> (u32, u32, u32, u32) {
        let t = self.header.tile_cells as usize;
        let (tiles_x, tiles_z) = self.header.tiles();
        let tx = ((col / t) as u32).min(tiles_x - 1);
        let tz = ((row / t) as u32).min(tiles_z - 1);
        (
            tx,
            tz,
            (row - tz as usize * t) as u32,
            (col - tx as usize * t) as u32,
        )
    }

    /// The sample at (row, col), at full resolution.
    pub fn get(&self, row: usize, col: usize) -> Result<f32, TiledError> {
        assert!(
            row < self.depth() && col < self.width(),
            "sample ({row}, {col}) out of range"
        );
        let (tx, tz, r, c) = self.locate(row, col);
        Ok(self.tile(tx, tz, 0)?.get(r, c))
    }

    /// Height at continuous sample coordinates (`col`, `row`) on the
    /// triangulated surface, clamped to the grid: the same arithmetic as
    /// `Heightmap::interpolate`, on the full-resolution tile holding the
    /// cell.
    pub fn interpolate(&self, col: f64, row: f64) -> Result<f64, TiledError> {
        let cell = locate_cell(self.width(), self.depth(), col, row);
        let (tx, tz, r, c) = self.locate(cell.row, cell.col);
        let tile = self.tile(tx, tz, 0)?;
        Ok(blend_cell(
            &cell,
            [
                tile.get(r, c),
                tile.get(r, c + 1),
                tile.get(r + 1, c),
                tile.get(r + 1, c + 1),
            ],
        ))
    }

    /// The error tables stored at import, with the patch size they are
    /// for: (cells per patch, the tess path's table, the geomip path's).
    pub fn error_tables(&self) -> Result<Option<StoredTables>, TiledError> {
        let Some(at) = self.header.tables else {
            return Ok(None);
        };
        let bad = |what: String| TiledError::Tables {
            path: self.path.clone(),
            what,
        };
        let bytes = self
            .read_at(
                at.offset,
                self.header.tables_bytes(at.cells_per_patch) as usize,
            )
            .map_err(|e| bad(format!("cannot read them: {e}")))?;
        if crc32fast::hash(&bytes) != at.crc {
            return Err(bad("checksum mismatch".into()));
        }
        let mut errors: Vec<f32> = bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let patches = errors.len() / (2 * ErrorTable::LEVELS + 2);
        let bounds = errors.split_off(2 * patches * ErrorTable::LEVELS);
        let geomip = errors.split_off(errors.len() / 2);
        let y_bounds: Vec<[f32; 2]> = bounds.chunks_exact(2).map(|b| [b[0], b[1]]).collect();
        if let Some(p) = y_bounds
            .iter()
            .position(|b| !(b[0].is_finite() && b[1].is_finite() && b[0] <= b[1]))
        {
            return Err(bad(format!(
                "patch {p}'s Y bounds {:?} are not a finite range",
                y_bounds[p]
            )));
        }
        match (ErrorTable::from_flat(errors), ErrorTable::from_flat(geomip)) {
            (Some(tess), Some(geomip)) => Ok(Some(StoredTables {
                cells_per_patch: at.cells_per_patch,
                tess,
                geomip,
                y_bounds,
            })),
            _ => Err(bad("an error is negative or not a finite number".into())),
        }
    }

    /// Height of the surface at world (x, z) with the samples placed by
    /// `placement` (which must be this terrain's size), or None outside the
    /// terrain: `TerrainInfo::height_at`, reading only the tile it needs.
    pub fn height_at(
        &self,
        placement: &crate::terrain::Placement,
        x: f64,
        z: f64,
    ) -> Result<Option<f32>, TiledError> {
        debug_assert_eq!(
            (placement.cols(), placement.rows()),
            (self.width(), self.depth())
        );
        match placement.grid_on_terrain(x, z) {
            Some(g) => Ok(Some(self.interpolate(g.x, g.y)? as f32)),
            None => Ok(None),
        }
    }

    /// Min and max height over every sample each patch of `grid` covers
    /// (borders included), row-major: `grid::patch_y_bounds` with no margin,
    /// reading each full-resolution tile once.
    pub fn patch_y_bounds(
        &self,
        grid: &crate::terrain::PatchGrid,
    ) -> Result<Vec<[f32; 2]>, TiledError> {
        let mut bounds = vec![[f32::INFINITY, f32::NEG_INFINITY]; grid.patch_count()];
        let (tiles_x, tiles_z) = self.header.tiles();
        let n = grid.cells_per_patch();
        for tz in 0..tiles_z {
            for tx in 0..tiles_x {
                let tile = self.read_uncached(tx, tz, 0)?;
                let [c0, c1, r0, r1] = self.header.tile_rect(tx, tz).map(|v| v as usize);
                // Patches whose samples meet the tile's: a patch ending on
                // the tile's first row or column shares that border.
                let (pr0, pr1) = (
                    r0.saturating_sub(1) / n,
                    (r1 / n).min(grid.patch_rows() - 1),
                );
                let (pc0, pc1) = (
                    c0.saturating_sub(1) / n,
                    (c1 / n).min(grid.patch_cols() - 1),
                );
                for pr in pr0..=pr1 {
                    for pc in pc0..=pc1 {
                        let id = crate::terrain::PatchId { row: pr, col: pc };
                        let rect = grid.sample_rect(id);
                        let (ra, rb) = (rect.row0.max(r0), rect.row1.min(r1));
                        let (ca, cb) = (rect.col0.max(c0), rect.col1.min(c1));
                        if ra > rb || ca > cb {
                            continue;
                        }
                        let b = &mut bounds[grid.patch_index(id)];
                        for r in ra..=rb {
                            let start = (r - r0) * tile.cols as usize;
                            let row = &tile.heights[start + ca - c0..=start + cb - c0];
                            let (lo, hi) = crate::terrain::heightmap::min_max_of(row);
                            b[0] = b[0].min(lo);
                            b[1] = b[1].max(hi);
                        }
                    }
                }
            }
        }
        Ok(bounds)
    }

    /// The whole terrain as one heightmap, refused when it has more than
    /// `max_samples` samples.
    pub fn to_heightmap(&self, max_samples: u64) -> Result<Heightmap, TiledError> {
        let (w, d) = (self.width(), self.depth());
        let samples = w as u64 * d as u64;
        if samples > max_samples {
            return Err(TiledError::TooLarge {
                path: self.path.clone(),
                width: w as u64,
                depth: d as u64,
                samples,
                limit: max_samples,
            });
        }
        let mut heights = vec![0.0f32; w * d];
        let (tiles_x, tiles_z) = self.header.tiles();
        for tz in 0..tiles_z {
            for tx in 0..tiles_x {
                // Read around the cache: a whole load would only churn it.
                let tile = self.read_uncached(tx, tz, 0)?;
                let [c0, _, r0, _] = self.header.tile_rect(tx, tz);
                for (r, row) in tile.heights.chunks_exact(tile.cols as usize).enumerate() {
                    let start = (r0 as usize + r) * w + c0 as usize;
                    heights[start..start + row.len()].copy_from_slice(row);
                }
            }
        }
        Heightmap::from_heights(w, d, heights).map_err(|e| TiledError::Input {
            path: self.path.clone(),
            what: e.to_string(),
        })
    }
}

/// Opens `data` as a tiled terrain and reads every tile level and a few
/// heights from it; true when all of that succeeded. Never panics on any
/// input: the fuzz target and its regression test call it.
pub fn fuzz_open(data: &[u8]) -> bool {
    let Ok(map) = TiledHeightmap::from_bytes(data.to_vec(), Path::new("fuzz-input")) else {
        return false;
    };
    if map.error_tables().is_err() {
        return false;
    }
    let (tiles_x, tiles_z) = map.header().tiles();
    // A valid file this small has few tiles; the cap keeps a fuzzer's
    // header from asking for billions of reads.
    if u64::from(tiles_x) * u64::from(tiles_z) > 4096 {
        return false;
    }
    for tz in 0..tiles_z {
        for tx in 0..tiles_x {
            for level in 0..map.header().levels {
                if map.tile(tx, tz, level).is_err() {
                    return false;
                }
            }
        }
    }
    let (w, d) = (map.width() as f64, map.depth() as f64);
    [
        (0.0, 0.0),
        (w - 1.0, d - 1.0),
        (0.5 * w, 0.3 * d),
        (-5.0, 1e9),
    ]
    .iter()
    .all(|&(c, r)| map.interpolate(c, r).is_ok())
}

/// `fuzz_open` on `data` with its checksums first made to match (the
/// header's, the directory's, and each tile level's whose bytes lie in the
/// input), so that a fuzzer's mutations reach the checks behind them:
/// sizes, offsets, encodings and samples.
pub fn fuzz_open_resealed(data: &[u8]) -> bool {
    let mut b = data.to_vec();
    if b.len() >= HEADER_BYTES && b[..8] == MAGIC {
        let crc_at = HEADER_BYTES - 4;
        let crc = crc32fast::hash(&b[..crc_at]);
        b[crc_at..HEADER_BYTES].copy_from_slice(&crc.to_le_bytes());
        if let Ok(mut header) = Header::decode(&b, b.len() as u64, Path::new("fuzz-input")) {
            if let Some(mut t) = header.tables {
                let start = t.offset as usize;
                let end = start + header.tables_bytes(t.cells_per_patch) as usize;
                t.crc = crc32fast::hash(&b[start..end]);
                header.tables = Some(t);
            }
            let start = header.directory_offset as usize;
            let end = start + header.directory_bytes() as usize;
            for at in (start..end).step_by(ENTRY_BYTES) {
                let field = |i: usize, n: usize| {
                    b[at + i..at + i + n]
                        .iter()
                        .rev()
                        .fold(0u64, |v, &x| (v << 8) | u64::from(x))
                };
                let (offset, bytes) = (field(0, 8), field(8, 4));
                if let Some(stored) = offset
                    .checked_add(bytes)
                    .filter(|&e| e <= b.len() as u64)
                    .map(|e| offset as usize..e as usize)
                {
                    let crc = crc32fast::hash(&b[stored]);
                    b[at + 24..at + 28].copy_from_slice(&crc.to_le_bytes());
                }
            }
            header.directory_crc = crc32fast::hash(&b[start..end]);
            b[..HEADER_BYTES].copy_from_slice(&header.encode());
        }
    }
    fuzz_open(&b)
}
/// Refuses the load options that would change a tiled terrain's heights:
/// they were fixed by `vkterrain import`.
pub fn check_tiled_options(path: &Path, opts: &LoadOptions) -> Result<(), HeightmapError> {
    let defaults = LoadOptions::default();
    let refused = [
        (opts.format.is_some(), "a format"),
        (opts.size.is_some(), "a size"),
        (opts.height_scale != defaults.height_scale, "a height scale"),
        (
            opts.height_offset != defaults.height_offset,
            "a height offset",
        ),
        (opts.luminance, "luminance conversion"),
    ];
    if let Some((_, what)) = refused.iter().find(|(given, _)| *given) {
        return Err(HeightmapError::TiledOption {
            path: path.to_path_buf(),
            option: what,
        });
    }
    Ok(())
}

/// A tiled terrain read whole into memory, within `opts.max_samples`; the
/// options that would change its heights are refused
/// (`check_tiled_options`), not ignored.
pub fn load_whole(path: &Path, opts: &LoadOptions) -> Result<Heightmap, HeightmapError> {
    check_tiled_options(path, opts)?;
    let map = TiledHeightmap::open(path)?.to_heightmap(opts.max_samples)?;
    Ok(if opts.smooth { map.smoothed() } else { map })
}
