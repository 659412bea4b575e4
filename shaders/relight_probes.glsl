// The relight's probe projection (viewer/physical/relight.py probe_coefficients): each probe sums, over its
// directions, the SH basis x quadrature weight of the direction times the radiance of the voxel the
// geometry stage found there (index K: nothing, a zero row). Two results: the reflected light (what the
// renderer shades) and the emitted light (the gathered emitters, plus the lamps' and the sun's direct SH
// computed on the CPU). Probe p = (x M + y) M + z; coefficient c of channel k at 27 p + 3 c + k.

#if defined COMPUTE_SHADER
layout(local_size_x = 64) in;

layout(std430, binding = 7) readonly buffer HitBlock { int hits[]; };
layout(std430, binding = 8) readonly buffer BasisBlock { float basis[]; };
layout(std430, binding = 9) readonly buffer ReflectedBlock { vec4 reflected[]; };
layout(std430, binding = 10) readonly buffer EmissionBlock { vec4 emission[]; };
layout(std430, binding = 11) readonly buffer DirectBlock { float direct_sh[]; };
layout(std430, binding = 12) writeonly buffer EmittedBlock { float emitted_sh[]; };
layout(std430, binding = 15) writeonly buffer IndirectBlock { float indirect_sh[]; };

uniform int probe_count;
uniform int direction_count;
uniform bool with_emission;  // any gathered emitter: else the emitted light is the direct SH alone

void main() {
    int p = int(gl_GlobalInvocationID.x);
    if (p >= probe_count) {
        return;
    }
    vec3 reflected_sum[9];
    vec3 emitted_sum[9];
    for (int c = 0; c < 9; ++c) {
        reflected_sum[c] = vec3(0.0);
        emitted_sum[c] = vec3(0.0);
    }
    for (int r = 0; r < direction_count; ++r) {
        int j = hits[p * direction_count + r];
        vec3 light = reflected[j].rgb;
        for (int c = 0; c < 9; ++c) {
            reflected_sum[c] += basis[9 * r + c] * light;
        }
    }
    if (with_emission) {   // a second pass only where some surface found by the rays emits
        for (int r = 0; r < direction_count; ++r) {
            vec3 glow = emission[hits[p * direction_count + r]].rgb;
            for (int c = 0; c < 9; ++c) {
                emitted_sum[c] += basis[9 * r + c] * glow;
            }
        }
    }
    for (int c = 0; c < 9; ++c) {
        for (int k = 0; k < 3; ++k) {
            indirect_sh[27 * p + 3 * c + k] = reflected_sum[c][k];
            emitted_sh[27 * p + 3 * c + k] = emitted_sum[c][k] + direct_sh[27 * p + 3 * c + k];
        }
    }
}
#endif
