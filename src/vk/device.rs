//! Physical device choice, the logical device, its queue, and object names.

use std::collections::BTreeMap;
use std::ffi::{c_char, CStr, CString};
use std::mem::ManuallyDrop;
use std::sync::Mutex;

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};

use super::error::{Result, VkError, VkResultExt};
use super::instance::Instance;

/// What the chosen device offers that the renderer cares about.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Capabilities {
    pub device_name: String,
    pub device_type: String,
    pub driver_name: String,
    pub driver_info: String,
    pub api_version: String,
    pub tessellation_shader: bool,
    pub fill_mode_non_solid: bool,
    pub pipeline_statistics_query: bool,
    /// Anisotropic texture filtering (enabled when present; for textured
    /// materials).
    pub sampler_anisotropy: bool,
    /// Nanoseconds per timestamp tick, when the graphics queue has
    /// timestamps.
    pub timestamp_period_ns: Option<f32>,
    pub timestamp_valid_bits: u32,
    pub max_tessellation_level: u32,
    pub max_image_dimension_2d: u32,
    pub max_image_array_layers: u32,
    /// maxSamplerAnisotropy (meaningful with `sampler_anisotropy`).
    pub max_sampler_anisotropy: f32,
    /// Patches one tessellated draw may hold on this driver; None: no limit.
    ///
    /// lavapipe (Mesa 22.3) drops whole runs of triangles from a draw whose
    /// tessellation output grows large (measured: 570 patches at factor 16
    /// lose about a third of their area, while 64 patches per draw render
    /// complete; 16 patches at factor 64 are still complete). Eight patches at
    /// factor 64 stay well inside what renders correctly.
    pub max_patches_per_draw: Option<u32>,
}

/// A failure the device can be told to report, to test how it surfaces:
/// the `n`th queue submission (from 1, uploads included) and every one
/// after it report VK_ERROR_DEVICE_LOST, or the `n`th allocation reports
/// VK_ERROR_OUT_OF_DEVICE_MEMORY.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    DeviceLost { submission: u32 },
    OutOfDeviceMemory { allocation: u32 },
}

#[derive(Debug, Default)]
pub(super) struct FaultState {
    fault: Option<Fault>,
    submissions: u32,
    allocations: u32,
}

impl Device {
    /// Arms (or with None, disarms) an injected failure.
    pub fn set_fault(&self, fault: Option<Fault>) {
        *self.fault.lock().expect("fault lock") = FaultState {
            fault,
            ..FaultState::default()
        };
    }

    /// Counts a queue submission; Err when it is to be reported lost.
    pub(super) fn count_submission(&self) -> Result<()> {
        let mut state = self.fault.lock().expect("fault lock");
        state.submissions += 1;
        match state.fault {
            Some(Fault::DeviceLost { submission }) if state.submissions >= submission => {
                Err(vk::Result::ERROR_DEVICE_LOST)
            }
            _ => Ok(()),
        }
        .context("submitting commands (injected fault)")
    }

    /// Counts an allocation; Err when it is to fail.
    pub(super) fn count_allocation(&self, name: &str) -> Result<()> {
        let mut state = self.fault.lock().expect("fault lock");
        state.allocations += 1;
        match state.fault {
            Some(Fault::OutOfDeviceMemory { allocation }) if state.allocations == allocation => {
                Err(VkError::Allocation {
                    name: format!("{name} (injected fault)"),
                    source: gpu_allocator::AllocationError::OutOfMemory,
                })
            }
            _ => Ok(()),
        }
    }
}

pub struct Device {
    pub physical: vk::PhysicalDevice,
    pub raw: ash::Device,
    pub queue: vk::Queue,
    pub queue_family: u32,
    pub caps: Capabilities,
    debug_utils: Option<ash::ext::debug_utils::Device>,
    /// Dropped explicitly before the device (see Drop).
    pub(super) allocator: ManuallyDrop<Mutex<Allocator>>,
    /// Bytes allocated per resource name, for memory reports.
    pub(super) memory: Mutex<BTreeMap<String, u64>>,
    pub(super) transient_pool: vk::CommandPool,
    /// Largest bytes in use allowed; u64::MAX: no limit.
    pub(super) memory_budget: std::sync::atomic::AtomicU64,
    /// A failure to inject (`set_fault`), and how many submissions and
    /// allocations have been counted towards it.
    pub(super) fault: std::sync::Mutex<FaultState>,
}

/// Features to treat as missing even where the device has them, to test
/// the fallbacks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DisabledFeatures {
    pub tessellation_shader: bool,
    pub fill_mode_non_solid: bool,
    pub pipeline_statistics_query: bool,
    pub sampler_anisotropy: bool,
    pub timestamps: bool,
}

