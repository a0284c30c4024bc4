//! Tiled terrains: import from every row source, exact read-back at full
//! resolution and at every level, the SRTM mosaic, a bounded tile cache,
//! and a clear error naming the tile for every kind of corruption.

mod common;

use std::path::{Path, PathBuf};

use glam::DVec2;
use vkterrain::scene::{HeightmapSource, Scene};
use vkterrain::terrain::grid::patch_y_bounds;
use vkterrain::terrain::heightmap::{Heightmap, HeightmapFormat, LoadOptions};
use vkterrain::terrain::tiled::{
    self, fuzz_open, level_sample, Encoding, Header, TiledHeightmap, ENTRY_BYTES, HEADER_BYTES,
};
use vkterrain::terrain::{ErrorTable, PatchGrid, Placement, TerrainInfo};

/// Imports `inputs` with `opts` into `out` and returns the report.
fn import(inputs: &[&Path], opts: &LoadOptions, tile: u32, out: &Path) -> tiled::ImportReport {
    import_with_tables(inputs, opts, tile, 16, out)
}

/// `import`, storing the error tables of `cells`-cell patches.
fn import_with_tables(
    inputs: &[&Path],
    opts: &LoadOptions,
    tile: u32,
    cells: u32,
    out: &Path,
) -> tiled::ImportReport {
    let inputs: Vec<PathBuf> = inputs.iter().map(|p| p.to_path_buf()).collect();
    let (mut source, _) = tiled::open_source(&inputs, opts).unwrap();
    let mut rows_seen = 0;
    let report = tiled::import(
        source.as_mut(),
        tile,
        Some(cells),
        out,
        &mut |done, total| {
            assert!(done > rows_seen && done <= total);
            rows_seen = done;
        },
    )
    .unwrap();
    assert_eq!(
        rows_seen, report.depth as u64,
        "progress reaches the last row"
    );
    report
}

/// A rough 16-bit map with a remainder on both axes, 203x150 samples,
/// written to `dir/rough.r16`: its path, load options mapping it with
/// `height_scale` and `height_offset`, and its size.
fn rough_r16(
    dir: &Path,
    height_scale: f64,
    height_offset: f64,
) -> (PathBuf, LoadOptions, (usize, usize)) {
    let (w, d) = (203usize, 150usize);
    let bytes: Vec<u8> = (0..w * d)
        .flat_map(|i| {
            let (r, c) = (i / w, i % w);
            let v = (r * 397 + c * 1009 + (r * c) % 7919) % 65536;
            (v as u16).to_le_bytes()
        })
        .collect();
    let path = dir.join("rough.r16");
    std::fs::write(&path, bytes).unwrap();
    let opts = LoadOptions {
        size: Some((w as u64, d as u64)),
        height_scale,
        height_offset,
        ..LoadOptions::default()
    };
    (path, opts, (w, d))
}

/// Every sample of every level of `tiled` against the loaded source.
fn assert_exact(tiled: &TiledHeightmap, source: &Heightmap) {
    assert_eq!(
        (tiled.width(), tiled.depth()),
        (source.width(), source.depth())
    );
    let header = *tiled.header();
    let (tiles_x, tiles_z) = header.tiles();
    for tz in 0..tiles_z {
        for tx in 0..tiles_x {
            let [c0, c1, r0, r1] = header.tile_rect(tx, tz);
            for level in 0..header.levels {
                let tile = tiled.tile(tx, tz, level).unwrap();
                for i in 0..tile.rows {
                    for j in 0..tile.cols {
                        let r = r0 + level_sample(i, r1 - r0, level);
                        let c = c0 + level_sample(j, c1 - c0, level);
                        assert_eq!(
                            tile.get(i, j).to_bits(),
                            source.get(r as usize, c as usize).to_bits(),
                            "tile ({tx}, {tz}) level {level} sample ({i}, {j})"
                        );
                    }
                }
            }
        }
    }
    assert_eq!(&tiled.to_heightmap(u64::MAX).unwrap(), source);
}

