//! Distance LOD: known values, shared edges, degenerate parameters.

mod common;

use common::*;
use glam::Vec3;
use proptest::prelude::*;
use vkterrain::lod::{patch_tess_factors, tess_factor, LodError};
use vkterrain::terrain::{DistanceLod, DistanceMode, PatchId, Terrain};

const LOD: DistanceLod = DistanceLod {
    min_dist: 100.0,
    max_dist: 1100.0,
    min_exp: 0.0,
    max_exp: 6.0,
};

#[test]
fn known_values() {
    let at = |d: f32, mode| tess_factor(Vec3::new(d, 0.0, 0.0), &LOD, mode);
    assert_eq!(at(0.0, DistanceMode::Smooth), 64.0);
    assert_eq!(
        at(100.0, DistanceMode::Smooth),
        64.0,
        "d exactly on min_dist"
    );
    assert_eq!(
        at(1100.0, DistanceMode::Smooth),
        1.0,
        "d exactly on max_dist"
    );
    assert_eq!(at(5000.0, DistanceMode::Smooth), 1.0);
    assert_eq!(at(600.0, DistanceMode::Smooth), 8.0, "halfway: 2^3");
    // Exponent 6 - 6 * 0.25 = 4.5 rounds up in debug mode, stays fractional otherwise.
    assert_eq!(at(350.0, DistanceMode::Debug), 32.0);
    assert!((at(350.0, DistanceMode::Smooth) - 4.5f32.exp2()).abs() < 1e-4);
    // Debug mode measures the xz max-norm and ignores height.
    let p = Vec3::new(300.0, 5000.0, -350.0);
    assert_eq!(tess_factor(p, &LOD, DistanceMode::Debug), 32.0);
}

#[test]
fn degenerate_parameters_stay_finite_in_range() {
    let step = DistanceLod {
        min_dist: 50.0,
        max_dist: 50.0,
        ..LOD
    };
    let reversed = DistanceLod {
        min_dist: 500.0,
        max_dist: 50.0,
        ..LOD
    };
    let zero = DistanceLod {
        min_dist: 0.0,
        max_dist: 0.0,
        min_exp: 3.0,
        max_exp: 3.0,
    };
    let points = [
        Vec3::ZERO,
        Vec3::new(50.0, 0.0, 0.0),
        Vec3::new(49.999, 0.0, 0.0),
        Vec3::new(f32::NAN, 0.0, 0.0),
        Vec3::splat(f32::INFINITY),
        Vec3::new(f32::NEG_INFINITY, 1.0, f32::INFINITY),
        Vec3::splat(f32::MAX),
    ];
    for lod in [LOD, step, reversed, zero] {
        for p in points {
            for mode in [DistanceMode::Smooth, DistanceMode::Debug] {
                let f = tess_factor(p, &lod, mode);
                assert!((1.0..=64.0).contains(&f), "{lod:?} at {p}: {f}");
            }
        }
    }
    // A step at min == max: finest on the bound, coarsest past it.
    assert_eq!(
        tess_factor(Vec3::new(50.0, 0.0, 0.0), &step, DistanceMode::Smooth),
        64.0
    );
    assert_eq!(
        tess_factor(Vec3::new(50.001, 0.0, 0.0), &step, DistanceMode::Smooth),
        1.0
    );
    // A NaN eye gives the coarsest level, not the finest.
    assert_eq!(tess_factor(Vec3::NAN, &LOD, DistanceMode::Smooth), 1.0);
    assert_eq!(tess_factor(Vec3::ZERO, &zero, DistanceMode::Smooth), 8.0);
}

#[test]
fn validation_names_the_bad_parameter() {
    assert_eq!(LOD.validate(), Ok(()));
    let bad = DistanceLod {
        min_dist: 10.0,
        max_dist: 5.0,
        ..LOD
    };
    assert!(matches!(bad.validate(), Err(LodError::Distance { .. })));
    let bad = DistanceLod {
        max_dist: f32::INFINITY,
        ..LOD
    };
    assert!(matches!(bad.validate(), Err(LodError::Distance { .. })));
    let bad = DistanceLod {
        max_exp: 7.0,
        ..LOD
    };
    assert!(matches!(bad.validate(), Err(LodError::Exponent { .. })));
    let bad = DistanceLod {
        min_exp: f32::NAN,
        ..LOD
    };
    assert!(matches!(bad.validate(), Err(LodError::Exponent { .. })));
}

