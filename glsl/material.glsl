// Material layers: parameters, weights, projections and displacement.
// Included after terrain_common.glsl by the stages of scenes with layers
// (MATERIAL), with DISPLACE in the vertex stages of scenes whose layers
// displace, BLEND_MAPS in blend-map mode, NORMAL_MAPS when a layer has a
// normal map and TRIPLANAR when steep ground is projected from the side.
// The layer and blend-map counts are specialisation constants.

layout(constant_id = SPEC_LAYER_COUNT) const uint LAYER_COUNT = 1u;
layout(constant_id = SPEC_BLEND_MAP_COUNT) const uint BLEND_MAP_COUNT = 1u;

// One layer. Mirrors `render::material::LayerUniform`.
struct Layer {
    // Rows of the world (x, z) -> texture (u, v) matrix: (m00, m01, m10, m11).
    vec4 tile;
    // xy: offset in repeats; z: displacement scale; w: normal-map layer (-1: none).
    vec4 offset;
    // x: height-map layer (-1: none); y, z: rules-mode height band centre and
    // half-width (half-width 0: no band); w: the texture's mip level for
    // vertex fetches.
    vec4 band;
};

// Mirrors `render::material::MaterialUniforms`.
layout(std140, set = 0, binding = BINDING_MATERIAL) uniform Material {
    Layer layers[MAX_LAYERS];
    // x: cliff layer (-1: none); y, z: slopes in degrees where the cliff
    // layer starts and takes over.
    vec4 rules;
} material;

#ifdef BLEND_MAPS
layout(set = 0, binding = BINDING_BLEND_MAPS) uniform sampler2DArray blend_maps;

// Texture coordinates of a map stretched over the terrain with a texel
// centred on every sample (or every 2^k-th).
vec2 stretched_uv(vec2 g, vec2 map_size) {
    return (g / (frame.spacing_size.zw - 1.0) * (map_size - 1.0) + 0.5) / map_size;
}

// Per-layer weights of blend-map values: layer k (1..) is laid over the
// layers below it with opacity b[k - 1]. Mirror: terrain::shading::blend_map_weights.
void blend_weights(vec4 b0, vec4 b1, out float w[MAX_LAYERS]) {
    float b[MAX_LAYERS - 1] = float[MAX_LAYERS - 1](b0.x, b0.y, b0.z, b0.w, b1.x, b1.y, b1.z);
    float left = 1.0;
    for (int k = MAX_LAYERS - 1; k >= 1; --k) {
        float o = k < int(LAYER_COUNT) ? clamp(b[k - 1], 0.0, 1.0) : 0.0;
        w[k] = left * o;
        left *= 1.0 - o;
    }
    w[0] = left;
}
#else
// Weights from height bands normalised to sum 1 (all on layer 0 where no
// band reaches), blended towards the cliff layer by slope.
// Mirror: terrain::shading::Rules::weights.
void rule_weights(float height, float normal_y, out float w[MAX_LAYERS]) {
    float sum = 0.0;
    for (int i = 0; i < MAX_LAYERS; ++i) {
        vec4 band = material.layers[i].band;
        w[i] = (i < int(LAYER_COUNT) && band.z > 0.0)
            ? clamp(1.0 - abs(height - band.y) / band.z, 0.0, 1.0) : 0.0;
        sum += w[i];
    }
    for (int i = 0; i < MAX_LAYERS; ++i) {
        w[i] = sum > 0.0 ? w[i] / sum : (i == 0 ? 1.0 : 0.0);
    }
    int cliff = int(material.rules.x);
    if (cliff >= 0) {
        float slope = degrees(acos(clamp(normal_y, -1.0, 1.0)));
        float lo = material.rules.y;
        float hi = material.rules.z;
        float s = hi > lo ? smoothstep(lo, hi, slope) : (slope >= hi ? 1.0 : 0.0);
        for (int i = 0; i < MAX_LAYERS; ++i) {
            w[i] *= 1.0 - s;
        }
        w[cliff] += s;
    }
}
#endif

// Texture coordinates of layer i at plane coordinates q (local (x, z) for
// the projection from above).
vec2 layer_uv(int i, vec2 q) {
    vec4 m = material.layers[i].tile;
    return vec2(dot(m.xy, q), dot(m.zw, q)) + material.layers[i].offset.xy;
}

// Projections of the layers' maps, by the axis they look along: 0 along
// x, 1 from above (along y), 2 along z. Without TRIPLANAR only the one
// from above is used. Every layer maps the plane
// coordinates of each through its own tile matrix, so a texture keeps
// its scale on every face.
const int PROJECT_X = 0;
const int PROJECT_Y = 1;
const int PROJECT_Z = 2;

