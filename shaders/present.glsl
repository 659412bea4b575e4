// Full-screen pass: an image -> a framebuffer. From an HDR target: linear radiance -> exposure -> tone
// curve (display_value, tonemap.glsl) -> sRGB. From a display target (ENCODED: 8-bit values already
// tone-mapped and encoded, see surface.glsl's DISPLAY variant) only scaled to another size.
// The image may be smaller than the output (a render scale below 1): it is then sampled bilinearly;
// at the same size (SAME_SIZE) each pixel reads its own texel.
//
// Defines (one variant each, since llvmpipe runs every side of a branch with masks): TONE_CURVE and RAW
// (see tonemap.glsl), SAME_SIZE, ENCODED.

#ifndef SAME_SIZE
#define SAME_SIZE 0
#endif
#ifndef ENCODED
#define ENCODED 0
#endif

#if defined VERTEX_SHADER

#include "fullscreen.glsl"

void main() {
    gl_Position = fullscreen_corner(0.0);
}

#elif defined FRAGMENT_SHADER

#include "tonemap.glsl"

uniform sampler2D hdr_image;
uniform vec4 output_viewport;  // x, y, width, height of the output in pixels

out vec4 frag_color;

void main() {
#if SAME_SIZE
    vec3 radiance = texelFetch(hdr_image, ivec2(gl_FragCoord.xy - output_viewport.xy), 0).rgb;
#else
    vec2 uv = (gl_FragCoord.xy - output_viewport.xy) / output_viewport.zw;
    vec3 radiance = textureLod(hdr_image, uv, 0.0).rgb;
#endif
#if ENCODED
    frag_color = vec4(radiance, 1.0);
#else
    frag_color = vec4(linear_to_srgb(display_value(radiance)), 1.0);
#endif
}

#endif
