#version 460
#extension GL_GOOGLE_include_directive : require
#include "terrain_common.glsl"
#ifdef MATERIAL
#include "material.glsl"
#endif

layout(quads, fractional_even_spacing, ccw) in;

layout(location = 0) in vec3 in_rel[];
layout(location = 1) in vec2 in_grid[];
layout(location = 2) patch in float in_inside_factor;

layout(location = 0) out vec2 out_grid;
layout(location = 1) out float out_height;
layout(location = 2) flat out float out_inside_factor;

void main() {
    vec2 uv = gl_TessCoord.xy;
    // Bilinear interpolation across the patch: u runs left to right, v top
    // to bottom.
    vec3 rel = mix(mix(in_rel[0], in_rel[1], uv.x), mix(in_rel[2], in_rel[3], uv.x), uv.y);
    vec2 g = mix(mix(in_grid[0], in_grid[1], uv.x), mix(in_grid[2], in_grid[3], uv.x), uv.y);
    float h = sample_height(g);
#ifdef DISPLACE
    h += layer_displacement(g, h);
#endif
    rel.y = h - frame.eye_local.y;
    gl_Position = frame.view_proj * vec4(rel, 1.0);
    out_grid = g;
    out_height = h;
    out_inside_factor = in_inside_factor;
}
