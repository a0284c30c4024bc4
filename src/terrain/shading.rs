//! Material maths on the CPU: layer weights from height and slope rules,
//! the conversion between blend-map weights and per-layer weights, the
//! largest displacement a material can add, and the baked lightmap.
//!
//! `rule_weights` and `blend_map_weights` are mirrored in glsl/material.glsl
//! (`rule_weights`, `blend_weights`); tests/material_gpu.rs renders a scene
//! both ways and holds the two equal.

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::info::TerrainInfo;

/// Most layers a scene may have (the blend maps carry 7 weights over a base).
pub const MAX_LAYERS: usize = 8;

/// Per-layer weights, unused layers 0.
pub type LayerWeights = [f32; MAX_LAYERS];

/// A layer's height band in rules mode: full weight at `centre`, falling
/// linearly to 0 at `centre ± half_width`. Heights are normalised to the
/// terrain's range (0 lowest, 1 highest).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeightBand {
    pub centre: f32,
    pub half_width: f32,
}

/// Steep ground turns to one layer: none of it below `slope_deg[0]`, all
/// of it above `slope_deg[1]`, smoothstep between.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cliff {
    pub layer: usize,
    pub slope_deg: [f32; 2],
}

/// Weights from height bands and slope: the bands normalised to sum 1 (all
/// on layer 0 where no band reaches), then blended towards the cliff layer
/// by slope.
#[derive(Clone, Debug, PartialEq)]
pub struct Rules {
    pub bands: Vec<Option<HeightBand>>,
    pub cliff: Option<Cliff>,
}

fn saturate(x: f32) -> f32 {
    x.clamp(0.0, 1.0)
}

/// GLSL's smoothstep, with a zero-width edge as a step at `e1`.
fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    if e1 <= e0 {
        return if x >= e1 { 1.0 } else { 0.0 };
    }
    let t = saturate((x - e0) / (e1 - e0));
    t * t * (3.0 - 2.0 * t)
}

/// Slope in degrees of a surface with unit normal y component `normal_y`.
pub fn slope_deg(normal_y: f32) -> f32 {
    normal_y.clamp(-1.0, 1.0).acos().to_degrees()
}

impl Rules {
    /// Weights at normalised height `height` on ground of unit normal y
    /// component `normal_y`. Mirror: rule_weights in glsl/material.glsl.
    pub fn weights(&self, height: f32, normal_y: f32) -> LayerWeights {
        let mut w = [0.0; MAX_LAYERS];
        for (i, band) in self.bands.iter().enumerate().take(MAX_LAYERS) {
            if let Some(b) = band {
                let width = b.half_width.max(f32::MIN_POSITIVE);
                w[i] = saturate(1.0 - (height - b.centre).abs() / width);
            }
        }
        let sum: f32 = w.iter().sum();
        if sum > 0.0 {
            w.iter_mut().for_each(|x| *x /= sum);
        } else {
            w[0] = 1.0;
        }
        if let Some(c) = self.cliff {
            let s = smoothstep(c.slope_deg[0], c.slope_deg[1], slope_deg(normal_y));
            w.iter_mut().for_each(|x| *x *= 1.0 - s);
            w[c.layer] += s;
        }
        w
    }
}

/// Per-layer weights of blend-map values: layer 0 is the base and layer
/// k (1..count) is laid over the layers below it with opacity
/// `blend[k - 1]`, so layer k keeps `blend[k-1]` times what the layers
/// above it leave. The weights sum to 1. Mirror: blend_weights in
/// glsl/material.glsl.
pub fn blend_map_weights(blend: &[f32; MAX_LAYERS - 1], count: usize) -> LayerWeights {
    let mut w = [0.0; MAX_LAYERS];
    let mut left = 1.0;
    for k in (1..count.min(MAX_LAYERS)).rev() {
        let b = saturate(blend[k - 1]);
        w[k] = left * b;
        left *= 1.0 - b;
    }
    w[0] = left;
    w
}

/// The blend-map values that give `weights` (the inverse of
/// `blend_map_weights`), for baking rules into a blend map.
pub fn blend_values(weights: &LayerWeights, count: usize) -> [f32; MAX_LAYERS - 1] {
    let mut blend = [0.0; MAX_LAYERS - 1];
    let mut left = 1.0f32;
    for k in (1..count.min(MAX_LAYERS)).rev() {
        blend[k - 1] = if left > 1e-6 {
            saturate(weights[k] / left)
        } else {
            0.0
        };
        left = (left - weights[k]).max(0.0);
    }
    blend
}

