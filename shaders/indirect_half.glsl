// Indirect irradiance from the probe grid (probe_grid.glsl) at half resolution, with what the
// upsampling in surface.glsl (HALF_INDIRECT) needs to keep to one plane: the facing normal n and the
// plane's offset dot(n, p). Indirect light is smooth (probes are a probe spacing apart), so a quarter of
// the fragments carry it. The plane goes into one 32-bit key, so that the full-resolution upsampling
// reads the planes of its 2x2 footprint with one textureGather: octahedral n (8 + 8 bits) in the high
// half, half(dot(n, p)) in the low half. A cleared texel (key 0) decodes to no normal: no plane matches.

#if defined VERTEX_SHADER

invariant gl_Position;

in vec3 in_position;
in vec3 in_normal;

uniform mat4 view_proj;

out vec3 v_position;
flat out vec3 v_normal;

void main() {
    v_position = in_position;
    v_normal = in_normal;
    gl_Position = view_proj * vec4(in_position, 1.0);
}

#elif defined FRAGMENT_SHADER

#include "probe_grid.glsl"
#include "octahedral.glsl"

in vec3 v_position;
flat in vec3 v_normal;

layout(location = 0) out vec4 frag_irradiance;
layout(location = 1) out uint frag_plane;

void main() {
    vec3 n = gl_FrontFacing ? v_normal : -v_normal;
    vec3 irradiance = probe_irradiance(v_position, n);
    frag_irradiance = vec4(irradiance, 1.0);
    frag_plane = (octahedral_encode(n) << 16) | (packHalf2x16(vec2(dot(n, v_position), 0.0)) & 0xffffu);
}

#endif