#[test]
fn raw16_imports_exactly_as_16_bit_codes_and_answers_height_at_like_the_loader() {
    let dir = tempfile::tempdir().unwrap();
    let (src, opts, (w, d)) = rough_r16(dir.path(), 1234.5, -17.25);
    let out = dir.path().join("rough.vkt");
    let report = import(&[&src], &opts, 16, &out);
    assert_eq!((report.width, report.depth), (w, d));
    assert_eq!((report.tiles_x, report.tiles_z), (13, 10));
    assert_eq!(report.levels, 5);
    assert_eq!(
        report.levels_as_floats, 0,
        "integer input is stored as codes"
    );
    assert_eq!(report.levels_as_codes, 13 * 10 * 5);
    assert_eq!(report.max_error, 0.0);
    // 16-bit levels; with tiles this small, shared borders, the pyramid
    // and the directory more than double that.
    assert_eq!(report.file_bytes, std::fs::metadata(&out).unwrap().len());
    assert_eq!(
        report.bytes_per_sample,
        report.file_bytes as f64 / (w * d) as f64
    );

    let source = Heightmap::load(&src, &opts).unwrap();
    let tiled = TiledHeightmap::open(&out).unwrap();
    assert_exact(&tiled, &source);
    assert_eq!(tiled.min_max(), source.min_max());
    // Each tile's Y bounds are its level 0 range.
    let e = tiled.entry(3, 2, 0);
    let [c0, c1, r0, r1] = tiled.header().tile_rect(3, 2);
    let mut lo = f32::INFINITY;
    let mut hi = f32::NEG_INFINITY;
    for r in r0..=r1 {
        for c in c0..=c1 {
            let h = source.get(r as usize, c as usize);
            lo = lo.min(h);
            hi = hi.max(h);
        }
    }
    assert_eq!((e.min, e.max), (lo, hi));
    // Each level's error against the full resolution, and 0 at level 0.
    let full: Vec<f32> = (r0..=r1)
        .flat_map(|r| (c0..=c1).map(move |c| (r, c)))
        .map(|(r, c)| source.get(r as usize, c as usize))
        .collect();
    assert_eq!(e.error, 0.0);
    for level in 1..tiled.header().levels {
        let stored = tiled.entry(3, 2, level).error;
        assert_eq!(stored, tiled::level_error(&full, (c1 - c0, r1 - r0), level));
        assert!(stored > 0.0, "rough data: level {level} misses something");
    }

    // height_at at samples, cell interiors, tile borders and outside, with
    // the terrain placed off the world origin.
    let spacing = DVec2::new(3.5, 2.25);
    let origin = DVec2::new(1.0e5, -7.0e4);
    let info = TerrainInfo::new(source, spacing, 16, origin).unwrap();
    let placement = Placement::new(w, d, spacing, origin).unwrap();
    let mut checked = 0;
    for i in 0..=97 {
        for j in 0..=61 {
            let x = origin.x - 0.52 * info.world_width() + i as f64 * 0.0107 * info.world_width();
            let z = origin.y - 0.51 * info.world_depth() + j as f64 * 0.0167 * info.world_depth();
            let expected = info.height_at(x, z);
            assert_eq!(
                tiled.height_at(&placement, x, z).unwrap(),
                expected,
                "({x}, {z})"
            );
            checked += usize::from(expected.is_some());
        }
    }
    assert!(checked > 5000, "most points are on the terrain: {checked}");
    for (r, c) in [(0, 0), (16, 16), (149, 202), (32, 200), (149, 0)] {
        let p = info.sample_position(r, c);
        assert_eq!(
            tiled.height_at(&placement, p.x, p.y).unwrap(),
            Some(info.whole().get(r, c))
        );
    }
}

