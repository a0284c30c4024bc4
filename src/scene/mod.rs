//! What to load: a heightmap and its placement, the patch size, LOD
//! parameters and a starting camera, from a TOML scene file (see `file`).
//! The default scene, `assets/scenes/default.toml` and its heightmap, is
//! built into the binary, so the run command works from any directory.

mod file;

use std::path::{Path, PathBuf};

use glam::{DVec2, DVec3};

pub use file::SceneFileError;

use crate::terrain::camera::Camera;
use crate::terrain::{
    DistanceLod, Heightmap, HeightmapError, HeightmapFormat, LoadOptions, TerrainError, TerrainInfo,
};

/// The default scene file.
pub const DEFAULT_SCENE_TOML: &str = include_str!("../../assets/scenes/default.toml");
/// The default heightmap: 1025x1025, 16-bit, made by `vkterrain generate`
/// with its default parameters (see assets/README.md).
pub const DEFAULT_HEIGHTMAP_PNG: &[u8] = include_bytes!("../../assets/heightmaps/default.png");
/// Vertical field of view when a scene gives none.
pub const DEFAULT_FOV_DEG: f32 = 55.0;

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
    pub lod: DistanceLod,
    /// None: an overview of the whole terrain (`camera_for`).
    pub camera: Option<Camera>,
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
        scene
    }

    /// The scene's camera, or one that overlooks the whole terrain from
    /// beyond its south-west corner (-x, -z), high enough to see the far edge.
    pub fn camera_for(&self, info: &TerrainInfo) -> Camera {
        if let Some(camera) = self.camera {
            return camera;
        }
        let (lo, hi) = info.heightmap().min_max();
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

    pub fn terrain_info(&self) -> Result<TerrainInfo, SceneError> {
        crate::terrain::info::validate_cells_per_patch(self.cells_per_patch)?;
        let heightmap = self.load_heightmap()?;
        Ok(TerrainInfo::new(
            heightmap,
            self.cell_spacing,
            self.cells_per_patch,
            self.origin,
        )?)
    }
}
