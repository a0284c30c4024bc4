//! A scene's look on the GPU: the material layers' uniform block, their
//! texture arrays, blend maps and the lightmap, with the descriptors and
//! shader variant they need. Only what the scene uses is created: a scene
//! without layers gets none of it, and each map kind gets a binding only
//! when some layer has one.

use std::mem::{offset_of, size_of};

use ash::vk;

use super::residency::StreamShape;
use crate::appearance::{Appearance, Material, TexelFormat, TextureArray};
use crate::gpu::descriptors::DescriptorSet;
use crate::gpu::memory::{Buffer, Image, TexelUpload};
use crate::gpu::owned::Sampler;
use crate::gpu::Device;
use crate::render::error::{RenderError, Result};
use crate::shader_constants::{
    BINDING_BLEND_MAPS, BINDING_DIFFUSE_MAPS, BINDING_HEIGHT_MAPS, BINDING_LIGHTMAP,
    BINDING_MATERIAL, BINDING_NORMAL_MAPS, MAX_LAYERS, SPEC_BLEND_MAP_COUNT, SPEC_LAYER_COUNT,
    SPEC_STREAMED,
};
use crate::shader_variants::{Placing, Shading};
use crate::terrain::TerrainInfo;

const _: () = assert!(MAX_LAYERS as usize == crate::terrain::shading::MAX_LAYERS);
const _: () =
    assert!(crate::shader_constants::MAX_LIGHTS as usize == crate::scene::look::MAX_LIGHTS);

/// One layer (`Layer` in glsl/material.glsl), std140.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct LayerUniform {
    /// Rows of world (x, z) -> (u, v).
    pub tile: [f32; 4],
    /// Offset (u, v), displacement scale, normal-map layer (-1: none).
    pub offset: [f32; 4],
    /// Height-map layer (-1: none), band centre, band half-width (0: none),
    /// mip level for vertex fetches.
    pub band: [f32; 4],
}
const _: () = assert!(size_of::<LayerUniform>() == 48);

/// `Material` in glsl/material.glsl, std140.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct MaterialUniforms {
    pub layers: [LayerUniform; MAX_LAYERS as usize],
    /// Cliff layer (-1: none), slope where it starts, slope where it is full.
    pub rules: [f32; 4],
}
const _: () = assert!(size_of::<MaterialUniforms>() == 48 * MAX_LAYERS as usize + 16);
const _: () = assert!(offset_of!(MaterialUniforms, rules) == 48 * MAX_LAYERS as usize);

impl MaterialUniforms {
    /// `info` gives the sample spacing, which sets the mip level vertex
    /// stages read height maps at: about two vertices per cell at most.
    pub fn new(material: &Material, info: &TerrainInfo) -> Self {
        let spacing = info.spacing().min_element() as f32;
        let height_texels = material.heights.as_ref().map_or(1, |h| h.width);
        let mut layers = [LayerUniform::default(); MAX_LAYERS as usize];
        for (u, l) in layers.iter_mut().zip(&material.layers) {
            let index = |i: Option<u32>| i.map_or(-1.0, |i| i as f32);
            // Texels per metre along u, times half a cell.
            let texels_per_step = l.tile.row(0).length() * height_texels as f32 * 0.5 * spacing;
            u.tile = [
                l.tile.row(0).x,
                l.tile.row(0).y,
                l.tile.row(1).x,
                l.tile.row(1).y,
            ];
            u.offset = [
                l.tile_offset.x,
                l.tile_offset.y,
                l.displacement,
                index(l.normal_index),
            ];
            let (centre, half) = l.band.map_or((0.0, 0.0), |b| (b.centre, b.half_width));
            u.band = [
                index(l.height_index),
                centre,
                half,
                texels_per_step.max(1.0).log2(),
            ];
        }
        let rules = match material.cliff {
            Some(c) => [c.layer as f32, c.slope_deg[0], c.slope_deg[1], 0.0],
            None => [-1.0, 0.0, 0.0, 0.0],
        };
        MaterialUniforms { layers, rules }
    }
}

/// Which compiled variant of each stage a scene needs, and its
/// specialisation constants.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ShaderVariant {
    pub material: bool,
    pub normal_maps: bool,
    pub blend_maps: bool,
    pub lightmap: bool,
    pub displace: bool,
    pub triplanar: bool,
    pub layer_count: u32,
    pub blend_map_count: u32,
    /// How heights are streamed from a tiled terrain (`streaming`), if
    /// they are.
    pub stream: Option<StreamShape>,
}

