//! The look of a scene: material layers and how they are weighted, lights
//! and fog, as parsed from the scene file. Nothing is read here but the
//! file itself; `crate::appearance` loads the images these name.
//!
//! ```toml
//! [lighting]
//! ambient = [0.30, 0.33, 0.38]    # default [0.3, 0.3, 0.3]
//! lightmap = true                 # bake self-shadowing for the first light
//!
//! [[lighting.light]]              # 1 to 3; default: one sun
//! direction = [-0.5, 0.55, 0.45]  # towards the light
//! color = [1.0, 0.95, 0.86]       # default white
//! intensity = 1.0                 # default 1
//!
//! [fog]                           # optional
//! start = 3000.0                  # metres from the eye where fog begins
//! range = 12000.0                 # metres over which it thickens to full
//! color = [0.62, 0.71, 0.82]
//!
//! [material]
//! blend_maps = ["blend.png"]      # up to 2 RGBA maps; leave out for rules
//! cliff_layer = 2                 # rules mode: steep ground turns to this layer
//! cliff_slope = [30.0, 45.0]      # ... between these slopes, in degrees
//! anisotropy = 16                 # most filtering samples; default: 16 on
//!                                 # GPUs, off (1) on CPU rasterisers
//! triplanar = true                # project steep ground from the side too,
//!                                 # so cliffs don't stretch; default false
//!
//! [[material.layer]]              # 1 to 8; layer 0 is the base
//! diffuse = "grass.png"           # sRGB colour
//! normal = "grass-normal.png"     # optional tangent-space normal map
//! height = "grass-height.png"     # optional, for displacement
//! tile_size = 24.0                # metres per repeat, or [x, z]
//! tile_rotation = 0.0             # degrees
//! tile_offset = [0.0, 0.0]        # in repeats
//! displacement = 0.0              # metres between height-map values 0 and 1
//! height_band = [0.3, 0.25]       # rules mode: normalised centre, half-width
//! ```

use std::path::{Path, PathBuf};

use glam::{DVec3, Vec2, Vec3};
use serde::Deserialize;
use toml::Spanned;

use super::check::Checker;
use super::check::SceneFileError;
use crate::terrain::shading::{Cliff, HeightBand, MAX_LAYERS};

/// Most directional lights a scene may have.
pub const MAX_LIGHTS: usize = 3;
/// Most blend maps: each carries four layers' weights over the base.
pub const MAX_BLEND_MAPS: usize = 2;

/// An image a scene names: where it comes from, and where the scene named
/// it, for messages.
#[derive(Clone, Debug, PartialEq)]
pub struct Asset {
    pub source: AssetSource,
    /// The scene file and line that named it, and the key.
    pub scene: PathBuf,
    pub line: usize,
    pub key: String,
}

#[derive(Clone, Debug, PartialEq)]
pub enum AssetSource {
    File(PathBuf),
    /// Built into the binary (the default scene's assets).
    Embedded {
        name: &'static str,
        bytes: &'static [u8],
    },
}

impl Asset {
    /// "scene.toml:12: material.layer[1].diffuse" for messages.
    pub fn origin(&self) -> String {
        format!("{}:{}: {}", self.scene.display(), self.line, self.key)
    }

    pub fn display_path(&self) -> String {
        match &self.source {
            AssetSource::File(p) => p.display().to_string(),
            AssetSource::Embedded { name, .. } => format!("{name} (built in)"),
        }
    }
}

/// One directional light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectionalLight {
    /// Towards the light, unit length.
    pub direction: Vec3,
    /// Colour times intensity.
    pub radiance: Vec3,
}

/// Lights of a scene: 1 to 3 directional lights and an ambient term.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lighting {
    pub lights: [DirectionalLight; MAX_LIGHTS],
    pub light_count: usize,
    pub ambient: Vec3,
}

impl Default for Lighting {
    /// One white sun from the south-west at 0.7 and ambient 0.3, so flat
    /// ground facing the sun is lit at 1.
    fn default() -> Self {
        let sun = DirectionalLight {
            direction: Vec3::new(-0.4, 0.7, 0.45).normalize(),
            radiance: Vec3::splat(0.7),
        };
        Lighting {
            lights: [sun; MAX_LIGHTS],
            light_count: 1,
            ambient: Vec3::splat(0.3),
        }
    }
}

impl Lighting {
    pub fn active(&self) -> &[DirectionalLight] {
        &self.lights[..self.light_count]
    }
}

/// Distance fog: none before `start`, full at `start + range`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fog {
    pub start: f32,
    pub range: f32,
    pub color: Vec3,
}

