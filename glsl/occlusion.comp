#version 460
#extension GL_GOOGLE_include_directive : require
#include "terrain_common.glsl"

// The occlusion test, one invocation per patch, between the two draw
// passes. A patch's box (its corners' x and z, its Y bounds, which allow
// for material displacement) is projected; it is hidden when its nearest
// point lies behind the farthest depth the pyramid holds over every pixel
// the box can cover. The box encloses the patch's surface at any level,
// so a patch may be drawn needlessly but is never culled while any of it
// shows. The result, one word per patch (OCCLUSION_*_BIT), picks the
// second pass's patches and next frame's first.

layout(local_size_x = 64) in;

layout(push_constant) uniform Test {
    ivec2 size;   // pixels of the depth the pyramid was built from
    uint levels;  // pyramid levels; the last is 1x1
} pc;

layout(std430, set = 0, binding = BINDING_HIZ_PYRAMID) readonly buffer Pyramid {
    float pyramid[];
};

// Per control point: local x, z, and in a patch's upper-left point its
// Y bounds (the vertex buffer of the tess path).
layout(std430, set = 0, binding = BINDING_CONTROL_POINTS) readonly buffer ControlPoints {
    vec4 control_points[];
};

layout(std430, set = 0, binding = BINDING_VISIBILITY) buffer Visibility {
    uint visibility[];
};

// Patches in view hidden now and last frame (so nothing drew them),
// patches in view hidden now, drawn in the first pass or not, and every
// patch in view.
layout(std430, set = 0, binding = BINDING_OCCLUSION_COUNT) buffer Count {
    uint occluded_count;
    uint hidden_count;
    uint in_view_count;
};

// Texels of pyramid level l: each covers 2^(l+1) pixels a side.
ivec2 level_size(int l) {
    return (pc.size + ((2 << l) - 1)) >> (l + 1);
}

// Reversed Z: larger is nearer. True when every corner is in front of the
// eye, with the box's pixel rectangle (clamped to the target) and its
// nearest depth; false when the box reaches behind the eye (then it is
// treated as visible).
bool project_box(vec3 lo, vec3 hi, out ivec2 p0, out ivec2 p1, out float nearest, out bool on_screen) {
    vec2 ndc_min = vec2(1e30);
    vec2 ndc_max = vec2(-1e30);
    nearest = 0.0;
    for (int c = 0; c < 8; ++c) {
        vec3 corner = vec3((c & 1) != 0 ? hi.x : lo.x, (c & 2) != 0 ? hi.y : lo.y, (c & 4) != 0 ? hi.z : lo.z);
        vec4 clip = frame.view_proj * vec4(corner, 1.0);
        if (clip.w <= 1e-5) {
            return false;
        }
        vec3 ndc = clip.xyz / clip.w;
        ndc_min = min(ndc_min, ndc.xy);
        ndc_max = max(ndc_max, ndc.xy);
        nearest = max(nearest, ndc.z);
    }
    // Pixel i covers [i, i + 1); half a pixel of margin absorbs rounding.
    vec2 size = vec2(pc.size);
    vec2 lo_px = (ndc_min * 0.5 + 0.5) * size - 0.5;
    vec2 hi_px = (ndc_max * 0.5 + 0.5) * size + 0.5;
    on_screen = all(greaterThanEqual(hi_px, vec2(0.0))) && all(lessThan(lo_px, size));
    p0 = clamp(ivec2(floor(lo_px)), ivec2(0), pc.size - 1);
    p1 = clamp(ivec2(floor(hi_px)), ivec2(0), pc.size - 1);
    return true;
}

// The farthest depth over pixels p0..p1: at the finest level where they
// span at most 2x2 texels.
float farthest_over(ivec2 p0, ivec2 p1) {
    int level = 0;
    uint offset = 0u;
    while (level + 1 < int(pc.levels)
           && any(greaterThan((p1 >> (level + 1)) - (p0 >> (level + 1)), ivec2(1)))) {
        ivec2 s = level_size(level);
        offset += uint(s.x * s.y);
        level += 1;
    }
    int width = level_size(level).x;
    ivec2 t0 = p0 >> (level + 1);
    ivec2 t1 = p1 >> (level + 1);
    float d = 1.0;
    for (int y = t0.y; y <= t1.y; ++y) {
        for (int x = t0.x; x <= t1.x; ++x) {
            d = min(d, pyramid[offset + uint(y * width + x)]);
        }
    }
    return d;
}

void main() {
    int cols = int(frame.error_lod.z);
    int rows = int(frame.error_lod.w);
    int p = int(gl_GlobalInvocationID.x);
    if (p >= cols * rows) {
        return;
    }
    int row = p / cols;
    int col = p - row * cols;
    vec4 upper_left = control_points[row * (cols + 1) + col];
    vec4 lower_right = control_points[(row + 1) * (cols + 1) + col + 1];
    vec3 eye = frame.eye_local.xyz;
    vec3 lo = vec3(min(upper_left.x, lower_right.x), upper_left.z, min(upper_left.y, lower_right.y)) - eye;
    vec3 hi = vec3(max(upper_left.x, lower_right.x), upper_left.w, max(upper_left.y, lower_right.y)) - eye;

    bool was_visible = (visibility[p] & OCCLUSION_VISIBLE_BIT) != 0u;
    bool in_frustum = !aabb_outside_frustum(0.5 * (lo + hi), 0.5 * (hi - lo));
    bool visible = in_frustum;
    if (in_frustum) {
        ivec2 p0;
        ivec2 p1;
        float nearest;
        bool on_screen;
        if (project_box(lo, hi, p0, p1, nearest, on_screen)) {
            // A box the frustum planes keep may still cover no pixel: it
            // is outside the view, not hidden.
            in_frustum = on_screen;
            // A relative margin of 1e-5 in depth (1e-5 of the distance)
            // covers the rounding between this and the rasterised depths.
            visible = on_screen && nearest * (1.0 + 1e-5) >= farthest_over(p0, p1);
        }
    }
    if (in_frustum) {
        atomicAdd(in_view_count, 1u);
        if (!visible) {
            atomicAdd(hidden_count, 1u);
        }
    }
    uint state = 0u;
    if (visible) {
        state = was_visible ? OCCLUSION_VISIBLE_BIT : (OCCLUSION_VISIBLE_BIT | OCCLUSION_NEWLY_VISIBLE_BIT);
    } else if (in_frustum && !was_visible) {
        state = OCCLUSION_CULLED_BIT;
        atomicAdd(occluded_count, 1u);
    }
    visibility[p] = state;
}
