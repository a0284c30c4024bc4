//! What a benchmark run writes: results.csv, results.json, look.json,
//! pareto.png and BENCHMARKS.md. Rows of earlier runs in the same
//! directory are kept,
//! except those of the same scene on the same device, which the new run
//! replaces; so one directory can hold the default scene and the DEM, on
//! lavapipe and on a real GPU, in one report.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use plotters::prelude::*;

use serde::de::DeserializeOwned;
use serde::Serialize;

use super::look::{extra_percent, LookRow};
use super::run::{
    Row, RowLod, RowPath, FLYTHROUGH_PASSES, ORACLE_EXCEED_FRACTION, SINGLE_FRAME_TIMED_FRAMES,
    SINGLE_FRAME_TIMING, TIMED_FRAMES, WARM_UP,
};
use crate::output::write_atomically;

/// Tolerances at which tess error mode's p99 must be within tau.
pub const TARGET_TAUS: [f32; 3] = [0.5, 1.0, 2.0];
/// The level choice's largest time a frame of any error-mode row (tess and
/// geomip, the view measure's rows apart), in milliseconds.
pub const TARGET_LOD_MS: f64 = 0.5;
/// At tau = 1 px: tess error mode's frame time (CPU + GPU) over the
/// fastest row of the view whose p99 is within 1 px (every row counts).
pub const TARGET_TESS_VS_FASTEST: f64 = 1.25;
/// At tau = 1 px: tess error mode's triangles over the fewest of any row of
/// the view whose p99 is within 1 px.
pub const TARGET_TESS_VS_FEWEST: f64 = 2.0;

/// Rows already in `dir`, less those `fresh` replaces (same scene and
/// device), followed by `fresh`.
pub fn merge(dir: &Path, fresh: Vec<Row>) -> Result<Vec<Row>> {
    merge_file(&dir.join("results.json"), fresh, |r| {
        (r.scene.clone(), r.device.clone())
    })
}

/// Look rows already in `dir` (look.json), less those `fresh` replaces
/// (same scene and device), followed by `fresh`.
pub fn merge_look(dir: &Path, fresh: Vec<LookRow>) -> Result<Vec<LookRow>> {
    merge_file(&dir.join("look.json"), fresh, |r| {
        (r.scene.clone(), r.device.clone())
    })
}

fn merge_file<T: DeserializeOwned>(
    path: &Path,
    fresh: Vec<T>,
    key: impl Fn(&T) -> (String, String),
) -> Result<Vec<T>> {
    let mut rows: Vec<T> = match std::fs::read_to_string(path) {
        Ok(text) => serde_json::from_str(&text).with_context(|| {
            format!(
                "{}: not the results of an earlier run; remove it or choose another --out",
                path.display()
            )
        })?,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(e) => return Err(e).with_context(|| format!("{}: cannot read", path.display())),
    };
    let replaced: BTreeSet<(String, String)> = fresh.iter().map(&key).collect();
    rows.retain(|r| !replaced.contains(&key(r)));
    rows.extend(fresh);
    Ok(rows)
}

fn write_text(path: &Path, text: &str) -> Result<()> {
    write_atomically(path, |tmp| {
        std::fs::write(tmp, text).with_context(|| format!("{}: cannot write", path.display()))
    })
}

fn opt<T: std::fmt::Display>(v: Option<T>) -> String {
    v.map_or_else(String::new, |v| v.to_string())
}

/// One CSV field, quoted when it holds a comma or a quote.
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

pub fn csv(rows: &[Row]) -> String {
    let mut out = String::from(
        "scene,device,driver,width,height,camera,frames,path,lod,tau,config,gpu_ms,cpu_ms,\
         lod_ms,lod_ms_max,frame_ms,\
         triangles,tes_invocations,fragment_invocations,covered_pixels,gpu_memory_bytes,predicted_max_px,predicted_p99_px,predicted_over_share,over_share,max_px,p99_px,mean_px,error_pixels,\
         mismatched_pixels,occlusion,patches_occluded,patches_drawn_hidden,culling_gpu_ms,\
         differing_pixels\n",
    );
    for r in rows {
        let fields = [
            csv_field(&r.scene),
            csv_field(&r.device),
            csv_field(&r.driver),
            r.width.to_string(),
            r.height.to_string(),
            csv_field(&r.camera),
            r.frames.to_string(),
            r.path.name().to_string(),
            opt(r.lod.map(RowLod::name)),
            opt(r.tau),
            csv_field(&r.config),
            opt(r.figures.gpu_ms.map(|v| format!("{v:.3}"))),
            format!("{:.3}", r.figures.cpu_ms),
            opt(r.figures.lod_ms.map(|v| format!("{v:.4}"))),
            opt(r.lod_ms_max.map(|v| format!("{v:.4}"))),
            opt(r.frame_ms.map(|v| format!("{v:.3}"))),
            opt(r.figures.triangles),
            opt(r.figures.tes_invocations),
            opt(r.fragment_invocations),
            opt(r.covered_pixels),
            r.gpu_memory_bytes.to_string(),
            opt(r.predicted_max_px.map(|v| format!("{v:.4}"))),
            opt(r.predicted_p99_px.map(|v| format!("{v:.4}"))),
            opt(r.predicted_over_share.map(|v| format!("{v:.6}"))),
            opt(r.over_share.map(|v| format!("{v:.6}"))),
            format!("{:.4}", r.max_px),
            format!("{:.4}", r.p99_px),
            format!("{:.4}", r.mean_px),
            r.error_pixels.to_string(),
            r.mismatched_pixels.to_string(),
            r.occlusion.to_string(),
            opt(r.patches_occluded),
            opt(r.patches_drawn_hidden),
            opt(r.culling_gpu_ms.map(|v| format!("{v:.3}"))),
            opt(r.differing_pixels),
        ];
        out.push_str(&fields.join(","));
        out.push('\n');
    }
    out
}