#[test]
fn png_and_float_inputs_import_exactly() {
    let dir = tempfile::tempdir().unwrap();
    // The Jacksboro DEM as a 16-bit PNG, streamed by rows.
    let png = common::data_path("jacksboro_fault_dem.png");
    let opts = LoadOptions {
        height_scale: 65535.0,
        ..LoadOptions::default()
    };
    let out = dir.path().join("dem.vkt");
    let report = import_with_tables(&[&png], &opts, 64, 32, &out);
    assert_eq!(report.levels_as_floats, 0);
    assert_eq!((report.min_height, report.max_height), (236.0, 1076.0));
    // 2 bytes a sample, a third more for the pyramid, 65^2 samples stored
    // for each 64^2 cells, and 64 bytes of error tables and Y bounds per
    // 32^2 cells.
    assert!(
        (2.6..3.05).contains(&report.bytes_per_sample),
        "{}",
        report.bytes_per_sample
    );
    assert_exact(
        &TiledHeightmap::open(&out).unwrap(),
        &Heightmap::load(&png, &opts).unwrap(),
    );
    // Loading it whole through the heightmap loader gives the same map.
    assert_eq!(
        Heightmap::load(&out, &LoadOptions::default()).unwrap(),
        Heightmap::load(&png, &opts).unwrap()
    );

    // Floats that no integer mapping reproduces are stored as floats.
    let f32_path = dir.path().join("wave.f32");
    let (w, d) = (67usize, 41usize);
    let bytes: Vec<u8> = (0..w * d)
        .flat_map(|i| ((i as f32 * 0.37).sin() * 113.7 + 0.001 * i as f32).to_le_bytes())
        .collect();
    std::fs::write(&f32_path, bytes).unwrap();
    let opts = LoadOptions {
        size: Some((w as u64, d as u64)),
        height_scale: 2.0,
        ..LoadOptions::default()
    };
    let out = dir.path().join("wave.vkt");
    let report = import(&[&f32_path], &opts, 32, &out);
    assert_eq!(report.levels_as_codes, 0);
    assert_exact(
        &TiledHeightmap::open(&out).unwrap(),
        &Heightmap::load(&f32_path, &opts).unwrap(),
    );
}

/// A 1201x1201 SRTM tile: big-endian i16 metres with `voids` at -32768.
fn write_hgt(path: &Path, base: i16, voids: &[(usize, usize)]) {
    let n = 1201usize;
    let mut v: Vec<i16> = (0..n * n)
        .map(|i| base + ((i / n) as i16 % 97) * 3 - ((i % n) as i16 % 89))
        .collect();
    for &(r, c) in voids {
        v[r * n + c] = -32768;
    }
    let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_be_bytes()).collect();
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn srtm_tiles_mosaic_by_name_with_voids_filled_and_sea_where_a_tile_is_missing() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = dir.path().join("srtm");
    std::fs::create_dir(&tiles).unwrap();
    // North-west, south-west and south-east of a 2x2 block; the
    // north-east tile is missing (sea).
    let nw = tiles.join("N11E020.hgt");
    let sw = tiles.join("N10E020.hgt");
    let se = tiles.join("n10e021.hgt");
    write_hgt(&nw, 400, &[(500, 600), (500, 601), (501, 600)]);
    write_hgt(&sw, 200, &[]);
    write_hgt(&se, 900, &[(1200, 1200)]);
    let opts = LoadOptions {
        height_scale: 32767.0,
        ..LoadOptions::default()
    };
    let out = dir.path().join("mosaic.vkt");
    let report = import(&[&tiles], &opts, 128, &out);
    assert_eq!((report.width, report.depth), (2401, 2401));
    let mosaic = TiledHeightmap::open(&out).unwrap();
    let load = |p: &Path| {
        Heightmap::load(
            p,
            &LoadOptions {
                format: Some(HeightmapFormat::Hgt),
                ..opts.clone()
            },
        )
        .unwrap()
    };
    let (nw_map, sw_map, se_map) = (load(&nw), load(&sw), load(&se));
    // The voids are filled as the .hgt loader fills them, from their
    // neighbours: no -32768 is left.
    assert!(nw_map.get(500, 600) > 300.0);
    assert!(
        mosaic.min_max().0 >= 0.0,
        "no void survives: {:?}",
        mosaic.min_max()
    );
    for (r, c) in [(0, 0), (500, 600), (501, 600), (1199, 1199), (777, 1033)] {
        // North-west tile at the top left; south-west below it, sharing
        // row 1200; south-east right of that, sharing column 1200.
        assert_eq!(mosaic.get(r, c).unwrap(), nw_map.get(r, c));
        assert_eq!(mosaic.get(1200 + r, c).unwrap(), sw_map.get(r, c));
        assert_eq!(
            mosaic.get(1200 + r, 1200 + c + 1).unwrap(),
            se_map.get(r, c + 1)
        );
        // The missing north-east tile is sea level.
        assert_eq!(mosaic.get(r, 1201 + c).unwrap(), 0.0);
    }
    assert_eq!(mosaic.get(2400, 2400).unwrap(), se_map.get(1200, 1200));
    assert!(se_map.get(1200, 1200) > 800.0, "the corner void is filled");

    // Naming files instead of the directory gives the same terrain.
    let again = dir.path().join("again.vkt");
    import(&[&se, &nw, &sw], &opts, 128, &again);
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&again).unwrap());
}

