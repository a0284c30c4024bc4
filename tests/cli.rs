//! The `height` and `inspect` commands, and their errors, through the binary.

mod common;

use std::process::{Command, Output};

use common::*;

fn vkterrain(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vkterrain"))
        .args(args)
        .output()
        .expect("the binary runs")
}

fn run_ok(args: &[String]) -> serde_json::Value {
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = vkterrain(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON on stdout")
}

fn run_err(args: &[&str]) -> String {
    let out = vkterrain(args);
    assert!(!out.status.success(), "expected failure: {args:?}");
    assert!(out.stdout.is_empty(), "nothing on stdout when failing");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn height_at_points_in_input_order() {
    let info = dem_info(32);
    let corner = info.sample_position(343, 402);
    let mut args = vec!["height".to_string()];
    args.extend(dem_args());
    for p in [
        format!("{},{}", corner.x, corner.y),
        "0,0".into(),
        "-1e7,5".into(),
    ] {
        args.push("--at".into());
        args.push(p);
    }
    let json = run_ok(&args);
    let rows = json.as_array().unwrap();
    assert_eq!(rows.len(), 3);
    assert_eq!(rows[0]["height"], 272.0);
    assert_eq!(
        rows[1]["height"].as_f64().unwrap() as f32,
        info.height_at(0.0, 0.0).unwrap()
    );
    assert_eq!(rows[2]["x"], -1e7);
    assert!(rows[2]["height"].is_null());
}

#[test]
fn height_from_a_points_file() {
    let dir = tempfile::tempdir().unwrap();
    let info = dem_info(32);
    let a = info.sample_position(0, 0);
    let text = format!("# x z\n{} {}\n\n100.5 -2000\n99999 0\n", a.x, a.y);
    let points = temp_file(&dir, "points.txt", text.as_bytes());
    let mut args = vec!["height".to_string()];
    args.extend(dem_args());
    args.extend(["--points".into(), points.display().to_string()]);
    let json = run_ok(&args);
    let rows = json.as_array().unwrap();
    assert_eq!(rows.len(), 3);
    assert_eq!(rows[0]["height"], 483.0);
    assert_eq!(
        rows[1]["height"].as_f64().unwrap() as f32,
        info.height_at(100.5, -2000.0).unwrap()
    );
    assert!(rows[2]["height"].is_null());
}

#[test]
fn inspect_reports_grid_and_patches() {
    let mut args = vec!["inspect".to_string()];
    args.extend(dem_args());
    args.extend(["--cells-per-patch".into(), "64".into(), "--patches".into()]);
    let json = run_ok(&args);
    assert_eq!(json["width"], 403);
    assert_eq!(json["depth"], 344);
    assert_eq!(json["min_height"], 236.0);
    assert_eq!(json["max_height"], 1076.0);
    assert_eq!(json["patch_rows"], 6);
    assert_eq!(json["patch_cols"], 7);
    assert_eq!(json["control_points"], 7 * 8);
    assert_eq!(json["indices"], 4 * 42);
    let patches = json["patches"].as_array().unwrap();
    assert_eq!(patches.len(), 42);
    let last = &patches[41];
    assert_eq!(
        (last["row"].as_u64(), last["col"].as_u64()),
        (Some(5), Some(6))
    );
    assert!((last["x_max"].as_f64().unwrap() - 402.0 * 74.48 / 2.0).abs() < 1e-6);
    let lo = patches
        .iter()
        .map(|p| p["min_y"].as_f64().unwrap())
        .fold(f64::INFINITY, f64::min);
    let hi = patches
        .iter()
        .map(|p| p["max_y"].as_f64().unwrap())
        .fold(0.0, f64::max);
    assert_eq!((lo, hi), (236.0, 1076.0));
}

#[test]
fn bad_input_exits_non_zero_naming_the_problem() {
    let dem = data_path("jacksboro_fault_dem.r16").display().to_string();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["height", "--heightmap", "/no/such/file.r16", "--at", "0,0"],
            "/no/such/file.r16: file not found",
        ),
        (
            vec!["height", "--heightmap", &dem, "--at", "0,0"],
            "cannot infer the size",
        ),
        (
            vec![
                "height",
                "--heightmap",
                &dem,
                "--size",
                "403x343",
                "--at",
                "0,0",
            ],
            "too long",
        ),
        (
            vec![
                "height",
                "--heightmap",
                &dem,
                "--size",
                "403by344",
                "--at",
                "0,0",
            ],
            "WxD",
        ),
        (
            vec![
                "height",
                "--heightmap",
                &dem,
                "--size",
                "403x344",
                "--at",
                "nan,0",
            ],
            "not finite",
        ),
        (
            vec![
                "height",
                "--heightmap",
                &dem,
                "--size",
                "403x344",
                "--at",
                "1",
            ],
            "X,Z",
        ),
        (
            vec![
                "height",
                "--heightmap",
                &dem,
                "--size",
                "403x344",
                "--cell-spacing",
                "0",
                "--at",
                "0,0",
            ],
            "must be positive",
        ),
        (
            vec![
                "height",
                "--heightmap",
                &dem,
                "--size",
                "403x344",
                "--cell-spacing",
                "1,-2",
                "--at",
                "0,0",
            ],
            "must be positive",
        ),
        (
            vec![
                "height",
                "--heightmap",
                &dem,
                "--format",
                "tiff",
                "--at",
                "0,0",
            ],
            "unknown heightmap format",
        ),
        (
            vec![
                "height",
                "--heightmap",
                &dem,
                "--size",
                "403x344",
                "--max-samples",
                "1000",
                "--at",
                "0,0",
            ],
            "over the limit of 1000",
        ),
        (
            vec![
                "inspect",
                "--heightmap",
                &dem,
                "--size",
                "403x344",
                "--cells-per-patch",
                "24",
            ],
            "power of two",
        ),
        (
            vec!["height", "--heightmap", &dem, "--size", "403x344"],
            "--at",
        ),
    ];
    for (args, needle) in cases {
        let stderr = run_err(&args);
        assert!(
            stderr.contains(needle),
            "{args:?}: expected {needle:?} in {stderr:?}"
        );
    }
}

