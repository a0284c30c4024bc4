#version 460
#extension GL_GOOGLE_include_directive : require
#include "occlusion.glsl"

// The instance count (0 or 1) of each patch drawn from the CPU's list (the
// geomip path's patches, the tess path's full-resolution ones) for one
// draw phase, from the occlusion state: the draws are indirect, so a patch
// the phase does not keep costs nothing.

layout(local_size_x = 64) in;

layout(push_constant) uniform Select {
    uint count;   // draws in the list
    uint phase;   // OCCLUSION_PHASE_FIRST or OCCLUSION_PHASE_SECOND
    uint first;   // the phase's first command
} pc;

// The patch of each draw.
layout(std430, set = 0, binding = BINDING_DRAW_PATCHES) readonly buffer DrawPatches {
    uint draw_patches[];
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
    bool drawn = drawn_in_phase(pc.phase, int(draw_patches[i]));
    commands[(pc.first + i) * 5u + 1u] = drawn ? 1u : 0u;
}
