//! The tiled terrain's layout: the header, the directory's entries, the
//! tile levels and their errors, with the limits a file must keep.

use crate::terrain::error::TiledError;
use crate::terrain::heightmap::{integer_height, LoadOptions};

/// The first eight bytes of every tiled terrain. The CR LF catches a file
/// mangled by a text-mode copy.
pub const MAGIC: [u8; 8] = *b"VKTERR\r\n";
/// The layout version this build reads and writes.
pub const VERSION: u32 = 4;
/// Size of the header.
pub const HEADER_BYTES: usize = 80;
/// Where the header's own checksum sits: its last four bytes.
const HEADER_CRC_AT: usize = HEADER_BYTES - 4;
/// Size of one directory entry.
pub const ENTRY_BYTES: usize = 64;
/// Smallest and largest cells per tile side.
pub const MIN_TILE_CELLS: u32 = 2;
pub const MAX_TILE_CELLS: u32 = 4096;
/// Cells per tile when the caller does not choose: 257^2 samples, 129 KiB
/// at 16 bits.
pub const DEFAULT_TILE_CELLS: u32 = 256;
/// Largest side, in samples, of a tiled terrain.
pub const MAX_SIDE: u64 = 1 << 24;

/// The mapping from integer samples to heights that the integer loaders
/// use: `h = scale * v / divisor + offset`, in f64, rounded once to f32.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IntegerMapping {
    pub scale: f64,
    pub divisor: f64,
    pub offset: f64,
}

impl IntegerMapping {
    /// The mapping of a format whose largest integer is `max`.
    pub fn of(max: f64, opts: &LoadOptions) -> Self {
        IntegerMapping {
            scale: opts.height_scale,
            divisor: max,
            offset: opts.height_offset,
        }
    }

    #[inline]
    pub fn height(&self, v: i64) -> f32 {
        integer_height(v as f64, self.divisor, self.scale, self.offset)
    }

    /// The integer whose height is exactly `h`, bit for bit, if there is one.
    pub fn code_of(&self, h: f32) -> Option<i64> {
        let v = ((f64::from(h) - self.offset) * self.divisor / self.scale).round();
        if !(v.is_finite() && v.abs() < 1e15) {
            return None;
        }
        let v = v as i64;
        (self.height(v).to_bits() == h.to_bits()).then_some(v)
    }
}

/// The fixed-size header at the start of a tiled terrain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Header {
    pub width: u32,
    pub depth: u32,
    /// Cells per tile side, `T`.
    pub tile_cells: u32,
    /// Levels per tile: `log2(T) + 1`.
    pub levels: u32,
    pub min_height: f32,
    pub max_height: f32,
    pub directory_offset: u64,
    pub directory_crc: u32,
    /// The stored error tables, if any.
    pub tables: Option<TablesAt>,
}

/// Where a tiled terrain's error tables are, and for which patch size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TablesAt {
    pub offset: u64,
    pub cells_per_patch: u32,
    pub crc: u32,
}

impl Header {
    /// Bytes of the error tables for patches of `cells_per_patch` cells.
    pub fn tables_bytes(&self, cells_per_patch: u32) -> u64 {
        let grid = crate::terrain::PatchGrid::for_size(
            self.width as usize,
            self.depth as usize,
            cells_per_patch,
        );
        grid.patch_count() as u64 * (2 * crate::terrain::ErrorTable::LEVELS as u64 + 2) * 4
    }

    /// Tiles across and down.
    pub fn tiles(&self) -> (u32, u32) {
        (
            tile_count(self.width, self.tile_cells),
            tile_count(self.depth, self.tile_cells),
        )
    }

    /// Number of directory entries.
    pub fn entry_count(&self) -> u64 {
        let (x, z) = self.tiles();
        u64::from(x) * u64::from(z) * u64::from(self.levels)
    }

    pub fn directory_bytes(&self) -> u64 {
        self.entry_count() * ENTRY_BYTES as u64
    }

    /// Index of a tile level's directory entry.
    pub fn entry_index(&self, tx: u32, tz: u32, level: u32) -> usize {
        let (x, _) = self.tiles();
        ((tz as usize * x as usize + tx as usize) * self.levels as usize) + level as usize
    }

    /// The samples tile (tx, tz) covers, borders included: (first column,
    /// last column, first row, last row).
    pub fn tile_rect(&self, tx: u32, tz: u32) -> [u32; 4] {
        let t = self.tile_cells;
        [
            tx * t,
            ((tx + 1) * t).min(self.width - 1),
            tz * t,
            ((tz + 1) * t).min(self.depth - 1),
        ]
    }

