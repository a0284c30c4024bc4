//! `vkterrain soak`, short: paths and LOD modes switch along a looping
//! flythrough with validation on, and memory stays flat.

mod common;
use common::gpu::{open_gpu, skip_gpu};
use common::*;

#[test]
fn a_short_soak_is_clean_and_flat() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // Textured: material resources are part of what must not leak.
    let scene = data_path("jacksboro_fault_dem_textured.toml");
    let scene = scene.to_str().unwrap();
    let out = vkterrain_in(
        dir.path(),
        &[
            "soak",
            "--scene",
            scene,
            "--validate",
            // One full cycle of paths, LOD modes and error measures (27
            // phases of 50 frames) and one phase more before the baseline,
            // and a cycle after it, so that both ends sit at the same point
            // of the cycle: the last frame of a tessellated phase. Brute's
            // phases hold more driver memory than the others', and on
            // lavapipe several MB more during some of their frames than
            // others, so an end in one of them once read 6 % over a
            // baseline in another, or 4 % under, in runs whose memory did
            // not grow. The first use of each may allocate in the driver
            // (lavapipe compiles shader variants lazily); after it,
            // nothing may grow. No camera repeats: a driver that
            // specialises a shader on the frame's uniform values would
            // cache a looping flythrough's variants and hide the growth
            // (the control shader once grew 41 % here, a new compile per
            // tessellated frame).
            "--frames",
            "2750",
            "--baseline-frame",
            "1399",
            "--loop-frames",
            "2750",
            "--width",
            "96",
            "--height",
            "64",
            "--max-growth",
            "1",
            "--report",
            "soak.json",
        ],
    );
    succeeded(&out);
    let report: serde_json::Value = json_file(&dir.path().join("soak.json"));
    assert_eq!(report["frames"], 2750);
    assert_eq!(report["validation_enabled"], true);
    // Counted after the device is destroyed: leaks would show here.
    assert_eq!(report["validation_messages"], 0);
    // Everything is allocated up front: the allocator does not move at all.
    assert_eq!(report["allocator_growth_percent"], 0.0);
    assert!(report["allocator_bytes_at_end"].as_u64().unwrap() > 0);
    assert!(report["resident_bytes_at_baseline"].as_u64().unwrap() > 1 << 20);
}

#[test]
fn soak_refuses_bad_arguments() {
    for (args, needle) in [
        (&["soak", "--frames", "0"][..], "at least 1"),
        (
            &["soak", "--frames", "10", "--loop-frames", "2"][..],
            "--loop-frames 2",
        ),
        (&["soak"][..], "--frames"),
    ] {
        let out = vkterrain_in(std::path::Path::new("."), args);
        assert!(!out.status.success(), "{args:?}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
    }
}

#[test]
fn shutdown_reports_objects_left_alive() {
    if skip_gpu() {
        return;
    }
    let gpu = open_gpu(None);
    let leaked = gpu
        .device
        .create_host_buffer(
            "leaked",
            ash::vk::BufferUsageFlags::UNIFORM_BUFFER,
            &[0u8; 64],
        )
        .unwrap();
    std::mem::forget(leaked);
    let report = gpu.shutdown();
    assert!(report.count > 0, "a buffer left alive is reported");
    assert!(
        report
            .messages
            .iter()
            .any(|m| m.contains("BUFFER \"leaked\"") && m.contains("leak")),
        "{:#?}",
        report.messages
    );
}
