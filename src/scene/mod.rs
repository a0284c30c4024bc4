//! What to load: a heightmap and its placement, the patch size, LOD
//! parameters and a starting camera, from a TOML scene file (see `file`).
//! The default scene, `assets/scenes/default.toml` and its heightmap, is
//! built into the binary, so the run command works from any directory.

mod check;
mod file;
pub mod look;

use std::path::{Path, PathBuf};

use glam::{DVec2, DVec3};

pub use check::SceneFileError;
pub use look::{
    Asset, AssetSource, DirectionalLight, Fog, LayerSpec, Lighting, MaterialSpec, WeightSource,
    MAX_LIGHTS,
};

use crate::terrain::camera::Camera;
use crate::terrain::tiled::TiledHeightmap;
use crate::terrain::{
    DistanceLod, Heightmap, HeightmapError, HeightmapFormat, LoadOptions, Placement, TerrainError,
    TerrainInfo,
};

/// The default scene file.
pub const DEFAULT_SCENE_TOML: &str = include_str!("../../assets/scenes/default.toml");
/// The default heightmap: 1025x1025, 16-bit, made by `vkterrain generate`
/// with its default parameters (see assets/README.md).
pub const DEFAULT_HEIGHTMAP_PNG: &[u8] = include_bytes!("../../assets/heightmaps/default.png");
/// The default scene's textures and blend map, built in like its heightmap
/// (paths relative to assets/).
pub const DEFAULT_SCENE_ASSETS: &[(&str, &[u8])] = &[
    (
        "textures/grass.png",
        include_bytes!("../../assets/textures/grass.png"),
    ),
    (
        "textures/grass-normal.png",
        include_bytes!("../../assets/textures/grass-normal.png"),
    ),
    (
        "textures/dirt.png",
        include_bytes!("../../assets/textures/dirt.png"),
    ),
    (
        "textures/dirt-normal.png",
        include_bytes!("../../assets/textures/dirt-normal.png"),
    ),
    (
        "textures/rock.png",
        include_bytes!("../../assets/textures/rock.png"),
    ),
    (
        "textures/rock-normal.png",
        include_bytes!("../../assets/textures/rock-normal.png"),
    ),
    (
        "textures/snow.png",
        include_bytes!("../../assets/textures/snow.png"),
    ),
    (
        "textures/snow-normal.png",
        include_bytes!("../../assets/textures/snow-normal.png"),
    ),
    (
        "textures/sand.png",
        include_bytes!("../../assets/textures/sand.png"),
    ),
    (
        "textures/sand-normal.png",
        include_bytes!("../../assets/textures/sand-normal.png"),
    ),
    (
        "textures/default-blend.png",
        include_bytes!("../../assets/textures/default-blend.png"),
    ),
];

/// Vertical field of view when a scene gives none.
pub const DEFAULT_FOV_DEG: f32 = 55.0;

/// The error LOD's tolerance in pixels where neither the command line nor
/// the scene gives one: a scene with no `[lod]`, or a bare heightmap.
pub const DEFAULT_PIXEL_ERROR: f32 = 1.0;

/// Where a scene's heights come from.
#[derive(Clone, Debug, PartialEq)]
pub enum HeightmapSource {
    /// Bytes built into the binary; `name` stands in for a path in messages.
    Embedded {
        name: &'static str,
        bytes: &'static [u8],
        format: HeightmapFormat,
    },
    File(PathBuf),
}

#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub heightmap: HeightmapSource,
    pub load: LoadOptions,
    /// (dx, dz) in world units.
    pub cell_spacing: DVec2,
    /// World (x, z) of the terrain's centre.
    pub origin: DVec2,
    pub cells_per_patch: u32,
    /// The distance LOD's parameters; None: in proportion to the terrain
    /// (`DistanceLod::for_extent`, see `distance_lod`).
    pub lod: Option<DistanceLod>,
    /// The LOD drawn unless told otherwise: the error LOD at this many
    /// pixels, or with None the distance LOD. A scene that names no LOD
    /// gets the error LOD at 1 px.
    pub pixel_error: Option<f32>,
    /// None: an overview of the whole terrain (`camera_for`).
    pub camera: Option<Camera>,
    pub lighting: Lighting,
    /// Bake a self-shadowing lightmap for the first light.
    pub lightmap: bool,
    pub fog: Option<Fog>,
    /// None: colours by height.
    pub material: Option<MaterialSpec>,
}

/// Why a scene's terrain could not be built.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error(transparent)]
    Heightmap(#[from] HeightmapError),
    #[error(transparent)]
    Terrain(#[from] TerrainError),
    #[error(transparent)]
    File(#[from] SceneFileError),
    #[error(
        "{}: streaming needs the error tables and Y bounds of {wanted}-cell patches, and the \
         file stores {}: re-import it with --cells-per-patch {wanted}, use that patch size, or \
         draw it whole with --no-streaming",
        path.display(),
        stored.map_or("none".to_string(), |n| format!("those of {n}-cell patches"))
    )]
    StreamedPatchSize {
        path: std::path::PathBuf,
        stored: Option<u32>,
        wanted: u32,
    },
}

