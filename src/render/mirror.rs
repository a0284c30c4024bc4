//! Runs the shared GLSL formulas (tessellation factor, frustum test, height
//! sampling) in a compute shader on inputs from the CPU, so tests can hold
//! them against their Rust mirrors. A diagnostic: no render path uses it.

use std::mem::size_of;

use ash::vk;
use glam::{Vec2, Vec3};
use gpu_allocator::MemoryLocation;

use super::settings::RenderSettings;
use super::shaders;
use super::uniforms::FrameUniforms;
use super::view::FrameView;
use crate::gpu::memory::BufferDesc;
use crate::gpu::Gpu;
use crate::render::error::{RenderError, Result};
use crate::shader_constants::{BINDING_MIRROR_CASES, BINDING_MIRROR_RESULTS};
use crate::terrain::error_table::PatchErrors;
use crate::terrain::Terrain;

/// One input of the check.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MirrorCase {
    /// Camera-relative position for the factor; box centre for the frustum test.
    pub position: Vec3,
    pub extents: Vec3,
    /// Continuous sample coordinates (column, row) for height sampling.
    pub grid: Vec2,
    /// Per-level errors for the error-bounded factor at `position`'s distance.
    pub errors: PatchErrors,
    /// Cells the error-bounded factor spans.
    pub cells: u32,
    /// The byte the error LOD's plan writes for a patch (0, or the level
    /// its share chose plus one), as the control shader reads `errors`
    /// with it (`lod::plan::chosen_errors`).
    pub chosen: u8,
}

/// What the GPU computed for one case.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MirrorResult {
    pub tess_factor: f32,
    pub outside_frustum: bool,
    pub height: f32,
    pub error_tess_factor: f32,
    /// The error-bounded factor of the errors as `chosen` reads them.
    pub chosen_tess_factor: f32,
    /// Distance to the box `position` +- `extents`.
    pub box_distance: f32,
    /// Distance to the strip on the segment from `position` to `position +
    /// extents` (x, z) between heights `position.y` -+ `extents.y`.
    pub edge_distance: f32,
    /// The peers' factors: sphere and edge length for the edge from
    /// `position` to `position + extents`, CDLOD at `position`.
    pub sphere_tess_factor: f32,
    pub edge_length_tess_factor: f32,
    pub cdlod_tess_factor: f32,
    /// The patch (row-major index) a pixel whose surface point lies at
    /// `grid` is counted for (`render::seen`).
    pub patch: u32,
}

const LOCAL_SIZE: u32 = 64;
// Each case's errors travel in two vec4s (glsl/mirror_check.comp).
const _: () = assert!(crate::terrain::error_table::LEVEL_COUNT == 7);

/// Evaluates every case on the GPU with the uniforms a frame of `view` and
/// `settings` would use.
pub fn run_mirror_check(
    gpu: &Gpu,
    terrain: &Terrain,
    view: &FrameView,
    settings: &RenderSettings,
    cases: &[MirrorCase],
) -> Result<Vec<MirrorResult>> {
    if cases.is_empty() {
        return Ok(Vec::new());
    }
    let device = &gpu.device;
    let info = terrain.info();
    let inputs = pack_cases(cases);
    let uniforms = FrameUniforms::new(terrain, view, settings);
    let results_size = (cases.len() * 3 * size_of::<[f32; 4]>()) as u64;

    let heightmap = super::renderer::upload_heightmap(device, info, "mirror.heightmap")?;
    let sampler = device.create_nearest_sampler("mirror.sampler")?;
    let frame = device.create_host_buffer(
        "mirror.frame",
        vk::BufferUsageFlags::UNIFORM_BUFFER,
        bytemuck::bytes_of(&uniforms),
    )?;
    let input = device.create_host_buffer(
        "mirror.cases",
        vk::BufferUsageFlags::STORAGE_BUFFER,
        bytemuck::cast_slice(&inputs),
    )?;
    let output = device.create_buffer(
        BufferDesc {
            size: results_size,
            usage: vk::BufferUsageFlags::STORAGE_BUFFER,
            location: MemoryLocation::GpuToCpu,
        },
        "mirror.results",
    )?;
    let stage = vk::ShaderStageFlags::COMPUTE;
    let mut bindings = super::frame::frame_bindings(stage).to_vec();
    for binding in [BINDING_MIRROR_CASES, BINDING_MIRROR_RESULTS] {
        bindings.push((binding, vk::DescriptorType::STORAGE_BUFFER, stage));
    }
    let set_layout = device.create_descriptor_set_layout(&bindings, "mirror.set_layout")?;
    let layout = device.create_pipeline_layout(&[&set_layout], "mirror.pipeline_layout")?;
    let sets = device.allocate_descriptor_sets(
        &set_layout,
        &[
            (vk::DescriptorType::UNIFORM_BUFFER, 1),
            (vk::DescriptorType::COMBINED_IMAGE_SAMPLER, 2),
            (vk::DescriptorType::STORAGE_BUFFER, 3),
        ],
        1,
        "mirror.set",
    )?;
    let set = sets.get(0);
    super::frame::write_frame_bindings(device, set, &frame, &heightmap, &sampler);
    let no_stream = super::streaming::NoStream::new(device, "mirror")?;
    no_stream.write_bindings(device, set, &sampler);
    device.write_buffer(
        set,
        BINDING_MIRROR_CASES,
        vk::DescriptorType::STORAGE_BUFFER,
        &input,
        (inputs.len() * 16) as u64,
    );
    device.write_buffer(
        set,
        BINDING_MIRROR_RESULTS,
        vk::DescriptorType::STORAGE_BUFFER,
        &output,
        results_size,
    );
    let pipeline = device.create_compute_pipeline(
        shaders::spirv(crate::shader_variants::Shader::MirrorCheckComp),
        &layout,
        "mirror.pipeline",
    )?;
    let groups = (cases.len() as u32).div_ceil(LOCAL_SIZE);
    device.one_shot("mirror.commands", |rec| {
        rec.dispatch_for_host(&pipeline, &layout, set, groups);
    })?;
    let bytes = output
        .mapped()
        .ok_or(RenderError::NotMapped("result memory"))?;
    Ok(unpack_results(&bytemuck::pod_collect_to_vec(bytes)))
}

/// Five vec4s a case, as glsl/mirror_check.comp reads them.
fn pack_cases(cases: &[MirrorCase]) -> Vec<[f32; 4]> {
    cases
        .iter()
        .flat_map(|c| {
            let e = c.errors;
            [
                c.position.extend(0.0).to_array(),
                c.extents.extend(0.0).to_array(),
                c.grid
                    .extend(c.cells as f32)
                    .extend(f32::from(c.chosen))
                    .to_array(),
                [e[0], e[1], e[2], e[3]],
                [e[4], e[5], e[6], 0.0],
            ]
        })
        .collect()
}

/// Three vec4s a case, as glsl/mirror_check.comp writes them.
fn unpack_results(values: &[[f32; 4]]) -> Vec<MirrorResult> {
    values
        .chunks_exact(3)
        .map(|v| MirrorResult {
            tess_factor: v[0][0],
            outside_frustum: v[0][1] != 0.0,
            height: v[0][2],
            error_tess_factor: v[0][3],
            chosen_tess_factor: v[1][3],
            box_distance: v[1][0],
            edge_distance: v[1][1],
            sphere_tess_factor: v[2][0],
            edge_length_tess_factor: v[2][1],
            cdlod_tess_factor: v[2][2],
            patch: v[1][2] as u32,
        })
        .collect()
}
