//! SPIR-V compiled by build.rs from glsl/, embedded in the binary.

macro_rules! spirv {
    ($name:literal) => {
        include_bytes!(concat!(env!("OUT_DIR"), "/", $name, ".spv"))
    };
}

pub const TERRAIN_VERT: &[u8] = spirv!("terrain.vert");
pub const TERRAIN_TESC: &[u8] = spirv!("terrain.tesc");
pub const TERRAIN_TESE: &[u8] = spirv!("terrain.tese");
pub const TERRAIN_FRAG: &[u8] = spirv!("terrain.frag");
pub const BRUTE_VERT: &[u8] = spirv!("brute.vert");
pub const GEOMIP_VERT: &[u8] = spirv!("geomip.vert");
pub const MIRROR_CHECK_COMP: &[u8] = spirv!("mirror_check.comp");
