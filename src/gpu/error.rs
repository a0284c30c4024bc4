//! The Vulkan layer's error type. `SUBOPTIMAL`/`OUT_OF_DATE` are not errors
//! here: the swapchain code treats them as "rebuild".

use ash::vk;

#[derive(Debug, thiserror::Error)]
pub enum VkError {
    #[error("cannot load the Vulkan loader (libvulkan.so.1): {0}; install a Vulkan driver (apt-get install libvulkan1 mesa-vulkan-drivers)")]
    Loading(#[from] ash::LoadingError),

    #[error("{context}: {result}")]
    Call {
        context: &'static str,
        result: vk::Result,
    },

    #[error("no Vulkan device found; install a driver (apt-get install mesa-vulkan-drivers for lavapipe)")]
    NoDevice,

    #[error("the validation layer VK_LAYER_KHRONOS_validation is not installed (apt-get install vulkan-validationlayers)")]
    NoValidationLayer,

    #[error("{0}")]
    Unsupported(String),

    #[error("the validation layer reported {count} messages; the first: {first}")]
    Validation { count: u32, first: String },

    #[error(
        "GPU memory for {name}: {requested} bytes would bring the {in_use} in use past the \
         budget of {budget} bytes (--gpu-memory-budget)"
    )]
    OverBudget {
        name: String,
        requested: u64,
        in_use: u64,
        budget: u64,
    },

    /// The allocator's reason follows as the error's source.
    #[error("GPU memory for {name}")]
    Allocation {
        name: String,
        #[source]
        source: gpu_allocator::AllocationError,
    },
}

impl From<vk::Result> for VkError {
    fn from(result: vk::Result) -> Self {
        VkError::Call {
            context: "Vulkan call",
            result,
        }
    }
}

pub type Result<T> = std::result::Result<T, VkError>;

/// Attaches what was being done to a raw Vulkan result.
pub trait VkResultExt<T> {
    fn context(self, context: &'static str) -> Result<T>;
}

impl<T> VkResultExt<T> for std::result::Result<T, vk::Result> {
    fn context(self, context: &'static str) -> Result<T> {
        self.map_err(|result| VkError::Call { context, result })
    }
}
