//! Scene files (TOML). Every error names the file, and where it can, the key
//! and the line.
//!
//! ```toml
//! [heightmap]
//! path = "../heightmaps/default.png"  # relative to the scene file
//! format = "png"                      # optional: raw8 raw16 raw16be png hgt f32
//! size = [403, 344]                   # optional, headerless formats
//! height_scale = 1400.0               # default 1
//! height_offset = 0.0                 # default 0
//! cell_spacing = 8.0                  # or [dx, dz]; default 1
//! origin = [0.0, 0.0]                 # world x, z of the centre
//! smooth = false
//! luminance = false
//! max_samples = 134217728
//!
//! [terrain]
//! cells_per_patch = 32
//!
//! [lod]                               # no keys: the error LOD at 1 px
//!                                     # (the distance LOD if layers displace)
//! pixel_error = 1.0                   # the error LOD, at most this many pixels
//! min_distance = 150.0                # the distance LOD (the default when these
//!                                     # are given without pixel_error)
//! max_distance = 6000.0
//! min_level = 0.0                     # exponents: factors 2^min_level..2^max_level
//! max_level = 6.0
//!
//! [camera]                            # optional: an overview when left out
//! eye = [-2300.0, 1750.0, -4300.0]
//! target = [300.0, 350.0, 400.0]
//! fov = 55.0
//! ```

use std::path::Path;

use glam::{DVec2, DVec3};
use serde::Deserialize;
use toml::Spanned;

use super::check::{Checker, SceneFileError};

