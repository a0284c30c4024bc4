//! Shader modules from SPIR-V embedded at build time.

use ash::vk;

use super::device::Device;
use super::error::{Result, VkError, VkResultExt};
use super::owned::Owned;

impl Device {
    /// A shader module from SPIR-V bytes (any alignment).
    pub(super) fn create_shader_module(
        &self,
        spirv: &[u8],
        name: &str,
    ) -> Result<Owned<vk::ShaderModule>> {
        let words = ash::util::read_spv(&mut std::io::Cursor::new(spirv))
            .map_err(|e| VkError::Unsupported(format!("{name}: invalid SPIR-V: {e}")))?;
        let info = vk::ShaderModuleCreateInfo::default().code(&words);
        // SAFETY: `words` is SPIR-V produced by shaderc at build time.
        let module = unsafe { self.ash().create_shader_module(&info, None) }
            .context("creating a shader module")?;
        Ok(Owned::new(self, module, name))
    }
}
