//! The patch grid covers every cell exactly once, its Y bounds contain
//! every covered sample, and its buffers have the documented layout.

mod common;

use common::*;
use glam::DVec2;
use vkterrain::terrain::{PatchId, Terrain, TerrainInfo};

fn check_grid(width: usize, depth: usize, cells_per_patch: u32, margin: f32) {
    let map = noise_map(width, depth, (width * 31 + depth) as u64);
    let info = TerrainInfo::new(
        map,
        DVec2::new(1.5, 0.75),
        cells_per_patch,
        DVec2::new(10.0, -3.0),
    )
    .unwrap();
    let terrain = Terrain::new(info, margin).unwrap();
    let (info, grid) = (terrain.info(), terrain.grid());
    let n = cells_per_patch as usize;
    let ctx = format!("{width}x{depth}, {n} cells per patch");

    // Counts.
    assert_eq!(grid.patch_rows(), (depth - 1).div_ceil(n), "{ctx}");
    assert_eq!(grid.patch_cols(), (width - 1).div_ceil(n), "{ctx}");
    let patches = grid.patch_rows() * grid.patch_cols();
    assert_eq!(
        terrain.control_points().len(),
        (grid.patch_rows() + 1) * (grid.patch_cols() + 1),
        "{ctx}"
    );
    assert_eq!(terrain.indices().len(), 4 * patches, "{ctx}");
    assert_eq!(terrain.y_bounds().len(), patches, "{ctx}");

    // Every cell in exactly one patch.
    let cells_x = width - 1;
    let mut owners = vec![0u8; cells_x * (depth - 1)];
    for p in 0..patches {
        let id = grid.patch_id(p);
        let rect = grid.sample_rect(id);
        assert!(
            rect.cells_x() >= 1 && rect.cells_x() <= n,
            "{ctx}: {rect:?}"
        );
        assert!(
            rect.cells_z() >= 1 && rect.cells_z() <= n,
            "{ctx}: {rect:?}"
        );
        for r in rect.row0..rect.row1 {
            for c in rect.col0..rect.col1 {
                owners[r * cells_x + c] += 1;
                assert_eq!(grid.patch_of_cell(r, c), id, "{ctx}");
            }
        }
        // Y bounds: exactly the min/max of the covered samples, widened by the margin.
        let mut lo = f32::INFINITY;
        let mut hi = f32::NEG_INFINITY;
        for r in rect.row0..=rect.row1 {
            for c in rect.col0..=rect.col1 {
                let h = info.whole().get(r, c);
                lo = lo.min(h);
                hi = hi.max(h);
            }
        }
        assert_eq!(
            terrain.y_bounds()[p],
            [lo - margin, hi + margin],
            "{ctx}: patch {id:?}"
        );
        // The bounds sit in the patch's upper-left control point.
        let ul = terrain.indices()[4 * p] as usize;
        assert_eq!(
            terrain.control_points()[ul][2..],
            [lo - margin, hi + margin],
            "{ctx}"
        );
    }
    assert!(
        owners.iter().all(|&o| o == 1),
        "{ctx}: a cell is covered {} times",
        owners.iter().find(|&&o| o != 1).unwrap()
    );

    // The last patch boundary is the last sample.
    assert_eq!(grid.boundary_col(grid.patch_cols()), width - 1, "{ctx}");
    assert_eq!(grid.boundary_row(grid.patch_rows()), depth - 1, "{ctx}");
}

#[test]
fn covers_every_cell_once_for_all_sizes() {
    for (w, d) in [(2, 2), (33, 33), (65, 33), (100, 37), (403, 344)] {
        for n in [2, 4, 8, 16, 32, 64] {
            check_grid(w, d, n, 0.0);
        }
    }
}

#[test]
fn covers_every_cell_once_for_4097_squared() {
    check_grid(4097, 4097, 32, 0.5);
}

#[test]
fn y_margin_widens_bounds() {
    check_grid(100, 37, 16, 2.5);
}

#[test]
fn dem_grid_has_a_narrower_last_row_and_column() {
    let terrain = Terrain::new(dem_info(32), 0.0).unwrap();
    let grid = terrain.grid();
    assert_eq!((grid.patch_rows(), grid.patch_cols()), (11, 13));
    let last = grid.sample_rect(PatchId { row: 10, col: 12 });
    assert_eq!((last.cells_z(), last.cells_x()), (343 - 320, 402 - 384));
    // Control points of the last column sit on the last sample column, at x = +W/2.
    let info = terrain.info();
    let cp = terrain.control_points()[grid.control_index(0, 13)];
    assert_eq!(f64::from(cp[0]), (0.5 * info.world_width()) as f32 as f64);
    assert_eq!(f64::from(cp[1]), (0.5 * info.world_depth()) as f32 as f64);
}

#[test]
fn indices_are_upper_left_upper_right_lower_left_lower_right() {
    let terrain = Terrain::new(dem_info(32), 0.0).unwrap();
    let grid = terrain.grid();
    let cps = terrain.control_points();
    for p in 0..grid.patch_count() {
        let [ul, ur, ll, lr] = [0, 1, 2, 3].map(|k| cps[terrain.indices()[4 * p + k] as usize]);
        // x grows to the right, z shrinks downwards (row 0 is +z).
        assert!(ul[0] < ur[0] && ll[0] < lr[0]);
        assert!(ul[1] > ll[1] && ur[1] > lr[1]);
        assert_eq!((ul[0], ul[1]), (ll[0], ur[1]));
        assert_eq!((lr[0], lr[1]), (ur[0], ll[1]));
        // The corners match the control points.
        let corners = terrain.patch_corners(grid.patch_id(p));
        for (c, cp) in corners.iter().zip([ul, ur, ll, lr]) {
            assert_eq!((c.x, c.z), (cp[0], cp[1]));
        }
    }
}