impl DisabledFeatures {
    /// Clears what is disabled from `caps`.
    pub fn apply(&self, caps: &mut Capabilities) {
        caps.tessellation_shader &= !self.tessellation_shader;
        caps.fill_mode_non_solid &= !self.fill_mode_non_solid;
        caps.pipeline_statistics_query &= !self.pipeline_statistics_query;
        caps.sampler_anisotropy &= !self.sampler_anisotropy;
        if self.timestamps {
            caps.timestamp_period_ns = None;
        }
    }
}

struct Candidate {
    physical: vk::PhysicalDevice,
    queue_family: u32,
    caps: Capabilities,
    rank: u32,
}

fn device_type_name(t: vk::PhysicalDeviceType) -> (&'static str, u32) {
    match t {
        vk::PhysicalDeviceType::DISCRETE_GPU => ("discrete GPU", 4),
        vk::PhysicalDeviceType::INTEGRATED_GPU => ("integrated GPU", 3),
        vk::PhysicalDeviceType::VIRTUAL_GPU => ("virtual GPU", 2),
        vk::PhysicalDeviceType::CPU => ("CPU", 1),
        _ => ("other", 0),
    }
}

fn c_chars_to_string(chars: &[c_char]) -> String {
    // SAFETY: Vulkan fixed-size strings are NUL-terminated within the array.
    unsafe { CStr::from_ptr(chars.as_ptr()) }
        .to_string_lossy()
        .into_owned()
}

/// Describes one physical device; None when it can't run us at all (no
/// Vulkan 1.3, no graphics queue, no dynamic rendering).
fn inspect(instance: &ash::Instance, physical: vk::PhysicalDevice) -> Option<Candidate> {
    // SAFETY: queries on a physical device enumerated from this instance.
    unsafe {
        let mut driver = vk::PhysicalDeviceDriverProperties::default();
        let mut props2 = vk::PhysicalDeviceProperties2::default().push_next(&mut driver);
        instance.get_physical_device_properties2(physical, &mut props2);
        let props = props2.properties;
        let mut v13 = vk::PhysicalDeviceVulkan13Features::default();
        let mut features2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut v13);
        instance.get_physical_device_features2(physical, &mut features2);
        let features = features2.features;
        let families = instance.get_physical_device_queue_family_properties(physical);
        let (queue_family, family) = families
            .iter()
            .enumerate()
            .find(|(_, f)| f.queue_flags.contains(vk::QueueFlags::GRAPHICS))?;
        if props.api_version < vk::API_VERSION_1_3
            || v13.dynamic_rendering == 0
            || v13.synchronization2 == 0
        {
            return None;
        }
        let (type_name, rank) = device_type_name(props.device_type);
        let timestamps = family.timestamp_valid_bits > 0 && props.limits.timestamp_period > 0.0;
        let v = props.api_version;
        Some(Candidate {
            physical,
            queue_family: queue_family as u32,
            rank,
            caps: Capabilities {
                device_name: c_chars_to_string(&props.device_name),
                device_type: type_name.to_string(),
                driver_name: c_chars_to_string(&driver.driver_name),
                driver_info: c_chars_to_string(&driver.driver_info),
                api_version: format!(
                    "{}.{}.{}",
                    vk::api_version_major(v),
                    vk::api_version_minor(v),
                    vk::api_version_patch(v)
                ),
                tessellation_shader: features.tessellation_shader != 0,
                fill_mode_non_solid: features.fill_mode_non_solid != 0,
                pipeline_statistics_query: features.pipeline_statistics_query != 0,
                sampler_anisotropy: features.sampler_anisotropy != 0,
                timestamp_period_ns: timestamps.then_some(props.limits.timestamp_period),
                timestamp_valid_bits: family.timestamp_valid_bits,
                max_tessellation_level: props.limits.max_tessellation_generation_level,
                max_image_dimension_2d: props.limits.max_image_dimension2_d,
                max_image_array_layers: props.limits.max_image_array_layers,
                max_sampler_anisotropy: props.limits.max_sampler_anisotropy,
                max_patches_per_draw: (driver.driver_id == vk::DriverId::MESA_LLVMPIPE)
                    .then_some(8),
            },
        })
    }
}

