//! `vkterrain render`, `info` and the bare run command, through the binary
//! on a real Vulkan device (lavapipe in CI), with validation on.

mod common;

use std::path::Path;
use std::process::Command;

use common::gpu::skip_gpu;
use common::vkterrain_in as vkterrain;
use common::*;

#[test]
fn render_writes_the_png_and_its_stats() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = vkterrain(
        dir.path(),
        &[
            "render",
            "--validate",
            "--width",
            "320",
            "--height",
            "180",
            "--out",
            "f.png",
            "--stats",
            "s.json",
        ],
    );
    let stdout = succeeded(&out);
    assert!(stdout.contains("wrote f.png (320x180)"), "{stdout}");
    let image = image::open(dir.path().join("f.png")).unwrap();
    assert_eq!((image.width(), image.height()), (320, 180));
    let s = json_file(&dir.path().join("s.json"));
    assert!(!s["device"].as_str().unwrap().is_empty());
    assert_eq!(s["path"], "tess");
    assert_eq!(s["patches_total"], 1024);
    let in_view = s["patches_in_frustum"].as_u64().unwrap();
    assert!(in_view > 100 && in_view <= 1024, "{in_view}");
    // Occlusion culling is on by default: a first frame draws every patch
    // in its first pass, so the second pass's draws have nothing to keep
    // and are skipped. Each patch in view reaches the control shader once,
    // but those the error LOD draws at full resolution, which never do.
    assert_eq!(s["occlusion"], true);
    assert_eq!(s["patches_occluded"], 0);
    assert!(s["culling_gpu_ms"].as_f64().unwrap() > 0.0);
    let exact = s["patches_full_resolution"].as_u64().unwrap();
    assert!(exact < in_view, "{exact} of {in_view}");
    assert_eq!(s["tcs_patches"], in_view - exact);
    assert!(s["tes_invocations"].as_u64().unwrap() > 1000);
    assert!(s["triangles"].as_u64().unwrap() > 1000);
    assert!(
        s["gpu_ms"].as_f64().unwrap() > 0.0,
        "lavapipe has timestamps"
    );
    assert!(s["cpu_ms"].as_f64().unwrap() > 0.0);
    // The heightmap alone is 1025 * 1025 floats.
    assert!(s["gpu_memory"]["terrain.heightmap"].as_u64().unwrap() >= 1025 * 1025 * 4);
    assert!(s["gpu_memory_bytes"].as_u64().unwrap() >= 1025 * 1025 * 4);
    // 4 samples per pixel by default: Vulkan requires every device to
    // draw them. The multisampled images hold 4 samples of each pixel.
    assert_eq!(s["samples"], 4);
    for (name, bytes_per_sample) in [
        ("offscreen.multisampled_color", 4),
        ("offscreen.multisampled_depth", 4),
    ] {
        let bytes = s["gpu_memory"][name].as_u64().unwrap_or(0);
        assert!(
            bytes >= 320 * 180 * 4 * bytes_per_sample,
            "{name}: {bytes} bytes"
        );
    }
    assert_eq!(s["validation_enabled"], true);
    assert_eq!(s["validation_messages"], 0);
    assert!(!dir.path().join(".f.png.partial").exists());
}

/// `render --validate` of the DEM in 16-cell patches, in `dir`, with
/// `options` after.
fn render_dem(dir: &Path, options: &[&str]) -> std::process::Output {
    let dem = dem_args();
    let mut args = vec!["render", "--validate", "--cells-per-patch", "16"];
    args.extend(dem.iter().map(String::as_str));
    args.extend(options);
    vkterrain(dir, &args)
}

