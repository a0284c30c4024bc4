// Shared by every terrain stage: the per-frame uniform block, the heightmap,
// and the formulas the CPU model mirrors in Rust (each names its mirror).
// Constants (BINDING_*, *_TESS_*, LOD_MODE_*, SHADE_*) come from
// src/shader_constants.rs through build.rs.

// Per-frame values. Positions are camera-relative: the terrain's local
// coordinates minus the eye's, so precision does not depend on where the
// terrain sits in the world. Mirrors `render::uniforms::FrameUniforms`.
// The control shader defines FRAME_IN_STORAGE and reads the same block
// as a read-only storage buffer (`render::frame::DescriptorPlan::new` says why).
#ifdef FRAME_IN_STORAGE
layout(std140, set = 0, binding = BINDING_FRAME_STORAGE) readonly buffer Frame {
#else
layout(std140, set = 0, binding = BINDING_FRAME) uniform Frame {
#endif
    // Projection times the view's rotation (the eye is the origin).
    mat4 view_proj;
    // Normalised frustum planes in camera-relative coordinates, inside where
    // dot(n, p) + w >= 0.
    vec4 frustum[6];
    // xyz: the eye in terrain-local coordinates.
    vec4 eye_local;
    // min_dist, max_dist, min_exp, max_exp of the distance LOD.
    vec4 lod;
    // x: local x of sample column 0, y: local z of sample row 0,
    // z: 1 / dx, w: 1 / dz.
    vec4 grid;
    // dx, dz, columns, rows.
    vec4 spacing_size;
    // rgb: ambient light; w: number of directional lights (1..MAX_LIGHTS).
    vec4 ambient;
    // Lowest and highest height (colour ramp and the edges' strips).
    float height_min;
    float height_max;
    // 1 when frustum culling is on.
    uint cull;
    uint pad0;
    // LOD_MODE_*, SHADE_*, cells per patch, LOD_METRIC_*.
    uint lod_mode;
    uint shading;
    uint cells_per_patch;
    uint lod_metric;
    // x: largest projected error in pixels (error LOD), y: viewport height
    // over 2 tan(fov / 2), z, w: patch columns and rows.
    vec4 error_lod;
    // Directional lights: xyz towards the light (unit), and rgb radiance.
    vec4 light_dir[MAX_LIGHTS];
    vec4 light_color[MAX_LIGHTS];
    // x: fog start, y: 1 / fog range (0: no fog); fog_color.rgb.
    vec4 fog;
    vec4 fog_color;
    // The peers' policies: sphere edge px, sphere factor, edge target px,
    // CDLOD morph start.
    vec4 peer;
    // xy: viewport width and height in pixels.
    vec4 viewport;
    // xyz: the camera's right vector.
    vec4 camera_right;
    // Inverse of view_proj: clip-space points back to camera-relative ones.
    mat4 sky_ray;
    // rgb: the sky at the horizon; w: cosine of the sun disc's radius.
    vec4 sky_horizon;
    // rgb: the sky overhead.
    vec4 sky_zenith;
} frame;

// Heights, one texel per sample, row 0 first: R32_SFLOAT read with
// texelFetch (linear filtering of R32_SFLOAT is optional in Vulkan, and
// the surface between samples is triangles, not bilinear). Unread where
// heights are streamed.
layout(set = 0, binding = BINDING_HEIGHTMAP) uniform sampler2D heightmap;

// Whether heights are streamed (see render::streaming): every height is
// then in a page of `pages` (a block of 2^L x 2^L tiles at level L, every
// 2^L-th sample; the base level's pages always resident), and
// `page_table` gives each tile the finest resident page over it: its level
// above PAGE_LEVEL_SHIFT, its layer below. The streamed terrain's shape is
// constant for a pipeline.
layout(constant_id = SPEC_STREAMED) const bool STREAMED = false;
layout(constant_id = SPEC_STREAMED + 1) const int STREAM_TILE_CELLS = 1;
layout(constant_id = SPEC_STREAMED + 2) const int STREAM_BASE_LEVEL = 0;
layout(constant_id = SPEC_STREAMED + 3) const int STREAM_TILES_X = 1;
layout(constant_id = SPEC_STREAMED + 4) const int STREAM_TILES_Z = 1;
layout(set = 0, binding = BINDING_PAGES) uniform sampler2DArray pages;
layout(std430, set = 0, binding = BINDING_PAGE_TABLE) readonly buffer PageTable {
    uint page_table[];
};

// Local (x, z) to continuous sample coordinates (column, row).
// Mirror: TerrainInfo::world_to_grid (there with the world origin added).
vec2 local_to_grid(vec2 xz) {
    return vec2((xz.x - frame.grid.x) * frame.grid.z, (frame.grid.y - xz.y) * frame.grid.w);
}

// The patch (row-major index) owning the cell under continuous sample
// coordinates g, clamped to the grid. Mirror: PatchGrid::patch_of_cell on
// the cell floor(g) clamped to the last, as `lod::seen` counts pixels.
uint patch_of_grid(vec2 g) {
    ivec2 last_cell = ivec2(frame.spacing_size.zw) - 2;
    ivec2 cell = clamp(ivec2(floor(g)), ivec2(0), last_cell);
    int n = int(frame.cells_per_patch);
    int cols = (last_cell.x + n) / n;
    return uint((cell.y / n) * cols + cell.x / n);
}

// The height at a fraction st across a cell with samples a (upper left),
// b (upper right), c (lower left) and d (lower right), split along the
// diagonal from b to c: triangles ABC and DCB. Mirror: heightmap::blend_cell.
float blend_cell(vec2 st, float a, float b, float c, float d) {
    bool lower = st.x + st.y > 1.0;
    vec3 h = lower ? vec3(d, c, b) : vec3(a, b, c);
    vec2 uv = lower ? 1.0 - st : st;
    return (1.0 - uv.x - uv.y) * h.x + uv.x * h.y + uv.y * h.z;
}

// The cell of a level lattice (every 2^level-th sample of a grid whose
// last sample is `last`, and that last one) that sample s (not negative)
// lies in: the
// lattice index of its first corner, and s's fraction across it. The last
// cell of a row or column is narrower where the grid is not a multiple of
// 2^level. Mirror: tiled::level_surface.
void lattice_cell(ivec2 s, ivec2 last, int level, out ivec2 i, out vec2 st) {
    // s and last are not negative: shifts, not divisions (the level varies
    // per sample, and a vector integer division has no SIMD form).
    int step = 1 << level;
    ivec2 side = ((last + step - 1) >> level) + 1;
    i = min(s >> level, side - 2);
    ivec2 lo = i << level;
    st = vec2(s - lo) / vec2(min(lo + step, last) - lo);
}

// The surface at sample s of the level-`level` page in layer `layer`,
// whose first sample is `origin`: the same lattice surface as the whole
// level's, its cells read from the page.
float page_height(ivec2 s, ivec2 origin, int level, int layer) {
    ivec2 last = min(ivec2(STREAM_TILE_CELLS << level), ivec2(frame.spacing_size.zw) - 1 - origin);
    ivec2 i;
    vec2 st;
    lattice_cell(s - origin, last, level, i, st);
    float a = texelFetch(pages, ivec3(i, layer), 0).r;
    if (st == vec2(0.0)) {
        return a;
    }
    float b = texelFetch(pages, ivec3(i + ivec2(1, 0), layer), 0).r;
    float c = texelFetch(pages, ivec3(i + ivec2(0, 1), layer), 0).r;
    float d = texelFetch(pages, ivec3(i + ivec2(1, 1), layer), 0).r;
    return blend_cell(st, a, b, c, d);
}

// The height drawn at sample (column, row) s. Streamed: a sample belongs
// to one tile (on a border between tiles, the one before it: left,
// above), and takes the page its tile's entry names. Every sample so has
// one value whichever patch asks, and the surface stays watertight
// between tiles drawn at different levels.
// Mirror: render::residency::streamed_sample.
float fetch_sample(ivec2 s) {
    if (!STREAMED) {
        return texelFetch(heightmap, s, 0).r;
    }
    ivec2 tiles = ivec2(STREAM_TILES_X, STREAM_TILES_Z);
    ivec2 tile = min(max(s - 1, ivec2(0)) / STREAM_TILE_CELLS, tiles - 1);
    uint entry = page_table[tile.y * tiles.x + tile.x];
    int level = int(entry >> PAGE_LEVEL_SHIFT);
    int layer = int(entry & ((1u << PAGE_LEVEL_SHIFT) - 1u));
    return page_height(s, (tile >> level) * (STREAM_TILE_CELLS << level), level, layer);
}

// Height on the triangulated surface at continuous sample coordinates,
// clamped to the grid. Each cell splits along the diagonal from its
// upper-right sample B to its lower-left sample C: triangles ABC and DCB.
// Texel-centre addressing: sample (r, c) is texel (c, r) and returns its
// value exactly. Mirror: Heightmap::interpolate.
float sample_height(vec2 g) {
    vec2 size = frame.spacing_size.zw;
    vec2 p = clamp(g, vec2(0.0), size - 1.0);
    ivec2 cell = min(ivec2(p), ivec2(size) - 2);
    vec2 st = p - vec2(cell);
    float a = fetch_sample(cell);
    float b = fetch_sample(cell + ivec2(1, 0));
    float c = fetch_sample(cell + ivec2(0, 1));
    float d = fetch_sample(cell + ivec2(1, 1));
    return blend_cell(st, a, b, c, d);
}

// Local (x, z) of continuous sample coordinates. Mirror:
// TerrainInfo::local_x / local_z.
vec2 grid_to_local(vec2 g) {
    return vec2(frame.grid.x + g.x * frame.spacing_size.x, frame.grid.y - g.y * frame.spacing_size.y);
}

// Height gradient (dh/dx, dh/dz) by central differences one sample either
// side, one-sided at the borders (the offsets are clamped to the grid, and
// the step is the distance actually spanned). Mirror: TerrainInfo::normal_at.
vec2 height_gradient(vec2 g) {
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
    return vec2(dhdx, dhdz);
}

// Unit surface normal from the gradient.
vec3 gradient_normal(vec2 gradient) {
    return normalize(vec3(-gradient.x, 1.0, -gradient.y));
}

// Height normalised to the terrain's range (0 lowest, 1 highest).
float normalised_height(float h) {
    return (h - frame.height_min) / max(frame.height_max - frame.height_min, 1e-6);
}

// True when the box lies entirely behind one of the frustum planes; the
// per-plane tests are or-ed without an early exit.
// Mirror: terrain::camera::aabb_outside_frustum.
bool aabb_outside_frustum(vec3 center, vec3 extents) {
    bool outside = false;
    for (int i = 0; i < 6; ++i) {
        vec4 plane = frame.frustum[i];
        float radius = dot(extents, abs(plane.xyz));
        float distance = dot(plane.xyz, center) + plane.w;
        outside = outside || (distance + radius < 0.0);
    }
    return outside;
}

// Clamp to [0, 1] with NaN going to 1. Mirror: terrain::lod::saturate.
float lod_saturate(float x) {
    return x < 1.0 ? (x > 0.0 ? x : 0.0) : 1.0;
}

// Clamp to [1, 64] with NaN going to 1. Mirror: terrain::lod::clamp_tess_factor.
float clamp_tess_factor(float f) {
    return f > MIN_TESS_FACTOR ? (f < MAX_TESS_FACTOR ? f : MAX_TESS_FACTOR) : MIN_TESS_FACTOR;
}

// Distance tessellation factor at a camera-relative position:
// 2^mix(max_exp, min_exp, s), s = saturate((d - min_dist) / (max_dist - min_dist)).
// The debug mode measures the xz max-norm and rounds the exponent with
// floor(x + 0.5) (round() may go either way at .5).
// Mirror: terrain::lod::tess_factor.
float tess_factor(vec3 rel) {
    bool debug_mode = frame.lod_mode == LOD_MODE_DEBUG;
    float d = debug_mode ? max(abs(rel.x), abs(rel.z)) : length(rel);
    float range = max(frame.lod.y - frame.lod.x, 1.17549435e-38);
    float s = lod_saturate((d - frame.lod.x) / range);
    float exponent = frame.lod.w + s * (frame.lod.z - frame.lod.w);
    if (debug_mode) {
        exponent = floor(exponent + 0.5);
    }
    return clamp_tess_factor(exp2(exponent));
}

// Distance from the eye (the origin: positions are camera-relative) to the
// box [lo, hi]. Mirror: terrain::lod::box_distance.
float box_distance(vec3 lo, vec3 hi) {
    return length(max(max(lo, -hi), vec3(0.0)));
}

// Distance from the eye to the vertical strip standing on the segment a-b
// (camera-relative x, z) between heights y_lo and y_hi (camera-relative).
// Mirror: terrain::lod::edge_distance.
float edge_distance(vec2 a, vec2 b, float y_lo, float y_hi) {
    vec2 ab = b - a;
    float len2 = dot(ab, ab);
    float t = len2 > 0.0 ? clamp(-dot(a, ab) / len2, 0.0, 1.0) : 0.0;
    vec2 p = a + t * ab;
    float dy = max(max(y_lo, -y_hi), 0.0);
    return sqrt(dot(p, p) + dy * dy);
}

// Whether an error seen at `scale` pixels per unit is within tau pixels; a
// zero error always is, even where the scale is infinite. Mirror:
// terrain::lod::within_tolerance.
bool within_tolerance(float error, float scale, float tau) {
    return error == 0.0 || error * scale <= tau;
}

// Error-bounded tessellation factor of a span of `cells` cells: the
// smallest power of two below `cells` whose error projects to at most
// error_lod.x pixels at `distance`, else `cells` (a vertex on every sample).
// errors[k] is the error of 2^k segments. Mirror: terrain::lod::error_tess_factor.
float error_tess_factor(float errors[ERROR_LEVEL_COUNT], float distance, int cells) {
    float scale = frame.error_lod.y / max(distance, 1.17549435e-38);
    if (isnan(scale)) {
        return MIN_TESS_FACTOR;
    }
    float tau = max(frame.error_lod.x, 1.17549435e-38);
    float full = clamp(float(cells), MIN_TESS_FACTOR, MAX_TESS_FACTOR);
    for (int k = 0; k < int(ERROR_LEVEL_COUNT); ++k) {
        float factor = float(1 << k);
        if (factor >= full) {
            break;
        }
        if (within_tolerance(errors[k], scale, tau)) {
            return factor;
        }
    }
    return full;
}

// A patch's error at level index k as the error LOD's control shader reads
// it, from its own error there and the byte the frame plan wrote for it:
// 0 where its own errors decide, else the level index the plan's share of
// pixels over tau chose, plus one. From that level on the error reads as
// zero, so the patch is drawn no finer; below it the patch's own error
// stands, so where its own bound accepts a coarser level, as it does for
// smooth or farther patches of a block chosen as one, the patch is drawn
// that much coarser. Mirror: lod::plan::chosen_errors.
float chosen_error(float own, int k, int chosen) {
    return chosen != 0 && k >= chosen - 1 ? 0.0 : own;
}

// Clip-space position of the surface point at sample coordinates g with
// height h. Every path that places a vertex on a sample goes through here
// with the same arithmetic and no contraction, so a sample that two draws
// share lands on the same position bit for bit.
vec4 surface_clip_position(vec2 g, float h) {
    // grid_to_local, written out so `precise` covers it.
    precise float x = frame.grid.x + g.x * frame.spacing_size.x;
    precise float z = frame.grid.y - g.y * frame.spacing_size.y;
    precise vec3 rel = vec3(x, h, z) - frame.eye_local.xyz;
    precise vec4 clip = frame.view_proj * vec4(rel, 1.0);
    return clip;
}

// SaschaWillems's factor for the edge a-b (camera-relative): the edge's
// sphere, its diameter along the camera's right vector projected to NDC and
// scaled by the viewport, over peer.x pixels, times peer.y, clamped to
// [1, 64]. Mirror: terrain::lod::sphere_tess_factor.
float sphere_tess_factor(vec3 a, vec3 b) {
    vec3 mid = 0.5 * (a + b);
    float radius = 0.5 * distance(a, b);
    vec3 offset = radius * frame.camera_right.xyz;
    vec4 c0 = frame.view_proj * vec4(mid - offset, 1.0);
    vec4 c1 = frame.view_proj * vec4(mid + offset, 1.0);
    c0 /= c0.w;
    c1 /= c1.w;
    vec3 p0 = vec3(c0.xy * frame.viewport.xy, c0.z);
    vec3 p1 = vec3(c1.xy * frame.viewport.xy, c1.z);
    return clamp_tess_factor(distance(p0, p1) / frame.peer.x * frame.peer.y);
}

// Dupuy's factor for the edge a-b (camera-relative): its length seen from
// its centre in pixels over peer.z, clamped to [1, 64].
// Mirror: terrain::lod::edge_length_tess_factor.
float edge_length_tess_factor(vec3 a, vec3 b) {
    float d = max(length(0.5 * (a + b)), 1.17549435e-38);
    float pixels = distance(a, b) * frame.error_lod.y / d;
    return clamp_tess_factor(pixels / frame.peer.z);
}

// CDLOD's factor at a camera-relative position: level l covers distances
// up to lod.x * 2^l, drawn at 2^(max_exp - l), morphing into the next over
// the last (1 - peer.w) of its range; never below 2^min_exp.
// Mirror: terrain::lod::cdlod_tess_factor.
float cdlod_tess_factor(vec3 rel) {
    float d = length(rel);
    float r0 = max(frame.lod.x, 1.17549435e-38);
    float level = d < r0 ? 0.0 : floor(log2(d / r0)) + 1.0;
    float hi = r0 * exp2(level);
    float lo = level == 0.0 ? 0.0 : 0.5 * hi;
    float start = lo + frame.peer.w * (hi - lo);
    float morph = lod_saturate((d - start) / max(hi - start, 1.17549435e-38));
    float exponent = max(frame.lod.w - (level + morph), frame.lod.z);
    return clamp_tess_factor(exp2(exponent));
}
