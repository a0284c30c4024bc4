//! The benchmark on a real device (lavapipe in CI), validation on: the rows
//! it produces, and `vkterrain bench` end to end.

mod common;

use common::gpu::{open_gpu, skip_gpu};
use common::vkterrain_in as vkterrain;
use common::*;
use glam::DVec2;
use vkterrain::bench::run::{
    configs, Bench, BenchOptions, Progress, Row, RowLod, RowPath, TIMED_FRAMES,
};
use vkterrain::lod::plan::EXCEED_SHARE;
use vkterrain::terrain::{DistanceLod, Terrain, TerrainInfo};

struct Count(u64, u64);

impl Progress for Count {
    fn start(&mut self, total: u64) {
        self.0 = total;
    }
    fn advance(&mut self, _: &str) {
        self.1 += 1;
    }
}

fn rows_of<'a>(rows: &'a [Row], camera: &str, path: RowPath, lod: Option<RowLod>) -> Vec<&'a Row> {
    rows.iter()
        .filter(|r| r.camera == camera && r.path == path && r.lod == lod && !r.occlusion)
        .collect()
}

#[test]
fn a_quick_run_measures_every_configuration() {
    if skip_gpu() {
        return;
    }
    let gpu = open_gpu(None);
    let info =
        TerrainInfo::new(noise_map(65, 49, 4), DVec2::new(4.0, 3.0), 16, DVec2::ZERO).unwrap();
    let terrain = Terrain::new(info, 0.0).unwrap();
    let lod = DistanceLod {
        min_dist: 20.0,
        max_dist: 200.0,
        min_exp: 0.0,
        max_exp: 4.0,
    };
    let configs = configs(lod, true, true);
    let options = BenchOptions {
        width: 96,
        height: 64,
        quick: true,
        flythrough_frames: 3,
        single_frame: false,
        views: Vec::new(),
        gpu_warm_ms: 0,
        timed_frames: TIMED_FRAMES,
    };
    let mut bench = Bench::new(&gpu, &terrain, lod, &configs, 96, 64).expect("bench objects");
    let mut progress = Count(0, 0);
    let rows = bench
        .run("noise", &configs, &options, &mut progress)
        .expect("the run");
    drop(bench);
    assert_eq!(gpu.device.memory_in_use(), 0, "memory left allocated");
    let report = gpu.shutdown();
    assert_eq!(report.count, 0, "{:#?}", report.messages);
    assert_eq!(
        progress.0, progress.1,
        "the progress total is what was rendered"
    );
    // One view and the flythrough, every configuration in each.
    assert_eq!(rows.len(), 2 * configs.len());
    for camera in ["grazing", "flythrough"] {
        let brute = rows_of(&rows, camera, RowPath::Brute, None)[0];
        assert_eq!(
            (brute.max_px, brute.p99_px, brute.mismatched_pixels),
            (0.0, 0.0, 0)
        );
        let brute_tris = brute.figures.triangles.expect("lavapipe counts primitives");
        for r in rows.iter().filter(|r| r.camera == camera) {
            assert!(
                r.error_pixels > 500,
                "{}: {} pixels",
                r.config,
                r.error_pixels
            );
            assert!(r.figures.gpu_ms.is_some_and(|ms| ms > 0.0), "{}", r.config);
            assert!(r.figures.triangles.is_some_and(|t| t > 0), "{}", r.config);
            assert!(r.gpu_memory_bytes > 96 * 64 * 8, "{}", r.config);
            assert!(
                r.p99_px <= r.max_px && r.mean_px <= r.max_px,
                "{}",
                r.config
            );
            assert_eq!(r.frames, if camera == "grazing" { 1 } else { 3 });
            // Only the tess path tessellates; its error LOD may draw every
            // patch at full resolution instead.
            let tessellates = r.figures.tes_invocations.unwrap() > 0;
            if r.path != RowPath::Tess || r.lod == Some(RowLod::Distance) {
                assert_eq!(tessellates, r.path == RowPath::Tess, "{}", r.config);
            }
            // The error LOD says what it expects; nothing else does.
            let error_lod = matches!(r.lod, Some(RowLod::Error | RowLod::ErrorView));
            assert_eq!(r.predicted_max_px.is_some(), error_lod, "{}", r.config);
            // The view measure expects the frame's 99th percentile within
            // tau (its largest error may be more: 1 % of pixels may).
            assert_eq!(
                r.predicted_p99_px.is_some(),
                r.lod == Some(RowLod::ErrorView),
                "{}",
                r.config
            );
            if let (Some(predicted), Some(tau)) = (r.predicted_p99_px, r.tau) {
                assert!(
                    predicted <= f64::from(tau) + 1e-6,
                    "{}: predicted p99 {predicted} px over tau",
                    r.config
                );
            }
            // The view model's share over tau is what the error LOD's
            // choice spent of its budget, never more; every row with a
            // tau has its measured share.
            assert_eq!(
                r.predicted_over_share.is_some(),
                r.lod == Some(RowLod::Error),
                "{}",
                r.config
            );
            if let Some(share) = r.predicted_over_share {
                assert!(
                    (0.0..=EXCEED_SHARE * 1.001).contains(&share),
                    "{}: the model put {share} of the pixels over tau",
                    r.config
                );
            }
            assert_eq!(r.over_share.is_some(), r.tau.is_some(), "{}", r.config);
            if let Some(share) = r.over_share {
                assert!((0.0..=1.0).contains(&share), "{}: {share}", r.config);
            }
            // Every row but brute's chooses levels and times it, in every
            // frame; the frame's time is the CPU's and the GPU's.
            assert_eq!(
                r.figures.lod_ms.is_some(),
                r.path != RowPath::Brute,
                "{}",
                r.config
            );
            if let (Some(median), Some(max)) = (r.figures.lod_ms, r.lod_ms_max) {
                assert!(median <= max && median > 0.0, "{}", r.config);
            }
            let frame = r.frame_ms.expect("lavapipe has timestamps");
            assert!(frame >= r.figures.gpu_ms.unwrap(), "{}", r.config);
        }
        // Looser tolerances draw no more. The oracle picks each patch's
        // level on its own, so every step holds. The error modes share the
        // frame's pixels over tau greedily (and geomip balances and stitches
        // after), so a tolerance twice as loose may spend its share on other
        // patches and draw a few more triangles; four times as loose never
        // draws more.
        for (path, lod) in [
            (RowPath::Tess, Some(RowLod::Error)),
            (RowPath::Geomip, Some(RowLod::Error)),
            (RowPath::Oracle, None),
        ] {
            let tris: Vec<u64> = rows_of(&rows, camera, path, lod)
                .iter()
                .map(|r| r.figures.triangles.unwrap())
                .collect();
            assert_eq!(tris.len(), 3);
            let monotone = if path == RowPath::Oracle {
                tris.windows(2).all(|w| w[0] >= w[1])
            } else {
                tris[0] >= tris[2]
            };
            assert!(monotone, "{camera} {path:?}: {tris:?}");
        }
        // Occlusion culling changes no pixel and draws no more, where the
        // two rows choose alike. A still camera's tess error rows read
        // the pixels their own frames counted (`render::seen`), which
        // culling changes (a culled patch counts nothing; an unculled
        // hidden one drawn before what hides it counts its overdraw):
        // each is held to tau on its own, above.
        for r in rows.iter().filter(|r| r.camera == camera && r.occlusion) {
            let off = rows_of(&rows, camera, r.path, r.lod)
                .into_iter()
                .find(|o| o.tau == r.tau)
                .expect("an occluded row has its counterpart");
            let alike = r.path != RowPath::Tess || camera == "flythrough";
            if alike {
                assert_eq!(r.differing_pixels, Some(0), "{}", r.config);
                assert!(r.figures.triangles <= off.figures.triangles, "{}", r.config);
            } else {
                let tau = f64::from(r.tau.expect("an error row's tau"));
                for row in [r, off] {
                    assert!(row.p99_px <= tau, "{}: p99 {} px", row.config, row.p99_px);
                }
            }
            // Culling ran on the measured frames, or sat out after a
            // frame where it hid nothing and drew what the row without it
            // draws. In the flythrough it may have run only on the frames
            // before those timed (a moving camera sits the next ones out).
            match (r.patches_occluded, r.culling_gpu_ms) {
                (_, Some(ms)) => {
                    assert!(ms > 0.0 && r.patches_occluded.is_some(), "{}", r.config)
                }
                (Some(_), None) => assert_eq!(camera, "flythrough", "{}", r.config),
                (None, None) if alike => {
                    assert_eq!(r.figures.triangles, off.figures.triangles, "{}", r.config);
                }
                (None, None) => {}
            }
            if alike {
                assert_eq!(
                    (r.max_px, r.p99_px, r.mismatched_pixels),
                    (off.max_px, off.p99_px, off.mismatched_pixels),
                    "{}",
                    r.config
                );
            }
        }
        for r in rows.iter().filter(|r| !r.occlusion) {
            assert_eq!(
                (r.patches_occluded, r.culling_gpu_ms, r.differing_pixels),
                (None, None, None),
                "{}",
                r.config
            );
        }
        for r in rows_of(&rows, camera, RowPath::Oracle, None) {
            assert!(r.figures.triangles.unwrap() <= brute_tris, "{}", r.config);
        }
    }
}