/// A material layer.
#[derive(Clone, Debug, PartialEq)]
pub struct LayerSpec {
    pub diffuse: Asset,
    pub normal: Option<Asset>,
    pub height: Option<Asset>,
    /// World metres per repeat along the texture's u and v.
    pub tile_size: Vec2,
    pub tile_rotation_deg: f32,
    /// In repeats.
    pub tile_offset: Vec2,
    /// Metres between height-map values 0 and 1 (centred on 0.5).
    pub displacement: f32,
    /// Rules mode only.
    pub band: Option<HeightBand>,
}

/// Where layer weights come from.
#[derive(Clone, Debug, PartialEq)]
pub enum WeightSource {
    /// Blend maps stretched over the whole terrain.
    BlendMaps(Vec<Asset>),
    /// Height bands and slope.
    Rules { cliff: Option<Cliff> },
}

#[derive(Clone, Debug, PartialEq)]
pub struct MaterialSpec {
    pub layers: Vec<LayerSpec>,
    pub weights: WeightSource,
    /// Most anisotropic filtering samples (1: off); None: the device's
    /// default.
    pub anisotropy: Option<f32>,
    /// Project every layer's maps onto steep ground from the side as well
    /// as from above, blended by slope (see glsl/material.glsl).
    pub triplanar: bool,
}

