//! Distance-driven tessellation factors: the Rust side of the formula the
//! tessellation control shader evaluates. The GLSL mirrors these functions
//! operation for operation, including how they treat degenerate input.
//!
//! Positions given to these functions are relative to the eye (the shader
//! works in camera-relative coordinates), so the eye is the origin.

use glam::Vec3;

pub use crate::shader_constants::{MAX_TESS_EXPONENT, MAX_TESS_FACTOR, MIN_TESS_FACTOR};

/// Parameters of the distance formula `2^lerp(max_exp, min_exp, s)`,
/// `s = saturate((d - min_dist) / (max_dist - min_dist))`: factor 2^max_exp
/// up to `min_dist` from the eye, falling to 2^min_exp at `max_dist`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DistanceLod {
    pub min_dist: f32,
    pub max_dist: f32,
    pub min_exp: f32,
    pub max_exp: f32,
}

impl Default for DistanceLod {
    fn default() -> Self {
        DistanceLod {
            min_dist: 20.0,
            max_dist: 500.0,
            min_exp: 0.0,
            max_exp: 6.0,
        }
    }
}

/// Why LOD parameters are unusable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LodError {
    #[error("LOD distances must be finite with 0 <= min <= max, got min {min}, max {max}")]
    Distance { min: f32, max: f32 },
    #[error("LOD exponents must satisfy 0 <= min <= max <= 6, got min {min}, max {max}")]
    Exponent { min: f32, max: f32 },
}

impl DistanceLod {
    /// Checks what a user may type; the factor functions stay finite even
    /// without this check.
    pub fn validate(&self) -> Result<(), LodError> {
        let (min, max) = (self.min_dist, self.max_dist);
        if !(min.is_finite() && max.is_finite() && min >= 0.0 && min <= max) {
            return Err(LodError::Distance { min, max });
        }
        let (min, max) = (self.min_exp, self.max_exp);
        if !(min >= 0.0 && min <= max && max <= MAX_TESS_EXPONENT) {
            return Err(LodError::Exponent { min, max });
        }
        Ok(())
    }
}

/// How the distance formula measures distance.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum DistanceMode {
    /// Euclidean distance, continuous exponent: smooth fractional factors.
    #[default]
    Smooth,
    /// Max-norm in the xz-plane and a rounded exponent: only the factors
    /// 1, 2, 4, ..., 64, constant in square rings around the eye, which makes
    /// the levels easy to see from above.
    Debug,
}

/// Clamp to [0, 1] with NaN going to 1 (the coarsest level), so a broken eye
/// position can never ask for maximum tessellation everywhere.
#[inline]
pub fn saturate(x: f32) -> f32 {
    if x < 1.0 {
        if x > 0.0 {
            x
        } else {
            0.0
        }
    } else {
        1.0
    }
}

/// Clamp to [1, 64] with NaN going to 1.
#[inline]
pub fn clamp_tess_factor(f: f32) -> f32 {
    if f > MIN_TESS_FACTOR {
        if f < MAX_TESS_FACTOR {
            f
        } else {
            MAX_TESS_FACTOR
        }
    } else {
        MIN_TESS_FACTOR
    }
}

/// Tessellation factor at `rel`, a position relative to the eye.
///
/// Degenerate input stays finite: `min_dist == max_dist` makes the formula a
/// step at that distance (the range is floored at the smallest positive
/// float, so `d == min_dist` still gets the finest level); a NaN or infinite
/// distance yields the coarsest level.
#[inline]
pub fn tess_factor(rel: Vec3, lod: &DistanceLod, mode: DistanceMode) -> f32 {
    let d = match mode {
        DistanceMode::Smooth => rel.length(),
        DistanceMode::Debug => rel.x.abs().max(rel.z.abs()),
    };
    let range = (lod.max_dist - lod.min_dist).max(f32::MIN_POSITIVE);
    let s = saturate((d - lod.min_dist) / range);
    // lerp(max_exp, min_exp, s) written as the shader's mix().
    let exponent = lod.max_exp + s * (lod.min_exp - lod.max_exp);
    let exponent = match mode {
        DistanceMode::Smooth => exponent,
        // floor(x + 0.5) rather than round(): GLSL leaves round()'s
        // behaviour at .5 to the implementation.
        DistanceMode::Debug => (exponent + 0.5).floor(),
    };
    clamp_tess_factor(exponent.exp2())
}

/// Tessellation factors of one quad patch.
///
/// Edge order follows the control point order (0 upper-left, 1 upper-right,
/// 2 lower-left, 3 lower-right): edge 0 is the left edge (0-2), 1 the top
/// (0-1), 2 the right (1-3), 3 the bottom (2-3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchTessFactors {
    pub edges: [f32; 4],
    pub inside: [f32; 2],
}

impl PatchTessFactors {
    pub const CULLED: PatchTessFactors = PatchTessFactors {
        edges: [0.0; 4],
        inside: [0.0; 2],
    };
}

/// Midpoint of an edge. `0.5 * (a + b)` is symmetric in a and b in floating
/// point too, so two patches sharing an edge compute the same midpoint
/// whichever way round they list its ends.
#[inline]
pub fn edge_midpoint(a: Vec3, b: Vec3) -> Vec3 {
    0.5 * (a + b)
}

/// Edge factors from the edge midpoints and the inside factors from the
/// patch centre. `corners` are eye-relative, in control point order.
pub fn patch_tess_factors(
    corners: [Vec3; 4],
    lod: &DistanceLod,
    mode: DistanceMode,
) -> PatchTessFactors {
    let [ul, ur, ll, lr] = corners;
    let edge = |a, b| tess_factor(edge_midpoint(a, b), lod, mode);
    let centre = 0.25 * (ul + ur + ll + lr);
    let inside = tess_factor(centre, lod, mode);
    PatchTessFactors {
        edges: [edge(ul, ll), edge(ul, ur), edge(ur, lr), edge(ll, lr)],
        inside: [inside, inside],
    }
}
