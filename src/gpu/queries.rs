//! GPU timestamps and pipeline statistics around a draw. Each is optional:
//! a device without it reports the figure as unavailable, not as zero.

use ash::vk;

use super::commands::Recorder;
use super::device::Device;
use super::error::{Result, VkResultExt};
use super::owned::Owned;

/// Counters of one draw, from a pipeline-statistics query.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct PipelineStatistics {
    pub vertex_invocations: u64,
    pub tcs_patches: u64,
    pub tes_invocations: u64,
    /// Primitives that reached the clipper.
    pub clipping_invocations: u64,
    /// Primitives the clipper output: the triangles that were rasterised.
    pub clipping_primitives: u64,
    /// Fragment shader invocations: every pixel shaded, overdraw included
    /// (a device may count pixels the depth test then drops).
    pub fragment_invocations: u64,
}

/// The flags in the order Vulkan writes their results (by bit position).
const STATISTICS: [vk::QueryPipelineStatisticFlags; 6] = [
    vk::QueryPipelineStatisticFlags::VERTEX_SHADER_INVOCATIONS,
    vk::QueryPipelineStatisticFlags::CLIPPING_INVOCATIONS,
    vk::QueryPipelineStatisticFlags::CLIPPING_PRIMITIVES,
    vk::QueryPipelineStatisticFlags::FRAGMENT_SHADER_INVOCATIONS,
    vk::QueryPipelineStatisticFlags::TESSELLATION_CONTROL_SHADER_PATCHES,
    vk::QueryPipelineStatisticFlags::TESSELLATION_EVALUATION_SHADER_INVOCATIONS,
];

/// Timestamps of one frame: its start and end, and two marks inside it.
const TIMESTAMPS: u32 = 4;

/// Query pools for one frame in flight.
pub struct FrameQueries {
    timestamps: Option<Owned<vk::QueryPool>>,
    statistics: Option<Owned<vk::QueryPool>>,
    /// Pipeline-statistics queries: one per part of the frame counted.
    counted_parts: u32,
    period_ns: f64,
    valid_mask: u64,
}

impl FrameQueries {
    /// Pools for a frame that counts its pipeline statistics in
    /// `counted_parts` parts (at least one).
    pub fn new(device: &Device, counted_parts: u32, name: &str) -> Result<Self> {
        let counted_parts = counted_parts.max(1);
        let timestamps = match device.caps.timestamp_period_ns {
            Some(_) => {
                let info = vk::QueryPoolCreateInfo::default()
                    .query_type(vk::QueryType::TIMESTAMP)
                    .query_count(TIMESTAMPS);
                // SAFETY: valid create info.
                let pool = unsafe { device.ash().create_query_pool(&info, None) }
                    .context("creating a timestamp query pool")?;
                Some(Owned::new(device, pool, &format!("{name}.timestamps")))
            }
            None => None,
        };
        let statistics = if device.caps.pipeline_statistics_query {
            let flags = STATISTICS
                .iter()
                .fold(vk::QueryPipelineStatisticFlags::empty(), |a, &f| a | f);
            let info = vk::QueryPoolCreateInfo::default()
                .query_type(vk::QueryType::PIPELINE_STATISTICS)
                .query_count(counted_parts)
                .pipeline_statistics(flags);
            // SAFETY: the feature is enabled on the device.
            let pool = unsafe { device.ash().create_query_pool(&info, None) }
                .context("creating a statistics query pool")?;
            Some(Owned::new(device, pool, &format!("{name}.statistics")))
        } else {
            None
        };
        let bits = device.caps.timestamp_valid_bits;
        Ok(FrameQueries {
            timestamps,
            statistics,
            counted_parts,
            period_ns: f64::from(device.caps.timestamp_period_ns.unwrap_or(0.0)),
            valid_mask: if bits >= 64 {
                u64::MAX
            } else {
                (1u64 << bits) - 1
            },
        })
    }

    /// Resets the pools; recorded outside any rendering.
    pub fn reset(&self, rec: &Recorder) {
        let (device, cmd) = (rec.device.ash(), rec.cmd);
        // SAFETY: pools of this device, `cmd` recording outside rendering.
        unsafe {
            if let Some(pool) = &self.timestamps {
                device.cmd_reset_query_pool(cmd, pool.raw(), 0, TIMESTAMPS);
            }
            if let Some(pool) = &self.statistics {
                device.cmd_reset_query_pool(cmd, pool.raw(), 0, self.counted_parts);
            }
        }
    }