#[test]
fn render_takes_heightmap_and_camera_options() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = render_dem(
        dir.path(),
        &[
            "--eye=-15000,9000,-16000",
            "--target",
            "0,600,0",
            "--fov",
            "50",
            "--lod-distance",
            "1000,30000",
            "--lod-levels",
            "1,5",
            "--lod-mode",
            "debug",
            "--lod-colors",
            "--width",
            "200",
            "--height",
            "150",
            "--out",
            "dem.png",
            "--stats",
            "dem.json",
        ],
    );
    succeeded(&out);
    let s = json_file(&dir.path().join("dem.json"));
    assert_eq!(s["patches_total"], 22 * 26);
    assert_eq!(s["validation_messages"], 0);
    assert_eq!(s["eye"][0], -15000.0);
    let brute = vkterrain(
        dir.path(),
        &[
            "render",
            "--validate",
            "--path",
            "brute",
            "--width",
            "96",
            "--height",
            "64",
            "--out",
            "b.png",
            "--stats",
            "b.json",
        ],
    );
    succeeded(&brute);
    let b = json_file(&dir.path().join("b.json"));
    assert_eq!(b["path"], "brute");
    assert_eq!(b["tes_invocations"], 0);
    assert!(
        b["triangles"].as_u64().unwrap() > 100_000,
        "every cell in view drawn: {}",
        b["triangles"]
    );
    assert_eq!(b["validation_messages"], 0);
    // Brute needs no buffers of its own: no control points, no indices.
    assert!(b["gpu_memory"].get("terrain.control_points").is_none());
    assert!(b["gpu_memory"].get("terrain.patch_indices").is_none());
    let wire = vkterrain(
        dir.path(),
        &[
            "render",
            "--validate",
            "--wireframe",
            "--width",
            "64",
            "--height",
            "64",
            "--out",
            "w.png",
        ],
    );
    succeeded(&wire);
}

/// From far off, the error LOD draws the DEM's flat blocks as merged
/// nodes: fewer patches reach the control shader than are in view, and
/// `--merge-patches off` sends every patch in view (none of them at full
/// resolution from there).
#[test]
fn render_stats_count_merged_nodes_and_merging_turns_off() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let stats = |merge: &str| {
        let out = render_dem(
            dir.path(),
            &[
                "--eye=0,60000,1",
                "--target",
                "0,0,0",
                "--pixel-error",
                "4",
                "--error-measure",
                "bound",
                "--merge-patches",
                merge,
                "--width",
                "320",
                "--height",
                "240",
                "--out",
                "m.png",
                "--stats",
                "m.json",
            ],
        );
        succeeded(&out);
        json_file(&dir.path().join("m.json"))
    };
    let on = stats("on");
    let off = stats("off");
    for s in [&on, &off] {
        assert_eq!(s["patches_full_resolution"], 0);
        assert_eq!(s["validation_messages"], 0);
    }
    let in_view = on["patches_in_frustum"].as_u64().unwrap();
    let nodes = on["merged_nodes"].as_u64().unwrap();
    assert!(nodes >= 2, "{nodes} merged nodes");
    let tcs = on["tcs_patches"].as_u64().unwrap();
    assert!(tcs < in_view / 2, "{tcs} patches shaded of {in_view}");
    assert_eq!(off["merged_nodes"], 0);
    assert_eq!(off["tcs_patches"], in_view);
}

#[test]
fn bare_command_without_a_display_renders_headless_and_says_where() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_vkterrain"))
        .current_dir(dir.path())
        .env("VKTERRAIN_VALIDATE", "1")
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    let stdout = succeeded(&out);
    assert!(stdout.contains("no display (DISPLAY and WAYLAND_DISPLAY are unset): rendering the default scene headless"), "{stdout}");
    assert!(
        stdout.contains("wrote vkterrain-default.png (1280x720)"),
        "{stdout}"
    );
    assert!(stdout.contains("0 validation messages"), "{stdout}");
    let image = image::open(dir.path().join("vkterrain-default.png")).unwrap();
    assert_eq!((image.width(), image.height()), (1280, 720));
}

#[test]
fn info_names_the_device_and_features() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&succeeded(&vkterrain(dir.path(), &["info", "--validate"]))).unwrap();
    assert!(!json["device"]["device_name"].as_str().unwrap().is_empty());
    assert_eq!(json["device"]["tessellation_shader"], true);
    assert!(json["used"]
        .as_array()
        .unwrap()
        .iter()
        .any(|f| f.as_str().unwrap().starts_with("tessellationShader")));
    assert_eq!(json["validation"], true);
}

#[test]
fn no_vulkan_driver_is_a_clear_failure() {
    let dir = tempfile::tempdir().unwrap();
    for args in [&["info"][..], &["render", "--out", "x.png"][..]] {
        let out = Command::new(env!("CARGO_BIN_EXE_vkterrain"))
            .current_dir(dir.path())
            .args(args)
            .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
            .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?} succeeded without a driver");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.contains("no Vulkan device found"),
            "{args:?}: {stderr}"
        );
        assert!(
            !dir.path().join("x.png").exists(),
            "no image without a device"
        );
    }
}

