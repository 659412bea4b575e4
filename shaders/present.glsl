// Full-screen pass: linear HDR radiance -> exposure -> tone curve -> sRGB (see tonemap.glsl).
// The HDR image may be smaller than the output (a render scale below 1): it is then sampled bilinearly.

#if defined VERTEX_SHADER

void main() {
    // One triangle that covers the screen: (-1,-1), (3,-1), (-1,3).
    vec2 corner = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    gl_Position = vec4(corner, 0.0, 1.0);
}

#elif defined FRAGMENT_SHADER

#include "tonemap.glsl"

uniform sampler2D hdr_image;
uniform float exposure_scale;  // 2^EV
uniform int tone_curve;        // TONEMAP_NONE / REINHARD / ACES
uniform bool raw;              // debug quantities (albedo, normals): no exposure, no tone curve
uniform vec4 output_viewport;  // x, y, width, height of the output in pixels

out vec4 frag_color;

void main() {
    vec2 uv = (gl_FragCoord.xy - output_viewport.xy) / output_viewport.zw;
    vec3 radiance = textureLod(hdr_image, uv, 0.0).rgb;
    vec3 display = raw ? radiance : tonemap(radiance * exposure_scale, tone_curve);
    frag_color = vec4(linear_to_srgb(display), 1.0);
}

#endif