#[test]
fn bench_command_writes_every_output_and_merges_runs() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = data_path("jacksboro_fault_dem.toml");
    let scene = scene.to_str().unwrap();
    let run = |extra: &[&str]| {
        let mut args = vec![
            "bench",
            "--quick",
            "--validate",
            "--width",
            "64",
            "--height",
            "48",
            "--out",
            "out",
        ];
        args.extend_from_slice(extra);
        vkterrain(dir.path(), &args)
    };
    let out = run(&["--scene", scene]);
    let stdout = succeeded(&out);
    assert!(
        stdout.contains("rows on jacksboro_fault_dem (64x48"),
        "{stdout}"
    );
    assert!(stdout.contains("0 validation messages"), "{stdout}");
    for file in ["results.csv", "results.json", "pareto.png", "BENCHMARKS.md"] {
        assert!(
            dir.path().join("out").join(file).is_file(),
            "{file} written"
        );
    }
    let rows: Vec<serde_json::Value> = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("out/results.json")).unwrap(),
    )
    .unwrap();
    let paths: std::collections::BTreeSet<&str> =
        rows.iter().map(|r| r["path"].as_str().unwrap()).collect();
    assert_eq!(
        paths.into_iter().collect::<Vec<_>>(),
        ["brute", "geomip", "oracle", "tess"]
    );
    for r in &rows {
        for key in [
            "lod",
            "tau",
            "gpu_ms",
            "cpu_ms",
            "triangles",
            "tes_invocations",
            "gpu_memory_bytes",
            "max_px",
            "p99_px",
            "mean_px",
            "camera",
            "device",
        ] {
            assert!(r.get(key).is_some(), "{key} in {r}");
        }
    }
    let plot = image::open(dir.path().join("out/pareto.png")).unwrap();
    assert!(plot.width() >= 1000);

    // A second scene joins the first in one report.
    let out = run(&[
        "--name",
        "second",
        "--scene",
        scene,
        "--without",
        "tessellation",
    ]);
    succeeded(&out);
    let md = std::fs::read_to_string(dir.path().join("out/BENCHMARKS.md")).unwrap();
    assert!(md.contains("### jacksboro_fault_dem, grazing"));
    assert!(md.contains("### second, grazing"));
    let csv = std::fs::read_to_string(dir.path().join("out/results.csv")).unwrap();
    assert_eq!(
        csv.lines().count(),
        1 + rows.len() + rows.len() - 11,
        "second run has no tess rows"
    );

    // The report alone, published elsewhere with its plot link adjusted.
    std::fs::create_dir(dir.path().join("docs")).unwrap();
    let out = vkterrain(
        dir.path(),
        &[
            "bench",
            "--report-only",
            "--out",
            "out",
            "--publish",
            "docs/B.md",
        ],
    );
    succeeded(&out);
    let published = std::fs::read_to_string(dir.path().join("docs/B.md")).unwrap();
    assert!(published.contains("](../out/pareto.png)"));
}

