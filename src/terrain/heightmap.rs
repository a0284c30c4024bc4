//! Heightmaps: a row-major grid of heights in world units, and the loaders
//! for the file formats we accept.
//!
//! Integer samples map to `h = scale * (v / max) + offset`, where `max` is the
//! largest value of the format (255, 65535, or 32767 for signed SRTM data).
//! Float samples map to `h = scale * v + offset`. The arithmetic runs in f64 and
//! rounds once to f32, so a 16-bit elevation model loaded with scale 65535
//! gives back its integer metres exactly.

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use image::codecs::png::PngDecoder;
use image::ImageDecoder;
use rayon::prelude::*;

use super::error::HeightmapError;

/// Default limit on the number of samples a loader accepts (2^27: an
/// 8193x8193 map fits with room to spare; one float per sample is 512 MiB).
pub const DEFAULT_MAX_SAMPLES: u64 = 1 << 27;

/// The value SRTM uses to mark a sample with no data.
pub const HGT_VOID: i16 = -32768;

/// File formats a heightmap can be read from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum HeightmapFormat {
    /// Unsigned 8-bit samples, row-major, no header.
    Raw8,
    /// Unsigned 16-bit little-endian samples, row-major, no header.
    Raw16,
    /// Unsigned 16-bit big-endian samples, row-major, no header.
    Raw16Be,
    /// 8- or 16-bit grayscale PNG.
    Png,
    /// SRTM tile: signed 16-bit big-endian, 1201x1201 or 3601x3601.
    Hgt,
    /// 32-bit little-endian IEEE floats, row-major, no header.
    F32,
}

impl HeightmapFormat {
    pub const ALL: [HeightmapFormat; 6] = [
        HeightmapFormat::Raw8,
        HeightmapFormat::Raw16,
        HeightmapFormat::Raw16Be,
        HeightmapFormat::Png,
        HeightmapFormat::Hgt,
        HeightmapFormat::F32,
    ];

    pub fn name(self) -> &'static str {
        match self {
            HeightmapFormat::Raw8 => "raw8",
            HeightmapFormat::Raw16 => "raw16",
            HeightmapFormat::Raw16Be => "raw16be",
            HeightmapFormat::Png => "png",
            HeightmapFormat::Hgt => "hgt",
            HeightmapFormat::F32 => "f32",
        }
    }

    /// Infers the format from a file extension: `.r8`/`.raw8`, `.r16`/`.raw`/
    /// `.raw16` (little-endian, the common export), `.png`, `.hgt`,
    /// `.f32`/`.r32`.
    pub fn from_path(path: &Path) -> Result<Self, HeightmapError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .unwrap_or_default();
        let format = match ext.as_str() {
            "r8" | "raw8" => HeightmapFormat::Raw8,
            "r16" | "raw" | "raw16" => HeightmapFormat::Raw16,
            "png" => HeightmapFormat::Png,
            "hgt" => HeightmapFormat::Hgt,
            "f32" | "r32" => HeightmapFormat::F32,
            // A tiled terrain is told by its header, not its name
            // (`Heightmap::load`); a `.vkt` that reaches here has none.
            "vkt" => {
                return Err(HeightmapError::NotTiled {
                    path: path.to_path_buf(),
                })
            }
            _ => {
                return Err(HeightmapError::UnknownFormat {
                    path: path.to_path_buf(),
                    name: if ext.is_empty() {
                        "(no extension)".to_string()
                    } else {
                        format!(".{ext}")
                    },
                })
            }
        };
        Ok(format)
    }

    /// The largest sample value of the integer headerless formats, which
    /// maps to `height_scale`; None for floats, and for PNG, whose bit
    /// depth decides it.
    pub(crate) fn integer_max(self) -> Option<f64> {
        match self {
            HeightmapFormat::Raw8 => Some(255.0),
            HeightmapFormat::Raw16 | HeightmapFormat::Raw16Be => Some(65535.0),
            HeightmapFormat::Hgt => Some(32767.0),
            HeightmapFormat::F32 | HeightmapFormat::Png => None,
        }
    }

    /// Bytes per sample of the headerless formats; None for PNG.
    pub(crate) fn raw_sample_bytes(self) -> Option<u64> {
        match self {
            HeightmapFormat::Raw8 => Some(1),
            HeightmapFormat::Raw16 | HeightmapFormat::Raw16Be | HeightmapFormat::Hgt => Some(2),
            HeightmapFormat::F32 => Some(4),
            HeightmapFormat::Png => None,
        }
    }
}

