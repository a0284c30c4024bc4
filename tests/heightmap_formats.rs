//! Every heightmap format round-trips, and the real DEM loads exactly.

mod common;

use common::*;
use image::{ImageBuffer, Luma, Rgb};
use vkterrain::terrain::heightmap::HGT_VOID;
use vkterrain::terrain::{Heightmap, HeightmapError, HeightmapFormat, LoadOptions};

fn opts(format: HeightmapFormat, size: Option<(u64, u64)>, scale: f64, offset: f64) -> LoadOptions {
    LoadOptions {
        format: Some(format),
        size,
        height_scale: scale,
        height_offset: offset,
        ..LoadOptions::default()
    }
}

fn load(dir: &tempfile::TempDir, name: &str, bytes: &[u8], o: &LoadOptions) -> Heightmap {
    Heightmap::load(&temp_file(dir, name, bytes), o).expect("loads")
}

#[test]
fn raw8_maps_to_scale_times_unit_plus_offset() {
    let dir = tempfile::tempdir().unwrap();
    let values: Vec<u8> = vec![0, 1, 2, 127, 128, 200, 254, 255, 17, 34, 51, 68];
    let map = load(
        &dir,
        "a.r8",
        &values,
        &opts(HeightmapFormat::Raw8, Some((4, 3)), 510.0, -10.0),
    );
    assert_eq!((map.width(), map.depth()), (4, 3));
    for (i, v) in values.iter().enumerate() {
        assert_eq!(
            map.heights()[i],
            (510.0 * f64::from(*v) / 255.0 - 10.0) as f32,
            "sample {i}"
        );
    }
    assert_eq!(map.get(0, 0), -10.0);
    assert_eq!(map.get(1, 3), 500.0);
}

#[test]
fn raw16_little_and_big_endian_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let values: Vec<u16> = vec![0, 1, 65535, 32768, 1000, 4242];
    let le: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let be: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
    let a = load(
        &dir,
        "a.r16",
        &le,
        &opts(HeightmapFormat::Raw16, Some((3, 2)), 65535.0, 0.0),
    );
    let b = load(
        &dir,
        "b.raw",
        &be,
        &opts(HeightmapFormat::Raw16Be, Some((3, 2)), 65535.0, 0.0),
    );
    let expected: Vec<f32> = values.iter().map(|&v| f32::from(v)).collect();
    assert_eq!(a.heights(), &expected[..]);
    assert_eq!(b.heights(), &expected[..]);
    // Default mapping is scale 1, offset 0: v / 65535.
    let c = load(
        &dir,
        "c.r16",
        &le,
        &opts(HeightmapFormat::Raw16, Some((2, 3)), 1.0, 0.0),
    );
    assert_eq!(c.heights()[2], 1.0);
    assert_eq!(c.heights()[3], (32768.0f64 / 65535.0) as f32);
}

#[test]
fn square_raw_size_is_inferred() {
    let dir = tempfile::tempdir().unwrap();
    let bytes: Vec<u8> = (0..25u16).flat_map(|v| v.to_le_bytes()).collect();
    let map = load(
        &dir,
        "sq.r16",
        &bytes,
        &LoadOptions {
            height_scale: 65535.0,
            ..LoadOptions::default()
        },
    );
    assert_eq!((map.width(), map.depth()), (5, 5));
    assert_eq!(map.get(4, 4), 24.0);
}

#[test]
fn png_gray8_and_gray16_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let g8 = ImageBuffer::<Luma<u8>, _>::from_fn(7, 5, |x, y| Luma([(x * 30 + y) as u8]));
    let g16 = ImageBuffer::<Luma<u16>, _>::from_fn(7, 5, |x, y| Luma([(x * 9000 + y * 7) as u16]));
    let p8 = dir.path().join("g8.png");
    let p16 = dir.path().join("g16.png");
    g8.save(&p8).unwrap();
    g16.save(&p16).unwrap();
    let m8 = Heightmap::load(
        &p8,
        &LoadOptions {
            height_scale: 255.0,
            ..LoadOptions::default()
        },
    )
    .unwrap();
    let m16 = Heightmap::load(
        &p16,
        &LoadOptions {
            height_scale: 65535.0,
            height_offset: 3.0,
            ..LoadOptions::default()
        },
    )
    .unwrap();
    assert_eq!((m8.width(), m8.depth()), (7, 5));
    for y in 0..5 {
        for x in 0..7 {
            assert_eq!(m8.get(y, x), (x * 30 + y) as f32);
            assert_eq!(m16.get(y, x), (x * 9000 + y * 7) as f32 + 3.0);
        }
    }
}

#[test]
fn colour_png_loads_only_as_luminance() {
    let dir = tempfile::tempdir().unwrap();
    let rgb = ImageBuffer::<Rgb<u8>, _>::from_fn(4, 4, |x, _| Rgb([(x * 60) as u8; 3]));
    let path = dir.path().join("rgb.png");
    rgb.save(&path).unwrap();
    let err = Heightmap::load(&path, &LoadOptions::default()).unwrap_err();
    assert!(matches!(err, HeightmapError::ColorPng { .. }), "{err}");
    let map = Heightmap::load(
        &path,
        &LoadOptions {
            luminance: true,
            height_scale: 255.0,
            ..LoadOptions::default()
        },
    )
    .unwrap();
    // Gray pixels have luminance equal to their channels.
    assert_eq!(map.get(2, 3), 180.0);
}

fn hgt_bytes(values: &[i16]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_be_bytes()).collect()
}

