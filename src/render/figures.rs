//! `FrameFigures`: what one frame cost and drew, under the names and in
//! the units every report of frames uses: `render --stats`, the stream
//! report's frames, and the bench's rows (there the median of each time
//! and the mean of each count over the row's frames).

use serde::{Deserialize, Serialize};

use super::renderer::FrameMeasurements;

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameFigures {
    /// CPU milliseconds to choose levels, write uniforms and record the
    /// frame's commands (not waiting for the GPU).
    pub cpu_ms: f64,
    /// Of that, the level choice's alone; null where nothing was chosen
    /// (the brute path, given levels).
    #[serde(default)]
    pub lod_ms: Option<f64>,
    /// GPU milliseconds between the timestamps around the terrain's draw;
    /// null without timestamps.
    pub gpu_ms: Option<f64>,
    /// Triangles rasterised (the clipper's output primitives); null
    /// without pipeline statistics.
    pub triangles: Option<u64>,
    /// Tessellation evaluation shader invocations; null without pipeline
    /// statistics.
    pub tes_invocations: Option<u64>,
}

impl FrameFigures {
    /// A frame's figures from what its queries measured and what its CPU
    /// work took.
    pub fn new(measurements: &FrameMeasurements, cpu_ms: f64, lod_ms: Option<f64>) -> Self {
        let statistics = measurements.statistics;
        FrameFigures {
            cpu_ms,
            lod_ms,
            gpu_ms: measurements.gpu_ms,
            triangles: statistics.map(|s| s.clipping_primitives),
            tes_invocations: statistics.map(|s| s.tes_invocations),
        }
    }

    /// CPU plus GPU milliseconds: what the frame costs a user; null
    /// without timestamps.
    pub fn frame_ms(&self) -> Option<f64> {
        self.gpu_ms.map(|gpu| gpu + self.cpu_ms)
    }

    /// The figures of a run of frames: the median of each time over
    /// `timed` and the mean of each count over `counted` (a bench times
    /// frames drawn back to back and counts the one it reads back). A
    /// figure none of the frames has stays null.
    pub fn summary(timed: &[FrameFigures], counted: &[FrameFigures]) -> FrameFigures {
        let times = |f: fn(&FrameFigures) -> Option<f64>| {
            median(&mut timed.iter().filter_map(f).collect::<Vec<_>>())
        };
        let counts = |f: fn(&FrameFigures) -> Option<u64>| {
            mean_count(&counted.iter().filter_map(f).collect::<Vec<_>>())
        };
        FrameFigures {
            cpu_ms: times(|f| Some(f.cpu_ms)).unwrap_or(0.0),
            lod_ms: times(|f| f.lod_ms),
            gpu_ms: times(|f| f.gpu_ms),
            triangles: counts(|f| f.triangles),
            tes_invocations: counts(|f| f.tes_invocations),
        }
    }
}

/// The median; None for no values.
pub fn median(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    Some(if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    })
}

/// The mean of counts, rounded; None for no values.
pub fn mean_count(values: &[u64]) -> Option<u64> {
    (!values.is_empty())
        .then(|| (values.iter().sum::<u64>() as f64 / values.len() as f64).round() as u64)
}
