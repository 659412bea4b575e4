// Probe projection, light part: the SH of the reflected radiance each probe sees,
//   c_lm = sum_k w_k Y_lm(d_k) B_reflected(first hit along d_k)
// (viewer/probes/grid.py project with the quadrature of viewer.sh.sphere_directions). The first hits come
// from compute_probe_rays (STORED_HITS 1) or are marched again here (0, when storing them would take
// too much memory). One invocation per probe; probes first_probe.. and directions
// first_direction..end_direction-1 in this dispatch (marching, all directions do not fit llvmpipe's
// loop budget, see compute_bounce.glsl), summed in probe_sh.

#if defined COMPUTE_SHADER
#include "compute_scene.glsl"
#include "sh.glsl"

#ifndef STORED_HITS
#define STORED_HITS 1
#endif

layout(local_size_x = 64) in;

layout(std430, binding = 7) readonly buffer ProbePositionBlock { vec4 probe_position[]; };
layout(std430, binding = 8) readonly buffer DirectionBlock { vec4 directions[]; };  // xyz unit, w weight
layout(std430, binding = 11) readonly buffer HitBlock { int hits[]; };
layout(std430, binding = 13) readonly buffer ReflectedBlock { vec4 reflected[]; };
layout(std430, binding = 15) buffer ProbeBlock { float probe_sh[]; };   // [probe][9][rgb]

uniform int first_probe;
uniform int probe_count;
uniform int direction_count;
uniform int first_direction;
uniform int end_direction;
uniform bool first_chunk;

void main() {
    int p = first_probe + int(gl_GlobalInvocationID.x);
    if (p >= probe_count) {
        return;
    }
    vec3 origin = probe_position[p].xyz;
    vec3 c[9];
    for (int l = 0; l < 9; ++l) {
        c[l] = first_chunk ? vec3(0.0)
                           : vec3(probe_sh[27 * p + 3 * l], probe_sh[27 * p + 3 * l + 1], probe_sh[27 * p + 3 * l + 2]);
    }
    for (int k = first_direction; k < end_direction; ++k) {
        vec4 direction = directions[k];
#if STORED_HITS
        int hit = hits[p * direction_count + k];
#else
        int hit = first_hit(origin, direction.xyz);
#endif
        if (hit < 0) {
            continue;  // MISS or BACKFACE: no light
        }
        vec3 radiance = direction.w * reflected[hit].rgb;
        float y[9];
        sh_basis(direction.xyz, y);
        for (int l = 0; l < 9; ++l) {
            c[l] += y[l] * radiance;
        }
    }
    for (int l = 0; l < 9; ++l) {
        probe_sh[27 * p + 3 * l] = c[l].r;
        probe_sh[27 * p + 3 * l + 1] = c[l].g;
        probe_sh[27 * p + 3 * l + 2] = c[l].b;
    }
}
#endif
