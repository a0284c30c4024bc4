//! Render targets: what a renderer draws into. An offscreen target owns its
//! images and reads them back; a swapchain hands out the same views.

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::commands::Recorder;
use super::device::{sample_count_flag, Device};
use super::error::{Result, VkError};
use super::memory::{Buffer, BufferDesc, Image, ImageDesc, Transition, DEPTH_WRITTEN};

/// Colour format of offscreen targets: sRGB, like a swapchain, so shaders
/// write linear values and the PNG holds encoded ones.
pub const OFFSCREEN_COLOR_FORMAT: vk::Format = vk::Format::R8G8B8A8_SRGB;
pub use super::views::{TargetViews, DEPTH_FORMAT};

/// The multisampled colour and depth images a target draws into before
/// resolving, when it has more than one sample per pixel.
pub(super) struct Multisampled {
    pub(super) color: Image,
    pub(super) depth: Image,
}

impl Multisampled {
    /// None for one sample per pixel.
    pub(super) fn new(
        device: &Device,
        extent: vk::Extent2D,
        color_format: vk::Format,
        samples: u32,
        name: &str,
    ) -> Result<Option<Self>> {
        if samples == 1 {
            return Ok(None);
        }
        device.caps.check_samples(samples)?;
        let flag = sample_count_flag(samples);
        let image = |format, usage, aspect, what| {
            device.create_image(
                ImageDesc {
                    extent,
                    format,
                    usage,
                    aspect,
                    samples: flag,
                },
                &format!("{name}.{what}"),
            )
        };
        Ok(Some(Multisampled {
            color: image(
                color_format,
                vk::ImageUsageFlags::COLOR_ATTACHMENT,
                vk::ImageAspectFlags::COLOR,
                "multisampled_color",
            )?,
            depth: image(
                DEPTH_FORMAT,
                depth_usage(device, samples),
                vk::ImageAspectFlags::DEPTH,
                "multisampled_depth",
            )?,
        }))
    }

    /// Makes both images attachments, their old contents discarded, after
    /// the previous frame's writes to them (targets share them between
    /// frames in flight).
    pub(super) fn record_begin(&self, rec: &Recorder) {
        use vk::{AccessFlags2 as A, PipelineStageFlags2 as S};
        rec.transition_images(&Transition::to_attachments(
            self.color.raw(),
            (S::COLOR_ATTACHMENT_OUTPUT, A::COLOR_ATTACHMENT_WRITE),
            self.depth.raw(),
            DEPTH_USED,
        ));
    }

    /// The views of a target whose own images are `color` and (when it
    /// keeps depth) `depth`: drawn into these, resolved into those.
    pub(super) fn views(
        &self,
        extent: vk::Extent2D,
        color: vk::ImageView,
        depth: Option<vk::ImageView>,
    ) -> TargetViews {
        TargetViews {
            extent,
            color_format: self.color.desc.format,
            samples: self.color.desc.samples,
            color_view: self.color.view(),
            depth_view: self.depth.view(),
            depth_image: self.depth.raw(),
            depth_serial: self.depth.serial(),
            depth_readable: self.depth.desc.usage.contains(vk::ImageUsageFlags::SAMPLED),
            color_resolve: Some(color),
            depth_resolve: depth,
        }
    }
}

/// The stages and accesses of a frame's use of a depth attachment that a
/// later frame sharing it must wait for: depth tests, and the occlusion
/// pyramid's reads.
pub(super) const DEPTH_USED: (vk::PipelineStageFlags2, vk::AccessFlags2) = (
    vk::PipelineStageFlags2::from_raw(
        vk::PipelineStageFlags2::EARLY_FRAGMENT_TESTS.as_raw()
            | vk::PipelineStageFlags2::LATE_FRAGMENT_TESTS.as_raw()
            | vk::PipelineStageFlags2::COMPUTE_SHADER.as_raw(),
    ),
    vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE,
);

/// Usage of a depth attachment of `samples` samples per pixel: sampled
/// too where the device can read it (occlusion culling).
pub(super) fn depth_usage(device: &Device, samples: u32) -> vk::ImageUsageFlags {
    let usage = vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT;
    if device.caps.supports_occlusion(samples) {
        usage | vk::ImageUsageFlags::SAMPLED
    } else {
        usage
    }
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
    /// Single-sample depth: drawn into, or resolved into from `multisampled`.
    depth: Image,
    multisampled: Option<Multisampled>,
    color_readback: Buffer,
    depth_readback: Buffer,
}

impl OffscreenTarget {
    /// A `width` x `height` target of `samples` samples per pixel.
    pub fn new(device: &Device, width: u32, height: u32, samples: u32) -> Result<Self> {
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
                samples: vk::SampleCountFlags::TYPE_1,
            },
            "offscreen.color",
        )?;
        let depth = device.create_image(
            ImageDesc {
                extent,
                format: DEPTH_FORMAT,
                usage: depth_usage(device, 1) | vk::ImageUsageFlags::TRANSFER_SRC,
                aspect: vk::ImageAspectFlags::DEPTH,
                samples: vk::SampleCountFlags::TYPE_1,
            },
            "offscreen.depth",
        )?;
        let multisampled =
            Multisampled::new(device, extent, OFFSCREEN_COLOR_FORMAT, samples, "offscreen")?;
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
            multisampled,
            color_readback: readback("offscreen.color_readback")?,
            depth_readback: readback("offscreen.depth_readback")?,
        })
    }

    pub fn views(&self) -> TargetViews {
        let extent = self.color.desc.extent;
        match &self.multisampled {
            Some(ms) => ms.views(extent, self.color.view(), Some(self.depth.view())),
            None => TargetViews {
                extent,
                color_view: self.color.view(),
                color_format: self.color.desc.format,
                samples: vk::SampleCountFlags::TYPE_1,
                depth_view: self.depth.view(),
                depth_image: self.depth.raw(),
                depth_serial: self.depth.serial(),
                depth_readable: self.depth.desc.usage.contains(vk::ImageUsageFlags::SAMPLED),
                color_resolve: None,
                depth_resolve: None,
            },
        }
    }

    /// Makes both images attachments; earlier contents are discarded.
    pub fn record_begin(&self, rec: &Recorder) {
        use vk::{AccessFlags2 as A, PipelineStageFlags2 as S};
        // A previous frame's copies, reads of depth by the occlusion
        // pyramid, and (for a frame drawn without a readback) attachment
        // writes must finish before we overwrite.
        rec.transition_images(&Transition::to_attachments(
            self.color.raw(),
            (
                S::COPY | S::COLOR_ATTACHMENT_OUTPUT,
                A::COLOR_ATTACHMENT_WRITE,
            ),
            self.depth.raw(),
            (S::COPY | DEPTH_USED.0, DEPTH_USED.1),
        ));
        if let Some(ms) = &self.multisampled {
            ms.record_begin(rec);
        }
    }

    /// Copies both images into host-visible buffers after drawing.
    pub fn record_readback(&self, rec: &Recorder) {
        use vk::{AccessFlags2 as A, ImageLayout as L, PipelineStageFlags2 as S};
        rec.transition_images(&[
            Transition::color_output_to_copy(self.color.raw()),
            Transition {
                image: self.depth.raw(),
                aspect: vk::ImageAspectFlags::DEPTH,
                from: DEPTH_WRITTEN,
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