impl ShaderVariant {
    pub fn of(appearance: &Appearance) -> Self {
        let m = appearance.material.as_ref();
        ShaderVariant {
            material: m.is_some(),
            normal_maps: m.is_some_and(|m| m.normals.is_some()),
            blend_maps: m.is_some_and(|m| m.blend_maps.is_some()),
            lightmap: appearance.lightmap.is_some(),
            displace: m.is_some_and(Material::displaces),
            triplanar: m.is_some_and(|m| m.triplanar),
            layer_count: m.map_or(1, |m| m.layers.len() as u32),
            blend_map_count: m
                .and_then(|m| m.blend_maps.as_ref())
                .map_or(1, |b| b.layers),
            stream: None,
        }
    }

    /// Macros of the fragment stage.
    /// The fragment shader's features.
    pub fn shading(&self) -> Shading {
        if self.material {
            Shading::Material {
                normal_maps: self.normal_maps,
                blend_maps: self.blend_maps,
                lightmap: self.lightmap,
                triplanar: self.triplanar,
            }
        } else {
            Shading::Heights {
                lightmap: self.lightmap,
            }
        }
    }

    /// How the vertex-placing stages displace.
    pub fn placing(&self) -> Placing {
        match self.displace {
            false => Placing::Plain,
            true => Placing::Displaced {
                blend_maps: self.blend_maps,
                triplanar: self.triplanar,
            },
        }
    }

    /// Values of constant ids 0.. (SPEC_LAYER_COUNT, SPEC_BLEND_MAP_COUNT,
    /// then SPEC_STREAMED and the streamed terrain's shape: tile cells,
    /// base level, tiles across and down).
    pub fn specialization(&self) -> [u32; 7] {
        let mut s = [0; 7];
        s[SPEC_LAYER_COUNT as usize] = self.layer_count;
        s[SPEC_BLEND_MAP_COUNT as usize] = self.blend_map_count;
        if let Some(shape) = self.stream {
            s[SPEC_STREAMED as usize..][..5].copy_from_slice(&[
                1,
                shape.tile_cells,
                shape.base_level,
                shape.tiles_x,
                shape.tiles_z,
            ]);
        }
        s
    }
}

/// Anisotropic filtering when a scene has textures: what the scene asks
/// for (at most the device's limit), or by default 16 samples on GPUs and
/// none on CPU rasterisers, where lavapipe (Mesa 22.3) takes over 1000x
/// longer per frame with it (a 320x180 geomip frame of the default scene:
/// 0.26 s without, 434 s at 16x; 2x is hardly faster). None without the
/// device feature, or at 1.
pub fn anisotropy_for(asked: Option<f32>, caps: &crate::gpu::Capabilities) -> Option<f32> {
    let wanted = asked.unwrap_or(if caps.device_type == "CPU" { 1.0 } else { 16.0 });
    (caps.sampler_anisotropy && wanted > 1.0).then(|| wanted.min(caps.max_sampler_anisotropy))
}

/// The GPU objects of a scene's look.
pub struct GpuAppearance {
    pub variant: ShaderVariant,
    uniforms: Option<Buffer>,
    diffuse: Option<Image>,
    normals: Option<Image>,
    heights: Option<Image>,
    blend_maps: Option<Image>,
    lightmap: Option<Image>,
    /// Repeating, for layer textures.
    tiling: Option<Sampler>,
    /// Clamped, for maps stretched over the terrain.
    stretched: Option<Sampler>,
}

fn vk_format(format: TexelFormat) -> vk::Format {
    match format {
        TexelFormat::Srgba8 => vk::Format::R8G8B8A8_SRGB,
        TexelFormat::Rgba8 => vk::Format::R8G8B8A8_UNORM,
        TexelFormat::R8 => vk::Format::R8_UNORM,
    }
}

impl GpuAppearance {
    /// Nothing at all: height colours, no lightmap.
    pub fn none() -> Self {
        GpuAppearance {
            variant: ShaderVariant::default(),
            uniforms: None,
            diffuse: None,
            normals: None,
            heights: None,
            blend_maps: None,
            lightmap: None,
            tiling: None,
            stretched: None,
        }
    }

    /// Uploads what `appearance` holds. On failure what was created so far
    /// frees itself.
    pub fn new(device: &Device, appearance: &Appearance, info: &TerrainInfo) -> Result<Self> {
        let mut gpu = GpuAppearance::none();
        gpu.variant = ShaderVariant::of(appearance);
        gpu.fill(device, appearance, info)?;
        Ok(gpu)
    }