fn write_json<T: Serialize>(path: &Path, rows: &[T]) -> Result<()> {
    write_text(path, &(serde_json::to_string_pretty(rows)? + "\n"))
}

/// What a report is made of: the speed-against-error rows and the look
/// rows.
pub struct Results<'a> {
    pub rows: &'a [Row],
    pub look: &'a [LookRow],
}

/// Writes every output into `dir` (and BENCHMARKS.md also to `publish`).
pub fn write_all(dir: &Path, results: &Results, notes: &str, publish: Option<&Path>) -> Result<()> {
    let rows = results.rows;
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create the output directory", dir.display()))?;
    write_json(&dir.join("results.json"), rows)?;
    if !results.look.is_empty() {
        write_json(&dir.join("look.json"), results.look)?;
    }
    write_text(&dir.join("results.csv"), &csv(rows))?;
    let png = dir.join("pareto.png");
    write_atomically(&png, |tmp| pareto(rows, tmp))?;
    write_text(
        &dir.join("BENCHMARKS.md"),
        &markdown(results, notes, "pareto.png"),
    )?;
    if let Some(target) = publish {
        let link = relative_link(target, &png);
        write_text(target, &markdown(results, notes, &link))?;
    }
    Ok(())
}

/// `to` as a link from the directory of `from` (both made absolute).
fn relative_link(from: &Path, to: &Path) -> String {
    let absolute = |p: &Path| -> PathBuf {
        let p = if p.is_absolute() {
            p.to_path_buf()
        } else {
            std::env::current_dir().unwrap_or_default().join(p)
        };
        p.components().collect()
    };
    let base = absolute(from);
    let base = base.parent().unwrap_or(Path::new("/"));
    let to = absolute(to);
    let common = base
        .components()
        .zip(to.components())
        .take_while(|(a, b)| a == b)
        .count();
    let ups = base.components().count() - common;
    let mut parts: Vec<String> = vec!["..".into(); ups];
    parts.extend(
        to.components()
            .skip(common)
            .map(|c| c.as_os_str().to_string_lossy().into_owned()),
    );
    parts.join("/")
}

/// The distinct `key`s of `rows`, in first-seen order.
pub fn first_seen<T, K: PartialEq>(rows: &[T], key: impl Fn(&T) -> K) -> Vec<K> {
    let mut seen = Vec::new();
    for r in rows {
        let k = key(r);
        if !seen.contains(&k) {
            seen.push(k);
        }
    }
    seen
}

/// Scene, device and camera: what one group of rows shares.
type GroupKey = (String, String, String);

/// Each group of rows, in first-seen order, with its key.
/// `path`'s error-mode row at tau = 1 px of a group, with or without
/// occlusion culling.
fn error_row_at_1px<'a>(group: &[&'a Row], path: RowPath, occlusion: bool) -> Option<&'a Row> {
    group.iter().copied().find(|r| {
        r.path == path
            && r.lod == Some(RowLod::Error)
            && r.tau == Some(1.0)
            && r.occlusion == occlusion
    })
}

fn groups(rows: &[Row]) -> Vec<(GroupKey, Vec<&Row>)> {
    first_seen(rows, |r| {
        (r.scene.clone(), r.device.clone(), r.camera.clone())
    })
    .into_iter()
    .map(|key| {
        let group = rows
            .iter()
            .filter(|r| (&r.scene, &r.device, &r.camera) == (&key.0, &key.1, &key.2))
            .collect();
        (key, group)
    })
    .collect()
}

/// What the targets come to on one camera's rows.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TargetCheck {
    /// Tess and geomip error mode's p99 at each of `TARGET_TAUS`.
    pub tess_p99: [Option<f64>; 3],
    pub geomip_p99: [Option<f64>; 3],
    /// The largest level choice of any frame of the tess and of the geomip
    /// error mode's rows (the view measure's rows apart).
    pub tess_lod_ms_max: Option<f64>,
    pub geomip_lod_ms_max: Option<f64>,
    /// At tau = 1 px: tess error mode's frame time (CPU + GPU), drawn with
    /// occlusion culling as `render` and the window draw it (its "+
    /// occlusion" row, where the run has one).
    pub tess_frame_ms: Option<f64>,
    /// The row with the smallest frame time whose p99 is within 1 px.
    pub fastest_config: Option<String>,
    /// Tess error mode's frame time over the fastest row's.
    pub tess_vs_fastest: Option<f64>,
    /// At tau = 1 px: tess error mode's triangles over brute's.
    pub tess_vs_brute_triangles: Option<f64>,
    /// The row with the fewest triangles whose p99 is within 1 px.
    pub fewest_config: Option<String>,
    /// Tess error mode's triangles over the fewest row's.
    pub tess_vs_fewest: Option<f64>,
}