#[test]
fn bad_points_file_names_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let points = temp_file(&dir, "bad.txt", b"1 2\n3 four\n");
    let dem = data_path("jacksboro_fault_dem.png").display().to_string();
    let p = points.display().to_string();
    let stderr = run_err(&["height", "--heightmap", &dem, "--points", &p]);
    assert!(stderr.contains("bad.txt:2"), "{stderr}");
}

#[test]
fn import_writes_a_tiled_terrain_that_height_and_inspect_open() {
    let dir = tempfile::tempdir().unwrap();
    let out_path = dir.path().join("dem.vkt");
    let out = out_path.display().to_string();
    let mut args: Vec<String> = vec!["import".into()];
    args.push(data_path("jacksboro_fault_dem.r16").display().to_string());
    args.extend(
        [
            "--size",
            "403x344",
            "--height-scale",
            "65535",
            "--tile",
            "64",
            "--out",
            &out,
        ]
        .map(String::from),
    );
    let report = run_ok(&args);
    assert_eq!(report["width"], 403);
    assert_eq!(report["depth"], 344);
    assert_eq!(report["read"], "streamed by rows");
    assert_eq!(report["tiles_x"], 7);
    assert_eq!(report["levels_as_floats"], 0);
    assert_eq!(report["max_error"], 0.0);
    assert_eq!(
        report["file_bytes"],
        std::fs::metadata(&out_path).unwrap().len()
    );
    assert!(report["seconds"].as_f64().unwrap() >= 0.0);

    // The same heights as the source, at full resolution, read tile by
    // tile; and the same grid through inspect (loaded whole).
    let info = dem_info(32);
    let corner = info.sample_position(343, 402);
    let points = [
        format!("{},{}", corner.x, corner.y),
        "0,0".into(),
        "1234.5,-987.25".into(),
        "-1e7,5".into(),
    ];
    let query = |heightmap: Vec<String>| {
        let mut args = vec!["height".to_string()];
        args.extend(heightmap);
        args.extend(["--cell-spacing".into(), "74.48,92.15".into()]);
        for p in &points {
            args.extend(["--at".into(), p.clone()]);
        }
        run_ok(&args)
    };
    let tiled = query(vec!["--heightmap".into(), out.clone()]);
    let mut source = dem_args();
    source.truncate(6);
    assert_eq!(tiled, query(source));
    assert_eq!(tiled[3]["height"], serde_json::Value::Null);
    assert_eq!(tiled[0]["height"], f64::from(info.whole().get(343, 402)));
    // inspect reads it a tile at a time and reports what it reports for
    // the source, every patch's Y bounds included.
    for cells in ["16", "32"] {
        let inspect = |heightmap: Vec<String>| {
            let mut args = vec!["inspect".to_string(), "--patches".into()];
            args.extend(heightmap);
            args.extend(["--cell-spacing".into(), "74.48,92.15".into()]);
            args.extend(["--cells-per-patch".into(), cells.into()]);
            run_ok(&args)
        };
        let tiled = inspect(vec!["--heightmap".into(), out.clone()]);
        let mut source = dem_args();
        source.truncate(6);
        assert_eq!(tiled, inspect(source));
        assert_eq!(tiled["min_height"], 236.0);
        assert!(tiled["patches"].as_array().unwrap().len() > 100);
    }

    // Heights were fixed at import: mapping options are refused, not
    // silently ignored.
    let err = run_err(&[
        "height",
        "--heightmap",
        &out,
        "--height-scale",
        "2",
        "--at",
        "0,0",
    ]);
    assert!(
        err.contains("dem.vkt") && err.contains("height scale"),
        "{err}"
    );
    // Bad import arguments: nothing is left behind.
    let bad = dir.path().join("bad.vkt").display().to_string();
    let r16 = data_path("jacksboro_fault_dem.r16").display().to_string();
    for (args, says) in [
        (
            vec![
                "import", &r16, "--size", "403x344", "--tile", "100", "--out", &bad,
            ],
            "power of two",
        ),
        (
            vec!["import", &r16, "--size", "400x344", "--out", &bad],
            "too long",
        ),
        (vec!["import", "no-such.png", "--out", &bad], "not found"),
        (vec!["import", &r16, &r16, "--out", &bad], "SRTM"),
    ] {
        let err = run_err(&args);
        assert!(err.contains(says), "{args:?}: {err}");
        assert!(!dir.path().join("bad.vkt").exists());
        assert!(!dir.path().join(".bad.vkt.partial").exists());
    }
}

