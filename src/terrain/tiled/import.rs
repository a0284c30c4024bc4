//! Writing a tiled terrain from a heightmap read row by row.
//!
//! The importer holds one band of `T + 2` sample rows (a row of tiles, the
//! border row it shares with the next, and the row after that, which the
//! error tables read), never the whole terrain: raw
//! files and non-interlaced grayscale PNGs are read a row at a time, and a
//! mosaic of SRTM tiles one row of `.hgt` files at a time. Other inputs
//! (a single `.hgt`, an interlaced or colour PNG) are loaded whole by the
//! heightmap loaders first, under their sample limit.

use std::collections::BTreeMap;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;

use super::format::{
    level_count, level_error, level_sample, level_side, validate_tile_cells, Encoding, Entry,
    Header, IntegerMapping, TablesAt, HEADER_BYTES, MAX_SIDE,
};
use super::reader::{load_whole, TiledHeightmap};
use crate::terrain::error::TiledError;
use crate::terrain::heightmap::{
    check_finite, decode_raw_rows, headerless_shape, Heightmap, HeightmapFormat, LoadOptions,
};
use crate::terrain::{ErrorTable, PatchGrid};

/// A heightmap read one row at a time, top to bottom.
pub trait RowSource {
    fn width(&self) -> usize;
    fn depth(&self) -> usize;
    /// Reads the next row's heights into `out` (`width` of them).
    fn read_row(&mut self, out: &mut [f32]) -> Result<(), TiledError>;
    /// The integer mapping the heights came through, if any: levels whose
    /// heights it reproduces are stored as 16-bit codes.
    fn mapping(&self) -> Option<IntegerMapping>;
}

/// How an input is read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SourceKind {
    /// A row at a time from the file.
    Streamed,
    /// Loaded whole by the heightmap loaders.
    Whole,
    /// A mosaic of SRTM tiles, one row of tiles at a time.
    SrtmMosaic,
}

/// A heightmap already in memory, read row by row.
pub struct MemoryRows {
    map: Heightmap,
    next: usize,
    mapping: Option<IntegerMapping>,
}

impl MemoryRows {
    pub fn new(map: Heightmap, mapping: Option<IntegerMapping>) -> Self {
        MemoryRows {
            map,
            next: 0,
            mapping,
        }
    }
}

impl RowSource for MemoryRows {
    fn width(&self) -> usize {
        self.map.width()
    }
    fn depth(&self) -> usize {
        self.map.depth()
    }
    fn read_row(&mut self, out: &mut [f32]) -> Result<(), TiledError> {
        out.copy_from_slice(self.map.row(self.next));
        self.next += 1;
        Ok(())
    }
    fn mapping(&self) -> Option<IntegerMapping> {
        self.mapping
    }
}

/// A headerless file (raw8, raw16, raw16be, f32) read a row at a time.
struct RawRows {
    path: PathBuf,
    reader: BufReader<std::fs::File>,
    format: HeightmapFormat,
    width: usize,
    depth: usize,
    row: usize,
    bytes: Vec<u8>,
    opts: LoadOptions,
}

impl RowSource for RawRows {
    fn width(&self) -> usize {
        self.width
    }
    fn depth(&self) -> usize {
        self.depth
    }
    fn read_row(&mut self, out: &mut [f32]) -> Result<(), TiledError> {
        self.reader
            .read_exact(&mut self.bytes)
            .map_err(|source| TiledError::io(&self.path, source))?;
        let (path, width, row) = (self.path.as_path(), self.width, self.row);
        let heights = decode_raw_rows(&self.bytes, self.format, width, row, &self.opts, path)
            .and_then(|h| check_finite(path, width, row, &h).map(|()| h))
            .map_err(|e| TiledError::Load(Box::new(e)))?;
        out.copy_from_slice(&heights);
        self.row += 1;
        Ok(())
    }
    fn mapping(&self) -> Option<IntegerMapping> {
        self.format
            .integer_max()
            .map(|max| IntegerMapping::of(max, &self.opts))
    }
}

