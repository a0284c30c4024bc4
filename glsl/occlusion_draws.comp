#version 460
#extension GL_GOOGLE_include_directive : require
#include "occlusion.glsl"

// The instance count of each draw the CPU lists (a geomip patch, a batch
// of tess patches, a full-resolution tess patch) for one draw phase: 1 when
// the occlusion state keeps any of its patches, else 0. The draws are
// indirect, so a draw with nothing to keep costs nothing.

layout(local_size_x = 64) in;

layout(push_constant) uniform Select {
    uint count;   // draws in the list
    uint phase;   // OCCLUSION_PHASE_FIRST or OCCLUSION_PHASE_SECOND
    uint first;   // the phase's first command
} pc;

// The patches of each draw: first, count (grid order).
layout(std430, set = 0, binding = BINDING_DRAW_PATCHES) readonly buffer DrawPatches {
    uvec2 draw_patches[];
};

// VkDrawIndexedIndirectCommand: index count, instance count, first index,
// vertex offset, first instance.
layout(std430, set = 0, binding = BINDING_DRAW_COMMANDS) buffer DrawCommands {
    uint commands[];
};

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.count) {
        return;
    }
    uvec2 range = draw_patches[i];
    bool drawn = false;
    for (uint p = range.x; p < range.x + range.y; ++p) {
        drawn = drawn || drawn_in_phase(pc.phase, int(p));
    }
    commands[(pc.first + i) * 5u + 1u] = drawn ? 1u : 0u;
}