    /// Samples across and down of tile (tx, tz) at `level`.
    pub fn level_size(&self, tx: u32, tz: u32, level: u32) -> (u32, u32) {
        let [c0, c1, r0, r1] = self.tile_rect(tx, tz);
        (level_side(c1 - c0, level), level_side(r1 - r0, level))
    }

    pub fn encode(&self) -> [u8; HEADER_BYTES] {
        let mut b = [0u8; HEADER_BYTES];
        b[0..8].copy_from_slice(&MAGIC);
        b[8..12].copy_from_slice(&VERSION.to_le_bytes());
        b[12..16].copy_from_slice(&(HEADER_BYTES as u32).to_le_bytes());
        b[16..20].copy_from_slice(&self.width.to_le_bytes());
        b[20..24].copy_from_slice(&self.depth.to_le_bytes());
        b[24..28].copy_from_slice(&self.tile_cells.to_le_bytes());
        b[28..32].copy_from_slice(&self.levels.to_le_bytes());
        b[32..36].copy_from_slice(&self.min_height.to_le_bytes());
        b[36..40].copy_from_slice(&self.max_height.to_le_bytes());
        b[40..48].copy_from_slice(&self.directory_offset.to_le_bytes());
        b[48..52].copy_from_slice(&self.directory_crc.to_le_bytes());
        if let Some(t) = self.tables {
            b[52..60].copy_from_slice(&t.offset.to_le_bytes());
            b[60..64].copy_from_slice(&t.cells_per_patch.to_le_bytes());
            b[64..68].copy_from_slice(&t.crc.to_le_bytes());
        }
        // 68..76 reserved, zero.
        let crc = crc32fast::hash(&b[..HEADER_CRC_AT]);
        b[HEADER_CRC_AT..].copy_from_slice(&crc.to_le_bytes());
        b
    }

    /// Parses and checks a header against the length of its file: magic,
    /// version, checksum, sizes, and a directory that lies inside the file.
    pub fn decode(b: &[u8], file_len: u64, path: &std::path::Path) -> Result<Header, TiledError> {
        let path = path.to_path_buf();
        if b.len() < 8 || b[0..8] != MAGIC {
            return Err(TiledError::NotTiled { path });
        }
        let bad = |what: String| TiledError::Header {
            path: path.clone(),
            what,
        };
        if b.len() < 12 {
            return Err(bad(format!(
                "the file ends after {} bytes, inside the header",
                b.len()
            )));
        }
        let version = u32_at(b, 8);
        if version != VERSION {
            return Err(TiledError::Version {
                path,
                found: version,
                reads: VERSION,
            });
        }
        if b.len() < HEADER_BYTES {
            return Err(bad(format!(
                "the file ends after {} bytes, inside the {HEADER_BYTES}-byte header",
                b.len()
            )));
        }
        let stored_crc = u32_at(b, HEADER_CRC_AT);
        if crc32fast::hash(&b[..HEADER_CRC_AT]) != stored_crc {
            return Err(bad("checksum mismatch".into()));
        }
        let header_bytes = u32_at(b, 12);
        if header_bytes as usize != HEADER_BYTES {
            return Err(bad(format!(
                "header size {header_bytes}, expected {HEADER_BYTES}"
            )));
        }
        let header = Header {
            width: u32_at(b, 16),
            depth: u32_at(b, 20),
            tile_cells: u32_at(b, 24),
            levels: u32_at(b, 28),
            min_height: f32::from_le_bytes(b[32..36].try_into().expect("4 bytes")),
            max_height: f32::from_le_bytes(b[36..40].try_into().expect("4 bytes")),
            directory_offset: u64::from_le_bytes(b[40..48].try_into().expect("8 bytes")),
            directory_crc: u32_at(b, 48),
            tables: None,
        };
        let tables_offset = u64::from_le_bytes(b[52..60].try_into().expect("8 bytes"));
        let tables = (tables_offset != 0).then(|| TablesAt {
            offset: tables_offset,
            cells_per_patch: u32_at(b, 60),
            crc: u32_at(b, 64),
        });
        let (w, d) = (u64::from(header.width), u64::from(header.depth));
        if w < 2 || d < 2 || w > MAX_SIDE || d > MAX_SIDE {
            return Err(bad(format!(
                "size {w}x{d} is outside 2x2 to {MAX_SIDE}x{MAX_SIDE}"
            )));
        }
        if validate_tile_cells(header.tile_cells).is_err() {
            return Err(bad(format!(
                "cells per tile {} is not a power of two from {MIN_TILE_CELLS} to {MAX_TILE_CELLS}",
                header.tile_cells
            )));
        }
        if header.levels != level_count(header.tile_cells) {
            return Err(bad(format!(
                "{} levels per tile, expected {} for {}-cell tiles",
                header.levels,
                level_count(header.tile_cells),
                header.tile_cells
            )));
        }
        let (lo, hi) = (header.min_height, header.max_height);
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(bad(format!("height range {lo}..{hi} is not finite")));
        }
        let end = header
            .directory_offset
            .checked_add(header.directory_bytes())
            .filter(|&end| header.directory_offset >= HEADER_BYTES as u64 && end <= file_len);
        let Some(directory_end) = end else {
            return Err(bad(format!(
                "the directory ({} bytes at offset {}) does not lie inside the file of {file_len} bytes (truncated?)",
                header.directory_bytes(),
                header.directory_offset
            )));
        };
        if let Some(t) = tables {
            let n = t.cells_per_patch;
            if crate::terrain::grid::validate_cells_per_patch(n).is_err()
                || header.tile_cells % n != 0
            {
                return Err(bad(format!(
                    "error tables for {n}-cell patches, which {}-cell tiles cannot hold",
                    header.tile_cells
                )));
            }
            let bytes = header.tables_bytes(n);
            if !(t.offset >= directory_end
                && t.offset.checked_add(bytes).is_some_and(|e| e <= file_len))
            {
                return Err(bad(format!(
                    "the error tables ({bytes} bytes at offset {}) do not lie after the directory inside the file of {file_len} bytes (truncated?)",
                    t.offset
                )));
            }
        }
        Ok(Header { tables, ..header })
    }
}