/// The largest height a material's displacement can add or remove: each
/// layer displaces by `scale * (h - 0.5)` with h in [0, 1], and weights
/// sum to 1, so no point moves further than the largest half scale.
pub fn max_displacement(scales: &[f32]) -> f32 {
    scales.iter().map(|s| 0.5 * s.abs()).fold(0.0, f32::max)
}

/// Softness of the baked shadow edge: the sun's elevation is compared with
/// the horizon's over this many degrees either side.
pub const LIGHTMAP_SOFTNESS_DEG: f64 = 1.5;

/// The march towards the light takes steps of one cell up to this many
/// cells away, then steps of this fraction of the distance: far occluders
/// need a horizon angle, not every cell (a 1025^2 map bakes about 4x
/// faster).
pub const LIGHTMAP_FINE_STEPS: f64 = 24.0;

/// Sunlight visibility per sample (row-major, 0 shadowed .. 255 lit) for a
/// light in direction `to_light`: from each sample, march the heightmap
/// towards the light and find the highest horizon; the sample is lit when
/// the light stands above it, with a soft edge of `LIGHTMAP_SOFTNESS_DEG`.
/// Steps are one cell long for the first `LIGHTMAP_FINE_STEPS` cells, then
/// grow with the distance. The march stops at the terrain's border or once
/// even the highest sample could no longer block the light.
pub fn bake_lightmap(info: &TerrainInfo, to_light: DVec3) -> Vec<u8> {
    let (cols, rows) = (info.cols(), info.rows());
    let dir = to_light.try_normalize().unwrap_or(DVec3::Y);
    let horizontal = DVec2::new(dir.x, dir.z);
    let flat_len = horizontal.length();
    if flat_len < 1e-9 || dir.y <= -1.0 + 1e-9 {
        // Straight overhead (or below): no horizon to march.
        let value = if dir.y > 0.0 { 255 } else { 0 };
        return vec![value; cols * rows];
    }
    let sun = dir.y.atan2(flat_len).to_degrees();
    let soft = LIGHTMAP_SOFTNESS_DEG;
    let sp = info.spacing();
    let step_world = sp.x.min(sp.y);
    let unit = horizontal / flat_len;
    // Grid cells per world unit along the march; rows grow towards -z.
    let per_metre = DVec2::new(unit.x / sp.x, -unit.y / sp.y);
    let heightmap = info.whole();
    let (_, top) = heightmap.min_max();
    let top = f64::from(top);
    // The horizon can only matter while it could reach the light's upper
    // edge.
    let reach = (sun + soft).to_radians().tan().max(1e-6);
    let mut out = vec![0u8; cols * rows];
    out.par_chunks_mut(cols).enumerate().for_each(|(r, row)| {
        for (c, texel) in row.iter_mut().enumerate() {
            let h0 = f64::from(heightmap.get(r, c));
            let start = DVec2::new(c as f64, r as f64);
            let mut best = f64::NEG_INFINITY;
            let mut t = 0.0;
            loop {
                t += step_world.max(t / LIGHTMAP_FINE_STEPS);
                let p = start + per_metre * t;
                let outside =
                    p.x < 0.0 || p.y < 0.0 || p.x > (cols - 1) as f64 || p.y > (rows - 1) as f64;
                if outside || h0 + t * reach > top {
                    break;
                }
                best = best.max((heightmap.interpolate(p.x, p.y) - h0) / t);
            }
            let horizon = best.atan().to_degrees();
            let lit = if best == f64::NEG_INFINITY {
                1.0
            } else {
                let x = ((sun - horizon + soft) / (2.0 * soft)).clamp(0.0, 1.0);
                x * x * (3.0 - 2.0 * x)
            };
            *texel = (lit * 255.0).round() as u8;
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blend_values_invert_blend_map_weights() {
        let w = [0.1, 0.2, 0.3, 0.15, 0.25, 0.0, 0.0, 0.0];
        let b = blend_values(&w, 5);
        let back = blend_map_weights(&b, 5);
        for (a, b) in w.iter().zip(back) {
            assert!((a - b).abs() < 1e-6, "{w:?} -> {back:?}");
        }
    }

    #[test]
    fn smoothstep_handles_a_zero_width_edge() {
        assert_eq!(smoothstep(30.0, 30.0, 29.0), 0.0);
        assert_eq!(smoothstep(30.0, 30.0, 30.0), 1.0);
        assert_eq!(smoothstep(0.0, 1.0, 0.5), 0.5);
    }
}