#[test]
fn bad_render_arguments_fail_before_rendering() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&[&str], &str); 7] = [
        (
            &["render", "--out", "x.png", "--width", "0"],
            "outside 1..=16384",
        ),
        (
            &["render", "--out", "x.png", "--fov", "180"],
            "between 0 and 180",
        ),
        (
            &["render", "--out", "x.png", "--lod-levels", "3,9"],
            "LOD exponents",
        ),
        (
            &["render", "--out", "x.png", "--lod-distance", "500,100"],
            "MIN must not exceed MAX",
        ),
        (
            &["render", "--out", "x.png", "--cells-per-patch", "48"],
            "power of two",
        ),
        (&["render", "--out", "x.png", "--eye", "1,2"], "X,Y,Z"),
        (
            &["render", "--out", "x.png", "--clear-color", "1,2,3"],
            "in [0, 1]",
        ),
    ];
    for (args, needle) in cases {
        let out = vkterrain(dir.path(), args);
        assert!(!out.status.success(), "{args:?}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.contains(needle),
            "{args:?}: expected {needle:?} in {stderr}"
        );
        assert!(!dir.path().join("x.png").exists());
    }
}

#[test]
fn without_tessellation_render_falls_back_to_geomip_and_says_so() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = vkterrain(
        dir.path(),
        &[
            "render",
            "--validate",
            "--without",
            "tessellation",
            "--width",
            "160",
            "--height",
            "90",
            "--out",
            "f.png",
            "--stats",
            "f.json",
        ],
    );
    let stdout = succeeded(&out);
    assert!(
        stdout.contains("tessellationShader is unavailable, falling back to the geomip path"),
        "{stdout}"
    );
    let s = json_file(&dir.path().join("f.json"));
    assert_eq!(s["path"], "geomip");
    assert_eq!(s["tcs_patches"], 0);
    assert_eq!(s["tes_invocations"], 0);
    assert!(s["triangles"].as_u64().unwrap() > 100);
    assert_eq!(s["validation_messages"], 0);
    // The geomip path's shared buffers: one vertex template, one index list.
    assert!(
        s["gpu_memory"]["terrain.geomip_vertex_template"]
            .as_u64()
            .unwrap()
            > 0
    );
    assert!(s["gpu_memory"]["terrain.geomip_indices"].as_u64().unwrap() > 0);
    assert!(s["gpu_memory"].get("terrain.control_points").is_none());
    let info: serde_json::Value = serde_json::from_str(&succeeded(&vkterrain(
        dir.path(),
        &["info", "--without", "tessellation"],
    )))
    .unwrap();
    assert_eq!(info["device"]["tessellation_shader"], false);
}

