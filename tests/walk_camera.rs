//! Walking keeps the eye a fixed height above the terrain and on it, even
//! when pushed past the border.

mod common;

use common::*;
use glam::{DVec2, DVec3};
use vkterrain::app::camera::{CameraController, Mode, Movement};
use vkterrain::terrain::camera::Camera;

#[test]
fn walking_stays_on_the_terrain_at_eye_height() {
    let info = dem_info(32);
    let (hw, hd) = (info.world_width() / 2.0, info.world_depth() / 2.0);
    let start = Camera {
        eye: DVec3::new(hw - 100.0, 5000.0, 0.0),
        target: DVec3::new(hw + 1000.0, 5000.0, 0.0),
        fov_y_deg: 60.0,
    };
    let mut walker = CameraController::new(&start, 500.0);
    walker.eye_height = 1.8;
    walker.set_mode(Mode::Walk, &info);
    // Landed: at eye height above the ground, not at the flying height.
    let ground = f64::from(info.clamped_height_at(walker.eye.x, walker.eye.z));
    assert!((walker.eye.y - ground - 1.8).abs() < 1e-9);

    // Walk east, past the border, for 10 seconds.
    for _ in 0..100 {
        walker.update(
            0.1,
            Movement {
                forward: 1.0,
                ..Movement::default()
            },
            &info,
        );
        let ground = f64::from(info.clamped_height_at(walker.eye.x, walker.eye.z));
        assert!(walker.eye.x <= hw && walker.eye.x >= -hw, "{}", walker.eye);
        assert!(
            (walker.eye.y - ground - 1.8).abs() < 1e-9,
            "{} over {ground}",
            walker.eye
        );
    }
    assert_eq!(walker.eye.x, hw, "stopped at the east border");
    let border = f64::from(info.height_at(hw, walker.eye.z).unwrap());
    assert!((walker.eye.y - border - 1.8).abs() < 1e-9);

    // Facing +x, left is -z: sideways and fast into the (+x, -z) corner.
    for _ in 0..100 {
        walker.update(
            0.1,
            Movement {
                right: -1.0,
                fast: true,
                ..Movement::default()
            },
            &info,
        );
    }
    assert_eq!(
        DVec2::new(walker.eye.x, walker.eye.z),
        DVec2::new(hw, -hd),
        "pinned in the corner"
    );
    let corner = f64::from(info.whole().get(343, 402));
    assert!((walker.eye.y - corner - 1.8).abs() < 1e-9);

    // Flying again leaves the height alone and may leave the terrain.
    walker.set_mode(Mode::Fly, &info);
    walker.update(
        1.0,
        Movement {
            up: 1.0,
            ..Movement::default()
        },
        &info,
    );
    assert!((walker.eye.y - (corner + 1.8 + 500.0)).abs() < 1e-6);
}

#[test]
fn looking_is_clamped_short_of_straight_up_and_down() {
    let start = Camera {
        eye: DVec3::ZERO,
        target: DVec3::NEG_Z,
        fov_y_deg: 60.0,
    };
    let mut c = CameraController::new(&start, 1.0);
    assert!((c.direction() - DVec3::NEG_Z).length() < 1e-12);
    c.look(0.0, -1e6);
    assert!(c.direction().y < 1.0 && c.direction().y > 0.99);
    assert!(c.camera().relative_view().is_finite());
    c.look(0.0, 2e6);
    assert!(c.direction().y > -1.0 && c.direction().y < -0.99);
}
