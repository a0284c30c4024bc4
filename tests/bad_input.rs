//! Every malformed input gives a typed error naming the file and the problem.

mod common;

use common::*;
use glam::DVec2;
use vkterrain::terrain::{
    Heightmap, HeightmapError, HeightmapFormat, LoadOptions, TerrainError, TerrainInfo,
};

fn raw16(size: Option<(u64, u64)>) -> LoadOptions {
    LoadOptions {
        format: Some(HeightmapFormat::Raw16),
        size,
        ..LoadOptions::default()
    }
}

fn load_bytes(name: &str, bytes: &[u8], opts: &LoadOptions) -> HeightmapError {
    let dir = tempfile::tempdir().unwrap();
    let path = temp_file(&dir, name, bytes);
    let err = Heightmap::load(&path, opts).expect_err("input must be rejected");
    assert!(
        err.to_string().contains(name),
        "message names the file: {err}"
    );
    err
}

#[test]
fn file_shorter_than_its_size() {
    let err = load_bytes("short.r16", &[0u8; 2 * 11], &raw16(Some((4, 3))));
    assert!(
        matches!(
            err,
            HeightmapError::LengthMismatch {
                expected: 24,
                actual: 22,
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("too short"), "{err}");
}

#[test]
fn file_longer_than_its_size() {
    let err = load_bytes("long.r16", &[0u8; 2 * 13], &raw16(Some((4, 3))));
    assert!(
        matches!(
            err,
            HeightmapError::LengthMismatch {
                expected: 24,
                actual: 26,
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("too long"), "{err}");
}

#[test]
fn non_square_file_without_a_size() {
    let err = load_bytes("odd.r16", &[0u8; 2 * 12], &raw16(None));
    assert!(
        matches!(err, HeightmapError::CannotInferSize { .. }),
        "{err}"
    );
    let err = load_bytes("odd.r16", &[0u8; 9], &raw16(None));
    assert!(
        matches!(err, HeightmapError::CannotInferSize { .. }),
        "{err}"
    );
}

#[test]
fn empty_file() {
    for format in HeightmapFormat::ALL {
        let opts = LoadOptions {
            format: Some(format),
            ..LoadOptions::default()
        };
        let err = load_bytes("empty.bin", &[], &opts);
        assert!(
            matches!(err, HeightmapError::Empty { .. }),
            "{format}: {err}"
        );
    }
}

#[test]
fn width_or_depth_below_two() {
    let err = load_bytes("thin.r16", &[0u8; 2 * 5], &raw16(Some((1, 5))));
    assert!(
        matches!(
            err,
            HeightmapError::TooSmall {
                width: 1,
                depth: 5,
                ..
            }
        ),
        "{err}"
    );
    let err = load_bytes("one.r16", &[0u8; 2], &raw16(None));
    assert!(
        matches!(
            err,
            HeightmapError::TooSmall {
                width: 1,
                depth: 1,
                ..
            }
        ),
        "{err}"
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("row.png");
    image::GrayImage::new(5, 1).save(&path).unwrap();
    let err = Heightmap::load(&path, &LoadOptions::default()).unwrap_err();
    assert!(
        matches!(
            err,
            HeightmapError::TooSmall {
                width: 5,
                depth: 1,
                ..
            }
        ),
        "{err}"
    );
    assert!(matches!(
        Heightmap::from_heights(1, 1, vec![0.0]),
        Err(HeightmapError::TooSmall { .. })
    ));
}

#[test]
fn sample_count_overflow() {
    let err = load_bytes("huge.r16", &[0u8; 8], &raw16(Some((u64::MAX, 3))));
    assert!(matches!(err, HeightmapError::SizeOverflow { .. }), "{err}");
    let err = load_bytes("huge.r16", &[0u8; 8], &raw16(Some((1 << 32, 1 << 32))));
    assert!(matches!(err, HeightmapError::SizeOverflow { .. }), "{err}");
}

#[test]
fn sample_limit_is_checked_before_reading() {
    // The size claims 10^10 samples; the limit refuses it before the
    // length is even compared (and before anything is allocated).
    let err = load_bytes("big.r16", &[0u8; 8], &raw16(Some((100_000, 100_000))));
    assert!(
        matches!(
            err,
            HeightmapError::TooManySamples {
                samples: 10_000_000_000,
                ..
            }
        ),
        "{err}"
    );
    let opts = LoadOptions {
        max_samples: 15,
        ..raw16(Some((4, 4)))
    };
    let err = load_bytes("limit.r16", &[0u8; 32], &opts);
    assert!(
        matches!(
            err,
            HeightmapError::TooManySamples {
                samples: 16,
                limit: 15,
                ..
            }
        ),
        "{err}"
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("limit.png");
    image::GrayImage::new(8, 8).save(&path).unwrap();
    let err = Heightmap::load(
        &path,
        &LoadOptions {
            max_samples: 63,
            ..LoadOptions::default()
        },
    )
    .unwrap_err();
    assert!(
        matches!(err, HeightmapError::TooManySamples { samples: 64, .. }),
        "{err}"
    );
}

#[test]
fn nan_or_infinity_in_float_input() {
    for (bad, at) in [
        (f32::NAN, 5usize),
        (f32::INFINITY, 0),
        (f32::NEG_INFINITY, 8),
    ] {
        let mut values = [1.0f32; 9];
        values[at] = bad;
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let opts = LoadOptions {
            format: Some(HeightmapFormat::F32),
            ..LoadOptions::default()
        };
        let err = load_bytes("nan.f32", &bytes, &opts);
        let (row, col) = ((at / 3) as u64, (at % 3) as u64);
        assert!(
            matches!(err, HeightmapError::NonFinite { row: r, col: c, .. } if (r, c) == (row, col)),
            "{err}"
        );
    }
    // Finite input that a scale overflows to infinity is caught too.
    let bytes: Vec<u8> = [1.0f32; 4].iter().flat_map(|v| v.to_le_bytes()).collect();
    let opts = LoadOptions {
        format: Some(HeightmapFormat::F32),
        height_scale: 1e300,
        ..LoadOptions::default()
    };
    assert!(matches!(
        load_bytes("big.f32", &bytes, &opts),
        HeightmapError::NonFinite { .. }
    ));
    assert!(matches!(
        Heightmap::from_heights(2, 2, vec![0.0, f32::NAN, 0.0, 0.0]),
        Err(HeightmapError::NonFinite { .. })
    ));
}

#[test]
fn png_that_is_not_a_png() {
    let err = load_bytes(
        "fake.png",
        b"GIF89a this is not a png at all",
        &LoadOptions::default(),
    );
    assert!(matches!(err, HeightmapError::NotPng { .. }), "{err}");
    // A real PNG signature with a truncated body.
    let mut bytes = Vec::new();
    image::GrayImage::new(16, 16)
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .unwrap();
    bytes.truncate(bytes.len() / 2);
    let err = load_bytes("truncated.png", &bytes, &LoadOptions::default());
    assert!(matches!(err, HeightmapError::NotPng { .. }), "{err}");
}

fn png_with(color: png::ColorType, depth: png::BitDepth, data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, 8, 2);
        encoder.set_color(color);
        encoder.set_depth(depth);
        if color == png::ColorType::Indexed {
            encoder.set_palette(vec![0u8; 3 * 16]);
        }
        encoder
            .write_header()
            .unwrap()
            .write_image_data(data)
            .unwrap();
    }
    out
}

#[test]
fn png_with_unsupported_bit_depth_or_colour_type() {
    let one_bit = png_with(png::ColorType::Grayscale, png::BitDepth::One, &[0xAA, 0x55]);
    let err = load_bytes("onebit.png", &one_bit, &LoadOptions::default());
    assert!(
        matches!(err, HeightmapError::UnsupportedPng { .. }),
        "{err}"
    );
    let four_bit = png_with(png::ColorType::Grayscale, png::BitDepth::Four, &[0x12; 8]);
    let err = load_bytes(
        "fourbit.png",
        &four_bit,
        &LoadOptions {
            luminance: true,
            ..LoadOptions::default()
        },
    );
    assert!(
        matches!(err, HeightmapError::UnsupportedPng { .. }),
        "{err}"
    );
    let indexed = png_with(png::ColorType::Indexed, png::BitDepth::Four, &[0x12; 8]);
    let err = load_bytes("indexed.png", &indexed, &LoadOptions::default());
    assert!(
        matches!(err, HeightmapError::UnsupportedPng { .. }),
        "{err}"
    );
}

#[test]
fn cells_per_patch_not_a_power_of_two() {
    let map = noise_map(9, 9, 1);
    for n in [0, 1, 3, 24, 48, 128, u32::MAX] {
        let err = TerrainInfo::new(map.clone(), DVec2::ONE, n, DVec2::ZERO).unwrap_err();
        assert_eq!(err, TerrainError::CellsPerPatch(n));
    }
}

#[test]
fn zero_or_negative_cell_spacing() {
    let map = noise_map(9, 9, 1);
    for spacing in [
        DVec2::new(0.0, 1.0),
        DVec2::new(1.0, -2.0),
        DVec2::new(f64::NAN, 1.0),
        DVec2::new(1.0, f64::INFINITY),
    ] {
        let err = TerrainInfo::new(map.clone(), spacing, 8, DVec2::ZERO).unwrap_err();
        assert!(
            matches!(err, TerrainError::CellSpacing { .. }),
            "{spacing}: {err}"
        );
    }
}

#[test]
fn unknown_format() {
    let err = load_bytes("terrain.tiff", &[0u8; 8], &LoadOptions::default());
    assert!(
        matches!(err, HeightmapError::UnknownFormat { ref name, .. } if name == ".tiff"),
        "{err}"
    );
    let err = load_bytes("noext", &[0u8; 8], &LoadOptions::default());
    assert!(matches!(err, HeightmapError::UnknownFormat { .. }), "{err}");
    assert!("raw24".parse::<HeightmapFormat>().is_err());
}

#[test]
fn missing_file() {
    let err = Heightmap::load(
        std::path::Path::new("/nonexistent/dem.r16"),
        &LoadOptions::default(),
    )
    .unwrap_err();
    assert!(matches!(err, HeightmapError::Missing { .. }), "{err}");
    assert!(err.to_string().contains("/nonexistent/dem.r16"));
    // A missing file is missing whatever its name says it holds.
    for name in ["/nonexistent/big.vkt", "/nonexistent/map.tiff"] {
        let err = Heightmap::load(std::path::Path::new(name), &LoadOptions::default()).unwrap_err();
        assert!(matches!(err, HeightmapError::Missing { .. }), "{err}");
    }
}

#[test]
fn vkt_without_a_tiled_header() {
    let err = load_bytes("half.vkt", &[7u8; 64], &LoadOptions::default());
    assert!(matches!(err, HeightmapError::NotTiled { .. }), "{err}");
    assert!(err.to_string().contains("not a tiled terrain"), "{err}");
}

#[test]
fn hgt_of_the_wrong_size() {
    let err = load_bytes(
        "N00E000.hgt",
        &[0u8; 2 * 1200 * 1200],
        &LoadOptions::default(),
    );
    assert!(matches!(err, HeightmapError::HgtSize { .. }), "{err}");
}