/// How a tile level's samples are stored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Encoding {
    /// 32-bit floats.
    F32,
    /// 16-bit codes q: `h = (scale * ((base + q) / divisor) + offset) as f32`.
    Codes { base: i32, mapping: IntegerMapping },
}

impl Encoding {
    pub fn sample_bytes(self) -> u64 {
        match self {
            Encoding::F32 => 4,
            Encoding::Codes { .. } => 2,
        }
    }
}

/// One tile level's directory entry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Entry {
    pub offset: u64,
    pub bytes: u32,
    pub encoding: Encoding,
    /// Smallest and largest height of the level (at level 0, the tile's Y
    /// bounds).
    pub min: f32,
    pub max: f32,
    /// CRC-32 of the stored bytes.
    pub crc: u32,
    /// Largest difference, over the tile's full-resolution samples, between
    /// a sample and the level's surface at it (`level_error`); 0 at level
    /// 0. What drawing the tile at this level instead of its full
    /// resolution moves a sample by, and what a switch between levels pops.
    pub error: f32,
}

impl Entry {
    pub fn encode(&self) -> [u8; ENTRY_BYTES] {
        let mut b = [0u8; ENTRY_BYTES];
        b[0..8].copy_from_slice(&self.offset.to_le_bytes());
        b[8..12].copy_from_slice(&self.bytes.to_le_bytes());
        b[16..20].copy_from_slice(&self.min.to_le_bytes());
        b[20..24].copy_from_slice(&self.max.to_le_bytes());
        b[24..28].copy_from_slice(&self.crc.to_le_bytes());
        b[56..60].copy_from_slice(&self.error.to_le_bytes());
        // 60..64 reserved, zero.
        match self.encoding {
            Encoding::F32 => b[12..16].copy_from_slice(&0u32.to_le_bytes()),
            Encoding::Codes { base, mapping } => {
                b[12..16].copy_from_slice(&1u32.to_le_bytes());
                b[28..32].copy_from_slice(&base.to_le_bytes());
                b[32..40].copy_from_slice(&mapping.scale.to_le_bytes());
                b[40..48].copy_from_slice(&mapping.divisor.to_le_bytes());
                b[48..56].copy_from_slice(&mapping.offset.to_le_bytes());
            }
        }
        b
    }

