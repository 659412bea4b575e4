// Reading the SH probe grid: seven RGBA 3D textures over the box [probe_lo, probe_hi], probe (i,j,k) at
// the centre of texel (i,j,k), trilinear filtering and CLAMP_TO_EDGE (so the outer probes are held
// outside their layer instead of wrapping to the opposite side of the box).
#include "sh.glsl"

uniform sampler3D probe_sh[7];
uniform vec3 probe_lo;
uniform vec3 probe_hi;
uniform float probe_normal_offset; // world units along the normal (a fraction of the probe spacing)

SH9 probe_sample(vec3 p) {
    vec3 uvw = (p - probe_lo) / (probe_hi - probe_lo);
    vec4 t[7];
    for (int i = 0; i < 7; ++i) {
        t[i] = textureLod(probe_sh[i], uvw, 0.0);  // no mipmaps: skip the derivatives
    }
    return sh_unpack(t);
}

SH9 probe_fetch(ivec3 index) {
    vec4 t[7];
    for (int i = 0; i < 7; ++i) {
        t[i] = texelFetch(probe_sh[i], index, 0);
    }
    return sh_unpack(t);
}

// Indirect irradiance at a surface point. Sampled a little off the surface along the normal, which
// keeps the trilinear footprint on the lit side of a wall (less light leaking from behind it); the
// L2 reconstruction can ring below zero, which is clamped.
vec3 probe_irradiance(vec3 p, vec3 n) {
    return max(sh_irradiance(probe_sample(p + n * probe_normal_offset), n), vec3(0.0));
}
