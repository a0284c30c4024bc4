//! Streamed terrains on a real Vulkan device: small imported terrains with
//! tiny tiles and a tiny pool, so eviction and re-streaming happen here.
//! With room for every tile the image is the whole-terrain renderer's,
//! pixel for pixel; under a tight pool a flythrough has no holes or cracks
//! in any frame; a mix of full-resolution tiles, coarser pages and the base
//! level draws what its CPU mirror says. Validation is on and counted
//! after the device is destroyed.

mod common;

use std::path::{Path, PathBuf};

use common::gpu::*;
use common::{json_file, succeeded};
use glam::DVec2;
use vkterrain::bench::error::enclosed_background;
use vkterrain::render::residency::{entry_level, StreamShape};
use vkterrain::render::{
    ErrorMeasure, LodMetric, RenderPath, RenderSettings, Shading, StreamConfig,
};
use vkterrain::terrain::camera::Camera;
use vkterrain::terrain::generate::{generate, GeneratorParams};
use vkterrain::terrain::tiled::{self, MemoryRows};
use vkterrain::terrain::{Heightmap, Terrain, TerrainInfo};

const TILE: u32 = 16;
const CELLS_PER_PATCH: u32 = 16;
/// Base sides of at most 17 samples: every 16th sample of the 257x203 map.
const BASE_MAX_SIDE: u32 = 17;

/// Eroded hills, 257x203 samples, 0 to 60 m: a remainder tile down, whose
/// 10 cells are a multiple of no level's step but the first, so every
/// coarser level's last row of cells is narrower.
fn hills() -> Heightmap {
    let square = generate(&GeneratorParams {
        size: 257,
        seed: 11,
        droplets: 4000,
    })
    .unwrap();
    Heightmap::from_fn(257, 203, |r, c| 60.0 * square.get(r, c)).unwrap()
}

fn info(map: Heightmap) -> TerrainInfo {
    TerrainInfo::new(map, DVec2::new(2.0, 2.0), CELLS_PER_PATCH, DVec2::ZERO).unwrap()
}

/// `map` imported into `dir` with 16-cell tiles.
fn imported(map: &Heightmap, dir: &Path) -> PathBuf {
    let out = dir.join("hills.vkt");
    let mut rows = MemoryRows::new(map.clone(), None);
    tiled::import(&mut rows, TILE, Some(CELLS_PER_PATCH), &out, &mut |_, _| {}).unwrap();
    out
}

fn config(path: PathBuf, layers: Option<u32>) -> StreamConfig {
    StreamConfig {
        base_max_side: BASE_MAX_SIDE,
        layers,
        ..StreamConfig::new(path)
    }
}

/// The terrain's CPU model with its Y bounds widened for the base level.
fn streamed_terrain(map: &Heightmap) -> Terrain {
    let mut terrain = Terrain::new(info(map.clone()), 0.0).unwrap();
    terrain.widen_y_bounds_to_blocks(1 << shape().base_level);
    terrain
}

fn shape() -> StreamShape {
    StreamShape::new(257, 203, TILE, BASE_MAX_SIDE)
}

fn cameras() -> Vec<(&'static str, Camera)> {
    vec![
        ("top", camera([0.0, 600.0, 0.0], [0.0, 0.0, 0.0], 60.0)),
        (
            "oblique",
            camera([-260.0, 120.0, -200.0], [0.0, 20.0, 0.0], 55.0),
        ),
        (
            "low",
            camera([200.0, 45.0, 150.0], [-40.0, 15.0, -20.0], 70.0),
        ),
    ]
}

/// The error LOD at 1 px on its bounds: a streamed terrain's CPU does not
/// hold the heights the view's measure needs, so the whole terrain it is
/// compared with is drawn on its bounds too.
fn settings(path: RenderPath, shading: Shading) -> RenderSettings {
    RenderSettings {
        path,
        lod_metric: LodMetric::Error(1.0),
        error_measure: ErrorMeasure::Bound,
        shading,
        clear_color: [0.0; 3],
        ..RenderSettings::default()
    }
}

