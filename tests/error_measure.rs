//! The screen-space error measurement itself, on renders whose error is
//! known.

mod common;

use common::gpu::*;
use glam::DVec2;
use vkterrain::bench::error::{measure, DepthView};
use vkterrain::render::{RenderPath, RenderSettings};
use vkterrain::terrain::{Heightmap, Terrain, TerrainInfo};

fn flat(height: f32, origin: DVec2) -> Terrain {
    let map = Heightmap::from_fn(65, 65, move |_, _| height).unwrap();
    Terrain::new(
        TerrainInfo::new(map, DVec2::splat(10.0), 16, origin).unwrap(),
        0.0,
    )
    .unwrap()
}

fn brute() -> RenderSettings {
    RenderSettings {
        path: RenderPath::Brute,
        ..RenderSettings::default()
    }
}

#[test]
fn a_render_against_itself_has_no_error() {
    if skip_gpu() {
        return;
    }
    let mut scene = GpuScene::new(flat(3.0, DVec2::ZERO), 160, 120, false);
    let cam = camera([-200.0, 150.0, -250.0], [0.0, 0.0, 0.0], 60.0);
    let a = scene.render(&cam, &brute());
    let stats = measure(
        &DepthView::of(&a),
        &DepthView::of(&a),
        f64::from(a.view.pixels_per_radian),
    );
    assert!(stats.pixels > 5000);
    assert_eq!(
        (stats.max_px, stats.mean_px, stats.mismatched),
        (0.0, 0.0, 0)
    );
    scene.finish();
}

#[test]
fn a_known_vertical_offset_gives_its_projected_size() {
    if skip_gpu() {
        return;
    }
    let offset = 5.0;
    let mut low = GpuScene::new(flat(0.0, DVec2::ZERO), 160, 120, false);
    let mut high = GpuScene::new(flat(offset, DVec2::ZERO), 160, 120, false);
    // Looking down at the middle: terrain fills every pixel of both.
    let cam = camera([0.0, 120.0, -60.0], [0.0, 0.0, 30.0], 50.0);
    let reference = low.render(&cam, &brute());
    let tested = high.render(&cam, &brute());
    let k = f64::from(reference.view.pixels_per_radian);
    let stats = measure(&DepthView::of(&tested), &DepthView::of(&reference), k);
    assert_eq!(stats.mismatched, 0);
    assert_eq!(stats.pixels, 160 * 120);
    // Every pixel: offset * K / distance to the reference surface.
    let expected: Vec<f64> = world_positions(&reference, &cam)
        .into_iter()
        .map(|p| f64::from(offset) * k / (p.unwrap() - cam.eye).length())
        .collect();
    let max = expected.iter().copied().fold(0.0, f64::max);
    let mean = expected.iter().sum::<f64>() / expected.len() as f64;
    assert!(
        (stats.max_px - max).abs() < 1e-3 * max,
        "max {} vs {max}",
        stats.max_px
    );
    assert!(
        (stats.mean_px - mean).abs() < 1e-3 * mean,
        "mean {} vs {mean}",
        stats.mean_px
    );
    assert!(stats.p99_px <= stats.max_px && stats.p99_px >= mean);
    low.finish();
    high.finish();
}

#[test]
fn coverage_mismatches_count_as_the_silhouette_shift() {
    if skip_gpu() {
        return;
    }
    // The same flat square moved 20 units sideways, seen from straight
    // above: its edge moves by 20 * K / height pixels.
    let mut here = GpuScene::new(flat(0.0, DVec2::ZERO), 200, 200, false);
    let mut there = GpuScene::new(flat(0.0, DVec2::new(20.0, 0.0)), 200, 200, false);
    let cam = camera([0.0, 900.0, 0.0], [0.0, 0.0, 0.0], 60.0);
    let reference = here.render(&cam, &brute());
    let tested = there.render(&cam, &brute());
    let k = f64::from(reference.view.pixels_per_radian);
    let stats = measure(&DepthView::of(&tested), &DepthView::of(&reference), k);
    let shift = 20.0 * k / 900.0;
    assert!(stats.mismatched > 0);
    assert!(
        (stats.max_px - shift).abs() <= 1.5,
        "silhouette moved {} px, expected about {shift}",
        stats.max_px
    );
    here.finish();
    there.finish();
}
