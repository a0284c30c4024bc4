#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_ballot : require
#include "terrain_common.glsl"
#ifdef MATERIAL
#include "material.glsl"
#endif

layout(location = 0) in vec2 in_grid;
layout(location = 1) in float in_height;
layout(location = 2) flat in float in_inside_factor;

layout(location = 0) out vec4 out_color;

// The depth test comes before this shader, as it would without the count
// below: only fragments in front of what is drawn so far are counted.
layout(early_fragment_tests) in;

// The pixels each patch shows, counted in the frames the CPU asks for
// (src/render/seen.rs): `counting` is 1 in such a frame. A pixel belongs
// to the patch owning the cell under its surface point (`patch_of_grid`).
layout(std430, set = 0, binding = BINDING_SEEN_PIXELS) buffer SeenPixels {
    uint counting;
    uint seen_pixels[];
};

// One atomic add per subgroup where its fragments share a patch (the
// common case: they are neighbours on screen), one each otherwise. Helper
// invocations, which cover no sample, take no part.
void count_seen_pixel() {
    if (counting == 0u || gl_SampleMaskIn[0] == 0) {
        return;
    }
    uint patch_index = patch_of_grid(in_grid);
    if (subgroupAllEqual(patch_index)) {
        uint fragments = subgroupBallotBitCount(subgroupBallot(true));
        if (subgroupElect()) {
            atomicAdd(seen_pixels[patch_index], fragments);
        }
    } else {
        atomicAdd(seen_pixels[patch_index], 1u);
    }
}

#ifdef MATERIAL
layout(set = 0, binding = BINDING_DIFFUSE_MAPS) uniform sampler2DArray diffuse_maps;
#endif
#ifdef NORMAL_MAPS
layout(set = 0, binding = BINDING_NORMAL_MAPS) uniform sampler2DArray normal_maps;
#endif
#ifdef LIGHTMAP
// Sunlight visibility of the first light, one texel per sample.
layout(set = 0, binding = BINDING_LIGHTMAP) uniform sampler2DArray lightmap;
#endif

// Low ground green, through brown rock, to snow.
vec3 height_color(float t) {
    vec3 low = vec3(0.20, 0.36, 0.14);
    vec3 mid = vec3(0.42, 0.35, 0.25);
    vec3 high = vec3(0.92, 0.92, 0.95);
    return t < 0.6 ? mix(low, mid, t / 0.6) : mix(mid, high, (t - 0.6) / 0.4);
}

// One hue per power of two, from blue (1) through cyan, green and yellow
// to red (64, full resolution): two thirds of the hue circle, so the ends
// never meet.
vec3 lod_color(float factor) {
    float t = clamp(log2(max(factor, 1.0)) / MAX_TESS_EXPONENT, 0.0, 1.0);
    float hue = 4.0 * (1.0 - t);
    return clamp(abs(mod(hue + vec3(0.0, 4.0, 2.0), 6.0) - 3.0) - 1.0, 0.0, 1.0);
}

// Ambient plus every directional light; the first is dimmed by the baked
// lightmap when there is one.
vec3 lighting(vec3 n) {
    vec3 light = frame.ambient.rgb;
    for (int i = 0; i < int(frame.ambient.w); ++i) {
        float visible = 1.0;
#ifdef LIGHTMAP
        if (i == 0) {
            vec2 size = frame.spacing_size.zw;
            visible = texture(lightmap, vec3((in_grid + 0.5) / size, 0.0)).r;
        }
#endif
        light += frame.light_color[i].rgb * max(dot(n, frame.light_dir[i].xyz), 0.0) * visible;
    }
    return light;
}

