//! Graphics pipelines for dynamic rendering, and pipeline layouts.

use ash::vk;

use super::device::Device;
use super::error::{Result, VkResultExt};
use super::owned::{DescriptorSetLayout, Owned, Pipeline, PipelineLayout};

/// Everything that varies between our graphics pipelines.
#[derive(Clone, Debug)]
pub struct GraphicsPipelineDesc<'a> {
    pub name: &'a str,
    /// Stage and SPIR-V of each shader.
    pub stages: &'a [(vk::ShaderStageFlags, &'a [u8])],
    pub vertex_stride: u32,
    /// (location, format, offset) of each vertex attribute.
    pub vertex_attributes: &'a [(u32, vk::Format, u32)],
    pub topology: vk::PrimitiveTopology,
    /// Control points per patch; 0 for pipelines without tessellation.
    pub patch_control_points: u32,
    pub polygon_mode: vk::PolygonMode,
    /// Whether triangles facing away from the eye (clockwise on screen)
    /// are dropped before rasterisation.
    pub cull_back_faces: bool,
    pub color_format: vk::Format,
    pub depth_format: vk::Format,
    pub depth_compare: vk::CompareOp,
    /// Whether fragments write depth (the test is always on).
    pub depth_write: bool,
    /// Samples per pixel of the attachments.
    pub samples: vk::SampleCountFlags,
    pub layout: &'a PipelineLayout,
    /// Values of specialisation constants 0, 1, ... (u32 each), given to
    /// every stage; a stage ignores the ids it doesn't declare.
    pub specialization: &'a [u32],
}

impl Device {
    pub fn create_pipeline_layout(
        &self,
        set_layouts: &[&DescriptorSetLayout],
        name: &str,
    ) -> Result<PipelineLayout> {
        self.create_pipeline_layout_with_push(set_layouts, vk::ShaderStageFlags::empty(), 0, name)
    }