impl fmt::Display for HeightmapFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Error of parsing a format name; the loader wraps it with the file path.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown heightmap format {0:?} (expected raw8, raw16, raw16be, png, hgt or f32)")]
pub struct UnknownFormatName(pub String);

impl FromStr for HeightmapFormat {
    type Err = UnknownFormatName;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        HeightmapFormat::ALL
            .into_iter()
            .find(|f| f.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| UnknownFormatName(s.to_string()))
    }
}

/// How to read a heightmap file and map its samples to heights.
#[derive(Clone, Debug, PartialEq)]
pub struct LoadOptions {
    /// None: inferred from the file extension.
    pub format: Option<HeightmapFormat>,
    /// Width (columns) and depth (rows) of headerless data; None: a square
    /// size is inferred from the file length. Ignored for PNG.
    pub size: Option<(u64, u64)>,
    pub height_scale: f64,
    pub height_offset: f64,
    /// Average every sample with its in-bounds 3x3 neighbourhood.
    pub smooth: bool,
    /// Accept colour PNGs by converting them to luminance.
    pub luminance: bool,
    /// Inputs with more samples are refused before anything is allocated.
    pub max_samples: u64,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            format: None,
            size: None,
            height_scale: 1.0,
            height_offset: 0.0,
            smooth: false,
            luminance: false,
            max_samples: DEFAULT_MAX_SAMPLES,
        }
    }
}

/// A grid of `width` columns by `depth` rows of heights in world units,
/// row-major: sample (row, col) is `heights[row * width + col]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Heightmap {
    width: usize,
    depth: usize,
    heights: Vec<f32>,
}

impl Heightmap {
    /// Wraps heights already in world units. They must be finite, at least
    /// 2x2, and exactly `width * depth` of them.
    pub fn from_heights(
        width: usize,
        depth: usize,
        heights: Vec<f32>,
    ) -> Result<Self, HeightmapError> {
        let path = PathBuf::from("<memory>");
        let (w, d) = (width as u64, depth as u64);
        if width < 2 || depth < 2 {
            return Err(HeightmapError::TooSmall {
                path,
                width: w,
                depth: d,
            });
        }
        let samples = width
            .checked_mul(depth)
            .ok_or(HeightmapError::SizeOverflow {
                path: path.clone(),
                width: w,
                depth: d,
            })?;
        if heights.len() != samples {
            return Err(HeightmapError::LengthMismatch {
                path,
                format: "f32",
                width: w,
                depth: d,
                expected: samples as u64 * 4,
                actual: heights.len() as u64 * 4,
            });
        }
        check_finite(&path, width, 0, &heights)?;
        Ok(Heightmap {
            width,
            depth,
            heights,
        })
    }

    /// Builds a heightmap by evaluating `f(row, col)` at every sample.
    pub fn from_fn(
        width: usize,
        depth: usize,
        f: impl Fn(usize, usize) -> f32 + Sync,
    ) -> Result<Self, HeightmapError> {
        let heights = (0..width.saturating_mul(depth))
            .into_par_iter()
            .map(|i| f(i / width, i % width))
            .collect();
        Heightmap::from_heights(width, depth, heights)
    }

