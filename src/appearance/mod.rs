//! A scene's look, loaded: layer textures as 2D arrays with their mip
//! chains, blend maps, the per-layer parameters the shaders read, and the
//! baked lightmap. Only what the scene names is loaded. Pure Rust: the
//! renderer uploads what this builds.

pub mod generate;
mod mips;
mod texel;

use glam::{Mat2, Vec2};
use image::DynamicImage;

pub use mips::{linear_to_srgb, srgb_to_linear};
pub use texel::{Content, TexelFormat};

use crate::scene::{Asset, AssetSource, MaterialSpec, Scene, WeightSource};
use crate::terrain::shading::{bake_lightmap, Cliff, HeightBand};
use crate::terrain::TerrainInfo;

/// Largest side of a layer texture or blend map accepted.
pub const MAX_TEXTURE_SIDE: u32 = 8192;

/// Why a scene's look could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum MaterialError {
    #[error(
        "the scene's material layers and lightmap are made from the whole heightmap, which a \
         streamed terrain does not hold: draw it with --no-streaming"
    )]
    Streamed,
    #[error("{origin}: cannot read {path}: {message}")]
    Read {
        origin: String,
        path: String,
        message: String,
    },
    #[error("{origin}: {path} is {width}x{height}; textures may be at most {MAX_TEXTURE_SIDE} on a side")]
    TooLarge {
        origin: String,
        path: String,
        width: u32,
        height: u32,
    },
    #[error("{origin}: {path} is {width}x{height}, which does not fit the {cols}x{rows} heightmap: a blend map has one texel per sample or per 2^k cells ({expected})")]
    BlendMapSize {
        origin: String,
        path: String,
        width: u32,
        height: u32,
        cols: usize,
        rows: usize,
        expected: String,
    },
    #[error("{origin}: {path} has no {missing}, which {why}")]
    Channels {
        origin: String,
        path: String,
        missing: &'static str,
        why: String,
    },
    #[error("{origin}: {path} is {width}x{height}, but the first blend map is {first_width}x{first_height}")]
    BlendMapsDiffer {
        origin: String,
        path: String,
        width: u32,
        height: u32,
        first_width: u32,
        first_height: u32,
    },
}

/// Same-sized images as the layers of a 2D array, each with a full mip
/// chain (or one level).
#[derive(Clone, Debug, PartialEq)]
pub struct TextureArray {
    pub format: TexelFormat,
    pub width: u32,
    pub height: u32,
    pub layers: u32,
    /// Level i holds every layer in turn, each (width >> i) x (height >> i)
    /// (at least 1), rows top first.
    pub levels: Vec<Vec<u8>>,
}

impl TextureArray {
    pub fn level_extent(&self, level: usize) -> (u32, u32) {
        ((self.width >> level).max(1), (self.height >> level).max(1))
    }

    /// Builds an array from images of any size: each is resized to the
    /// largest width and height among them, then mipmapped.
    pub fn from_images(content: Content, images: &[DynamicImage]) -> Self {
        let width = images.iter().map(DynamicImage::width).max().unwrap_or(1);
        let height = images.iter().map(DynamicImage::height).max().unwrap_or(1);
        let chains: Vec<Vec<Vec<u8>>> = images
            .iter()
            .map(|img| mips::chain(content, img, width, height))
            .collect();
        let count = chains.first().map_or(1, Vec::len);
        let levels = (0..count)
            .map(|level| {
                chains
                    .iter()
                    .flat_map(|c| c[level].iter().copied())
                    .collect()
            })
            .collect();
        TextureArray {
            format: content.format(),
            width,
            height,
            layers: images.len() as u32,
            levels,
        }
    }
}

/// What the shaders read for one layer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LayerParams {
    /// World (x, z) to texture (u, v): rows of the matrix, then the offset.
    pub tile: Mat2,
    pub tile_offset: Vec2,
    pub displacement: f32,
    /// Layer of the normal-map array, if the layer has one.
    pub normal_index: Option<u32>,
    /// Layer of the height-map array, if the layer displaces with one.
    pub height_index: Option<u32>,
    pub band: Option<HeightBand>,
}

/// Material layers, loaded.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub layers: Vec<LayerParams>,
    pub diffuse: TextureArray,
    pub normals: Option<TextureArray>,
    pub heights: Option<TextureArray>,
    /// None: rules mode.
    pub blend_maps: Option<TextureArray>,
    pub cliff: Option<Cliff>,
    /// Most anisotropic filtering samples; None: the device's default
    /// (see `render::appearance::anisotropy_for`).
    pub anisotropy: Option<f32>,
    /// Steep ground projected from the side too (`MaterialSpec::triplanar`).
    pub triplanar: bool,
}

