//! Helpers shared by the integration tests.
#![allow(dead_code)] // each test binary uses a different subset

use std::path::{Path, PathBuf};

use glam::DVec2;
use vkterrain::terrain::{Heightmap, LoadOptions, TerrainInfo};

pub const DEM_WIDTH: usize = 403;
pub const DEM_DEPTH: usize = 344;
pub const DEM_SPACING: DVec2 = DVec2::new(74.48, 92.15);

pub fn data_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// The Jacksboro DEM in metres (scale 65535 undoes the v / 65535 mapping).
pub fn dem(file: &str, size: Option<(u64, u64)>) -> Heightmap {
    let opts = LoadOptions {
        size,
        height_scale: 65535.0,
        ..LoadOptions::default()
    };
    Heightmap::load(&data_path(file), &opts).expect("the DEM loads")
}

pub fn dem_info(cells_per_patch: u32) -> TerrainInfo {
    dem_info_at(cells_per_patch, DVec2::ZERO)
}

/// The DEM with its real spacing, centred on `origin`.
pub fn dem_info_at(cells_per_patch: u32, origin: DVec2) -> TerrainInfo {
    TerrainInfo::new(
        dem("jacksboro_fault_dem.png", None),
        DEM_SPACING,
        cells_per_patch,
        origin,
    )
    .expect("valid terrain parameters")
}

/// The DEM as a terrain with its real spacing, centred on `origin`.
pub fn dem_terrain(cells_per_patch: u32, origin: DVec2) -> vkterrain::terrain::Terrain {
    vkterrain::terrain::Terrain::new(dem_info_at(cells_per_patch, origin), 0.0)
        .expect("valid margin")
}

/// A deterministic pseudo-random heightmap: rough noise plus a slope, so
/// neighbouring samples differ and planes never fit exactly.
pub fn noise_map(width: usize, depth: usize, seed: u64) -> Heightmap {
    Heightmap::from_fn(width, depth, |r, c| {
        let mut x = seed ^ ((r as u64) << 32 | c as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        x ^= x >> 29;
        x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        x ^= x >> 32;
        (x % 10_000) as f32 * 0.01 + 0.05 * r as f32
    })
    .expect("valid size")
}

/// A map that steps from 0 to `height` halfway across.
pub fn cliff_map(width: usize, depth: usize, height: f32) -> Heightmap {
    Heightmap::from_fn(
        width,
        depth,
        |_, c| if c < width / 2 { 0.0 } else { height },
    )
    .expect("valid size")
}

/// Capabilities of a made-up device, for policies tested without one:
/// everything optional present, 1 or 4 samples per pixel.
pub fn test_capabilities() -> vkterrain::gpu::Capabilities {
    vkterrain::gpu::Capabilities {
        device_name: "test".into(),
        device_type: "discrete GPU".into(),
        driver_name: String::new(),
        driver_info: String::new(),
        api_version: "1.3.0".into(),
        tessellation_shader: true,
        fill_mode_non_solid: true,
        pipeline_statistics_query: true,
        sampler_anisotropy: true,
        multi_draw_indirect: true,
        draw_indirect_first_instance: true,
        fragment_stores_and_atomics: true,
        fragment_subgroup_ballot: true,
        max_draw_indirect_count: u32::MAX,
        timestamp_period_ns: None,
        timestamp_valid_bits: 0,
        max_tessellation_level: 64,
        max_image_dimension_2d: 4096,
        max_image_array_layers: 256,
        max_sampler_anisotropy: 16.0,
        sub_pixel_precision_bits: 8,
        sample_counts: vec![1, 4],
        occlusion_sample_counts: vec![1, 4],
    }
}

/// Writes bytes to a fresh file named `name` in a temporary directory.
pub fn temp_file(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).expect("temp file written");
    path
}

/// Runs the vkterrain binary in `dir` (its relative paths land there).
pub fn vkterrain_in(dir: &std::path::Path, args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_vkterrain"))
        .current_dir(dir)
        .args(args)
        .output()
        .expect("the binary runs")
}

/// The command-line options that load the Jacksboro DEM as `dem_info` does
/// (its samples, scale and spacing).
pub fn dem_args() -> Vec<String> {
    vec![
        "--heightmap".into(),
        data_path("jacksboro_fault_dem.r16").display().to_string(),
        "--size".into(),
        "403x344".into(),
        "--height-scale".into(),
        "65535".into(),
        "--cell-spacing".into(),
        "74.48,92.15".into(),
    ]
}

pub mod gpu;

/// Asserts that a command succeeded, showing its stderr where it did not,
/// and returns its stdout.
pub fn succeeded(out: &std::process::Output) -> String {
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A JSON file a command wrote (stats, reports).
pub fn json_file(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("the JSON file is written"))
        .expect("the file is JSON")
}

