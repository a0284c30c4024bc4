//! The benchmark's CPU side: cameras, configurations, pooled statistics,
//! targets and the report files.

mod common;

use common::*;
use glam::DVec2;
use vkterrain::bench::cameras::{flythrough, named_views};
use vkterrain::bench::error::{ErrorHistogram, PixelError};
use vkterrain::bench::look::LookRow;
use vkterrain::bench::report::{check_targets, csv, markdown, merge, Results};
use vkterrain::bench::run::{
    configs, Config, Row, RowLod, RowPath, OCCLUSION_TAU, QUICK_TAUS, TAUS, VIEW_MEASURE_TAU,
};
use vkterrain::render::FrameFigures;
use vkterrain::terrain::{DistanceLod, TerrainInfo};

fn terrains() -> Vec<(&'static str, TerrainInfo)> {
    vec![
        ("dem", dem_info(32)),
        (
            "noise off-centre",
            TerrainInfo::new(
                noise_map(70, 45, 9),
                DVec2::new(3.0, 5.0),
                16,
                DVec2::new(1e5, -2e5),
            )
            .unwrap(),
        ),
        (
            "flat",
            TerrainInfo::new(
                vkterrain::terrain::Heightmap::from_fn(33, 33, |_, _| 4.0).unwrap(),
                DVec2::ONE,
                8,
                DVec2::ZERO,
            )
            .unwrap(),
        ),
    ]
}

#[test]
fn named_views_stand_above_the_ground_and_look_at_the_terrain() {
    for (name, info) in terrains() {
        let views = named_views(&info);
        let names: Vec<&str> = views.iter().map(|v| v.name).collect();
        assert_eq!(names, ["grazing", "overview", "valley"]);
        for v in views {
            let c = v.camera;
            let ground = f64::from(info.clamped_height_at(c.eye.x, c.eye.z));
            assert!(
                c.eye.y > ground,
                "{name}/{}: eye {} under ground {ground}",
                v.name,
                c.eye
            );
            assert!(c.eye.distance(c.target) > 1.0, "{name}/{}", v.name);
            let t = info.clamp_to_terrain(DVec2::new(c.target.x, c.target.z));
            assert!(
                (t - DVec2::new(c.target.x, c.target.z)).length() < 1e-6,
                "{name}/{}: target off the terrain",
                v.name
            );
        }
    }
}

#[test]
fn the_grazing_view_is_low_and_level() {
    let info = dem_info(32);
    let v = named_views(&info)[0].camera;
    let ground = f64::from(info.clamped_height_at(v.eye.x, v.eye.z));
    let (lo, hi) = info.min_max();
    // 3 % of the relief plus one cell above the ground.
    let lift = 0.03 * f64::from(hi - lo) + info.spacing().max_element();
    assert!(
        (v.eye.y - ground - lift).abs() < 1e-3,
        "{} vs {lift}",
        v.eye.y - ground
    );
    assert!((v.eye.y - v.target.y).abs() < 1e-9);
}

#[test]
fn the_flythrough_is_a_smooth_closed_loop_above_the_ground() {
    for (name, info) in terrains() {
        let frames = flythrough(&info, 200);
        assert_eq!(frames.len(), 200);
        let size = info.world_width().max(info.world_depth());
        let (lo, hi) = info.min_max();
        let steps: Vec<glam::DVec3> = frames
            .iter()
            .zip(frames.iter().cycle().skip(1))
            .map(|(a, b)| b.eye - a.eye)
            .collect();
        // Every step, the last back to the first included, is short.
        let longest = steps.iter().map(|d| d.x.hypot(d.z)).fold(0.0, f64::max);
        assert!(longest < 0.02 * size, "{name}: a step of {longest}");
        if name == "dem" {
            // Over real ground the altitude changes smoothly too.
            let climb = steps.iter().map(|d| d.y.abs()).fold(0.0, f64::max);
            assert!(
                climb < 0.05 * f64::from(hi - lo),
                "{name}: a climb of {climb}"
            );
        }
        for c in &frames {
            let ground = f64::from(info.clamped_height_at(c.eye.x, c.eye.z));
            assert!(c.eye.y > ground, "{name}: under ground at {}", c.eye);
            assert!(c.eye.distance(c.target) > 0.0);
        }
    }
    assert!(flythrough(&dem_info(32), 0).is_empty());
    // Even three frames make usable cameras.
    let three = flythrough(&dem_info(32), 3);
    assert!(three.iter().all(|c| c.eye != c.target));
}