#[test]
fn each_missing_feature_still_renders_and_says_what_is_off() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // A scene that asks for anisotropic filtering.
    let scenes = tempfile::tempdir().unwrap();
    let anisotropic = temp_file(
        &scenes,
        "anisotropic.toml",
        format!(
            "[heightmap]\npath = \"{}\"\nheight_scale = 65535.0\ncell_spacing = [74.48, 92.15]\n\
             [material]\nanisotropy = 4.0\n[[material.layer]]\ndiffuse = \"{}/rock.png\"\n",
            data_path("jacksboro_fault_dem.png").display(),
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("assets/textures")
                .display()
        )
        .as_bytes(),
    );
    let anisotropic = anisotropic.to_str().unwrap();
    let cases: [(&str, &[&str], &str); 7] = [
        ("tessellation", &[], "falling back to the geomip path"),
        (
            "fill-mode-non-solid",
            &["--wireframe"],
            "drawing filled instead of wireframe",
        ),
        (
            "pipeline-statistics",
            &[],
            "triangle counts are not measured",
        ),
        (
            "sampler-anisotropy",
            &["--scene", anisotropic],
            "textures are filtered without anisotropy",
        ),
        ("timestamps", &[], "GPU time is not measured"),
        ("sampled-depth", &[], "drawing without occlusion culling"),
        (
            "multi-draw-indirect",
            &[],
            "each patch batch is its own draw call",
        ),
    ];
    for (feature, extra, note) in cases {
        let mut args = vec![
            "render",
            "--validate",
            "--width",
            "96",
            "--height",
            "64",
            "--out",
            "f.png",
            "--stats",
            "s.json",
            "--without",
            feature,
        ];
        args.extend_from_slice(extra);
        let stdout = succeeded(&vkterrain(dir.path(), &args));
        assert!(stdout.contains(note), "{feature}: {stdout}");
        assert!(
            stdout.contains("0 validation messages"),
            "{feature}: {stdout}"
        );
        let s = json_file(&dir.path().join("s.json"));
        let image = image::open(dir.path().join("f.png")).unwrap().to_rgba8();
        assert!(
            image.pixels().any(|p| p.0 != image.get_pixel(0, 0).0),
            "{feature}: the image shows something"
        );
        assert_eq!(s["validation_messages"], 0);
        assert_eq!(
            s["path"],
            if feature == "tessellation" {
                "geomip"
            } else {
                "tess"
            }
        );
        // Occlusion culling needs depth it can sample.
        assert_eq!(s["occlusion"], feature != "sampled-depth", "{feature}");
        // Unavailable figures are null, never zero.
        assert_eq!(
            s["triangles"].is_null(),
            feature == "pipeline-statistics",
            "{feature}"
        );
        assert_eq!(s["gpu_ms"].is_null(), feature == "timestamps", "{feature}");
        let info: serde_json::Value =
            serde_json::from_slice(&vkterrain(dir.path(), &["info", "--without", feature]).stdout)
                .unwrap();
        let missing = info["missing"].to_string();
        let name = match feature {
            "tessellation" => "tessellationShader",
            "fill-mode-non-solid" => "fillModeNonSolid",
            "pipeline-statistics" => "pipelineStatisticsQuery",
            "sampler-anisotropy" => "samplerAnisotropy",
            "sampled-depth" => "sampled depth attachments",
            "multi-draw-indirect" => "multiDrawIndirect",
            _ => "timestamps",
        };
        assert!(missing.contains(name), "{feature}: {missing}");
    }
    let err = vkterrain(
        dir.path(),
        &["render", "--out", "f.png", "--without", "warp-drive"],
    );
    assert!(!err.status.success());
    assert!(String::from_utf8_lossy(&err.stderr).contains("warp-drive"));
}

#[test]
fn a_gpu_memory_budget_refuses_the_resource_that_exceeds_it() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // The default scene's 1025x1025 float heightmap alone is 4 MiB; the
    // target, made first, fits.
    let out = vkterrain(
        dir.path(),
        &[
            "render",
            "--validate",
            "--gpu-memory-budget",
            "3",
            "--width",
            "64",
            "--height",
            "48",
            "--out",
            "f.png",
        ],
    );
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("GPU memory for terrain.heightmap"),
        "{stderr}"
    );
    assert!(stderr.contains("budget of 3145728 bytes"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert!(left.is_empty(), "no output file is left behind: {left:?}");
    // Within budget it renders.
    let out = vkterrain(
        dir.path(),
        &[
            "render",
            "--gpu-memory-budget",
            "64",
            "--width",
            "64",
            "--height",
            "48",
            "--out",
            "f.png",
        ],
    );
    succeeded(&out);
    for bad in ["0", "1.5", "x", "99999999999999999"] {
        let out = vkterrain(
            dir.path(),
            &["render", "--gpu-memory-budget", bad, "--out", "g.png"],
        );
        assert!(!out.status.success(), "{bad}");
        assert!(
            String::from_utf8_lossy(&out.stderr).contains("--gpu-memory-budget"),
            "{bad}"
        );
    }
}

#[test]
fn render_stats_list_the_material_resources_of_the_default_scene() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = vkterrain(
        dir.path(),
        &[
            "render",
            "--validate",
            "--width",
            "64",
            "--height",
            "36",
            "--out",
            "f.png",
            "--stats",
            "s.json",
        ],
    );
    succeeded(&out);
    let s = json_file(&dir.path().join("s.json"));
    let memory = s["gpu_memory"].as_object().unwrap();
    for (name, at_least) in [
        // 5 layers of 256x256 RGBA with mip chains.
        ("material.diffuse_maps", 5 * 256 * 256 * 4),
        ("material.normal_maps", 5 * 256 * 256 * 4),
        ("material.blend_maps", 513 * 513 * 4),
        ("lighting.lightmap", 1025 * 1025),
        ("material.uniforms", 400),
    ] {
        let bytes = memory[name].as_u64().unwrap_or(0);
        assert!(bytes >= at_least as u64, "{name}: {bytes} bytes");
    }
    assert!(!memory.contains_key("material.height_maps"), "{memory:?}");
    assert!(s["startup"]["material_ms"].as_f64().unwrap() > 0.0);
    assert_eq!(s["validation_messages"], 0);
}