#ifdef MATERIAL
// Blended colour and normal of the layers at this fragment, each layer's
// maps projected as `projections` says (from above alone but with
// TRIPLANAR). A projection's tangent frame follows the layer's texture
// axes in its plane: u and v run along the rows of the tile matrix,
// lifted onto the surface along the projection's axis.
// `height` is the data's surface height under the fragment.
void layered(vec3 n, float height, out vec3 albedo, out vec3 normal) {
    float w[MAX_LAYERS];
#ifdef BLEND_MAPS
    vec2 size = vec2(textureSize(blend_maps, 0).xy);
    vec2 uv = stretched_uv(in_grid, size);
    vec4 b0 = texture(blend_maps, vec3(uv, 0.0));
    vec4 b1 = BLEND_MAP_COUNT > 1u ? texture(blend_maps, vec3(uv, 1.0)) : vec4(0.0);
    blend_weights(b0, b1, w);
#else
    rule_weights(normalised_height(height), n.y, w);
#endif
    vec2 xz = grid_to_local(in_grid);
    vec3 p = vec3(xz.x, in_height, xz.y);
    // Derivatives taken here, in uniform control flow, so layers and
    // projections whose weight is 0 can be skipped without losing mip
    // selection.
    vec3 dx = dFdx(p);
    vec3 dy = dFdy(p);
    ivec2 axes;
    vec2 pw;
    projections(n, axes, pw);
    albedo = vec3(0.0);
    normal = vec3(0.0);
    for (int i = 0; i < int(LAYER_COUNT); ++i) {
        if (w[i] <= 0.0) {
            continue;
        }
        vec4 m = material.layers[i].tile;
        for (int k = 0; k < PROJECTIONS; ++k) {
            if (pw[k] <= 0.0) {
                continue;
            }
            int a = axes[k];
            float weight = w[i] * pw[k];
            vec2 uv = layer_uv(i, projected(a, p));
            vec2 qx = projected(a, dx);
            vec2 qy = projected(a, dy);
            vec2 gx = vec2(dot(m.xy, qx), dot(m.zw, qx));
            vec2 gy = vec2(dot(m.xy, qy), dot(m.zw, qy));
            albedo += weight * textureGrad(diffuse_maps, vec3(uv, float(i)), gx, gy).rgb;
            vec3 layer_normal = n;
#ifdef NORMAL_MAPS
            int nl = int(material.layers[i].offset.w);
            if (nl >= 0) {
                vec3 t = textureGrad(normal_maps, vec3(uv, float(nl)), gx, gy).xyz * 2.0 - 1.0;
                vec3 tu = lifted(a, normalize(m.xy), n);
                vec3 tv = lifted(a, normalize(m.zw), n);
                // The third axis along the surface normal, whatever the
                // handedness of (u, v) on the surface.
                layer_normal = normalize(t.x * tu + t.y * tv + t.z * n);
            }
#endif
            normal += weight * layer_normal;
        }
    }
    normal = normalize(normal);
}
#endif

void main() {
    count_seen_pixel();
    uint mode = frame.shading;
    if (mode == SHADE_FLAT) {
        out_color = vec4(1.0);
        return;
    }
    vec2 gradient = height_gradient(in_grid);
    vec3 n = gradient_normal(gradient);
    // Colours by height read the data's surface under the pixel, as the
    // normal does, not the drawn triangle's: a coarse level's vertical
    // error stays within its pixel bound on screen, but would move every
    // colour band by its full size.
    float height = sample_height(in_grid);
    vec3 albedo;
    if (mode == SHADE_LOD_COLORS) {
        albedo = lod_color(in_inside_factor);
    } else {
#ifdef MATERIAL
        layered(n, height, albedo, n);
#else
        albedo = height_color(clamp(normalised_height(height), 0.0, 1.0));
#endif
    }
    vec3 color = albedo * lighting(n);
    if (frame.fog.y > 0.0) {
        vec3 rel = vec3(grid_to_local(in_grid), in_height).xzy - frame.eye_local.xyz;
        float f = clamp((length(rel) - frame.fog.x) * frame.fog.y, 0.0, 1.0);
        color = mix(color, frame.fog_color.rgb, f);
    }
    out_color = vec4(color, 1.0);
}