    /// Starts timing the frame.
    pub fn begin_timing(&self, rec: &Recorder) {
        self.write_timestamp(rec, vk::PipelineStageFlags2::TOP_OF_PIPE, 0);
    }

    /// Starts counting part `part` (below the parts counted) of the frame.
    pub fn begin_counting(&self, rec: &Recorder, part: u32) {
        if let Some(pool) = &self.statistics {
            // SAFETY: the pool was reset earlier in this command buffer.
            unsafe {
                rec.device.ash().cmd_begin_query(
                    rec.cmd,
                    pool.raw(),
                    part,
                    vk::QueryControlFlags::empty(),
                )
            };
        }
    }

    /// Stops counting part `part`: what is drawn after this is timed but
    /// not counted.
    pub fn end_counting(&self, rec: &Recorder, part: u32) {
        if let Some(pool) = &self.statistics {
            // SAFETY: matches `begin_counting` in the same command buffer.
            unsafe { rec.device.ash().cmd_end_query(rec.cmd, pool.raw(), part) };
        }
    }

    /// Marks where the frame's inner span (`span_ms`) starts, once the
    /// work before it is done.
    pub fn mark_span_start(&self, rec: &Recorder) {
        self.write_timestamp(rec, vk::PipelineStageFlags2::ALL_COMMANDS, 2);
    }

    /// Marks where the frame's inner span ends.
    pub fn mark_span_end(&self, rec: &Recorder) {
        self.write_timestamp(rec, vk::PipelineStageFlags2::ALL_COMMANDS, 3);
    }

    /// Stops timing the frame; after `end_counting`.
    pub fn end_timing(&self, rec: &Recorder) {
        self.write_timestamp(rec, vk::PipelineStageFlags2::ALL_COMMANDS, 1);
    }

    fn write_timestamp(&self, rec: &Recorder, stage: vk::PipelineStageFlags2, query: u32) {
        if let Some(pool) = &self.timestamps {
            // SAFETY: the pool was reset earlier in this command buffer.
            unsafe {
                rec.device
                    .ash()
                    .cmd_write_timestamp2(rec.cmd, stage, pool.raw(), query)
            };
        }
    }

    /// GPU milliseconds between the frame's start and end, when
    /// timestamps exist. Call after the frame's fence has signalled.
    pub fn gpu_ms(&self) -> Result<Option<f64>> {
        self.milliseconds(0)
    }

    /// GPU milliseconds of the inner span the frame marked (only a frame
    /// that marked one may ask).
    pub fn span_ms(&self) -> Result<Option<f64>> {
        self.milliseconds(2)
    }

    /// Milliseconds from timestamp `first` to `first + 1`.
    fn milliseconds(&self, first: u32) -> Result<Option<f64>> {
        let Some(pool) = &self.timestamps else {
            return Ok(None);
        };
        let mut ticks = [0u64; 2];
        // SAFETY: both queries were written by a completed submission.
        unsafe {
            pool.device().ash().get_query_pool_results(
                pool.raw(),
                first,
                &mut ticks,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .context("reading timestamps")?;
        let elapsed =
            (ticks[1] & self.valid_mask).wrapping_sub(ticks[0] & self.valid_mask) & self.valid_mask;
        Ok(Some(elapsed as f64 * self.period_ns / 1e6))
    }

    /// The counters of the frame's first `parts` parts, summed, when
    /// pipeline statistics exist.
    pub fn statistics(&self, parts: u32) -> Result<Option<PipelineStatistics>> {
        let Some(pool) = &self.statistics else {
            return Ok(None);
        };
        let parts = parts.clamp(1, self.counted_parts) as usize;
        let mut values = vec![[0u64; STATISTICS.len()]; parts];
        // SAFETY: the queries were ended in a completed submission.
        unsafe {
            pool.device().ash().get_query_pool_results(
                pool.raw(),
                0,
                &mut values,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .context("reading pipeline statistics")?;
        let mut sum = [0u64; STATISTICS.len()];
        for part in &values {
            for (s, v) in sum.iter_mut().zip(part) {
                *s += v;
            }
        }
        let [vs, clip_in, clip_out, fragments, tcs, tes] = sum;
        Ok(Some(PipelineStatistics {
            vertex_invocations: vs,
            tcs_patches: tcs,
            tes_invocations: tes,
            clipping_invocations: clip_in,
            clipping_primitives: clip_out,
            fragment_invocations: fragments,
        }))
    }
}