impl MaterialSpec {
    /// Every asset, for embedding or listing.
    pub fn assets_mut(&mut self) -> impl Iterator<Item = &mut Asset> {
        let maps: Vec<&mut Asset> = match &mut self.weights {
            WeightSource::BlendMaps(maps) => maps.iter_mut().collect(),
            WeightSource::Rules { .. } => Vec::new(),
        };
        self.layers
            .iter_mut()
            .flat_map(|l| {
                std::iter::once(&mut l.diffuse)
                    .chain(l.normal.as_mut())
                    .chain(l.height.as_mut())
            })
            .chain(maps)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct LightingToml {
    ambient: Option<Spanned<[f32; 3]>>,
    #[serde(default)]
    lightmap: bool,
    light: Option<Spanned<Vec<LightToml>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LightToml {
    direction: Spanned<[f64; 3]>,
    color: Option<Spanned<[f32; 3]>>,
    intensity: Option<Spanned<f32>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct FogToml {
    start: Spanned<f32>,
    range: Spanned<f32>,
    color: Spanned<[f32; 3]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MaterialToml {
    blend_maps: Option<Spanned<Vec<Spanned<String>>>>,
    cliff_layer: Option<Spanned<usize>>,
    cliff_slope: Option<Spanned<[f32; 2]>>,
    anisotropy: Option<Spanned<f32>>,
    #[serde(default)]
    triplanar: bool,
    layer: Spanned<Vec<LayerToml>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LayerToml {
    diffuse: Spanned<String>,
    normal: Option<Spanned<String>>,
    height: Option<Spanned<String>>,
    tile_size: Option<Spanned<TileSize>>,
    tile_rotation: Option<Spanned<f32>>,
    tile_offset: Option<Spanned<[f32; 2]>>,
    displacement: Option<Spanned<f32>>,
    height_band: Option<Spanned<[f32; 2]>>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(untagged)]
enum TileSize {
    Uniform(f32),
    PerAxis([f32; 2]),
}

/// Colours are linear RGB, each component finite and non-negative.
fn color(check: &Checker, key: &str, v: &Spanned<[f32; 3]>) -> Result<Vec3, SceneFileError> {
    let c = Vec3::from(*v.get_ref());
    if c.is_finite() && c.min_element() >= 0.0 {
        Ok(c)
    } else {
        check.invalid(
            key,
            v.span(),
            format!("{c} must be finite and not negative"),
        )
    }
}

fn finite_f32(check: &Checker, key: &str, v: &Spanned<f32>) -> Result<f32, SceneFileError> {
    let x = *v.get_ref();
    if x.is_finite() {
        Ok(x)
    } else {
        check.invalid(key, v.span(), format!("{x} must be finite"))
    }
}

pub(super) fn parse_lighting(
    check: &Checker,
    t: Option<&LightingToml>,
) -> Result<(Lighting, bool), SceneFileError> {
    let mut lighting = Lighting::default();
    let Some(t) = t else {
        return Ok((lighting, false));
    };
    if let Some(a) = &t.ambient {
        lighting.ambient = color(check, "lighting.ambient", a)?;
    }
    let lights: &[LightToml] = t.light.as_ref().map_or(&[], |l| l.get_ref());
    if lights.len() > MAX_LIGHTS {
        return check.invalid(
            "lighting.light",
            t.light.as_ref().map_or(0..0, |l| l.span()),
            format!("{} lights, at most {MAX_LIGHTS}", lights.len()),
        );
    }
    if !lights.is_empty() {
        lighting.light_count = lights.len();
    }
    for (i, l) in lights.iter().enumerate() {
        let key = format!("lighting.light[{i}]");
        let d = DVec3::from(*l.direction.get_ref());
        let Some(direction) = d.is_finite().then(|| d.try_normalize()).flatten() else {
            return check.invalid(
                &format!("{key}.direction"),
                l.direction.span(),
                format!("{d} must be finite and not zero"),
            );
        };
        let c = match &l.color {
            Some(c) => color(check, &format!("{key}.color"), c)?,
            None => Vec3::ONE,
        };
        let intensity = match &l.intensity {
            None => 1.0,
            Some(v) => {
                let x = finite_f32(check, &format!("{key}.intensity"), v)?;
                if x < 0.0 {
                    return check.invalid(
                        &format!("{key}.intensity"),
                        v.span(),
                        format!("{x} must not be negative"),
                    );
                }
                x
            }
        };
        lighting.lights[i] = DirectionalLight {
            direction: direction.as_vec3(),
            radiance: c * intensity,
        };
    }
    Ok((lighting, t.lightmap))
}

pub(super) fn parse_fog(
    check: &Checker,
    t: Option<&FogToml>,
) -> Result<Option<Fog>, SceneFileError> {
    let Some(t) = t else {
        return Ok(None);
    };
    let start = finite_f32(check, "fog.start", &t.start)?;
    if start < 0.0 {
        return check.invalid(
            "fog.start",
            t.start.span(),
            format!("{start} must not be negative"),
        );
    }
    let range = finite_f32(check, "fog.range", &t.range)?;
    if range <= 0.0 {
        return check.invalid(
            "fog.range",
            t.range.span(),
            format!("{range} must be positive"),
        );
    }
    Ok(Some(Fog {
        start,
        range,
        color: color(check, "fog.color", &t.color)?,
    }))
}

pub(super) fn parse_material(
    check: &Checker,
    t: Option<&MaterialToml>,
    scene_dir: &Path,
) -> Result<Option<MaterialSpec>, SceneFileError> {
    let Some(t) = t else {
        return Ok(None);
    };
    let layers_toml = t.layer.get_ref();
    if layers_toml.is_empty() || layers_toml.len() > MAX_LAYERS {
        return check.invalid(
            "material.layer",
            t.layer.span(),
            format!(
                "{} layers; a material has 1 to {MAX_LAYERS}",
                layers_toml.len()
            ),
        );
    }
    let weights = match &t.blend_maps {
        Some(maps) => parse_blend_maps(check, t, maps, layers_toml.len(), scene_dir)?,
        None => WeightSource::Rules {
            cliff: parse_cliff(check, t, layers_toml.len())?,
        },
    };
    let rules = matches!(weights, WeightSource::Rules { .. });
    let layers = layers_toml
        .iter()
        .enumerate()
        .map(|(i, l)| parse_layer(check, i, l, rules, scene_dir))
        .collect::<Result<Vec<_>, _>>()?;
    let anisotropy = match &t.anisotropy {
        None => None,
        Some(v) => {
            let a = finite_f32(check, "material.anisotropy", v)?;
            if !(1.0..=64.0).contains(&a) {
                return check.invalid(
                    "material.anisotropy",
                    v.span(),
                    format!("{a} must be from 1 (off) to 64"),
                );
            }
            Some(a)
        }
    };
    Ok(Some(MaterialSpec {
        layers,
        weights,
        anisotropy,
        triplanar: t.triplanar,
    }))
}

/// A file named by the scene at `key`, relative to the scene's folder.
fn asset(check: &Checker, scene_dir: &Path, key: String, v: &Spanned<String>) -> Asset {
    let p = Path::new(v.get_ref());
    Asset {
        source: AssetSource::File(if p.is_absolute() {
            p.to_path_buf()
        } else {
            scene_dir.join(p)
        }),
        scene: check.path.to_path_buf(),
        line: super::check::line_of(check.text, v.span().start),
        key,
    }
}

/// Blend-map mode: 1 to MAX_BLEND_MAPS maps, enough for the layers, and
/// none of the rules-mode keys.
fn parse_blend_maps(
    check: &Checker,
    t: &MaterialToml,
    maps: &Spanned<Vec<Spanned<String>>>,
    layer_count: usize,
    scene_dir: &Path,
) -> Result<WeightSource, SceneFileError> {
    let list = maps.get_ref();
    if list.is_empty() || list.len() > MAX_BLEND_MAPS {
        return check.invalid(
            "material.blend_maps",
            maps.span(),
            format!("{} blend maps; give 1 or {MAX_BLEND_MAPS}", list.len()),
        );
    }
    // Each map's RGBA weighs four layers over the base.
    let carried = 1 + 4 * list.len();
    if layer_count > carried {
        return check.invalid(
            "material.blend_maps",
            maps.span(),
            format!(
                "{} blend map(s) weigh at most {carried} layers, but there are {layer_count}",
                list.len(),
            ),
        );
    }
    for (key, span) in [
        (
            "material.cliff_layer",
            t.cliff_layer.as_ref().map(|v| v.span()),
        ),
        (
            "material.cliff_slope",
            t.cliff_slope.as_ref().map(|v| v.span()),
        ),
    ] {
        if let Some(span) = span {
            return check.invalid(
                key,
                span,
                "is a rules-mode key, but the material has blend maps".into(),
            );
        }
    }
    Ok(WeightSource::BlendMaps(
        list.iter()
            .enumerate()
            .map(|(i, m)| asset(check, scene_dir, format!("material.blend_maps[{i}]"), m))
            .collect(),
    ))
}

/// Rules mode's cliff: a layer that exists, and a slope range (default 30
/// to 45 degrees) only with it.
fn parse_cliff(
    check: &Checker,
    t: &MaterialToml,
    layer_count: usize,
) -> Result<Option<Cliff>, SceneFileError> {
    let (l, s) = match (&t.cliff_layer, &t.cliff_slope) {
        (None, None) => return Ok(None),
        (None, Some(s)) => {
            return check.invalid(
                "material.cliff_slope",
                s.span(),
                "needs material.cliff_layer".into(),
            )
        }
        (Some(l), s) => (l, s),
    };
    let layer = *l.get_ref();
    if layer >= layer_count {
        return check.invalid(
            "material.cliff_layer",
            l.span(),
            format!("layer {layer} does not exist ({layer_count} layers)"),
        );
    }
    let slope_deg = match s {
        None => [30.0, 45.0],
        Some(s) => {
            let [a, b] = *s.get_ref();
            if !(a.is_finite() && b.is_finite() && 0.0 <= a && a <= b && b <= 90.0) {
                return check.invalid(
                    "material.cliff_slope",
                    s.span(),
                    format!("[{a}, {b}] must be increasing degrees in 0..=90"),
                );
            }
            [a, b]
        }
    };
    Ok(Some(Cliff { layer, slope_deg }))
}

/// Layer `i`: its maps, tiling, displacement (only with a height map) and
/// height band (rules mode only).
fn parse_layer(
    check: &Checker,
    i: usize,
    l: &LayerToml,
    rules: bool,
    scene_dir: &Path,
) -> Result<LayerSpec, SceneFileError> {
    let key = |k: &str| format!("material.layer[{i}].{k}");
    let tile_size = match &l.tile_size {
        None => Vec2::splat(16.0),
        Some(s) => {
            let v = match *s.get_ref() {
                TileSize::Uniform(x) => Vec2::splat(x),
                TileSize::PerAxis(xz) => Vec2::from(xz),
            };
            if !(v.is_finite() && v.min_element() > 0.0) {
                return check.invalid(
                    &key("tile_size"),
                    s.span(),
                    format!("{v} must be positive and finite"),
                );
            }
            v
        }
    };
    let tile_rotation_deg = match &l.tile_rotation {
        None => 0.0,
        Some(v) => finite_f32(check, &key("tile_rotation"), v)?,
    };
    let tile_offset = match &l.tile_offset {
        None => Vec2::ZERO,
        Some(v) => {
            let o = Vec2::from(*v.get_ref());
            if !o.is_finite() {
                return check.invalid(&key("tile_offset"), v.span(), format!("{o} must be finite"));
            }
            o
        }
    };
    let displacement = match &l.displacement {
        None => 0.0,
        Some(v) => {
            let d = finite_f32(check, &key("displacement"), v)?;
            if l.height.is_none() && d != 0.0 {
                return check.invalid(
                    &key("displacement"),
                    v.span(),
                    "needs a height map (height = ...)".into(),
                );
            }
            d
        }
    };
    let band = match &l.height_band {
        None => None,
        Some(v) if !rules => {
            return check.invalid(
                &key("height_band"),
                v.span(),
                "is a rules-mode key, but the material has blend maps".into(),
            )
        }
        Some(v) => {
            let [centre, half_width] = *v.get_ref();
            if !(centre.is_finite() && half_width.is_finite() && half_width > 0.0) {
                return check.invalid(
                    &key("height_band"),
                    v.span(),
                    format!(
                        "[{centre}, {half_width}] needs a finite centre and a positive half-width"
                    ),
                );
            }
            Some(HeightBand { centre, half_width })
        }
    };
    let file = |k: &str, v: &Spanned<String>| asset(check, scene_dir, key(k), v);
    Ok(LayerSpec {
        diffuse: file("diffuse", &l.diffuse),
        normal: l.normal.as_ref().map(|v| file("normal", v)),
        height: l.height.as_ref().map(|v| file("height", v)),
        tile_size,
        tile_rotation_deg,
        tile_offset,
        displacement,
        band,
    })
}
