//! The tessellation path: patches of four control points, factors and
//! culling in the control shader, displacement in the evaluation shader.

use std::mem::size_of;

use ash::vk;

use super::shaders;
use super::uniforms::{FrameUniforms, RenderSettings};
use crate::shader_constants::{BINDING_FRAME, BINDING_HEIGHTMAP};
use crate::terrain::Terrain;
use crate::vk::commands::Recorder;
use crate::vk::memory::{Buffer, Image};
use crate::vk::pipeline::GraphicsPipelineDesc;
use crate::vk::queries::{FrameQueries, PipelineStatistics};
use crate::vk::target::{TargetViews, DEPTH_FORMAT};
use crate::vk::{Device, Gpu, Result, VkError};

/// Per-frame-in-flight resources: the uniform block is rewritten each frame,
/// so a frame still on the GPU keeps its own.
struct FrameSlot {
    uniforms: Buffer,
    set: vk::DescriptorSet,
    queries: FrameQueries,
}

/// Draws a terrain with the tessellation pipeline into any target.
pub struct TessRenderer {
    control_points: Buffer,
    indices: Buffer,
    index_count: u32,
    heightmap: Image,
    sampler: vk::Sampler,
    set_layout: vk::DescriptorSetLayout,
    pipeline_layout: vk::PipelineLayout,
    descriptor_pool: vk::DescriptorPool,
    fill: vk::Pipeline,
    /// Built only when asked for, and only where fillModeNonSolid exists.
    wireframe: Option<vk::Pipeline>,
    color_format: vk::Format,
    max_patches_per_draw: Option<u32>,
    frames: Vec<FrameSlot>,
}

/// What one frame's queries measured; None where the device can't tell.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameMeasurements {
    pub gpu_ms: Option<f64>,
    pub statistics: Option<PipelineStatistics>,
}

impl TessRenderer {
    /// Uploads the terrain and builds the pipeline for targets of
    /// `color_format`. `wireframe`: also build the line pipeline.
    pub fn new(
        gpu: &Gpu,
        terrain: &Terrain,
        color_format: vk::Format,
        frames_in_flight: u32,
        wireframe: bool,
    ) -> Result<Self> {
        let device = &gpu.device;
        let info = terrain.info();
        let (cols, rows) = (info.cols() as u32, info.rows() as u32);
        let limit = device.caps.max_image_dimension_2d;
        if cols > limit || rows > limit {
            return Err(VkError::Unsupported(format!(
                "heightmap of {cols}x{rows} samples exceeds this device's largest image ({limit}x{limit})"
            )));
        }
        let features = device.format_features(&gpu.instance, vk::Format::R32_SFLOAT);
        if !features
            .contains(vk::FormatFeatureFlags::SAMPLED_IMAGE | vk::FormatFeatureFlags::TRANSFER_DST)
        {
            return Err(VkError::Unsupported(format!(
                "{} cannot sample R32_SFLOAT images ({features:?})",
                device.caps.device_name
            )));
        }
        if wireframe && !device.caps.fill_mode_non_solid {
            return Err(VkError::Unsupported(format!(
                "wireframe needs fillModeNonSolid, which {} lacks",
                device.caps.device_name
            )));
        }

        let control_points = device.upload_buffer(
            "terrain.control_points",
            vk::BufferUsageFlags::VERTEX_BUFFER,
            bytemuck::cast_slice(terrain.control_points()),
        )?;
        let indices = device.upload_buffer(
            "terrain.patch_indices",
            vk::BufferUsageFlags::INDEX_BUFFER,
            bytemuck::cast_slice(terrain.indices()),
        )?;
        let heightmap = device.upload_r32f_image(
            "terrain.heightmap",
            cols,
            rows,
            info.heightmap().heights(),
        )?;
        let sampler = device.create_nearest_sampler("terrain.heightmap_sampler")?;

        let all_stages = vk::ShaderStageFlags::VERTEX
            | vk::ShaderStageFlags::TESSELLATION_CONTROL
            | vk::ShaderStageFlags::TESSELLATION_EVALUATION
            | vk::ShaderStageFlags::FRAGMENT;
        let set_layout = device.create_descriptor_set_layout(
            &[
                (
                    BINDING_FRAME,
                    vk::DescriptorType::UNIFORM_BUFFER,
                    all_stages,
                ),
                (
                    BINDING_HEIGHTMAP,
                    vk::DescriptorType::COMBINED_IMAGE_SAMPLER,
                    all_stages,
                ),
            ],
            "terrain.set_layout",
        )?;
        let pipeline_layout =
            device.create_pipeline_layout(&[set_layout], "terrain.pipeline_layout")?;
        let (descriptor_pool, sets) = device.allocate_descriptor_sets(
            set_layout,
            &[
                (vk::DescriptorType::UNIFORM_BUFFER, 1),
                (vk::DescriptorType::COMBINED_IMAGE_SAMPLER, 1),
            ],
            frames_in_flight,
            "terrain.frame_set",
        )?;
        let fill = create_pipeline(
            device,
            pipeline_layout,
            color_format,
            vk::PolygonMode::FILL,
            "terrain.pipeline.fill",
        )?;
        let wireframe = if wireframe {
            Some(create_pipeline(
                device,
                pipeline_layout,
                color_format,
                vk::PolygonMode::LINE,
                "terrain.pipeline.wireframe",
            )?)
        } else {
            None
        };
        let mut frames = Vec::with_capacity(sets.len());
        for (i, set) in sets.into_iter().enumerate() {
            let uniforms = device.create_host_buffer(
                &format!("terrain.frame_uniforms[{i}]"),
                vk::BufferUsageFlags::UNIFORM_BUFFER,
                bytemuck::bytes_of(&FrameUniforms::default()),
            )?;
            device.write_uniform_buffer(
                set,
                BINDING_FRAME,
                uniforms.raw,
                size_of::<FrameUniforms>() as u64,
            );
            device.write_sampled_image(set, BINDING_HEIGHTMAP, heightmap.view, sampler);
            let queries = FrameQueries::new(device, &format!("terrain.frame_queries[{i}]"))?;
            frames.push(FrameSlot {
                uniforms,
                set,
                queries,
            });
        }
        Ok(TessRenderer {
            control_points,
            indices,
            index_count: terrain.indices().len() as u32,
            heightmap,
            sampler,
            set_layout,
            pipeline_layout,
            descriptor_pool,
            fill,
            wireframe,
            color_format,
            max_patches_per_draw: device.caps.max_patches_per_draw,
            frames,
        })
    }

