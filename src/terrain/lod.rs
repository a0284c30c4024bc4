//! Distance-driven tessellation factors: the Rust side of the formula the
//! tessellation control shader evaluates. The GLSL mirrors these functions
//! operation for operation, including how they treat degenerate input.
//!
//! Positions given to these functions are relative to the eye (the shader
//! works in camera-relative coordinates), so the eye is the origin.

use glam::{Vec2, Vec3};

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

/// Error-bounded tessellation factor (the tess path's `--lod error`).
///
/// `errors[k]` is the largest geometric error of tessellating with 2^k
/// segments (the error table's levels, non-increasing in k). At `distance`
/// an error e covers e * pixels_per_radian / distance pixels. The factor is
/// the smallest level whose projected error is at most `pixel_error`,
/// interpolated in log space between it and the level before, so it moves
/// continuously with distance: exactly 2^k where level k's error projects
/// to `pixel_error`. Finite in [1, 64] for any input.
pub fn error_tess_factor(
    errors: &[f32; 7],
    distance: f32,
    pixels_per_radian: f32,
    pixel_error: f32,
) -> f32 {
    let scale = pixels_per_radian / distance.max(f32::MIN_POSITIVE);
    if scale.is_nan() {
        return MIN_TESS_FACTOR;
    }
    let tau = pixel_error.max(f32::MIN_POSITIVE);
    let projected = |k: usize| errors[k] * scale;
    let mut factor = MAX_TESS_FACTOR;
    for k in 0..7 {
        if projected(k) <= tau {
            factor = if k == 0 {
                MIN_TESS_FACTOR
            } else {
                let (coarse, fine) = (projected(k - 1), projected(k));
                // Fraction of the way from level k-1 (error coarse > tau) to
                // level k (error fine <= tau), in log space.
                let t = if fine > 0.0 {
                    saturate((coarse.ln() - tau.ln()) / (coarse.ln() - fine.ln()))
                } else {
                    saturate((coarse - tau) / coarse)
                };
                ((k - 1) as f32 + t).exp2()
            };
            break;
        }
    }
    clamp_tess_factor(factor)
}

/// Per-level errors of an edge shared by two patches: the larger of each.
pub fn shared_edge_errors(a: &[f32; 7], b: Option<&[f32; 7]>) -> [f32; 7] {
    match b {
        Some(b) => std::array::from_fn(|k| a[k].max(b[k])),
        None => *a,
    }
}

/// Distance from the eye (the origin: points are eye-relative) to the box
/// `[lo, hi]`; 0 inside it.
pub fn box_distance(lo: Vec3, hi: Vec3) -> f32 {
    lo.max(-hi).max(Vec3::ZERO).length()
}

/// Distance from the eye (the origin) to the vertical strip standing on the
/// segment `a`-`b` (eye-relative x, z) between heights `y_lo` and `y_hi`
/// (eye-relative). A degenerate segment is its point.
pub fn edge_distance(a: Vec2, b: Vec2, y_lo: f32, y_hi: f32) -> f32 {
    let ab = b - a;
    let len2 = ab.dot(ab);
    let t = if len2 > 0.0 {
        (-a.dot(ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let p = a + t * ab;
    let dy = y_lo.max(-y_hi).max(0.0);
    (p.dot(p) + dy * dy).sqrt()
}

/// Error-bounded factors of one patch: each edge from the errors it shares
/// with the neighbour across it (left, top, right, bottom; None at the
/// terrain's border), the inside from the patch's own errors. Each is
/// projected from the nearest point that can carry it, so no part of the
/// patch is nearer than the distance its factor assumes:
/// - an edge from the strip standing on it between the terrain's lowest and
///   highest heights (`height_range`), which both patches sharing it know
///   alike, so they agree on its factor;
/// - the inside from the patch's box: its corners' x and z, `bounds_y`.
///
/// `corners` and both height pairs are eye-relative.
pub fn patch_error_factors(
    corners: [Vec3; 4],
    bounds_y: [f32; 2],
    height_range: [f32; 2],
    own: &[f32; 7],
    neighbours: [Option<&[f32; 7]>; 4],
    pixels_per_radian: f32,
    pixel_error: f32,
) -> PatchTessFactors {
    let [ul, ur, ll, lr] = corners;
    let xz = |v: Vec3| Vec2::new(v.x, v.z);
    let ends = [(ul, ll), (ul, ur), (ur, lr), (ll, lr)];
    let edges = std::array::from_fn(|i| {
        let errors = shared_edge_errors(own, neighbours[i]);
        let (a, b) = ends[i];
        let d = edge_distance(xz(a), xz(b), height_range[0], height_range[1]);
        error_tess_factor(&errors, d, pixels_per_radian, pixel_error)
    });
    // Lower-left has the smallest x and z, upper-right the largest.
    let lo = Vec3::new(ll.x, bounds_y[0], ll.z);
    let hi = Vec3::new(ur.x, bounds_y[1], ur.z);
    let inside = error_tess_factor(own, box_distance(lo, hi), pixels_per_radian, pixel_error);
    PatchTessFactors {
        edges,
        inside: [inside, inside],
    }
}
