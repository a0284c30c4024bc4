//! Render targets: what a renderer draws into. An offscreen target owns its
//! images and reads them back; a swapchain hands out the same views.

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::commands::Recorder;
use super::device::Device;
use super::error::{Result, VkError};
use super::memory::{Buffer, BufferDesc, Image, ImageDesc, Transition};

/// Colour format of offscreen targets: sRGB, like a swapchain, so shaders
/// write linear values and the PNG holds encoded ones.
pub const OFFSCREEN_COLOR_FORMAT: vk::Format = vk::Format::R8G8B8A8_SRGB;
/// Depth format: 32-bit float, used with reversed Z (1 near, 0 far).
pub const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;

/// The images a frame is drawn into, in COLOR_ATTACHMENT_OPTIMAL and
/// DEPTH_ATTACHMENT_OPTIMAL when the renderer records.
#[derive(Clone, Copy, Debug)]
pub struct TargetViews {
    pub extent: vk::Extent2D,
    pub color_format: vk::Format,
    pub(super) color_view: vk::ImageView,
    pub(super) depth_view: vk::ImageView,
}

/// What a target read back: sRGB RGBA8 pixels and depth, row-major, top row
/// first.
pub struct Readback {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<u8>,
    pub depth: Vec<f32>,
}

fn require(
    device: &Device,
    format: vk::Format,
    needed: vk::FormatFeatureFlags,
    what: &str,
) -> Result<()> {
    let has = device.format_features(format);
    if has.contains(needed) {
        Ok(())
    } else {
        Err(VkError::Unsupported(format!(
            "{} does not support {format:?} as {what} (needs {needed:?}, has {has:?})",
            device.caps.device_name
        )))
    }
}

/// Checks the depth format once for every kind of target.
pub fn check_depth_format(device: &Device) -> Result<()> {
    require(
        device,
        DEPTH_FORMAT,
        vk::FormatFeatureFlags::DEPTH_STENCIL_ATTACHMENT,
        "a depth attachment",
    )
}

pub struct OffscreenTarget {
    color: Image,
    depth: Image,
    color_readback: Buffer,
    depth_readback: Buffer,
}

impl OffscreenTarget {
    pub fn new(device: &Device, width: u32, height: u32) -> Result<Self> {
        if width == 0 || height == 0 {
            return Err(VkError::Unsupported(format!(
                "target size {width}x{height} has no pixels"
            )));
        }
        require(
            device,
            OFFSCREEN_COLOR_FORMAT,
            vk::FormatFeatureFlags::COLOR_ATTACHMENT | vk::FormatFeatureFlags::TRANSFER_SRC,
            "a colour attachment read back by copy",
        )?;
        check_depth_format(device)?;
        require(
            device,
            DEPTH_FORMAT,
            vk::FormatFeatureFlags::TRANSFER_SRC,
            "a copy source",
        )?;
        let extent = vk::Extent2D { width, height };
        let color = device.create_image(
            ImageDesc {
                extent,
                format: OFFSCREEN_COLOR_FORMAT,
                usage: vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
                aspect: vk::ImageAspectFlags::COLOR,
            },
            "offscreen.color",
        )?;
        let depth = device.create_image(
            ImageDesc {
                extent,
                format: DEPTH_FORMAT,
                usage: vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT
                    | vk::ImageUsageFlags::TRANSFER_SRC,
                aspect: vk::ImageAspectFlags::DEPTH,
            },
            "offscreen.depth",
        )?;
        let pixels = u64::from(width) * u64::from(height);
        let readback = |name: &str| {
            device.create_buffer(
                BufferDesc {
                    size: pixels * 4,
                    usage: vk::BufferUsageFlags::TRANSFER_DST,
                    location: MemoryLocation::GpuToCpu,
                },
                name,
            )
        };
        Ok(OffscreenTarget {
            color,
            depth,
            color_readback: readback("offscreen.color_readback")?,
            depth_readback: readback("offscreen.depth_readback")?,
        })
    }

    pub fn views(&self) -> TargetViews {
        TargetViews {
            extent: self.color.desc.extent,
            color_view: self.color.view(),
            color_format: self.color.desc.format,
            depth_view: self.depth.view(),
        }
    }

    /// Makes both images attachments; earlier contents are discarded.
    pub fn record_begin(&self, rec: &Recorder) {
        use vk::{AccessFlags2 as A, PipelineStageFlags2 as S};
        // A previous frame's copies must finish before we overwrite.
        rec.transition_images(&Transition::to_attachments(
            self.color.raw(),
            (S::COPY, A::NONE),
            self.depth.raw(),
            (S::COPY, A::NONE),
        ));
    }

    /// Copies both images into host-visible buffers after drawing.
    pub fn record_readback(&self, rec: &Recorder) {
        use vk::{AccessFlags2 as A, ImageLayout as L, PipelineStageFlags2 as S};
        rec.transition_images(&[
            Transition::color_output_to_copy(self.color.raw()),
            Transition {
                image: self.depth.raw(),
                aspect: vk::ImageAspectFlags::DEPTH,
                from: (
                    L::DEPTH_ATTACHMENT_OPTIMAL,
                    S::EARLY_FRAGMENT_TESTS | S::LATE_FRAGMENT_TESTS,
                    A::DEPTH_STENCIL_ATTACHMENT_WRITE,
                ),
                to: (L::TRANSFER_SRC_OPTIMAL, S::COPY, A::TRANSFER_READ),
            },
        ]);
        let extent = self.color.desc.extent;
        rec.copy_image_to_buffer(
            self.color.raw(),
            vk::ImageAspectFlags::COLOR,
            extent,
            &self.color_readback,
        );
        rec.copy_image_to_buffer(
            self.depth.raw(),
            vk::ImageAspectFlags::DEPTH,
            extent,
            &self.depth_readback,
        );
    }

    /// The pixels and depth of the last completed `record_readback`.
    pub fn read(&self) -> Result<Readback> {
        let extent = self.color.desc.extent;
        let unmapped = || VkError::Unsupported("readback memory is not host-mapped".into());
        let rgba = self.color_readback.mapped().ok_or_else(unmapped)?.to_vec();
        let depth =
            bytemuck::pod_collect_to_vec(self.depth_readback.mapped().ok_or_else(unmapped)?);
        Ok(Readback {
            width: extent.width,
            height: extent.height,
            rgba,
            depth,
        })
    }
}
