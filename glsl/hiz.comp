#version 460

// Several levels of the occlusion pyramid in one dispatch. Each texel is
// the farthest depth (reversed Z: the smallest value) of the 2x2 texels
// under it in the level below, or of the 2x2 pixels (every sample of each)
// of the depth attachment for the pyramid's first level. Level j of the
// dispatch has ceil(src_size / 2^(j+1)) texels a side; a texel past an odd
// edge takes only the texels that exist under it (the same as reading the
// last row or column again), so every texel covers exactly the pixels
// under it.
//
// Each invocation reduces a BLOCK x BLOCK block of the dispatch's first
// level, then halves it in registers down to one texel: up to
// HIZ_LEVELS_PER_DISPATCH levels with no barrier between them, so the whole
// pyramid of a 1280x720 target takes three launches, and most of its cost
// is reading the depth once.

#define BLOCK (1 << (HIZ_LEVELS_PER_DISPATCH - 1))

layout(local_size_x = 8, local_size_y = 8) in;

layout(push_constant) uniform Reduce {
    ivec2 src_size;  // texels (pixels) of what is read
    uint src_offset; // first float of the level read (pyramid levels)
    uint dst_offset; // first float of the dispatch's first level
    uint samples;    // samples per pixel of the depth attachment
    uint levels;     // levels written, 1 to HIZ_LEVELS_PER_DISPATCH
} pc;

layout(std430, set = 0, binding = BINDING_HIZ_PYRAMID) buffer Pyramid {
    float pyramid[];
};

#if defined(FROM_DEPTH_MS)
layout(set = 0, binding = BINDING_HIZ_DEPTH) uniform sampler2DMS depth;
#elif defined(FROM_DEPTH)
layout(set = 0, binding = BINDING_HIZ_DEPTH) uniform sampler2D depth;
#endif

#if !defined(FROM_DEPTH)
float farthest_at(ivec2 p) {
#if defined(FROM_DEPTH_MS)
    float d = texelFetch(depth, p, 0).r;
    for (int s = 1; s < int(pc.samples); ++s) {
        d = min(d, texelFetch(depth, p, s).r);
    }
    return d;
#else
    return pyramid[pc.src_offset + uint(p.y * pc.src_size.x + p.x)];
#endif
}
#endif

// The farthest depth of the 2x2 texels (pixels) under texel t of the
// dispatch's first level, the last row or column read again past an odd
// edge.
float farthest_under(ivec2 t) {
#if defined(FROM_DEPTH)
    // One gather reads the 2x2 pixels around the corner they share; the
    // sampler clamps to the edge.
    vec4 d = textureGather(depth, vec2(2 * t + 1) / vec2(pc.src_size));
    return min(min(d.x, d.y), min(d.z, d.w));
#else
    ivec2 p0 = 2 * t;
    ivec2 p1 = min(p0 + 1, pc.src_size - 1);
    return min(min(farthest_at(p0), farthest_at(ivec2(p1.x, p0.y))),
               min(farthest_at(ivec2(p0.x, p1.y)), farthest_at(p1)));
#endif
}

// Texels of the dispatch's level j.
ivec2 level_size(uint j) {
    return (pc.src_size + ((2 << j) - 1)) >> (j + 1);
}

void main() {
    ivec2 block = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = level_size(0u);
    if (any(greaterThanEqual(block * BLOCK, size))) {
        return;
    }

    // The block's texels of level j, row stride BLOCK; a texel past the
    // level's edge holds 1.0 (the nearest depth), which no min picks.
    float v[BLOCK * BLOCK];
    uint offset = pc.dst_offset;
    for (int y = 0; y < BLOCK; ++y) {
        for (int x = 0; x < BLOCK; ++x) {
            ivec2 t = block * BLOCK + ivec2(x, y);
            float d = 1.0;
            if (all(lessThan(t, size))) {
                d = farthest_under(t);
                pyramid[offset + uint(t.y * size.x + t.x)] = d;
            }
            v[y * BLOCK + x] = d;
        }
    }

    // Levels 1 on: the block halves in place. A texel past the level's
    // edge has only texels past the edge under it, so it stays 1.0.
    int side = BLOCK;
    for (uint j = 1u; j < pc.levels; ++j) {
        offset += uint(size.x * size.y);
        size = level_size(j);
        side >>= 1;
        for (int y = 0; y < side; ++y) {
            for (int x = 0; x < side; ++x) {
                int i = 2 * y * BLOCK + 2 * x;
                float d = min(min(v[i], v[i + 1]), min(v[i + BLOCK], v[i + BLOCK + 1]));
                v[y * BLOCK + x] = d;
                ivec2 t = block * side + ivec2(x, y);
                if (all(lessThan(t, size))) {
                    pyramid[offset + uint(t.y * size.x + t.x)] = d;
                }
            }
        }
    }
}
