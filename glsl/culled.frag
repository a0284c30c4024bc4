#version 460

// The patches occlusion culled, drawn over the frame in one colour (the
// window's show-culled view).

layout(location = 0) out vec4 out_color;

void main() {
    out_color = vec4(1.0, 0.1, 0.6, 1.0);
}
