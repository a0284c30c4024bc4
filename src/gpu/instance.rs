//! The Vulkan instance, with the validation layer (synchronization
//! validation included) when asked for.

use std::ffi::{c_char, CStr};
use std::sync::Arc;

use ash::vk;

use super::debug::{messenger_info, ValidationLog};
use super::error::{Result, VkError, VkResultExt};

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// The instance; owned by the `Device` made from it, which destroys it
/// after itself.
pub struct Instance {
    pub(super) entry: ash::Entry,
    pub(super) raw: ash::Instance,
    /// Present when VK_EXT_debug_utils is (object names, messenger).
    pub(super) debug_utils: Option<ash::ext::debug_utils::Instance>,
    messenger: vk::DebugUtilsMessengerEXT,
    /// Shared so that its count can be read after the instance is gone
    /// (messages from destroying the device and instance included).
    validation: Arc<ValidationLog>,
    validation_enabled: bool,
}

impl Instance {
    /// `validate`: enable VK_LAYER_KHRONOS_validation with synchronization
    /// validation, and fail if the layer is missing. `extensions`: extra
    /// instance extensions (a window surface's, say).
    pub(super) fn new(validate: bool, extensions: &[*const c_char]) -> Result<Self> {
        // SAFETY: loading the Vulkan loader runs its initialisers; that is
        // the only way to reach Vulkan.
        let entry = unsafe { ash::Entry::load()? };
        // SAFETY: plain queries on a loaded entry.
        let (layers, available) = unsafe {
            (
                entry
                    .enumerate_instance_layer_properties()
                    .context("listing instance layers")?,
                entry
                    .enumerate_instance_extension_properties(None)
                    .context("listing instance extensions")?,
            )
        };
        let has_layer = layers
            .iter()
            .any(|l| l.layer_name_as_c_str() == Ok(VALIDATION_LAYER));
        if validate && !has_layer {
            return Err(VkError::NoValidationLayer);
        }
        let has_debug_utils = available
            .iter()
            .any(|e| e.extension_name_as_c_str() == Ok(ash::ext::debug_utils::NAME));
        if validate && !has_debug_utils {
            return Err(VkError::Unsupported(
                "validation needs VK_EXT_debug_utils, which this Vulkan loader lacks".into(),
            ));
        }

        let mut extension_names: Vec<*const c_char> = extensions.to_vec();
        if has_debug_utils {
            extension_names.push(ash::ext::debug_utils::NAME.as_ptr());
        }
        if validate {
            // Provided by the validation layer itself.
            extension_names.push(ash::ext::validation_features::NAME.as_ptr());
        }
        let layer_names: Vec<*const c_char> = if validate {
            vec![VALIDATION_LAYER.as_ptr()]
        } else {
            Vec::new()
        };

        let validation = Arc::<ValidationLog>::default();
        let app = vk::ApplicationInfo::default()
            .application_name(c"vkterrain")
            .engine_name(c"vkterrain")
            .api_version(vk::API_VERSION_1_3);
        let enabled_features = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
        let mut features =
            vk::ValidationFeaturesEXT::default().enabled_validation_features(&enabled_features);
        let mut instance_messenger = messenger_info(&validation);
        let mut info = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_extension_names(&extension_names)
            .enabled_layer_names(&layer_names);
        if validate {
            info = info
                .push_next(&mut features)
                .push_next(&mut instance_messenger);
        }
        // SAFETY: every pointer in `info` refers to locals that outlive the call.
        let raw = match unsafe { entry.create_instance(&info, None) } {
            Ok(raw) => raw,
            // The loader's answer when it finds no driver at all.
            Err(vk::Result::ERROR_INCOMPATIBLE_DRIVER) => return Err(VkError::NoDevice),
            Err(result) => {
                return Err(VkError::Call {
                    context: "creating the Vulkan instance",
                    result,
                })
            }
        };

        let debug_utils =
            has_debug_utils.then(|| ash::ext::debug_utils::Instance::new(&entry, &raw));
        let messenger = match (&debug_utils, validate) {
            (Some(utils), true) => {
                // SAFETY: the log is behind an Arc the instance holds, so
                // its address is stable for as long as the messenger exists
                // (see Drop).
                let created = unsafe {
                    utils.create_debug_utils_messenger(&messenger_info(&validation), None)
                };
                match created {
                    Ok(m) => m,
                    Err(result) => {
                        // SAFETY: nothing else was created from the instance.
                        unsafe { raw.destroy_instance(None) };
                        return Err(VkError::Call {
                            context: "creating the debug messenger",
                            result,
                        });
                    }
                }
            }
            _ => vk::DebugUtilsMessengerEXT::null(),
        };
        Ok(Instance {
            entry,
            raw,
            debug_utils,
            messenger,
            validation,
            validation_enabled: validate,
        })
    }

    /// Warnings and errors the validation layer reported; readable after
    /// the instance is destroyed.
    pub(super) fn validation_log(&self) -> Arc<ValidationLog> {
        Arc::clone(&self.validation)
    }

    pub fn validation_enabled(&self) -> bool {
        self.validation_enabled
    }
}

impl Drop for Instance {
    fn drop(&mut self) {
        // SAFETY: the device that owns this instance is destroyed first; the messenger
        // goes before the instance it belongs to, and before the log it
        // points at is freed.
        unsafe {
            if let Some(utils) = &self.debug_utils {
                if self.messenger != vk::DebugUtilsMessengerEXT::null() {
                    utils.destroy_debug_utils_messenger(self.messenger, None);
                }
            }
            self.raw.destroy_instance(None);
        }
    }
}