/// A non-interlaced 8- or 16-bit grayscale PNG read a row at a time.
struct PngRows {
    path: PathBuf,
    reader: png::Reader<BufReader<std::fs::File>>,
    sixteen: bool,
    width: usize,
    depth: usize,
    mapping: IntegerMapping,
}

impl RowSource for PngRows {
    fn width(&self) -> usize {
        self.width
    }
    fn depth(&self) -> usize {
        self.depth
    }
    fn read_row(&mut self, out: &mut [f32]) -> Result<(), TiledError> {
        let path = &self.path;
        let bad = |what: String| TiledError::Input {
            path: path.clone(),
            what,
        };
        let row = self
            .reader
            .next_row()
            .map_err(|e| bad(format!("not a valid PNG: {e}")))?
            .ok_or_else(|| bad("the PNG ends before its last row".into()))?;
        let data = row.data();
        let m = self.mapping;
        if self.sixteen {
            for (o, b) in out.iter_mut().zip(data.chunks_exact(2)) {
                *o = m.height(i64::from(u16::from_be_bytes([b[0], b[1]])));
            }
        } else {
            for (o, &v) in out.iter_mut().zip(data) {
                *o = m.height(i64::from(v));
            }
        }
        Ok(())
    }
    fn mapping(&self) -> Option<IntegerMapping> {
        Some(self.mapping)
    }
}

/// Opens a PNG for row reading; None where it must be loaded whole
/// (interlaced, colour, or a bit depth the loader rejects with a reason).
fn png_rows(path: &Path, opts: &LoadOptions) -> Result<Option<PngRows>, TiledError> {
    let io = |source| TiledError::io(path, source);
    let file = std::fs::File::open(path).map_err(io)?;
    let mut decoder =
        png::Decoder::new_with_limits(BufReader::new(file), png::Limits { bytes: usize::MAX });
    decoder.set_transformations(png::Transformations::IDENTITY);
    let Ok(reader) = decoder.read_info() else {
        // Not a readable PNG: the loader gives the reason.
        return Ok(None);
    };
    let info = reader.info();
    let sixteen = match info.bit_depth {
        png::BitDepth::Eight => false,
        png::BitDepth::Sixteen => true,
        _ => return Ok(None),
    };
    if info.interlaced || info.color_type != png::ColorType::Grayscale {
        return Ok(None);
    }
    let (width, depth) = (info.width as usize, info.height as usize);
    Ok(Some(PngRows {
        path: path.to_path_buf(),
        reader,
        sixteen,
        width,
        depth,
        mapping: IntegerMapping::of(if sixteen { 65535.0 } else { 255.0 }, opts),
    }))
}

/// SRTM tiles named by their south-west corner (N37W119.hgt), mosaicked
/// north to south and west to east. Tiles share their border samples.
/// Each tile's voids are filled as the `.hgt` loader fills them (from the
/// tile's own samples); a tile missing from the rectangle the names span
/// is sea level (height of code 0).
struct SrtmMosaic {
    /// (south edge latitude, west edge longitude) -> file.
    tiles: BTreeMap<(i32, i32), PathBuf>,
    /// Samples along a tile side (1201 or 3601).
    n: usize,
    lat_max: i32,
    lon_min: i32,
    lat_count: usize,
    lon_count: usize,
    row: usize,
    /// The loaded row of tiles, west to east, and which band it is.
    band: Option<(usize, Vec<Option<Heightmap>>)>,
    opts: LoadOptions,
}

