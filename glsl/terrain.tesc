#version 460
#extension GL_GOOGLE_include_directive : require
#include "terrain_common.glsl"
#include "occlusion.glsl"

// One quad patch: control points 0 upper-left, 1 upper-right, 2 lower-left,
// 3 lower-right.
layout(vertices = 4) out;

layout(location = 0) in vec3 in_rel[];
layout(location = 1) in vec2 in_grid[];
layout(location = 2) in vec2 in_bounds_y[];

// Errors of each patch at 1, 2, ..., 64 segments (error LOD only).
layout(std430, set = 0, binding = BINDING_ERROR_TABLE) readonly buffer ErrorTable {
    float patch_errors[];
};

// This frame's full-resolution patches, one bit each, chosen on the CPU
// (error LOD only): they are drawn with the reference's triangles instead,
// and every edge they share gets a vertex on every sample.
layout(std430, set = 0, binding = BINDING_FULL_RESOLUTION) readonly buffer FullResolution {
    uint full_resolution[];
};

bool is_full_resolution(int patch_index) {
    return (full_resolution[patch_index >> 5] & (1u << uint(patch_index & 31))) != 0u;
}

// Which patches this draw keeps (OCCLUSION_PHASE_*).
layout(push_constant) uniform Draw {
    uint occlusion_phase;
} draw;

void cull_patch() {
    gl_TessLevelOuter[0] = 0.0;
    gl_TessLevelOuter[1] = 0.0;
    gl_TessLevelOuter[2] = 0.0;
    gl_TessLevelOuter[3] = 0.0;
    gl_TessLevelInner[0] = 0.0;
    gl_TessLevelInner[1] = 0.0;
}

layout(location = 1) out vec2 out_grid[];
layout(location = 2) patch out float out_inside_factor;

