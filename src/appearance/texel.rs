//! What a texture's texels are: how they are stored and what they mean.

/// How texels are stored and what they mean.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TexelFormat {
    /// sRGB colour with alpha.
    Srgba8,
    /// Linear RGBA (normals, blend weights).
    Rgba8,
    /// One linear channel (heights, light).
    R8,
}

/// What a texture holds, which decides its format and how levels are made.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Content {
    /// sRGB colour.
    Colour,
    /// Tangent-space normals, renormalised on every level.
    Normals,
    /// Blend weights.
    Weights,
    /// Heights for displacement.
    Heights,
}

impl Content {
    pub fn format(self) -> TexelFormat {
        match self {
            Content::Colour => TexelFormat::Srgba8,
            Content::Normals | Content::Weights => TexelFormat::Rgba8,
            Content::Heights => TexelFormat::R8,
        }
    }
}