/// The targets, read from the rows of one scene, device and camera.
pub fn check_targets(rows: &[&Row]) -> TargetCheck {
    let error_rows = |path: RowPath| {
        rows.iter()
            .filter(move |r| r.path == path && r.lod == Some(RowLod::Error))
            .copied()
    };
    let find =
        |path: RowPath, tau: f32| error_rows(path).find(|r| r.tau == Some(tau) && !r.occlusion);
    let brute = rows.iter().find(|r| r.path == RowPath::Brute).copied();
    // Tess error mode as `render` and the window draw it: with occlusion
    // culling, its own row where the run has one.
    let tess = error_rows(RowPath::Tess)
        .find(|r| r.tau == Some(1.0) && r.occlusion)
        .or_else(|| find(RowPath::Tess, 1.0));
    let ratio = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) if b > 0.0 => Some(a / b),
        _ => None,
    };
    let tris = |r: Option<&Row>| r.and_then(|r| r.figures.triangles).map(|t| t as f64);
    let within: Vec<&Row> = rows.iter().filter(|r| r.p99_px <= 1.0).copied().collect();
    let fewest = within
        .iter()
        .filter(|r| r.figures.triangles.is_some())
        .min_by_key(|r| r.figures.triangles)
        .copied();
    let fastest = within
        .iter()
        .filter_map(|r| Some((*r, r.frame_ms?)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(r, _)| r);
    let lod_max = |path: RowPath| {
        error_rows(path)
            .filter_map(|r| r.lod_ms_max)
            .fold(None, |m: Option<f64>, v| Some(m.map_or(v, |m| m.max(v))))
    };
    TargetCheck {
        tess_p99: TARGET_TAUS.map(|t| find(RowPath::Tess, t).map(|r| r.p99_px)),
        geomip_p99: TARGET_TAUS.map(|t| find(RowPath::Geomip, t).map(|r| r.p99_px)),
        tess_lod_ms_max: lod_max(RowPath::Tess),
        geomip_lod_ms_max: lod_max(RowPath::Geomip),
        tess_frame_ms: tess.and_then(|r| r.frame_ms),
        fastest_config: fastest.map(|r| {
            format!(
                "{} ({})",
                r.config,
                r.frame_ms.map_or("n/a".into(), |v| format!("{v:.2} ms"))
            )
        }),
        tess_vs_fastest: ratio(
            tess.and_then(|r| r.frame_ms),
            fastest.and_then(|r| r.frame_ms),
        ),
        tess_vs_brute_triangles: ratio(tris(tess), tris(brute)),
        fewest_config: fewest.map(|r| format!("{} ({})", r.config, opt(r.figures.triangles))),
        tess_vs_fewest: ratio(tris(tess), tris(fewest)),
    }
}

fn verdict(value: Option<f64>, target: f64, at_least: bool, unit: &str) -> String {
    match value {
        None => "n/a".into(),
        Some(v) => {
            let met = if at_least { v >= target } else { v <= target };
            if met {
                format!("{v:.2}{unit} (met)")
            } else {
                let by = if at_least { target / v } else { v / target };
                format!("{v:.2}{unit} (**missed**, {by:.2}x off)")
            }
        }
    }
}

fn mib(bytes: u64) -> String {
    format!("{:.1}", bytes as f64 / (1024.0 * 1024.0))
}

/// BENCHMARKS.md: definitions, the targets, the notes, every row, and
/// what the picture costs.
pub fn markdown(results: &Results, notes: &str, pareto_link: &str) -> String {
    let rows = results.rows;
    let mut md = String::new();
    let w = &mut md;
    let _ = writeln!(w, "# Benchmarks: speed against error\n");
    let _ = writeln!(
        w,
        "Generated by `vkterrain bench` (`scripts/bench` reruns it on the default scene and the \
         Jacksboro DEM and copies this file to the repository root); edit `benches/notes.md` \
         for the prose at the end, not this file.\n"
    );
    let devices: BTreeSet<(String, String)> = rows
        .iter()
        .map(|r| (r.device.clone(), r.driver.clone()))
        .collect();
    let _ = writeln!(w, "Devices:\n");
    for (device, driver) in &devices {
        let _ = writeln!(w, "- {device}, driver {driver}");
    }
    let _ = writeln!(w, "\n**Every GPU time below:** {GPU_CLOCK_NOTE}");
    let _ = writeln!(
        w,
        "\n![Triangles and frame time against p99 error]({pareto_link})\n"
    );
    let _ = writeln!(w, "{}", definitions());
    targets_section(w, rows);
    predicted_section(w, rows);
    occlusion_section(w, rows);
    overdraw_section(w, rows);
    if !notes.trim().is_empty() {
        let _ = writeln!(w, "{}\n", notes.trim());
    }
    results_section(w, rows);
    look_section(w, results.look);
    md
}

