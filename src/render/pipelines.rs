//! The terrain renderer's graphics pipelines: each path's fill and
//! wireframe pipelines, the show-culled overlay's and the sky's.

use std::mem::size_of;

use ash::vk;

use super::appearance::ShaderVariant;
use super::settings::RenderPath;
use super::shaders;
use crate::gpu::owned::{Pipeline, PipelineLayout};
use crate::gpu::pipeline::GraphicsPipelineDesc;
use crate::gpu::target::DEPTH_FORMAT;
use crate::gpu::Device;
use crate::render::error::{RenderError, Result};
use crate::shader_variants::{Placing, Shader};

/// What every terrain pipeline is built for: the device, the targets'
/// colour format and samples, and the scene's shader variant.
pub(super) struct PipelineTarget<'a> {
    pub(super) device: &'a Device,
    pub(super) color_format: vk::Format,
    pub(super) samples: vk::SampleCountFlags,
    pub(super) variant: &'a ShaderVariant,
}

/// Fill and (when asked for) wireframe pipelines of one path.
pub(super) struct PathPipelines {
    pub(super) fill: Pipeline,
    pub(super) wireframe: Option<Pipeline>,
}

impl PathPipelines {
    pub(super) fn select(&self, wireframe: bool) -> Result<&Pipeline> {
        if !wireframe {
            return Ok(&self.fill);
        }
        self.wireframe
            .as_ref()
            .ok_or(RenderError::NotBuilt("the wireframe pipeline"))
    }
}

/// The show-culled overlay's pipelines: the tess path's stages with a
/// one-colour fragment shader, no depth test, lines where the device has
/// them; fractional even and equal spacing.
pub(super) struct CulledPipelines {
    pub(super) fractional: Pipeline,
    pub(super) equal: Pipeline,
}

/// The fill pipeline of `path` on `layout` and, when asked, the wireframe
/// one. `path.1`: the tess path with equal spacing (the error LOD).
pub(super) fn build_pipelines(
    target: &PipelineTarget,
    layout: &PipelineLayout,
    path: (RenderPath, bool),
    wireframe: bool,
) -> Result<PathPipelines> {
    let create = |mode, suffix| {
        create_pipeline(
            target.device,
            layout,
            (target.color_format, target.samples),
            target.variant,
            path,
            mode,
            suffix,
        )
    };
    Ok(PathPipelines {
        fill: create(vk::PolygonMode::FILL, "fill")?,
        wireframe: match wireframe {
            true => Some(create(vk::PolygonMode::LINE, "wireframe")?),
            false => None,
        },
    })
}

fn create_pipeline(
    device: &Device,
    layout: &PipelineLayout,
    (color_format, samples): (vk::Format, vk::SampleCountFlags),
    variant: &ShaderVariant,
    (path, equal_spacing): (RenderPath, bool),
    polygon_mode: vk::PolygonMode,
    suffix: &str,
) -> Result<Pipeline> {
    let frag = shaders::spirv(Shader::TerrainFrag(variant.shading()));
    let placing = variant.placing();
    let (name, stages, topology, patch_control_points, vertex_stride, vertex_attributes): (
        String,
        &[_],
        _,
        _,
        _,
        &[_],
    ) = match path {
        RenderPath::Tess => (
            if equal_spacing {
                format!("terrain.pipeline.tess_error.{suffix}")
            } else {
                format!("terrain.pipeline.tess.{suffix}")
            },
            &tess_stages(placing, equal_spacing, frag),
            vk::PrimitiveTopology::PATCH_LIST,
            4,
            size_of::<[f32; 4]>() as u32,
            &[(0, vk::Format::R32G32B32A32_SFLOAT, 0)],
        ),
        RenderPath::Geomip => (
            format!("terrain.pipeline.geomip.{suffix}"),
            &[
                (
                    vk::ShaderStageFlags::VERTEX,
                    shaders::spirv(Shader::GeomipVert(placing)),
                ),
                (vk::ShaderStageFlags::FRAGMENT, frag),
            ],
            vk::PrimitiveTopology::TRIANGLE_LIST,
            0,
            size_of::<[u16; 2]>() as u32,
            &[(0, vk::Format::R16G16_UINT, 0)],
        ),
        RenderPath::Brute => (
            format!("terrain.pipeline.brute.{suffix}"),
            &[
                (
                    vk::ShaderStageFlags::VERTEX,
                    shaders::spirv(Shader::BruteVert(placing)),
                ),
                (vk::ShaderStageFlags::FRAGMENT, frag),
            ],
            vk::PrimitiveTopology::TRIANGLE_LIST,
            0,
            0,
            &[],
        ),
    };
    device
        .create_graphics_pipeline(&GraphicsPipelineDesc {
            name: &name,
            stages,
            vertex_stride,
            vertex_attributes,
            topology,
            patch_control_points,
            polygon_mode,
            cull_back_faces: true,
            color_format,
            depth_format: DEPTH_FORMAT,
            // Reversed Z: nearer is larger.
            depth_compare: vk::CompareOp::GREATER,
            depth_write: true,
            samples,
            layout,
            specialization: &variant.specialization(),
        })
        .map_err(RenderError::from)
}