#[test]
fn hgt_round_trips_and_fills_voids_from_valid_neighbours() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1201;
    let mut values: Vec<i16> = (0..n * n).map(|i| ((i % n) as i16 % 100) - 20).collect();
    // A lone void: its neighbours are cols 9..=11 of rows 4..=6, values -11, -10, -9.
    values[5 * n + 10] = HGT_VOID;
    // A 3x3 block of voids in a corner, filled ring by ring.
    for r in 0..3 {
        for c in 0..3 {
            values[r * n + c] = HGT_VOID;
        }
    }
    let map = load(
        &dir,
        "N00E000.hgt",
        &hgt_bytes(&values),
        &LoadOptions {
            height_scale: 32767.0,
            ..LoadOptions::default()
        },
    );
    assert_eq!((map.width(), map.depth()), (1201, 1201));
    assert_eq!(map.get(7, 42), 22.0);
    assert_eq!(map.get(100, 3), -17.0);
    // Mean of the eight valid neighbours (-11, -10, -9 twice each, -11 and -9 once).
    assert_eq!(map.get(5, 10), -10.0);
    // Corner block: the rim fills first from valid samples, so every filled
    // value lies within the valid range around it and none stays a void.
    for r in 0..3 {
        for c in 0..3 {
            let h = map.get(r, c);
            assert!((-20.0..=-15.0).contains(&h), "({r},{c}) = {h}");
        }
    }
    // (2, 2) sees five valid samples in the first pass: (3, 1..=3) = -19,
    // -18, -17 and (1..=2, 3) = -17, -17.
    assert!((map.get(2, 2) - (-17.6)).abs() < 1e-4, "{}", map.get(2, 2));
}

#[test]
fn hgt_all_void_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let values = vec![HGT_VOID; 1201 * 1201];
    let err = Heightmap::load(
        &temp_file(&dir, "void.hgt", &hgt_bytes(&values)),
        &LoadOptions::default(),
    )
    .unwrap_err();
    assert!(matches!(err, HeightmapError::AllVoid { .. }), "{err}");
}

#[test]
fn f32_maps_to_scale_times_value_plus_offset() {
    let dir = tempfile::tempdir().unwrap();
    let values = [-1.5f32, 0.0, 2.25, 1000.0, -0.125, 7.0];
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let map = load(
        &dir,
        "a.f32",
        &bytes,
        &opts(HeightmapFormat::F32, Some((2, 3)), 2.0, 1.0),
    );
    let expected: Vec<f32> = values.iter().map(|v| 2.0 * v + 1.0).collect();
    assert_eq!(map.heights(), &expected[..]);
}

#[test]
fn smoothing_averages_in_bounds_neighbours_of_the_unsmoothed_input() {
    #[rustfmt::skip]
    let heights = vec![
        0.0, 0.0, 0.0,
        0.0, 9.0, 0.0,
        0.0, 0.0, 18.0,
    ];
    let map = Heightmap::from_heights(3, 3, heights).unwrap().smoothed();
    // Corner (0,0) averages 4 samples: 9 / 4.
    assert_eq!(map.get(0, 0), 2.25);
    // Centre averages all 9: 27 / 9. Reading already-smoothed values would change it.
    assert_eq!(map.get(1, 1), 3.0);
    // Edge (1,2) averages 6 samples: 27 / 6.
    assert_eq!(map.get(1, 2), 4.5);
    // Corner (2,2): (9 + 18) / 4.
    assert_eq!(map.get(2, 2), 6.75);
}

#[test]
fn dem_raw_and_png_agree_with_known_samples_and_sidecar() {
    let png = dem("jacksboro_fault_dem.png", None);
    let raw = dem(
        "jacksboro_fault_dem.r16",
        Some((DEM_WIDTH as u64, DEM_DEPTH as u64)),
    );
    assert_eq!((png.width(), png.depth()), (DEM_WIDTH, DEM_DEPTH));
    assert_eq!(png, raw);
    // Values read straight from the file's bytes by an independent tool.
    for (r, c, v) in [
        (0, 0, 483.0),
        (0, 402, 444.0),
        (343, 0, 545.0),
        (343, 402, 272.0),
        (171, 201, 553.0),
        (100, 300, 537.0),
        (343, 200, 850.0),
        (50, 402, 357.0),
        (288, 347, 236.0),
        (297, 219, 1076.0),
    ] {
        assert_eq!(png.get(r, c), v, "sample ({r}, {c})");
    }
    let sidecar: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(data_path("jacksboro_fault_dem.json")).unwrap(),
    )
    .unwrap();
    let (lo, hi) = png.min_max();
    assert_eq!(f64::from(lo), sidecar["elevation_min_m"].as_f64().unwrap());
    assert_eq!(f64::from(hi), sidecar["elevation_max_m"].as_f64().unwrap());
    assert_eq!(sidecar["width"].as_u64().unwrap() as usize, png.width());
    assert_eq!(sidecar["height"].as_u64().unwrap() as usize, png.depth());
}

#[test]
fn format_names_parse_and_extensions_infer() {
    for f in HeightmapFormat::ALL {
        assert_eq!(f.name().parse::<HeightmapFormat>().unwrap(), f);
    }
    assert_eq!(
        "RAW16BE".parse::<HeightmapFormat>().unwrap(),
        HeightmapFormat::Raw16Be
    );
    let infer = |p: &str| HeightmapFormat::from_path(std::path::Path::new(p)).unwrap();
    assert_eq!(infer("a.r8"), HeightmapFormat::Raw8);
    assert_eq!(infer("a.RAW"), HeightmapFormat::Raw16);
    assert_eq!(infer("a.png"), HeightmapFormat::Png);
    assert_eq!(infer("N35W084.hgt"), HeightmapFormat::Hgt);
    assert_eq!(infer("a.f32"), HeightmapFormat::F32);
}
