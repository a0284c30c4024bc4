//! Physical device choice, the logical device, its queue, and object names.

use std::collections::BTreeMap;
use std::ffi::{c_char, CStr, CString};
use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

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
    /// multiDrawIndirect: one indirect draw call reads many commands
    /// (at most `max_draw_indirect_count`).
    pub multi_draw_indirect: bool,
    pub max_draw_indirect_count: u32,
    /// drawIndirectFirstInstance: an indirect command's first instance
    /// may be other than 0 (the geomip path's listed constants).
    pub draw_indirect_first_instance: bool,
    /// fragmentStoresAndAtomics: the terrain's fragment shader counts the
    /// pixels each patch shows in a storage buffer (required).
    pub fragment_stores_and_atomics: bool,
    /// Subgroup vote and ballot operations in fragment shaders: the count
    /// adds once per subgroup of fragments on one patch (required).
    pub fragment_subgroup_ballot: bool,
    /// Nanoseconds per timestamp tick, when the graphics queue has
    /// timestamps.
    pub timestamp_period_ns: Option<f32>,
    pub timestamp_valid_bits: u32,
    pub max_tessellation_level: u32,
    pub max_image_dimension_2d: u32,
    pub max_image_array_layers: u32,
    /// maxSamplerAnisotropy (meaningful with `sampler_anisotropy`).
    pub max_sampler_anisotropy: f32,
    /// subPixelPrecisionBits: the rasteriser snaps vertex positions to
    /// 1/2^bits of a pixel.
    pub sub_pixel_precision_bits: u32,
    /// Samples per pixel that colour and depth attachments both support,
    /// of 1, 2, 4 and 8, ascending.
    pub sample_counts: Vec<u32>,
    /// Samples per pixel of depth attachments the occlusion pyramid can
    /// read (sampled depth of these counts); empty: no occlusion culling.
    pub occlusion_sample_counts: Vec<u32>,
}

impl Capabilities {
    /// Whether one indirect call can draw a frame's geomip patches, each
    /// reading its listed constants by its first instance.
    pub fn lists_geomip_draws(&self) -> bool {
        self.multi_draw_indirect && self.draw_indirect_first_instance
    }

    /// Whether attachments of `samples` samples per pixel can be drawn.
    pub fn supports_samples(&self, samples: u32) -> bool {
        self.sample_counts.contains(&samples)
    }

    /// Whether occlusion culling can read depth drawn at `samples`.
    pub fn supports_occlusion(&self, samples: u32) -> bool {
        self.occlusion_sample_counts.contains(&samples)
    }

