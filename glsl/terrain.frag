#version 460
#extension GL_GOOGLE_include_directive : require
#include "terrain_common.glsl"

layout(location = 0) in vec2 in_grid;
layout(location = 1) in float in_height;
layout(location = 2) flat in float in_inside_factor;

layout(location = 0) out vec4 out_color;

// Unit normal by central differences one sample either side, one-sided at
// the borders (the offsets are clamped to the grid, and the step is the
// distance actually spanned). Mirror: TerrainInfo::normal_at.
vec3 surface_normal(vec2 g) {
    vec2 size = frame.spacing_size.zw;
    float left = max(g.x - 1.0, 0.0);
    float right = min(g.x + 1.0, size.x - 1.0);
    float up = max(g.y - 1.0, 0.0);
    float down = min(g.y + 1.0, size.y - 1.0);
    float dhdx = (sample_height(vec2(right, g.y)) - sample_height(vec2(left, g.y)))
        / ((right - left) * frame.spacing_size.x);
    // Rows grow towards -z: up (smaller row) is +z.
    float dhdz = (sample_height(vec2(g.x, up)) - sample_height(vec2(g.x, down)))
        / ((down - up) * frame.spacing_size.y);
    return normalize(vec3(-dhdx, 1.0, -dhdz));
}

// Low ground green, through brown rock, to snow.
vec3 height_color(float t) {
    vec3 low = vec3(0.20, 0.36, 0.14);
    vec3 mid = vec3(0.42, 0.35, 0.25);
    vec3 high = vec3(0.92, 0.92, 0.95);
    return t < 0.6 ? mix(low, mid, t / 0.6) : mix(mid, high, (t - 0.6) / 0.4);
}

// One hue per power of two: 1 blue ... 64 red.
vec3 lod_color(float factor) {
    float t = clamp(log2(max(factor, 1.0)) / MAX_TESS_EXPONENT, 0.0, 1.0);
    return clamp(vec3(abs(t * 6.0 - 3.0) - 1.0, 2.0 - abs(t * 6.0 - 2.0), 2.0 - abs(t * 6.0 - 4.0)), 0.0, 1.0).bgr;
}

void main() {
    uint mode = frame.modes.y;
    if (mode == SHADE_FLAT) {
        out_color = vec4(1.0);
        return;
    }
    vec3 n = surface_normal(in_grid);
    float diffuse = max(dot(n, frame.light.xyz), 0.0);
    float lighting = frame.light.w + (1.0 - frame.light.w) * diffuse;
    vec3 albedo;
    if (mode == SHADE_LOD_COLORS) {
        albedo = lod_color(in_inside_factor);
    } else {
        float span = max(frame.height_range.y - frame.height_range.x, 1e-6);
        albedo = height_color(clamp((in_height - frame.height_range.x) / span, 0.0, 1.0));
    }
    out_color = vec4(albedo * lighting, 1.0);
}