/// The tess path's stages: the vertex and control shaders, the evaluation
/// shader placing vertices as `placing` with `equal_spacing` or fractional
/// even spacing, and `frag`.
fn tess_stages(
    placing: Placing,
    equal_spacing: bool,
    frag: &'static [u8],
) -> [(vk::ShaderStageFlags, &'static [u8]); 4] {
    [
        (
            vk::ShaderStageFlags::VERTEX,
            shaders::spirv(Shader::TerrainVert),
        ),
        (
            vk::ShaderStageFlags::TESSELLATION_CONTROL,
            shaders::spirv(Shader::TerrainTesc),
        ),
        (
            vk::ShaderStageFlags::TESSELLATION_EVALUATION,
            shaders::spirv(Shader::TerrainTese {
                placing,
                equal_spacing,
            }),
        ),
        (vk::ShaderStageFlags::FRAGMENT, frag),
    ]
}

/// The show-culled overlay's pipeline for the tess path with `equal_spacing`
/// (the error LOD) or fractional even spacing.
pub(super) fn create_culled_pipeline(
    target: &PipelineTarget,
    layout: &PipelineLayout,
    equal_spacing: bool,
) -> Result<Pipeline> {
    let device = target.device;
    let spacing = if equal_spacing { "equal" } else { "fractional" };
    device
        .create_graphics_pipeline(&GraphicsPipelineDesc {
            name: &format!("terrain.pipeline.culled.{spacing}"),
            stages: &tess_stages(
                target.variant.placing(),
                equal_spacing,
                shaders::spirv(Shader::CulledFrag),
            ),
            vertex_stride: size_of::<[f32; 4]>() as u32,
            vertex_attributes: &[(0, vk::Format::R32G32B32A32_SFLOAT, 0)],
            topology: vk::PrimitiveTopology::PATCH_LIST,
            patch_control_points: 4,
            polygon_mode: if device.caps.fill_mode_non_solid {
                vk::PolygonMode::LINE
            } else {
                vk::PolygonMode::FILL
            },
            cull_back_faces: false,
            color_format: target.color_format,
            depth_format: DEPTH_FORMAT,
            depth_compare: vk::CompareOp::ALWAYS,
            depth_write: false,
            samples: target.samples,
            layout,
            specialization: &target.variant.specialization(),
        })
        .map_err(RenderError::from)
}

/// The sky's pipeline: one triangle at the far plane, drawn where the
/// depth is still the cleared far value, writing no depth.
pub(super) fn create_sky_pipeline(
    device: &Device,
    layout: &PipelineLayout,
    color_format: vk::Format,
    samples: vk::SampleCountFlags,
) -> Result<Pipeline> {
    device
        .create_graphics_pipeline(&GraphicsPipelineDesc {
            name: "terrain.pipeline.sky",
            stages: &[
                (
                    vk::ShaderStageFlags::VERTEX,
                    shaders::spirv(Shader::SkyVert),
                ),
                (
                    vk::ShaderStageFlags::FRAGMENT,
                    shaders::spirv(Shader::SkyFrag),
                ),
            ],
            vertex_stride: 0,
            vertex_attributes: &[],
            topology: vk::PrimitiveTopology::TRIANGLE_LIST,
            patch_control_points: 0,
            polygon_mode: vk::PolygonMode::FILL,
            cull_back_faces: false,
            color_format,
            depth_format: DEPTH_FORMAT,
            depth_compare: vk::CompareOp::GREATER_OR_EQUAL,
            depth_write: false,
            samples,
            layout,
            specialization: &[],
        })
        .map_err(RenderError::from)
}