    /// "1, 4": the sample counts the device can draw.
    pub fn sample_count_list(&self) -> String {
        self.sample_counts
            .iter()
            .map(u32::to_string)
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// Refuses `samples` samples per pixel where the device cannot draw
    /// them, naming the counts it can.
    pub fn check_samples(&self, samples: u32) -> Result<()> {
        if self.supports_samples(samples) {
            return Ok(());
        }
        Err(VkError::Unsupported(format!(
            "{} cannot draw {samples} samples per pixel (it can draw {})",
            self.device_name,
            self.sample_count_list()
        )))
    }
}

/// How the renderer must work around a driver's faults: kept apart from
/// the device's public capabilities, which say what it can do.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Workarounds {
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

impl DeviceShared {
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

/// The logical device, shared by every object made from it: cloning is
/// cheap, and the device (with its instance) is destroyed when the last
/// clone goes, after waiting for it to go idle. Objects hold a clone, so
/// the device cannot go before them.
#[derive(Clone)]
pub struct Device(Arc<DeviceShared>);

impl std::ops::Deref for Device {
    type Target = DeviceShared;
    fn deref(&self) -> &DeviceShared {
        &self.0
    }
}

/// What a `Device` shares. Fields drop after `Drop::drop` runs, so the
/// instance goes after the device.
pub struct DeviceShared {
    pub caps: Capabilities,
    pub workarounds: Workarounds,
    pub(super) physical: vk::PhysicalDevice,
    pub(super) queue: vk::Queue,
    pub(super) queue_family: u32,
    debug_utils: Option<ash::ext::debug_utils::Device>,
    /// Dropped explicitly before the device (see Drop).
    allocator: ManuallyDrop<Mutex<Allocator>>,
    /// For one-shot uploads; used under its lock.
    transient_pool: Mutex<vk::CommandPool>,
    /// Largest bytes in use allowed; u64::MAX: no limit.
    memory_budget: AtomicU64,
    /// A failure to inject (`set_fault`), and how many submissions and
    /// allocations have been counted towards it.
    fault: Mutex<FaultState>,
    /// Objects alive now, by (type, handle): their names, for the leak
    /// report at shutdown.
    live: Mutex<BTreeMap<(i32, u64), String>>,
    raw: ash::Device,
    instance: Instance,
}

/// Features to treat as missing even where the device has them, to test
/// the fallbacks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DisabledFeatures {
    pub tessellation_shader: bool,
    pub fill_mode_non_solid: bool,
    pub pipeline_statistics_query: bool,
    pub sampler_anisotropy: bool,
    pub multi_draw_indirect: bool,
    pub timestamps: bool,
    /// Sampling depth attachments (occlusion culling).
    pub sampled_depth: bool,
}

impl DisabledFeatures {
    /// Clears what is disabled from `caps`.
    pub fn apply(&self, caps: &mut Capabilities) {
        caps.tessellation_shader &= !self.tessellation_shader;
        caps.fill_mode_non_solid &= !self.fill_mode_non_solid;
        caps.pipeline_statistics_query &= !self.pipeline_statistics_query;
        caps.sampler_anisotropy &= !self.sampler_anisotropy;
        caps.multi_draw_indirect &= !self.multi_draw_indirect;
        if self.timestamps {
            caps.timestamp_period_ns = None;
        }
        if self.sampled_depth {
            caps.occlusion_sample_counts.clear();
        }
    }
}

struct Candidate {
    physical: vk::PhysicalDevice,
    queue_family: u32,
    caps: Capabilities,
    workarounds: Workarounds,
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
        let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
        let mut props2 = vk::PhysicalDeviceProperties2::default()
            .push_next(&mut driver)
            .push_next(&mut subgroup);
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
        let depth_features = instance
            .get_physical_device_format_properties(physical, super::views::DEPTH_FORMAT)
            .optimal_tiling_features;
        let sampled_depth = if depth_features.contains(vk::FormatFeatureFlags::SAMPLED_IMAGE) {
            props.limits.sampled_image_depth_sample_counts
        } else {
            vk::SampleCountFlags::empty()
        };
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
                multi_draw_indirect: features.multi_draw_indirect != 0,
                draw_indirect_first_instance: features.draw_indirect_first_instance != 0,
                fragment_stores_and_atomics: features.fragment_stores_and_atomics != 0,
                fragment_subgroup_ballot: subgroup
                    .supported_stages
                    .contains(vk::ShaderStageFlags::FRAGMENT)
                    && subgroup.supported_operations.contains(
                        vk::SubgroupFeatureFlags::VOTE | vk::SubgroupFeatureFlags::BALLOT,
                    ),
                max_draw_indirect_count: props.limits.max_draw_indirect_count,
                timestamp_period_ns: timestamps.then_some(props.limits.timestamp_period),
                timestamp_valid_bits: family.timestamp_valid_bits,
                max_tessellation_level: props.limits.max_tessellation_generation_level,
                max_image_dimension_2d: props.limits.max_image_dimension2_d,
                max_image_array_layers: props.limits.max_image_array_layers,
                max_sampler_anisotropy: props.limits.max_sampler_anisotropy,
                sub_pixel_precision_bits: props.limits.sub_pixel_precision_bits,
                sample_counts: sample_counts(
                    props.limits.framebuffer_color_sample_counts
                        & props.limits.framebuffer_depth_sample_counts,
                ),
                occlusion_sample_counts: sample_counts(
                    props.limits.framebuffer_color_sample_counts
                        & props.limits.framebuffer_depth_sample_counts
                        & sampled_depth,
                ),
            },
            workarounds: Workarounds {
                max_patches_per_draw: (driver.driver_id == vk::DriverId::MESA_LLVMPIPE)
                    .then_some(8),
            },
        })
    }
}