/// Latitude and longitude of a `.hgt` name's south-west corner.
fn parse_srtm_name(path: &Path) -> Option<(i32, i32)> {
    let stem = path.file_stem()?.to_str()?.to_ascii_uppercase();
    let b = stem.as_bytes();
    if b.len() != 7 || !b[1..3].iter().chain(&b[4..7]).all(u8::is_ascii_digit) {
        return None;
    }
    let lat: i32 = stem[1..3].parse().ok()?;
    let lon: i32 = stem[4..7].parse().ok()?;
    let lat = match b[0] {
        b'N' => lat,
        b'S' => -lat,
        _ => return None,
    };
    let lon = match b[3] {
        b'E' => lon,
        b'W' => -lon,
        _ => return None,
    };
    ((-90..90).contains(&lat) && (-180..180).contains(&lon)).then_some((lat, lon))
}

impl SrtmMosaic {
    fn new(files: Vec<PathBuf>, opts: &LoadOptions) -> Result<Self, TiledError> {
        let opts = LoadOptions {
            format: Some(HeightmapFormat::Hgt),
            size: None,
            ..opts.clone()
        };
        let mut tiles = BTreeMap::new();
        let mut n = None;
        for path in files {
            let Some(corner) = parse_srtm_name(&path) else {
                return Err(TiledError::Input {
                    path,
                    what: "an SRTM tile's name must give its south-west corner, like N37W119.hgt"
                        .into(),
                });
            };
            let len = std::fs::metadata(&path)
                .map_err(|source| TiledError::io(&path, source))?
                .len();
            // The .hgt loader's own size check, from the length alone.
            let (side, _) = headerless_shape(&path, HeightmapFormat::Hgt, &opts, len)
                .map_err(|e| TiledError::Load(Box::new(e)))?;
            if *n.get_or_insert(side) != side {
                return Err(TiledError::Input {
                    path,
                    what: format!(
                        "{side}x{side} samples, but the other tiles are {0}x{0}",
                        n.unwrap_or(side)
                    ),
                });
            }
            if let Some(other) = tiles.insert(corner, path.clone()) {
                return Err(TiledError::Input {
                    path,
                    what: format!("names the same tile as {}", other.display()),
                });
            }
        }
        let n = n.expect("at least one tile");
        let lat_min = tiles.keys().map(|k| k.0).min().expect("tiles");
        let lat_max = tiles.keys().map(|k| k.0).max().expect("tiles");
        let lon_min = tiles.keys().map(|k| k.1).min().expect("tiles");
        let lon_max = tiles.keys().map(|k| k.1).max().expect("tiles");
        Ok(SrtmMosaic {
            tiles,
            n,
            lat_max,
            lon_min,
            lat_count: (lat_max - lat_min + 1) as usize,
            lon_count: (lon_max - lon_min + 1) as usize,
            row: 0,
            band: None,
            opts,
        })
    }

    fn mapping_of(&self) -> IntegerMapping {
        let max = HeightmapFormat::Hgt
            .integer_max()
            .expect("an integer format");
        IntegerMapping::of(max, &self.opts)
    }
}

impl RowSource for SrtmMosaic {
    fn width(&self) -> usize {
        self.lon_count * (self.n - 1) + 1
    }
    fn depth(&self) -> usize {
        self.lat_count * (self.n - 1) + 1
    }
    fn read_row(&mut self, out: &mut [f32]) -> Result<(), TiledError> {
        let step = self.n - 1;
        let b = (self.row / step).min(self.lat_count - 1);
        let k = self.row - b * step;
        if self.band.as_ref().map(|(loaded, _)| *loaded) != Some(b) {
            // Drop the last band before loading the next.
            self.band = None;
            let lat = self.lat_max - b as i32;
            let mut maps = Vec::with_capacity(self.lon_count);
            for i in 0..self.lon_count {
                let lon = self.lon_min + i as i32;
                maps.push(match self.tiles.get(&(lat, lon)) {
                    Some(path) => Some(
                        Heightmap::load_raster(path, &self.opts)
                            .map_err(|e| TiledError::Load(Box::new(e)))?,
                    ),
                    None => None,
                });
            }
            self.band = Some((b, maps));
        }
        let sea = self.mapping_of().height(0);
        let (_, maps) = self.band.as_ref().expect("loaded");
        for (i, map) in maps.iter().enumerate() {
            let start = i * step;
            // Every tile but the last leaves its east border to the next.
            let len = if i + 1 == self.lon_count {
                step + 1
            } else {
                step
            };
            let dst = &mut out[start..start + len];
            match map {
                Some(map) => dst.copy_from_slice(&map.row(k)[..len]),
                None => dst.fill(sea),
            }
        }
        self.row += 1;
        Ok(())
    }
    fn mapping(&self) -> Option<IntegerMapping> {
        Some(self.mapping_of())
    }
}

