//! A scene loaded for drawing: the one way every command turns a scene
//! (or bare heightmap options, which make one) into what a renderer is
//! built from.

use std::time::Instant;

use crate::appearance::{Appearance, MaterialError};
use crate::scene::{Scene, SceneError};
use crate::terrain::{Terrain, TerrainError};

use super::streaming::StreamConfig;

/// What to load besides the terrain.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Loading {
    /// Stream a tiled terrain file a tile at a time; otherwise every
    /// terrain is read whole.
    pub stream: bool,
    /// Load the scene's textures and bake its lightmap; otherwise it is
    /// drawn with none, its Y bounds not widened for displacement.
    pub appearance: bool,
}

impl Loading {
    /// The terrain alone, read whole.
    pub const WHOLE_TERRAIN: Loading = Loading {
        stream: false,
        appearance: false,
    };
}

/// Milliseconds each step of loading took.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LoadTimings {
    /// Reading the heights (or a tiled file's tables).
    pub terrain_ms: f64,
    /// Loading the textures and baking the lightmap.
    pub appearance_ms: f64,
    /// Building the CPU model: the patch grid and its Y bounds.
    pub model_ms: f64,
}

/// A scene ready for a renderer.
pub struct LoadedScene {
    /// The CPU model. A streamed terrain's Y bounds are widened for the
    /// base level its tiles are drawn from until they are resident, and
    /// every terrain's for the appearance's displacement.
    pub terrain: Terrain,
    /// The textures and lightmap (none unless `Loading::appearance`).
    pub appearance: Appearance,
    /// How a tiled terrain streams; None where the terrain is held whole.
    pub stream: Option<StreamConfig>,
    pub timings: LoadTimings,
}

/// Why a scene did not load; each names what was wrong.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Material(#[from] MaterialError),
    #[error(transparent)]
    Terrain(#[from] TerrainError),
}

impl LoadedScene {
    /// Loads `scene` as `loading` asks.
    pub fn load(scene: &Scene, loading: Loading) -> Result<LoadedScene, LoadError> {
        let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        let started = Instant::now();
        let streamed = match loading.stream {
            true => scene.streamed_terrain_info()?,
            false => None,
        };
        let (info, stream) = match streamed {
            Some(info) => {
                let tiled = info
                    .tiled_samples()
                    .expect("a streamed terrain's info is tiled");
                let config = StreamConfig::new(tiled.path().to_path_buf());
                (info, Some(config))
            }
            None => (scene.terrain_info()?, None),
        };
        let terrain_ms = ms(started);
        let started = Instant::now();
        let appearance = match loading.appearance {
            true => Appearance::load(scene, &info)?,
            false => Appearance::default(),
        };
        let appearance_ms = ms(started);
        let started = Instant::now();
        let mut terrain = Terrain::new(info, appearance.y_margin())?;
        if let (Some(config), Some(tiled)) = (&stream, terrain.info().tiled_samples()) {
            let base = config.shape(tiled).base_level;
            terrain.widen_y_bounds_to_blocks(1 << base);
        }
        Ok(LoadedScene {
            terrain,
            appearance,
            stream,
            timings: LoadTimings {
                terrain_ms,
                appearance_ms,
                model_ms: ms(started),
            },
        })
    }
}
