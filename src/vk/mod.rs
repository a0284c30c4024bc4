//! Vulkan plumbing over ash: instance, device, memory, shaders, queries,
//! render targets. Nothing here knows about terrains. All `unsafe` of the
//! crate lives in this module.

pub mod commands;
pub mod debug;
pub mod descriptors;
pub mod device;
pub mod error;
pub mod instance;
pub mod memory;
pub mod pipeline;
pub mod queries;
pub mod shader;
pub mod swapchain;
pub mod target;

pub use device::{Capabilities, Device, DisabledFeatures, Fault};
pub use error::{Result, VkError};
pub use instance::Instance;

/// Environment variable that turns validation on for any command.
pub const VALIDATE_ENV: &str = "VKTERRAIN_VALIDATE";

/// The instance and device, torn down in the right order: wait for the GPU,
/// then the device (which frees its allocator), then the instance (whose
/// messenger goes last). Fields drop in declaration order.
pub struct Gpu {
    pub device: Device,
    pub instance: Instance,
}

impl Gpu {
    /// `validate`: VK_LAYER_KHRONOS_validation with synchronization
    /// validation (also on when VKTERRAIN_VALIDATE=1).
    pub fn new(validate: bool) -> Result<Self> {
        Gpu::with_disabled(validate, &DisabledFeatures::default())
    }

    /// As `new`, treating the `disabled` features as missing.
    pub fn with_disabled(validate: bool, disabled: &DisabledFeatures) -> Result<Self> {
        let validate = validate || std::env::var(VALIDATE_ENV).is_ok_and(|v| v == "1");
        let instance = Instance::new(validate, &[])?;
        let device = Device::new(&instance, &[], disabled)?;
        Ok(Gpu { device, instance })
    }

    /// Validation warnings and errors so far.
    pub fn validation_messages(&self) -> u32 {
        self.instance.validation_log().count()
    }

    /// Tears everything down and returns how many validation messages were
    /// reported by the end, the device's destruction included (objects
    /// still alive then are reported as leaks), with the first ones' text.
    pub fn shutdown(self) -> (u32, Vec<String>) {
        let _ = self.device.wait_idle();
        let this = std::mem::ManuallyDrop::new(self);
        // SAFETY: `this` is wrapped in ManuallyDrop and never touched again,
        // so each field is moved out exactly once and dropped exactly once,
        // in the order `Drop` would use (device, then instance).
        let (device, instance) =
            unsafe { (std::ptr::read(&this.device), std::ptr::read(&this.instance)) };
        drop(device);
        let log = instance.validation_log();
        let reported = (log.count(), log.messages());
        drop(instance);
        reported
    }
}

impl Drop for Gpu {
    fn drop(&mut self) {
        // Nothing may be in flight when the device goes; an error here
        // (device lost) leaves nothing better to do than tear down anyway.
        let _ = self.device.wait_idle();
    }
}
