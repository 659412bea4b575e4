// Full-screen pass: linear HDR radiance -> exposure -> tone curve -> sRGB (see tonemap.glsl).
// The HDR image may be smaller than the output (a render scale below 1): it is then sampled bilinearly;
// at the same size (SAME_SIZE) each pixel reads its own texel.
//
// Defines (one variant each, since llvmpipe runs every side of a branch with masks): TONE_CURVE (one of
// the TONEMAP_* of tonemap.glsl), RAW (1: debug quantities such as albedo and normals, no exposure and no
// tone curve), SAME_SIZE.

#ifndef TONE_CURVE
#define TONE_CURVE TONEMAP_ACES
#endif
#ifndef RAW
#define RAW 0
#endif
#ifndef SAME_SIZE
#define SAME_SIZE 0
#endif

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
uniform vec4 output_viewport;  // x, y, width, height of the output in pixels

out vec4 frag_color;

void main() {
#if SAME_SIZE
    vec3 radiance = texelFetch(hdr_image, ivec2(gl_FragCoord.xy - output_viewport.xy), 0).rgb;
#else
    vec2 uv = (gl_FragCoord.xy - output_viewport.xy) / output_viewport.zw;
    vec3 radiance = textureLod(hdr_image, uv, 0.0).rgb;
#endif
#if RAW
    vec3 display = radiance;
#elif TONE_CURVE == TONEMAP_ACES
    vec3 display = tonemap_aces(radiance * exposure_scale);
#elif TONE_CURVE == TONEMAP_REINHARD
    vec3 display = tonemap_reinhard(radiance * exposure_scale);
#else
    vec3 display = clamp(radiance * exposure_scale, 0.0, 1.0);
#endif
    frag_color = vec4(linear_to_srgb(display), 1.0);
}

#endif
