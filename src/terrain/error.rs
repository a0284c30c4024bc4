//! Typed errors of the terrain model. Every variant names the input it is
//! about (a file path, or the parameter) and what is wrong with it.

use std::path::PathBuf;

/// Why a heightmap could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum HeightmapError {
    #[error("{path}: file not found")]
    Missing { path: PathBuf },

    #[error("{path}: cannot read: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    #[error("{path}: file is empty")]
    Empty { path: PathBuf },

    #[error("{path}: not a tiled terrain: a .vkt file starts with the header that `vkterrain import` and `generate` write")]
    NotTiled { path: PathBuf },

    #[error("{path}: unknown heightmap format {name:?} (expected raw8, raw16, raw16be, png, hgt or f32)")]
    UnknownFormat { path: PathBuf, name: String },

    #[error("{path}: size {width}x{depth} is too small; a heightmap needs at least 2x2 samples")]
    TooSmall {
        path: PathBuf,
        width: u64,
        depth: u64,
    },

    #[error("{path}: size {width}x{depth} overflows the sample count")]
    SizeOverflow {
        path: PathBuf,
        width: u64,
        depth: u64,
    },

    #[error("{path}: size {width}x{depth} is {samples} samples, over the limit of {limit}")]
    TooManySamples {
        path: PathBuf,
        width: u64,
        depth: u64,
        samples: u64,
        limit: u64,
    },

    #[error(
        "{path}: {format} data of {width}x{depth} samples needs {expected} bytes, but the file has {actual} ({})",
        if actual < expected { "too short" } else { "too long" }
    )]
    LengthMismatch {
        path: PathBuf,
        format: &'static str,
        width: u64,
        depth: u64,
        expected: u64,
        actual: u64,
    },

    #[error("{path}: cannot infer the size of {actual} bytes of {format} data: not a square number of samples; give the size (--size WxD)")]
    CannotInferSize {
        path: PathBuf,
        format: &'static str,
        actual: u64,
    },

    #[error("{path}: an SRTM .hgt file must be 1201x1201 or 3601x3601 samples, but it has {actual} bytes")]
    HgtSize { path: PathBuf, actual: u64 },

    #[error("{path}: every sample is a void (-32768); nothing to fill them from")]
    AllVoid { path: PathBuf },

    #[error("{path}: sample at row {row}, column {col} is {value}, not a finite number")]
    NonFinite {
        path: PathBuf,
        row: u64,
        col: u64,
        value: f32,
    },

    #[error("{path}: not a valid PNG: {reason}")]
    NotPng { path: PathBuf, reason: String },

    #[error("{path}: PNG colour type {color} is not grayscale; ask for luminance conversion (--luminance) to use it")]
    ColorPng { path: PathBuf, color: String },

    #[error("{path}: PNG colour type {color} is not supported (use 8- or 16-bit grayscale)")]
    UnsupportedPng { path: PathBuf, color: String },

    #[error("{path}: an imported (tiled) terrain's heights were fixed by `vkterrain import`; {option} applies to the import, not here")]
    TiledOption { path: PathBuf, option: &'static str },

    #[error(transparent)]
    Tiled(#[from] TiledError),

    #[error("{path}: height scale {scale} and offset {offset} must be finite")]
    BadMapping {
        path: PathBuf,
        scale: f64,
        offset: f64,
    },
}

/// Why terrain parameters are unusable.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TerrainError {
    #[error("cells per patch must be a power of two from 2 to 64, got {0}")]
    CellsPerPatch(u32),

    #[error("cell spacing must be positive and finite, got x={x}, z={z}")]
    CellSpacing { x: f64, z: f64 },

    #[error("world origin must be finite, got ({x}, {z})")]
    Origin { x: f64, z: f64 },

    #[error("Y-bounds margin must be finite and not negative, got {0}")]
    Margin(f32),

    /// A tiled terrain's file could not give what the model needs (the
    /// message names the file and the tile).
    #[error("{0}")]
    Tiled(String),
}

/// Why a tiled terrain could not be read or written. Every variant names
/// the file; those about one tile name the tile and level too.
#[derive(Debug, thiserror::Error)]
pub enum TiledError {
    // The reason follows in the error's source chain.
    #[error("{path}: cannot read")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    #[error("{path}: file not found")]
    Missing { path: PathBuf },

    #[error("{path}: cannot write")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    #[error("{path}: not a tiled terrain (no vkterrain tiled header)")]
    NotTiled { path: PathBuf },

    #[error("{path}: tiled terrain version {found}, but this build reads version {reads}; import the source heightmap again")]
    Version {
        path: PathBuf,
        found: u32,
        reads: u32,
    },

    #[error("{path}: corrupt tiled terrain header: {what}")]
    Header { path: PathBuf, what: String },

    #[error("{path}: corrupt tiled terrain directory: {what}")]
    Directory { path: PathBuf, what: String },

    #[error("{path}: corrupt tiled terrain error tables: {what}")]
    Tables { path: PathBuf, what: String },

    #[error("{path}: tile ({tx}, {tz}) level {level}: {what}")]
    Tile {
        path: PathBuf,
        tx: u32,
        tz: u32,
        level: u32,
        what: String,
    },

    #[error("{path}: tiled terrain of {width}x{depth} samples is {samples} samples, over the limit of {limit} for loading it whole, which this command does (--max-samples raises it; the window, `render`, `soak` and `stream` read a tiled terrain a tile at a time unless given --no-streaming)")]
    TooLarge {
        path: PathBuf,
        width: u64,
        depth: u64,
        samples: u64,
        limit: u64,
    },

    #[error("cells per tile must be a power of two from {min} to {max}, got {got}")]
    TileCells { got: u32, min: u32, max: u32 },

    #[error("{path}: {what}")]
    Input { path: PathBuf, what: String },

    /// An input the heightmap loaders refused, with their reason.
    #[error(transparent)]
    Load(Box<HeightmapError>),
}

impl TiledError {
    /// An I/O error on `path`; a missing file says so plainly.
    pub fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        if source.kind() == std::io::ErrorKind::NotFound {
            TiledError::Missing {
                path: path.to_path_buf(),
            }
        } else {
            TiledError::Io {
                path: path.to_path_buf(),
                source,
            }
        }
    }
}
