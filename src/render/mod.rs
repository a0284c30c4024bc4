//! The terrain renderer: pipelines, descriptor sets, per-frame uniforms, and
//! draw recording into a target it is given. Knows nothing of windows.

pub mod appearance;
pub mod error;
pub mod figures;
mod frame;
mod geomip_path;
pub mod headless;
pub mod loaded;
pub mod mirror;
pub mod occlusion;
mod pipelines;
pub mod renderer;
pub mod residency;
mod seen;
pub mod settings;
pub mod shaders;
pub mod stream_budget;
pub mod streaming;
mod tess_path;
pub mod uniforms;
pub mod view;
mod view_measure;

pub use error::{RenderError, Result};
pub use figures::FrameFigures;
pub use headless::{offscreen, Headless, HeadlessFrame, TimedFrame};
pub use loaded::{LoadError, LoadTimings, LoadedScene, Loading};
pub use renderer::{FrameMeasurements, RendererOptions, TerrainRenderer};
pub use settings::{
    sample_count, with_fallback, ErrorMeasure, LodMetric, RenderPath, RenderSettings, Shading,
    DEFAULT_SAMPLES,
};
pub use streaming::{StreamConfig, StreamStats};
pub use uniforms::FrameUniforms;
pub use view::FrameView;