/// The look rows: GPU time of each addition to the picture, and its share.
fn look_section(w: &mut String, look: &[LookRow]) {
    if look.is_empty() {
        return;
    }
    let _ = writeln!(w, "## What the picture costs\n");
    let _ = writeln!(
        w,
        "`vkterrain bench --look`: the scene's own view, the tess path with the scene's \
         LOD and material, drawn plain (layers projected from above, one sample per \
         pixel, a flat background) and with each addition: triplanar projection of steep \
         ground, the sky, multisample anti-aliasing, and all three. Each look is drawn \
         once untimed, then once a round in turn with the others; the GPU time is the \
         median over the rounds, and the last column the time over the plain row's. The \
         error rows above are drawn plain, with one sample per pixel, so their figures \
         keep their meaning.\n"
    );
    let keys = first_seen(look, |r| (r.scene.clone(), r.device.clone()));
    for (scene, device) in keys {
        let group: Vec<&LookRow> = look
            .iter()
            .filter(|r| r.scene == scene && r.device == device)
            .collect();
        let first = group[0];
        let _ = writeln!(
            w,
            "### {scene} ({}x{}, {} frames), {device}\n",
            first.width, first.height, first.frames
        );
        let _ = writeln!(w, "| look | samples | GPU ms | over plain |");
        let _ = writeln!(w, "|---|---:|---:|---:|");
        for r in group {
            let _ = writeln!(
                w,
                "| {} | {} | {} | {} |",
                r.config,
                r.samples,
                r.gpu_ms.map_or("n/a".into(), |v| format!("{v:.2}")),
                extra_percent(look, r).map_or("n/a".into(), |p| format!("{p:+.1} %")),
            );
        }
        let _ = writeln!(w);
    }
}

/// The target table: each target read off the rows, met or missed.
fn targets_section(w: &mut String, rows: &[Row]) {
    let _ = writeln!(w, "## Targets\n");
    let _ = writeln!(
        w,
        "Read from the rows below. Tess and geomip error mode's p99 at tau = 0.5, 1 and 2 px \
         must be within tau, and their level choice must take at most {TARGET_LOD_MS} ms in \
         every frame of every row (`lod_ms_max`: warm-up frames and each view's first frame \
         included; the view measure's rows apart). At tau = 1 px, tess error mode as `render` and \
         the window draw it (with occlusion culling: its \"+ occlusion\" row) must take a frame \
         (CPU + GPU) within {TARGET_TESS_VS_FASTEST}x of the fastest row of the same view whose \
         p99 is within 1 px (every row counts: brute, any distance setting, the peers' \
         policies, geomip, the oracle, the view measure), and draw no more triangles than \
         brute and at most {TARGET_TESS_VS_FEWEST}x the fewest of any row whose p99 is within \
         1 px. The rows without occlusion culling are in the tables below.\n"
    );
    let _ = writeln!(
        w,
        "| scene | device | camera | tess p99 at 0.5 / 1 / 2 px | level choice, largest frame: tess / geomip (<= {TARGET_LOD_MS} ms) | tess frame ms at 1 px | fastest row at p99 <= 1 px | tess / fastest (<= {TARGET_TESS_VS_FASTEST}x) | tess / brute triangles (<= 1x) | fewest triangles at p99 <= 1 px | tess / fewest (<= {TARGET_TESS_VS_FEWEST}x) | geomip p99 at 0.5 / 1 / 2 px |"
    );
    let _ = writeln!(w, "|---|---|---|---|---|---|---|---|---|---|---|---|");
    for ((scene, device, camera), group) in groups(rows) {
        let c = check_targets(&group);
        let p99s = |p99: &[Option<f64>; 3]| -> String {
            p99.iter()
                .zip(TARGET_TAUS)
                .map(|(&p, t)| verdict(p, f64::from(t), false, " px"))
                .collect::<Vec<_>>()
                .join(" / ")
        };
        let _ = writeln!(
            w,
            "| {scene} | {device} | {camera} | {} | {} / {} | {} | {} | {} | {} | {} | {} | {} |",
            p99s(&c.tess_p99),
            verdict(c.tess_lod_ms_max, TARGET_LOD_MS, false, " ms"),
            verdict(c.geomip_lod_ms_max, TARGET_LOD_MS, false, " ms"),
            c.tess_frame_ms.map_or("n/a".into(), |v| format!("{v:.2}")),
            c.fastest_config.as_deref().unwrap_or("none"),
            verdict(c.tess_vs_fastest, TARGET_TESS_VS_FASTEST, false, "x"),
            verdict(c.tess_vs_brute_triangles, 1.0, false, "x"),
            c.fewest_config.as_deref().unwrap_or("none"),
            verdict(c.tess_vs_fewest, TARGET_TESS_VS_FEWEST, false, "x"),
            p99s(&c.geomip_p99),
        );
    }
    let _ = writeln!(w);
}

