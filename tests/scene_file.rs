//! Scene files: the default scene, relative paths, and errors that name the
//! file, the key and the line.

mod common;

use std::path::Path;

use common::*;
use glam::{DVec2, DVec3};
use vkterrain::scene::{AssetSource, HeightmapSource, Scene, SceneError, SceneFileError};

#[test]
fn the_default_scene_file_is_the_built_in_scene() {
    let built_in = Scene::default_scene();
    assert!(matches!(
        built_in.heightmap,
        HeightmapSource::Embedded { .. }
    ));
    assert_eq!(built_in.cell_spacing, DVec2::splat(8.0));
    assert_eq!(built_in.cells_per_patch, 32);
    assert_eq!(built_in.load.height_scale, 1400.0);
    assert_eq!(
        built_in.lod.map(|l| (l.min_dist, l.max_dist)),
        Some((150.0, 6000.0))
    );
    let camera = built_in.camera.expect("the default scene has a camera");
    assert_eq!(camera.eye, DVec3::new(-2300.0, 1750.0, -4300.0));

    // The file on disk describes the same scene, with its heightmap on disk.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/default.toml");
    let from_file = Scene::load(&path).unwrap();
    let HeightmapSource::File(heightmap) = &from_file.heightmap else {
        panic!("a file scene reads a file")
    };
    assert!(heightmap.ends_with("assets/scenes/../heightmaps/default.png"));
    assert_eq!(
        Scene {
            heightmap: built_in.heightmap.clone(),
            material: built_in.material.clone(),
            ..from_file.clone()
        },
        built_in
    );
    // Its textures and blend map are the files the scene names, built in.
    let mut on_disk = from_file.material.clone().unwrap();
    let mut embedded = built_in.material.clone().unwrap();
    let pairs: Vec<_> = on_disk.assets_mut().zip(embedded.assets_mut()).collect();
    assert_eq!(pairs.len(), 11);
    for (file, built) in pairs {
        let (AssetSource::File(path), AssetSource::Embedded { bytes, .. }) =
            (&file.source, &built.source)
        else {
            panic!("{} is a file on disk and built in", file.origin())
        };
        assert_eq!(&std::fs::read(path).unwrap(), bytes, "{}", path.display());
        assert_eq!((&file.key, file.line), (&built.key, built.line));
    }
    assert_eq!(
        from_file.terrain_info().unwrap(),
        built_in.terrain_info().unwrap()
    );
}

fn write_scene(dir: &tempfile::TempDir, text: &str) -> std::path::PathBuf {
    temp_file(dir, "scene.toml", text.as_bytes())
}

/// A temporary directory holding the DEM as dem.r16.
fn dir_with_dem() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(
        data_path("jacksboro_fault_dem.r16"),
        dir.path().join("dem.r16"),
    )
    .unwrap();
    dir
}

#[test]
fn heightmap_paths_are_relative_to_the_scene() {
    let dir = dir_with_dem();
    let path = write_scene(
        &dir,
        "[heightmap]\npath = \"dem.r16\"\nsize = [403, 344]\nheight_scale = 65535.0\ncell_spacing = [74.48, 92.15]\norigin = [1000.0, -50.0]\n\n[terrain]\ncells_per_patch = 16\n",
    );
    let scene = Scene::load(&path).unwrap();
    let info = scene.terrain_info().unwrap();
    assert_eq!((info.cols(), info.rows()), (403, 344));
    assert_eq!(info.whole().get(343, 402), 272.0);
    assert_eq!(info.origin(), DVec2::new(1000.0, -50.0));
    assert_eq!(info.cells_per_patch(), 16);
    // No camera given: an overview from beyond the -x, -z corner, above the top.
    assert!(scene.camera.is_none());
    let overview = scene.camera_for(&info);
    assert!(
        overview.eye.x < 1000.0 - info.world_width() / 4.0
            && overview.eye.z < -50.0 - info.world_depth() / 2.0
    );
    assert!(overview.eye.y > 1076.0);
}

#[test]
fn a_scene_without_lod_draws_the_error_lod_at_one_pixel() {
    let dir = dir_with_dem();
    let head = "[heightmap]\npath = \"dem.r16\"\nsize = [403, 344]\ncell_spacing = 10.0\n";
    let load = |extra: &str| Scene::load(&write_scene(&dir, &format!("{head}{extra}"))).unwrap();
    let bare = load("");
    assert_eq!((bare.pixel_error, bare.lod), (Some(1.0), None));
    // Its distances, when the distance LOD is asked for, fit the terrain:
    // 4020 m wide, not the default scene's 8 km.
    let lod = bare.distance_lod(&bare.terrain_info().unwrap());
    assert!(
        (lod.min_dist - 80.4).abs() < 0.01 && (lod.max_dist - 3015.0).abs() < 0.1,
        "{lod:?}"
    );
    let distance = load("[lod]\nmin_distance = 10.0\nmax_distance = 900.0\n");
    assert_eq!(distance.pixel_error, None);
    assert_eq!(distance.lod.unwrap().max_dist, 900.0);
    let both = load("[lod]\npixel_error = 2.5\nmin_distance = 10.0\n");
    assert_eq!(both.pixel_error, Some(2.5));
    assert_eq!(both.lod.unwrap().min_dist, 10.0);
    // The default scene keeps its distance LOD.
    assert_eq!(Scene::default_scene().pixel_error, None);
}

