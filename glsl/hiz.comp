#version 460

// One level of the occlusion pyramid: each texel is the farthest depth
// (reversed Z: the smallest value) of the 2x2 texels under it in the level
// below, or of the 2x2 pixels (every sample of each) of the depth
// attachment for the first level. Texels past an odd edge read the last
// row or column again, so every texel covers exactly the pixels under it.

layout(local_size_x = 8, local_size_y = 8) in;

layout(push_constant) uniform Reduce {
    ivec2 src_size;  // texels (pixels) of what is read
    ivec2 dst_size;  // texels of the level written
    uint src_offset; // first float of the level read (pyramid levels)
    uint dst_offset; // first float of the level written
    uint samples;    // samples per pixel of the depth attachment
} pc;

layout(std430, set = 0, binding = BINDING_HIZ_PYRAMID) buffer Pyramid {
    float pyramid[];
};

#if defined(FROM_DEPTH_MS)
layout(set = 0, binding = BINDING_HIZ_DEPTH) uniform sampler2DMS depth;
#elif defined(FROM_DEPTH)
layout(set = 0, binding = BINDING_HIZ_DEPTH) uniform sampler2D depth;
#endif

float farthest_at(ivec2 p) {
#if defined(FROM_DEPTH_MS)
    float d = texelFetch(depth, p, 0).r;
    for (int s = 1; s < int(pc.samples); ++s) {
        d = min(d, texelFetch(depth, p, s).r);
    }
    return d;
#elif defined(FROM_DEPTH)
    return texelFetch(depth, p, 0).r;
#else
    return pyramid[pc.src_offset + uint(p.y * pc.src_size.x + p.x)];
#endif
}

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(t, pc.dst_size))) {
        return;
    }
    ivec2 p0 = 2 * t;
    ivec2 p1 = min(p0 + 1, pc.src_size - 1);
    float d = min(min(farthest_at(p0), farthest_at(ivec2(p1.x, p0.y))),
                  min(farthest_at(ivec2(p0.x, p1.y)), farthest_at(p1)));
    pyramid[pc.dst_offset + uint(t.y * pc.dst_size.x + t.x)] = d;
}
