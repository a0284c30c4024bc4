//! The fault-injection walk: every command that builds GPU objects is run
//! with the Nth allocation failing, and with the Nth queue submission and
//! all after it reporting a lost device, for N = 1, 2, ... until the fault
//! comes too late to matter. Every failing run must exit 1 with the
//! injected error, no panic, nothing written, and no leak: validation is
//! counted after the device is destroyed, and objects still alive then are
//! named as leaks.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::gpu::skip_gpu;
use common::*;

/// How to run one command of the walk in `dir`.
struct Walk {
    /// Arguments after the binary.
    args: Vec<String>,
    /// Run under a fresh Xvfb (the window demo).
    window: bool,
}

impl Walk {
    /// Runs the walk's command with `fault`. Under load, xvfb-run itself
    /// sometimes fails to remove its temporary directory after the
    /// command has finished and exits with its own error; such a run says
    /// nothing of vkterrain and is run again (at most twice more).
    fn run(&self, dir: &Path, fault: &str) -> Output {
        let mut out = self.run_once(dir, fault);
        for _ in 0..2 {
            let xvfb_failed = String::from_utf8_lossy(&out.stderr)
                .contains("xvfb-run: error: problem while cleaning up temporary directory");
            if !(self.window && xvfb_failed) {
                break;
            }
            out = self.run_once(dir, fault);
        }
        out
    }

    fn run_once(&self, dir: &Path, fault: &str) -> Output {
        let bin = env!("CARGO_BIN_EXE_vkterrain");
        let mut cmd = if self.window {
            let mut c = Command::new("xvfb-run");
            c.args(["-a", "-s", "-screen 0 640x480x24", bin]);
            c.env_remove("WAYLAND_DISPLAY");
            c
        } else {
            Command::new(bin)
        };
        cmd.current_dir(dir)
            .args(&self.args)
            .args(["--validate", "--inject-fault", fault])
            .output()
            .expect("the binary runs (xvfb-run for the window: apt-get install xvfb)")
    }
}

/// Runs `walk` with `KIND@n` for n = 1, 2, ... until a run succeeds; every
/// run before must fail cleanly. Returns how many points failed.
fn fails_cleanly_at_every_point(walk: &Walk, kind: &str, expected: &str) -> u32 {
    let dir = tempfile::tempdir().unwrap();
    for n in 1..=200 {
        let fault = format!("{kind}@{n}");
        let out = walk.run(dir.path(), &fault);
        let stderr = String::from_utf8_lossy(&out.stderr);
        let stdout = String::from_utf8_lossy(&out.stdout);
        if out.status.success() {
            // The run the fault came too late for is clean too.
            assert!(!stderr.contains("leak"), "{fault}: {stderr}");
            assert!(
                !stdout.contains("validation messages")
                    || stdout.contains(" 0 validation messages"),
                "{fault}: {stdout}"
            );
            return n - 1;
        }
        let what = format!("{:?} {fault}", walk.args.first());
        assert_eq!(out.status.code(), Some(1), "{what}: {stderr}");
        assert!(stderr.contains(expected), "{what}: {stderr}");
        assert!(stderr.contains("injected fault"), "{what}: {stderr}");
        assert!(!stderr.contains("panicked"), "{what}: {stderr}");
        // Whatever was built before the failure was freed again: no object
        // is still alive at shutdown, and validation reported nothing by
        // the device's destruction (its own leak report included).
        for leak in ["leak", "has not been destroyed", "Validation Error"] {
            assert!(!stderr.contains(leak), "{what}: {stderr}");
        }
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert!(left.is_empty(), "{what} left files behind: {left:?}");
    }
    panic!("{:?} still failing after 200 points", walk.args);
}

/// Both walks of one command; each must reach at least the given number
/// of points.
fn walk_both(walk: &Walk, submissions: u32, allocations: u32) {
    let lost = fails_cleanly_at_every_point(walk, "device-lost", "device has been lost");
    assert!(lost >= submissions, "{:?}: {lost} submissions", walk.args);
    let oom = fails_cleanly_at_every_point(walk, "out-of-memory", "Out of memory");
    assert!(oom >= allocations, "{:?}: {oom} allocations", walk.args);
}