/// The `.hgt` files among `inputs`: files as given, directories searched
/// (not recursively) for names ending in `.hgt`.
fn hgt_files(inputs: &[PathBuf]) -> Result<Vec<PathBuf>, TiledError> {
    let mut files = Vec::new();
    for input in inputs {
        if input.is_dir() {
            let io = |source| TiledError::io(input, source);
            let mut found: Vec<PathBuf> = std::fs::read_dir(input)
                .map_err(io)?
                .map(|e| e.map(|e| e.path()))
                .collect::<Result<_, _>>()
                .map_err(io)?;
            found.retain(|p| {
                p.is_file() && p.extension().is_some_and(|e| e.eq_ignore_ascii_case("hgt"))
            });
            if found.is_empty() {
                return Err(TiledError::Input {
                    path: input.clone(),
                    what: "directory holds no .hgt files".into(),
                });
            }
            found.sort();
            files.extend(found);
        } else {
            files.push(input.clone());
        }
    }
    Ok(files)
}

/// Opens the inputs of `vkterrain import` as rows: one heightmap file, or
/// SRTM `.hgt` tiles (files or directories of them) as a mosaic.
pub fn open_source(
    inputs: &[PathBuf],
    opts: &LoadOptions,
) -> Result<(Box<dyn RowSource>, SourceKind), TiledError> {
    let is_hgt = |p: &Path| {
        p.is_dir()
            || opts.format == Some(HeightmapFormat::Hgt)
            || (opts.format.is_none()
                && p.extension().is_some_and(|e| e.eq_ignore_ascii_case("hgt")))
    };
    let Some(first) = inputs.first() else {
        return Err(TiledError::Input {
            path: PathBuf::from("(none)"),
            what: "no input given".into(),
        });
    };
    if inputs.len() > 1 || first.is_dir() {
        if let Some(other) = inputs.iter().find(|p| !is_hgt(p)) {
            return Err(TiledError::Input {
                path: other.clone(),
                what: "several inputs are mosaicked only as SRTM .hgt tiles (or directories of them); this is not one".into(),
            });
        }
        let mosaic = SrtmMosaic::new(hgt_files(inputs)?, opts)?;
        return Ok((Box::new(mosaic), SourceKind::SrtmMosaic));
    }
    let path = first.as_path();
    let loader_error = |e: crate::terrain::HeightmapError| TiledError::Load(Box::new(e));
    let whole =
        |mapping: Option<IntegerMapping>| -> Result<(Box<dyn RowSource>, SourceKind), TiledError> {
            let map = Heightmap::load_raster(path, opts).map_err(loader_error)?;
            Ok((Box::new(MemoryRows::new(map, mapping)), SourceKind::Whole))
        };
    if opts.smooth {
        return Err(TiledError::Input {
            path: path.to_path_buf(),
            what: "smoothing is not applied on import; import the heightmap as it is".into(),
        });
    }
    if TiledHeightmap::is_tiled(path) {
        // Re-tiling: read it whole (mapping options refused).
        let map = load_whole(path, opts).map_err(loader_error)?;
        return Ok((Box::new(MemoryRows::new(map, None)), SourceKind::Whole));
    }
    let format = match opts.format {
        Some(f) => f,
        None => HeightmapFormat::from_path(path).map_err(loader_error)?,
    };
    match format {
        HeightmapFormat::Png => match png_rows(path, opts)? {
            Some(rows) => Ok((Box::new(rows), SourceKind::Streamed)),
            // Colour (with --luminance) and interlaced PNGs: their rows are
            // not heights as stored, so the loader converts them whole.
            None => whole(None),
        },
        HeightmapFormat::Hgt => whole(
            HeightmapFormat::Hgt
                .integer_max()
                .map(|max| IntegerMapping::of(max, opts)),
        ),
        raw => {
            // The loader's own checks of the size against the file length,
            // without reading more than one sample.
            let len = std::fs::metadata(path)
                .map_err(|source| TiledError::io(path, source))?
                .len();
            let (width, depth) = headerless_shape(path, raw, opts, len).map_err(loader_error)?;
            let file = std::fs::File::open(path).map_err(|source| TiledError::io(path, source))?;
            let bytes_per_sample = raw.raw_sample_bytes().expect("a headerless format") as usize;
            Ok((
                Box::new(RawRows {
                    path: path.to_path_buf(),
                    reader: BufReader::new(file),
                    format: raw,
                    width,
                    depth,
                    row: 0,
                    bytes: vec![0u8; width * bytes_per_sample],
                    opts: opts.clone(),
                }),
                SourceKind::Streamed,
            ))
        }
    }
}

