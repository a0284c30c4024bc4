//! Parsers for the numeric argument forms (`WxD`, `X[,Z]`, `X,Z`). Each
//! rejects non-finite numbers and trailing junk with a message that quotes
//! the input.

use std::path::PathBuf;

use clap::Args;
use glam::{DVec2, DVec3};

use crate::scene::{HeightmapSource, Lighting, Scene, SceneFileError};

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
        let n = v
            .trim()
            .parse::<u64>()
            .map_err(|_| format!("size {s:?}: {name} {v:?} is not a whole number"))?;
        if n < 2 {
            return Err(format!("size {s:?}: {name} must be at least 2 samples"));
        }
        Ok(n)
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

/// `X,Y,Z`: a point in space.
pub fn parse_dvec3(s: &str) -> Result<DVec3, String> {
    let parts: Vec<&str> = s.split(',').collect();
    let [x, y, z] = parts[..] else {
        return Err(format!("{s:?} is not of the form X,Y,Z"));
    };
    Ok(DVec3::new(
        parse_f64(x, "x")?,
        parse_f64(y, "y")?,
        parse_f64(z, "z")?,
    ))
}

/// `A,B`: two finite numbers with A <= B.
pub fn parse_range(s: &str) -> Result<(f32, f32), String> {
    let (a, b) = s
        .split_once(',')
        .ok_or_else(|| format!("{s:?} is not of the form MIN,MAX"))?;
    let (a, b) = (parse_f64(a, "min")? as f32, parse_f64(b, "max")? as f32);
    if !a.is_finite() || !b.is_finite() {
        return Err(format!("{s:?} is out of range"));
    }
    if a <= b {
        Ok((a, b))
    } else {
        Err(format!("{s:?}: MIN must not exceed MAX"))
    }
}

/// `R,G,B` with each in [0, 1].
pub fn parse_color(s: &str) -> Result<[f32; 3], String> {
    let v = parse_dvec3(s)?;
    if v.min_element() >= 0.0 && v.max_element() <= 1.0 {
        Ok(v.as_vec3().to_array())
    } else {
        Err(format!("colour {s:?}: components must be in [0, 1]"))
    }
}

/// A field of view in degrees, strictly between 0 and 180.
pub fn parse_fov(s: &str) -> Result<f32, String> {
    // Checked after narrowing: 1e-50 is positive, but not as an f32.
    let v = parse_f64(s, "field of view")? as f32;
    if v > 0.0 && v < 180.0 {
        Ok(v)
    } else {
        Err(format!(
            "field of view {s:?} must be between 0 and 180 degrees"
        ))
    }
}

/// An image dimension: 1 to 16384 pixels.
pub fn parse_pixels(s: &str) -> Result<u32, String> {
    let v: u32 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a whole number of pixels"))?;
    if (1..=16384).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} pixels is outside 1..=16384"))
    }
}

/// Which terrain to use: the built-in default scene, or a heightmap file.
/// Options left out keep the scene's values (for a file: scale 1, offset 0,
/// spacing 1, origin 0).
#[derive(Args, Clone, Debug)]
pub struct TerrainArgs {
    /// Scene file (TOML); without it and without --heightmap, the built-in
    /// default scene (assets/scenes/default.toml).
    #[arg(long, value_name = "PATH", conflicts_with = "heightmap")]
    pub scene: Option<PathBuf>,

    /// Heightmap file, instead of a scene.
    #[arg(long, value_name = "PATH")]
    pub heightmap: Option<PathBuf>,

    #[command(flatten)]
    pub samples: SampleArgs,

    /// World distance between samples along x and z (one number for both).
    #[arg(long, value_name = "X[,Z]", value_parser = parse_spacing)]
    pub cell_spacing: Option<DVec2>,

    /// World (x, z) of the terrain's centre.
    #[arg(long, value_name = "X,Z", value_parser = parse_point, allow_hyphen_values = true)]
    pub origin: Option<DVec2>,

    /// Average each sample with its 3x3 neighbourhood after loading.
    #[arg(long)]
    pub smooth: bool,

    /// Accept colour PNGs, using their luminance.
    #[arg(long)]
    pub luminance: bool,

    /// Refuse heightmaps with more samples than this (checked before
    /// allocating).
    #[arg(long, value_name = "N")]
    pub max_samples: Option<u64>,
}

/// How a heightmap file's samples are read and mapped to heights.
#[derive(Args, Clone, Debug)]
pub struct SampleArgs {
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
    #[arg(long, value_name = "S", value_parser = parse_finite, allow_negative_numbers = true)]
    pub height_scale: Option<f64>,

    /// Added to every height after scaling.
    #[arg(long, value_name = "O", value_parser = parse_finite, allow_negative_numbers = true)]
    pub height_offset: Option<f64>,
}