    /// Reads a heightmap file of one of the formats of `HeightmapFormat`
    /// (not a tiled terrain: `Heightmap::load` tells them apart). Size
    /// limits are checked against the file's length before its samples
    /// are read or allocated.
    pub fn load_raster(path: &Path, opts: &LoadOptions) -> Result<Self, HeightmapError> {
        let io_err = |source: std::io::Error| {
            if source.kind() == std::io::ErrorKind::NotFound {
                HeightmapError::Missing {
                    path: path.to_path_buf(),
                }
            } else {
                HeightmapError::Io {
                    path: path.to_path_buf(),
                    source,
                }
            }
        };
        // A missing file is reported as missing before its name is read
        // for a format.
        let len = std::fs::metadata(path).map_err(io_err)?.len();
        let format = match opts.format {
            Some(f) => f,
            None => HeightmapFormat::from_path(path)?,
        };
        if len == 0 {
            return Err(HeightmapError::Empty {
                path: path.to_path_buf(),
            });
        }
        if format != HeightmapFormat::Png {
            // Validate the shape from the length alone, before reading.
            raw_shape(path, format, opts, len)?;
        }
        let bytes = std::fs::read(path).map_err(io_err)?;
        Heightmap::from_bytes(&bytes, format, opts, path)
    }

    /// Decodes a heightmap from bytes in memory; `path` only names the input
    /// in error messages.
    pub fn from_bytes(
        bytes: &[u8],
        format: HeightmapFormat,
        opts: &LoadOptions,
        path: &Path,
    ) -> Result<Self, HeightmapError> {
        if !opts.height_scale.is_finite() || !opts.height_offset.is_finite() {
            return Err(HeightmapError::BadMapping {
                path: path.to_path_buf(),
                scale: opts.height_scale,
                offset: opts.height_offset,
            });
        }
        if bytes.is_empty() {
            return Err(HeightmapError::Empty {
                path: path.to_path_buf(),
            });
        }
        let (width, depth, heights) = match format {
            HeightmapFormat::Png => decode_png(bytes, opts, path)?,
            _ => {
                let (width, depth) = raw_shape(path, format, opts, bytes.len() as u64)?;
                let heights = decode_raw(bytes, format, width, opts, path)?;
                (width, depth, heights)
            }
        };
        // A huge scale can overflow f32 even from valid input.
        check_finite(path, width, 0, &heights)?;
        let map = Heightmap {
            width,
            depth,
            heights,
        };
        Ok(if opts.smooth { map.smoothed() } else { map })
    }

    /// Number of columns.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Number of rows.
    pub fn depth(&self) -> usize {
        self.depth
    }

    pub fn heights(&self) -> &[f32] {
        &self.heights
    }

    /// The sample at (row, col). Panics when out of range, like slice indexing.
    #[inline]
    pub fn get(&self, row: usize, col: usize) -> f32 {
        assert!(col < self.width, "column {col} out of range");
        self.heights[row * self.width + col]
    }

    /// One row of samples.
    pub fn row(&self, row: usize) -> &[f32] {
        &self.heights[row * self.width..(row + 1) * self.width]
    }

    /// Height at continuous sample coordinates (`col`, `row`) on the
    /// triangulated surface (see `terrain::query` for the split), clamped to
    /// the grid. Sample (r, c) is at exactly (c, r) and returns that sample.
    ///
    /// This is the height sampling the shaders mirror (`sample_height` in
    /// `glsl/terrain_common.glsl`). f64 keeps the weights exact enough that
    /// the f32 result at a sample is the sample itself.
    #[inline]
    pub fn interpolate(&self, col: f64, row: f64) -> f64 {
        let cell = locate_cell(self.width, self.depth, col, row);
        let upper = self.row(cell.row);
        let lower = self.row(cell.row + 1);
        blend_cell(
            &cell,
            [
                upper[cell.col],
                upper[cell.col + 1],
                lower[cell.col],
                lower[cell.col + 1],
            ],
        )
    }

    /// Smallest and largest height.
    pub fn min_max(&self) -> (f32, f32) {
        self.heights.par_chunks(1 << 16).map(min_max_of).reduce(
            || (f32::INFINITY, f32::NEG_INFINITY),
            |a, b| (a.0.min(b.0), a.1.max(b.1)),
        )
    }

