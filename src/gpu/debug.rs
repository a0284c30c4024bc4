//! Validation messages: a debug-utils messenger that logs every warning and
//! error and counts them, so tests can fail on any.

use std::ffi::CStr;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Mutex;

use ash::vk;

/// How many messages to keep verbatim for reports; the count goes on.
const KEPT_MESSAGES: usize = 32;

/// Counts validation warnings and errors. Lives in an `Arc` whose address
/// the messenger holds, so it must outlive the messenger (the instance owns
/// both and destroys the messenger first).
#[derive(Default, Debug)]
pub struct ValidationLog {
    count: AtomicU32,
    messages: Mutex<Vec<String>>,
}

impl ValidationLog {
    /// Warnings and errors reported so far.
    pub fn count(&self) -> u32 {
        self.count.load(Ordering::SeqCst)
    }

    /// The first few messages, verbatim.
    pub fn messages(&self) -> Vec<String> {
        self.messages.lock().map(|m| m.clone()).unwrap_or_default()
    }

    fn record(&self, severity: vk::DebugUtilsMessageSeverityFlagsEXT, text: String) {
        self.count.fetch_add(1, Ordering::SeqCst);
        if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR) {
            log::error!("vulkan: {text}");
        } else {
            log::warn!("vulkan: {text}");
        }
        if let Ok(mut kept) = self.messages.lock() {
            if kept.len() < KEPT_MESSAGES {
                kept.push(text);
            }
        }
    }
}

/// The messenger's create info; also chained into instance creation so
/// messages from vkCreateInstance/vkDestroyInstance are caught.
pub fn messenger_info(log: &ValidationLog) -> vk::DebugUtilsMessengerCreateInfoEXT<'static> {
    vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(
            vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
        )
        .message_type(
            vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
        )
        .pfn_user_callback(Some(on_message))
        .user_data(log as *const ValidationLog as *mut std::ffi::c_void)
}

unsafe extern "system" fn on_message(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _kind: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user_data: *mut std::ffi::c_void,
) -> vk::Bool32 {
    // SAFETY: the loader passes valid callback data for the duration of the
    // call; `user_data` is the `ValidationLog` registered with the
    // messenger, which outlives it.
    unsafe {
        let text = if data.is_null() || (*data).p_message.is_null() {
            "(no message)".to_string()
        } else {
            CStr::from_ptr((*data).p_message)
                .to_string_lossy()
                .into_owned()
        };
        if let Some(log) = (user_data as *const ValidationLog).as_ref() {
            log.record(severity, text);
        }
    }
    vk::FALSE
}
