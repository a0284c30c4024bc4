//! An 8193x8193 terrain (67 M samples), generated here rather than
//! committed: it renders on lavapipe with validation on, and the sample limit
//! refuses larger input before allocating anything.

mod common;

use common::gpu::*;
use common::vkterrain_in;
use glam::DVec2;
use vkterrain::render::{RenderPath, RenderSettings};
use vkterrain::terrain::{DistanceLod, Heightmap, Terrain, TerrainInfo};

const SIZE: usize = 8193;

#[test]
fn an_8193_square_terrain_renders() {
    if skip_gpu() {
        return;
    }
    // Ridges at several scales, cheap to generate.
    let map = Heightmap::from_fn(SIZE, SIZE, |r, c| {
        let (x, z) = (c as f32, r as f32);
        800.0 * (x * 0.0011).sin() * (z * 0.0007).cos()
            + 120.0 * (x * 0.013 + z * 0.007).sin()
            + 9.0 * (x * 0.21).sin() * (z * 0.17).sin()
    })
    .unwrap();
    let info = TerrainInfo::new(map, DVec2::splat(4.0), 32, DVec2::ZERO).unwrap();
    let terrain = Terrain::new(info, 0.0).unwrap();
    assert_eq!(terrain.grid().patch_count(), 256 * 256);
    let mut scene = GpuScene::new(terrain, 320, 180, false);
    let heightmap_bytes = scene
        .gpu()
        .device
        .memory_report()
        .into_iter()
        .find(|(name, _)| name == "terrain.heightmap")
        .map(|(_, bytes)| bytes)
        .unwrap();
    assert!(heightmap_bytes >= (SIZE * SIZE * 4) as u64);
    let cam = camera([-14000.0, 3000.0, -14000.0], [0.0, 0.0, 0.0], 55.0);
    for path in [RenderPath::Tess, RenderPath::Geomip] {
        let settings = RenderSettings {
            path,
            lod: DistanceLod {
                min_dist: 200.0,
                max_dist: 20000.0,
                min_exp: 0.0,
                max_exp: 6.0,
            },
            ..RenderSettings::default()
        };
        let frame = scene.render(&cam, &settings);
        let terrain_pixels = frame.covered_pixels();
        assert!(
            terrain_pixels > 320 * 180 / 3,
            "{path:?}: {terrain_pixels} pixels of terrain"
        );
        let triangles = frame.measurements.statistics.unwrap().clipping_primitives;
        assert!(triangles > 10_000, "{path:?}: {triangles} triangles");
    }
    // Drawn by distance, it needs no view model, which would take 497 MB.
    assert!(!scene.terrain.sight_table_asked());
    scene.finish();
}

#[test]
fn the_sample_limit_refuses_larger_input_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    // Sparse files: the right length, no data written, nothing read.
    let file = |name: &str, side: u64| {
        let f = std::fs::File::create(dir.path().join(name)).unwrap();
        f.set_len(side * side * 2).unwrap();
    };
    file("big.r16", SIZE as u64);
    file("huge.r16", 16385);
    let inspect = |args: &[&str]| vkterrain_in(dir.path(), &[&["inspect"], args].concat());
    let limited = inspect(&["--heightmap", "big.r16", "--max-samples", "67000000"]);
    assert!(!limited.status.success());
    let stderr = String::from_utf8_lossy(&limited.stderr);
    assert!(stderr.contains("big.r16"), "{stderr}");
    assert!(stderr.contains("67000000"), "{stderr}");
    // The default limit (2^27 samples) takes 8193^2 and refuses 16385^2.
    let ok = inspect(&["--heightmap", "big.r16"]);
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let refused = inspect(&["--heightmap", "huge.r16"]);
    assert!(!refused.status.success());
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        stderr.contains("huge.r16") && stderr.contains("134217728"),
        "{stderr}"
    );
}
