//! SPIR-V compiled by build.rs from glsl/, embedded in the binary: every
//! stage, and the material variants of some (see `variants` in build.rs).

include!(concat!(env!("OUT_DIR"), "/spirv_table.rs"));

/// The SPIR-V of `file` compiled with the macros `defines` (in any order).
/// Panics on a combination build.rs doesn't compile: that is a bug in the
/// caller, not bad input.
pub fn spirv(file: &str, defines: &[&str]) -> &'static [u8] {
    let mut sorted = defines.to_vec();
    sorted.sort_unstable();
    let key = std::iter::once(file)
        .chain(sorted)
        .collect::<Vec<_>>()
        .join("+");
    SPIRV
        .iter()
        .find(|(k, _)| *k == key)
        .map(|(_, bytes)| *bytes)
        .unwrap_or_else(|| panic!("no shader variant {key} was compiled"))
}

pub fn terrain_vert() -> &'static [u8] {
    spirv("terrain.vert", &[])
}

pub fn terrain_tesc() -> &'static [u8] {
    spirv("terrain.tesc", &[])
}

pub fn mirror_check_comp() -> &'static [u8] {
    spirv("mirror_check.comp", &[])
}
