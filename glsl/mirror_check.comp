#version 460
#extension GL_GOOGLE_include_directive : require
#include "terrain_common.glsl"

// Evaluates the shared GLSL formulas on inputs from the CPU so tests can
// hold them against their Rust mirrors: the tessellation factor, the
// frustum test and height sampling, exactly as the terrain stages use them.

layout(local_size_x = 64) in;

// Per case: a position (camera-relative for the factor, the box centre for
// the frustum test), then the box extents, then continuous sample
// coordinates (column, row) in xy.
layout(std430, set = 0, binding = BINDING_MIRROR_CASES) readonly buffer Cases {
    vec4 cases[];
};

// Per case: factor, 1 if the box is outside the frustum, sampled height.
layout(std430, set = 0, binding = BINDING_MIRROR_RESULTS) writeonly buffer Results {
    vec4 results[];
};

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (3u * i + 2u >= uint(cases.length())) {
        return;
    }
    vec4 position = cases[3u * i];
    vec4 extents = cases[3u * i + 1u];
    vec4 grid = cases[3u * i + 2u];
    results[i] = vec4(
        tess_factor(position.xyz),
        aabb_outside_frustum(position.xyz, extents.xyz) ? 1.0 : 0.0,
        sample_height(grid.xy),
        0.0);
}
