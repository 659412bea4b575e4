// Bakes direct irradiance (direct_light.glsl) into the lightmap of viewer/gpu/direct_bake.py: the left
// half for the front sides of the faces, the right half (the same texels again) for their back sides.

#if defined VERTEX_SHADER

#include "fullscreen.glsl"

void main() {
    gl_Position = fullscreen_corner(0.0);
}

#elif defined FRAGMENT_SHADER

#include "direct_light.glsl"

uniform sampler2D bake_position;
uniform sampler2D bake_normal;

layout(location = 0) out vec4 irradiance;

void main() {
    ivec2 texel = ivec2(gl_FragCoord.xy);
    int width = textureSize(bake_position, 0).x;
    bool back = texel.x >= width;
    texel.x -= back ? width : 0;
    vec3 p = texelFetch(bake_position, texel, 0).xyz;
    vec3 n = texelFetch(bake_normal, texel, 0).xyz;
    irradiance = vec4(direct_irradiance(p, back ? -n : n), 1.0);
}

#endif
