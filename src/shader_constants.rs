// Constants shared by Rust and GLSL. `build.rs` includes this file and hands
// every entry of `shader_defines()` to the shader compiler as a macro, so the
// two sides cannot drift apart. Keep this file free of `use` and of anything
// that needs the rest of the crate.

/// Descriptor binding of the per-frame uniform block (set 0).
pub const BINDING_FRAME: u32 = 0;
/// Descriptor binding of the heightmap (set 0): R32_SFLOAT, read with texelFetch.
pub const BINDING_HEIGHTMAP: u32 = 1;
/// The same frame block, read by the control shader as a read-only
/// storage buffer (see `render::frame::DescriptorPlan::new`).
pub const BINDING_FRAME_STORAGE: u32 = 21;

/// Storage buffer of the pixels each patch shows (glsl/terrain.frag):
/// a word that is 1 in a frame that counts, then a count per patch.
pub const BINDING_SEEN_PIXELS: u32 = 22;

/// Storage buffer of a frame's listed geomip draws' constants (the geomip
/// path's patches, or the tess path's full-resolution ones), read by
/// glsl/geomip.vert at the draw's instance index.
pub const BINDING_PATCH_CONSTANTS: u32 = 23;
/// The geomip push constants' list index that says the draw carries its
/// own constants instead.
pub const OWN_PATCH_CONSTANTS: u32 = u32::MAX;

/// Storage buffer of the per-patch error table (tess path, error LOD).
pub const BINDING_ERROR_TABLE: u32 = 4;
/// Storage buffer of this frame's full-resolution patches, one bit each
/// (tess path, error LOD).
pub const BINDING_FULL_RESOLUTION: u32 = 11;
/// Storage buffer of the occlusion state, one word per patch
/// (`OCCLUSION_*_BIT`), kept from frame to frame.
pub const BINDING_VISIBILITY: u32 = 12;
/// The depth the occlusion pyramid is reduced from (compute).
pub const BINDING_HIZ_DEPTH: u32 = 13;
/// Storage buffer of the occlusion pyramid, every level one after another.
pub const BINDING_HIZ_PYRAMID: u32 = 14;
/// Levels of the occlusion pyramid one dispatch of glsl/hiz.comp writes:
/// each invocation reduces a block of 2^(levels - 1) texels a side of the
/// dispatch's first level down to one texel.
pub const HIZ_LEVELS_PER_DISPATCH: u32 = 5;
/// The control points (x, z, Y bounds), read by the occlusion test.
pub const BINDING_CONTROL_POINTS: u32 = 15;
/// Storage buffer counting the patches the occlusion test culled.
pub const BINDING_OCCLUSION_COUNT: u32 = 16;
/// Storage buffer of the patch of each draw the CPU lists (occlusion).
pub const BINDING_DRAW_PATCHES: u32 = 17;
/// The indirect draw commands of the CPU's list, both phases (occlusion).
pub const BINDING_DRAW_COMMANDS: u32 = 18;
/// Occlusion state bit: the patch passed this frame's test (drawn first
/// next frame).
pub const OCCLUSION_VISIBLE_BIT: u32 = 1;
/// Occlusion state bit: the patch passed the test but was not drawn
/// first, so the second pass draws it.
pub const OCCLUSION_NEWLY_VISIBLE_BIT: u32 = 2;
/// Occlusion state bit: in the frustum, not drawn first, and hidden: not
/// drawn at all.
pub const OCCLUSION_CULLED_BIT: u32 = 4;
/// Draw phase: every patch the frustum keeps (occlusion off).
pub const OCCLUSION_PHASE_ALL: u32 = 0;
/// Draw phase: the patches with `OCCLUSION_VISIBLE_BIT` from last frame.
pub const OCCLUSION_PHASE_FIRST: u32 = 1;
/// Draw phase: the patches with `OCCLUSION_NEWLY_VISIBLE_BIT`.
pub const OCCLUSION_PHASE_SECOND: u32 = 2;
/// Draw phase: the patches with `OCCLUSION_CULLED_BIT` (shown culled).
pub const OCCLUSION_PHASE_CULLED: u32 = 3;
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
/// Most directional lights. Mirror: scene::look::MAX_LIGHTS.
pub const MAX_LIGHTS: u32 = 3;
/// Specialisation constant: number of material layers.
pub const SPEC_LAYER_COUNT: u32 = 0;
/// Specialisation constant: number of blend maps (blend-map mode).
pub const SPEC_BLEND_MAP_COUNT: u32 = 1;
/// Specialisation constant: 1 when heights are streamed (the heightmap
/// binding then holds the base level, and tiles come from the page pool).
/// The streamed terrain's cells a tile, base level and tiles across and
/// down follow it as ids SPEC_STREAMED + 1 to + 4.
pub const SPEC_STREAMED: u32 = 2;

