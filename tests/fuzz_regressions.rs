//! The fuzz targets' checks (fuzz/) on their committed seed corpus and on
//! every input that once failed them, so each finding stays fixed.

use std::path::Path;

use vkterrain::cli::fuzz_parse;
use vkterrain::terrain::heightmap::fuzz_load;
use vkterrain::terrain::tiled::{fuzz_open, fuzz_open_resealed};
use vkterrain::terrain::HeightmapFormat;

fn corpus(target: &str) -> Vec<Vec<u8>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/corpus")
        .join(target);
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    assert!(!files.is_empty(), "{target}: a seed corpus is committed");
    files.iter().map(|f| std::fs::read(f).unwrap()).collect()
}

#[test]
fn heightmap_seeds_load() {
    for (target, format) in [
        ("heightmap_raw8", HeightmapFormat::Raw8),
        ("heightmap_raw16", HeightmapFormat::Raw16),
        ("heightmap_png", HeightmapFormat::Png),
        ("heightmap_f32", HeightmapFormat::F32),
    ] {
        for (i, seed) in corpus(target).iter().enumerate() {
            assert!(fuzz_load(seed, format), "{target} seed {i} loads");
        }
    }
    // The .hgt seed is a truncated tile: refused, not loaded.
    for seed in corpus("heightmap_hgt") {
        assert!(!fuzz_load(&seed, HeightmapFormat::Hgt));
    }
}

#[test]
fn hostile_heightmap_bytes_are_refused_cleanly() {
    let nan = f32::NAN.to_le_bytes();
    let inputs: Vec<Vec<u8>> = vec![
        vec![],
        vec![0],
        vec![0, 0, 0],
        // A declared 128x256 size with 4 bytes of data.
        vec![254, 255, 0, 1, 2, 3, 4],
        // NaN and infinite floats, and a scale that overflows f32.
        [vec![2, 1, 3], nan.repeat(4)].concat(),
        [vec![2, 1, 3], 1e30f32.to_le_bytes().repeat(4)].concat(),
        // A PNG signature with a truncated header.
        [vec![1, 0, 0], b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR".to_vec()].concat(),
    ];
    let truncated_png = inputs.len() - 1;
    for (i, input) in inputs.iter().enumerate() {
        for format in HeightmapFormat::ALL {
            // The truncated PNG's 16 bytes are a well-formed 4x4 8-bit map
            // and a 2x2 float map; as anything else they are refused.
            let well_formed = i == truncated_png
                && matches!(format, HeightmapFormat::Raw8 | HeightmapFormat::F32);
            assert_eq!(
                fuzz_load(input, format),
                well_formed,
                "{input:?} as {format:?}"
            );
        }
    }
}

#[test]
fn scene_seeds_parse_and_hostile_text_is_refused() {
    for seed in corpus("scene_file") {
        let text = String::from_utf8(seed).unwrap();
        vkterrain::scene::Scene::from_toml(&text, Path::new("seed.toml")).unwrap();
    }
    for text in [
        "",
        "[heightmap]",
        "[heightmap]\npath = 5",
        "[heightmap]\npath = \"a\"\ncell_spacing = [1e400, 1]",
        "[heightmap]\npath = \"a\"\n[camera]\neye = [0, 0, 0]\ntarget = [0, 0, 0]",
        "[heightmap]\npath = \"a\"\n[lod]\nmin_distance = -1.0",
        "[heightmap]\npath = \"a\"\n[terrain]\ncells_per_patch = 4294967295",
    ] {
        assert!(
            vkterrain::scene::Scene::from_toml(text, Path::new("bad.toml")).is_err(),
            "{text:?}"
        );
    }
}

#[test]
fn numeric_arguments_never_yield_non_finite_values() {
    for seed in corpus("cli_numbers") {
        fuzz_parse(&String::from_utf8(seed).unwrap());
    }
    // Found by the fuzz checks: values finite as f64 but not as f32 (an
    // infinite LOD range; a field of view that narrows to 0).
    for text in [
        "1e39,1e40",
        "-1e39,0",
        "1e-50",
        "1e-46",
        "179.99999999999",
        "0x10",
        "nan,1",
        "inf",
    ] {
        fuzz_parse(text);
    }
    assert!(vkterrain::cli::args::parse_range("1e39,1e40").is_err());
    assert!(vkterrain::cli::args::parse_fov("1e-50").is_err());
}

#[test]
fn tiled_terrain_seeds_open_and_hostile_bytes_are_refused() {
    let seeds = corpus("tiled_terrain");
    for (i, seed) in seeds.iter().enumerate() {
        assert!(fuzz_open(seed), "tiled_terrain seed {i} opens and reads");
        assert!(
            fuzz_open_resealed(seed),
            "resealing a valid file keeps it valid"
        );
    }
    // Every truncation and every byte replaced by 0, 0xff or flipped:
    // refused or read, never a panic. Replacing a header byte always
    // breaks its checksum, so those are refused.
    for seed in &seeds {
        for i in 0..seed.len() {
            assert!(!fuzz_open(&seed[..i]), "truncated at {i} is refused");
            for v in [0u8, 0xff, seed[i] ^ 0x80] {
                if v == seed[i] {
                    continue;
                }
                let mut b = seed.clone();
                b[i] = v;
                let opened = fuzz_open(&b);
                if i < 64 {
                    assert!(!opened, "header byte {i} set to {v} is refused");
                }
                // Past the checksums, the other checks still hold.
                fuzz_open_resealed(&b);
            }
        }
    }
}