#[test]
fn with_room_for_every_tile_the_image_is_the_resident_renderers() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let map = hills();
    let path = imported(&map, dir.path());
    let (w, h) = (320, 200);
    let mut whole = GpuScene::new(Terrain::new(info(map.clone()), 0.0).unwrap(), w, h, false);
    let mut streamed = GpuScene::streamed(streamed_terrain(&map), config(path, None), w, h);
    for (view, cam) in cameras() {
        for path in [RenderPath::Tess, RenderPath::Geomip, RenderPath::Brute] {
            let s = settings(path, Shading::Lit);
            let expected = whole.render(&cam, &s);
            let frame = streamed.render(&cam, &s);
            let stats = streamed.renderer().stream_stats().unwrap();
            assert_eq!(
                stats.missing_px, 0.0,
                "{view}/{path:?}: every tile in view is resident"
            );
            assert!(stats.resident_pages > 0, "{view}/{path:?}: {stats:?}");
            let differing = frame
                .readback
                .rgba
                .chunks_exact(4)
                .zip(expected.readback.rgba.chunks_exact(4))
                .filter(|(a, b)| a != b)
                .count();
            assert_eq!(
                differing, 0,
                "{view}/{path:?}: pixels differ from the resident image"
            );
        }
    }
    whole.finish();
    streamed.finish();
}

/// Low along the terrain and back again, then a cut to a view from
/// above: tiles leave a small pool and come back.
fn low_pass() -> Vec<Camera> {
    let mut path: Vec<Camera> = (0..=16)
        .chain((0..=16).rev())
        .map(|i| {
            let x = -220.0 + 27.5 * f64::from(i);
            camera([x, 70.0, -150.0], [x + 40.0, 10.0, 0.0], 60.0)
        })
        .collect();
    path.push(camera([0.0, 520.0, 0.0], [0.0, 0.0, 0.0], 60.0));
    path
}

/// The frame's background pixels enclosed by terrain.
fn holes(frame: &vkterrain::render::HeadlessFrame) -> usize {
    let (w, h) = (frame.readback.width, frame.readback.height);
    enclosed_background(&frame.readback.rgba, w as usize, h as usize, |p| p[0] < 128).len()
}