/// What an import wrote.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ImportReport {
    pub width: usize,
    pub depth: usize,
    pub tile_cells: u32,
    pub tiles_x: u32,
    pub tiles_z: u32,
    pub levels: u32,
    pub min_height: f32,
    pub max_height: f32,
    /// Tile levels stored as 16-bit codes, and as floats.
    pub levels_as_codes: u64,
    pub levels_as_floats: u64,
    /// Largest difference between a stored height and its input: 0, the
    /// storage is exact.
    pub max_error: f32,
    /// The patch size whose error tables are stored, if any.
    pub tables_cells_per_patch: Option<u32>,
    pub file_bytes: u64,
    pub bytes_per_sample: f64,
    pub seconds: f64,
}

/// One tile level, encoded.
struct EncodedLevel {
    bytes: Vec<u8>,
    encoding: Encoding,
    min: f32,
    max: f32,
    error: f32,
}

/// Encodes samples as 16-bit codes where `mapping` reproduces every one
/// bit for bit within a span of 65536 codes, else as floats.
fn encode_level(samples: &[f32], mapping: Option<IntegerMapping>) -> EncodedLevel {
    let (min, max) = crate::terrain::heightmap::min_max_of(samples);
    let codes = mapping.and_then(|m| {
        let codes: Option<Vec<i64>> = samples.iter().map(|&h| m.code_of(h)).collect();
        let codes = codes?;
        let lo = *codes.iter().min()?;
        let hi = *codes.iter().max()?;
        let base = i32::try_from(lo).ok()?;
        (hi - lo <= i64::from(u16::MAX)).then(|| {
            let bytes = codes
                .iter()
                .flat_map(|&v| ((v - lo) as u16).to_le_bytes())
                .collect();
            (bytes, Encoding::Codes { base, mapping: m })
        })
    });
    let (bytes, encoding) = codes.unwrap_or_else(|| {
        (
            samples.iter().flat_map(|h| h.to_le_bytes()).collect(),
            Encoding::F32,
        )
    });
    EncodedLevel {
        bytes,
        encoding,
        min,
        max,
        error: 0.0,
    }
}

