//! What the renderer reports when building it or drawing a frame fails:
//! the Vulkan layer's errors, and conditions of its own.

use crate::gpu::VkError;

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A Vulkan call, an allocation, the budget or validation.
    #[error(transparent)]
    Vk(#[from] VkError),

    /// Settings asked for a part of the renderer (a path, a pipeline, a
    /// pass) that it was built without.
    #[error("{0} was not built for this renderer")]
    NotBuilt(&'static str),

    /// Memory the CPU writes or reads is not mapped into its address space.
    #[error("{0} is not host-mapped")]
    NotMapped(&'static str),

    /// What this renderer, its device or its terrain cannot do, named in
    /// full.
    #[error("{0}")]
    Unsupported(String),

    /// A streamed terrain's file or loaders failed (the message names the
    /// file and, for a bad tile, the tile).
    #[error("streaming the terrain: {0}")]
    Stream(String),
}

pub type Result<T> = std::result::Result<T, RenderError>;