/// What a device's rasteriser and depth buffer resolve: the inputs of
/// `surface_height_tolerance`.
#[derive(Clone, Copy, Debug)]
pub struct RasterPrecision {
    /// subPixelPrecisionBits.
    pub sub_pixel_bits: u32,
    /// Significand bits of the depth format (24 for D32_SFLOAT).
    pub depth_significand_bits: u32,
}

/// How far apart in height a surface drawn on the GPU and the same
/// surface evaluated on the CPU may lie at a pixel, from the device's
/// precision alone, for a view `distance` metres from the surface whose
/// pixels span `pixel_metres` on ground rising at most `max_slope`:
/// - the rasteriser snaps each vertex to 1/2^bits of a pixel along x and
///   y, so the surface seen at a pixel centre moves sideways by at most
///   sqrt(2)/2 of that step, `pixel_metres` times it in metres, and its
///   height there by `max_slope` times that;
/// - depth is stored in a float, and positions are computed in f32
///   relative to the eye: the point rebuilt from a pixel's depth is off
///   along its ray by a few units of the last significand bit of its
///   distance (8 allowed).
pub fn surface_height_tolerance(
    precision: RasterPrecision,
    pixel_metres: f64,
    max_slope: f64,
    distance: f64,
) -> f64 {
    let snap = std::f64::consts::FRAC_1_SQRT_2
        * (-f64::from(precision.sub_pixel_bits)).exp2()
        * pixel_metres
        * max_slope;
    let depth = 8.0 * (-f64::from(precision.depth_significand_bits)).exp2() * distance;
    snap + depth
}

/// How far apart in height two renders of the same surface may lie at a
/// pixel whose ray, from `eye` with `pixels_per_radian`, meets the surface
/// at `point`, from the device's precision alone. Each render snaps its
/// vertices to 1/2^bits of a pixel, which moves the surface across the
/// ray by at most sqrt(2)/2 of that step, `s = step * distance / K` in
/// metres; a surface moved `s` across a ray it meets at angle theta moves
/// the hit `s / tan(theta)` along the ray, and its height `|ray.y|` times
/// that. Both renders move, and each rebuilds the point from a float
/// depth (8 units of the last bit of the distance, as in
/// `surface_height_tolerance`). `normal` is the surface's unit normal
/// there; where the ray grazes the surface (theta near 0, a silhouette)
/// the bound grows without limit, as the error can.
pub fn pair_height_tolerance(
    precision: RasterPrecision,
    (eye, pixels_per_radian): (glam::DVec3, f64),
    point: glam::DVec3,
    normal: glam::DVec3,
) -> f64 {
    let to = point - eye;
    let distance = to.length();
    let ray = to / distance;
    let across =
        std::f64::consts::FRAC_1_SQRT_2 * (-f64::from(precision.sub_pixel_bits)).exp2() * distance
            / pixels_per_radian;
    let sin = normal.dot(ray).abs().max(1e-9);
    let cos = (1.0 - sin * sin).max(0.0).sqrt();
    let depth = 8.0 * (-f64::from(precision.depth_significand_bits)).exp2() * distance;
    2.0 * (across * cos / sin + depth) * ray.y.abs()
}

/// The unit normal of `info`'s surface (as `height_at` splits it) at world
/// (x, z), from the heights a hundredth of a cell either side.
pub fn surface_normal(info: &TerrainInfo, x: f64, z: f64) -> Option<glam::DVec3> {
    let (dx, dz) = (0.01 * info.spacing().x, 0.01 * info.spacing().y);
    let h = |x: f64, z: f64| info.height_at(x, z).map(f64::from);
    let gx = (h(x + dx, z)? - h(x - dx, z)?) / (2.0 * dx);
    let gz = (h(x, z + dz)? - h(x, z - dz)?) / (2.0 * dz);
    Some(glam::DVec3::new(-gx, 1.0, -gz).normalize())
}

/// The steepest rise of a terrain's triangles, per metre: over every cell,
/// the gradient of its samples' differences along x and z.
pub fn max_slope(info: &TerrainInfo) -> f64 {
    let spacing = info.spacing();
    let heights = info.heightmap().expect("the heights are in memory");
    let at = |r: usize, c: usize| f64::from(heights.get(r, c));
    let mut steepest = 0.0f64;
    for r in 0..info.rows() - 1 {
        for c in 0..info.cols() - 1 {
            let (a, b, cc, d) = (at(r, c), at(r, c + 1), at(r + 1, c), at(r + 1, c + 1));
            let sx = (b - a).abs().max((d - cc).abs()) / spacing.x;
            let sz = (cc - a).abs().max((d - b).abs()) / spacing.y;
            steepest = steepest.max(sx.hypot(sz));
        }
    }
    steepest
}
