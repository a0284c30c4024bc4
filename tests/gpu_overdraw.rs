//! What a frame shades per pixel it covers, from pipeline statistics, on a
//! constructed view with a known answer. Validation on; any message fails.

mod common;

use common::gpu::*;
use glam::DVec2;
use vkterrain::render::{LodMetric, RenderPath, RenderSettings};
use vkterrain::terrain::{Heightmap, Terrain, TerrainInfo};

/// A ramp rising 40 m over 120 cells along +x, then a cliff falling 40 m
/// over the last 8 cells: 129x129 samples 1 m apart, 16-cell patches.
fn ramp_and_cliff() -> Terrain {
    let map = Heightmap::from_fn(129, 129, |_, c| match c {
        0..=120 => 40.0 * c as f32 / 120.0,
        _ => 40.0 * (128 - c) as f32 / 8.0,
    })
    .expect("valid size");
    let info = TerrainInfo::new(map, DVec2::ONE, 16, DVec2::ZERO).expect("valid terrain");
    Terrain::new(info, 0.0).expect("valid margin")
}

/// Seen from past the ramp's foot, below the crest, nothing is hidden but
/// the cliff, and the cliff faces away: every covered pixel shows the one
/// front face over it. A path that draws back faces rasterises the cliff
/// too, a band below the crest about 200 pixels tall (the cliff's foot
/// 0.23 rad below the eye, the crest 0.08 rad above, 665 pixels a radian)
/// across the terrain's width: 0.4 of the covered pixels more (measured on
/// lavapipe: 1.57 per covered pixel with back faces drawn, 1.16 without).
///
/// A device counts an invocation per fragment shaded, or (lavapipe) 16
/// per 4x4 block a triangle touches, before the depth test, so that blocks
/// on a triangle's edge count once for each triangle touching them. The
/// error LODs draw this plane in 2 triangles a patch, 50 to 400 pixels a
/// side at 1024x768, where edges add about a block in ten: the frame
/// shades from 1 to 1.25 times the pixels it covers. (A LOD that draws the
/// plane in small triangles, as the distance LOD does near the eye, counts
/// more on lavapipe without shading more.)
#[test]
fn each_covered_pixel_is_shaded_about_once() {
    if skip_gpu() {
        return;
    }
    let mut scene = GpuScene::new(ramp_and_cliff(), 1024, 768, false);
    let cam = camera([-70.0, 30.0, 0.0], [56.0, 38.0, 0.0], 60.0);
    for (name, path) in [
        ("tess error", RenderPath::Tess),
        ("geomip error", RenderPath::Geomip),
    ] {
        let settings = RenderSettings {
            path,
            lod_metric: LodMetric::Error(1.0),
            ..RenderSettings::default()
        };
        let frame = scene.render(&cam, &settings);
        let stats = frame.measurements.statistics.expect("pipeline statistics");
        let covered = frame.covered_pixels() as f64;
        let per_pixel = stats.fragment_invocations as f64 / covered;
        eprintln!(
            "{name}: {} invocations over {covered} covered pixels ({per_pixel:.3}), {} triangles",
            stats.fragment_invocations, stats.clipping_primitives
        );
        assert!(covered > 20_000.0, "{name}: {covered} pixels covered");
        assert!(
            (1.0..=1.25).contains(&per_pixel),
            "{name}: {per_pixel:.3} invocations per covered pixel"
        );
    }
    scene.finish();
}
