//! Loading a heightmap file of any format: the one place that tells a
//! tiled terrain (`vkterrain import`, recognised by its header) from the
//! raster formats, above both loaders.

use std::path::Path;

use super::error::HeightmapError;
use super::heightmap::{Heightmap, LoadOptions};
use super::tiled::{self, TiledHeightmap};

impl Heightmap {
    /// Reads a heightmap file. A tiled terrain is loaded whole, within
    /// `max_samples`; its heights were fixed at import, so the format,
    /// size and height mapping options are refused for it rather than
    /// ignored (`tiled::load_whole`). Any other file is read by its format
    /// (`Heightmap::load_raster`), its size limits checked against its
    /// length before its samples are read or allocated.
    pub fn load(path: &Path, opts: &LoadOptions) -> Result<Self, HeightmapError> {
        if TiledHeightmap::is_tiled(path) {
            tiled::load_whole(path, opts)
        } else {
            Heightmap::load_raster(path, opts)
        }
    }
}