/// The levels of one tile cut from a band of rows (`band` holds rows
/// `r0..` of the terrain, `width` samples each).
fn tile_levels(
    header: &Header,
    band: &[f32],
    width: usize,
    (tx, tz): (u32, u32),
    mapping: Option<IntegerMapping>,
) -> Vec<EncodedLevel> {
    let [c0, c1, r0, r1] = header.tile_rect(tx, tz);
    let (cells_x, cells_z) = (c1 - c0, r1 - r0);
    let stride = cells_x as usize + 1;
    let full: Vec<f32> = (0..=cells_z as usize)
        .flat_map(|r| &band[r * width + c0 as usize..r * width + c0 as usize + stride])
        .copied()
        .collect();
    (0..header.levels)
        .map(|level| {
            let (cols, rows) = (level_side(cells_x, level), level_side(cells_z, level));
            let samples: Vec<f32> = (0..rows)
                .flat_map(|i| {
                    let row = level_sample(i, cells_z, level) as usize * stride;
                    (0..cols).map(move |j| row + level_sample(j, cells_x, level) as usize)
                })
                .map(|k| full[k])
                .collect();
            EncodedLevel {
                error: level_error(&full, (cells_x, cells_z), level),
                ..encode_level(&samples, mapping)
            }
        })
        .collect()
}

