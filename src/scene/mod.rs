//! What to load: a heightmap and its placement, the patch size, LOD
//! parameters and a starting camera. The default scene is built into the
//! binary, so the run command works from any directory.

use std::path::PathBuf;

use glam::{DVec2, DVec3};

use crate::terrain::camera::Camera;
use crate::terrain::{
    DistanceLod, Heightmap, HeightmapError, HeightmapFormat, LoadOptions, TerrainError, TerrainInfo,
};

/// The default heightmap: 1025x1025, 16-bit, made by `vkterrain generate`
/// with its default parameters (see assets/README.md).
pub const DEFAULT_HEIGHTMAP_PNG: &[u8] = include_bytes!("../../assets/heightmaps/default.png");

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
    pub camera: Camera,
}

/// Why a scene's terrain could not be built.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error(transparent)]
    Heightmap(#[from] HeightmapError),
    #[error(transparent)]
    Terrain(#[from] TerrainError),
}

impl Scene {
    /// 8.2 km of generated mountains, 1400 m high, seen from the south-west.
    pub fn default_scene() -> Scene {
        Scene {
            heightmap: HeightmapSource::Embedded {
                name: "assets/heightmaps/default.png (built in)",
                bytes: DEFAULT_HEIGHTMAP_PNG,
                format: HeightmapFormat::Png,
            },
            load: LoadOptions {
                height_scale: 1400.0,
                ..LoadOptions::default()
            },
            cell_spacing: DVec2::splat(8.0),
            origin: DVec2::ZERO,
            cells_per_patch: 32,
            lod: DistanceLod {
                min_dist: 150.0,
                max_dist: 6000.0,
                min_exp: 0.0,
                max_exp: 6.0,
            },
            camera: Camera {
                eye: DVec3::new(-2300.0, 1750.0, -4300.0),
                target: DVec3::new(300.0, 350.0, 400.0),
                fov_y_deg: 55.0,
            },
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