    /// Parses an entry; `Err` says what is wrong with it.
    pub fn decode(b: &[u8]) -> Result<Entry, String> {
        let f64_at = |i: usize| f64::from_le_bytes(b[i..i + 8].try_into().expect("8 bytes"));
        let encoding = match u32_at(b, 12) {
            0 => Encoding::F32,
            1 => {
                let mapping = IntegerMapping {
                    scale: f64_at(32),
                    divisor: f64_at(40),
                    offset: f64_at(48),
                };
                if !(mapping.scale.is_finite()
                    && mapping.offset.is_finite()
                    && mapping.divisor.is_finite()
                    && mapping.divisor > 0.0)
                {
                    return Err(format!("sample mapping {mapping:?} is not finite"));
                }
                Encoding::Codes {
                    base: u32_at(b, 28) as i32,
                    mapping,
                }
            }
            other => return Err(format!("unknown sample encoding {other}")),
        };
        let entry = Entry {
            offset: u64::from_le_bytes(b[0..8].try_into().expect("8 bytes")),
            bytes: u32_at(b, 8),
            encoding,
            min: f32::from_le_bytes(b[16..20].try_into().expect("4 bytes")),
            max: f32::from_le_bytes(b[20..24].try_into().expect("4 bytes")),
            crc: u32_at(b, 24),
            error: f32::from_le_bytes(b[56..60].try_into().expect("4 bytes")),
        };
        if !(entry.error.is_finite() && entry.error >= 0.0) {
            return Err(format!(
                "level error {} is not a finite, non-negative number",
                entry.error
            ));
        }
        if !(entry.min.is_finite() && entry.max.is_finite() && entry.min <= entry.max) {
            return Err(format!(
                "height range {}..{} is not finite",
                entry.min, entry.max
            ));
        }
        Ok(entry)
    }
}

fn u32_at(b: &[u8], i: usize) -> u32 {
    u32::from_le_bytes(b[i..i + 4].try_into().expect("4 bytes"))
}

/// Tiles needed to cover `samples` samples with `tile_cells`-cell tiles.
pub fn tile_count(samples: u32, tile_cells: u32) -> u32 {
    (samples - 1).div_ceil(tile_cells)
}

/// Levels per tile of `tile_cells` cells: down to the tile's corners.
pub fn level_count(tile_cells: u32) -> u32 {
    tile_cells.trailing_zeros() + 1
}

/// Samples along a tile side of `cells` cells at `level`: every `2^level`-th
/// sample and the last.
pub fn level_side(cells: u32, level: u32) -> u32 {
    cells.div_ceil(1 << level) + 1
}

/// The tile-relative sample index of position `i` along a side of `cells`
/// cells at `level`.
pub fn level_sample(i: u32, cells: u32, level: u32) -> u32 {
    (i << level).min(cells)
}

/// Largest difference between a tile's full-resolution samples and its
/// level `level` surface at them: the level's samples (`level_sample`)
/// joined into cells split like the reference's (`Heightmap::interpolate`),
/// a cell at the far edge narrower where `cells` is not a multiple of
/// `2^level`. `samples` is the tile's `(cells_x + 1) x (cells_z + 1)` full
/// resolution, row-major.
pub fn level_error(samples: &[f32], (cells_x, cells_z): (u32, u32), level: u32) -> f32 {
    if level == 0 {
        return 0.0;
    }
    let stride = cells_x as usize + 1;
    let h = |r: u32, c: u32| samples[r as usize * stride + c as usize];
    let mut worst = 0.0f64;
    for r in 0..=cells_z {
        for c in 0..=cells_x {
            let coarse = level_surface((cells_x, cells_z), level, (c, r), h);
            worst = worst.max((f64::from(h(r, c)) - coarse).abs());
        }
    }
    worst as f32
}

/// The level-`level` surface of a grid of `cells` (across, down) cells at
/// its sample (col, row): the level's samples (`level_sample`) joined into
/// cells split like the reference's (`Heightmap::interpolate`), a cell at
/// the far edge narrower where the cells are not a multiple of
/// `2^level`. `full(row, col)` reads the grid's full-resolution samples,
/// of which the level keeps some. A sample the level keeps is returned
/// exactly. Mirror: glsl/terrain_common.glsl `base_height`.
pub fn level_surface(
    (cells_x, cells_z): (u32, u32),
    level: u32,
    (col, row): (u32, u32),
    full: impl Fn(u32, u32) -> f32,
) -> f64 {
    let step = 1u32 << level;
    // A coordinate's coarse cell ends, and the fraction across.
    let locate = |v: u32, cells: u32| {
        let i = (v / step).min(level_side(cells, level) - 2);
        let (a, b) = (
            level_sample(i, cells, level),
            level_sample(i + 1, cells, level),
        );
        (a, b, f64::from(v - a) / f64::from(b - a))
    };
    let (c0, c1, s) = locate(col, cells_x);
    let (r0, r1, t) = locate(row, cells_z);
    let cell = crate::terrain::heightmap::CellPoint {
        row: 0,
        col: 0,
        s,
        t,
    };
    crate::terrain::heightmap::blend_cell(
        &cell,
        [full(r0, c0), full(r0, c1), full(r1, c0), full(r1, c1)],
    )
}

