#version 460
#extension GL_GOOGLE_include_directive : require
#include "terrain_common.glsl"
#ifdef MATERIAL
#include "material.glsl"
#endif

// The brute path: every sample is a vertex and nothing is buffered. Six
// vertices per cell, cells row-major, form the triangles ABC and DCB of
// height_at's split (A upper-left, B upper-right, C lower-left, D lower-right).
// Mirror: TerrainInfo::height_at (the split), TerrainInfo::local_x/local_z.

layout(location = 0) out vec2 out_grid;
layout(location = 1) out float out_height;
layout(location = 2) flat out float out_inside_factor;

const ivec2 CORNER[6] = ivec2[6](
    ivec2(0, 0), ivec2(1, 0), ivec2(0, 1),  // A B C
    ivec2(1, 1), ivec2(0, 1), ivec2(1, 0)   // D C B
);

void main() {
    int cells_across = int(frame.spacing_size.z) - 1;
    int cell = gl_VertexIndex / 6;
    ivec2 sample_cr = ivec2(cell % cells_across, cell / cells_across) + CORNER[gl_VertexIndex % 6];
    float h = fetch_sample(sample_cr);
#ifdef DISPLACE
    h += layer_displacement(vec2(sample_cr), h);
#endif
    gl_Position = surface_clip_position(vec2(sample_cr), h);
    out_grid = vec2(sample_cr);
    out_height = h;
    // Full resolution: shown as the finest tessellation level.
    out_inside_factor = MAX_TESS_FACTOR;
}