    /// Each sample replaced by the mean of itself and its in-bounds
    /// neighbours in a 3x3 window, all read from the unsmoothed input (so the
    /// result does not depend on traversal order). Border samples average
    /// fewer neighbours rather than reading outside the grid.
    pub fn smoothed(&self) -> Heightmap {
        let (w, d) = (self.width, self.depth);
        let mut out = vec![0.0f32; w * d];
        out.par_chunks_mut(w).enumerate().for_each(|(r, out_row)| {
            let rows = r.saturating_sub(1)..=(r + 1).min(d - 1);
            for (c, out) in out_row.iter_mut().enumerate() {
                let cols = c.saturating_sub(1)..=(c + 1).min(w - 1);
                let mut sum = 0.0f64;
                let mut n = 0u32;
                for rr in rows.clone() {
                    for v in &self.row(rr)[cols.clone()] {
                        sum += f64::from(*v);
                        n += 1;
                    }
                }
                *out = (sum / f64::from(n)) as f32;
            }
        });
        Heightmap {
            width: w,
            depth: d,
            heights: out,
        }
    }
}

pub(crate) fn min_max_of(values: &[f32]) -> (f32, f32) {
    values
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        })
}

/// The cell a continuous sample position (`col`, `row`) falls in, clamped
/// to a grid of `width` x `depth` samples, and the position's fractions
/// across it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellPoint {
    /// The cell's upper-left sample.
    pub row: usize,
    pub col: usize,
    /// Fractions across (s) and down (t) the cell, in [0, 1].
    pub s: f64,
    pub t: f64,
}

/// Finds the cell of `Heightmap::interpolate` (and of every reader that
/// mirrors it): the last row or column has no cell of its own, so a point
/// on it belongs to the cell before, at s or t = 1.
#[inline]
pub fn locate_cell(width: usize, depth: usize, col: f64, row: f64) -> CellPoint {
    let max_c = (width - 1) as f64;
    let max_r = (depth - 1) as f64;
    let (c, r) = (col.clamp(0.0, max_c), row.clamp(0.0, max_r));
    let c0 = (c as usize).min(width - 2);
    let r0 = (r as usize).min(depth - 2);
    CellPoint {
        row: r0,
        col: c0,
        s: c - c0 as f64,
        t: r - r0 as f64,
    }
}

/// The height at `cell`'s point on the cell's two triangles, from its
/// samples [A upper-left, B upper-right, C lower-left, D lower-right]
/// (see `terrain::query` for the split).
#[inline]
pub fn blend_cell(cell: &CellPoint, [a, b, c, d]: [f32; 4]) -> f64 {
    let (a, b, cc, d) = (f64::from(a), f64::from(b), f64::from(c), f64::from(d));
    let (s, t) = (cell.s, cell.t);
    // Triangle ABC weighs A, B, C by (1 - s - t, s, t); triangle DCB
    // weighs D, C, B by (1 - u - v, u, v) with u = 1 - s, v = 1 - t. The
    // choice is a select rather than a branch: which side of the
    // diagonal a query falls on is unpredictable.
    let lower_triangle = s + t > 1.0;
    let (p, q, w) = if lower_triangle {
        (d, cc, b)
    } else {
        (a, b, cc)
    };
    let (u, v) = if lower_triangle {
        (1.0 - s, 1.0 - t)
    } else {
        (s, t)
    };
    (1.0 - u - v) * p + u * q + v * w
}

/// Refuses the first non-finite height of rows `first_row..` of a map
/// `width` samples wide, naming its position.
pub(crate) fn check_finite(
    path: &Path,
    width: usize,
    first_row: usize,
    heights: &[f32],
) -> Result<(), HeightmapError> {
    match heights.iter().position(|h| !h.is_finite()) {
        None => Ok(()),
        Some(i) => Err(HeightmapError::NonFinite {
            path: path.to_path_buf(),
            row: (first_row + i / width) as u64,
            col: (i % width) as u64,
            value: heights[i],
        }),
    }
}

