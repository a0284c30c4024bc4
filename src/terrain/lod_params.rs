//! The LOD's parameters that a scene file sets and the level choice
//! reads: the distance formula's ranges and exponents, and how it measures
//! distance. The formulas themselves are in `crate::lod`.

use crate::shader_constants::MAX_TESS_EXPONENT;

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
    /// Distances in proportion to a terrain `extent` wide (its larger
    /// world side), for terrains whose scene names none: finest up to 2 %
    /// of it, coarsest from 75 % on, as the default scene's 150 to 6000 m
    /// are for its 8 km.
    pub fn for_extent(extent: f64) -> DistanceLod {
        let extent = if extent.is_finite() && extent > 0.0 {
            extent as f32
        } else {
            1.0
        };
        DistanceLod {
            min_dist: 0.02 * extent,
            max_dist: 0.75 * extent,
            ..DistanceLod::default()
        }
    }

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