#[test]
fn bad_scenes_fail_with_the_file_key_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let textures = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/textures");
    let base = "[heightmap]\npath = \"../assets/heightmaps/default.png\"\n";
    let cases: [(&str, String, &str); 4] = [
        (
            "missing.toml",
            String::new(),
            "missing.toml: cannot read the scene",
        ),
        (
            "unknown.toml",
            format!("{base}[material]\nlayer_count = 2\n"),
            "unknown field `layer_count`",
        ),
        (
            "texture.toml",
            format!("{base}[material]\n[[material.layer]]\ndiffuse = \"nowhere.png\"\n"),
            "texture.toml:5: material.layer[0].diffuse: cannot read",
        ),
        (
            "blend.toml",
            format!(
                "{base}[material]\nblend_maps = [\"{}\"]\n[[material.layer]]\ndiffuse = \"{}\"\n",
                textures.join("grass.png").display(),
                textures.join("grass.png").display()
            ),
            "blend.toml:4: material.blend_maps[0]",
        ),
    ];
    for (name, text, expected) in cases {
        let path = dir.path().join("scenes").join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        if !text.is_empty() {
            std::fs::write(&path, text).unwrap();
        }
        // The heightmap path is relative to the scene: scenes/../assets.
        std::os::unix::fs::symlink(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("assets"),
            dir.path().join("assets"),
        )
        .ok();
        let out = vkterrain(
            dir.path(),
            &[
                "render",
                "--scene",
                path.to_str().unwrap(),
                "--out",
                "x.png",
            ],
        );
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{name} must fail");
        assert!(stderr.contains(expected), "{name}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert!(!dir.path().join("x.png").exists());
    }
}

/// A bare heightmap gets the error LOD at 1 px, whatever its size: far
/// fewer triangles than brute on a smooth map. Distances on the command
/// line ask for the distance LOD.
#[test]
fn a_bare_heightmap_renders_with_the_error_lod() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // 257x257 16-bit samples of smooth hills.
    let mut bytes = Vec::new();
    for r in 0..257u32 {
        for c in 0..257u32 {
            let h = 30_000.0 + 2_000.0 * (c as f32 * 0.05).sin() * (r as f32 * 0.04).cos();
            bytes.extend_from_slice(&(h as u16).to_le_bytes());
        }
    }
    let map = temp_file(&dir, "hills.r16", &bytes);
    let map = map.to_str().unwrap();
    let render = |name: &str, extra: &[&str]| {
        let json = format!("{name}.json");
        let png = format!("{name}.png");
        let mut args = vec![
            "render",
            "--validate",
            "--heightmap",
            map,
            "--width",
            "160",
            "--height",
            "120",
            "--out",
            &png,
            "--stats",
            &json,
        ];
        args.extend_from_slice(extra);
        succeeded(&vkterrain(dir.path(), &args));
        json_file(&dir.path().join(json))
    };
    let bare = render("bare", &[]);
    assert_eq!(bare["lod"], serde_json::json!({ "error": 1.0 }));
    assert!(bare["predicted_max_px"].as_f64().unwrap() <= 1.0);
    let brute = render("brute", &["--path", "brute"]);
    let (t, b) = (
        bare["triangles"].as_u64().unwrap(),
        brute["triangles"].as_u64().unwrap(),
    );
    assert!(10 * t < b, "{t} triangles against brute's {b}");
    let distance = render("distance", &["--lod-distance", "10,200"]);
    assert_eq!(distance["lod"], "distance");
    assert!(distance["predicted_max_px"].is_null());
}
