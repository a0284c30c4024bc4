#version 460
#extension GL_GOOGLE_include_directive : require
#include "terrain_common.glsl"

// Control point: local x, z and (in a patch's upper-left point) its Y bounds.
layout(location = 0) in vec4 in_control_point;

layout(location = 0) out vec3 out_rel;      // camera-relative position
layout(location = 1) out vec2 out_grid;     // sample coordinates
layout(location = 2) out vec2 out_bounds_y; // patch min/max height

void main() {
    // Control points sit on samples; rounding removes the f32 noise of the
    // local -> grid conversion so the displacement reads that sample exactly.
    vec2 g = round(local_to_grid(in_control_point.xy));
    float h = sample_height(g);
    out_rel = vec3(in_control_point.x, h, in_control_point.y) - frame.eye_local.xyz;
    out_grid = g;
    out_bounds_y = in_control_point.zw;
}