#[test]
fn bench_refuses_bad_arguments() {
    let dir = tempfile::tempdir().unwrap();
    let fail = |args: &[&str], needle: &str| {
        let out = vkterrain(dir.path(), args);
        assert!(!out.status.success(), "{args:?} succeeded");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
    };
    fail(
        &["bench", "--out", "o", "--frames", "2"],
        "give 0 or at least 3",
    );
    fail(
        &["bench", "--out", "o", "--frames", "x"],
        "not a frame count",
    );
    fail(
        &["bench", "--report-only", "--out", "o"],
        "no results.json to report on",
    );
    std::fs::create_dir(dir.path().join("bad")).unwrap();
    std::fs::write(dir.path().join("bad/results.json"), "[1, 2]").unwrap();
    fail(
        &["bench", "--out", "bad"],
        "not the results of an earlier run",
    );
    fail(&["bench"], "--out");
    fail(
        &["bench", "--out", "o", "--gpu-warm-ms", "20000"],
        "--gpu-warm-ms",
    );
    fail(
        &["bench", "--out", "o", "--gpu-warm-ms=-5"],
        "--gpu-warm-ms",
    );
    fail(
        &["bench", "--out", "o", "--timed-frames", "0"],
        "--timed-frames",
    );
    fail(
        &["bench", "--out", "q", "--quick", "--view", "flythrough"],
        "leave the flythrough out",
    );
    assert!(!dir.path().join("q").exists(), "nothing written");
}