impl Material {
    /// The largest height displacement can add or remove.
    pub fn max_displacement(&self) -> f32 {
        crate::terrain::shading::max_displacement(
            &self
                .layers
                .iter()
                .filter(|l| l.height_index.is_some())
                .map(|l| l.displacement)
                .collect::<Vec<_>>(),
        )
    }

    /// True when the surface is displaced by some layer: only displacing
    /// layers' height maps are kept.
    pub fn displaces(&self) -> bool {
        self.heights.is_some()
    }
}

/// Everything a scene's look needs on the GPU, loaded.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Appearance {
    pub material: Option<Material>,
    /// Sun visibility per sample of the heightmap (one level, R8).
    pub lightmap: Option<TextureArray>,
}

impl Appearance {
    /// Loads the scene's textures and bakes its lightmap.
    pub fn load(scene: &Scene, info: &TerrainInfo) -> Result<Appearance, MaterialError> {
        if (scene.material.is_some() || scene.lightmap) && info.heightmap().is_none() {
            return Err(MaterialError::Streamed);
        }
        let material = scene
            .material
            .as_ref()
            .map(|m| load_material(m, info))
            .transpose()?;
        let lightmap = scene.lightmap.then(|| {
            let sun = scene.lighting.lights[0].direction.as_dvec3();
            TextureArray {
                format: TexelFormat::R8,
                width: info.cols() as u32,
                height: info.rows() as u32,
                layers: 1,
                levels: vec![cached_lightmap(crate::cache::dir().as_deref(), info, sun)],
            }
        });
        Ok(Appearance { material, lightmap })
    }

    /// The height Y bounds must grow by for culling to stay conservative.
    pub fn y_margin(&self) -> f32 {
        self.material
            .as_ref()
            .map_or(0.0, Material::max_displacement)
    }
}

/// `bake_lightmap(info, sun)`, from the cache in `dir` when an earlier
/// launch baked the same heights, spacing and sun (see `cache`).
pub fn cached_lightmap(
    dir: Option<&std::path::Path>,
    info: &TerrainInfo,
    sun: glam::DVec3,
) -> Vec<u8> {
    use crate::terrain::shading::{LIGHTMAP_FINE_STEPS, LIGHTMAP_SOFTNESS_DEG};
    let heights: &[u8] = bytemuck::cast_slice(info.whole().heights());
    let numbers = [
        info.spacing().x,
        info.spacing().y,
        sun.x,
        sun.y,
        sun.z,
        LIGHTMAP_SOFTNESS_DEG,
        LIGHTMAP_FINE_STEPS,
    ]
    .map(f64::to_bits);
    let key = crate::cache::key((heights, info.cols(), info.rows(), numbers));
    let len = info.cols() * info.rows();
    crate::cache::load_or_compute(dir, "lightmap", key, len, || bake_lightmap(info, sun))
}

/// Reads an asset as an image, refusing oversized ones before decoding.
pub fn read_image(asset: &Asset) -> Result<DynamicImage, MaterialError> {
    let fail = |message: String| MaterialError::Read {
        origin: asset.origin(),
        path: asset.display_path(),
        message,
    };
    let owned;
    let bytes: &[u8] = match &asset.source {
        AssetSource::File(path) => {
            owned = std::fs::read(path).map_err(|e| fail(e.to_string()))?;
            &owned
        }
        AssetSource::Embedded { bytes, .. } => bytes,
    };
    let reader = || {
        image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| fail(e.to_string()))
    };
    let (width, height) = reader()?
        .into_dimensions()
        .map_err(|e| fail(format!("not a readable image ({e})")))?;
    if width > MAX_TEXTURE_SIDE || height > MAX_TEXTURE_SIDE {
        return Err(MaterialError::TooLarge {
            origin: asset.origin(),
            path: asset.display_path(),
            width,
            height,
        });
    }
    reader()?
        .decode()
        .map_err(|e| fail(format!("not a readable image ({e})")))
}