impl SampleArgs {
    /// Applies the options given over `load`'s.
    pub fn apply(&self, load: &mut LoadOptions) {
        load.format = self.format.or(load.format);
        load.size = self.size.or(load.size);
        load.height_scale = self.height_scale.unwrap_or(load.height_scale);
        load.height_offset = self.height_offset.unwrap_or(load.height_offset);
    }
}

pub fn parse_format(s: &str) -> Result<HeightmapFormat, String> {
    s.parse()
        .map_err(|e: crate::terrain::heightmap::UnknownFormatName| e.to_string())
}

impl TerrainArgs {
    /// The scene these arguments describe: a scene file, the default scene,
    /// or a heightmap file, with the options given applied.
    pub fn scene(&self) -> Result<Scene, SceneFileError> {
        let mut scene = match &self.scene {
            Some(path) => Scene::load(path)?,
            None => Scene::default_scene(),
        };
        if let Some(path) = &self.heightmap {
            scene.heightmap = HeightmapSource::File(path.clone());
            scene.load = LoadOptions::default();
            scene.cell_spacing = DVec2::ONE;
            scene.origin = DVec2::ZERO;
            scene.camera = None;
            // The default look belongs to its own heightmap (its blend map,
            // fog distances): a bare heightmap is coloured by height.
            scene.material = None;
            scene.lightmap = false;
            scene.fog = None;
            scene.lighting = Lighting::default();
            // Nor do its LOD distances, meant for its 8 km: a heightmap of
            // any size gets the error LOD at 1 px (and distances in
            // proportion to it when the distance LOD is asked for).
            scene.lod = None;
            scene.pixel_error = Some(crate::scene::DEFAULT_PIXEL_ERROR);
            // A tiled terrain brings the patch size its tables were stored
            // for, which streaming needs.
            if let Some(n) = crate::terrain::tiled::TiledHeightmap::stored_patch_size(path) {
                scene.cells_per_patch = n;
            }
        }
        let load = &mut scene.load;
        self.samples.apply(load);
        load.smooth |= self.smooth;
        load.luminance |= self.luminance;
        load.max_samples = self.max_samples.unwrap_or(load.max_samples);
        scene.cell_spacing = self.cell_spacing.unwrap_or(scene.cell_spacing);
        scene.origin = self.origin.unwrap_or(scene.origin);
        Ok(scene)
    }
}

/// Image or window size in pixels.
#[derive(Args, Clone, Copy, Debug)]
pub struct SizeArgs {
    /// Width in pixels.
    #[arg(long, value_name = "W", default_value = "1280", value_parser = parse_pixels)]
    pub width: u32,

    /// Height in pixels.
    #[arg(long, value_name = "H", default_value = "720", value_parser = parse_pixels)]
    pub height: u32,
}

/// An optional device feature `--without` can take away.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Feature {
    /// tessellationShader: the tess path falls back to geomip.
    Tessellation,
    /// fillModeNonSolid: no wireframe.
    FillModeNonSolid,
    /// pipelineStatisticsQuery: triangle counts are unavailable.
    PipelineStatistics,
    /// samplerAnisotropy: textures are filtered without anisotropy.
    SamplerAnisotropy,
    /// Timestamp queries: GPU time is unavailable.
    Timestamps,
    /// Sampled depth attachments: no occlusion culling.
    SampledDepth,
    /// multiDrawIndirect: each patch batch is its own draw call.
    MultiDrawIndirect,
}

/// Features to treat as missing, to run the fallbacks on any device.
#[derive(Args, Clone, Debug)]
pub struct FeatureArgs {
    /// Behave as if the device lacked FEATURE (repeat for more);
    /// `--without tessellation` draws with the geomip path, as on a device
    /// without tessellation shaders.
    #[arg(long = "without", value_enum, value_name = "FEATURE")]
    pub without: Vec<Feature>,

    /// Refuse to allocate more than this much GPU memory, with an error
    /// naming the resource that would exceed it. A streamed terrain sizes
    /// its pool of resident tiles to fit.
    #[arg(long, value_name = "MIB", value_parser = parse_budget)]
    pub gpu_memory_budget: Option<u64>,

    /// Upload a tiled terrain (from `vkterrain import`) whole, as other
    /// heightmaps are, instead of streaming its tiles within the budget.
    #[arg(long)]
    pub no_streaming: bool,

    /// Make the device fail, to see how it is reported: `device-lost[@N]`
    /// reports the Nth queue submission (default 1, uploads included) and
    /// all after it lost; `out-of-memory[@N]` fails the Nth allocation.
    #[arg(long, value_name = "FAULT", value_parser = parse_fault)]
    pub inject_fault: Option<crate::gpu::Fault>,

