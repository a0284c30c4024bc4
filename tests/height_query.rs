//! `height_at` is exact at samples, continuous, agrees with an independent
//! barycentric implementation, and is None outside.

mod common;

use common::*;
use glam::{DVec2, DVec3, Vec3};
use proptest::prelude::*;
use vkterrain::terrain::{Heightmap, PatchId, Terrain, TerrainInfo};

fn infos() -> Vec<TerrainInfo> {
    vec![
        dem_info(32),
        // The same DEM a million units from the world origin.
        dem_info_at(32, DVec2::new(1e6, -1e6)),
        TerrainInfo::new(
            noise_map(37, 100, 7),
            DVec2::new(0.3, 2.0),
            8,
            DVec2::new(-5.0, 12.5),
        )
        .unwrap(),
        TerrainInfo::new(noise_map(2, 2, 3), DVec2::new(1.0, 1.0), 2, DVec2::ZERO).unwrap(),
    ]
}

#[test]
fn exact_at_every_sample_including_the_far_edges() {
    for info in infos() {
        for r in 0..info.rows() {
            for c in 0..info.cols() {
                let p = info.sample_position(r, c);
                assert_eq!(
                    info.height_at(p.x, p.y),
                    Some(info.whole().get(r, c)),
                    "sample ({r}, {c})"
                );
            }
        }
    }
}

#[test]
fn far_corners_are_inside_and_exact() {
    let info = dem_info(32);
    let (w, d) = (info.world_width(), info.world_depth());
    let map = info.whole();
    assert_eq!(info.height_at(-w / 2.0, d / 2.0), Some(map.get(0, 0)));
    assert_eq!(info.height_at(w / 2.0, d / 2.0), Some(map.get(0, 402)));
    assert_eq!(info.height_at(-w / 2.0, -d / 2.0), Some(map.get(343, 0)));
    assert_eq!(info.height_at(w / 2.0, -d / 2.0), Some(map.get(343, 402)));
    // Midway along the last column: between rows 100 and 101 of column 402.
    let z = 0.5 * (info.local_z(100) + info.local_z(101));
    let expected = 0.5 * (f64::from(map.get(100, 402)) + f64::from(map.get(101, 402)));
    assert!((f64::from(info.height_at(w / 2.0, z).unwrap()) - expected).abs() < 1e-3);
}

#[test]
fn none_outside() {
    for info in infos() {
        let o = info.origin();
        let (hw, hd) = (info.world_width() / 2.0, info.world_depth() / 2.0);
        let step = 1e-3 * info.spacing().min_element();
        for (x, z) in [
            (o.x - hw - step, o.y),
            (o.x + hw + step, o.y),
            (o.x, o.y - hd - step),
            (o.x, o.y + hd + step),
            (o.x + 1e9, o.y),
            (f64::NAN, o.y),
            (o.x, f64::INFINITY),
            (f64::NEG_INFINITY, f64::NAN),
        ] {
            assert_eq!(info.height_at(x, z), None, "({x}, {z})");
        }
    }
}

#[test]
fn continuous_across_cell_borders_and_the_diagonal() {
    let info =
        TerrainInfo::new(noise_map(40, 30, 11), DVec2::new(1.0, 1.0), 8, DVec2::ZERO).unwrap();
    let eps = 1e-7;
    // Heights are below 200 and neighbouring samples differ by less than
    // 200, so the slope is below 200 per cell: 2 * eps * 200 plus rounding.
    let tol = 1e-4;
    for r in 0..29usize {
        for c in 0..39usize {
            let x0 = info.local_x(c);
            let z0 = info.local_z(r);
            // Vertical cell border at column c, at several depths in the cell.
            for t in [0.1, 0.5, 0.9] {
                let z = z0 - t;
                if c > 0 {
                    let a = info.height_at(x0 - eps, z).unwrap();
                    let b = info.height_at(x0 + eps, z).unwrap();
                    assert!((a - b).abs() < tol, "border x at ({r}, {c}): {a} vs {b}");
                }
                if r > 0 {
                    let a = info.height_at(x0 + t, z0 + eps).unwrap();
                    let b = info.height_at(x0 + t, z0 - eps).unwrap();
                    assert!((a - b).abs() < tol, "border z at ({r}, {c}): {a} vs {b}");
                }
                // The diagonal s + t = 1, from either side.
                let (s, tt) = (t, 1.0 - t);
                let a = info.height_at(x0 + s - eps, z0 - tt + eps).unwrap();
                let b = info.height_at(x0 + s + eps, z0 - tt - eps).unwrap();
                assert!((a - b).abs() < tol, "diagonal in ({r}, {c}): {a} vs {b}");
            }
        }
    }
}

