//! Descriptor set layouts, pools, sets and samplers.

use ash::vk;

use super::device::Device;
use super::error::{Result, VkResultExt};

impl Device {
    /// (binding, type, stages) per binding, one descriptor each.
    pub fn create_descriptor_set_layout(
        &self,
        bindings: &[(u32, vk::DescriptorType, vk::ShaderStageFlags)],
        name: &str,
    ) -> Result<vk::DescriptorSetLayout> {
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
        let layout = unsafe { self.raw.create_descriptor_set_layout(&info, None) }
            .context("creating a descriptor set layout")?;
        self.set_name(layout, name);
        Ok(layout)
    }

    pub fn destroy_descriptor_set_layout(&self, layout: vk::DescriptorSetLayout) {
        // SAFETY: no pipeline layout or set is still being created from it.
        unsafe { self.raw.destroy_descriptor_set_layout(layout, None) };
    }

    /// A pool for `count` sets of `layout`, whose bindings are `sizes`.
    pub fn allocate_descriptor_sets(
        &self,
        layout: vk::DescriptorSetLayout,
        sizes: &[(vk::DescriptorType, u32)],
        count: u32,
        name: &str,
    ) -> Result<(vk::DescriptorPool, Vec<vk::DescriptorSet>)> {
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
        let pool = unsafe { self.raw.create_descriptor_pool(&info, None) }
            .context("creating a descriptor pool")?;
        self.set_name(pool, &format!("{name}.pool"));
        let layouts = vec![layout; count as usize];
        let alloc = vk::DescriptorSetAllocateInfo::default()
            .descriptor_pool(pool)
            .set_layouts(&layouts);
        // SAFETY: the pool was sized for exactly these sets.
        let sets = match unsafe { self.raw.allocate_descriptor_sets(&alloc) } {
            Ok(sets) => sets,
            Err(r) => {
                // SAFETY: the pool has no sets in use.
                unsafe { self.raw.destroy_descriptor_pool(pool, None) };
                return Err(r).context("allocating descriptor sets");
            }
        };
        for (i, &set) in sets.iter().enumerate() {
            self.set_name(set, &format!("{name}[{i}]"));
        }
        Ok((pool, sets))
    }

    pub fn destroy_descriptor_pool(&self, pool: vk::DescriptorPool) {
        // SAFETY: none of its sets is used by pending work.
        unsafe { self.raw.destroy_descriptor_pool(pool, None) };
    }

    /// Points a uniform- or storage-buffer binding of `set` at `range`
    /// bytes of `buffer`.
    pub fn write_buffer(
        &self,
        set: vk::DescriptorSet,
        binding: u32,
        kind: vk::DescriptorType,
        buffer: vk::Buffer,
        range: u64,
    ) {
        let info = [vk::DescriptorBufferInfo::default()
            .buffer(buffer)
            .range(range)];
        let write = vk::WriteDescriptorSet::default()
            .dst_set(set)
            .dst_binding(binding)
            .descriptor_type(kind)
            .buffer_info(&info);
        // SAFETY: set and buffer belong to this device; the set is not in use.
        unsafe { self.raw.update_descriptor_sets(&[write], &[]) };
    }

    pub fn write_sampled_image(
        &self,
        set: vk::DescriptorSet,
        binding: u32,
        view: vk::ImageView,
        sampler: vk::Sampler,
    ) {
        let info = [vk::DescriptorImageInfo::default()
            .image_view(view)
            .sampler(sampler)
            .image_layout(vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL)];
        let write = vk::WriteDescriptorSet::default()
            .dst_set(set)
            .dst_binding(binding)
            .descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER)
            .image_info(&info);
        // SAFETY: as above.
        unsafe { self.raw.update_descriptor_sets(&[write], &[]) };
    }

    /// Nearest filtering, clamped: for images read with texelFetch, which
    /// ignores the sampler but still needs one bound.
    pub fn create_nearest_sampler(&self, name: &str) -> Result<vk::Sampler> {
        let info = vk::SamplerCreateInfo::default()
            .mag_filter(vk::Filter::NEAREST)
            .min_filter(vk::Filter::NEAREST)
            .mipmap_mode(vk::SamplerMipmapMode::NEAREST)
            .address_mode_u(vk::SamplerAddressMode::CLAMP_TO_EDGE)
            .address_mode_v(vk::SamplerAddressMode::CLAMP_TO_EDGE)
            .address_mode_w(vk::SamplerAddressMode::CLAMP_TO_EDGE);
        // SAFETY: valid create info.
        let sampler =
            unsafe { self.raw.create_sampler(&info, None) }.context("creating a sampler")?;
        self.set_name(sampler, name);
        Ok(sampler)
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
    ) -> Result<vk::Sampler> {
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
        // SAFETY: valid create info; anisotropy only when the caller has
        // checked the feature.
        let sampler =
            unsafe { self.raw.create_sampler(&info, None) }.context("creating a sampler")?;
        self.set_name(sampler, name);
        Ok(sampler)
    }

    pub fn destroy_sampler(&self, sampler: vk::Sampler) {
        // SAFETY: no descriptor set using it is in use.
        unsafe { self.raw.destroy_sampler(sampler, None) };
    }
}