fn invalid(text: &str) -> SceneFileError {
    let dir = tempfile::tempdir().unwrap();
    let err = Scene::load(&write_scene(&dir, text)).expect_err("must be refused");
    assert!(
        err.to_string().contains("scene.toml"),
        "names the file: {err}"
    );
    err
}

fn assert_invalid(text: &str, key: &str, line: usize) {
    match invalid(text) {
        SceneFileError::Invalid {
            key: k, line: l, ..
        } => assert_eq!((k.as_str(), l), (key, line), "{text}"),
        other => panic!("expected an invalid {key} at line {line}, got {other}"),
    }
}

#[test]
fn errors_name_the_key_and_line() {
    let head = "[heightmap]\npath = \"x.png\"\n";
    assert_invalid(
        &format!("{head}\n[terrain]\ncells_per_patch = 24\n"),
        "terrain.cells_per_patch",
        5,
    );
    assert_invalid(
        &format!("{head}cell_spacing = -2.0\n"),
        "heightmap.cell_spacing",
        3,
    );
    assert_invalid(
        &format!("{head}cell_spacing = [1.0, 0.0]\n"),
        "heightmap.cell_spacing",
        3,
    );
    assert_invalid(&format!("{head}format = \"tiff\"\n"), "heightmap.format", 3);
    assert_invalid(
        &format!("{head}height_scale = nan\n"),
        "heightmap.height_scale",
        3,
    );
    assert_invalid(
        &format!("{head}[lod]\nmin_distance = 500.0\nmax_distance = 100.0\n"),
        "lod",
        4,
    );
    assert_invalid(&format!("{head}[lod]\nmax_level = 7.0\n"), "lod", 4);
    assert_invalid(
        &format!("{head}[lod]\npixel_error = 0.0\n"),
        "lod.pixel_error",
        4,
    );
    assert_invalid(
        &format!("{head}[camera]\neye = [0.0, 1.0, 0.0]\ntarget = [0.0, 1.0, 0.0]\n"),
        "camera.target",
        5,
    );
    assert_invalid(
        &format!("{head}[camera]\neye = [0.0, 1.0, 0.0]\ntarget = [1.0, 0.0, 0.0]\nfov = 190.0\n"),
        "camera.fov",
        6,
    );
}

#[test]
fn unknown_keys_and_bad_syntax_name_the_line() {
    for (text, needles) in [
        (
            "[heightmap]\npath = \"x.png\"\nscael = 2.0\n",
            &["line 3", "scael"][..],
        ),
        (
            "[heightmap]\npath = \"x.png\"\n[lights]\n",
            &["line 3", "lights"][..],
        ),
        ("[heightmap]\npath = 5\n", &["line 2", "string"][..]),
        ("[heightmap\npath = \"x.png\"\n", &["line 1"][..]),
        ("[terrain]\ncells_per_patch = 32\n", &["heightmap"][..]),
    ] {
        let err = invalid(text);
        assert!(matches!(err, SceneFileError::Parse { .. }), "{err}");
        for needle in needles {
            assert!(
                err.to_string().contains(needle),
                "{text:?}: expected {needle:?} in {err}"
            );
        }
    }
}

#[test]
fn missing_files_are_named() {
    let err = Scene::load(Path::new("/no/such/scene.toml")).unwrap_err();
    assert!(
        matches!(err, SceneFileError::Io { .. }) && err.to_string().contains("/no/such/scene.toml"),
        "{err}"
    );
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::load(&write_scene(&dir, "[heightmap]\npath = \"missing.png\"\n")).unwrap();
    let err = scene.terrain_info().unwrap_err();
    assert!(matches!(err, SceneError::Heightmap(_)), "{err}");
    assert!(
        err.to_string().contains("missing.png: file not found"),
        "{err}"
    );
}

#[test]
fn cli_takes_a_scene_on_every_command() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/default.toml");
    let scene = scene.to_str().unwrap();
    let run = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_vkterrain"))
            .args(args)
            .output()
            .unwrap()
    };
    let out = run(&["inspect", "--scene", scene]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (json["width"].as_u64(), json["patch_rows"].as_u64()),
        (Some(1025), Some(32))
    );
    let out = run(&["height", "--scene", scene, "--at", "0,0"]);
    assert!(out.status.success());
    let dir = tempfile::tempdir().unwrap();
    let bad = write_scene(
        &dir,
        "[heightmap]\npath = \"x.png\"\n[terrain]\ncells_per_patch = 3\n",
    );
    let out = run(&[
        "render",
        "--scene",
        bad.to_str().unwrap(),
        "--out",
        "/tmp/never.png",
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("scene.toml:4: terrain.cells_per_patch"),
        "{stderr}"
    );
    let out = run(&["inspect", "--scene", scene, "--heightmap", "x.png"]);
    assert!(
        !out.status.success(),
        "--scene and --heightmap exclude each other"
    );
}
