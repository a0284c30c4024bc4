#version 460

// The patches occlusion culled, drawn over the frame in magenta (the
// window's show-culled view): bluer where the patch's level is finer, with
// faint bands by height and across the grid so their lines stay apart.

layout(location = 0) in vec2 in_grid;
layout(location = 1) in float in_height;
layout(location = 2) flat in float in_inside_factor;

layout(location = 0) out vec4 out_color;

void main() {
    float level = clamp(log2(max(in_inside_factor, 1.0)) / 6.0, 0.0, 1.0);
    float band = fract(0.125 * (in_grid.x + in_grid.y));
    out_color = vec4(1.0, 0.1 + 0.05 * fract(in_height), 0.5 + 0.1 * band + 0.1 * level, 1.0);
}
