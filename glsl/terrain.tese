#version 460
#extension GL_GOOGLE_include_directive : require
#include "terrain_common.glsl"
#ifdef MATERIAL
#include "material.glsl"
#endif

// The error LOD's factors are whole numbers (powers of two, or an edge's
// cell count towards a full-resolution neighbour), tessellated with equal
// spacing so the surface is the one the error table bounds; the distance
// LOD glides with fractional even spacing. u runs along +x and v along +z,
// so the domain's clockwise order is the counter-clockwise front face the
// pipelines cull against, as the brute and geomip paths wind theirs.
#ifdef EQUAL_SPACING
layout(quads, equal_spacing, cw) in;
#else
layout(quads, fractional_even_spacing, cw) in;
#endif

layout(location = 1) in vec2 in_grid[];
layout(location = 2) patch in float in_inside_factor;

layout(location = 0) out vec2 out_grid;
layout(location = 1) out float out_height;
layout(location = 2) flat out float out_inside_factor;

void main() {
    vec2 uv = gl_TessCoord.xy;
    // Bilinear interpolation across the patch: u runs left to right, v top
    // to bottom. Positions that are whole samples in exact arithmetic
    // (k * cells / L for a factor L) are snapped onto them: every other
    // position is at least 1/64 of a cell from a sample, and a vertex on a
    // sample then reads it exactly and lands where the full-resolution
    // draw puts it.
    vec2 g = mix(mix(in_grid[0], in_grid[1], uv.x), mix(in_grid[2], in_grid[3], uv.x), uv.y);
    vec2 nearest = round(g);
    g = mix(g, nearest, lessThan(abs(g - nearest), vec2(1.0 / 128.0)));
    float h = sample_height(g);
#ifdef DISPLACE
    h += layer_displacement(g, h);
#endif
    gl_Position = surface_clip_position(g, h);
    out_grid = g;
    out_height = h;
    out_inside_factor = in_inside_factor;
}