/// Validates width, depth, overflow and the sample limit.
fn check_size(path: &Path, width: u64, depth: u64, limit: u64) -> Result<u64, HeightmapError> {
    let path = path.to_path_buf();
    if width < 2 || depth < 2 {
        return Err(HeightmapError::TooSmall { path, width, depth });
    }
    let samples = width
        .checked_mul(depth)
        .filter(|&s| usize::try_from(s).is_ok())
        .ok_or(HeightmapError::SizeOverflow {
            path: path.clone(),
            width,
            depth,
        })?;
    if samples > limit {
        return Err(HeightmapError::TooManySamples {
            path,
            width,
            depth,
            samples,
            limit,
        });
    }
    Ok(samples)
}

/// Width and depth of headerless data of `len` bytes, checked against the
/// size the caller gave (or inferred as a square), the limit, and the length.
fn raw_shape(
    path: &Path,
    format: HeightmapFormat,
    opts: &LoadOptions,
    len: u64,
) -> Result<(usize, usize), HeightmapError> {
    let bytes_per_sample = format
        .raw_sample_bytes()
        .expect("raw_shape is only called for headerless formats");
    let (width, depth) = match (format, opts.size) {
        (_, Some(size)) => size,
        (HeightmapFormat::Hgt, None) => match len {
            2_884_802 => (1201, 1201),
            25_934_402 => (3601, 3601),
            actual => {
                return Err(HeightmapError::HgtSize {
                    path: path.to_path_buf(),
                    actual,
                })
            }
        },
        (_, None) => {
            let side = (len % bytes_per_sample == 0)
                .then(|| integer_sqrt(len / bytes_per_sample))
                .flatten()
                .ok_or(HeightmapError::CannotInferSize {
                    path: path.to_path_buf(),
                    format: format.name(),
                    actual: len,
                })?;
            (side, side)
        }
    };
    let samples = check_size(path, width, depth, opts.max_samples)?;
    let expected = samples
        .checked_mul(bytes_per_sample)
        .ok_or(HeightmapError::SizeOverflow {
            path: path.to_path_buf(),
            width,
            depth,
        })?;
    if expected != len {
        return Err(HeightmapError::LengthMismatch {
            path: path.to_path_buf(),
            format: format.name(),
            width,
            depth,
            expected,
            actual: len,
        });
    }
    Ok((width as usize, depth as usize))
}

/// The width and depth of a headerless file of `len` bytes, checked as
/// `Heightmap::load` checks them, without reading it.
pub(crate) fn headerless_shape(
    path: &Path,
    format: HeightmapFormat,
    opts: &LoadOptions,
    len: u64,
) -> Result<(usize, usize), HeightmapError> {
    if len == 0 {
        return Err(HeightmapError::Empty {
            path: path.to_path_buf(),
        });
    }
    // Streamed, so the whole-load sample limit does not apply.
    let opts = LoadOptions {
        max_samples: u64::MAX,
        ..opts.clone()
    };
    raw_shape(path, format, &opts, len)
}

/// The exact square root of `n`, if `n` is a perfect square.
fn integer_sqrt(n: u64) -> Option<u64> {
    let guess = (n as f64).sqrt() as u64;
    (guess.saturating_sub(1)..=guess + 1).find(|s| s.checked_mul(*s) == Some(n))
}

fn map_integer(v: f64, max: f64, opts: &LoadOptions) -> f32 {
    integer_height(v, max, opts.height_scale, opts.height_offset)
}

/// The height of an integer sample `v` of a format whose largest value is
/// `max`: `scale * v / max + offset` in f64, rounded once to f32. Tiled
/// terrains store integer samples with the same mapping, so they read back
/// bit for bit.
#[inline]
pub fn integer_height(v: f64, max: f64, scale: f64, offset: f64) -> f32 {
    (scale * v / max + offset) as f32
}