    fn fill(&mut self, device: &Device, appearance: &Appearance, info: &TerrainInfo) -> Result<()> {
        let upload = |name: &str, t: &TextureArray| -> Result<Image> {
            let format = vk_format(t.format);
            let needed = vk::FormatFeatureFlags::SAMPLED_IMAGE
                | vk::FormatFeatureFlags::SAMPLED_IMAGE_FILTER_LINEAR
                | vk::FormatFeatureFlags::TRANSFER_DST;
            let has = device.format_features(format);
            if !has.contains(needed) {
                return Err(RenderError::Unsupported(format!(
                    "{} cannot filter {format:?} textures ({has:?})",
                    device.caps.device_name
                )));
            }
            let caps = &device.caps;
            if t.width.max(t.height) > caps.max_image_dimension_2d
                || t.layers > caps.max_image_array_layers
            {
                return Err(RenderError::Unsupported(format!(
                    "{name}: {}x{} with {} layers exceeds this device's images ({} on a side, {} layers)",
                    t.width, t.height, t.layers, caps.max_image_dimension_2d, caps.max_image_array_layers
                )));
            }
            let levels: Vec<&[u8]> = t.levels.iter().map(Vec::as_slice).collect();
            device
                .upload_image(
                    name,
                    &TexelUpload {
                        format,
                        width: t.width,
                        height: t.height,
                        layers: t.layers,
                        view_type: vk::ImageViewType::TYPE_2D_ARRAY,
                    },
                    &levels,
                )
                .map_err(RenderError::from)
        };
        if let Some(m) = &appearance.material {
            self.uniforms = Some(device.upload_buffer(
                "material.uniforms",
                vk::BufferUsageFlags::UNIFORM_BUFFER,
                bytemuck::bytes_of(&MaterialUniforms::new(m, info)),
            )?);
            self.diffuse = Some(upload("material.diffuse_maps", &m.diffuse)?);
            if let Some(t) = &m.normals {
                self.normals = Some(upload("material.normal_maps", t)?);
            }
            if let Some(t) = &m.heights {
                self.heights = Some(upload("material.height_maps", t)?);
            }
            if let Some(t) = &m.blend_maps {
                self.blend_maps = Some(upload("material.blend_maps", t)?);
            }
            let anisotropy = anisotropy_for(m.anisotropy, &device.caps);
            self.tiling =
                Some(device.create_texture_sampler("material.tiling_sampler", true, anisotropy)?);
        }
        if let Some(t) = &appearance.lightmap {
            self.lightmap = Some(upload("lighting.lightmap", t)?);
        }
        if self.blend_maps.is_some() || self.lightmap.is_some() {
            self.stretched =
                Some(device.create_texture_sampler("material.stretched_sampler", false, None)?);
        }
        Ok(())
    }

    /// (binding, type, stages) of every descriptor this look needs.
    /// `vertex_stages`: the stages that place vertices (for displacement).
    pub fn bindings(
        &self,
        vertex_stages: vk::ShaderStageFlags,
    ) -> Vec<(u32, vk::DescriptorType, vk::ShaderStageFlags)> {
        let frag = vk::ShaderStageFlags::FRAGMENT;
        let displacing = if self.variant.displace {
            frag | vertex_stages
        } else {
            frag
        };
        let sampled = vk::DescriptorType::COMBINED_IMAGE_SAMPLER;
        let mut b = Vec::new();
        if self.uniforms.is_some() {
            b.push((
                BINDING_MATERIAL,
                vk::DescriptorType::UNIFORM_BUFFER,
                displacing,
            ));
        }
        for (image, binding, stages) in [
            (&self.diffuse, BINDING_DIFFUSE_MAPS, frag),
            (&self.normals, BINDING_NORMAL_MAPS, frag),
            (&self.heights, BINDING_HEIGHT_MAPS, vertex_stages),
            (&self.blend_maps, BINDING_BLEND_MAPS, displacing),
            (&self.lightmap, BINDING_LIGHTMAP, frag),
        ] {
            if image.is_some() {
                b.push((binding, sampled, stages));
            }
        }
        b
    }

    /// Points `set`'s bindings (from `bindings`) at the objects.
    pub fn write(&self, device: &Device, set: DescriptorSet) {
        if let Some(u) = &self.uniforms {
            device.write_buffer(
                set,
                BINDING_MATERIAL,
                vk::DescriptorType::UNIFORM_BUFFER,
                u,
                u.desc.size,
            );
        }
        for (image, binding, sampler) in [
            (&self.diffuse, BINDING_DIFFUSE_MAPS, &self.tiling),
            (&self.normals, BINDING_NORMAL_MAPS, &self.tiling),
            (&self.heights, BINDING_HEIGHT_MAPS, &self.tiling),
            (&self.blend_maps, BINDING_BLEND_MAPS, &self.stretched),
            (&self.lightmap, BINDING_LIGHTMAP, &self.stretched),
        ] {
            if let (Some(image), Some(sampler)) = (image, sampler) {
                device.write_sampled_image(set, binding, image, sampler);
            }
        }
    }
}