impl Scene {
    /// The built-in default scene: its file and heightmap are embedded.
    pub fn default_scene() -> Scene {
        let mut scene =
            Scene::from_toml(DEFAULT_SCENE_TOML, Path::new("assets/scenes/default.toml"))
                .expect("the built-in scene file is valid");
        scene.heightmap = HeightmapSource::Embedded {
            name: "assets/heightmaps/default.png (built in)",
            bytes: DEFAULT_HEIGHTMAP_PNG,
            format: HeightmapFormat::Png,
        };
        if let Some(material) = &mut scene.material {
            for asset in material.assets_mut() {
                let AssetSource::File(path) = &asset.source else {
                    continue;
                };
                let (name, bytes) = DEFAULT_SCENE_ASSETS
                    .iter()
                    .find(|(name, _)| path.ends_with(name))
                    .expect("every asset of the built-in scene is built in");
                asset.source = AssetSource::Embedded { name, bytes };
            }
        }
        scene
    }

    /// The scene's camera, or one that overlooks the whole terrain from
    /// beyond its south-west corner (-x, -z), high enough to see the far edge.
    pub fn camera_for(&self, info: &TerrainInfo) -> Camera {
        if let Some(camera) = self.camera {
            return camera;
        }
        let (lo, hi) = info.min_max();
        let (w, d) = (info.world_width(), info.world_depth());
        let size = w.max(d);
        let o = info.origin();
        let mid = 0.5 * f64::from(lo + hi);
        Camera {
            eye: DVec3::new(o.x - 0.3 * w, f64::from(hi) + 0.3 * size, o.y - 0.75 * d),
            target: DVec3::new(o.x, mid, o.y + 0.1 * d),
            fov_y_deg: DEFAULT_FOV_DEG,
        }
    }

    /// The distance LOD's parameters for the scene's terrain.
    pub fn distance_lod(&self, info: &TerrainInfo) -> DistanceLod {
        self.lod
            .unwrap_or_else(|| DistanceLod::for_extent(info.world_width().max(info.world_depth())))
    }

    pub fn load_heightmap(&self) -> Result<Heightmap, HeightmapError> {
        match &self.heightmap {
            HeightmapSource::Embedded {
                name,
                bytes,
                format,
            } => Heightmap::from_bytes(bytes, *format, &self.load, std::path::Path::new(name)),
            HeightmapSource::File(path) => Heightmap::load(path, &self.load),
        }
    }

    /// The scene's heightmap opened tile by tile, and where its samples lie,
    /// when it is a tiled terrain (`vkterrain import`) read as it is
    /// stored; None for any other heightmap, and for a tiled one the scene
    /// smooths, which needs it whole. Options that would change its
    /// heights are refused.
    pub fn open_tiled(&self) -> Result<Option<(TiledHeightmap, Placement)>, SceneError> {
        let HeightmapSource::File(path) = &self.heightmap else {
            return Ok(None);
        };
        if self.load.smooth || !TiledHeightmap::is_tiled(path) {
            return Ok(None);
        }
        crate::terrain::tiled::check_tiled_options(path, &self.load)?;
        let tiled = TiledHeightmap::open(path).map_err(HeightmapError::from)?;
        let placement =
            Placement::new(tiled.width(), tiled.depth(), self.cell_spacing, self.origin)?;
        Ok(Some((tiled, placement)))
    }

    /// A tiled terrain placed in the world without reading it whole: its
    /// samples stay in the file, read a tile at a time, and its error
    /// tables and Y bounds come stored (for the scene's patch size). None
    /// for any other heightmap; an error for a tiled one that stores
    /// nothing for this patch size.
    pub fn streamed_terrain_info(&self) -> Result<Option<TerrainInfo>, SceneError> {
        crate::terrain::grid::validate_cells_per_patch(self.cells_per_patch)?;
        let Some((tiled, _)) = self.open_tiled()? else {
            return Ok(None);
        };
        let tables = tiled.error_tables().map_err(HeightmapError::from)?;
        let tables = match tables {
            Some(t) if t.cells_per_patch == self.cells_per_patch => t,
            other => {
                return Err(SceneError::StreamedPatchSize {
                    path: tiled.path().to_path_buf(),
                    stored: other.map(|t| t.cells_per_patch),
                    wanted: self.cells_per_patch,
                })
            }
        };
        Ok(Some(TerrainInfo::tiled(
            std::sync::Arc::new(tiled),
            tables,
            self.cell_spacing,
            self.origin,
        )?))
    }

    /// The heightmap placed in the world. A tiled terrain that stores the
    /// error tables of the scene's patch size brings them along, so they
    /// are not rebuilt.
    pub fn terrain_info(&self) -> Result<TerrainInfo, SceneError> {
        crate::terrain::grid::validate_cells_per_patch(self.cells_per_patch)?;
        if let Some((tiled, _)) = self.open_tiled()? {
            let heightmap = tiled
                .to_heightmap(self.load.max_samples)
                .map_err(HeightmapError::from)?;
            let tables = tiled.error_tables().map_err(HeightmapError::from)?;
            let info = TerrainInfo::new(
                heightmap,
                self.cell_spacing,
                self.cells_per_patch,
                self.origin,
            )?;
            return Ok(match tables {
                Some(t) if t.cells_per_patch == self.cells_per_patch => {
                    info.with_error_tables(t.tess, t.geomip)
                }
                _ => info,
            });
        }
        let heightmap = self.load_heightmap()?;
        Ok(TerrainInfo::new(
            heightmap,
            self.cell_spacing,
            self.cells_per_patch,
            self.origin,
        )?)
    }
}