impl Device {
    /// Picks the best device: one with tessellation shaders first, then
    /// discrete, integrated, virtual, CPU. Optional features it has are
    /// enabled, except those `disabled` asks to behave as missing.
    /// `extensions`: device extensions to enable (the swapchain's).
    pub fn new(
        instance: &Instance,
        extensions: &[&CStr],
        disabled: &DisabledFeatures,
    ) -> Result<Self> {
        // SAFETY: enumerating devices of a live instance.
        let physicals = unsafe { instance.raw.enumerate_physical_devices() }
            .context("listing Vulkan devices")?;
        let mut candidates: Vec<Candidate> = physicals
            .iter()
            .filter_map(|&p| inspect(&instance.raw, p))
            .collect();
        for c in &mut candidates {
            disabled.apply(&mut c.caps);
        }
        let best = candidates
            .into_iter()
            .max_by_key(|c| (c.caps.tessellation_shader, c.rank))
            .ok_or(VkError::NoDevice)?;
        let caps = best.caps;
        let features = vk::PhysicalDeviceFeatures::default()
            .tessellation_shader(caps.tessellation_shader)
            .fill_mode_non_solid(caps.fill_mode_non_solid)
            .pipeline_statistics_query(caps.pipeline_statistics_query)
            .sampler_anisotropy(caps.sampler_anisotropy);
        let mut v13 = vk::PhysicalDeviceVulkan13Features::default()
            .dynamic_rendering(true)
            .synchronization2(true);
        let priorities = [1.0f32];
        let queue_info = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(best.queue_family)
            .queue_priorities(&priorities)];
        let extension_names: Vec<*const c_char> = extensions.iter().map(|e| e.as_ptr()).collect();
        let info = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queue_info)
            .enabled_features(&features)
            .enabled_extension_names(&extension_names)
            .push_next(&mut v13);
        // SAFETY: the create info points at locals alive for the call.
        let raw = unsafe { instance.raw.create_device(best.physical, &info, None) }
            .context("creating the Vulkan device")?;
        // SAFETY: family and index 0 exist: we created the device with them.
        let queue = unsafe { raw.get_device_queue(best.queue_family, 0) };

        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: instance.raw.clone(),
            device: raw.clone(),
            physical_device: best.physical,
            debug_settings: Default::default(),
            buffer_device_address: false,
            allocation_sizes: Default::default(),
        });
        let allocator = match allocator {
            Ok(a) => a,
            Err(source) => {
                // SAFETY: nothing was created from the device yet.
                unsafe { raw.destroy_device(None) };
                return Err(VkError::Allocation {
                    name: "allocator".into(),
                    source,
                });
            }
        };
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(best.queue_family)
            .flags(
                vk::CommandPoolCreateFlags::TRANSIENT
                    | vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER,
            );
        // SAFETY: valid device and create info.
        let transient_pool = unsafe { raw.create_command_pool(&pool_info, None) }
            .context("creating a command pool")?;
        let debug_utils = instance
            .debug_utils
            .as_ref()
            .map(|_| ash::ext::debug_utils::Device::new(&instance.raw, &raw));
        let device = Device {
            physical: best.physical,
            raw,
            queue,
            queue_family: best.queue_family,
            caps,
            debug_utils,
            allocator: ManuallyDrop::new(Mutex::new(allocator)),
            memory: Mutex::new(BTreeMap::new()),
            transient_pool,
            memory_budget: std::sync::atomic::AtomicU64::new(u64::MAX),
            fault: std::sync::Mutex::new(FaultState::default()),
        };
        device.set_name(device.raw.handle(), "vkterrain.device");
        device.set_name(device.queue, "vkterrain.queue");
        device.set_name(transient_pool, "vkterrain.transient_command_pool");
        Ok(device)
    }

    /// Gives a Vulkan object a debug name (shown by validation messages and
    /// graphics debuggers). A no-op without VK_EXT_debug_utils.
    pub fn set_name<H: vk::Handle>(&self, handle: H, name: &str) {
        let Some(utils) = &self.debug_utils else {
            return;
        };
        let Ok(name) = CString::new(name) else {
            return;
        };
        let info = vk::DebugUtilsObjectNameInfoEXT::default()
            .object_handle(handle)
            .object_name(&name);
        // SAFETY: the handle belongs to this device; a failure only loses
        // the name, so it is ignored on purpose.
        let _ = unsafe { utils.set_debug_utils_object_name(&info) };
    }

    /// Format features for optimal tiling.
    pub fn format_features(
        &self,
        instance: &Instance,
        format: vk::Format,
    ) -> vk::FormatFeatureFlags {
        // SAFETY: plain query.
        unsafe {
            instance
                .raw
                .get_physical_device_format_properties(self.physical, format)
                .optimal_tiling_features
        }
    }

    /// Waits until the device is idle (before teardown or resizes).
    pub fn wait_idle(&self) -> Result<()> {
        // SAFETY: valid device.
        unsafe { self.raw.device_wait_idle() }.context("waiting for the device")
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: the owner has destroyed every object made from this device
        // and waited for it to go idle. The allocator frees its memory blocks
        // through the device, so it goes before the device.
        unsafe {
            self.raw.destroy_command_pool(self.transient_pool, None);
            ManuallyDrop::drop(&mut self.allocator);
            self.raw.destroy_device(None);
        }
    }
}
