#version 460
#extension GL_GOOGLE_include_directive : require
#include "terrain_common.glsl"

// Evaluates the shared GLSL formulas on inputs from the CPU so tests can
// hold them against their Rust mirrors: the tessellation factor, the
// frustum test, height sampling and the patch a pixel is counted for, exactly as the terrain stages use them.

layout(local_size_x = 64) in;

// Per case: a position (camera-relative for the factors, the box centre for
// the frustum test), the box extents, continuous sample coordinates
// (column, row) in xy, in z the cells the error-bounded factor spans and
// in w a chosen level byte (`chosen_error`), and the 7 per-level errors
// for that factor (at the position's distance) in two vec4s.
layout(std430, set = 0, binding = BINDING_MIRROR_CASES) readonly buffer Cases {
    vec4 cases[];
};

// Per case, three vec4s: distance factor, 1 if the box is outside the
// frustum, sampled height, error-bounded factor; then the distance to the
// box (position +- extents) and to the strip on the segment from position
// to position + extents (x, z) between heights position.y -+ extents.y,
// the patch of the surface point at the sample coordinates, and the
// error-bounded factor of the errors as the chosen level byte reads them;
// then the peers' factors: sphere and edge length for the edge from
// position to position + extents, CDLOD at position.
layout(std430, set = 0, binding = BINDING_MIRROR_RESULTS) writeonly buffer Results {
    vec4 results[];
};

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (5u * i + 4u >= uint(cases.length())) {
        return;
    }
    vec4 position = cases[5u * i];
    vec4 extents = cases[5u * i + 1u];
    vec4 grid = cases[5u * i + 2u];
    vec4 e0 = cases[5u * i + 3u];
    vec4 e1 = cases[5u * i + 4u];
    float errors[ERROR_LEVEL_COUNT] = float[ERROR_LEVEL_COUNT](e0.x, e0.y, e0.z, e0.w, e1.x, e1.y, e1.z);
    float chosen[ERROR_LEVEL_COUNT];
    for (int k = 0; k < int(ERROR_LEVEL_COUNT); ++k) {
        chosen[k] = chosen_error(errors[k], k, int(grid.w));
    }
    results[3u * i] = vec4(
        tess_factor(position.xyz),
        aabb_outside_frustum(position.xyz, extents.xyz) ? 1.0 : 0.0,
        sample_height(grid.xy),
        error_tess_factor(errors, length(position.xyz), int(grid.z)));
    results[3u * i + 1u] = vec4(
        box_distance(position.xyz - extents.xyz, position.xyz + extents.xyz),
        edge_distance(position.xz, position.xz + extents.xz,
                      position.y - extents.y, position.y + extents.y),
        float(patch_of_grid(grid.xy)),
        error_tess_factor(chosen, length(position.xyz), int(grid.z)));
    results[3u * i + 2u] = vec4(
        sphere_tess_factor(position.xyz, position.xyz + extents.xyz),
        edge_length_tess_factor(position.xyz, position.xyz + extents.xyz),
        cdlod_tess_factor(position.xyz),
        0.0);
}