/// Independent reference: find the triangle by the diagonal's side, then
/// solve for the height with the plane through the triangle's 3D corners.
fn plane_height(info: &TerrainInfo, x: f64, z: f64) -> f64 {
    let local = DVec2::new(x, z) - info.origin();
    let sp = info.spacing();
    let c = ((local.x + info.world_width() / 2.0) / sp.x)
        .floor()
        .clamp(0.0, (info.cols() - 2) as f64) as usize;
    let r = ((info.world_depth() / 2.0 - local.y) / sp.y)
        .floor()
        .clamp(0.0, (info.rows() - 2) as f64) as usize;
    let corner = |rr: usize, cc: usize| {
        DVec3::new(
            info.local_x(cc),
            f64::from(info.whole().get(rr, cc)),
            info.local_z(rr),
        )
    };
    let (a, b, cc, d) = (
        corner(r, c),
        corner(r, c + 1),
        corner(r + 1, c),
        corner(r + 1, c + 1),
    );
    // Which side of the line from B to C (in xz) is the point on? A's side is the upper triangle.
    let side = |p: DVec2| (cc.x - b.x) * (p.y - b.z) - (cc.z - b.z) * (p.x - b.x);
    let (p0, p1, p2) = if side(local) * side(DVec2::new(a.x, a.z)) >= 0.0 {
        (a, b, cc)
    } else {
        (d, cc, b)
    };
    let n = (p1 - p0).cross(p2 - p0);
    // n . (P - p0) = 0 solved for P.y.
    p0.y - (n.x * (local.x - p0.x) + n.z * (local.y - p0.z)) / n.y
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 100, ..ProptestConfig::default() })]

    /// 100 cases of 1000 points: 10^5 random points on the real DEM.
    #[test]
    fn matches_independent_barycentric(points in prop::collection::vec((0.0f64..=1.0, 0.0f64..=1.0), 1000)) {
        thread_local!(static INFO: TerrainInfo = dem_info(32));
        INFO.with(|info| {
            for (u, v) in points {
                let x = (u - 0.5) * info.world_width();
                let z = (v - 0.5) * info.world_depth();
                let got = f64::from(info.height_at(x, z).expect("inside"));
                let want = plane_height(info, x, z);
                // f32 output: half an ulp of ~1000 m is 3e-5; allow a little more.
                prop_assert!((got - want).abs() < 1e-4, "({}, {}): {} vs {}", x, z, got, want);
            }
            Ok(())
        })?;
    }
}

#[test]
fn clamped_height_follows_the_border_and_never_fails() {
    let info = dem_info(32);
    let (hw, hd) = (info.world_width() / 2.0, info.world_depth() / 2.0);
    let z = 1234.5;
    assert_eq!(
        info.clamped_height_at(hw + 500.0, z),
        info.height_at(hw, z).unwrap()
    );
    assert_eq!(
        info.clamped_height_at(-hw - 1e12, z),
        info.height_at(-hw, z).unwrap()
    );
    assert_eq!(
        info.clamped_height_at(hw * 3.0, hd * 3.0),
        info.whole().get(0, 402)
    );
    assert_eq!(
        info.clamped_height_at(f64::NAN, f64::INFINITY),
        info.height_at(0.0, 0.0).unwrap()
    );
    assert_eq!(
        info.clamped_height_at(100.0, 200.0),
        info.height_at(100.0, 200.0).unwrap()
    );
}

