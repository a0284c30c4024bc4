//! Descriptor set layouts, pools, sets and samplers.

use ash::vk;

use super::device::Device;
use super::error::{Result, VkError, VkResultExt};
use super::memory::{Buffer, Image};
use super::owned::{DescriptorSetLayout, Owned, Sampler};
use super::views::TargetViews;

/// One descriptor set of a `DescriptorSets`; valid while they are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DescriptorSet(pub(super) vk::DescriptorSet);

/// Sets of one layout and the pool they came from, which frees them.
pub struct DescriptorSets {
    sets: Vec<DescriptorSet>,
    _pool: Owned<vk::DescriptorPool>,
}

impl DescriptorSets {
    pub fn get(&self, i: usize) -> DescriptorSet {
        self.sets[i]
    }

    pub fn iter(&self) -> impl Iterator<Item = DescriptorSet> + '_ {
        self.sets.iter().copied()
    }
}

impl Device {
    /// (binding, type, stages) per binding, one descriptor each.
    pub fn create_descriptor_set_layout(
        &self,
        bindings: &[(u32, vk::DescriptorType, vk::ShaderStageFlags)],
        name: &str,
    ) -> Result<DescriptorSetLayout> {
        let bindings: Vec<vk::DescriptorSetLayoutBinding> = bindings
            .iter()
            .map(|&(binding, kind, stages)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(binding)
                    .descriptor_type(kind)
                    .descriptor_count(1)
                    .stage_flags(stages)
            })
            .collect();
        let info = vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings);
        // SAFETY: valid create info.
        let layout = unsafe { self.ash().create_descriptor_set_layout(&info, None) }
            .context("creating a descriptor set layout")?;
        Ok(Owned::new(self, layout, name))
    }

    /// A pool for `count` sets of `layout`, whose bindings are `sizes`.
    pub fn allocate_descriptor_sets(
        &self,
        layout: &DescriptorSetLayout,
        sizes: &[(vk::DescriptorType, u32)],
        count: u32,
        name: &str,
    ) -> Result<DescriptorSets> {
        let sizes: Vec<vk::DescriptorPoolSize> = sizes
            .iter()
            .map(|&(ty, n)| {
                vk::DescriptorPoolSize::default()
                    .ty(ty)
                    .descriptor_count(n * count)
            })
            .collect();
        let info = vk::DescriptorPoolCreateInfo::default()
            .max_sets(count)
            .pool_sizes(&sizes);
        // SAFETY: valid create info.
        let pool = unsafe { self.ash().create_descriptor_pool(&info, None) }
            .context("creating a descriptor pool")?;
        let pool = Owned::new(self, pool, &format!("{name}.pool"));
        let layouts = vec![layout.raw(); count as usize];
        let alloc = vk::DescriptorSetAllocateInfo::default()
            .descriptor_pool(pool.raw())
            .set_layouts(&layouts);
        // SAFETY: the pool was sized for exactly these sets.
        let sets = unsafe { self.ash().allocate_descriptor_sets(&alloc) }
            .context("allocating descriptor sets")?;
        for (i, &set) in sets.iter().enumerate() {
            self.set_name(set, &format!("{name}[{i}]"));
        }
        Ok(DescriptorSets {
            sets: sets.into_iter().map(DescriptorSet).collect(),
            _pool: pool,
        })
    }

    /// Points a uniform- or storage-buffer binding of `set` at `range`
    /// bytes of `buffer`.
    pub fn write_buffer(
        &self,
        set: DescriptorSet,
        binding: u32,
        kind: vk::DescriptorType,
        buffer: &Buffer,
        range: u64,
    ) {
        let info = [vk::DescriptorBufferInfo::default()
            .buffer(buffer.raw())
            .range(range)];
        let write = vk::WriteDescriptorSet::default()
            .dst_set(set.0)
            .dst_binding(binding)
            .descriptor_type(kind)
            .buffer_info(&info);
        // SAFETY: set and buffer belong to this device; the set is not in use.
        unsafe { self.ash().update_descriptor_sets(&[write], &[]) };
    }

    pub fn write_sampled_image(
        &self,
        set: DescriptorSet,
        binding: u32,
        image: &Image,
        sampler: &Sampler,
    ) {
        self.write_image_view(
            set,
            binding,
            image.view(),
            sampler,
            vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
        );
    }

    /// Points a combined-image-sampler binding at `target`'s depth, read in
    /// SHADER_READ_ONLY_OPTIMAL (see `Recorder::depth_to_compute`).
    pub fn write_target_depth(
        &self,
        set: DescriptorSet,
        binding: u32,
        target: &TargetViews,
        sampler: &Sampler,
    ) {
        self.write_image_view(
            set,
            binding,
            target.depth_view,
            sampler,
            vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
        );
    }

    fn write_image_view(
        &self,
        set: DescriptorSet,
        binding: u32,
        view: vk::ImageView,
        sampler: &Sampler,
        layout: vk::ImageLayout,
    ) {
        let info = [vk::DescriptorImageInfo::default()
            .image_view(view)
            .sampler(sampler.raw())
            .image_layout(layout)];
        let write = vk::WriteDescriptorSet::default()
            .dst_set(set.0)
            .dst_binding(binding)
            .descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER)
            .image_info(&info);
        // SAFETY: as above.
        unsafe { self.ash().update_descriptor_sets(&[write], &[]) };
    }

    /// Nearest filtering, clamped: for images read with texelFetch, which
    /// ignores the sampler but still needs one bound.
    pub fn create_nearest_sampler(&self, name: &str) -> Result<Sampler> {
        let info = vk::SamplerCreateInfo::default()
            .mag_filter(vk::Filter::NEAREST)
            .min_filter(vk::Filter::NEAREST)
            .mipmap_mode(vk::SamplerMipmapMode::NEAREST)
            .address_mode_u(vk::SamplerAddressMode::CLAMP_TO_EDGE)
            .address_mode_v(vk::SamplerAddressMode::CLAMP_TO_EDGE)
            .address_mode_w(vk::SamplerAddressMode::CLAMP_TO_EDGE);
        // SAFETY: valid create info.
        let sampler =
            unsafe { self.ash().create_sampler(&info, None) }.context("creating a sampler")?;
        Ok(Owned::new(self, sampler, name))
    }

    /// Linear filtering across levels for textures: `repeat` tiles them
    /// (layer textures), otherwise they clamp to the edge (maps stretched
    /// over the terrain). Anisotropic filtering at up to `anisotropy`
    /// samples when given (the device feature must be on).
    pub fn create_texture_sampler(
        &self,
        name: &str,
        repeat: bool,
        anisotropy: Option<f32>,
    ) -> Result<Sampler> {
        if anisotropy.is_some() && !self.caps.sampler_anisotropy {
            return Err(VkError::Unsupported(format!(
                "{name}: anisotropic filtering needs samplerAnisotropy, which {} lacks",
                self.caps.device_name
            )));
        }
        let address = if repeat {
            vk::SamplerAddressMode::REPEAT
        } else {
            vk::SamplerAddressMode::CLAMP_TO_EDGE
        };
        let info = vk::SamplerCreateInfo::default()
            .mag_filter(vk::Filter::LINEAR)
            .min_filter(vk::Filter::LINEAR)
            .mipmap_mode(vk::SamplerMipmapMode::LINEAR)
            .address_mode_u(address)
            .address_mode_v(address)
            .address_mode_w(vk::SamplerAddressMode::CLAMP_TO_EDGE)
            .max_lod(vk::LOD_CLAMP_NONE)
            .anisotropy_enable(anisotropy.is_some())
            .max_anisotropy(anisotropy.unwrap_or(1.0));
        // SAFETY: valid create info; anisotropy only with the feature
        // (checked above).
        let sampler =
            unsafe { self.ash().create_sampler(&info, None) }.context("creating a sampler")?;
        Ok(Owned::new(self, sampler, name))
    }
}
