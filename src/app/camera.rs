//! The demo's camera: flying freely, or walking at a fixed height above the
//! terrain, which it can neither leave nor sink into.

use glam::{DVec2, DVec3};

use crate::terrain::camera::Camera;
use crate::terrain::TerrainInfo;

/// Pitch stops short of straight up or down, where yaw stops meaning anything.
const MAX_PITCH: f64 = 89.0 * std::f64::consts::PI / 180.0;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    Fly,
    Walk,
}

/// Movement asked for this frame, each axis in -1..=1.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Movement {
    pub forward: f64,
    pub right: f64,
    pub up: f64,
    pub fast: bool,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraController {
    pub eye: DVec3,
    /// Radians about +y; 0 looks down -z.
    pub yaw: f64,
    /// Radians above the horizon.
    pub pitch: f64,
    pub fov_y_deg: f32,
    pub mode: Mode,
    /// Eye height above the ground when walking.
    pub eye_height: f64,
    /// World units per second; the fast modifier multiplies it by 5.
    pub speed: f64,
    /// Radians per pixel of mouse motion.
    pub sensitivity: f64,
}

impl CameraController {
    pub fn new(camera: &Camera, speed: f64) -> Self {
        let dir = (camera.target - camera.eye).normalize_or(DVec3::NEG_Z);
        CameraController {
            eye: camera.eye,
            yaw: (-dir.x).atan2(-dir.z),
            pitch: dir.y.clamp(-1.0, 1.0).asin().clamp(-MAX_PITCH, MAX_PITCH),
            fov_y_deg: camera.fov_y_deg,
            mode: Mode::Fly,
            eye_height: 1.8,
            speed,
            sensitivity: 0.0025,
        }
    }

    pub fn direction(&self) -> DVec3 {
        DVec3::new(
            -self.yaw.sin() * self.pitch.cos(),
            self.pitch.sin(),
            -self.yaw.cos() * self.pitch.cos(),
        )
    }

    pub fn camera(&self) -> Camera {
        Camera {
            eye: self.eye,
            target: self.eye + self.direction(),
            fov_y_deg: self.fov_y_deg,
        }
    }

    /// Turns by a mouse motion in pixels.
    pub fn look(&mut self, dx: f64, dy: f64) {
        self.yaw -= dx * self.sensitivity;
        self.pitch = (self.pitch - dy * self.sensitivity).clamp(-MAX_PITCH, MAX_PITCH);
    }

    pub fn set_mode(&mut self, mode: Mode, terrain: &TerrainInfo) {
        self.mode = mode;
        if mode == Mode::Walk {
            self.stay_on(terrain);
        }
    }

    /// Moves for `dt` seconds. Flying follows the view direction; walking
    /// moves in the horizontal plane and then stands on the terrain.
    pub fn update(&mut self, dt: f64, movement: Movement, terrain: &TerrainInfo) {
        let step = self.speed * dt * if movement.fast { 5.0 } else { 1.0 };
        match self.mode {
            Mode::Fly => {
                let forward = self.direction();
                let right = forward.cross(DVec3::Y).normalize_or(DVec3::X);
                self.eye +=
                    (forward * movement.forward + right * movement.right + DVec3::Y * movement.up)
                        * step;
            }
            Mode::Walk => {
                let forward = DVec3::new(-self.yaw.sin(), 0.0, -self.yaw.cos());
                let right = DVec3::new(self.yaw.cos(), 0.0, -self.yaw.sin());
                self.eye += (forward * movement.forward + right * movement.right) * step;
                self.stay_on(terrain);
            }
        }
    }

    /// Clamps the eye to the terrain's rectangle and puts it `eye_height`
    /// above the surface there.
    fn stay_on(&mut self, terrain: &TerrainInfo) {
        let p = terrain.clamp_to_terrain(DVec2::new(self.eye.x, self.eye.z));
        let ground = f64::from(terrain.clamped_height_at(p.x, p.y));
        // A tile that could not be read (logged) leaves the eye's height.
        let y = if ground.is_nan() {
            self.eye.y
        } else {
            ground + self.eye_height
        };
        self.eye = DVec3::new(p.x, y, p.y);
    }
}
