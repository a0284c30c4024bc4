//! Vulkan plumbing over ash: instance, device, memory, shaders, queries,
//! render targets. Nothing here knows about terrains. All `unsafe` of the
//! crate lives in this module, and only this module touches raw Vulkan
//! handles: everything it hands out owns its objects and frees them when
//! dropped (see `owned`).

pub mod commands;
pub mod debug;
pub mod descriptors;
pub mod device;
pub mod error;
pub mod instance;
pub mod memory;
pub mod owned;
pub mod pipeline;
pub mod queries;
pub mod shader;
pub mod swapchain;
pub mod target;
pub mod transfer;
pub mod views;

use std::ffi::{c_char, CStr};

pub use device::{sample_count_flag, Capabilities, Device, DisabledFeatures, Fault, Workarounds};
pub use error::{Result, VkError};
pub use instance::Instance;

/// Environment variable that turns validation on for any command.
pub const VALIDATE_ENV: &str = "VKTERRAIN_VALIDATE";
/// Environment variable that picks the device by name for any command.
pub const DEVICE_ENV: &str = "VKTERRAIN_DEVICE";

/// How to open the GPU: every command and the window go through
/// `Gpu::open` with one of these.
#[derive(Clone, Debug, Default)]
pub struct GpuOptions {
    /// VK_LAYER_KHRONOS_validation with synchronization validation (also
    /// on when VKTERRAIN_VALIDATE=1).
    pub validate: bool,
    /// Features to treat as missing, to exercise the fallbacks.
    pub disabled: DisabledFeatures,
    /// Refuse allocations past this many bytes in use.
    pub memory_budget: Option<u64>,
    /// A failure to inject, to see how it is reported.
    pub fault: Option<Fault>,
    /// Instance extensions a window surface needs.
    pub instance_extensions: Vec<*const c_char>,
    /// Device extensions (the swapchain's, for a window).
    pub device_extensions: Vec<&'static CStr>,
    /// Only a device whose name contains this (any case); otherwise
    /// VKTERRAIN_DEVICE's, otherwise the best device.
    pub device: Option<String>,
}

impl GpuOptions {
    /// Whether validation is on: asked for, or by VKTERRAIN_VALIDATE=1.
    pub fn validation(&self) -> bool {
        self.validate || std::env::var(VALIDATE_ENV).is_ok_and(|v| v == "1")
    }

    /// The device name asked for, by option or by VKTERRAIN_DEVICE.
    pub fn device_name(&self) -> Option<String> {
        self.device
            .clone()
            .or_else(|| std::env::var(DEVICE_ENV).ok().filter(|v| !v.is_empty()))
    }
}

/// The GPU a command works with: the device, which owns its instance.
/// Everything made from it holds the device, so the device and instance
/// are destroyed when the last of them goes; `shutdown` reports what
/// validation said by then, leaks included.
pub struct Gpu {
    pub device: Device,
}

/// What validation reported by the time the GPU was torn down.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ValidationReport {
    /// Whether the validation layer was on.
    pub enabled: bool,
    /// Warnings and errors, leaks reported at device destruction included,
    /// plus one per object still alive at shutdown.
    pub count: u32,
    /// The first messages, verbatim.
    pub messages: Vec<String>,
}

impl ValidationReport {
    /// An error naming the count and the first message, unless clean.
    pub fn check(&self) -> Result<()> {
        if self.count == 0 {
            return Ok(());
        }
        Err(VkError::Validation {
            count: self.count,
            first: self.messages.first().cloned().unwrap_or_default(),
        })
    }
}

impl Gpu {
    /// Opens the best device with `options`.
    pub fn open(options: &GpuOptions) -> Result<Self> {
        let instance = Instance::new(options.validation(), &options.instance_extensions)?;
        let device = Device::new(
            instance,
            &options.device_extensions,
            &options.disabled,
            options.device_name().as_deref(),
        )?;
        device.set_memory_budget(options.memory_budget);
        device.set_fault(options.fault);
        Ok(Gpu { device })
    }

    /// Validation warnings and errors so far.
    pub fn validation_messages(&self) -> u32 {
        self.device.instance().validation_log().count()
    }

    pub fn validation_enabled(&self) -> bool {
        self.device.instance().validation_enabled()
    }

    /// Tears the device and instance down and reports what validation said
    /// by the end, their destruction included. An object still alive here
    /// (held elsewhere, or leaked) keeps the device alive: each one counts
    /// as a message naming it, and the device is not destroyed.
    pub fn shutdown(self) -> ValidationReport {
        let log = self.device.instance().validation_log();
        let enabled = self.validation_enabled();
        let _ = self.device.wait_idle();
        let live = self.device.live_objects();
        let others = self.device.holders() - 1;
        drop(self);
        let mut count = log.count();
        let mut messages = log.messages();
        if others > 0 {
            let extra = live.len().max(1);
            count += extra as u32;
            messages.extend(live.iter().map(|object| {
                format!(
                    "leak: {object} is still alive at shutdown, so the device was not destroyed"
                )
            }));
            if live.is_empty() {
                messages.push(format!(
                    "leak: {others} holders of the device are still alive at shutdown"
                ));
            }
        }
        ValidationReport {
            enabled,
            count,
            messages,
        }
    }
}
