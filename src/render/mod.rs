//! The terrain renderer: pipelines, descriptor sets, per-frame uniforms, and
//! draw recording into a target it is given. Knows nothing of windows.

pub mod headless;
pub mod material;
pub mod mirror;
pub mod renderer;
pub mod shaders;
pub mod uniforms;

pub use headless::{Headless, HeadlessFrame};
pub use renderer::{
    with_fallback, FrameMeasurements, RenderPath, RendererOptions, TerrainRenderer,
};
pub use uniforms::{FrameUniforms, FrameView, LodMetric, RenderSettings, Shading};
