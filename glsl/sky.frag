#version 460
#extension GL_GOOGLE_include_directive : require
#include "terrain_common.glsl"

// The sky behind the terrain: the horizon colour (the fog's, so distant
// ground fades into it) rising to the zenith colour, and the first
// light's sun disc with a glow around it.

layout(location = 0) in vec2 in_ndc;

layout(location = 0) out vec4 out_color;

void main() {
    // The view ray through this pixel: the point it meets on the near
    // plane (depth 1 with reversed Z), camera-relative.
    vec4 near = frame.sky_ray * vec4(in_ndc, 1.0, 1.0);
    vec3 ray = normalize(near.xyz / near.w);
    float up = clamp(ray.y, 0.0, 1.0);
    vec3 color = mix(frame.sky_horizon.rgb, frame.sky_zenith.rgb, pow(up, 0.6));
    if (frame.ambient.w > 0.0) {
        vec3 light = frame.light_color[0].rgb;
        // The disc takes the light's hue at full brightness.
        vec3 sun = light / max(max(light.r, light.g), max(light.b, 1e-3));
        float c = dot(ray, frame.light_dir[0].xyz);
        float glow = 0.35 * pow(max(c, 0.0), 600.0) + 0.12 * pow(max(c, 0.0), 12.0);
        color += glow * sun;
        // Anti-aliased edge: one pixel's change of c wide.
        float edge = max(fwidth(c), 1e-6);
        float disc = smoothstep(frame.sky_horizon.w - edge, frame.sky_horizon.w + edge, c);
        color = mix(color, sun, disc);
    }
    out_color = vec4(color, 1.0);
}