#[test]
fn patch_y_bounds_from_tiles_equal_the_in_memory_ones_whether_patches_or_tiles_are_larger() {
    let dir = tempfile::tempdir().unwrap();
    let (src, opts, (w, d)) = rough_r16(dir.path(), 1.0, 0.0);
    let source = Heightmap::load(&src, &opts).unwrap();
    for tile in [4, 16, 64] {
        let out = dir.path().join(format!("t{tile}.vkt"));
        import(&[&src], &opts, tile, &out);
        let tiled = TiledHeightmap::open(&out).unwrap();
        for cells in [2, 16, 64] {
            let grid = PatchGrid::for_size(w, d, cells);
            assert_eq!(
                tiled.patch_y_bounds(&grid).unwrap(),
                patch_y_bounds(&source, &grid, 0.0),
                "{tile}-cell tiles, {cells}-cell patches"
            );
        }
    }
}

#[test]
fn stored_error_tables_equal_the_ones_built_at_load_and_come_with_the_scene() {
    let dir = tempfile::tempdir().unwrap();
    let (src, opts, (w, d)) = rough_r16(dir.path(), 300.0, 0.0);
    let source = Heightmap::load(&src, &opts).unwrap();
    for (tile, cells) in [(16, 16), (64, 16), (64, 64), (256, 4), (16, 32)] {
        let out = dir.path().join(format!("t{tile}-{cells}.vkt"));
        let report = import_with_tables(&[&src], &opts, tile, cells, &out);
        let tiled = TiledHeightmap::open(&out).unwrap();
        if tile % cells != 0 {
            // Tiles that hold no whole number of patches store none.
            assert_eq!(report.tables_cells_per_patch, None);
            assert!(tiled.error_tables().unwrap().is_none());
            continue;
        }
        assert_eq!(report.tables_cells_per_patch, Some(cells));
        let stored = tiled.error_tables().unwrap().unwrap();
        let (stored_cells, tess, geomip) = (stored.cells_per_patch, stored.tess, stored.geomip);
        assert_eq!(stored_cells, cells);
        let grid = PatchGrid::for_size(w, d, cells);
        assert_eq!(
            stored.y_bounds,
            patch_y_bounds(&source, &grid, 0.0),
            "{tile}-cell tiles, {cells}-cell patches: stored Y bounds"
        );
        let (want_tess, want_geomip) = ErrorTable::compute_pair(&source, &grid);
        assert_eq!(tess, want_tess, "{tile}-cell tiles, {cells}-cell patches");
        assert_eq!(
            geomip, want_geomip,
            "{tile}-cell tiles, {cells}-cell patches"
        );

        // A scene of that patch size gets them with its terrain; another
        // size builds its own.
        let mut scene = Scene::default_scene();
        scene.heightmap = HeightmapSource::File(out.clone());
        scene.load = LoadOptions::default();
        scene.cells_per_patch = cells;
        let info = scene.terrain_info().unwrap();
        assert_eq!(info.whole(), &source);
        assert_eq!(info.stored_error_tables(), Some(&(want_tess, want_geomip)));
        scene.cells_per_patch = if cells == 16 { 8 } else { 16 };
        assert!(scene
            .terrain_info()
            .unwrap()
            .stored_error_tables()
            .is_none());
    }
}

