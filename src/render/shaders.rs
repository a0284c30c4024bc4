//! SPIR-V compiled by build.rs from glsl/, embedded in the binary: every
//! variant of `Shader` (src/shader_variants.rs).

use crate::shader_variants::Shader;

include!(concat!(env!("OUT_DIR"), "/spirv_table.rs"));

/// The SPIR-V of `shader`. Every value of `Shader` is in `Shader::all`,
/// which build.rs compiled in this order.
pub fn spirv(shader: Shader) -> &'static [u8] {
    let index = Shader::all()
        .iter()
        .position(|&s| s == shader)
        .expect("Shader::all lists every value of Shader");
    SPIRV[index]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_variant_has_its_own_spirv() {
        let all = Shader::all();
        assert_eq!(all.len(), SPIRV.len());
        let keys: std::collections::BTreeSet<String> = all.iter().map(|s| s.key()).collect();
        assert_eq!(keys.len(), all.len(), "two variants share a key");
        for shader in all {
            let words = spirv(shader);
            assert_eq!(&words[..4], &0x0723_0203u32.to_le_bytes(), "{shader:?}");
        }
    }
}
