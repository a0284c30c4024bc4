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

/// The two triangulations of the quad with corner heights A (upper-left),
/// B, C, D (lower-right) at fractions (u, v) of it: split B-C (the
/// reference's), split A-D.
fn splits(a: f64, b: f64, c: f64, d: f64, u: f64, v: f64) -> (f64, f64) {
    let bc = if u + v <= 1.0 {
        a * (1.0 - u - v) + b * u + c * v
    } else {
        d * (u + v - 1.0) + c * (1.0 - u) + b * (1.0 - v)
    };
    let ad = if u >= v {
        a * (1.0 - u) + b * (u - v) + d * v
    } else {
        a * (1.0 - v) + c * (v - u) + d * u
    };
    (bc, ad)
}

/// Straightforward floating-point recomputation, through the public height
/// query. Levels at or above the patch's smaller side are drawn exactly
/// (0). Where the level's quads are square runs of whole cells, the error
/// of each split is measured at every sample, cell centre and cell edge
/// midpoint (a superset of where two piecewise-linear surfaces on these
/// grids can differ most); elsewhere the bound: at every sample, cell
/// centre and quad centre, the distance to the bilinear surface of its quad
/// plus a quarter of that quad's twist. Then each level is made at least as
/// large as every finer tessellated one. Returns (tess, geomip) tables.
fn brute_force(info: &TerrainInfo, grid: &PatchGrid) -> (Vec<f32>, Vec<f32>) {
    let (mut tess, mut geomip) = (Vec::new(), Vec::new());
    for p in 0..grid.patch_count() {
        let rect = grid.sample_rect(grid.patch_id(p));
        let (cx, cz) = (rect.cells_x(), rect.cells_z());
        let (nx, nz) = (cx as f64, cz as f64);
        let (c0, r0) = (rect.col0 as f64, rect.row0 as f64);
        let (mut raw_tess, mut raw_geomip) = (Vec::new(), Vec::new());
        for &level in &ERROR_LEVELS {
            let level = level as usize;
            if level >= cx.min(cz) {
                raw_tess.push(0.0);
                raw_geomip.push(0.0);
                continue;
            }
            let l = level as f64;
            let vertex = |i: f64, j: f64| surface(info, c0 + j * nx / l, r0 + i * nz / l);
            let exact = cx == cz && cx % level == 0;
            // Points as patch-relative (col, row).
            let mut points = Vec::new();
            for r in 0..=cz {
                for c in 0..=cx {
                    let (col, row) = (c as f64, r as f64);
                    points.push((col, row));
                    if c < cx {
                        points.push((col + 0.5, row));
                    }
                    if r < cz {
                        points.push((col, row + 0.5));
                    }
                    if r < cz && c < cx {
                        points.push((col + 0.5, row + 0.5));
                    }
                }
            }
            if !exact {
                for i in 0..level {
                    for j in 0..level {
                        points.push(((j as f64 + 0.5) * nx / l, (i as f64 + 0.5) * nz / l));
                    }
                }
            }
            let (mut worst_tess, mut worst_geomip) = (0.0f64, 0.0f64);
            for (col, row) in points {
                let (u, v) = (col * l / nx, row * l / nz);
                let (i, j) = (v.floor().min(l - 1.0), u.floor().min(l - 1.0));
                let (fv, fu) = (v - i, u - j);
                let (v00, v01) = (vertex(i, j), vertex(i, j + 1.0));
                let (v10, v11) = (vertex(i + 1.0, j), vertex(i + 1.0, j + 1.0));
                let here = surface(info, c0 + col, r0 + row);
                if exact {
                    let (bc, ad) = splits(v00, v01, v10, v11, fu, fv);
                    worst_geomip = worst_geomip.max((here - bc).abs());
                    worst_tess = worst_tess.max((here - bc).abs()).max((here - ad).abs());
                } else {
                    let top = v00 * (1.0 - fu) + v01 * fu;
                    let bottom = v10 * (1.0 - fu) + v11 * fu;
                    let bilinear = top * (1.0 - fv) + bottom * fv;
                    let bound = (here - bilinear).abs() + 0.25 * (v00 + v11 - v01 - v10).abs();
                    worst_tess = worst_tess.max(bound);
                    worst_geomip = worst_geomip.max(bound);
                }
            }
            raw_tess.push(worst_tess);
            raw_geomip.push(worst_geomip);
        }
        for raw in [&mut raw_tess, &mut raw_geomip] {
            for k in (0..raw.len() - 1).rev() {
                raw[k] = raw[k].max(raw[k + 1]);
            }
        }
        tess.extend(raw_tess.iter().map(|&e| e as f32));
        geomip.extend(raw_geomip.iter().map(|&e| e as f32));
    }
    (tess, geomip)
}

fn tables_for(
    map: Heightmap,
    cells_per_patch: u32,
) -> ((ErrorTable, ErrorTable), PatchGrid, TerrainInfo) {
    let info = TerrainInfo::new(map, DVec2::new(1.0, 1.0), cells_per_patch, DVec2::ZERO).unwrap();
    let grid = info.patch_grid();
    (ErrorTable::compute_pair(info.whole(), &grid), grid, info)
}

fn table_for(map: Heightmap, cells_per_patch: u32) -> (ErrorTable, PatchGrid, TerrainInfo) {
    let ((tess, _), grid, info) = tables_for(map, cells_per_patch);
    (tess, grid, info)
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
        let ((tess, geomip), grid, info) = tables_for(noise_map(w, d, seed), n);
        let (want_tess, want_geomip) = brute_force(&info, &grid);
        for (name, table, want) in [("tess", &tess, want_tess), ("geomip", &geomip, want_geomip)] {
            // One cell is drawn exactly; anything larger has errors.
            assert_eq!(
                table.as_slice().iter().any(|&e| e > 0.0),
                w > 2,
                "{name} {w}x{d} n={n}"
            );
            for (i, (&got, &want)) in table.as_slice().iter().zip(&want).enumerate() {
                assert!(
                    (got - want).abs() <= 1e-4 * want.max(1.0),
                    "{name} {w}x{d} n={n}: entry {i}: {got} vs {want}"
                );
            }
        }
        // The geomip path's fixed diagonal is never worse than either.
        for (g, t) in geomip.as_slice().iter().zip(tess.as_slice()) {
            assert!(g <= t);
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
            // Levels 32 and 64 are never tessellated: such a patch is drawn
            // with the reference's own triangles.
            assert_eq!(&levels[5..], &[0.0, 0.0], "patch {p}");
            assert!(levels[4] > 0.0, "patch {p}: level 16 has some error");
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
    // Level 16: the spike is a vertex of 2x2-cell quads. Split along the
    // reference's diagonal, a quad's edge from the spike to a neighbouring
    // vertex passes over a sample of height 0 at 5. Split against it, the
    // fold from the spike crosses the centre of the cell beside it a
    // quarter of the way along, at 7.5, where the reference is 0.
    assert_eq!(levels[4], 7.5);
    // Levels 32 and 64: drawn exactly.
    assert_eq!(&levels[5..], &[0.0, 0.0]);
}