pub fn validate_tile_cells(n: u32) -> Result<(), TiledError> {
    if n.is_power_of_two() && (MIN_TILE_CELLS..=MAX_TILE_CELLS).contains(&n) {
        Ok(())
    } else {
        Err(TiledError::TileCells {
            got: n,
            min: MIN_TILE_CELLS,
            max: MAX_TILE_CELLS,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_keep_every_other_sample_and_the_last() {
        assert_eq!(level_count(256), 9);
        assert_eq!(level_side(256, 0), 257);
        assert_eq!(level_side(256, 8), 2);
        // A 100-cell remainder tile: 0, 8, ..., 96, then 100.
        assert_eq!(level_side(100, 3), 14);
        assert_eq!(level_sample(12, 100, 3), 96);
        assert_eq!(level_sample(13, 100, 3), 100);
    }

    #[test]
    fn level_error_is_the_largest_sample_off_the_coarse_surface() {
        // A 4x2-cell tile: flat but for one raised sample between level 1's
        // samples, and a plane, which every level reproduces.
        let mut bump = vec![0.0f32; 5 * 3];
        bump[5 + 1] = 2.0;
        assert_eq!(level_error(&bump, (4, 2), 0), 0.0);
        assert_eq!(level_error(&bump, (4, 2), 1), 2.0);
        let plane: Vec<f32> = (0..15)
            .map(|i| (i % 5) as f32 * 0.5 + (i / 5) as f32)
            .collect();
        for level in 0..3 {
            assert!(level_error(&plane, (4, 2), level) < 1e-6);
        }
        // A 3-cell side at level 1: samples 0 and 2, then the last, 3,
        // which follow this ramp exactly; level 2 keeps only 0 and 3 and
        // misses sample 2 by 14/3 - 2.
        let ramp = [0.0f32, 1.0, 2.0, 7.0, 0.0, 1.0, 2.0, 7.0];
        assert!(level_error(&ramp, (3, 1), 1) < 1e-6);
        assert!((level_error(&ramp, (3, 1), 2) - 8.0 / 3.0).abs() < 1e-6);
    }

    #[test]
    fn header_round_trips_and_rejects_a_changed_byte() {
        let header = Header {
            width: 1025,
            depth: 700,
            tile_cells: 256,
            levels: 9,
            min_height: -3.5,
            max_height: 812.25,
            directory_offset: 4096,
            directory_crc: 0xdead_beef,
            tables: None,
        };
        let path = std::path::Path::new("t.vkt");
        let bytes = header.encode();
        let len = 4096 + header.directory_bytes();
        assert_eq!(Header::decode(&bytes, len, path).unwrap(), header);
        assert_eq!(header.tiles(), (4, 3));
        assert_eq!(header.tile_rect(3, 2), [768, 1024, 512, 699]);
        assert_eq!(header.level_size(3, 2, 0), (257, 188));
        assert_eq!(header.level_size(3, 2, 8), (2, 2));
        let with_tables = Header {
            tables: Some(TablesAt {
                offset: len,
                cells_per_patch: 32,
                crc: 7,
            }),
            ..header
        };
        let tables_end = len + with_tables.tables_bytes(32);
        assert_eq!(
            Header::decode(&with_tables.encode(), tables_end, path).unwrap(),
            with_tables
        );
        let err = Header::decode(&with_tables.encode(), tables_end - 1, path)
            .unwrap_err()
            .to_string();
        assert!(err.contains("error tables"), "{err}");
        let mut flipped = bytes;
        flipped[20] ^= 1;
        let err = Header::decode(&flipped, len, path).unwrap_err().to_string();
        assert!(err.contains("checksum"), "{err}");
        let err = Header::decode(&bytes, len - 1, path)
            .unwrap_err()
            .to_string();
        assert!(err.contains("truncated"), "{err}");
    }
}
