//! Tiled terrains on disk: a heightmap cut into square tiles, each stored
//! with a pyramid of coarser levels, so that a terrain larger than memory
//! can be opened and read a tile at a time.
//!
//! `vkterrain import` writes one (`import`), and every `--heightmap` opens
//! one, recognised by its header (`TiledHeightmap::is_tiled`).
//!
//! # Layout (version 4, little-endian throughout)
//!
//! ```text
//! header      HEADER_BYTES bytes at offset 0 (`Header`)
//! tile data   the encoded samples of every tile level, in any order
//! directory   one ENTRY_BYTES entry per tile level (`Entry`), tile rows
//!             top to bottom, tiles left to right, levels finest first
//! tables      optional: the error tables of one patch size (`ErrorTable`),
//!             the tess path's then the geomip path's, then each patch's
//!             Y bounds (min, max), patches row-major
//! ```
//!
//! **Tiles.** With `T` cells per tile, tile (tx, tz) covers sample columns
//! `tx * T ..= min((tx + 1) * T, width - 1)` and the matching rows: a tile
//! holds its shared border samples, so each is complete on its own, and
//! the last tile of a row or column is narrower when `width - 1` is not a
//! multiple of `T`. Level `l` keeps every `2^l`-th sample of the tile, and
//! the tile's last column and row whatever their index, so every level has
//! the tile's corners and `ceil(cells / 2^l) + 1` samples a side. The
//! coarsest level (`l = log2 T`) is a tile's corners.
//!
//! **Samples.** A tile level is stored either as 32-bit floats, or, where
//! that is exact, as 16-bit codes `q` with heights
//! `h = scale * ((base + q) / divisor) + offset`, rounded once from f64 to
//! f32: the integer loaders' own mapping (`Heightmap::load`), so an integer
//! heightmap imports losslessly in half the space. Every sample is checked
//! at import; a level whose heights the codes cannot reproduce bit for bit
//! is stored as floats. Heights read back are therefore exactly the heights
//! imported.
//!
//! **Error tables.** Building a terrain's error tables reads every sample
//! and takes seconds on a large map, so the importer stores them for one
//! patch size (`--cells-per-patch`, when tiles are a whole number of
//! patches), computed on the same samples as `ErrorTable::compute_pair`
//! would at load, with each patch's Y bounds: a terrain loaded with that
//! patch size starts without rebuilding them, and a streamed one has its
//! CPU model without reading every tile.
//!
//! **Integrity.** The header carries a magic number, a format version and
//! a CRC-32 of itself; the directory, the tables and every tile level carry
//! their own CRC-32. A reader checks the header and directory when it opens a file
//! and each tile level when it reads it, and names the tile in any error.

mod format;
mod import;
mod reader;

pub use import::{import, open_source, ImportReport, MemoryRows, RowSource, SourceKind};
pub use reader::{
    check_tiled_options, fuzz_open, fuzz_open_resealed, load_whole, StoredTables, TileLevel,
    TiledHeightmap, DEFAULT_CACHE_BYTES,
};

pub use crate::terrain::error::TiledError;
pub use format::{
    level_count, level_error, level_sample, level_side, level_surface, tile_count,
    validate_tile_cells, Encoding, Entry, Header, IntegerMapping, TablesAt, DEFAULT_TILE_CELLS,
    ENTRY_BYTES, HEADER_BYTES, MAGIC, MAX_SIDE, MAX_TILE_CELLS, MIN_TILE_CELLS, VERSION,
};
