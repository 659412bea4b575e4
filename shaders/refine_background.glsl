// The background of one more image of a refining display target (viewer/gpu/targets.py RefiningTarget):
// a full-screen triangle at the far plane, drawn after the surfaces with the depth test "<=", so it
// shades only the pixels no surface covered in this image and mixes the clear colour (black) into their
// running mean, as surface.glsl's ACCUMULATE mixes a surface's display value into it.

#if defined VERTEX_SHADER

#include "fullscreen.glsl"

void main() {
    gl_Position = fullscreen_corner(1.0);   // at the far plane
}

#elif defined FRAGMENT_SHADER

uniform sampler2D accumulated;
uniform float accumulate_weight;

out vec4 frag_color;

void main() {
    vec3 mean = texelFetch(accumulated, ivec2(gl_FragCoord.xy), 0).rgb * (1.0 - accumulate_weight);
    frag_color = vec4(mean, 1.0);
}

#endif
