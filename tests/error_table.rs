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
/// at every sample, cell centre and quad centre add the distance to the
/// bilinear surface of its quad and a quarter of that quad's twist; then
/// make each level at least as large as every finer one.
fn brute_force(info: &TerrainInfo, grid: &PatchGrid) -> Vec<f32> {
    let mut out = Vec::new();
    for p in 0..grid.patch_count() {
        let rect = grid.sample_rect(grid.patch_id(p));
        let (nx, nz) = (rect.cells_x() as f64, rect.cells_z() as f64);
        let (c0, r0) = (rect.col0 as f64, rect.row0 as f64);
        let mut raw = Vec::new();
        for &level in &ERROR_LEVELS {
            let l = f64::from(level);
            let vertex = |i: f64, j: f64| surface(info, c0 + j * nx / l, r0 + i * nz / l);
            // Points as patch-relative (col, row).
            let mut points = Vec::new();
            for r in 0..=rect.cells_z() {
                for c in 0..=rect.cells_x() {
                    points.push((c as f64, r as f64));
                    if r < rect.cells_z() && c < rect.cells_x() {
                        points.push((c as f64 + 0.5, r as f64 + 0.5));
                    }
                }
            }
            for i in 0..level {
                for j in 0..level {
                    points.push(((f64::from(j) + 0.5) * nx / l, (f64::from(i) + 0.5) * nz / l));
                }
            }
            let mut worst = 0.0f64;
            for (col, row) in points {
                let (u, v) = (col * l / nx, row * l / nz);
                let (i, j) = (v.floor().min(l - 1.0), u.floor().min(l - 1.0));
                let (fv, fu) = (v - i, u - j);
                let (v00, v01) = (vertex(i, j), vertex(i, j + 1.0));
                let (v10, v11) = (vertex(i + 1.0, j), vertex(i + 1.0, j + 1.0));
                let top = v00 * (1.0 - fu) + v01 * fu;
                let bottom = v10 * (1.0 - fu) + v11 * fu;
                let bilinear = top * (1.0 - fv) + bottom * fv;
                let here = surface(info, c0 + col, r0 + row);
                worst = worst.max((here - bilinear).abs() + 0.25 * (v00 + v11 - v01 - v10).abs());
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
            // Level 32 puts a vertex on every sample: what is left is a cell
            // folded along the other diagonal, half its twist at worst.
            let map = dem("jacksboro_fault_dem.png", None);
            let mut fold = 0.0f32;
            for r in rect.row0..rect.row1 {
                for c in rect.col0..rect.col1 {
                    let twist = map.get(r, c) + map.get(r + 1, c + 1)
                        - map.get(r, c + 1)
                        - map.get(r + 1, c);
                    fold = fold.max(0.5 * twist.abs());
                }
            }
            assert!(
                (levels[5] - fold).abs() <= 1e-3,
                "patch {p}: {} vs {fold}",
                levels[5]
            );
        }
    }
    assert!(nonzero > grid.patch_count() * 4);
}

#[test]
fn a_single_spike_is_seen_at_coarse_levels() {
    let spike =
        Heightmap::from_fn(33, 33, |r, c| if (r, c) == (16, 16) { 10.0 } else { 0.0 }).unwrap();
    let (table, _, _) = table_for(spike, 32);
    let levels = table.patch(0);
    // Level 1: a flat quad, the spike 10 above it.
    assert!(levels[0] >= 10.0);
    // Level 32: a vertex on every sample; the four cells around the spike
    // have a twist of 10, and the wrong diagonal misses by half of it.
    assert_eq!(levels[5], 5.0);
    // Level 64: half-cell quads; those on the spike cells' folds twist by
    // 5 and miss by a quarter of the fold.
    assert_eq!(levels[6], 2.5);
}