fn args(list: &[&str]) -> Vec<String> {
    list.iter().map(|s| s.to_string()).collect()
}

/// A small generated heightmap, so each run of the walk is quick.
fn small_map(dir: &tempfile::TempDir) -> PathBuf {
    let mut bytes = Vec::new();
    for r in 0..33u32 {
        for c in 0..33u32 {
            let h = 30_000.0 + 9_000.0 * (c as f32 * 0.3).sin() * (r as f32 * 0.2).cos();
            bytes.extend_from_slice(&(h as u16).to_le_bytes());
        }
    }
    temp_file(dir, "small.r16", &bytes)
}

#[test]
fn render_fails_cleanly_at_every_point() {
    if skip_gpu() {
        return;
    }
    // The DEM with a textured layer, a normal map and a lightmap, so the
    // material's uploads are in the sequence too.
    let scenes = tempfile::tempdir().unwrap();
    let textures = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/textures");
    let scene = temp_file(
        &scenes,
        "scene.toml",
        format!(
            "[heightmap]\npath = \"{}\"\nheight_scale = 65535.0\ncell_spacing = [74.48, 92.15]\n\
             [lighting]\nlightmap = true\n[material]\n[[material.layer]]\ndiffuse = \"{t}/rock.png\"\n\
             normal = \"{t}/rock-normal.png\"\n",
            data_path("jacksboro_fault_dem.png").display(),
            t = textures.display()
        )
        .as_bytes(),
    );
    let walk = Walk {
        args: args(&[
            "render",
            "--scene",
            scene.to_str().unwrap(),
            "--width",
            "32",
            "--height",
            "18",
            "--out",
            "f.png",
            "--stats",
            "s.json",
        ]),
        window: false,
    };
    // Uploads and the frame itself; every buffer and image in turn.
    walk_both(&walk, 8, 16);
}

/// `command` on a small generated map at 32x18 pixels, with `extra`
/// arguments; the map's folder lives as long as the walk.
fn on_small_map(command: &str, extra: &[&str]) -> (tempfile::TempDir, Walk) {
    let maps = tempfile::tempdir().unwrap();
    let map = small_map(&maps).to_str().unwrap().to_string();
    let mut list = vec![
        command,
        "--heightmap",
        &map,
        "--width",
        "32",
        "--height",
        "18",
    ];
    list.extend_from_slice(extra);
    let walk = Walk {
        args: args(&list),
        window: false,
    };
    (maps, walk)
}

#[test]
fn bench_fails_cleanly_at_every_point() {
    if skip_gpu() {
        return;
    }
    // One timed frame a row: the walk visits every submission.
    let (_maps, walk) = on_small_map(
        "bench",
        &[
            "--quick",
            "--single-frame",
            "--timed-frames",
            "1",
            "--out",
            "results",
        ],
    );
    // Three renderers and the target, then every render of every view.
    walk_both(&walk, 20, 16);
}

#[test]
fn soak_fails_cleanly_at_every_point() {
    if skip_gpu() {
        return;
    }
    let (_maps, walk) = on_small_map(
        "soak",
        &[
            "--frames",
            "3",
            "--loop-frames",
            "3",
            "--report",
            "soak.json",
        ],
    );
    walk_both(&walk, 6, 12);
}

#[test]
fn info_and_the_window_fail_cleanly_at_every_point() {
    if skip_gpu() {
        return;
    }
    // `info` opens the device and makes nothing from it: no point to fail
    // at, and a clean teardown.
    let info = Walk {
        args: args(&["info"]),
        window: false,
    };
    walk_both(&info, 0, 0);
    // The window's setup (surface, swapchain, renderer, frames) and two
    // frames.
    let (_maps, mut demo) = on_small_map("demo", &["--frames", "2", "--exit"]);
    demo.window = true;
    walk_both(&demo, 6, 12);
}