/// Each error mode's predicted errors beside the measured ones.
fn predicted_section(w: &mut String, rows: &[Row]) {
    let _ = writeln!(w, "## Predicted against measured error\n");
    let _ = writeln!(
        w,
        "At tau = 1 px: the frame's 99th percentile and the largest error each error mode's \
         level choice expected on screen (`predicted_p99_px` and `predicted_max_px`, the \
         largest over the frames), beside the measured p99 and max; then the share of the \
         terrain's pixels the view model put over tau at the levels chosen \
         (`predicted_over_share`, the mean over the frames measured), beside the share \
         measured over tau (`over_share`). The model's share is what the choice spent of \
         its 0.5 % (`lod::plan::EXCEED_SHARE`); a measured share below it is a margin the \
         model did not need, one above it ground the model does not see.\n"
    );
    let _ = writeln!(
        w,
        "| scene | device | camera | tess predicted p99 / measured p99 / predicted max / measured max px | tess model's / measured share over tau | geomip predicted p99 / measured p99 / predicted max / measured max px | geomip model's / measured share over tau |"
    );
    let _ = writeln!(w, "|---|---|---|---|---|---|---|");
    for ((scene, device, camera), group) in groups(rows) {
        let cell = |path: RowPath| {
            error_row_at_1px(&group, path, false).map_or("n/a".to_string(), |r| {
                let px = |p: Option<f64>| p.map_or("n/a".into(), |p| format!("{p:.2}"));
                format!(
                    "{} / {:.3} / {} / {:.2}",
                    px(r.predicted_p99_px),
                    r.p99_px,
                    px(r.predicted_max_px),
                    r.max_px,
                )
            })
        };
        let shares = |path: RowPath| {
            error_row_at_1px(&group, path, false).map_or("n/a".to_string(), |r| {
                let share =
                    |s: Option<f64>| s.map_or("n/a".into(), |s| format!("{:.3} %", 100.0 * s));
                format!(
                    "{} / {}",
                    share(r.predicted_over_share),
                    share(r.over_share)
                )
            })
        };
        let _ = writeln!(
            w,
            "| {scene} | {device} | {camera} | {} | {} | {} | {} |",
            cell(RowPath::Tess),
            shares(RowPath::Tess),
            cell(RowPath::Geomip),
            shares(RowPath::Geomip)
        );
    }
    let _ = writeln!(w);
}

/// Each error mode at tau = 1 px with occlusion culling beside without it,
/// and the oracle's triangles.
/// Fragment shader invocations per covered pixel of brute and the error
/// modes at 1 px, each against brute's.
fn overdraw_section(w: &mut String, rows: &[Row]) {
    if !rows.iter().any(|r| overdraw(r).is_some()) {
        return;
    }
    let _ = writeln!(
        w,
        "## Per-pixel cost
"
    );
    let _ = writeln!(
        w,
        "Fragment shader invocations per pixel the terrain covers (`overdraw`), from pipeline \
         statistics, for brute and the error modes at tau = 1 px, and each path's figure over \
         brute's (the target is at most 1.2x). Every path culls faces turned away from the eye \
         and draws its patches nearest first. What the counter counts is the device's: a GPU \
         counts the fragments it shades, while lavapipe counts 16 for every 4x4 block of pixels a \
         triangle touches, before the depth test, so there the figure follows the triangles' \
         number and size more than what is shaded.\n"
    );
    let _ = writeln!(
        w,
        "| scene | device | camera | brute | tess error | tess + occlusion | geomip error | geomip + occlusion |"
    );
    let _ = writeln!(w, "|---|---|---|---:|---:|---:|---:|---:|");
    for ((scene, device, camera), group) in groups(rows) {
        let Some(brute) = group
            .iter()
            .find(|r| r.path == RowPath::Brute)
            .and_then(|r| overdraw(r))
        else {
            continue;
        };
        let cell = |path: RowPath, occlusion: bool| {
            error_row_at_1px(&group, path, occlusion)
                .and_then(overdraw)
                .map_or("n/a".into(), |o| format!("{o:.2} ({:.2}x)", o / brute))
        };
        let _ = writeln!(
            w,
            "| {scene} | {device} | {camera} | {brute:.2} | {} | {} | {} | {} |",
            cell(RowPath::Tess, false),
            cell(RowPath::Tess, true),
            cell(RowPath::Geomip, false),
            cell(RowPath::Geomip, true),
        );
    }
    let _ = writeln!(w);
}

fn occlusion_section(w: &mut String, rows: &[Row]) {
    let _ = writeln!(
        w,
        "## Occlusion culling
"
    );
    let _ = writeln!(
        w,
        "Error mode at tau = 1 px with occlusion culling (\"+ occlusion\") beside the same mode \
         without it, and the oracle at 1 px, which charges hidden patches nothing. \"on / best\" \
         sets the culled row's triangles against the fewest of any row without culling whose p99 \
         is within 1 px (the targets' best row). Triangles and GPU ms are per frame; \"culling\" is the depth pyramid and the patch test, part of the \
         frame; \"occluded\" the patches it hid; \"drawn hidden\" the patches it drew though the \
         reference shows none of their pixels; \"differing\" the pixels, over all frames, whose \
         colour differs from the render without occlusion culling (the target is 0).\n"
    );
    let _ = writeln!(
        w,
        "| scene | device | camera | path | triangles off / on / oracle | fewer | on / best | GPU ms off / on | culling ms (share) | occluded | drawn hidden | differing |"
    );
    let _ = writeln!(w, "|---|---|---|---|---|---|---|---|---|---|---|---|");
    for ((scene, device, camera), group) in groups(rows) {
        let oracle = group
            .iter()
            .find(|r| r.path == RowPath::Oracle && r.tau == Some(1.0));
        // The fewest triangles of any row without occlusion culling whose
        // p99 is within 1 px (the targets' best row).
        let best = group
            .iter()
            .filter(|r| r.p99_px <= 1.0 && !r.occlusion)
            .filter_map(|r| r.figures.triangles)
            .min();
        for path in [RowPath::Tess, RowPath::Geomip] {
            let find = |occlusion: bool| error_row_at_1px(&group, path, occlusion);
            let (Some(off), Some(on)) = (find(false), find(true)) else {
                continue;
            };
            let ratio = |a: Option<u64>, b: Option<u64>| match (a, b) {
                (Some(a), Some(b)) if b > 0 => format!("{:.2}x", a as f64 / b as f64),
                _ => "n/a".into(),
            };
            let fewer = ratio(off.figures.triangles, on.figures.triangles);
            let vs_best = ratio(on.figures.triangles, best);
            let ms = |v: Option<f64>| v.map_or("n/a".into(), |v| format!("{v:.1}"));
            let share = match (on.culling_gpu_ms, on.figures.gpu_ms) {
                (Some(c), Some(f)) if f > 0.0 => format!("{c:.1} ({:.1} %)", 100.0 * c / f),
                _ => "n/a".into(),
            };
            let _ = writeln!(
                w,
                "| {scene} | {device} | {camera} | {} | {} / {} / {} | {fewer} | {vs_best} | {} / {} | {share} | {} | {} | {} |",
                path.name(),
                opt(off.figures.triangles),
                opt(on.figures.triangles),
                opt(oracle.and_then(|o| o.figures.triangles)),
                ms(off.figures.gpu_ms),
                ms(on.figures.gpu_ms),
                opt(on.patches_occluded),
                opt(on.patches_drawn_hidden),
                opt(on.differing_pixels),
            );
        }
    }
    let _ = writeln!(w);
}