fn check_shared_edges(
    terrain: &Terrain,
    eye: Vec3,
    lod: &DistanceLod,
    mode: DistanceMode,
) -> Result<(), TestCaseError> {
    let grid = terrain.grid();
    let factors = |row, col| {
        let corners = terrain.patch_corners(PatchId { row, col }).map(|c| c - eye);
        patch_tess_factors(corners, lod, mode)
    };
    for row in 0..grid.patch_rows() {
        for col in 0..grid.patch_cols() {
            let here = factors(row, col);
            for f in here.edges.iter().chain(&here.inside) {
                prop_assert!((1.0..=64.0).contains(f));
            }
            if col + 1 < grid.patch_cols() {
                let right = factors(row, col + 1);
                prop_assert_eq!(
                    here.edges[2].to_bits(),
                    right.edges[0].to_bits(),
                    "right edge of ({}, {})",
                    row,
                    col
                );
            }
            if row + 1 < grid.patch_rows() {
                let below = factors(row + 1, col);
                prop_assert_eq!(
                    here.edges[3].to_bits(),
                    below.edges[1].to_bits(),
                    "bottom edge of ({}, {})",
                    row,
                    col
                );
            }
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn shared_edges_get_identical_factors(
        ex in -20_000.0f32..20_000.0,
        ey in 0.0f32..5_000.0,
        ez in -20_000.0f32..20_000.0,
        min_dist in 0.0f32..5_000.0,
        span in 0.0f32..20_000.0,
        min_exp in 0.0f32..3.0,
        extra_exp in 0.0f32..3.0,
        debug in any::<bool>(),
    ) {
        thread_local!(static TERRAIN: Terrain = Terrain::new(dem_info(16), 0.0).unwrap());
        let lod = DistanceLod { min_dist, max_dist: min_dist + span, min_exp, max_exp: min_exp + extra_exp };
        let mode = if debug { DistanceMode::Debug } else { DistanceMode::Smooth };
        TERRAIN.with(|t| check_shared_edges(t, Vec3::new(ex, ey, ez), &lod, mode))?;
    }
}

#[test]
fn error_factors_are_powers_of_two_below_the_cells_or_the_cells() {
    use vkterrain::lod::{error_tess_factor, patch_is_full_resolution};
    // At distance 1 with 1 pixel per radian, level k projects to 8 / 2^k px.
    let errors = [8.0, 4.0, 2.0, 1.0, 0.5, 0.25, 0.125];
    let factor = |d: f32, px: f32, cells: u32| error_tess_factor(&errors, d, 1.0, px, cells);
    assert_eq!(factor(1.0, 1.0, 32), 8.0);
    assert_eq!(factor(1.0, 2.0, 32), 4.0);
    assert_eq!(factor(1.0, 1.0, 23), 8.0);
    // Nothing below the span's cells will do: a vertex on every sample.
    assert_eq!(factor(1.0, 1.0, 8), 8.0);
    assert_eq!(factor(1.0, 0.1, 23), 23.0);
    assert_eq!(factor(0.0, 1.0, 32), 32.0);
    assert_eq!(factor(1.0, 1.0, 1), 1.0);
    // Far away, or a broken scale: the coarsest.
    assert_eq!(factor(1e9, 1.0, 32), 1.0);
    assert_eq!(error_tess_factor(&errors, 1.0, f32::NAN, 1.0, 32), 1.0);
    // The full-resolution decision takes the smaller side.
    assert!(patch_is_full_resolution(&errors, 1.0, 1.0, 0.1, [32, 23]));
    assert!(patch_is_full_resolution(&errors, 1.0, 1.0, 1.0, [32, 8]));
    assert!(!patch_is_full_resolution(&errors, 1.0, 1.0, 1.0, [32, 32]));
}

#[test]
fn peer_policies_give_shared_edges_identical_factors() {
    use vkterrain::lod::{patch_peer_factors, PeerLod, PeerPolicy, ScreenParams};
    let terrain = Terrain::new(dem_info(16), 0.0).unwrap();
    let grid = terrain.grid();
    let eye = Vec3::new(-9000.0, 2500.0, -12000.0);
    let view = vkterrain::terrain::look_at(Vec3::ZERO, -eye, Vec3::Y);
    let proj = vkterrain::terrain::perspective(0.9, 16.0 / 9.0, 10.0, 1e5);
    let screen = ScreenParams {
        view_proj: proj * view,
        right: Vec3::new(view.x_axis.x, view.y_axis.x, view.z_axis.x),
        viewport: glam::Vec2::new(1280.0, 720.0),
        pixels_per_radian: 720.0 / (2.0 * 0.45f32.tan()),
    };
    for policy in PeerPolicy::ALL {
        let factors = |row, col| {
            let corners = terrain.patch_corners(PatchId { row, col }).map(|c| c - eye);
            patch_peer_factors(corners, policy, &LOD, &screen, &PeerLod::default())
        };
        let mut distinct = std::collections::BTreeSet::new();
        for row in 0..grid.patch_rows() {
            for col in 0..grid.patch_cols() {
                let here = factors(row, col);
                for f in here.edges.iter().chain(&here.inside) {
                    assert!((1.0..=64.0).contains(f), "{policy:?}: {f}");
                    distinct.insert(f.to_bits());
                }
                if col + 1 < grid.patch_cols() {
                    assert_eq!(
                        here.edges[2].to_bits(),
                        factors(row, col + 1).edges[0].to_bits()
                    );
                }
                if row + 1 < grid.patch_rows() {
                    assert_eq!(
                        here.edges[3].to_bits(),
                        factors(row + 1, col).edges[1].to_bits()
                    );
                }
            }
        }
        assert!(
            distinct.len() > 10,
            "{policy:?}: {} distinct factors",
            distinct.len()
        );
    }
}