fn decode_raw(
    bytes: &[u8],
    format: HeightmapFormat,
    width: usize,
    opts: &LoadOptions,
    path: &Path,
) -> Result<Vec<f32>, HeightmapError> {
    match format {
        HeightmapFormat::Hgt => {
            let raw: Vec<i16> = bytes
                .chunks_exact(2)
                .map(|b| i16::from_be_bytes([b[0], b[1]]))
                .collect();
            let filled = fill_hgt_voids(&raw, width).ok_or(HeightmapError::AllVoid {
                path: path.to_path_buf(),
            })?;
            let max = format.integer_max().expect("an integer format");
            Ok(filled
                .par_iter()
                .map(|&v| map_integer(v, max, opts))
                .collect())
        }
        _ => decode_raw_rows(bytes, format, width, 0, opts, path),
    }
}

/// Heights of whole rows of a headerless raw8, raw16, raw16be or f32 file,
/// the first of them row `first_row` of the map (.hgt is not read by rows:
/// its voids are filled from the whole map). A non-finite float sample is
/// an error naming its position.
pub(crate) fn decode_raw_rows(
    bytes: &[u8],
    format: HeightmapFormat,
    width: usize,
    first_row: usize,
    opts: &LoadOptions,
    path: &Path,
) -> Result<Vec<f32>, HeightmapError> {
    let max = format.integer_max().unwrap_or(1.0);
    let heights = match format {
        HeightmapFormat::Raw8 => bytes
            .par_iter()
            .map(|&v| map_integer(f64::from(v), max, opts))
            .collect(),
        HeightmapFormat::Raw16 => bytes
            .par_chunks_exact(2)
            .map(|b| map_integer(f64::from(u16::from_le_bytes([b[0], b[1]])), max, opts))
            .collect(),
        HeightmapFormat::Raw16Be => bytes
            .par_chunks_exact(2)
            .map(|b| map_integer(f64::from(u16::from_be_bytes([b[0], b[1]])), max, opts))
            .collect(),
        HeightmapFormat::F32 => {
            let raw: Vec<f32> = bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            // Non-finite input is an error in the data, reported with its
            // position, not something a mapping should hide.
            check_finite(path, width, first_row, &raw)?;
            raw.par_iter()
                .map(|&v| (opts.height_scale * f64::from(v) + opts.height_offset) as f32)
                .collect()
        }
        HeightmapFormat::Hgt | HeightmapFormat::Png => {
            unreachable!("{format} is not read by rows")
        }
    };
    Ok(heights)
}

/// Replaces SRTM voids by the mean of their valid 8-neighbours, growing
/// inwards one ring per pass so large holes fill from their rims. Each pass
/// reads only values that were valid when it began, so the result does not
/// depend on scan order. None when every sample is a void.
fn fill_hgt_voids(raw: &[i16], width: usize) -> Option<Vec<f64>> {
    let depth = raw.len() / width;
    let mut values: Vec<f64> = raw.iter().map(|&v| f64::from(v)).collect();
    let mut valid: Vec<bool> = raw.iter().map(|&v| v != HGT_VOID).collect();
    let mut voids: Vec<usize> = (0..raw.len()).filter(|&i| !valid[i]).collect();
    if voids.len() == raw.len() {
        return None;
    }
    while !voids.is_empty() {
        let mut filled = Vec::new();
        voids.retain(|&i| {
            let (r, c) = (i / width, i % width);
            let mut sum = 0.0;
            let mut n = 0u32;
            for rr in r.saturating_sub(1)..=(r + 1).min(depth - 1) {
                for cc in c.saturating_sub(1)..=(c + 1).min(width - 1) {
                    let j = rr * width + cc;
                    if valid[j] {
                        sum += values[j];
                        n += 1;
                    }
                }
            }
            if n == 0 {
                return true;
            }
            filled.push((i, sum / f64::from(n)));
            false
        });
        for (i, v) in filled {
            values[i] = v;
            valid[i] = true;
        }
    }
    Some(values)
}

