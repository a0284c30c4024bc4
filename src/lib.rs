//! vkterrain: heightmap terrain rendering with hardware tessellation.
//!
//! Layers, each using only those below it:
//! - [`cli`]: the command line.
//! - [`app`]: the window demo (winit and a swapchain).
//! - [`bench`]: speed against error: the screen-space error measurement.
//! - [`render`]: the terrain renderer, drawing into a target it is given.
//! - [`lod`]: the level choice, from a terrain and a view to a frame plan.
//!   No GPU types.
//! - [`gpu`]: Vulkan plumbing over ash; all `unsafe` lives here.
//! - [`appearance`]: a scene's textures, blend maps and lightmap, loaded.
//! - [`scene`]: what to load.
//! - [`terrain`]: the CPU model (heightmaps, patch grid, Y bounds, error
//!   table, the view model, height queries, frustum maths). No GPU types.
//! - [`shader_constants`], [`shader_variants`]: constants and shader
//!   variants shared with build.rs and GLSL.
//! - [`cache`], [`output`]: the on-disk cache and atomic file writes,
//!   which any layer may use.
//!
//! `unsafe` is denied everywhere but in [`gpu`], by the lint below.

#![deny(unsafe_code)]

pub mod app;
pub mod appearance;
pub mod bench;
pub mod cache;
pub mod cli;
#[allow(unsafe_code)]
pub mod gpu;
pub mod lod;
pub mod output;
pub mod render;
pub mod scene;
/// Constants shared with GLSL, passed to the shader compiler by build.rs.
pub mod shader_constants;
/// The shader variants build.rs compiles and the renderer picks, typed.
pub mod shader_variants;
pub mod terrain;
