#version 460
#extension GL_GOOGLE_include_directive : require
#define FRAME_IN_STORAGE
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

// This frame's choice, made on the CPU (error LOD only): first one bit a
// patch, set where it is drawn at full resolution (with the reference's
// triangles instead, every edge it shares getting a vertex on every
// sample); then one byte a patch, the level of the merged node holding it,
// 0 where it is drawn on its own (see lod::patch_merge); then one byte a
// patch, the level the share chose (`chosen_level`).
layout(std430, set = 0, binding = BINDING_FULL_RESOLUTION) readonly buffer PatchChoice {
    uint patch_choice[];
};

bool is_full_resolution(int patch_index) {
    return (patch_choice[patch_index >> 5] & (1u << uint(patch_index & 31))) != 0u;
}

int merged_level(int patch_index) {
    int patches = int(frame.error_lod.z * frame.error_lod.w);
    uint word = patch_choice[((patches + 31) >> 5) + (patch_index >> 2)];
    return int((word >> (8u * uint(patch_index & 3))) & 0xffu);
}

// The level the frame plan's share of pixels over tau chose for a patch
// (lod::plan): 0 where its own errors decide, else its level index plus
// one; one byte a patch after the merged levels. Mirror:
// render::tess_path::ChosenLevel.
int chosen_level(int patch_index) {
    int patches = int(frame.error_lod.z * frame.error_lod.w);
    int first_word = ((patches + 31) >> 5) + ((patches + 3) >> 2);
    uint word = patch_choice[first_word + (patch_index >> 2)];
    return int((word >> (8u * uint(patch_index & 3))) & 0xffu);
}

// A patch's errors at 1, 2, ..., 64 segments: its row of the table, read
// as zero from the level the share chose for it, if it chose one
// (`chosen_error`).
void read_errors(int patch_index, out float errors[ERROR_LEVEL_COUNT]) {
    int chosen = chosen_level(patch_index);
    for (int k = 0; k < int(ERROR_LEVEL_COUNT); ++k) {
        errors[k] = chosen_error(patch_errors[patch_index * int(ERROR_LEVEL_COUNT) + k], k, chosen);
    }
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

// Edge ends: left (0-2), top (0-1), right (1-3), bottom (2-3).
const ivec2 EDGE_ENDS[4] = ivec2[4](ivec2(0, 2), ivec2(0, 1), ivec2(1, 3), ivec2(2, 3));

// Factors of the merged node of 2^level x 2^level patches whose first
// patch is `here`. A side towards a node of the same level takes the
// larger errors of the two, from the strip on it; towards anything else
// it has one segment per patch along it, so every vertex there is a patch
// corner both sides draw. The inside comes from the node's box: its
// corners' x and z, the terrain's whole height range. The node's errors
// are in its first patch's row of the table.
// Mirror: terrain::patch_merge::node_error_factors.
void merged_node_factors(ivec2 here, int level, ivec2 grid_size) {
    int span = 1 << level;
    int cells = int(frame.cells_per_patch) << level;
    float own[ERROR_LEVEL_COUNT];
    read_errors(here.y * grid_size.x + here.x, own);
    ivec2 across[4] = ivec2[4](ivec2(-1, 0), ivec2(0, -1), ivec2(span, 0), ivec2(0, span));
    float y_lo = frame.height_min - frame.eye_local.y;
    float y_hi = frame.height_max - frame.eye_local.y;
    for (int e = 0; e < 4; ++e) {
        ivec2 there = here + across[e];
        float shared_errors[ERROR_LEVEL_COUNT] = own;
        if (all(greaterThanEqual(there, ivec2(0))) && all(lessThan(there, grid_size))) {
            if (merged_level(there.y * grid_size.x + there.x) != level) {
                gl_TessLevelOuter[e] = float(span);
                continue;
            }
            ivec2 first = (there >> level) << level;
            float theirs[ERROR_LEVEL_COUNT];
            read_errors(first.y * grid_size.x + first.x, theirs);
            for (int k = 0; k < int(ERROR_LEVEL_COUNT); ++k) {
                shared_errors[k] = max(own[k], theirs[k]);
            }
        }
        float d = edge_distance(in_rel[EDGE_ENDS[e].x].xz, in_rel[EDGE_ENDS[e].y].xz, y_lo, y_hi);
        gl_TessLevelOuter[e] = error_tess_factor(shared_errors, d, cells);
    }
    vec3 box_min = vec3(in_rel[2].x, y_lo, in_rel[2].z);
    vec3 box_max = vec3(in_rel[1].x, y_hi, in_rel[1].z);
    float inside = error_tess_factor(own, box_distance(box_min, box_max), cells);
    gl_TessLevelInner[0] = inside;
    gl_TessLevelInner[1] = inside;
    out_inside_factor = inside;
}

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
    int level = frame.lod_metric == LOD_METRIC_ERROR ? merged_level(p) : 0;
    if (level > 0) {
        // A merged node (error LOD): its control points are its block's
        // corners. The CPU's frustum test on its patches kept it, and it
        // is drawn in a frame's first pass, untested for occlusion.
        if (draw.occlusion_phase == OCCLUSION_PHASE_SECOND
            || draw.occlusion_phase == OCCLUSION_PHASE_CULLED) {
            cull_patch();
            out_inside_factor = 0.0;
            return;
        }
        merged_node_factors(here, level, grid_size);
        return;
    }
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
        read_errors(p, own);
        ivec2 across[4] = ivec2[4](ivec2(-1, 0), ivec2(0, -1), ivec2(1, 0), ivec2(0, 1));
        float y_lo = frame.height_min - frame.eye_local.y;
        float y_hi = frame.height_max - frame.eye_local.y;
        for (int e = 0; e < 4; ++e) {
            ivec2 there = here + across[e];
            float shared_errors[ERROR_LEVEL_COUNT] = own;
            if (all(greaterThanEqual(there, ivec2(0))) && all(lessThan(there, grid_size))) {
                int q = there.y * grid_size.x + there.x;
                if (merged_level(q) > 0) {
                    // One segment, as the node puts one on each patch.
                    gl_TessLevelOuter[e] = 1.0;
                    continue;
                }
                if (is_full_resolution(q)) {
                    gl_TessLevelOuter[e] = float(edge_cells[e]);
                    continue;
                }
                float theirs[ERROR_LEVEL_COUNT];
                read_errors(q, theirs);
                for (int k = 0; k < int(ERROR_LEVEL_COUNT); ++k) {
                    shared_errors[k] = max(own[k], theirs[k]);
                }
            }
            float d = edge_distance(in_rel[EDGE_ENDS[e].x].xz, in_rel[EDGE_ENDS[e].y].xz, y_lo, y_hi);
            gl_TessLevelOuter[e] = error_tess_factor(shared_errors, d, edge_cells[e]);
        }
        inside = error_tess_factor(own, box_distance(box_min, box_max), min(cells.x, cells.y));
    } else if (frame.lod_metric == LOD_METRIC_SPHERE || frame.lod_metric == LOD_METRIC_EDGE_LENGTH) {
        // The screen-space peers, per edge from its ends; the inside
        // factors are the means of the edges along them (inner 0 runs
        // along u: the top and bottom edges). Mirror:
        // terrain::lod::patch_peer_factors.
        for (int e = 0; e < 4; ++e) {
            vec3 a = in_rel[EDGE_ENDS[e].x];
            vec3 b = in_rel[EDGE_ENDS[e].y];
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
