//! What the level choice knows of a frame's view: the eye, the projection's
//! scale, the frustum and the tolerance, travelling together.

use glam::{Vec2, Vec3};

use crate::terrain::camera::Frustum;

/// The error LOD's tolerance: how many pixels a level's error may cover on
/// screen. Finite and positive.
#[derive(Clone, Copy, Debug, PartialEq, PartialOrd)]
pub struct Tau(f32);

/// Why a tolerance is unusable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the pixel error must be a finite number of pixels above 0, got {0}")]
pub struct TauError(pub f32);

impl Tau {
    /// The tolerance when none is given: one pixel.
    pub const DEFAULT: Tau = Tau(1.0);
    /// The smallest tolerance accepted: any positive one, however small
    /// (below a few thousandths of a pixel only full resolution will do).
    pub const MIN_PX: f32 = f32::MIN_POSITIVE;

    pub fn new(px: f32) -> Result<Tau, TauError> {
        if px.is_finite() && px >= Self::MIN_PX {
            Ok(Tau(px))
        } else {
            Err(TauError(px))
        }
    }

    /// In pixels.
    pub fn px(self) -> f32 {
        self.0
    }
}

impl Default for Tau {
    fn default() -> Self {
        Tau::DEFAULT
    }
}

impl std::fmt::Display for Tau {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} px", self.0)
    }
}

impl std::str::FromStr for Tau {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let px: f32 = s
            .parse()
            .map_err(|_| format!("{s:?} is not a number of pixels"))?;
        Tau::new(px).map_err(|e| e.to_string())
    }
}

/// One frame's view, as the level choice sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LodView {
    /// The eye relative to the terrain's centre.
    pub eye_local: Vec3,
    /// Viewport height over 2 tan(fov / 2): a length L at distance d seen
    /// face-on covers L * pixels_per_radian / d pixels.
    pub pixels_per_radian: f32,
    /// The frustum's planes, eye-relative.
    pub frustum: Frustum,
    /// Width and height in pixels.
    pub viewport: Vec2,
    /// The error LOD's tolerance.
    pub tau: Tau,
}

impl LodView {
    /// Pixels a unit of length covers face-on at `distance`.
    pub fn scale(&self, distance: f32) -> f32 {
        self.pixels_per_radian / distance.max(f32::MIN_POSITIVE)
    }

    /// The viewport's pixels.
    pub fn viewport_pixels(&self) -> f64 {
        f64::from(self.viewport.x) * f64::from(self.viewport.y)
    }
}