/// Under a budget that holds 40 of the pool's 284 streamed pages (the
/// smallest pool holds 36: 9 for each of the 4 levels finer than the
/// base), the pool takes what is left and the flythrough draws without holes,
/// its missing pages' error reported per frame and counted in the LOD's
/// predicted error; the budget with room for every page misses less. A
/// budget below the smallest layout is refused, and the refusal names a
/// budget that works.
#[test]
fn a_budget_smaller_than_the_pool_degrades_and_names_its_floor() {
    if skip_gpu() {
        return;
    }
    use vkterrain::render::stream_budget::MIN_HEADROOM_BYTES;
    const KEPT: u32 = 40;
    let dir = tempfile::tempdir().unwrap();
    let map = hills();
    let path = imported(&map, dir.path());
    let size = (320, 200);
    let stream = StreamConfig {
        upload_bytes_per_frame: 2 * 4 * u64::from((TILE + 1) * (TILE + 1)),
        ..config(path.clone(), None)
    };
    let flat = settings(RenderPath::Tess, Shading::Flat);
    // Without a budget, to learn what the whole pool takes; then a budget
    // with room for `KEPT` of its streamed layers.
    let budget = {
        let mut scene =
            GpuScene::streamed_within(streamed_terrain(&map), stream.clone(), size, u64::MAX)
                .expect("no budget to speak of");
        let in_use = scene.gpu().device.memory_in_use();
        scene.render(&low_pass()[0], &flat);
        let stats = scene.renderer().stream_stats().unwrap();
        let pool = |layers: u32| {
            let device = &scene.gpu().device;
            device.layer_pool_bytes(TILE + 1, stats.base_pages + layers)
        };
        let cut = pool(stats.layers) - pool(KEPT);
        let full_layers = stats.layers;
        scene.finish();
        (in_use + MIN_HEADROOM_BYTES - cut, full_layers)
    };
    let (budget, full_layers) = budget;
    let mut missing = Vec::new();
    for (name, budget) in [("kept", budget), ("whole", u64::MAX)] {
        let mut scene =
            GpuScene::streamed_within(streamed_terrain(&map), stream.clone(), size, budget)
                .unwrap_or_else(|e| panic!("{name}: {e}"));
        scene.wait_for_residency(false);
        let mut total = 0.0;
        for (i, cam) in low_pass().iter().enumerate() {
            let frame = scene.render(cam, &flat);
            let stats = scene.renderer().stream_stats().unwrap();
            assert_eq!(holes(&frame), 0, "{name}, frame {i}: holes ({stats:?})");
            let predicted = scene.renderer().predicted_max_px().unwrap();
            assert!(
                predicted >= stats.missing_px,
                "{name}, frame {i}: predicted {predicted} px, missing {}",
                stats.missing_px
            );
            total += stats.missing_px;
            if name == "kept" {
                assert!(
                    stats.layers <= KEPT + 1 && stats.layers >= KEPT,
                    "{} of {full_layers} layers",
                    stats.layers
                );
            }
        }
        if name == "kept" {
            assert!(scene.renderer().stream_evictions().unwrap() > 0);
        }
        missing.push(total);
        scene.finish();
    }
    eprintln!(
        "missing px summed over the pass: {KEPT} layers {} whole {}",
        missing[0], missing[1]
    );
    assert!(missing[0] > missing[1], "{missing:?}");
    // Below the smallest layout: refused, naming a budget that works.
    let refused = GpuScene::streamed_within(streamed_terrain(&map), stream.clone(), size, 2 << 20)
        .err()
        .expect("2 MiB is refused")
        .to_string();
    let named: u64 = refused
        .split("--gpu-memory-budget ")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no budget named: {refused}"));
    assert!(refused.contains("needs at least"), "{refused}");
    let scene = GpuScene::streamed_within(streamed_terrain(&map), stream, size, named << 20)
        .unwrap_or_else(|e| panic!("the named {named} MiB: {e}"));
    scene.finish();
}

#[test]
fn a_tight_pool_evicts_and_restreams_without_holes_or_cracks() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let map = hills();
    let layers = 6;
    let stream = StreamConfig {
        // Two tiles a frame, so arrivals spread over frames.
        upload_bytes_per_frame: 2 * 4 * u64::from((TILE + 1) * (TILE + 1)),
        ..config(imported(&map, dir.path()), Some(layers))
    };
    let (w, h) = (320, 200);
    let mut scene = GpuScene::streamed(streamed_terrain(&map), stream, w, h);
    // A flythrough never waits on the disk.
    scene.wait_for_residency(false);
    let flat = settings(RenderPath::Tess, Shading::Flat);
    let (mut uploads, mut most_resident) = (0, 0);
    for (i, cam) in low_pass().iter().enumerate() {
        let frame = scene.render(cam, &flat);
        let stats = scene.renderer().stream_stats().unwrap();
        uploads += stats.uploaded_pages;
        most_resident = most_resident.max(stats.resident_pages);
        let rgba = &frame.readback.rgba;
        let covered = rgba.chunks_exact(4).filter(|p| p[0] > 128).count();
        assert!(
            covered > (w * h / 10) as usize,
            "frame {i}: the terrain covers {covered} pixels"
        );
        let holes = enclosed_background(rgba, w as usize, h as usize, |p| p[0] < 128);
        if !holes.is_empty() {
            frame
                .rgba_image()
                .save(format!("stream-frame-{i}-cracks.png"))
                .unwrap();
        }
        assert!(
            holes.is_empty(),
            "frame {i}: {} background pixels inside the terrain, first at {:?} ({stats:?})",
            holes.len(),
            &holes[..holes.len().min(5)]
        );
    }
    let evictions = scene.renderer().stream_evictions().unwrap();
    assert_eq!(most_resident, layers, "the pool fills");
    assert!(evictions >= 4, "only {evictions} pages were evicted");
    assert!(
        u64::from(uploads) >= u64::from(layers) + evictions,
        "{uploads} uploads for {evictions} evictions"
    );
    scene.finish();
}

