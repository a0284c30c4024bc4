//! Compiles every shader stage in `glsl/` to SPIR-V with shaderc (glslang) at
//! build time. The binary embeds the results; no shader file is read at run
//! time.
//!
//! - Target: Vulkan 1.3, GLSL 460.
//! - Warnings are errors; a GLSL error fails the build, with file and line.
//! - Optimised for performance in release builds.
//! - `#include "..."` resolves inside `glsl/`.
//! - The constants of `src/shader_constants.rs` arrive as macro definitions.

use std::path::PathBuf;

include!("src/shader_constants.rs");

const STAGES: [(&str, shaderc::ShaderKind); 5] = [
    ("vert", shaderc::ShaderKind::Vertex),
    ("tesc", shaderc::ShaderKind::TessControl),
    ("tese", shaderc::ShaderKind::TessEvaluation),
    ("frag", shaderc::ShaderKind::Fragment),
    ("comp", shaderc::ShaderKind::Compute),
];

fn main() {
    // Read at run time: `env!` would bake in the checkout the build script
    // was compiled in, and a target directory shared between checkouts
    // would then compile another checkout's shaders.
    let manifest_dir =
        PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let glsl_dir = manifest_dir.join("glsl");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    println!("cargo:rerun-if-changed=src/shader_constants.rs");
    println!("cargo:rerun-if-changed={}", glsl_dir.display());

    let mut files: Vec<PathBuf> = std::fs::read_dir(&glsl_dir)
        .unwrap_or_else(|e| fail(&format!("cannot list {}: {e}", glsl_dir.display())))
        .map(|entry| entry.expect("readable glsl/ entry").path())
        .collect();
    files.sort();
    for file in &files {
        println!("cargo:rerun-if-changed={}", file.display());
    }

    let compiler = shaderc::Compiler::new().unwrap_or_else(|e| fail(&format!("shaderc: {e}")));
    let mut options =
        shaderc::CompileOptions::new().unwrap_or_else(|e| fail(&format!("shaderc: {e}")));
    options.set_source_language(shaderc::SourceLanguage::GLSL);
    options.set_target_env(
        shaderc::TargetEnv::Vulkan,
        shaderc::EnvVersion::Vulkan1_3 as u32,
    );
    options.set_target_spirv(shaderc::SpirvVersion::V1_6);
    options.set_warnings_as_errors();
    let release = std::env::var("PROFILE").as_deref() == Ok("release");
    options.set_optimization_level(if release {
        shaderc::OptimizationLevel::Performance
    } else {
        shaderc::OptimizationLevel::Zero
    });
    for (name, value) in shader_defines() {
        options.add_macro_definition(name, Some(&value));
    }
    let include_dir = glsl_dir.clone();
    options.set_include_callback(move |requested, _kind, requester, _depth| {
        let path = include_dir.join(requested);
        let content = std::fs::read_to_string(&path)
            .map_err(|e| format!("{requester}: cannot include {requested:?}: {e}"))?;
        Ok(shaderc::ResolvedInclude {
            resolved_name: path.display().to_string(),
            content,
        })
    });

    let mut compiled = 0;
    for file in &files {
        let Some(ext) = file.extension().and_then(|e| e.to_str()) else {
            continue;
        };
        let Some(&(_, kind)) = STAGES.iter().find(|(e, _)| *e == ext) else {
            continue;
        };
        let source = std::fs::read_to_string(file)
            .unwrap_or_else(|e| fail(&format!("cannot read {}: {e}", file.display())));
        let name = file.file_name().unwrap().to_string_lossy().into_owned();
        let artifact = compiler
            .compile_into_spirv(
                &source,
                kind,
                &file.display().to_string(),
                "main",
                Some(&options),
            )
            .unwrap_or_else(|e| fail(&format!("GLSL compilation failed:\n{e}")));
        std::fs::write(out_dir.join(format!("{name}.spv")), artifact.as_binary_u8())
            .unwrap_or_else(|e| fail(&format!("cannot write SPIR-V for {name}: {e}")));
        compiled += 1;
    }
    if compiled == 0 {
        fail("no shader stages found in glsl/");
    }
}

fn fail(message: &str) -> ! {
    eprintln!("{message}");
    std::process::exit(1);
}
