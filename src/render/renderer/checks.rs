//! What a renderer refuses before it builds anything: a heightmap larger
//! than the device's images, a path or sample count the device lacks, a
//! brute draw past what one draw can address.

use ash::vk;

use super::RendererOptions;
use crate::gpu::Device;
use crate::render::error::{RenderError, Result};
use crate::render::settings::RenderPath;
use crate::terrain::Terrain;

/// Refuses what this device or the draw limits cannot do, before anything
/// is built.
pub(super) fn check_device(
    device: &Device,
    terrain: &Terrain,
    options: &RendererOptions,
) -> Result<()> {
    let info = terrain.info();
    let (cols, rows) = (info.cols() as u32, info.rows() as u32);
    let limit = device.caps.max_image_dimension_2d;
    if options.stream.is_none() && (cols > limit || rows > limit) {
        return Err(RenderError::Unsupported(format!(
            "heightmap of {cols}x{rows} samples exceeds this device's largest image ({limit}x{limit})"
        )));
    }
    let features = device.format_features(vk::Format::R32_SFLOAT);
    if !features
        .contains(vk::FormatFeatureFlags::SAMPLED_IMAGE | vk::FormatFeatureFlags::TRANSFER_DST)
    {
        return Err(RenderError::Unsupported(format!(
            "{} cannot sample R32_SFLOAT images ({features:?})",
            device.caps.device_name
        )));
    }
    device.caps.check_samples(options.samples)?;
    if !device.caps.fragment_stores_and_atomics || !device.caps.fragment_subgroup_ballot {
        return Err(RenderError::Unsupported(format!(
            "{} lacks fragmentStoresAndAtomics or subgroup vote and ballot in fragment shaders, with which the terrain's fragment shader counts the pixels each patch shows",
            device.caps.device_name
        )));
    }
    for &path in &options.paths {
        check_path(device, terrain, path, options.wireframe)?;
    }
    Ok(())
}

/// Refuses a path (with line pipelines when `wireframe`) this device or
/// the draw limits cannot do.
pub(super) fn check_path(
    device: &Device,
    terrain: &Terrain,
    path: RenderPath,
    wireframe: bool,
) -> Result<()> {
    let caps = &device.caps;
    if wireframe && !caps.fill_mode_non_solid {
        return Err(RenderError::Unsupported(format!(
            "wireframe needs fillModeNonSolid, which {} lacks",
            caps.device_name
        )));
    }
    if path == RenderPath::Tess && !caps.tessellation_shader {
        return Err(RenderError::Unsupported(format!(
            "the tess path needs tessellationShader, which {} lacks",
            caps.device_name
        )));
    }
    let brute_vertices = brute_vertex_count(terrain);
    if path == RenderPath::Brute && brute_vertices > i32::MAX as u64 {
        let info = terrain.info();
        return Err(RenderError::Unsupported(format!(
            "the brute path draws {brute_vertices} vertices for {}x{} samples, over the {} one draw can address",
            info.cols(),
            info.rows(),
            i32::MAX
        )));
    }
    Ok(())
}

/// Brute draws 6 vertices per cell, counted by a signed index in GLSL.
pub(super) fn brute_vertex_count(terrain: &Terrain) -> u64 {
    let info = terrain.info();
    6 * (info.cols() as u64 - 1) * (info.rows() as u64 - 1)
}