    /// Use the device whose name contains NAME (any case), such as
    /// llvmpipe; also VKTERRAIN_DEVICE. Default: the best device.
    #[arg(long, value_name = "NAME")]
    pub device: Option<String>,
}

/// `--samples`: 1, 2, 4 or 8 samples per pixel.
pub fn parse_samples(s: &str) -> Result<u32, String> {
    match s.trim().parse::<u32>() {
        Ok(n @ (1 | 2 | 4 | 8)) => Ok(n),
        _ => Err(format!("{s:?}: expected 1, 2, 4 or 8 samples per pixel")),
    }
}

pub fn parse_fault(s: &str) -> Result<crate::gpu::Fault, String> {
    let (kind, n) = match s.split_once('@') {
        Some((kind, n)) => {
            let n: u32 =
                n.parse().ok().filter(|&n| n >= 1).ok_or_else(|| {
                    format!("--inject-fault {s:?}: N must be a whole number from 1")
                })?;
            (kind, n)
        }
        None => (s, 1),
    };
    match kind {
        "device-lost" => Ok(crate::gpu::Fault::DeviceLost { submission: n }),
        "out-of-memory" => Ok(crate::gpu::Fault::OutOfDeviceMemory { allocation: n }),
        _ => Err(format!(
            "--inject-fault {s:?}: expected device-lost[@N] or out-of-memory[@N]"
        )),
    }
}

pub fn parse_budget(s: &str) -> Result<u64, String> {
    let mib: u64 = s
        .trim()
        .parse()
        .map_err(|_| format!("--gpu-memory-budget {s:?} is not a whole number of MiB"))?;
    if mib == 0 {
        return Err("--gpu-memory-budget must be at least 1 MiB".into());
    }
    mib.checked_mul(1 << 20)
        .ok_or_else(|| format!("--gpu-memory-budget {s:?} MiB is too large"))
}

impl FeatureArgs {
    /// How to open the device these options describe.
    pub fn gpu_options(&self, validate: bool) -> crate::gpu::GpuOptions {
        crate::gpu::GpuOptions {
            validate,
            disabled: self.disabled(),
            memory_budget: self.gpu_memory_budget,
            fault: self.inject_fault,
            device: self.device.clone(),
            ..Default::default()
        }
    }

    /// Opens the device, runs `work` with it, then tears it down and counts
    /// validation messages after the device is destroyed, so leaked
    /// objects count (see `with_gpu`).
    pub fn with_gpu<T>(
        &self,
        validate: bool,
        work: impl FnOnce(&crate::gpu::Gpu) -> anyhow::Result<T>,
    ) -> anyhow::Result<(T, crate::gpu::ValidationReport)> {
        with_gpu(&self.gpu_options(validate), work)
    }

    pub fn disabled(&self) -> crate::gpu::DisabledFeatures {
        let off = |f| self.without.contains(&f);
        crate::gpu::DisabledFeatures {
            tessellation_shader: off(Feature::Tessellation),
            fill_mode_non_solid: off(Feature::FillModeNonSolid),
            pipeline_statistics_query: off(Feature::PipelineStatistics),
            sampler_anisotropy: off(Feature::SamplerAnisotropy),
            timestamps: off(Feature::Timestamps),
            sampled_depth: off(Feature::SampledDepth),
            multi_draw_indirect: off(Feature::MultiDrawIndirect),
        }
    }
}

/// Opens the device, runs `work` with it, then tears it down and counts
/// validation messages after the device is destroyed, so objects left
/// alive count too. A run that worked fails if validation reported
/// anything; a run that failed says so as well, naming its own error.
pub fn with_gpu<T>(
    options: &crate::gpu::GpuOptions,
    work: impl FnOnce(&crate::gpu::Gpu) -> anyhow::Result<T>,
) -> anyhow::Result<(T, crate::gpu::ValidationReport)> {
    use anyhow::Context;
    let gpu = crate::gpu::Gpu::open(options).context("starting Vulkan")?;
    let result = work(&gpu);
    let report = gpu.shutdown();
    match result {
        Ok(value) => {
            report.check()?;
            Ok((value, report))
        }
        Err(e) => Err(crate::app::with_validation(e, &report)),
    }
}

/// A command's arguments as clap parses `args`: with none given, its
/// defaults, which are written once, in the `#[arg]` attributes.
pub fn parse_args<T: clap::Args + clap::FromArgMatches>(args: &[&str]) -> anyhow::Result<T> {
    let command = T::augment_args(clap::Command::new("vkterrain").no_binary_name(true));
    let matches = command.try_get_matches_from(args)?;
    Ok(T::from_arg_matches(&matches)?)
}
