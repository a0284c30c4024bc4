#version 460
#extension GL_GOOGLE_include_directive : require
#include "terrain_common.glsl"
#ifdef MATERIAL
#include "material.glsl"
#endif

// The geomip path: one vertex template of (N+1)^2 grid offsets drawn once
// per visible patch, with the patch's level and sides: listed in a storage
// buffer and found by the draw's instance index (a frame's draws then go
// in one indirect call), or pushed with the draw.
// Mirror: terrain::geomip (levels, morph targets; the factors come from
// terrain::geomip::patch_morph in the constants), and
// render::geomip_path::GeomipConstants / GeomipPush.

layout(location = 0) in uvec2 in_offset;  // (column, row) in the patch

struct PatchConstants {
    ivec2 origin;      // sample (column, row) of the patch's upper-left corner
    int level;         // step 2^level
    float interior;    // morph factor of the interior
    vec4 sides;        // morph factors of the left, top, right, bottom sides
};

layout(std430, set = 0, binding = BINDING_PATCH_CONSTANTS) readonly buffer ListedConstants {
    PatchConstants listed[];
};

layout(push_constant) uniform DrawConstants {
    PatchConstants own;  // the draw's own constants, with OWN_PATCH_CONSTANTS
    uint first_listed;   // else the list index the instance index counts from
} draw;

PatchConstants pc;

layout(location = 0) out vec2 out_grid;
layout(location = 1) out float out_height;
layout(location = 2) flat out float out_inside_factor;

ivec2 clamp_sample(ivec2 offset) {
    // Remainder patches: offsets past the last sample collapse onto it.
    return min(pc.origin + offset, ivec2(frame.spacing_size.zw) - 1);
}

// The height drawn at a sample: the heightmap's, plus what the layers add.
float displaced(ivec2 sample_cr) {
    float h = fetch_sample(sample_cr);
#ifdef DISPLACE
    h += layer_displacement(vec2(sample_cr), h);
#endif
    return h;
}

float height_of(ivec2 offset) {
    return displaced(clamp_sample(offset));
}

void main() {
    pc = draw.first_listed == OWN_PATCH_CONSTANTS
        ? draw.own
        : listed[draw.first_listed + uint(gl_InstanceIndex)];
    ivec2 offset = ivec2(in_offset);
    ivec2 sample_cr = clamp_sample(offset);
    float h = displaced(sample_cr);

    int n = int(frame.cells_per_patch);
    int s = 1 << pc.level;
    ivec2 k = offset / s;
    bool odd_x = (k.x & 1) == 1;
    bool odd_y = (k.y & 1) == 1;
    // A vertex on a side takes that side's factor (shared with the
    // neighbour); corners are never odd.
    float morph = offset.x == 0 ? pc.sides.x
        : offset.y == 0 ? pc.sides.y
        : offset.x == n ? pc.sides.z
        : offset.y == n ? pc.sides.w
        : pc.interior;
    if ((odd_x || odd_y) && morph > 0.0) {
        // Mirror: terrain::geomip::morph_target.
        ivec2 a = odd_x && odd_y ? offset + ivec2(s, -s) : (odd_x ? offset - ivec2(s, 0) : offset - ivec2(0, s));
        ivec2 b = odd_x && odd_y ? offset + ivec2(-s, s) : (odd_x ? offset + ivec2(s, 0) : offset + ivec2(0, s));
        h = mix(h, 0.5 * (height_of(a) + height_of(b)), morph);
    }
    // Level 0 without morph is the reference's own triangles: the tess
    // path's full-resolution patches are drawn this way, and their edges
    // meet the tessellated ones on the same samples (surface_clip_position).
    gl_Position = surface_clip_position(vec2(sample_cr), h);
    out_grid = vec2(sample_cr);
    out_height = h;
    // Shown as the tessellation factor with the same density.
    out_inside_factor = float(n >> pc.level);
}