#[test]
fn generate_writes_a_tiled_terrain_equal_to_its_png_imported() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name).display().to_string();
    let (png, direct, imported) = (path("g.png"), path("g.vkt"), path("i.vkt"));
    let generate = |out: &str, extra: &[&str]| {
        let mut args = vec![
            "generate",
            "--size",
            "129",
            "--droplets",
            "3000",
            "--out",
            out,
        ];
        args.extend(extra);
        let out = vkterrain(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).unwrap()
    };
    generate(&png, &[]);
    let said = generate(&direct, &["--height-scale", "250", "--tile", "32"]);
    assert!(said.contains("tiled: 32-cell tiles"), "{said}");
    run_ok(&[
        "import".into(),
        png.clone(),
        "--height-scale".into(),
        "250".into(),
        "--tile".into(),
        "32".into(),
        "--out".into(),
        imported.clone(),
    ]);
    assert_eq!(
        std::fs::read(&direct).unwrap(),
        std::fs::read(&imported).unwrap()
    );
    // A PNG holds 0 to 1: its scale is given when it is loaded.
    let err = run_err(&[
        "generate",
        "--size",
        "9",
        "--height-scale",
        "2",
        "--out",
        &png,
    ]);
    assert!(err.contains("--height-scale applies to a tiled"), "{err}");
    let err = run_err(&["generate", "--size", "16386", "--out", &png]);
    assert!(err.contains("write a tiled .vkt for larger"), "{err}");
}
