//! What a rendering draws into, as handles: below the targets that own the
//! images and the commands that record into them.

use ash::vk;

/// Depth format: 32-bit float, used with reversed Z (1 near, 0 far).
pub const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;

/// The images a frame is drawn into, in COLOR_ATTACHMENT_OPTIMAL and
/// DEPTH_ATTACHMENT_OPTIMAL when the renderer records. With more than one
/// sample per pixel, the frame is drawn into multisampled images and
/// resolved at the end of rendering: colour by averaging the samples into
/// the target's colour image, depth (where the target keeps it) by taking
/// sample 0, the depth of the pixel's centre.
#[derive(Clone, Copy, Debug)]
pub struct TargetViews {
    pub extent: vk::Extent2D,
    pub color_format: vk::Format,
    pub samples: vk::SampleCountFlags,
    pub(super) color_view: vk::ImageView,
    pub(super) depth_view: vk::ImageView,
    /// The image of `depth_view` (the one drawn into).
    pub(super) depth_image: vk::Image,
    /// That image's serial number (`Image::serial`).
    pub(super) depth_serial: u64,
    /// Whether shaders can read `depth_view` (occlusion culling).
    pub depth_readable: bool,
    pub(super) color_resolve: Option<vk::ImageView>,
    pub(super) depth_resolve: Option<vk::ImageView>,
}

impl TargetViews {
    /// Which depth image is drawn into: a target whose depth is another
    /// image needs its descriptors written again. A serial number, not the
    /// view's handle, which a driver may reuse for a new view once the old
    /// one is destroyed.
    pub fn depth_identity(&self) -> u64 {
        self.depth_serial
    }
}
