//! The per-patch error table against a brute-force recomputation.

mod common;

use common::*;
use glam::DVec2;
use vkterrain::terrain::{ErrorTable, Heightmap, PatchGrid, TerrainInfo, ERROR_LEVELS};

/// Surface height at continuous sample coordinates (col, row), through the
/// public world-space query (unit spacing, so grid = world + half extent).
fn surface(info: &TerrainInfo, col: f64, row: f64) -> f64 {
    let x = col - info.world_width() / 2.0;
    let z = info.world_depth() / 2.0 - row;
    f64::from(info.height_at(x, z).expect("inside"))
}

/// Straightforward floating-point recomputation: tessellate, displace, and
/// compare every sample with the bilinear surface of its sub-quad; then make
/// each level at least as large as every finer one.
fn brute_force(info: &TerrainInfo, grid: &PatchGrid) -> Vec<f32> {
    let map = info.heightmap();
    let mut out = Vec::new();
    for p in 0..grid.patch_count() {
        let rect = grid.sample_rect(grid.patch_id(p));
        let (nx, nz) = (rect.cells_x() as f64, rect.cells_z() as f64);
        let mut raw = Vec::new();
        for &level in &ERROR_LEVELS {
            let l = f64::from(level);
            let vertex = |i: f64, j: f64| {
                surface(
                    info,
                    rect.col0 as f64 + j * nx / l,
                    rect.row0 as f64 + i * nz / l,
                )
            };
            let mut worst = 0.0f64;
            for r in rect.row0..=rect.row1 {
                for c in rect.col0..=rect.col1 {
                    let v = (r - rect.row0) as f64 * l / nz;
                    let u = (c - rect.col0) as f64 * l / nx;
                    let (i, j) = (v.floor().min(l - 1.0), u.floor().min(l - 1.0));
                    let (fv, fu) = (v - i, u - j);
                    let top = vertex(i, j) * (1.0 - fu) + vertex(i, j + 1.0) * fu;
                    let bottom = vertex(i + 1.0, j) * (1.0 - fu) + vertex(i + 1.0, j + 1.0) * fu;
                    let surface = top * (1.0 - fv) + bottom * fv;
                    worst = worst.max((f64::from(map.get(r, c)) - surface).abs());
                }
            }
            raw.push(worst);
        }
        for k in (0..raw.len() - 1).rev() {
            raw[k] = raw[k].max(raw[k + 1]);
        }
        out.extend(raw.iter().map(|&e| e as f32));
    }
    out
}

fn table_for(map: Heightmap, cells_per_patch: u32) -> (ErrorTable, PatchGrid, TerrainInfo) {
    let info = TerrainInfo::new(map, DVec2::new(1.0, 1.0), cells_per_patch, DVec2::ZERO).unwrap();
    let grid = PatchGrid::new(&info);
    (ErrorTable::compute(info.heightmap(), &grid), grid, info)
}

#[test]
fn planar_heightmap_has_no_error() {
    let plane = Heightmap::from_fn(100, 37, |r, c| 3.0 * c as f32 - 0.5 * r as f32 + 7.0).unwrap();
    let (table, grid, _) = table_for(plane, 16);
    assert_eq!(
        table.as_slice().len(),
        grid.patch_count() * ERROR_LEVELS.len()
    );
    let worst = table.as_slice().iter().fold(0.0f32, |a, &b| a.max(b));
    // Height range is ~300: this is zero up to f64 rounding.
    assert!(worst < 1e-9, "{worst}");
}

#[test]
fn equals_brute_force_on_random_maps() {
    for (w, d, n, seed) in [
        (33, 33, 32, 1),
        (100, 37, 16, 2),
        (65, 33, 8, 3),
        (70, 45, 32, 4),
        (2, 2, 2, 5),
        (40, 40, 64, 6),
    ] {
        let (table, grid, info) = table_for(noise_map(w, d, seed), n);
        let want = brute_force(&info, &grid);
        for (i, (&got, &want)) in table.as_slice().iter().zip(&want).enumerate() {
            assert!(
                (got - want).abs() <= 1e-4 * want.max(1.0),
                "{w}x{d} n={n}: entry {i}: {got} vs {want}"
            );
        }
    }
}

#[test]
fn non_increasing_as_the_level_rises() {
    let (table, grid, _) = table_for(dem("jacksboro_fault_dem.png", None), 32);
    let mut nonzero = 0;
    for p in 0..grid.patch_count() {
        let levels = table.patch(p);
        assert!(
            levels.windows(2).all(|w| w[0] >= w[1]),
            "patch {p}: {levels:?}"
        );
        assert!(levels[0] > 0.0, "a real DEM patch is not planar");
        nonzero += levels.iter().filter(|&&e| e > 0.0).count();
        let rect = grid.sample_rect(grid.patch_id(p));
        if rect.cells_x() == 32 && rect.cells_z() == 32 {
            // Levels 32 and 64 put a vertex on every sample.
            assert_eq!(&levels[5..], &[0.0, 0.0], "patch {p}");
        }
    }
    assert!(nonzero > grid.patch_count() * 4);
}

#[test]
fn a_single_spike_is_seen_at_coarse_levels() {
    let spike =
        Heightmap::from_fn(33, 33, |r, c| if (r, c) == (16, 16) { 10.0 } else { 0.0 }).unwrap();
    let (table, _, _) = table_for(spike, 32);
    // Level 1: a flat quad, the spike is 10 above it. Level 2 puts a vertex on
    // the spike, and its neighbour (16, 15) sits 10 * 15/16 below the slope.
    assert_eq!(table.patch(0)[0], 10.0);
    assert_eq!(table.patch(0)[1], 9.375);
    assert_eq!(table.patch(0)[5], 0.0);
}