#[test]
fn the_tile_cache_stays_within_its_budget() {
    let dir = tempfile::tempdir().unwrap();
    let (src, opts, (w, d)) = rough_r16(dir.path(), 1.0, 0.0);
    let out = dir.path().join("rough.vkt");
    import(&[&src], &opts, 16, &out);
    // Three full tiles' worth (17^2 floats each).
    let budget = 3 * 17 * 17 * 4;
    let tiled = TiledHeightmap::open(&out).unwrap().with_cache_bytes(budget);
    let source = Heightmap::load(&src, &opts).unwrap();
    for r in (0..d).step_by(7) {
        for c in (0..w).step_by(5) {
            assert_eq!(tiled.get(r, c).unwrap(), source.get(r, c));
            assert!(tiled.cached_bytes() <= budget);
        }
    }
    assert!(tiled.cached_bytes() > 0);
}

/// A small imported terrain of F32 tiles (so a NaN can be planted) and its
/// bytes.
fn float_terrain(dir: &Path) -> (PathBuf, Vec<u8>) {
    let f32_path = dir.join("small.f32");
    let (w, d) = (37usize, 21usize);
    let bytes: Vec<u8> = (0..w * d)
        .flat_map(|i| (i as f32 * 0.1 + 0.05).to_le_bytes())
        .collect();
    std::fs::write(&f32_path, bytes).unwrap();
    let opts = LoadOptions {
        size: Some((w as u64, d as u64)),
        ..LoadOptions::default()
    };
    let out = dir.join("small.vkt");
    import(&[&f32_path], &opts, 16, &out);
    let bytes = std::fs::read(&out).unwrap();
    (out, bytes)
}

/// Opens `bytes` and reads every tile level; the first error as text.
fn read_all(bytes: &[u8]) -> Result<(), String> {
    let map = TiledHeightmap::from_bytes(bytes.to_vec(), Path::new("bad.vkt"))
        .map_err(|e| e.to_string())?;
    map.error_tables().map_err(|e| e.to_string())?;
    let (tx, tz) = map.header().tiles();
    for z in 0..tz {
        for x in 0..tx {
            for level in 0..map.header().levels {
                map.tile(x, z, level).map_err(|e| e.to_string())?;
            }
        }
    }
    Ok(())
}