/// Blend-map sizes that put a texel on every sample, or on every 2^k-th.
pub fn blend_map_sizes(cols: usize, rows: usize) -> Vec<(usize, usize)> {
    let mut sizes = Vec::new();
    let mut step = 1;
    while (cols - 1) % step == 0 && (rows - 1) % step == 0 && step <= cols.max(rows) {
        sizes.push(((cols - 1) / step + 1, (rows - 1) / step + 1));
        step *= 2;
    }
    sizes
}

fn missing_channels(asset: &Asset, missing: &'static str, why: &str) -> MaterialError {
    MaterialError::Channels {
        origin: asset.origin(),
        path: asset.display_path(),
        missing,
        why: why.to_string(),
    }
}

fn load_material(spec: &MaterialSpec, info: &TerrainInfo) -> Result<Material, MaterialError> {
    let mut diffuse = Vec::new();
    let mut normals = Vec::new();
    let mut heights = Vec::new();
    let mut layers = Vec::new();
    for l in &spec.layers {
        diffuse.push(read_image(&l.diffuse)?);
        let normal_index = match &l.normal {
            Some(a) => {
                let img = read_image(a)?;
                if !img.color().has_color() {
                    return Err(missing_channels(
                        a,
                        "colour channels",
                        "a normal map needs for x, y and z",
                    ));
                }
                normals.push(img);
                Some(normals.len() as u32 - 1)
            }
            None => None,
        };
        // A height map is read (so a bad one is reported) but kept only
        // when its layer displaces: with scale 0 it would add nothing.
        let height_index = match &l.height {
            Some(a) => {
                let img = read_image(a)?;
                (l.displacement != 0.0).then(|| {
                    heights.push(img);
                    heights.len() as u32 - 1
                })
            }
            None => None,
        };
        // Rows of world (x, z) -> (u, v): rotate, then scale to repeats.
        let rotation = Mat2::from_angle(-l.tile_rotation_deg.to_radians());
        let scale = Mat2::from_diagonal(1.0 / l.tile_size);
        layers.push(LayerParams {
            tile: scale * rotation,
            tile_offset: l.tile_offset,
            displacement: l.displacement,
            normal_index,
            height_index,
            band: l.band,
        });
    }
    let (blend_maps, cliff) = match &spec.weights {
        WeightSource::Rules { cliff } => (None, *cliff),
        WeightSource::BlendMaps(assets) => {
            let sizes = blend_map_sizes(info.cols(), info.rows());
            let mut maps = Vec::new();
            for (m, a) in assets.iter().enumerate() {
                let img = read_image(a)?;
                // Map m weighs layers 4m + 1 ..= 4m + 4; the last of them
                // comes from alpha, which an RGB image would read as 1.
                let alpha_layer = 4 * m + 4;
                if alpha_layer < spec.layers.len() && !img.color().has_alpha() {
                    let why = format!("weighs layer {alpha_layer}");
                    return Err(missing_channels(a, "alpha channel", &why));
                }
                if !img.color().has_color() {
                    let why = "weigh the layers above the base";
                    return Err(missing_channels(a, "colour channels", why));
                }
                let (w, h) = (img.width(), img.height());
                if !sizes.contains(&(w as usize, h as usize)) {
                    return Err(MaterialError::BlendMapSize {
                        origin: a.origin(),
                        path: a.display_path(),
                        width: w,
                        height: h,
                        cols: info.cols(),
                        rows: info.rows(),
                        expected: sizes
                            .iter()
                            .map(|(w, h)| format!("{w}x{h}"))
                            .collect::<Vec<_>>()
                            .join(", "),
                    });
                }
                if let Some(first) = maps.first() {
                    let first: &DynamicImage = first;
                    if (first.width(), first.height()) != (w, h) {
                        return Err(MaterialError::BlendMapsDiffer {
                            origin: a.origin(),
                            path: a.display_path(),
                            width: w,
                            height: h,
                            first_width: first.width(),
                            first_height: first.height(),
                        });
                    }
                }
                maps.push(img);
            }
            (
                Some(TextureArray::from_images(Content::Weights, &maps)),
                None,
            )
        }
    };
    let array = |content, images: &[DynamicImage]| {
        (!images.is_empty()).then(|| TextureArray::from_images(content, images))
    };
    Ok(Material {
        layers,
        diffuse: TextureArray::from_images(Content::Colour, &diffuse),
        normals: array(Content::Normals, &normals),
        heights: array(Content::Heights, &heights),
        blend_maps,
        cliff,
        anisotropy: spec.anisotropy,
        triplanar: spec.triplanar,
    })
}