/// Every row, one table per scene, device and camera.
fn results_section(w: &mut String, rows: &[Row]) {
    let _ = writeln!(w, "## Results\n");
    for ((scene, device, camera), group) in groups(rows) {
        let first = group[0];
        let _ = writeln!(
            w,
            "### {scene}, {camera} ({} frame{}, {}x{}), {device}\n",
            first.frames,
            if first.frames == 1 { "" } else { "s" },
            first.width,
            first.height
        );
        let _ = writeln!(
            w,
            "| config | triangles | TES invocations | overdraw | GPU ms | CPU ms | level choice ms (largest) | frame ms | GPU MiB | predicted max px | max px | p99 px | mean px | mismatched |"
        );
        let _ = writeln!(
            w,
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
        );
        for r in group {
            let _ = writeln!(
                w,
                "| {} | {} | {} | {} | {} | {:.2} | {} | {} | {} | {} | {:.2} | {:.3} | {:.4} | {:.3} % |",
                r.config,
                opt(r.figures.triangles),
                opt(r.figures.tes_invocations),
                overdraw(r).map_or("n/a".into(), |v| format!("{v:.2}")),
                r.figures.gpu_ms.map_or("n/a".into(), |v| format!("{v:.2}")),
                r.figures.cpu_ms,
                match (r.figures.lod_ms, r.lod_ms_max) {
                    (Some(m), Some(x)) => format!("{m:.3} ({x:.3})"),
                    _ => "n/a".into(),
                },
                r.frame_ms.map_or("n/a".into(), |v| format!("{v:.2}")),
                mib(r.gpu_memory_bytes),
                r.predicted_max_px
                    .map_or("n/a".into(), |v| format!("{v:.2}")),
                r.max_px,
                r.p99_px,
                r.mean_px,
                100.0 * r.mismatched_pixels as f64 / r.error_pixels.max(1) as f64,
            );
        }
        let _ = writeln!(w);
    }
}

/// What every absolute GPU time in a report is taken under.
pub const GPU_CLOCK_NOTE: &str = "Each frame is submitted alone and waited for, as one frame in \
flight: a GPU that lowers its clocks when lightly loaded draws it at that clock, and an absolute \
GPU time can read several times what the same frame costs at full clock. On lavapipe ratios \
between rows of one run are fair. An NVIDIA H100 run this way sat at 345 of its 1,980 MHz for most \
of a run; its rows were measured with `--gpu-warm-ms 50` (each timed frame of a fixed view follows \
50 ms of the same frame drawn untimed), under which its SM clock, sampled every 50 ms, read \
1,980 MHz in 68 % of the samples, the rest mostly in the CPU-bound view-measure rows and the error \
read-backs.";

/// Fragment shader invocations per pixel the terrain covers.
pub fn overdraw(r: &Row) -> Option<f64> {
    match (r.fragment_invocations, r.covered_pixels) {
        (Some(f), Some(c)) if c > 0 => Some(f as f64 / c as f64),
        _ => None,
    }
}