#[test]
fn every_resident_level_and_the_base_draw_what_the_cpu_mirror_says() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let map = hills();
    let path = imported(&map, dir.path());
    // Coarse pages come first: with two layers, two of level 3's four
    // pages and the base level draw the view; with thirty, pages of every
    // level from full resolution to level 3 do.
    for (layers, levels_drawn) in [(2, vec![3, 4]), (30, vec![0, 1, 2, 3])] {
        mirror_case(&map, &path, layers, &levels_drawn);
    }
}

/// Streams `map` (imported at `path`) through a pool of `layers` layers
/// and checks that the image is the one drawn whole from the heights the
/// CPU mirror (`StreamShape::streamed_sample`) gives for the page table
/// the frame drew with, and that tiles were drawn at `levels_drawn`.
fn mirror_case(map: &Heightmap, path: &Path, layers: u32, levels_drawn: &[u32]) {
    let (w, h) = (320, 200);
    let mut streamed = GpuScene::streamed(
        streamed_terrain(map),
        config(path.to_path_buf(), Some(layers)),
        w,
        h,
    );
    let (_, cam) = cameras().remove(1);
    // Lit by the normals the heights give, in one colour (height colours
    // would follow each terrain's own height range).
    let lit = settings(RenderPath::Brute, Shading::LodColors);
    let frame = streamed.render(&cam, &lit);
    let table = streamed.renderer().stream_page_table().unwrap().to_vec();
    let stats = streamed.renderer().stream_stats().unwrap();
    streamed.finish();
    assert_eq!(stats.resident_pages, layers, "the pool fills");
    let shape = shape();
    let mut drawn: Vec<u32> = table.iter().map(|&e| entry_level(e)).collect();
    drawn.sort_unstable();
    drawn.dedup();
    assert_eq!(
        drawn, levels_drawn,
        "{layers} layers: the levels tiles are drawn at"
    );
    // The heights the GPU should have drawn, by the Rust mirror, drawn
    // whole.
    let mirror = Heightmap::from_fn(257, 203, |r, c| {
        shape.streamed_sample(
            &table,
            |row, col| map.get(row as usize, col as usize),
            (c as u32, r as u32),
        )
    })
    .unwrap();
    let mut whole = GpuScene::new(Terrain::new(info(mirror), 0.0).unwrap(), w, h, false);
    let expected = whole.render(&cam, &lit);
    let full = whole_render(map, &cam, &lit);
    whole.finish();
    let differing = |a: &[u8], b: &[u8]| {
        a.chunks_exact(4)
            .zip(b.chunks_exact(4))
            .filter(|(a, b)| a != b)
            .count()
    };
    let against_mirror = differing(&frame.readback.rgba, &expected.readback.rgba);
    let against_full = differing(&frame.readback.rgba, &full);
    assert!(
        against_full > 1000,
        "{layers} layers: the coarser levels should show, but only {against_full} pixels \
         differ from full resolution"
    );
    let allowed = (w * h / 10_000) as usize;
    if against_mirror > allowed {
        frame
            .rgba_image()
            .save(format!("stream-mirror-{layers}-gpu.png"))
            .unwrap();
        image::RgbaImage::from_raw(w, h, expected.readback.rgba.clone())
            .unwrap()
            .save(format!("stream-mirror-{layers}-cpu.png"))
            .unwrap();
    }
    // The heights are what is checked: Mesa 22.3.6's lavapipe shades one
    // of this view's 64,000 pixels differently between the two draws.
    assert!(
        against_mirror <= allowed,
        "{layers} layers: {against_mirror} pixels differ from the mirror's image"
    );
}