use super::look::{parse_fog, parse_lighting, parse_material, FogToml, LightingToml, MaterialToml};
use super::{HeightmapSource, Scene};
use crate::terrain::camera::Camera;
use crate::terrain::grid::validate_cells_per_patch;
use crate::terrain::heightmap::DEFAULT_MAX_SAMPLES;
use crate::terrain::{DistanceLod, HeightmapFormat, LoadOptions, DEFAULT_CELLS_PER_PATCH};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneToml {
    heightmap: HeightmapToml,
    #[serde(default)]
    terrain: TerrainToml,
    #[serde(default)]
    lod: LodToml,
    camera: Option<CameraToml>,
    lighting: Option<LightingToml>,
    fog: Option<FogToml>,
    material: Option<MaterialToml>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct HeightmapToml {
    path: Spanned<String>,
    format: Option<Spanned<String>>,
    size: Option<Spanned<[u64; 2]>>,
    height_scale: Option<Spanned<f64>>,
    height_offset: Option<Spanned<f64>>,
    cell_spacing: Option<Spanned<Spacing>>,
    origin: Option<Spanned<[f64; 2]>>,
    #[serde(default)]
    smooth: bool,
    #[serde(default)]
    luminance: bool,
    max_samples: Option<u64>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(untagged)]
enum Spacing {
    Uniform(f64),
    PerAxis([f64; 2]),
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct TerrainToml {
    cells_per_patch: Option<Spanned<u32>>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct LodToml {
    pixel_error: Option<Spanned<f32>>,
    min_distance: Option<Spanned<f32>>,
    max_distance: Option<Spanned<f32>>,
    min_level: Option<Spanned<f32>>,
    max_level: Option<Spanned<f32>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraToml {
    eye: Spanned<[f64; 3]>,
    target: Spanned<[f64; 3]>,
    fov: Option<Spanned<f32>>,
}

impl Scene {
    /// Reads a scene file; the heightmap path is taken relative to it.
    pub fn load(path: &Path) -> Result<Scene, SceneFileError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneFileError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Scene::from_toml(&text, path)
    }

    /// Parses scene text; `path` names it in errors and anchors relative
    /// heightmap paths. The heightmap itself is not read here.
    pub fn from_toml(text: &str, path: &Path) -> Result<Scene, SceneFileError> {
        let parsed: SceneToml = toml::from_str(text).map_err(|e| SceneFileError::Parse {
            path: path.to_path_buf(),
            message: e.to_string().trim_end().to_string(),
        })?;
        let check = Checker { path, text };
        let h = &parsed.heightmap;

        let format = match &h.format {
            None => None,
            Some(f) => match f.get_ref().parse::<HeightmapFormat>() {
                Ok(format) => Some(format),
                Err(e) => return check.invalid("heightmap.format", f.span(), e.to_string()),
            },
        };
        let size = h.size.as_ref().map(|s| (s.get_ref()[0], s.get_ref()[1]));
        let scalar = |key: &'static str, v: &Option<Spanned<f64>>, default: f64| match v {
            None => Ok(default),
            Some(s) if s.get_ref().is_finite() => Ok(*s.get_ref()),
            Some(s) => check.invalid(key, s.span(), format!("{} must be finite", s.get_ref())),
        };
        let height_scale = scalar("heightmap.height_scale", &h.height_scale, 1.0)?;
        let height_offset = scalar("heightmap.height_offset", &h.height_offset, 0.0)?;
        let cell_spacing = match &h.cell_spacing {
            None => DVec2::ONE,
            Some(s) => {
                let v = match *s.get_ref() {
                    Spacing::Uniform(d) => DVec2::splat(d),
                    Spacing::PerAxis([x, z]) => DVec2::new(x, z),
                };
                if !(v.x > 0.0 && v.y > 0.0 && v.is_finite()) {
                    return check.invalid(
                        "heightmap.cell_spacing",
                        s.span(),
                        format!("{v} must be positive and finite"),
                    );
                }
                v
            }
        };
        let origin = match &h.origin {
            None => DVec2::ZERO,
            Some(o) => DVec2::from(check.finite("heightmap.origin", o)?),
        };
        let heightmap_path = Path::new(h.path.get_ref());
        let resolved = if heightmap_path.is_absolute() {
            heightmap_path.to_path_buf()
        } else {
            path.parent().unwrap_or(Path::new(".")).join(heightmap_path)
        };

        let cells_per_patch = match &parsed.terrain.cells_per_patch {
            None => DEFAULT_CELLS_PER_PATCH,
            Some(n) => match validate_cells_per_patch(*n.get_ref()) {
                Ok(()) => *n.get_ref(),
                Err(e) => return check.invalid("terrain.cells_per_patch", n.span(), e.to_string()),
            },
        };

        let (lod, pixel_error) = parse_lod(&check, &parsed.lod)?;
        let camera = parse_camera(&check, parsed.camera.as_ref())?;

        let (lighting, lightmap) = parse_lighting(&check, parsed.lighting.as_ref())?;
        let fog = parse_fog(&check, parsed.fog.as_ref())?;
        let scene_dir = path.parent().unwrap_or(Path::new("."));
        let material = parse_material(&check, parsed.material.as_ref(), scene_dir)?;
        // The error table bounds the heightmap's surface, not what material
        // layers displace it by: such a scene keeps the distance LOD unless
        // it asks for the error LOD.
        let displaces = material
            .as_ref()
            .is_some_and(|m| m.layers.iter().any(|l| l.displacement != 0.0));
        let pixel_error = if displaces && parsed.lod.pixel_error.is_none() {
            None
        } else {
            pixel_error
        };

        Ok(Scene {
            heightmap: HeightmapSource::File(resolved),
            load: LoadOptions {
                format,
                size,
                height_scale,
                height_offset,
                smooth: h.smooth,
                luminance: h.luminance,
                max_samples: h.max_samples.unwrap_or(DEFAULT_MAX_SAMPLES),
            },
            cell_spacing,
            origin,
            cells_per_patch,
            lod,
            pixel_error,
            camera,
            lighting,
            lightmap,
            fog,
            material,
        })
    }
}

/// The `[lod]` table: distances (when any is given) and the error LOD's
/// pixel error (by default 1 px, unless distances are given).
fn parse_lod(
    check: &Checker,
    l: &LodToml,
) -> Result<(Option<DistanceLod>, Option<f32>), SceneFileError> {
    let defaults = DistanceLod::default();
    let pick = |v: &Option<Spanned<f32>>, d: f32| v.as_ref().map_or(d, |s| *s.get_ref());
    let lod = DistanceLod {
        min_dist: pick(&l.min_distance, defaults.min_dist),
        max_dist: pick(&l.max_distance, defaults.max_dist),
        min_exp: pick(&l.min_level, defaults.min_exp),
        max_exp: pick(&l.max_level, defaults.max_exp),
    };
    let given = [&l.min_distance, &l.max_distance, &l.min_level, &l.max_level];
    if let Err(e) = lod.validate() {
        // Point at the first LOD key given, or the table if none was.
        let span = given
            .iter()
            .find_map(|v| v.as_ref().map(|s| s.span()))
            .unwrap_or(0..0);
        return check.invalid("lod", span, e.to_string());
    }
    let distances = given.iter().any(|v| v.is_some());
    let pixel_error = match &l.pixel_error {
        Some(px) if !(px.get_ref().is_finite() && *px.get_ref() > 0.0) => {
            return check.invalid(
                "lod.pixel_error",
                px.span(),
                format!("must be a positive number of pixels, got {}", px.get_ref()),
            );
        }
        Some(px) => Some(*px.get_ref()),
        None if distances => None,
        None => Some(super::DEFAULT_PIXEL_ERROR),
    };
    Ok((distances.then_some(lod), pixel_error))
}

/// The `[camera]` table: finite eye and target apart, a field of view
/// strictly between 0 and 180 degrees.
fn parse_camera(check: &Checker, c: Option<&CameraToml>) -> Result<Option<Camera>, SceneFileError> {
    let Some(c) = c else {
        return Ok(None);
    };
    let eye = DVec3::from(check.finite("camera.eye", &c.eye)?);
    let target = DVec3::from(check.finite("camera.target", &c.target)?);
    if eye == target {
        return check.invalid(
            "camera.target",
            c.target.span(),
            "equals the eye position".into(),
        );
    }
    let fov = match &c.fov {
        None => super::DEFAULT_FOV_DEG,
        Some(f) if *f.get_ref() > 0.0 && *f.get_ref() < 180.0 => *f.get_ref(),
        Some(f) => {
            return check.invalid(
                "camera.fov",
                f.span(),
                format!("{} must be between 0 and 180 degrees", f.get_ref()),
            )
        }
    };
    Ok(Some(Camera {
        eye,
        target,
        fov_y_deg: fov,
    }))
}
