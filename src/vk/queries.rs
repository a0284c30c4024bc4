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
}

/// The flags in the order Vulkan writes their results (by bit position).
const STATISTICS: [vk::QueryPipelineStatisticFlags; 5] = [
    vk::QueryPipelineStatisticFlags::VERTEX_SHADER_INVOCATIONS,
    vk::QueryPipelineStatisticFlags::CLIPPING_INVOCATIONS,
    vk::QueryPipelineStatisticFlags::CLIPPING_PRIMITIVES,
    vk::QueryPipelineStatisticFlags::TESSELLATION_CONTROL_SHADER_PATCHES,
    vk::QueryPipelineStatisticFlags::TESSELLATION_EVALUATION_SHADER_INVOCATIONS,
];

/// Query pools for one frame in flight.
pub struct FrameQueries {
    timestamps: Option<Owned<vk::QueryPool>>,
    statistics: Option<Owned<vk::QueryPool>>,
    period_ns: f64,
    valid_mask: u64,
}

impl FrameQueries {
    pub fn new(device: &Device, name: &str) -> Result<Self> {
        let timestamps = match device.caps.timestamp_period_ns {
            Some(_) => {
                let info = vk::QueryPoolCreateInfo::default()
                    .query_type(vk::QueryType::TIMESTAMP)
                    .query_count(2);
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
                .query_count(1)
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
                device.cmd_reset_query_pool(cmd, pool.raw(), 0, 2);
            }
            if let Some(pool) = &self.statistics {
                device.cmd_reset_query_pool(cmd, pool.raw(), 0, 1);
            }
        }
    }

    /// Starts timing and counting.
    pub fn begin(&self, rec: &Recorder) {
        let (device, cmd) = (rec.device.ash(), rec.cmd);
        // SAFETY: the pools were reset earlier in this command buffer.
        unsafe {
            if let Some(pool) = &self.timestamps {
                device.cmd_write_timestamp2(
                    cmd,
                    vk::PipelineStageFlags2::TOP_OF_PIPE,
                    pool.raw(),
                    0,
                );
            }
            if let Some(pool) = &self.statistics {
                device.cmd_begin_query(cmd, pool.raw(), 0, vk::QueryControlFlags::empty());
            }
        }
    }

    /// Stops counting: what is drawn after this is timed but not counted.
    pub fn end_counting(&self, rec: &Recorder) {
        let (device, cmd) = (rec.device.ash(), rec.cmd);
        // SAFETY: matches `begin` in the same command buffer.
        unsafe {
            if let Some(pool) = &self.statistics {
                device.cmd_end_query(cmd, pool.raw(), 0);
            }
        }
    }

    /// Stops timing; after `end_counting`.
    pub fn end_timing(&self, rec: &Recorder) {
        let (device, cmd) = (rec.device.ash(), rec.cmd);
        // SAFETY: matches `begin` in the same command buffer.
        unsafe {
            if let Some(pool) = &self.timestamps {
                device.cmd_write_timestamp2(
                    cmd,
                    vk::PipelineStageFlags2::ALL_COMMANDS,
                    pool.raw(),
                    1,
                );
            }
        }
    }

    /// GPU milliseconds between `begin` and `end`, when timestamps exist.
    /// Call after the frame's fence has signalled.
    pub fn gpu_ms(&self) -> Result<Option<f64>> {
        let Some(pool) = &self.timestamps else {
            return Ok(None);
        };
        let mut ticks = [0u64; 2];
        // SAFETY: both queries were written by a completed submission.
        unsafe {
            pool.device().ash().get_query_pool_results(
                pool.raw(),
                0,
                &mut ticks,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .context("reading timestamps")?;
        let elapsed =
            (ticks[1] & self.valid_mask).wrapping_sub(ticks[0] & self.valid_mask) & self.valid_mask;
        Ok(Some(elapsed as f64 * self.period_ns / 1e6))
    }

    /// The draw's counters, when pipeline statistics exist.
    pub fn statistics(&self) -> Result<Option<PipelineStatistics>> {
        let Some(pool) = &self.statistics else {
            return Ok(None);
        };
        let mut values = [[0u64; STATISTICS.len()]; 1];
        // SAFETY: the query was ended in a completed submission.
        unsafe {
            pool.device().ash().get_query_pool_results(
                pool.raw(),
                0,
                &mut values,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .context("reading pipeline statistics")?;
        let [vs, clip_in, clip_out, tcs, tes] = values[0];
        Ok(Some(PipelineStatistics {
            vertex_invocations: vs,
            tcs_patches: tcs,
            tes_invocations: tes,
            clipping_invocations: clip_in,
            clipping_primitives: clip_out,
        }))
    }
}