/// `map` drawn whole from `cam`: its RGBA pixels.
fn whole_render(map: &Heightmap, cam: &Camera, s: &RenderSettings) -> Vec<u8> {
    let mut scene = GpuScene::new(
        Terrain::new(info(map.clone()), 0.0).unwrap(),
        320,
        200,
        false,
    );
    let rgba = scene.render(cam, s).readback.rgba;
    scene.finish();
    rgba
}

/// `vkterrain render` of an imported terrain streams it, with the CPU model
/// read from the file's stored tables, bounds and tile levels: the image is
/// the one drawn from the same heights loaded whole. A tile that breaks
/// after import is named in the error, and no image is left.
#[test]
fn render_streams_an_imported_terrain_and_names_a_broken_tile() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let path = imported(&hills(), dir.path());
    let path = path.to_str().unwrap();
    let run = |extra: &[&str], out: &str| {
        let mut args = vec![
            "render",
            "--validate",
            "--heightmap",
            path,
            "--width",
            "160",
            "--height",
            "100",
            "--gpu-memory-budget",
            "64",
            "--out",
            out,
            "--stats",
            "stats.json",
        ];
        args.extend_from_slice(extra);
        common::vkterrain_in(dir.path(), &args)
    };
    // No patch size is given: the file's stored tables bring theirs.
    let streamed = run(&[], "streamed.png");
    succeeded(&streamed);
    let stats: serde_json::Value = json_file(&dir.path().join("stats.json"));
    assert!(
        stats["stream"]["base_pages"].as_u64().unwrap() > 0,
        "{}",
        stats["stream"]
    );
    assert_eq!(stats["validation_messages"], 0);
    assert_eq!(
        stats["patches_total"].as_u64().unwrap(),
        Terrain::new(info(hills()), 0.0)
            .unwrap()
            .grid()
            .patch_count() as u64
    );
    // A streamed terrain's error LOD holds its bounds (the CPU does not
    // hold its heights to measure the view), so the whole one is drawn so
    // too.
    let whole = run(&["--no-streaming", "--error-measure", "bound"], "whole.png");
    succeeded(&whole);
    let stats: serde_json::Value = json_file(&dir.path().join("stats.json"));
    assert!(stats["stream"].is_null());
    let read = |name: &str| image::open(dir.path().join(name)).unwrap().to_rgba8();
    assert_eq!(read("streamed.png"), read("whole.png"));

    // Flip one byte in the middle of the file: inside some tile's samples.
    let mut bytes = std::fs::read(path).unwrap();
    let tiled = vkterrain::terrain::tiled::TiledHeightmap::open(Path::new(path)).unwrap();
    let entry = *tiled.entry(3, 2, 0);
    drop(tiled);
    bytes[entry.offset as usize + 5] ^= 0x40;
    std::fs::write(path, &bytes).unwrap();
    let broken = run(&[], "broken.png");
    assert!(!broken.status.success());
    let stderr = String::from_utf8_lossy(&broken.stderr);
    assert!(stderr.contains("tile (3, 2)"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!dir.path().join("broken.png").exists());
}

/// `vkterrain stream --against-resident` on an imported terrain whose base
/// level is its full resolution (the default base holds 2049 samples a
/// side): every frame's heights are the whole terrain's, so each frame
/// matches the whole-terrain renderer's exactly, and the report says so.
#[test]
fn the_stream_flythrough_measures_no_error_where_heights_are_exact() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let path = imported(&hills(), dir.path());
    let out = common::vkterrain_in(
        dir.path(),
        &[
            "stream",
            "--validate",
            "--heightmap",
            path.to_str().unwrap(),
            "--frames",
            "6",
            "--width",
            "160",
            "--height",
            "100",
            "--against-resident",
            "--report",
            "report.json",
        ],
    );
    succeeded(&out);
    let report: serde_json::Value = json_file(&dir.path().join("report.json"));
    assert_eq!(report["frames"], 6);
    assert_eq!(report["holes"], 0);
    assert_eq!(report["validation_messages"], 0);
    assert_eq!(report["base_level"], 0);
    for frame in report["per_frame"].as_array().unwrap() {
        assert_eq!(frame["error_max_px"], 0.0, "{frame}");
    }
}