/// Destroys a freshly created device unless defused: what `Device::new`
/// holds until the device has an owner.
struct DeviceGuard(Option<ash::Device>);

impl Drop for DeviceGuard {
    fn drop(&mut self) {
        if let Some(raw) = self.0.take() {
            // SAFETY: nothing else was made from the device yet, or what was
            // (the allocator, a pool) is dropped before this guard.
            unsafe { raw.destroy_device(None) };
        }
    }
}

impl Device {
    /// Picks the best device of `instance`: one with tessellation shaders
    /// first, then discrete, integrated, virtual, CPU. Optional features it
    /// has are enabled, except those `disabled` asks to behave as missing.
    /// `extensions`: device extensions to enable (the swapchain's). The
    /// device owns the instance from here on.
    /// `named`: only devices whose name contains this (any case).
    pub(super) fn new(
        instance: Instance,
        extensions: &[&CStr],
        disabled: &DisabledFeatures,
        named: Option<&str>,
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
        if let Some(name) = named {
            let found: Vec<String> = candidates
                .iter()
                .map(|c| c.caps.device_name.clone())
                .collect();
            let wanted = name.to_lowercase();
            candidates.retain(|c| c.caps.device_name.to_lowercase().contains(&wanted));
            if candidates.is_empty() {
                return Err(VkError::Unsupported(format!(
                    "no Vulkan device is named like {name:?} (VKTERRAIN_DEVICE or --device); found: {}",
                    if found.is_empty() {
                        "none".to_string()
                    } else {
                        found.join(", ")
                    }
                )));
            }
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
            .sampler_anisotropy(caps.sampler_anisotropy)
            .multi_draw_indirect(caps.multi_draw_indirect)
            .draw_indirect_first_instance(caps.draw_indirect_first_instance)
            .fragment_stores_and_atomics(caps.fragment_stores_and_atomics);
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
        let mut guard = DeviceGuard(Some(
            unsafe { instance.raw.create_device(best.physical, &info, None) }
                .context("creating the Vulkan device")?,
        ));
        let raw = guard.0.clone().expect("set just above");
        // SAFETY: family and index 0 exist: we created the device with them.
        let queue = unsafe { raw.get_device_queue(best.queue_family, 0) };

        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: instance.raw.clone(),
            device: raw.clone(),
            physical_device: best.physical,
            debug_settings: Default::default(),
            buffer_device_address: false,
            allocation_sizes: Default::default(),
        })
        .map_err(|source| VkError::Allocation {
            name: "allocator".into(),
            source,
        })?;
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
        // From here the shared state's Drop destroys the device.
        guard.0 = None;
        let device = Device(Arc::new(DeviceShared {
            physical: best.physical,
            raw,
            queue,
            queue_family: best.queue_family,
            caps,
            workarounds: best.workarounds,
            debug_utils,
            allocator: ManuallyDrop::new(Mutex::new(allocator)),
            transient_pool: Mutex::new(transient_pool),
            memory_budget: AtomicU64::new(u64::MAX),
            fault: Mutex::new(FaultState::default()),
            live: Mutex::new(BTreeMap::new()),
            instance,
        }));
        device.set_name(device.raw.handle(), "vkterrain.device");
        device.set_name(device.queue, "vkterrain.queue");
        device.set_name(transient_pool, "vkterrain.transient_command_pool");
        Ok(device)
    }

    /// Clones of this device alive now, this one included: one per object
    /// made from it, plus its owners.
    pub(super) fn holders(&self) -> usize {
        Arc::strong_count(&self.0)
    }
}

