//! Generators of the default scene's assets: tileable layer textures (sand,
//! grass, dirt, rock, snow) made from periodic gradient noise, each with a
//! normal map and a height map taken from the same height field, and the
//! blend map that bakes a rules-mode material for one heightmap.
//! Deterministic: `vkterrain generate-textures` and `vkterrain
//! generate-blend-map` rebuild the committed files bit for bit.

use std::f64::consts::TAU;

use glam::{DVec2, DVec3};
use image::{GrayImage, Rgb, RgbImage, RgbaImage};
use rayon::prelude::*;

use crate::terrain::generate::periodic_noise;
use crate::terrain::shading::{blend_values, Rules, MAX_LAYERS};
use crate::terrain::TerrainInfo;

/// One generated layer: colour, tangent-space normals and heights.
pub struct LayerTextures {
    pub name: &'static str,
    pub diffuse: RgbImage,
    pub normal: RgbImage,
    pub height: GrayImage,
}

/// Periodic fractal noise over a texture of `size` texels: `cells` lattice
/// cells across the first octave, doubling per octave, so every octave
/// tiles.
fn fbm(seed: u64, u: f64, v: f64, cells: i64, octaves: u32) -> f64 {
    let (mut sum, mut amp, mut period) = (0.0, 0.5, cells);
    for o in 0..octaves {
        let f = period as f64;
        sum += amp * periodic_noise(seed.wrapping_add(u64::from(o)), u * f, v * f, period);
        period *= 2;
        amp *= 0.5;
    }
    sum
}

fn mix(a: [f64; 3], b: [f64; 3], t: f64) -> [f64; 3] {
    let t = t.clamp(0.0, 1.0);
    [0, 1, 2].map(|i| a[i] + (b[i] - a[i]) * t)
}

/// How one texture is made: its height field and its colour at a height.
struct Recipe {
    name: &'static str,
    /// Height in about [0, 1] at (u, v) in [0, 1)^2.
    height: fn(f64, f64) -> f64,
    /// Colour (sRGB, 0..1) at (u, v) with height h.
    color: fn(f64, f64, f64) -> [f64; 3],
    /// Normal-map strength: height units per texture width.
    bump: f64,
}

const RECIPES: [Recipe; 5] = [
    Recipe {
        name: "sand",
        height: |u, v| {
            // Wind ripples: whole waves across the tile, bent by noise.
            let bend = 0.35 * fbm(11, u, v, 4, 3);
            let ripple = (TAU * (9.0 * u + 3.0 * v + bend)).sin();
            0.5 + 0.25 * ripple + 0.25 * fbm(12, u, v, 32, 3)
        },
        color: |u, v, h| {
            let grain = fbm(13, u, v, 64, 2);
            mix([0.71, 0.62, 0.45], [0.84, 0.76, 0.58], h + 0.4 * grain)
        },
        bump: 3.0,
    },
    Recipe {
        name: "grass",
        height: |u, v| 0.5 + 0.5 * fbm(21, u, v, 64, 3) + 0.3 * fbm(22, u, v, 8, 3),
        color: |u, v, h| {
            let patch = 0.5 + fbm(23, u, v, 4, 4);
            let dry = mix([0.24, 0.34, 0.12], [0.40, 0.42, 0.20], patch);
            mix([0.12, 0.22, 0.07], dry, h)
        },
        bump: 4.0,
    },
    Recipe {
        name: "dirt",
        height: |u, v| {
            let pebbles = (fbm(31, u, v, 16, 2) * 3.0).max(0.0).powi(2);
            0.4 + 0.3 * fbm(32, u, v, 8, 4) + 0.4 * pebbles
        },
        color: |u, v, h| {
            let damp = 0.5 + fbm(33, u, v, 4, 3);
            mix(
                mix([0.26, 0.19, 0.13], [0.42, 0.33, 0.24], h),
                [0.30, 0.24, 0.19],
                0.5 * damp,
            )
        },
        bump: 6.0,
    },
    Recipe {
        name: "rock",
        height: |u, v| {
            // Ridged strata with cracks where the noise crosses zero.
            let layers = (TAU * (5.0 * v + 0.4 * fbm(41, u, v, 4, 3))).sin() * 0.5 + 0.5;
            let cracks = 1.0 - fbm(42, u, v, 8, 4).abs() * 2.5;
            0.35 * layers + 0.45 * cracks.clamp(0.0, 1.0) + 0.2 * fbm(43, u, v, 32, 3)
        },
        color: |u, v, h| {
            let tint = 0.5 + fbm(44, u, v, 4, 3);
            mix(
                mix([0.22, 0.21, 0.20], [0.52, 0.49, 0.45], h),
                [0.46, 0.38, 0.30],
                0.5 * tint,
            )
        },
        bump: 8.0,
    },
    Recipe {
        name: "snow",
        height: |u, v| 0.5 + 0.4 * fbm(51, u, v, 8, 4),
        color: |u, v, h| {
            let sparkle = fbm(52, u, v, 64, 1);
            mix([0.78, 0.82, 0.90], [0.97, 0.98, 1.0], h + 0.2 * sparkle)
        },
        bump: 2.0,
    },
];