#[test]
fn configurations_cover_every_path_and_tolerance() {
    let lod = DistanceLod {
        min_dist: 100.0,
        max_dist: 4000.0,
        min_exp: 0.0,
        max_exp: 6.0,
    };
    let full = configs(lod, false, true);
    assert_eq!(full[0], Config::Brute);
    let count = |f: &dyn Fn(&Config) -> bool| full.iter().filter(|c| f(c)).count();
    assert_eq!(count(&|c| matches!(c, Config::TessDistance(_))), 8);
    for (path, lod) in [
        (RowPath::Tess, Some(RowLod::Error)),
        (RowPath::Geomip, Some(RowLod::Error)),
        (RowPath::Oracle, None),
    ] {
        let taus: Vec<f32> = full
            .iter()
            .filter(|c| c.path() == path && c.lod() == lod && !c.occlusion())
            .filter_map(|c| c.tau())
            .collect();
        assert_eq!(taus, TAUS, "{path:?} {lod:?}");
    }
    // Each error mode once more with occlusion culling, beside its
    // counterpart without.
    let occluded: Vec<Config> = full.iter().copied().filter(Config::occlusion).collect();
    assert_eq!(
        occluded,
        [
            Config::TessErrorOccluded(OCCLUSION_TAU),
            Config::GeomipErrorOccluded(OCCLUSION_TAU)
        ]
    );
    for c in occluded {
        let off = c.unoccluded().expect("an occluded row has a counterpart");
        assert!(full.contains(&off) && !off.occlusion());
        assert_eq!(
            (c.path(), c.lod(), c.tau()),
            (off.path(), off.lod(), off.tau())
        );
    }
    assert_eq!(count(&|c| matches!(c, Config::GeomipDistance(_))), 4);
    // The distance sweep spans the scene's distances from 1/4 to 8 times.
    let dists: Vec<f32> = full
        .iter()
        .filter_map(|c| match c {
            Config::TessDistance(l) => Some(l.min_dist),
            _ => None,
        })
        .collect();
    assert_eq!(dists.iter().copied().fold(f32::MAX, f32::min), 25.0);
    assert_eq!(dists.iter().copied().fold(0.0, f32::max), 800.0);

    let quick = configs(lod, true, true);
    assert!(quick.len() < full.len());
    assert!(quick
        .iter()
        .filter_map(|c| c.tau())
        .all(|t| QUICK_TAUS.contains(&t)));
    // Without tessellation there are no tess rows, the rest remains.
    let fallback = configs(lod, false, false);
    assert!(fallback.iter().all(|c| c.path() != RowPath::Tess));
    assert_eq!(fallback.len(), full.len() - 8 - TAUS.len() - 3 - 2);
    // The view measure's rows, once per error mode at tau = 1 px, beside
    // the real-time choice's.
    let view: Vec<Config> = full
        .iter()
        .copied()
        .filter(|c| c.lod() == Some(RowLod::ErrorView))
        .collect();
    assert_eq!(
        view,
        [
            Config::TessErrorView(VIEW_MEASURE_TAU),
            Config::GeomipErrorView(VIEW_MEASURE_TAU)
        ]
    );
    assert!(quick.iter().any(|c| c.lod() == Some(RowLod::ErrorView)));
    // The peers' policies, each once, in the quick run too.
    for run in [&full, &quick] {
        let peers: Vec<_> = run
            .iter()
            .filter(|c| matches!(c, Config::TessPeer(_)))
            .filter_map(|c| c.lod())
            .collect();
        assert_eq!(peers, [RowLod::Sphere, RowLod::EdgeLength, RowLod::Cdlod]);
    }
    // Labels name the parameters, and differ.
    let labels: std::collections::BTreeSet<String> = full.iter().map(Config::label).collect();
    assert_eq!(labels.len(), full.len());
}