impl DeviceShared {
    pub(super) fn ash(&self) -> &ash::Device {
        &self.raw
    }

    pub(super) fn instance(&self) -> &Instance {
        &self.instance
    }

    pub(super) fn allocator(&self) -> std::sync::MutexGuard<'_, Allocator> {
        self.allocator.lock().expect("allocator lock")
    }

    pub(super) fn transient_pool(&self) -> std::sync::MutexGuard<'_, vk::CommandPool> {
        self.transient_pool.lock().expect("command pool lock")
    }

    /// Refuses allocations that would bring the bytes in use past `budget`
    /// (None: no limit), with an error naming the resource.
    pub fn set_memory_budget(&self, budget: Option<u64>) {
        self.memory_budget
            .store(budget.unwrap_or(u64::MAX), Ordering::Relaxed);
    }

    pub fn memory_budget(&self) -> Option<u64> {
        let b = self.memory_budget.load(Ordering::Relaxed);
        (b != u64::MAX).then_some(b)
    }

    /// Records an owned object as alive until `forget_object`.
    pub(super) fn register_object<H: vk::Handle>(&self, handle: H, name: &str) {
        self.live
            .lock()
            .expect("object registry lock")
            .insert((H::TYPE.as_raw(), handle.as_raw()), name.to_string());
    }

    /// Gives a Vulkan object a debug name (shown by validation messages and
    /// graphics debuggers). A no-op without VK_EXT_debug_utils.
    pub(super) fn set_name<H: vk::Handle>(&self, handle: H, name: &str) {
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

    /// Records that an object from `register_object` was destroyed.
    pub(super) fn forget_object<H: vk::Handle>(&self, handle: H) {
        self.live
            .lock()
            .expect("object registry lock")
            .remove(&(H::TYPE.as_raw(), handle.as_raw()));
    }

    /// Owned objects made from this device and not destroyed yet, as
    /// `BUFFER "name"`.
    pub fn live_objects(&self) -> Vec<String> {
        self.live
            .lock()
            .expect("object registry lock")
            .iter()
            .map(|(&(kind, _), name)| format!("{:?} \"{name}\"", vk::ObjectType::from_raw(kind)))
            .collect()
    }

    /// Format features for optimal tiling.
    pub fn format_features(&self, format: vk::Format) -> vk::FormatFeatureFlags {
        // SAFETY: plain query.
        unsafe {
            self.instance
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

impl Drop for DeviceShared {
    fn drop(&mut self) {
        // Nothing may be in flight when the device goes; an error here
        // (device lost) leaves nothing better to do than tear down anyway.
        let _ = self.wait_idle();
        // SAFETY: every object made from the device holds a clone of it, so
        // none is left when this runs; it is idle. The allocator frees its
        // memory blocks through the device, so it goes before the device.
        // The instance is a field, dropped after this.
        unsafe {
            self.raw
                .destroy_command_pool(*self.transient_pool.get_mut().expect("pool lock"), None);
            ManuallyDrop::drop(&mut self.allocator);
            self.raw.destroy_device(None);
        }
    }
}

/// The counts of 1, 2, 4 and 8 samples per pixel in `flags`.
fn sample_counts(flags: vk::SampleCountFlags) -> Vec<u32> {
    [1u32, 2, 4, 8]
        .into_iter()
        .filter(|&n| flags.contains(sample_count_flag(n)))
        .collect()
}

/// The flag of `n` samples per pixel (1, 2, 4, 8, 16, 32 or 64); 1 for
/// anything else.
pub fn sample_count_flag(n: u32) -> vk::SampleCountFlags {
    match n {
        2 => vk::SampleCountFlags::TYPE_2,
        4 => vk::SampleCountFlags::TYPE_4,
        8 => vk::SampleCountFlags::TYPE_8,
        16 => vk::SampleCountFlags::TYPE_16,
        32 => vk::SampleCountFlags::TYPE_32,
        64 => vk::SampleCountFlags::TYPE_64,
        _ => vk::SampleCountFlags::TYPE_1,
    }
}
