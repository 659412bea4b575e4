// Reading the SH probe grid: seven RGBA 3D textures over the box [probe_lo, probe_hi], probe (i,j,k) at
// the centre of texel (i,j,k), trilinear filtering and CLAMP_TO_EDGE (so the outer probes are held
// outside their layer instead of wrapping to the opposite side of the box). Each probe's 27 numbers
// are premultiplied by its weight w (1 if valid, viewer.probes.INVALID_WEIGHT if inside solid
// geometry), and w is the 7th texture's alpha (ProbeGrid.texture_data).
#include "sh.glsl"

uniform sampler3D probe_sh[7];
uniform vec3 probe_lo;
uniform vec3 probe_hi;
uniform float probe_normal_offset; // world units along the normal (a fraction of the probe spacing)
uniform float probe_plane_falloff; // per world unit: a probe's weight is exp(this x its distance in
                                   // front of the shaded surface's plane)

// The SH at texture coordinate uvw, divided by the interpolated probe weight: the weighted mean of the
// 8 probes around it, with trilinear weights x the probes' own weights.
SH9 probe_sample_uvw(vec3 uvw) {
    vec4 t[7];
    for (int i = 0; i < 7; ++i) {
        t[i] = textureLod(probe_sh[i], uvw, 0.0);  // no mipmaps: skip the derivatives
    }
    float weight = t[6].w;   // >= INVALID_WEIGHT: every probe has one
    for (int i = 0; i < 7; ++i) {
        t[i] /= weight;
    }
    return sh_unpack(t);
}

// Indirect irradiance at a surface point p with normal n: the cosine-lobe convolution of the SH
// interpolated from the 8 probes around p + n * probe_normal_offset, DDGI-style (Majercik et al. 2019,
// "Dynamic Diffuse Global Illumination with Ray-Traced Irradiance Fields", without their per-probe
// depth): each probe weighs   trilinear weight x validity weight x exp(falloff x d),   d its distance
// in front of the surface plane, and the weights are renormalized. Probes behind the surface (inside the
// solid it bounds, seeing its dark inside) and those in front of it by less (near a rotated face they
// see the voxelized face's staircase) fade out smoothly instead of making dark blotches.
//
// The back-side weight is an exponential so that it factors over the axes: d = d0 + sum_a b_a n_a s_a
// for the corner b of the cell (s: spacing), so along each axis the far corner's weight is multiplied by
// e_a = exp(falloff n_a s_a), and the product of the 8 weights is a trilinear weight at a shifted point
// (per axis f -> f e / (1 - f + f e)). One hardware trilinear fetch per texture then does the whole
// weighting, at the cost of plain interpolation; the validity weight comes from the premultiplied
// textures (probe_sample_uvw). The L2 reconstruction can ring below zero, which is clamped.
vec3 probe_irradiance(vec3 p, vec3 n) {
    vec3 count = vec3(textureSize(probe_sh[0], 0));
    vec3 spacing = (probe_hi - probe_lo) / count;
    vec3 u = clamp((p + n * probe_normal_offset - probe_lo) / spacing - 0.5, vec3(0.0), count - 1.0);
    vec3 base = min(floor(u), max(count - 2.0, vec3(0.0)));
    vec3 f = u - base;
    vec3 e = exp(probe_plane_falloff * n * spacing);
    vec3 shifted = f * e / (1.0 - f + f * e);
    SH9 sh = probe_sample_uvw((base + shifted + 0.5) / count);
    return max(sh_irradiance(sh, n), vec3(0.0));
}