#[test]
fn pooled_histogram_matches_exact_statistics() {
    // Errors spread over six decades, with zeros and mismatches.
    let errors: Vec<PixelError> = (0..100_000)
        .map(|i| {
            let x =
                ((i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 11) as f64 / (1u64 << 53) as f64;
            PixelError {
                index: i,
                px: if i % 97 == 0 {
                    0.0
                } else {
                    1e-3 * 10f64.powf(6.0 * x)
                },
                mismatched: i % 1000 == 0,
            }
        })
        .collect();
    let mut histogram = ErrorHistogram::default();
    // Pooled in two halves, as frames are.
    histogram.add(&errors[..40_000]);
    histogram.add(&errors[40_000..]);
    let stats = histogram.stats();
    let mut sorted: Vec<f64> = errors.iter().map(|e| e.px).collect();
    sorted.sort_by(f64::total_cmp);
    let p99 = sorted[(0.99 * sorted.len() as f64).ceil() as usize - 1];
    let mean = sorted.iter().sum::<f64>() / sorted.len() as f64;
    assert_eq!(stats.pixels, 100_000);
    assert_eq!(stats.mismatched, 100);
    assert_eq!(stats.max_px, sorted[sorted.len() - 1]);
    assert!((stats.mean_px - mean).abs() <= 1e-9 * mean);
    // Never below the exact value, at most one bin (a thousandth of a
    // decade) above it.
    assert!(
        stats.p99_px >= p99 && stats.p99_px <= 10f64.powf(1e-3) * p99,
        "{} vs {p99}",
        stats.p99_px
    );
    assert_eq!(ErrorHistogram::default().stats().pixels, 0);
    // Silhouettes moved by whole pixels measure whole pixels: where the
    // percentile falls on them it is theirs, not a bin's centre beside it,
    // nor a larger error of the same bin.
    let whole: Vec<PixelError> = (0..1000)
        .map(|i| {
            let (px, mismatched) = match i {
                0..985 => (0.25, false),
                985..995 => (1.0, true),
                995 => (1.0015, false),
                _ => (2.0, true),
            };
            PixelError {
                index: i,
                px,
                mismatched,
            }
        })
        .collect();
    let mut histogram = ErrorHistogram::default();
    histogram.add(&whole);
    let stats = histogram.stats();
    assert_eq!(stats.mismatched, 14);
    assert_eq!((stats.p99_px, stats.max_px), (1.0, 2.0));
    // One rank further, past the mismatches at 1 px: the bin's others at
    // their largest.
    let mut histogram = ErrorHistogram::default();
    histogram.add(&whole[10..]);
    histogram.add(
        &[PixelError {
            index: 0,
            px: 1.0015,
            mismatched: false,
        }; 11],
    );
    assert_eq!(histogram.stats().p99_px, 1.0015);
}

fn row(
    camera: &str,
    path: &str,
    lod: Option<&str>,
    tau: Option<f32>,
    tris: u64,
    gpu: f64,
    p99: f64,
) -> Row {
    Row {
        scene: "s".into(),
        device: "d".into(),
        driver: "v".into(),
        width: 64,
        height: 32,
        camera: camera.into(),
        frames: 1,
        // By name, as results.json spells them.
        path: serde_json::from_str(&format!("{path:?}")).unwrap(),
        lod: lod.map(|l| serde_json::from_str(&format!("{l:?}")).unwrap()),
        tau,
        config: format!("{path} {lod:?} {tau:?}, {tris}"),
        figures: FrameFigures {
            gpu_ms: Some(gpu),
            cpu_ms: 0.1,
            // The error rows' level choice takes a little longer the finer
            // tau.
            lod_ms: tau.map(|t| 0.05 / f64::from(t)),
            triangles: Some(tris),
            tes_invocations: Some(tris / 2),
        },
        lod_ms_max: tau.map(|t| 0.2 / f64::from(t)),
        frame_ms: Some(gpu + 0.1),
        // Finer rows shade more of each pixel's hidden ground.
        fragment_invocations: Some(2048 + tris / 100),
        covered_pixels: Some(1024),
        gpu_memory_bytes: 1 << 20,
        predicted_max_px: tau.map(|t| f64::from(t) * 1.5),
        predicted_p99_px: tau.map(f64::from),
        predicted_over_share: tau.map(|_| 0.004),
        over_share: tau.map(|_| 0.002),
        max_px: 2.0 * p99,
        p99_px: p99,
        mean_px: 0.1 * p99,
        error_pixels: 1000,
        mismatched_pixels: 3,
        occlusion: false,
        patches_occluded: None,
        patches_drawn_hidden: None,
        culling_gpu_ms: None,
        differing_pixels: None,
    }
}

fn sample_rows() -> Vec<Row> {
    vec![
        row("v", "brute", None, None, 100_000, 50.0, 0.0),
        row("v", "tess", Some("distance"), None, 30_000, 20.0, 0.5),
        row("v", "tess", Some("distance"), None, 8_000, 8.0, 0.9),
        row("v", "tess", Some("distance"), None, 2_000, 2.0, 3.0),
        row("v", "tess", Some("error"), Some(0.5), 9_000, 7.0, 0.4),
        row("v", "tess", Some("error"), Some(1.0), 4_000, 5.0, 0.8),
        row("v", "tess", Some("error"), Some(2.0), 2_500, 3.0, 2.5),
        row("v", "geomip", Some("error"), Some(1.0), 20_000, 9.0, 0.2),
        row("v", "oracle", None, Some(1.0), 3_000, 4.0, 0.7),
    ]
}

#[test]
fn targets_are_read_from_the_rows() {
    let rows = sample_rows();
    let refs: Vec<&Row> = rows.iter().collect();
    let c = check_targets(&refs);
    assert_eq!(c.tess_p99, [Some(0.4), Some(0.8), Some(2.5)]);
    assert_eq!(c.tess_vs_brute_triangles, Some(0.04));
    // The fewest triangles at p99 <= 1 px: the oracle's 3 000 (the 2 000
    // distance setting measures 3 px).
    assert!(c.fewest_config.as_deref().unwrap().contains("oracle"));
    assert_eq!(c.tess_vs_fewest, Some(4.0 / 3.0));
    // The fastest frame at p99 <= 1 px: the oracle's 4.1 ms, against tess
    // error mode's 5.1 ms at 1 px.
    assert!(c.fastest_config.as_deref().unwrap().contains("oracle"));
    assert_eq!(c.tess_frame_ms, Some(5.1));
    assert_eq!(c.tess_vs_fastest, Some(5.1 / 4.1));
    // The largest level choice of any error row: tau 0.5's 0.4 ms.
    assert_eq!(c.tess_lod_ms_max, Some(0.4));
    assert_eq!(c.geomip_lod_ms_max, Some(0.2));
    assert_eq!(c.geomip_p99, [None, Some(0.2), None]);
    let look_row = |config: &str, gpu_ms: f64| LookRow {
        scene: "default".into(),
        device: "llvmpipe".into(),
        driver: "Mesa".into(),
        width: 1280,
        height: 720,
        config: config.into(),
        triplanar: false,
        sky: config == "+ sky",
        samples: 1,
        frames: 5,
        gpu_ms: Some(gpu_ms),
    };
    let look = [look_row("plain", 10.0), look_row("+ sky", 11.0)];
    let without_look = markdown(
        &Results {
            rows: &rows,
            look: &[],
        },
        "",
        "pareto.png",
    );
    assert!(!without_look.contains("## What the picture costs"));
    let md = markdown(
        &Results {
            rows: &rows,
            look: &look,
        },
        "## Why\n\nBecause.",
        "pareto.png",
    );
    assert!(md.contains("## What the picture costs"));
    assert!(
        md.contains("| + sky | 1 | 11.00 | +10.0 % |"),
        "each addition over the plain row"
    );
    assert!(md.contains("| plain | 1 | 10.00 | +0.0 % |"));
    assert!(
        md.contains("|T.y - R.y| * K / |R - eye|"),
        "the definition is written down"
    );
    assert!(md.contains("1.33x (met)"), "tess within 2x of the fewest");
    assert!(
        md.contains("1.24x (met)"),
        "tess's frame within 1.25x of the fastest"
    );
    assert!(
        md.contains("0.40 ms (met)"),
        "the level choice's largest frame within 0.5 ms"
    );
    assert!(
        md.contains("2.50 px (**missed**, 1.25x off)"),
        "p99 over tau at 2 px"
    );
    assert!(md.contains("## Predicted against measured error"));
    assert!(md.contains("Because."));
    // No occluded rows, no occlusion rows in its table.
    assert!(!md.contains("| tess | 4000 / "));

    // An occluded tess row beside its counterpart, and the best row, are
    // read into the occlusion table; it does not count as the best row.
    let mut with_occlusion = rows.clone();
    with_occlusion.push(Row {
        occlusion: true,
        patches_occluded: Some(40),
        patches_drawn_hidden: Some(3),
        culling_gpu_ms: Some(0.25),
        differing_pixels: Some(0),
        ..row("v", "tess", Some("error"), Some(1.0), 1_000, 2.5, 0.8)
    });
    let refs: Vec<&Row> = with_occlusion.iter().collect();
    // Tess error mode is read from its row with occlusion culling, as the
    // renderer draws it: 1 000 triangles, the fewest, in 2.6 ms, the
    // fastest.
    let c = check_targets(&refs);
    assert_eq!(c.tess_vs_fewest, Some(1.0));
    assert_eq!(c.tess_frame_ms, Some(2.6));
    assert_eq!(c.tess_vs_fastest, Some(1.0));
    let md = markdown(
        &Results {
            rows: &with_occlusion,
            look: &[],
        },
        "",
        "pareto.png",
    );
    assert!(
        md.contains(
            "| s | d | v | tess | 4000 / 1000 / 3000 | 4.00x | 0.33x | 5.0 / 2.5 | 0.2 (10.0 %) | 40 | 3 | 0 |"
        ),
        "{md}"
    );
    assert!(md.contains("![Triangles and frame time against p99 error](pareto.png)"));
}

#[test]
fn csv_has_one_line_per_row_and_quotes_commas() {
    let rows = sample_rows();
    let text = csv(&rows);
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), rows.len() + 1);
    assert!(lines[0].starts_with("scene,device,driver,width,height,camera,frames,path,lod,tau"));
    assert!(
        lines[1].contains("\"brute None None, 100000\""),
        "{}",
        lines[1]
    );
}

#[test]
fn merging_replaces_only_the_same_scene_and_device() {
    let dir = tempfile::tempdir().unwrap();
    assert!(merge(dir.path(), Vec::new()).unwrap().is_empty());
    let mut other = sample_rows();
    for r in &mut other {
        r.device = "other".into();
    }
    let first: Vec<Row> = sample_rows().into_iter().chain(other.clone()).collect();
    std::fs::write(
        dir.path().join("results.json"),
        serde_json::to_string(&first).unwrap(),
    )
    .unwrap();
    let fresh = vec![row("w", "brute", None, None, 5, 1.0, 0.0)];
    let merged = merge(dir.path(), fresh.clone()).unwrap();
    assert_eq!(merged.len(), other.len() + 1);
    assert!(merged.iter().filter(|r| r.device == "d").eq(fresh.iter()));
    std::fs::write(dir.path().join("results.json"), "{ not rows").unwrap();
    let err = merge(dir.path(), Vec::new()).unwrap_err();
    assert!(format!("{err:#}").contains("results.json: not the results of an earlier run"));
}