/// 2D array of streamed pages (`render::residency`), one a layer.
pub const BINDING_PAGES: u32 = 19;
/// Storage buffer of the page table: one word a tile, the page it is
/// drawn from (its level above `PAGE_LEVEL_SHIFT`, its layer in the page
/// pool below).
pub const BINDING_PAGE_TABLE: u32 = 20;
/// Where a page table entry's level starts; the layer is the bits below.
pub const PAGE_LEVEL_SHIFT: u32 = 24;

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
        ("BINDING_FRAME_STORAGE", BINDING_FRAME_STORAGE.to_string()),
        ("BINDING_ERROR_TABLE", BINDING_ERROR_TABLE.to_string()),
        (
            "BINDING_FULL_RESOLUTION",
            BINDING_FULL_RESOLUTION.to_string(),
        ),
        ("ERROR_LEVEL_COUNT", ERROR_LEVEL_COUNT.to_string()),
        ("BINDING_VISIBILITY", BINDING_VISIBILITY.to_string()),
        ("BINDING_HIZ_DEPTH", BINDING_HIZ_DEPTH.to_string()),
        ("BINDING_HIZ_PYRAMID", BINDING_HIZ_PYRAMID.to_string()),
        (
            "HIZ_LEVELS_PER_DISPATCH",
            HIZ_LEVELS_PER_DISPATCH.to_string(),
        ),
        ("BINDING_DRAW_PATCHES", BINDING_DRAW_PATCHES.to_string()),
        ("BINDING_DRAW_COMMANDS", BINDING_DRAW_COMMANDS.to_string()),
        ("BINDING_CONTROL_POINTS", BINDING_CONTROL_POINTS.to_string()),
        (
            "BINDING_OCCLUSION_COUNT",
            BINDING_OCCLUSION_COUNT.to_string(),
        ),
        ("OCCLUSION_VISIBLE_BIT", uint(OCCLUSION_VISIBLE_BIT)),
        (
            "OCCLUSION_NEWLY_VISIBLE_BIT",
            uint(OCCLUSION_NEWLY_VISIBLE_BIT),
        ),
        ("OCCLUSION_CULLED_BIT", uint(OCCLUSION_CULLED_BIT)),
        ("OCCLUSION_PHASE_ALL", uint(OCCLUSION_PHASE_ALL)),
        ("OCCLUSION_PHASE_FIRST", uint(OCCLUSION_PHASE_FIRST)),
        ("OCCLUSION_PHASE_SECOND", uint(OCCLUSION_PHASE_SECOND)),
        ("OCCLUSION_PHASE_CULLED", uint(OCCLUSION_PHASE_CULLED)),
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
        ("SPEC_STREAMED", SPEC_STREAMED.to_string()),
        ("BINDING_PAGES", BINDING_PAGES.to_string()),
        ("BINDING_PAGE_TABLE", BINDING_PAGE_TABLE.to_string()),
        ("BINDING_SEEN_PIXELS", BINDING_SEEN_PIXELS.to_string()),
        (
            "BINDING_PATCH_CONSTANTS",
            BINDING_PATCH_CONSTANTS.to_string(),
        ),
        ("OWN_PATCH_CONSTANTS", uint(OWN_PATCH_CONSTANTS)),
        ("PAGE_LEVEL_SHIFT", PAGE_LEVEL_SHIFT.to_string()),
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