#[test]
fn normals_of_flat_and_sloped_planes() {
    let flat = TerrainInfo::new(
        Heightmap::from_fn(9, 9, |_, _| 4.0).unwrap(),
        DVec2::new(2.0, 3.0),
        4,
        DVec2::ZERO,
    )
    .unwrap();
    for (x, z) in [(0.0, 0.0), (8.0, 12.0), (-8.0, -12.0), (100.0, 0.0)] {
        assert_eq!(flat.normal_at(x, z), Vec3::Y);
    }
    // h = 0.5 x - 0.25 z: x = -8 + 2c, z = 12 - 3r.
    let plane = Heightmap::from_fn(9, 9, |r, c| {
        let (x, z) = (-8.0 + 2.0 * c as f32, 12.0 - 3.0 * r as f32);
        0.5 * x - 0.25 * z
    })
    .unwrap();
    let plane = TerrainInfo::new(plane, DVec2::new(2.0, 3.0), 4, DVec2::ZERO).unwrap();
    let want = Vec3::new(-0.5, 1.0, 0.25).normalize();
    // Interior, edges and corners (one-sided differences there).
    for (x, z) in [
        (0.3, 0.7),
        (8.0, 0.0),
        (-8.0, 12.0),
        (8.0, -12.0),
        (0.0, -12.0),
    ] {
        let n = plane.normal_at(x, z);
        assert!((n - want).length() < 1e-5, "({x}, {z}): {n} vs {want}");
    }
}

/// `Terrain::surface_distances` bounds from below the distance from the
/// eye to every point within each grow above or below a patch's surface,
/// for eyes over, beside, under and above rough patches.
#[test]
fn surface_distances_bound_every_point_near_a_patchs_surface() {
    let info = TerrainInfo::new(
        noise_map(37, 29, 5),
        DVec2::new(3.0, 2.0),
        8,
        DVec2::new(10.0, -4.0),
    )
    .unwrap();
    let terrain = Terrain::new(info, 0.0).unwrap();
    let (info, grid) = (terrain.info(), terrain.grid());
    // Local x and z at continuous sample coordinates.
    let local = |c: f64, r: f64| {
        let x = info.local_x(0) + c * (info.local_x(1) - info.local_x(0));
        let z = info.local_z(0) + r * (info.local_z(1) - info.local_z(0));
        (x as f32, z as f32)
    };
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut unit = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let grows = [0.0f32, 0.5, 4.0, 30.0];
    let mut inside = 0;
    for p in 0..grid.patch_count() {
        let id = grid.patch_id(p);
        let rect = grid.sample_rect(id);
        let span = |lo: usize, hi: usize, u: f64| lo as f64 + u * (hi - lo) as f64;
        for _ in 0..12 {
            let (c, r) = (
                span(rect.col0, rect.col1, 1.6 * unit() - 0.3),
                span(rect.row0, rect.row1, 1.6 * unit() - 0.3),
            );
            let (x, z) = local(c, r);
            let eye = Vec3::new(x, (160.0 * unit() - 20.0) as f32, z);
            let bounds = terrain.surface_distances(id, eye, &grows).unwrap();
            inside += bounds.iter().filter(|&&b| b == 0.0).count();
            for _ in 0..300 {
                let (c, r) = (
                    span(rect.col0, rect.col1, unit()),
                    span(rect.row0, rect.row1, unit()),
                );
                let h = info.whole().interpolate(c, r) as f32;
                let (x, z) = local(c, r);
                let off = (2.0 * unit() - 1.0) as f32;
                for (&g, &bound) in grows.iter().zip(&bounds) {
                    let d = (Vec3::new(x, h + off * g, z) - eye).length();
                    assert!(
                        d >= bound - 1e-3 * bound.max(1.0),
                        "patch {p}, eye {eye}, grow {g}: a point {d} away, bound {bound}"
                    );
                }
            }
        }
    }
    // Some eyes lie within a grown box, and are told so.
    assert!(inside > 0);
}

/// Over flat ground, with a peak at the patch's far corner that puts the
/// eye inside its box, the nearest the surface comes is the eye's height,
/// less each grow, and 0 once the grow reaches the eye.
#[test]
fn over_flat_ground_the_surface_is_the_eyes_height_away() {
    let map =
        Heightmap::from_fn(17, 17, |r, c| if (r, c) == (16, 16) { 100.0 } else { 0.0 }).unwrap();
    let info = TerrainInfo::new(map, DVec2::splat(4.0), 16, DVec2::ZERO).unwrap();
    let terrain = Terrain::new(info, 0.0).unwrap();
    let info = terrain.info();
    let eye = Vec3::new(info.local_x(2) as f32, 10.0, info.local_z(3) as f32);
    let patch = PatchId { row: 0, col: 0 };
    assert_eq!(
        terrain.surface_distances(patch, eye, &[0.0, 2.5, 12.0]),
        Some([10.0, 7.5, 0.0])
    );
}