fn definitions() -> String {
    format!(
        "## What is measured\n\n\
**Screen-space error.** The reference is the brute path (every heightmap sample a vertex, \
split like `height_at`), rendered from the same camera at the same size. For each pixel, both \
depth buffers are turned back into the camera-relative positions their surfaces show at the \
pixel's centre: R on the reference, T on the tested render. Both lie on the pixel's view ray. \
The pixel's error is the vertical separation seen face-on at the reference's distance, \
|T.y - R.y| * K / |R - eye| pixels, where K = viewport height / (2 tan(fov_y / 2)). This is the \
quantity the LOD choices bound: a height error e at distance d covers e * K / d pixels, so tau \
and the measured figures are in the same unit. A pixel that is terrain in one render and sky \
in the other is a coverage mismatch; its error is the distance in pixels to the nearest pixel \
where the tested render shows what the reference shows there (how far the silhouette moved), \
searched up to 32 pixels and counted as 32 beyond. Pixels that are sky in both are left out. \
max, p99 and mean are over every remaining pixel of every frame of a row; p99 is the \
ceil(0.99 n)-th smallest error. Mismatches' errors are kept exactly; the others are \
binned, 1000 logarithmic bins per decade, and read at their bin's largest: the percentile is \
never below the exact value, within 0.23 % above it, and exact where it falls on a \
mismatch's distance (a silhouette moved by one whole pixel measures exactly 1 px).\n\n\
Where one surface hides another (a ridge in front of a valley), a pixel's two positions can lie \
on different hills, and its error is large even when both surfaces are close: such pixels are \
counted as they are, never filtered out.\n\n\
**Speed.** `gpu_ms` is the time between timestamps written before and after the terrain draw, \
the median of {TIMED_FRAMES} frames (`--timed-frames`) after {WARM_UP} untimed ones for a fixed view. The \
flythrough's closed loop is flown {FLYTHROUGH_PASSES} times, each row drawing each frame in turn and going on \
from its own frame before; a row's time for a frame is its median over the passes, and its time \
for the flythrough the median of those over all frames but the first {WARM_UP}, so a single slow \
draw of one frame does not move the row. A fixed view's frames are timed in \
rounds, one frame of every row (brute included) a round, nothing read back or measured \
between them, so that whatever slows the machine during the run slows every row alike; each \
row's error and counts come from one more frame, drawn and read back after the rounds. In the flythrough's first pass a frame is timed and read back at once (the \
readback is recorded after the second timestamp); the later passes read nothing back. With `--single-frame` a fixed view is read back once, and each row is \
timed by that frame and the frames it draws straight after it, up to {SINGLE_FRAME_TIMED_FRAMES} in all within \
{timing_ms} ms of that frame's start: a row a GPU draws in milliseconds is timed by a median, one \
that takes longer (brute's tens of millions of triangles on lavapipe) once. {GPU_CLOCK_NOTE} `cpu_ms` is the median time to choose \
levels, write uniforms and record the frame's commands; `lod_ms` is the level choice alone \
(its median over the timed frames), and `lod_ms_max` its largest in any frame of the row, \
warm-up frames and each view's first frame included, so a choice that only a still camera \
could reuse is not hidden. `frame_ms` is the median over the timed frames (the flythrough's, each a median over its \
passes) of CPU plus GPU time: what a frame costs a user. `triangles` are clipping primitives \
(lavapipe leaves out the back-facing triangles of a draw it sends through its clipper, \
and counts them in any other draw) and \
`tes_invocations` tessellation evaluation invocations, from pipeline statistics (the mean per \
frame over the flythrough). `overdraw` is `fragment_invocations` (fragment shader invocations, \
from the same statistics) over `covered_pixels` (the pixels the terrain covers in the row's \
own render): 1 where every covered pixel is shaded once. `gpu_memory_bytes` is the device memory of the renderer of the \
row's path (heightmap, buffers, uniforms) plus the render target.\n\n\
**Oracle.** For each camera frame, the geomip geometry is drawn with every patch at one uniform \
level, for each level in turn, and measured against brute. Each pixel's error is charged to \
the patch under its reference surface point. Per patch, the oracle takes the coarsest level at \
which at most {:.0} % of the patch's pixels exceed tau (its per-patch 99th percentile is at \
most tau); unseen patches take the coarsest level. Neighbours are then refined to within one \
level of each other so the stitched edges meet, and that mix is rendered and measured like any \
other row. Its triangle count is what measured error alone says a level choice could get \
away with.\n\n\
**Occlusion.** Rows marked \"+ occlusion\" draw each frame in two passes: the patches that \
passed the last frame's test, then, after a depth pyramid is built and every patch's box is \
tested against it, the patches newly found visible. Their renderer keeps its visibility from \
frame to frame and sees only its own row's frames, so each fixed view starts as a camera cut \
from the view before it (that first frame is compared but not timed) and the flythrough runs \
on from the last fixed view. The row without culling draws the same first frame, for the \
comparison. `differing` counts the pixels, over every compared frame, whose colour differs \
from the same row's render without occlusion culling at the same camera and the same frame \
of its view: a first frame with a first frame, the read-back frame with the read-back \
frame.\n",
        100.0 * ORACLE_EXCEED_FRACTION,
        timing_ms = SINGLE_FRAME_TIMING.as_millis(),
    )
}

/// What a plot's y axis shows of a row.
type Measure = dyn Fn(&Row) -> Option<f64>;

/// A point series of the plot: name, colour, (p99, value) points.
type Series = (String, RGBColor, Vec<(f64, f64)>);

/// Which rows a scene's plot shows: the flythrough's when there is one,
/// otherwise the first camera's.
fn plotted<'a>(rows: &'a [Row], scene: &str, device: &str) -> Vec<&'a Row> {
    let of_scene: Vec<&Row> = rows
        .iter()
        .filter(|r| r.scene == scene && r.device == device)
        .collect();
    let camera = of_scene
        .iter()
        .find(|r| r.frames > 1)
        .or(of_scene.first())
        .map(|r| r.camera.clone())
        .unwrap_or_default();
    of_scene
        .into_iter()
        .filter(|r| r.camera == camera)
        .collect()
}