/// Reads `source` and writes it to `out` as a tiled terrain of
/// `tile_cells`-cell tiles, with the error tables of
/// `tables_cells_per_patch`-cell patches where tiles hold a whole number
/// of them. `progress(rows_done, rows)` is called after
/// each row of tiles. On an error the file is left partly written: the
/// command writes it under a temporary name and renames it when complete
/// (`output::write_atomically`).
pub fn import(
    source: &mut dyn RowSource,
    tile_cells: u32,
    tables_cells_per_patch: Option<u32>,
    out: &Path,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<ImportReport, TiledError> {
    let started = Instant::now();
    validate_tile_cells(tile_cells)?;
    let (width, depth) = (source.width(), source.depth());
    if width < 2 || depth < 2 || width as u64 > MAX_SIDE || depth as u64 > MAX_SIDE {
        return Err(TiledError::Input {
            path: out.to_path_buf(),
            what: format!("a tiled terrain is 2x2 to {MAX_SIDE}x{MAX_SIDE} samples; the input is {width}x{depth}"),
        });
    }
    let mut header = Header {
        width: width as u32,
        depth: depth as u32,
        tile_cells,
        levels: level_count(tile_cells),
        min_height: f32::INFINITY,
        max_height: f32::NEG_INFINITY,
        directory_offset: 0,
        directory_crc: 0,
        tables: None,
    };
    let (tiles_x, tiles_z) = header.tiles();
    let io = |source| TiledError::Write {
        path: out.to_path_buf(),
        source,
    };
    let mut file = BufWriter::new(std::fs::File::create(out).map_err(io)?);
    file.write_all(&[0u8; HEADER_BYTES]).map_err(io)?;
    let mut offset = HEADER_BYTES as u64;
    let mut entries = vec![None; header.entry_count() as usize];
    let (mut levels_as_codes, mut levels_as_floats) = (0, 0);
    let t = tile_cells as usize;
    // Rows r0..=r1 + 1 of the terrain: the row after the band lets the
    // error tables interpolate across its last row as they would on the
    // whole map. The band's last rows are the next band's first.
    let mut band = vec![0.0f32; (t + 2) * width];
    let mut loaded = 0usize;
    let mapping = source.mapping();
    let tables_cells = tables_cells_per_patch.filter(|&n| tile_cells % n == 0);
    let (mut tess_table, mut geomip_table, mut y_bounds) = (Vec::new(), Vec::new(), Vec::new());
    for tz in 0..tiles_z {
        let [_, _, r0, r1] = header.tile_rect(0, tz);
        let (r0, r1) = (r0 as usize, r1 as usize);
        let rows = r1 - r0 + 1;
        if tz > 0 {
            let previous = r0 - t;
            band.copy_within(t * width..(loaded - previous) * width, 0);
        }
        let last = (r1 + 1).min(depth - 1);
        for r in loaded..=last {
            let local = r - r0;
            source.read_row(&mut band[local * width..(local + 1) * width])?;
        }
        loaded = last + 1;
        if let Some(cells) = tables_cells {
            let map_rows = last - r0 + 1;
            let map = Heightmap::from_heights(width, map_rows, band[..map_rows * width].to_vec())
                .map_err(|e| TiledError::Load(Box::new(e)))?;
            let grid = PatchGrid::for_size(width, map_rows, cells);
            let (tess, geomip) = ErrorTable::compute_pair(&map, &grid);
            // The band's patches end on its last row; the one after it
            // starts the next band's.
            let patches = (r1 - r0).div_ceil(cells as usize) * grid.patch_cols();
            let keep = patches * ErrorTable::LEVELS;
            tess_table.extend_from_slice(&tess.as_slice()[..keep]);
            geomip_table.extend_from_slice(&geomip.as_slice()[..keep]);
            y_bounds.extend_from_slice(
                &crate::terrain::grid::patch_y_bounds(&map, &grid, 0.0)[..patches],
            );
        }
        let band_rows = &band[..rows * width];
        let encoded: Vec<Vec<EncodedLevel>> = (0..tiles_x)
            .into_par_iter()
            .map(|tx| tile_levels(&header, band_rows, width, (tx, tz), mapping))
            .collect();
        for (tx, levels) in encoded.into_iter().enumerate() {
            for (level, e) in levels.into_iter().enumerate() {
                file.write_all(&e.bytes).map_err(io)?;
                if level == 0 {
                    header.min_height = header.min_height.min(e.min);
                    header.max_height = header.max_height.max(e.max);
                }
                match e.encoding {
                    Encoding::F32 => levels_as_floats += 1,
                    Encoding::Codes { .. } => levels_as_codes += 1,
                }
                entries[header.entry_index(tx as u32, tz, level as u32)] = Some(Entry {
                    offset,
                    bytes: e.bytes.len() as u32,
                    encoding: e.encoding,
                    min: e.min,
                    max: e.max,
                    crc: crc32fast::hash(&e.bytes),
                    error: e.error,
                });
                offset += e.bytes.len() as u64;
            }
        }
        progress(r1 as u64 + 1, depth as u64);
    }
    let directory: Vec<u8> = entries
        .iter()
        .flat_map(|e| e.expect("every tile level written").encode())
        .collect();
    file.write_all(&directory).map_err(io)?;
    header.directory_offset = offset;
    header.directory_crc = crc32fast::hash(&directory);
    offset += directory.len() as u64;
    if let Some(cells) = tables_cells {
        let tables: Vec<u8> = tess_table
            .iter()
            .chain(&geomip_table)
            .chain(y_bounds.iter().flatten())
            .flat_map(|e| e.to_le_bytes())
            .collect();
        debug_assert_eq!(tables.len() as u64, header.tables_bytes(cells));
        file.write_all(&tables).map_err(io)?;
        header.tables = Some(TablesAt {
            offset,
            cells_per_patch: cells,
            crc: crc32fast::hash(&tables),
        });
        offset += tables.len() as u64;
    }
    let mut file = file.into_inner().map_err(|e| io(e.into_error()))?;
    file.seek(SeekFrom::Start(0)).map_err(io)?;
    file.write_all(&header.encode()).map_err(io)?;
    file.sync_all().map_err(io)?;
    drop(file);
    Ok(ImportReport {
        width,
        depth,
        tile_cells,
        tiles_x,
        tiles_z,
        levels: header.levels,
        min_height: header.min_height,
        max_height: header.max_height,
        levels_as_codes,
        levels_as_floats,
        max_error: 0.0,
        tables_cells_per_patch: tables_cells,
        file_bytes: offset,
        bytes_per_sample: offset as f64 / (width as f64 * depth as f64),
        seconds: started.elapsed().as_secs_f64(),
    })
}
