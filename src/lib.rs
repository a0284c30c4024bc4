//! vkterrain: heightmap terrain rendering with hardware tessellation.
//!
//! - [`terrain`]: the CPU model (heightmaps, patch grid, Y bounds, error
//!   table, height queries, frustum and LOD maths). No GPU types.
//! - [`cli`]: the command line.

pub mod cli;
pub mod terrain;