/// `--single-frame`: every named view once, timed, no flythrough.
#[test]
fn a_single_frame_run_renders_each_view_once() {
    if skip_gpu() {
        return;
    }
    let gpu = open_gpu(None);
    let info =
        TerrainInfo::new(noise_map(33, 33, 7), DVec2::new(4.0, 4.0), 16, DVec2::ZERO).unwrap();
    let terrain = Terrain::new(info, 0.0).unwrap();
    let lod = DistanceLod::for_extent(128.0);
    let configs = configs(lod, true, true);
    let options = BenchOptions {
        width: 64,
        height: 48,
        quick: false,
        flythrough_frames: 0,
        single_frame: true,
        views: Vec::new(),
        gpu_warm_ms: 0,
        timed_frames: TIMED_FRAMES,
    };
    let mut bench = Bench::new(&gpu, &terrain, lod, &configs, 64, 48).expect("bench objects");
    let mut progress = Count(0, 0);
    let rows = bench
        .run("single", &configs, &options, &mut progress)
        .expect("the run completes");
    drop(bench);
    let report = gpu.shutdown();
    assert_eq!(report.count, 0, "{:#?}", report.messages);
    // Three views, one render of each configuration, plus the oracle's
    // uniform levels (5 for 16-cell patches) and the cut frame per view
    // of each occluded row and of the row it is compared with.
    let occluded = configs.iter().filter(|c| c.occlusion()).count() as u64;
    assert_eq!(occluded, 2);
    assert_eq!(progress.1, 3 * (configs.len() as u64 + 5 + 2 * occluded));
    assert_eq!(progress.0, progress.1);
    assert_eq!(rows.len(), 3 * configs.len());
    for r in &rows {
        assert_eq!(r.frames, 1);
        assert!(r.figures.gpu_ms.is_some_and(|ms| ms > 0.0), "{}", r.config);
    }
}