// Plane coordinates of local point p = (x, height, z) in projection a:
// (z, -y) along x, (x, z) from above, (x, -y) along z.
vec2 projected(int a, vec3 p) {
    return a == PROJECT_X ? vec2(p.z, -p.y) : a == PROJECT_Y ? p.xz : vec2(p.x, -p.y);
}

// The local direction of plane direction d of projection a, lifted along
// the projection's axis onto the surface of unit normal n (whose
// component along that axis is not 0 where the projection is used).
vec3 lifted(int a, vec2 d, vec3 n) {
    vec3 t = a == PROJECT_X ? vec3(0.0, -d.y, d.x)
           : a == PROJECT_Y ? vec3(d.x, 0.0, d.y)
                            : vec3(d.x, -d.y, 0.0);
    t[a] = -dot(t, n) / n[a];
    return normalize(t);
}

#ifdef TRIPLANAR
// Where a projection starts to take part: once the normal's component
// along its axis passes this. Ground under about 35 degrees of slope is
// projected from above alone, ground over about 55 degrees from the sides
// alone. It is just over 1 / sqrt(3), so the smallest component never
// passes it: two projections are enough (biplanar), and the two kept
// change places only where the one that leaves has weight 0.
const float TRIPLANAR_START = 0.58;
const int PROJECTIONS = 2;

// The two projections to sample at unit normal n and their weights
// (summing to 1): the axes of its largest and middle components, each
// weighted by its component past TRIPLANAR_START, squared. Within a hair
// of the cube's diagonal, where neither passes, the largest alone.
void projections(vec3 n, out ivec2 axes, out vec2 weights) {
    vec3 m = abs(n);
    int major = m.x >= m.y ? (m.x >= m.z ? PROJECT_X : PROJECT_Z)
                           : (m.y >= m.z ? PROJECT_Y : PROJECT_Z);
    int p = major == PROJECT_X ? PROJECT_Y : PROJECT_X;
    int q = major == PROJECT_Z ? PROJECT_Y : PROJECT_Z;
    int median = m[p] >= m[q] ? p : q;
    vec2 w = max(vec2(m[major], m[median]) - TRIPLANAR_START, 0.0);
    w *= w;
    float sum = w.x + w.y;
    axes = ivec2(major, median);
    weights = sum > 0.0 ? w / sum : vec2(1.0, 0.0);
}
#else
const int PROJECTIONS = 1;

void projections(vec3 n, out ivec2 axes, out vec2 weights) {
    axes = ivec2(PROJECT_Y);
    weights = vec2(1.0, 0.0);
}
#endif

#ifdef DISPLACE
layout(set = 0, binding = BINDING_HEIGHT_MAPS) uniform sampler2DArray height_maps;

// Height the layers add at sample coordinates g (surface height h): each
// layer with a height map moves the surface by scale * (sample - 0.5),
// weighted. A function of g alone, so patches that share a vertex move it
// alike. Mirror: terrain::shading::max_displacement bounds it.
float layer_displacement(vec2 g, float h) {
    // The undisplaced surface's normal: for the rules' slope and the
    // projections.
    vec3 n = gradient_normal(height_gradient(g));
    float w[MAX_LAYERS];
#ifdef BLEND_MAPS
    vec2 size = vec2(textureSize(blend_maps, 0).xy);
    vec2 uv = stretched_uv(g, size);
    vec4 b0 = textureLod(blend_maps, vec3(uv, 0.0), 0.0);
    vec4 b1 = BLEND_MAP_COUNT > 1u ? textureLod(blend_maps, vec3(uv, 1.0), 0.0) : vec4(0.0);
    blend_weights(b0, b1, w);
#else
    rule_weights(normalised_height(h), n.y, w);
#endif
    vec2 xz = grid_to_local(g);
    vec3 p = vec3(xz.x, h, xz.y);
    // Projected like the colour and normal maps, so the displaced surface
    // and its shading agree.
    ivec2 axes;
    vec2 pw;
    projections(n, axes, pw);
    float d = 0.0;
    for (int i = 0; i < int(LAYER_COUNT); ++i) {
        int layer = int(material.layers[i].band.x);
        if (layer >= 0 && w[i] > 0.0) {
            float s = 0.0;
            for (int k = 0; k < PROJECTIONS; ++k) {
                if (pw[k] > 0.0) {
                    s += pw[k] * textureLod(height_maps,
                        vec3(layer_uv(i, projected(axes[k], p)), float(layer)),
                        material.layers[i].band.w).r;
                }
            }
            d += w[i] * material.layers[i].offset.z * (s - 0.5);
        }
    }
    return d;
}
#endif
