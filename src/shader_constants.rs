// Constants shared by Rust and GLSL. `build.rs` includes this file and hands
// every entry of `shader_defines()` to the shader compiler as a macro, so the
// two sides cannot drift apart. Keep this file free of `use` and of anything
// that needs the rest of the crate.

/// Descriptor binding of the per-frame uniform block (set 0).
pub const BINDING_FRAME: u32 = 0;
/// Descriptor binding of the heightmap (set 0): R32_SFLOAT, read with texelFetch.
pub const BINDING_HEIGHTMAP: u32 = 1;

/// Storage buffer of the per-patch error table (tess path, error LOD).
pub const BINDING_ERROR_TABLE: u32 = 4;
/// Storage buffer of this frame's full-resolution patches, one bit each
/// (tess path, error LOD).
pub const BINDING_FULL_RESOLUTION: u32 = 11;
/// Levels per patch in the error table (factors 1, 2, ..., 64).
pub const ERROR_LEVEL_COUNT: u32 = 7;
/// LOD metric: distance.
pub const LOD_METRIC_DISTANCE: u32 = 0;
/// LOD metric: projected error.
pub const LOD_METRIC_ERROR: u32 = 1;
/// LOD metric: SaschaWillems's screen-space edge spheres.
pub const LOD_METRIC_SPHERE: u32 = 2;
/// LOD metric: Dupuy's target edge length on screen.
pub const LOD_METRIC_EDGE_LENGTH: u32 = 3;
/// LOD metric: CDLOD's doubling distance ranges.
pub const LOD_METRIC_CDLOD: u32 = 4;

/// Uniform block of the material layers' parameters (scenes with layers).
pub const BINDING_MATERIAL: u32 = 5;
/// 2D array of the layers' colour textures.
pub const BINDING_DIFFUSE_MAPS: u32 = 6;
/// 2D array of the layers' normal maps (when a layer has one).
pub const BINDING_NORMAL_MAPS: u32 = 7;
/// 2D array of the layers' height maps (when the material displaces).
pub const BINDING_HEIGHT_MAPS: u32 = 8;
/// 2D array of the blend maps (blend-map mode).
pub const BINDING_BLEND_MAPS: u32 = 9;
/// The baked lightmap (one layer).
pub const BINDING_LIGHTMAP: u32 = 10;
/// Most material layers. Mirror: terrain::shading::MAX_LAYERS.
pub const MAX_LAYERS: u32 = 8;
/// Most directional lights. Mirror: scene::material::MAX_LIGHTS.
pub const MAX_LIGHTS: u32 = 3;
/// Specialisation constant: number of material layers.
pub const SPEC_LAYER_COUNT: u32 = 0;
/// Specialisation constant: number of blend maps (blend-map mode).
pub const SPEC_BLEND_MAP_COUNT: u32 = 1;

/// Storage buffer of inputs of the GLSL mirror check (compute, tests only).
pub const BINDING_MIRROR_CASES: u32 = 2;
/// Storage buffer of results of the GLSL mirror check.
pub const BINDING_MIRROR_RESULTS: u32 = 3;

/// Smallest tessellation factor.
pub const MIN_TESS_FACTOR: f32 = 1.0;
/// Largest tessellation factor: the Vulkan minimum for maxTessellationGenerationLevel.
pub const MAX_TESS_FACTOR: f32 = 64.0;
/// log2(MAX_TESS_FACTOR).
pub const MAX_TESS_EXPONENT: f32 = 6.0;

/// LOD mode: Euclidean distance, continuous exponent.
pub const LOD_MODE_SMOOTH: u32 = 0;
/// LOD mode: xz max-norm distance, rounded exponent (debug view).
pub const LOD_MODE_DEBUG: u32 = 1;

/// Shading: height colours, one directional light plus ambient.
pub const SHADE_LIT: u32 = 0;
/// Shading: colour by tessellation factor.
pub const SHADE_LOD_COLORS: u32 = 1;
/// Shading: constant white, unlit (crack tests).
pub const SHADE_FLAT: u32 = 2;

/// Every constant above as (macro name, GLSL literal).
pub fn shader_defines() -> Vec<(&'static str, String)> {
    let uint = |v: u32| format!("{v}u");
    let float = |v: f32| format!("{v:?}");
    vec![
        ("BINDING_FRAME", BINDING_FRAME.to_string()),
        ("BINDING_HEIGHTMAP", BINDING_HEIGHTMAP.to_string()),
        ("BINDING_ERROR_TABLE", BINDING_ERROR_TABLE.to_string()),
        (
            "BINDING_FULL_RESOLUTION",
            BINDING_FULL_RESOLUTION.to_string(),
        ),
        ("ERROR_LEVEL_COUNT", ERROR_LEVEL_COUNT.to_string()),
        ("LOD_METRIC_DISTANCE", uint(LOD_METRIC_DISTANCE)),
        ("LOD_METRIC_ERROR", uint(LOD_METRIC_ERROR)),
        ("LOD_METRIC_SPHERE", uint(LOD_METRIC_SPHERE)),
        ("LOD_METRIC_EDGE_LENGTH", uint(LOD_METRIC_EDGE_LENGTH)),
        ("LOD_METRIC_CDLOD", uint(LOD_METRIC_CDLOD)),
        ("BINDING_MATERIAL", BINDING_MATERIAL.to_string()),
        ("BINDING_DIFFUSE_MAPS", BINDING_DIFFUSE_MAPS.to_string()),
        ("BINDING_NORMAL_MAPS", BINDING_NORMAL_MAPS.to_string()),
        ("BINDING_HEIGHT_MAPS", BINDING_HEIGHT_MAPS.to_string()),
        ("BINDING_BLEND_MAPS", BINDING_BLEND_MAPS.to_string()),
        ("BINDING_LIGHTMAP", BINDING_LIGHTMAP.to_string()),
        ("MAX_LAYERS", MAX_LAYERS.to_string()),
        ("MAX_LIGHTS", MAX_LIGHTS.to_string()),
        ("SPEC_LAYER_COUNT", SPEC_LAYER_COUNT.to_string()),
        ("SPEC_BLEND_MAP_COUNT", SPEC_BLEND_MAP_COUNT.to_string()),
        ("BINDING_MIRROR_CASES", BINDING_MIRROR_CASES.to_string()),
        ("BINDING_MIRROR_RESULTS", BINDING_MIRROR_RESULTS.to_string()),
        ("MIN_TESS_FACTOR", float(MIN_TESS_FACTOR)),
        ("MAX_TESS_FACTOR", float(MAX_TESS_FACTOR)),
        ("MAX_TESS_EXPONENT", float(MAX_TESS_EXPONENT)),
        ("LOD_MODE_SMOOTH", uint(LOD_MODE_SMOOTH)),
        ("LOD_MODE_DEBUG", uint(LOD_MODE_DEBUG)),
        ("SHADE_LIT", uint(SHADE_LIT)),
        ("SHADE_LOD_COLORS", uint(SHADE_LOD_COLORS)),
        ("SHADE_FLAT", uint(SHADE_FLAT)),
    ]
}