void main() {
    out_grid[gl_InvocationID] = in_grid[gl_InvocationID];
    if (gl_InvocationID != 0) {
        return;
    }

    // Cull the patch's box: x and z from its corners, y from the bounds in
    // control point 0, all camera-relative.
    vec3 box_min = vec3(in_rel[2].x, in_bounds_y[0].x - frame.eye_local.y, in_rel[2].z);
    vec3 box_max = vec3(in_rel[1].x, in_bounds_y[0].y - frame.eye_local.y, in_rel[1].z);
    vec3 center = 0.5 * (box_min + box_max);
    vec3 extents = 0.5 * (box_max - box_min);
    ivec2 grid_size = ivec2(frame.error_lod.zw);
    ivec2 here = ivec2(in_grid[0]) / int(frame.cells_per_patch);
    int p = here.y * grid_size.x + here.x;
    if ((frame.cull != 0u && aabb_outside_frustum(center, extents))
        || !drawn_in_phase(draw.occlusion_phase, p)) {
        cull_patch();
        out_inside_factor = 0.0;
        return;
    }
    // The patch's cells (columns, rows); remainder patches at the far
    // edges have fewer. No factor exceeds the cells it spans.
    ivec2 cells = ivec2(in_grid[3] - in_grid[0]);
    int edge_cells[4] = int[4](cells.y, cells.x, cells.y, cells.x);

    vec3 midpoints[4] = vec3[4](
        0.5 * (in_rel[0] + in_rel[2]),
        0.5 * (in_rel[0] + in_rel[1]),
        0.5 * (in_rel[1] + in_rel[3]),
        0.5 * (in_rel[2] + in_rel[3]));
    vec3 centre = 0.25 * (in_rel[0] + in_rel[1] + in_rel[2] + in_rel[3]);
    // Edge ends: left (0-2), top (0-1), right (1-3), bottom (2-3).
    ivec2 ends[4] = ivec2[4](ivec2(0, 2), ivec2(0, 1), ivec2(1, 3), ivec2(2, 3));
    float inside;
    vec2 inner = vec2(-1.0);
    if (frame.lod_metric == LOD_METRIC_ERROR) {
        // This patch and its neighbours across the left, top, right and
        // bottom edges; an edge uses the larger error of the two patches,
        // so both compute the same factor for it, and gets a vertex on
        // every sample when the neighbour is drawn at full resolution.
        // Errors are projected from the nearest point that can hold them:
        // for an edge, the strip on it between the terrain's lowest and
        // highest heights (what both patches know alike); for the inside,
        // the patch's box. Mirror: terrain::lod::patch_error_factors.
        if (is_full_resolution(p)) {
            cull_patch();
            out_inside_factor = 0.0;
            return;
        }
        float own[ERROR_LEVEL_COUNT];
        for (int k = 0; k < int(ERROR_LEVEL_COUNT); ++k) {
            own[k] = patch_errors[p * int(ERROR_LEVEL_COUNT) + k];
        }
        ivec2 across[4] = ivec2[4](ivec2(-1, 0), ivec2(0, -1), ivec2(1, 0), ivec2(0, 1));
        float y_lo = frame.height_min - frame.eye_local.y;
        float y_hi = frame.height_max - frame.eye_local.y;
        for (int e = 0; e < 4; ++e) {
            ivec2 there = here + across[e];
            float shared_errors[ERROR_LEVEL_COUNT] = own;
            if (all(greaterThanEqual(there, ivec2(0))) && all(lessThan(there, grid_size))) {
                int q = there.y * grid_size.x + there.x;
                if (is_full_resolution(q)) {
                    gl_TessLevelOuter[e] = float(edge_cells[e]);
                    continue;
                }
                for (int k = 0; k < int(ERROR_LEVEL_COUNT); ++k) {
                    shared_errors[k] = max(own[k], patch_errors[q * int(ERROR_LEVEL_COUNT) + k]);
                }
            }
            float d = edge_distance(in_rel[ends[e].x].xz, in_rel[ends[e].y].xz, y_lo, y_hi);
            gl_TessLevelOuter[e] = error_tess_factor(shared_errors, d, edge_cells[e]);
        }
        inside = error_tess_factor(own, box_distance(box_min, box_max), min(cells.x, cells.y));
    } else if (frame.lod_metric == LOD_METRIC_SPHERE || frame.lod_metric == LOD_METRIC_EDGE_LENGTH) {
        // The screen-space peers, per edge from its ends; the inside
        // factors are the means of the edges along them (inner 0 runs
        // along u: the top and bottom edges). Mirror:
        // terrain::lod::patch_peer_factors.
        for (int e = 0; e < 4; ++e) {
            vec3 a = in_rel[ends[e].x];
            vec3 b = in_rel[ends[e].y];
            gl_TessLevelOuter[e] = frame.lod_metric == LOD_METRIC_SPHERE
                ? sphere_tess_factor(a, b)
                : edge_length_tess_factor(a, b);
        }
        inner = vec2(0.5 * (gl_TessLevelOuter[1] + gl_TessLevelOuter[3]),
                     0.5 * (gl_TessLevelOuter[0] + gl_TessLevelOuter[2]));
        inside = max(inner.x, inner.y);
    } else if (frame.lod_metric == LOD_METRIC_CDLOD) {
        // CDLOD's ranges at edge midpoints and the centre.
        // Mirror: terrain::lod::patch_peer_factors.
        for (int e = 0; e < 4; ++e) {
            gl_TessLevelOuter[e] = cdlod_tess_factor(midpoints[e]);
        }
        inside = cdlod_tess_factor(centre);
    } else {
        // Edge factors from edge midpoints, so both patches sharing an edge
        // compute the same value; inside factors from the centre. Vulkan's
        // quad edges are u=0 (left, 0-2), v=0 (top, 0-1), u=1 (right, 1-3)
        // and v=1 (bottom, 2-3). Mirror: terrain::lod::patch_tess_factors.
        for (int e = 0; e < 4; ++e) {
            gl_TessLevelOuter[e] = tess_factor(midpoints[e]);
        }
        inside = tess_factor(centre);
    }
    if (inner.x < 0.0) {
        inner = vec2(inside);
    }
    gl_TessLevelInner[0] = inner.x;
    gl_TessLevelInner[1] = inner.y;
    out_inside_factor = inside;
}