fn to_u8(x: f64) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// The five default layers at `size` x `size` texels (tileable).
pub fn layer_textures(size: u32) -> Vec<LayerTextures> {
    RECIPES
        .par_iter()
        .map(|r| {
            let n = size as usize;
            let heights: Vec<f64> = (0..n * n)
                .into_par_iter()
                .map(|i| {
                    let (x, y) = (i % n, i / n);
                    (r.height)(x as f64 / n as f64, y as f64 / n as f64)
                })
                .collect();
            let at = |x: usize, y: usize| heights[(y % n) * n + (x % n)];
            let diffuse = RgbImage::from_fn(size, size, |x, y| {
                let (u, v) = (x as f64 / n as f64, y as f64 / n as f64);
                Rgb((r.color)(u, v, at(x as usize, y as usize)).map(to_u8))
            });
            // Central differences, wrapping: u right, v down the image.
            let normal = RgbImage::from_fn(size, size, |x, y| {
                let (x, y) = (x as usize, y as usize);
                let dhdu = (at(x + 1, y) - at(x + n - 1, y)) * 0.5 * n as f64;
                let dhdv = (at(x, y + 1) - at(x, y + n - 1)) * 0.5 * n as f64;
                let s = r.bump / n as f64;
                let nv = DVec3::new(-dhdu * s, -dhdv * s, 1.0).normalize();
                let e = (nv + 1.0) * 0.5;
                Rgb([to_u8(e.x), to_u8(e.y), to_u8(e.z)])
            });
            let height = GrayImage::from_fn(size, size, |x, y| {
                image::Luma([to_u8(at(x as usize, y as usize))])
            });
            LayerTextures {
                name: r.name,
                diffuse,
                normal,
                height,
            }
        })
        .collect()
}

/// Blend maps that reproduce `rules` (over `layers` layers) on `info`'s
/// terrain: one texel every `step` samples, weights from the height and
/// normal there, turned into the over-the-base values blend maps hold
/// (`blend_values`). One RGBA map per four layers above the base.
pub fn blend_maps_from_rules(
    info: &TerrainInfo,
    rules: &Rules,
    layers: usize,
    step: usize,
) -> Vec<RgbaImage> {
    let layers = layers.clamp(1, MAX_LAYERS);
    let step = step.max(1);
    let (w, h) = ((info.cols() - 1) / step + 1, (info.rows() - 1) / step + 1);
    let (lo, hi) = info.min_max();
    let span = (hi - lo).max(f32::MIN_POSITIVE);
    let texels: Vec<[f32; MAX_LAYERS - 1]> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (c, r) = ((i % w) * step, (i / w) * step);
            let p: DVec2 = info.sample_position(r, c);
            let height = (info.whole().get(r, c) - lo) / span;
            let n = info.normal_at(p.x, p.y);
            blend_values(&rules.weights(height, n.y), layers)
        })
        .collect();
    let maps = (layers - 1).div_ceil(4).max(1);
    (0..maps)
        .map(|m| {
            RgbaImage::from_fn(w as u32, h as u32, |x, y| {
                let t = &texels[y as usize * w + x as usize];
                image::Rgba([0, 1, 2, 3].map(|ch| {
                    let k = 4 * m + ch;
                    if k < MAX_LAYERS - 1 {
                        to_u8(f64::from(t[k]))
                    } else {
                        0
                    }
                }))
            })
        })
        .collect()
}
