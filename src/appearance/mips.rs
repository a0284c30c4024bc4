//! Mip chains, built on the CPU at load: each level halves the one before
//! with a triangle filter in linear space (sRGB colour is decoded first and
//! encoded again after), and normal maps are renormalised per level.

use image::imageops::{resize, FilterType};
use image::{DynamicImage, Rgba32FImage};

use super::texel::{Content, TexelFormat};

pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

pub fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

fn unorm8(x: f32) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Stores a linear level in `format`'s texels.
fn encode(format: TexelFormat, level: &Rgba32FImage) -> Vec<u8> {
    match format {
        TexelFormat::Srgba8 => level
            .pixels()
            .flat_map(|p| {
                let [r, g, b, a] = p.0;
                [
                    unorm8(linear_to_srgb(r)),
                    unorm8(linear_to_srgb(g)),
                    unorm8(linear_to_srgb(b)),
                    unorm8(a),
                ]
            })
            .collect(),
        TexelFormat::Rgba8 => level.pixels().flat_map(|p| p.0.map(unorm8)).collect(),
        TexelFormat::R8 => level.pixels().map(|p| unorm8(p.0[0])).collect(),
    }
}

/// Normal maps store xyz as (n + 1) / 2: averaging shortens the vectors, so
/// each level is made unit length again.
fn renormalise(level: &mut Rgba32FImage) {
    for p in level.pixels_mut() {
        let n = glam::Vec3::new(p.0[0], p.0[1], p.0[2]) * 2.0 - 1.0;
        let n = n.try_normalize().unwrap_or(glam::Vec3::Z);
        let e = (n + 1.0) * 0.5;
        p.0[..3].copy_from_slice(&e.to_array());
    }
}

/// `img` at `width` x `height`, then every level down to 1x1, each encoded
/// in `content`'s format.
pub fn chain(content: Content, img: &DynamicImage, width: u32, height: u32) -> Vec<Vec<u8>> {
    let format = content.format();
    let normals = content == Content::Normals;
    let mut level = to_linear(format, img);
    if level.dimensions() != (width, height) {
        level = resize(&level, width, height, FilterType::Triangle);
    }
    if normals {
        renormalise(&mut level);
    }
    let mut out = vec![encode(format, &level)];
    while level.width() > 1 || level.height() > 1 {
        let (w, h) = ((level.width() / 2).max(1), (level.height() / 2).max(1));
        level = resize(&level, w, h, FilterType::Triangle);
        if normals {
            renormalise(&mut level);
        }
        out.push(encode(format, &level));
    }
    out
}

/// An image as linear floats: sRGB decoded for colour, raw for data.
fn to_linear(format: TexelFormat, img: &DynamicImage) -> Rgba32FImage {
    let mut out = img.to_rgba32f();
    if format == TexelFormat::Srgba8 {
        for p in out.pixels_mut() {
            for c in &mut p.0[..3] {
                *c = srgb_to_linear(*c);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trips() {
        for i in 0..=255 {
            let c = i as f32 / 255.0;
            assert_eq!(unorm8(linear_to_srgb(srgb_to_linear(c))), i as u8);
        }
    }

    #[test]
    fn chains_halve_down_to_one_texel() {
        let img = DynamicImage::new_rgba8(12, 5);
        let c = chain(Content::Colour, &img, 12, 5);
        let sizes: Vec<usize> = c.iter().map(Vec::len).collect();
        assert_eq!(sizes, vec![12 * 5 * 4, 6 * 2 * 4, 3 * 4, 4]);
    }
}
