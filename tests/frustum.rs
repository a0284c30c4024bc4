//! Frustum planes from a Vulkan view-projection, and the AABB test.

use glam::{Mat4, Vec3, Vec4};
use vkterrain::terrain::camera::{aabb_outside_frustum, look_at, perspective, Frustum};

const NEAR: f32 = 1.0;
const FAR: f32 = 100.0;

/// Eye at the origin looking down -z, 90 degree field of view, square.
fn known_camera() -> Frustum {
    let view = look_at(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y);
    let proj = perspective(90f32.to_radians(), 1.0, NEAR, FAR);
    Frustum::from_view_proj(proj * view)
}

/// Equal within f32 rounding of the extraction, relative to the larger size.
fn close(a: Vec4, b: Vec4) -> bool {
    (a - b).abs().max_element() < 1e-5 * b.abs().max_element().max(1.0)
}

#[test]
fn planes_of_a_known_camera() {
    let f = known_camera();
    let s = std::f32::consts::FRAC_1_SQRT_2;
    assert!(
        close(f.planes[0], Vec4::new(s, 0.0, -s, 0.0)),
        "left {}",
        f.planes[0]
    );
    assert!(
        close(f.planes[1], Vec4::new(-s, 0.0, -s, 0.0)),
        "right {}",
        f.planes[1]
    );
    // Clip y points down in Vulkan, so "bottom" (clip y >= -w) is the world's top.
    assert!(
        close(f.planes[2], Vec4::new(0.0, -s, -s, 0.0)),
        "clip y >= -w {}",
        f.planes[2]
    );
    assert!(
        close(f.planes[3], Vec4::new(0.0, s, -s, 0.0)),
        "clip y <= w {}",
        f.planes[3]
    );
    assert!(
        close(f.planes[4], Vec4::new(0.0, 0.0, -1.0, -NEAR)),
        "near {}",
        f.planes[4]
    );
    assert!(
        close(f.planes[5], Vec4::new(0.0, 0.0, 1.0, FAR)),
        "far {}",
        f.planes[5]
    );
    for p in f.planes {
        assert!((p.truncate().length() - 1.0).abs() < 1e-6);
    }
}

#[test]
fn boxes_just_inside_and_just_outside_each_plane() {
    let f = known_camera();
    // A point on each face of the frustum, in plane order.
    let on_face = [
        Vec3::new(-50.0, 0.0, -50.0),
        Vec3::new(50.0, 0.0, -50.0),
        Vec3::new(0.0, 50.0, -50.0),
        Vec3::new(0.0, -50.0, -50.0),
        Vec3::new(0.0, 0.0, -NEAR),
        Vec3::new(0.0, 0.0, -FAR),
    ];
    let extents = Vec3::new(0.5, 0.25, 0.125);
    for (i, (&p, plane)) in on_face.iter().zip(f.planes).enumerate() {
        let n = plane.truncate();
        let radius = extents.dot(n.abs());
        let gap = 0.01;
        let outside = p - n * (radius + gap);
        let inside = p - n * (radius - gap);
        assert!(
            f.aabb_outside(outside, extents),
            "plane {i}: box just outside was kept"
        );
        assert!(
            !f.aabb_outside(inside, extents),
            "plane {i}: box just inside was culled"
        );
    }
}

#[test]
fn zero_thickness_box() {
    let f = known_camera();
    let flat = Vec3::new(5.0, 0.0, 5.0);
    assert!(!f.aabb_outside(Vec3::new(0.0, 0.0, -20.0), flat));
    assert!(f.aabb_outside(Vec3::new(0.0, 0.0, 20.0), flat));
    assert!(!f.aabb_outside(Vec3::new(0.0, 0.0, -20.0), Vec3::ZERO));
    assert!(f.aabb_outside(Vec3::new(0.0, 0.0, -200.0), Vec3::ZERO));
}

#[test]
fn camera_looking_straight_down() {
    let eye = Vec3::new(10.0, 100.0, -20.0);
    let view = look_at(eye, Vec3::new(10.0, 0.0, -20.0), Vec3::Y);
    assert!(view.is_finite(), "{view}");
    let proj = perspective(60f32.to_radians(), 16.0 / 9.0, 0.5, 1000.0);
    let vp = proj * view;
    let centre = vp.project_point3(Vec3::new(10.0, 0.0, -20.0));
    assert!(
        centre.truncate().length() < 1e-5,
        "target projects to the centre: {centre}"
    );
    // Screen up is -z when looking down, and x stays to the right.
    let north = vp.project_point3(Vec3::new(10.0, 0.0, -30.0));
    let east = vp.project_point3(Vec3::new(20.0, 0.0, -20.0));
    assert!(
        north.y < 0.0,
        "-z is up on screen (Vulkan y is down): {north}"
    );
    assert!(east.x > 0.0, "+x is right: {east}");
    let f = Frustum::from_view_proj(vp);
    assert!(!f.aabb_outside(Vec3::new(10.0, 0.0, -20.0), Vec3::new(1.0, 0.0, 1.0)));
    assert!(
        f.aabb_outside(Vec3::new(10.0, 200.0, -20.0), Vec3::splat(1.0)),
        "above the eye"
    );
    assert!(
        f.aabb_outside(Vec3::new(500.0, 0.0, -20.0), Vec3::splat(1.0)),
        "far to the side"
    );
    // Looking straight up works too, and flips screen-up to +z.
    let up = look_at(Vec3::ZERO, Vec3::new(0.0, 5.0, 0.0), Vec3::Y);
    assert!(up.is_finite());
    let p = (proj * up).project_point3(Vec3::new(0.0, 10.0, 1.0));
    assert!(p.y < 0.0, "{p}");
}

#[test]
fn degenerate_look_at_stays_finite() {
    for (eye, target, up) in [
        (Vec3::ONE, Vec3::ONE, Vec3::Y),
        (Vec3::ZERO, Vec3::NEG_Z, Vec3::ZERO),
        (Vec3::ZERO, Vec3::new(0.0, -1e-30, 0.0), Vec3::Y),
        (Vec3::splat(f32::NAN), Vec3::ZERO, Vec3::Y),
    ] {
        assert!(look_at(eye, target, up).is_finite(), "{eye} -> {target}");
    }
}

#[test]
fn infinite_far_plane_culls_nothing_beyond() {
    let view = Mat4::IDENTITY;
    let proj = Mat4::perspective_infinite_rh(1.0, 1.0, 0.1);
    let f = Frustum::from_view_proj(proj * view);
    assert!(f.planes.iter().all(|p| p.is_finite()));
    assert!(!aabb_outside_frustum(
        Vec3::new(0.0, 0.0, -1e7),
        Vec3::ONE,
        &f.planes
    ));
}