fn decode_png(
    bytes: &[u8],
    opts: &LoadOptions,
    path: &Path,
) -> Result<(usize, usize, Vec<f32>), HeightmapError> {
    let not_png = |e: image::ImageError| HeightmapError::NotPng {
        path: path.to_path_buf(),
        reason: e.to_string(),
    };
    let decoder = PngDecoder::new(std::io::Cursor::new(bytes)).map_err(not_png)?;
    let (w, h) = decoder.dimensions();
    check_size(path, u64::from(w), u64::from(h), opts.max_samples)?;
    // The decoder expands sub-byte and palette images to 8 bits, so their
    // original layout is read from the IHDR chunk (validated by the decoder
    // above): bit depth at byte 24, colour type at byte 25.
    let (bit_depth, color_type) = (bytes[24], bytes[25]);
    let color_name = match color_type {
        0 => "grayscale",
        2 => "RGB",
        3 => "indexed (palette)",
        4 => "grayscale+alpha",
        6 => "RGBA",
        _ => "unknown",
    };
    let color_name = format!("{bit_depth}-bit {color_name}");
    if !matches!(bit_depth, 8 | 16) || !matches!(color_type, 0 | 2 | 4 | 6) {
        // Sub-byte grayscale and palettes: the sample values would not mean
        // heights on a known scale.
        return Err(HeightmapError::UnsupportedPng {
            path: path.to_path_buf(),
            color: color_name,
        });
    }
    if color_type != 0 && !opts.luminance {
        return Err(HeightmapError::ColorPng {
            path: path.to_path_buf(),
            color: color_name,
        });
    }
    let sixteen = bit_depth == 16;
    let image = image::DynamicImage::from_decoder(decoder).map_err(not_png)?;
    let heights = if sixteen {
        image
            .to_luma16()
            .into_raw()
            .par_iter()
            .map(|&v| map_integer(f64::from(v), 65535.0, opts))
            .collect()
    } else {
        image
            .to_luma8()
            .into_raw()
            .par_iter()
            .map(|&v| map_integer(f64::from(v), 255.0, opts))
            .collect()
    };
    Ok((w as usize, h as usize, heights))
}

/// Loads untrusted `data` as `format` with options drawn from its first
/// three bytes (a size for headerless data or none, a height scale,
/// smoothing and luminance), then checks what a successful load promises:
/// at least 2x2 samples within the sample limit, all finite. Returns whether
/// it loaded. The fuzz targets (fuzz/) and their regression tests call this.
pub fn fuzz_load(data: &[u8], format: HeightmapFormat) -> bool {
    /// Small enough that a fuzzer's size bytes cannot exhaust memory.
    const FUZZ_MAX_SAMPLES: u64 = 1 << 22;
    let (head, body) = data.split_at(data.len().min(3));
    let byte = |i: usize| head.get(i).copied().unwrap_or(0);
    let opts = LoadOptions {
        format: Some(format),
        size: (byte(0) & 1 == 0).then(|| (u64::from(byte(0) >> 1) + 1, u64::from(byte(1)) + 1)),
        height_scale: [1.0, 65535.0, -3.5, 1e30][usize::from(byte(2) & 3)],
        height_offset: 0.0,
        smooth: byte(2) & 4 != 0,
        luminance: byte(2) & 8 != 0,
        max_samples: FUZZ_MAX_SAMPLES,
    };
    match Heightmap::from_bytes(body, format, &opts, Path::new("fuzz-input")) {
        Ok(map) => {
            assert!(
                map.width() >= 2 && map.depth() >= 2,
                "a map smaller than 2x2"
            );
            assert!(
                (map.width() * map.depth()) as u64 <= FUZZ_MAX_SAMPLES,
                "the sample limit was passed"
            );
            assert_eq!(map.heights().len(), map.width() * map.depth());
            assert!(
                map.heights().iter().all(|h| h.is_finite()),
                "a non-finite height"
            );
            true
        }
        Err(_) => false,
    }
}
