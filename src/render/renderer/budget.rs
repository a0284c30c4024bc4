//! A streamed terrain under a memory budget too small for its smallest
//! layout: that layout built with the budget lifted and measured, so the
//! refusal names the smallest budget that works.

use ash::vk;

use super::{Built, RendererOptions, TerrainRenderer};
use crate::appearance::Appearance;
use crate::gpu::Gpu;
use crate::render::error::RenderError;
use crate::render::stream_budget::{headroom, smallest_budget};
use crate::render::streaming::StreamConfig;
use crate::terrain::Terrain;

/// What a renderer is built from, besides its options.
pub(super) type BuildInputs<'a> = (&'a Gpu, &'a Terrain, &'a Appearance, vk::Format, u32);

impl TerrainRenderer {
    /// The error for a budget of `budget` bytes, `before` of them in use
    /// before the renderer, too small to stream `config` with `options`:
    /// it names the smallest budget that builds.
    pub(super) fn refuse_budget(
        inputs: BuildInputs,
        options: &RendererOptions,
        config: &StreamConfig,
        (before, budget): (u64, u64),
    ) -> RenderError {
        let (gpu, terrain, ..) = inputs;
        let device = &gpu.device;
        let tiled = match super::open_streamed(terrain.info(), config) {
            Ok(tiled) => tiled,
            Err(e) => return e,
        };
        let smallest = config.smallest(&tiled, terrain.info().cells_per_patch());
        let (shape, layers) = (smallest.shape(&tiled), smallest.layers.unwrap_or(0));
        let options = RendererOptions {
            stream: Some(smallest),
            ..options.clone()
        };
        device.set_memory_budget(None);
        let built = Self::build_within_budget(inputs, &options);
        let measured = match built {
            Ok(Built::Renderer(renderer)) => {
                let bytes = device.memory_in_use() - before;
                drop(renderer);
                Ok(bytes)
            }
            Ok(Built::Rebase(_)) => Err(RenderError::Unsupported(
                "the smallest streaming layout asked for another base level".into(),
            )),
            Err(e) => Err(e),
        };
        device.set_memory_budget(Some(budget));
        let needed = match measured {
            Ok(bytes) => bytes,
            Err(e) => return e,
        };
        let least = smallest_budget(before, needed);
        let mib = |bytes: u64| bytes.div_ceil(1 << 20);
        RenderError::Stream(format!(
            "{}: a GPU memory budget of {} MiB is too small to stream it here; it needs at least \
             {} MiB (--gpu-memory-budget {}): {} MiB in use before the renderer (the render \
             targets), {} MiB for the renderer with its smallest layout (base level {}, {layers} \
             pool layers, a page of staging a frame), and {} MiB of headroom",
            config.path.display(),
            budget >> 20,
            mib(least),
            mib(least),
            mib(before),
            mib(needed),
            shape.base_level,
            mib(headroom(least)),
        ))
    }
}