    pub fn color_format(&self) -> vk::Format {
        self.color_format
    }

    pub fn frames_in_flight(&self) -> usize {
        self.frames.len()
    }

    /// Writes the uniforms of frame slot `slot`; its previous frame must
    /// have completed.
    pub fn prepare(&mut self, slot: usize, uniforms: &FrameUniforms) -> Result<()> {
        self.frames[slot]
            .uniforms
            .mapped_mut()
            .ok_or_else(|| VkError::Unsupported("uniform memory is not host-mapped".into()))?
            .copy_from_slice(bytemuck::bytes_of(uniforms));
        Ok(())
    }

    /// Records the terrain draw into `target` (already in attachment
    /// layouts), timed and counted by slot `slot`'s queries.
    pub fn record(
        &self,
        rec: &Recorder,
        slot: usize,
        target: &TargetViews,
        settings: &RenderSettings,
    ) -> Result<()> {
        let frame = &self.frames[slot];
        let pipeline = if settings.wireframe {
            self.wireframe.ok_or_else(|| {
                VkError::Unsupported(
                    "the wireframe pipeline was not built for this renderer".into(),
                )
            })?
        } else {
            self.fill
        };
        frame.queries.reset(rec.device, rec.cmd);
        rec.begin_rendering(target, settings.clear_color);
        frame.queries.begin(rec.device, rec.cmd);
        rec.bind_graphics(pipeline, self.pipeline_layout, frame.set);
        rec.bind_geometry(self.control_points.raw, self.indices.raw);
        // One draw, or batches where the driver needs them (see
        // `Capabilities::max_patches_per_draw`).
        let batch = self
            .max_patches_per_draw
            .map_or(self.index_count, |n| n * 4);
        let mut first = 0;
        while first < self.index_count {
            let count = (self.index_count - first).min(batch);
            rec.draw_indexed(first, count);
            first += count;
        }
        frame.queries.end(rec.device, rec.cmd);
        rec.end_rendering();
        Ok(())
    }

    /// What slot `slot`'s last frame measured; call after its fence.
    pub fn measurements(&self, device: &Device, slot: usize) -> Result<FrameMeasurements> {
        let queries = &self.frames[slot].queries;
        Ok(FrameMeasurements {
            gpu_ms: queries.gpu_ms(&device.raw)?,
            statistics: queries.statistics(&device.raw)?,
        })
    }

    pub fn destroy(self, device: &Device) {
        for frame in self.frames {
            device.destroy_buffer(frame.uniforms);
            frame.queries.destroy(&device.raw);
        }
        for pipeline in std::iter::once(self.fill).chain(self.wireframe) {
            device.destroy_pipeline(pipeline);
        }
        device.destroy_pipeline_layout(self.pipeline_layout);
        // The pool frees its sets; the layout goes after them.
        device.destroy_descriptor_pool(self.descriptor_pool);
        device.destroy_descriptor_set_layout(self.set_layout);
        device.destroy_sampler(self.sampler);
        device.destroy_image(self.heightmap);
        device.destroy_buffer(self.control_points);
        device.destroy_buffer(self.indices);
    }
}

fn create_pipeline(
    device: &Device,
    layout: vk::PipelineLayout,
    color_format: vk::Format,
    polygon_mode: vk::PolygonMode,
    name: &str,
) -> Result<vk::Pipeline> {
    device.create_graphics_pipeline(&GraphicsPipelineDesc {
        name,
        stages: &[
            (vk::ShaderStageFlags::VERTEX, shaders::TERRAIN_VERT),
            (
                vk::ShaderStageFlags::TESSELLATION_CONTROL,
                shaders::TERRAIN_TESC,
            ),
            (
                vk::ShaderStageFlags::TESSELLATION_EVALUATION,
                shaders::TERRAIN_TESE,
            ),
            (vk::ShaderStageFlags::FRAGMENT, shaders::TERRAIN_FRAG),
        ],
        vertex_stride: size_of::<[f32; 4]>() as u32,
        vertex_attributes: &[(0, vk::Format::R32G32B32A32_SFLOAT, 0)],
        topology: vk::PrimitiveTopology::PATCH_LIST,
        patch_control_points: 4,
        polygon_mode,
        color_format,
        depth_format: DEPTH_FORMAT,
        // Reversed Z: nearer is larger.
        depth_compare: vk::CompareOp::GREATER,
        layout,
    })
}