#[test]
fn every_corruption_gives_an_error_naming_the_file_and_the_tile() {
    let dir = tempfile::tempdir().unwrap();
    let (_, good) = float_terrain(dir.path());
    read_all(&good).unwrap();
    let header = Header::decode(&good, good.len() as u64, Path::new("x")).unwrap();
    let dir_at = header.directory_offset as usize;
    let entry_at = |tx, tz, level| dir_at + header.entry_index(tx, tz, level) * ENTRY_BYTES;
    // Rewrites the directory's checksum in the header after an edit, so the
    // check under test is the one that fires.
    let reseal = |bytes: &mut Vec<u8>| {
        let mut h = Header::decode(&bytes[..HEADER_BYTES], bytes.len() as u64, Path::new("x"))
            .unwrap_or(header);
        h.directory_crc =
            crc32fast::hash(&bytes[dir_at..dir_at + header.directory_bytes() as usize]);
        bytes[..HEADER_BYTES].copy_from_slice(&h.encode());
    };
    let expect = |bytes: &[u8], words: &[&str]| {
        let err = read_all(bytes).expect_err(&format!("corruption is refused: {words:?}"));
        assert!(err.starts_with("bad.vkt: "), "names the file: {err}");
        for w in words {
            assert!(err.contains(w), "{err:?} should say {w:?}");
        }
    };

    // Truncated: the directory is cut off.
    expect(&good[..good.len() - 10], &["truncated"]);
    expect(&good[..40], &["header"]);
    // Not a tiled terrain at all, and a later version.
    let mut foreign = good.clone();
    foreign[0] = b'P';
    expect(&foreign, &["not a tiled terrain"]);
    let mut newer = good.clone();
    newer[8..12].copy_from_slice(&(tiled::VERSION + 1).to_le_bytes());
    let said = format!("version {}", tiled::VERSION + 1);
    expect(&newer, &[&said, "import the source heightmap again"]);
    // A flipped header byte.
    let mut flipped = good.clone();
    flipped[17] ^= 4;
    expect(&flipped, &["header", "checksum"]);
    // A flipped byte in the error tables, which end the file.
    let mut flipped = good.clone();
    let last = flipped.len() - 3;
    flipped[last] ^= 0x40;
    expect(&flipped, &["error tables", "checksum"]);
    // A flipped directory byte.
    let mut flipped = good.clone();
    flipped[dir_at + 3] ^= 1;
    expect(&flipped, &["directory", "checksum"]);
    // A tile offset pointing into the directory, and one into the header.
    for bad_offset in [dir_at as u64 - 4, 8] {
        let mut moved = good.clone();
        let at = entry_at(1, 0, 0);
        moved[at..at + 8].copy_from_slice(&bad_offset.to_le_bytes());
        reseal(&mut moved);
        expect(&moved, &["tile (1, 0) level 0", "outside the tile data"]);
    }
    // A wrong byte count.
    let mut short = good.clone();
    let at = entry_at(2, 1, 3);
    short[at + 8..at + 12].copy_from_slice(&4u32.to_le_bytes());
    reseal(&mut short);
    expect(&short, &["tile (2, 1) level 3", "bytes"]);
    // A flipped sample byte.
    let e = TiledHeightmap::from_bytes(good.clone(), Path::new("x"))
        .unwrap()
        .entry(1, 1, 0)
        .to_owned();
    assert_eq!(e.encoding, Encoding::F32);
    let mut flipped = good.clone();
    flipped[e.offset as usize + 9] ^= 0x10;
    expect(&flipped, &["tile (1, 1) level 0", "checksum"]);
    // A NaN sample with a matching checksum.
    let mut nan = good.clone();
    let s = e.offset as usize + 4 * 20;
    nan[s..s + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let crc = crc32fast::hash(&nan[e.offset as usize..e.offset as usize + e.bytes as usize]);
    let at = entry_at(1, 1, 0);
    nan[at + 24..at + 28].copy_from_slice(&crc.to_le_bytes());
    reseal(&mut nan);
    expect(
        &nan,
        &[
            "tile (1, 1) level 0",
            "row 1, column 3",
            "NaN",
            "not a finite number",
        ],
    );

    // Every single-byte change and every truncation is refused or read,
    // never a panic.
    for i in (0..good.len()).step_by(7) {
        let mut b = good.clone();
        b[i] ^= 0x5a;
        let _ = fuzz_open(&b);
        let _ = fuzz_open(&good[..i]);
    }
    assert!(fuzz_open(&good));
}

#[test]
fn bad_import_arguments_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.r16");
    let err = tiled::open_source(&[missing], &LoadOptions::default())
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("missing.r16") && err.contains("not found"),
        "{err}"
    );
    let junk = dir.path().join("N10E020.hgt");
    std::fs::write(&junk, [0u8; 100]).unwrap();
    let err = tiled::open_source(&[junk.clone(), junk.clone()], &LoadOptions::default())
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("1201x1201 or 3601x3601"), "{err}");
    let bad_name = dir.path().join("tile.hgt");
    write_hgt(&bad_name, 0, &[]);
    let err = tiled::open_source(&[bad_name, junk], &LoadOptions::default())
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("tile.hgt") && err.contains("south-west corner"),
        "{err}"
    );
    assert!(tiled::validate_tile_cells(48).is_err());
    assert!(tiled::validate_tile_cells(8192).is_err());
}
