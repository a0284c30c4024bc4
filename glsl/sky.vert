#version 460
#extension GL_GOOGLE_include_directive : require
#include "terrain_common.glsl"

// One triangle over the whole viewport, at the far plane (depth 0 with
// reversed Z): drawn after the terrain, it fills only what the terrain
// left uncovered.

layout(location = 0) out vec2 out_ndc;

void main() {
    vec2 p = vec2(float((gl_VertexIndex & 1) << 2) - 1.0, float((gl_VertexIndex & 2) << 1) - 1.0);
    gl_Position = vec4(p, 0.0, 1.0);
    out_ndc = p;
}
