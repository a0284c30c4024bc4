//! Parsers for the numeric argument forms (`WxD`, `X[,Z]`, `X,Z`). Each
//! rejects non-finite numbers and trailing junk with a message that quotes
//! the input.

use std::path::PathBuf;

use clap::Args;
use glam::DVec2;

use crate::terrain::heightmap::DEFAULT_MAX_SAMPLES;
use crate::terrain::{HeightmapFormat, LoadOptions};

fn parse_f64(s: &str, what: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{what} {s:?} is not a number"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{what} {s:?} is not finite"))
    }
}

/// A finite number.
pub fn parse_finite(s: &str) -> Result<f64, String> {
    parse_f64(s, "value")
}

/// `WxD`: width (columns) and depth (rows) in samples.
pub fn parse_size(s: &str) -> Result<(u64, u64), String> {
    let (w, d) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("size {s:?} is not of the form WxD (for example 403x344)"))?;
    let dim = |v: &str, name: &str| {
        v.trim()
            .parse::<u64>()
            .map_err(|_| format!("size {s:?}: {name} {v:?} is not a whole number"))
    };
    Ok((dim(w, "width")?, dim(d, "depth")?))
}

/// `X,Z`: a point in the xz-plane.
pub fn parse_point(s: &str) -> Result<DVec2, String> {
    let (x, z) = s
        .split_once(',')
        .ok_or_else(|| format!("point {s:?} is not of the form X,Z"))?;
    Ok(DVec2::new(parse_f64(x, "x")?, parse_f64(z, "z")?))
}

/// `X` or `X,Z`: cell spacing, the same along both axes when one number is
/// given. Must be positive.
pub fn parse_spacing(s: &str) -> Result<DVec2, String> {
    let spacing = match s.split_once(',') {
        Some((x, z)) => DVec2::new(parse_f64(x, "x spacing")?, parse_f64(z, "z spacing")?),
        None => DVec2::splat(parse_f64(s, "spacing")?),
    };
    if spacing.x > 0.0 && spacing.y > 0.0 {
        Ok(spacing)
    } else {
        Err(format!("cell spacing {s:?} must be positive"))
    }
}

/// Where the heightmap comes from and how it maps to world units; shared by
/// every command that loads a terrain.
#[derive(Args, Clone, Debug)]
pub struct HeightmapArgs {
    /// Heightmap file.
    #[arg(long, value_name = "PATH")]
    pub heightmap: PathBuf,

    /// File format; inferred from the extension when omitted
    /// (.r8 .r16/.raw .png .hgt .f32).
    #[arg(long, value_parser = parse_format)]
    pub format: Option<HeightmapFormat>,

    /// Samples across and down for headerless files, e.g. 403x344; square
    /// files are inferred.
    #[arg(long, value_name = "WxD", value_parser = parse_size)]
    pub size: Option<(u64, u64)>,

    /// Height of the format's largest value (255, 65535, or 32767 for .hgt);
    /// for float input, the factor applied to each sample.
    #[arg(long, value_name = "S", default_value_t = 1.0, value_parser = parse_finite, allow_negative_numbers = true)]
    pub height_scale: f64,

    /// Added to every height after scaling.
    #[arg(long, value_name = "O", default_value_t = 0.0, value_parser = parse_finite, allow_negative_numbers = true)]
    pub height_offset: f64,

    /// World distance between samples along x and z (one number for both).
    #[arg(long, value_name = "X[,Z]", default_value = "1", value_parser = parse_spacing)]
    pub cell_spacing: DVec2,

    /// World (x, z) of the terrain's centre.
    #[arg(long, value_name = "X,Z", default_value = "0,0", value_parser = parse_point, allow_hyphen_values = true)]
    pub origin: DVec2,

    /// Average each sample with its 3x3 neighbourhood after loading.
    #[arg(long)]
    pub smooth: bool,

    /// Accept colour PNGs, using their luminance.
    #[arg(long)]
    pub luminance: bool,

    /// Refuse heightmaps with more samples than this (checked before
    /// allocating).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_SAMPLES)]
    pub max_samples: u64,
}

fn parse_format(s: &str) -> Result<HeightmapFormat, String> {
    s.parse()
        .map_err(|e: crate::terrain::heightmap::UnknownFormatName| e.to_string())
}

impl HeightmapArgs {
    pub fn load_options(&self) -> LoadOptions {
        LoadOptions {
            format: self.format,
            size: self.size,
            height_scale: self.height_scale,
            height_offset: self.height_offset,
            smooth: self.smooth,
            luminance: self.luminance,
            max_samples: self.max_samples,
        }
    }
}