fn series(rows: &[&Row], value: impl Fn(&Row) -> Option<f64>) -> Vec<Series> {
    use RowLod as L;
    use RowPath as P;
    let families: [(&str, RowPath, Option<RowLod>, RGBColor); 11] = [
        ("brute", P::Brute, None, RGBColor(0, 0, 0)),
        (
            "SaschaWillems sphere",
            P::Tess,
            Some(L::Sphere),
            RGBColor(140, 86, 75),
        ),
        (
            "Dupuy edge length",
            P::Tess,
            Some(L::EdgeLength),
            RGBColor(227, 119, 194),
        ),
        ("CDLOD", P::Tess, Some(L::Cdlod), RGBColor(127, 127, 127)),
        (
            "tess distance",
            P::Tess,
            Some(L::Distance),
            RGBColor(31, 119, 180),
        ),
        ("tess error", P::Tess, Some(L::Error), RGBColor(214, 39, 40)),
        (
            "geomip distance",
            P::Geomip,
            Some(L::Distance),
            RGBColor(44, 160, 44),
        ),
        (
            "geomip error",
            P::Geomip,
            Some(L::Error),
            RGBColor(255, 127, 14),
        ),
        ("oracle", P::Oracle, None, RGBColor(148, 103, 189)),
        (
            "tess error, view measure",
            P::Tess,
            Some(L::ErrorView),
            RGBColor(120, 0, 0),
        ),
        (
            "geomip error, view measure",
            P::Geomip,
            Some(L::ErrorView),
            RGBColor(160, 80, 0),
        ),
    ];
    families
        .iter()
        .map(|&(name, path, lod, colour)| {
            let mut points: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.path == path && r.lod == lod)
                .filter_map(|r| Some((r.p99_px.max(PLOT_MIN_P99), value(r)?)))
                .filter(|p| p.1 > 0.0)
                .collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            (name.to_string(), colour, points)
        })
        .filter(|s| !s.2.is_empty())
        .collect()
}

/// p99 of 0 (brute against itself) is drawn here on the log axis.
const PLOT_MIN_P99: f64 = 0.01;

static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

fn register_font() -> Result<()> {
    static REGISTERED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, FONT).is_ok()
    });
    anyhow::ensure!(ok, "the built-in plot font could not be loaded");
    Ok(())
}

/// pareto.png: per scene and device, triangles and frame time against p99
/// error, log-log, one colour per configuration family.
pub fn pareto(rows: &[Row], path: &Path) -> Result<()> {
    register_font()?;
    let panels = first_seen(rows, |r| (r.scene.clone(), r.device.clone()));
    let (w, h) = (1400u32, 520 * panels.len().max(1) as u32);
    let mut pixels = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, (w, h)).into_drawing_area();
        let cells = root.split_evenly((panels.len().max(1), 2));
        for (i, (scene, device)) in panels.iter().enumerate() {
            let shown = plotted(rows, scene, device);
            let camera = shown.first().map(|r| r.camera.clone()).unwrap_or_default();
            let measures: [(&str, Box<Measure>); 2] = [
                (
                    "triangles per frame",
                    Box::new(|r: &Row| r.figures.triangles.map(|t| t as f64)),
                ),
                ("frame ms (CPU + GPU)", Box::new(|r: &Row| r.frame_ms)),
            ];
            for (j, (label, value)) in measures.iter().enumerate() {
                let data = series(&shown, value);
                let points = data.iter().flat_map(|s| s.2.iter());
                let (x_max, y_min, y_max) = points.fold((1.0f64, f64::MAX, 0.0f64), |a, p| {
                    (a.0.max(p.0), a.1.min(p.1), a.2.max(p.1))
                });
                if y_max <= 0.0 {
                    continue;
                }
                let area = &cells[i * 2 + j];
                let mut chart = ChartBuilder::on(area)
                    .caption(
                        format!("{scene}, {camera}: {label} ({device})"),
                        ("sans-serif", 16),
                    )
                    .margin(12)
                    .x_label_area_size(40)
                    .y_label_area_size(70)
                    .build_cartesian_2d(
                        (PLOT_MIN_P99 * 0.8..x_max * 1.5).log_scale(),
                        (y_min * 0.7..y_max * 1.4).log_scale(),
                    )?;
                chart
                    .configure_mesh()
                    .x_desc("p99 screen-space error (px)")
                    .y_desc(*label)
                    .label_style(("sans-serif", 13))
                    .draw()?;
                for (name, colour, pts) in data {
                    let style = ShapeStyle::from(colour).filled();
                    chart
                        .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(1)))?
                        .label(name)
                        .legend(move |(x, y)| Circle::new((x + 8, y), 4, style));
                    chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, style)))?;
                }
                chart
                    .configure_series_labels()
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK)
                    .label_font(("sans-serif", 13))
                    .position(SeriesLabelPosition::UpperRight)
                    .draw()?;
            }
        }
        root.present()?;
    }
    let image = image::RgbImage::from_raw(w, h, pixels).expect("buffer of w * h pixels");
    image
        .save_with_format(path, image::ImageFormat::Png)
        .with_context(|| format!("{}: cannot write the plot", path.display()))
}
