//! Vulkan objects that free themselves. Every handle the crate creates is
//! wrapped, as soon as it exists, in an owner that destroys it on drop and
//! holds the device it needs to do so. A constructor that fails part-way
//! therefore frees exactly what it had built, with no cleanup code of its
//! own, and nothing can be freed twice or forgotten.
//!
//! The one rule left to owners is the GPU's: an object must not be dropped
//! while submitted work still uses it. Every owner of per-frame work waits
//! for the device to go idle in its own `Drop` before its fields go
//! (`TerrainRenderer`, `Headless`, `CommandSlots`, `Swapchain`, `Surface`), and
//! one-shot submissions are waited for before they return.

use ash::vk;

use super::device::Device;

/// A handle type the device destroys with one call.
pub trait DeviceChild: vk::Handle + Copy {
    /// # Safety
    /// `self` was created from `device`, is destroyed once, and no pending
    /// GPU work uses it.
    unsafe fn destroy(self, device: &ash::Device);
}

macro_rules! device_child {
    ($($ty:ty => $destroy:ident),* $(,)?) => {$(
        impl DeviceChild for $ty {
            unsafe fn destroy(self, device: &ash::Device) {
                // SAFETY: forwarded from the trait's contract.
                unsafe { device.$destroy(self, None) }
            }
        }
    )*};
}

device_child! {
    vk::Buffer => destroy_buffer,
    vk::Image => destroy_image,
    vk::ImageView => destroy_image_view,
    vk::Sampler => destroy_sampler,
    vk::DescriptorSetLayout => destroy_descriptor_set_layout,
    vk::DescriptorPool => destroy_descriptor_pool,
    vk::PipelineLayout => destroy_pipeline_layout,
    vk::Pipeline => destroy_pipeline,
    vk::ShaderModule => destroy_shader_module,
    vk::CommandPool => destroy_command_pool,
    vk::Fence => destroy_fence,
    vk::Semaphore => destroy_semaphore,
    vk::QueryPool => destroy_query_pool,
}

/// One Vulkan object, destroyed when dropped.
pub struct Owned<H: DeviceChild> {
    raw: H,
    device: Device,
}

impl<H: DeviceChild> Owned<H> {
    /// Takes ownership of `raw`, just created from `device`, and names it.
    pub(super) fn new(device: &Device, raw: H, name: &str) -> Self {
        device.set_name(raw, name);
        device.register_object(raw, name);
        Owned {
            raw,
            device: device.clone(),
        }
    }

    pub(super) fn raw(&self) -> H {
        self.raw
    }

    pub(super) fn device(&self) -> &Device {
        &self.device
    }
}

impl<H: DeviceChild> Drop for Owned<H> {
    fn drop(&mut self) {
        // SAFETY: `raw` came from this device (see `new`) and is destroyed
        // only here; owners of submitted work wait for idle before they
        // drop (module docs).
        unsafe { self.raw.destroy(self.device.ash()) };
        self.device.forget_object(self.raw);
    }
}

impl<H: DeviceChild + std::fmt::Debug> std::fmt::Debug for Owned<H> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Owned({:?})", self.raw)
    }
}

pub type Sampler = Owned<vk::Sampler>;
pub type DescriptorSetLayout = Owned<vk::DescriptorSetLayout>;
pub type PipelineLayout = Owned<vk::PipelineLayout>;
pub type Pipeline = Owned<vk::Pipeline>;
pub type Fence = Owned<vk::Fence>;
pub type Semaphore = Owned<vk::Semaphore>;