    /// A pipeline layout with one push-constant range at offset 0.
    /// With `push_size` > 0, one push-constant range at offset 0.
    pub fn create_pipeline_layout_with_push(
        &self,
        set_layouts: &[&DescriptorSetLayout],
        stages: vk::ShaderStageFlags,
        push_size: u32,
        name: &str,
    ) -> Result<PipelineLayout> {
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(stages)
            .size(push_size)];
        let set_layouts: Vec<_> = set_layouts.iter().map(|l| l.raw()).collect();
        let info = vk::PipelineLayoutCreateInfo::default()
            .set_layouts(&set_layouts)
            .push_constant_ranges(if push_size > 0 { &ranges } else { &[] });
        // SAFETY: the set layouts belong to this device.
        let layout = unsafe { self.ash().create_pipeline_layout(&info, None) }
            .context("creating a pipeline layout")?;
        Ok(Owned::new(self, layout, name))
    }

    /// A graphics pipeline with dynamic viewport and scissor, no blending,
    /// a depth test, and back faces culled where `desc` asks.
    pub fn create_graphics_pipeline(&self, desc: &GraphicsPipelineDesc) -> Result<Pipeline> {
        let mut modules = Vec::with_capacity(desc.stages.len());
        for (stage, spirv) in desc.stages {
            let module = self.create_shader_module(spirv, &format!("{}.{stage:?}", desc.name))?;
            modules.push((*stage, module));
        }
        let entries: Vec<vk::SpecializationMapEntry> = (0..desc.specialization.len())
            .map(|i| {
                vk::SpecializationMapEntry::default()
                    .constant_id(i as u32)
                    .offset(4 * i as u32)
                    .size(4)
            })
            .collect();
        let specialization = vk::SpecializationInfo::default()
            .map_entries(&entries)
            .data(bytemuck::cast_slice(desc.specialization));
        let stages: Vec<vk::PipelineShaderStageCreateInfo> = modules
            .iter()
            .map(|(stage, module)| {
                vk::PipelineShaderStageCreateInfo::default()
                    .stage(*stage)
                    .module(module.raw())
                    .name(c"main")
                    .specialization_info(&specialization)
            })
            .collect();
        let bindings = [vk::VertexInputBindingDescription::default()
            .binding(0)
            .stride(desc.vertex_stride)
            .input_rate(vk::VertexInputRate::VERTEX)];
        let attributes: Vec<vk::VertexInputAttributeDescription> = desc
            .vertex_attributes
            .iter()
            .map(|&(location, format, offset)| {
                vk::VertexInputAttributeDescription::default()
                    .location(location)
                    .binding(0)
                    .format(format)
                    .offset(offset)
            })
            .collect();
        // A pipeline without attributes reads no vertex buffer at all.
        let bindings = if attributes.is_empty() {
            &bindings[..0]
        } else {
            &bindings[..]
        };
        let vertex_input = vk::PipelineVertexInputStateCreateInfo::default()
            .vertex_binding_descriptions(bindings)
            .vertex_attribute_descriptions(&attributes);
        let input_assembly =
            vk::PipelineInputAssemblyStateCreateInfo::default().topology(desc.topology);
        let tessellation = vk::PipelineTessellationStateCreateInfo::default()
            .patch_control_points(desc.patch_control_points);
        let viewport = vk::PipelineViewportStateCreateInfo::default()
            .viewport_count(1)
            .scissor_count(1);
        let raster = vk::PipelineRasterizationStateCreateInfo::default()
            .polygon_mode(desc.polygon_mode)
            .cull_mode(match desc.cull_back_faces {
                true => vk::CullModeFlags::BACK,
                false => vk::CullModeFlags::NONE,
            })
            .front_face(vk::FrontFace::COUNTER_CLOCKWISE)
            .line_width(1.0);
        let multisample =
            vk::PipelineMultisampleStateCreateInfo::default().rasterization_samples(desc.samples);
        let depth = vk::PipelineDepthStencilStateCreateInfo::default()
            .depth_test_enable(true)
            .depth_write_enable(desc.depth_write)
            .depth_compare_op(desc.depth_compare);
        let attachments = [vk::PipelineColorBlendAttachmentState::default()
            .color_write_mask(vk::ColorComponentFlags::RGBA)];
        let blend = vk::PipelineColorBlendStateCreateInfo::default().attachments(&attachments);
        let dynamic_states = [vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];
        let dynamic = vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic_states);
        let color_formats = [desc.color_format];
        let mut rendering = vk::PipelineRenderingCreateInfo::default()
            .color_attachment_formats(&color_formats)
            .depth_attachment_format(desc.depth_format);
        let mut info = vk::GraphicsPipelineCreateInfo::default()
            .stages(&stages)
            .vertex_input_state(&vertex_input)
            .input_assembly_state(&input_assembly)
            .viewport_state(&viewport)
            .rasterization_state(&raster)
            .multisample_state(&multisample)
            .depth_stencil_state(&depth)
            .color_blend_state(&blend)
            .dynamic_state(&dynamic)
            .layout(desc.layout.raw())
            .push_next(&mut rendering);
        if desc.patch_control_points > 0 {
            info = info.tessellation_state(&tessellation);
        }
        // SAFETY: all state structs are locals alive for the call; modules
        // and layout belong to this device.
        let created = unsafe {
            self.ash()
                .create_graphics_pipelines(vk::PipelineCache::null(), &[info], None)
        };
        // The modules are only needed during creation; they drop on return.
        let pipeline = created
            .map_err(|(_, r)| r)
            .context("creating a graphics pipeline")?[0];
        Ok(Owned::new(self, pipeline, desc.name))
    }

    /// A compute pipeline from one shader.
    pub fn create_compute_pipeline(
        &self,
        spirv: &[u8],
        layout: &PipelineLayout,
        name: &str,
    ) -> Result<Pipeline> {
        let module = self.create_shader_module(spirv, &format!("{name}.module"))?;
        let stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(module.raw())
            .name(c"main");
        let info = vk::ComputePipelineCreateInfo::default()
            .stage(stage)
            .layout(layout.raw());
        // SAFETY: module and layout belong to this device.
        let created = unsafe {
            self.ash()
                .create_compute_pipelines(vk::PipelineCache::null(), &[info], None)
        };
        let pipeline = created
            .map_err(|(_, r)| r)
            .context("creating a compute pipeline")?[0];
        Ok(Owned::new(self, pipeline, name))
    }
}
