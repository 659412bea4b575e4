// The probe grid into the renderer's seven RGBA 3D textures (viewer/gpu/probe_textures.py): the 27
// numbers coefficient-major as RGB triples (c0.rgb c1.r | c1.gb c2.rg | ...), premultiplied by the probe's
// weight (1 if valid, else invalid_weight) with the weight in the last alpha, as ProbeGrid.texture_data
// packs them, after the deringing window (per-coefficient band factors, viewer.sh.window_factors).
// Indirect light only for rendering; INCLUDE_EMITTED adds the light straight from emitters and sun.

#if defined COMPUTE_SHADER
#ifndef PROBE_FORMAT
#define PROBE_FORMAT rgba16f
#endif
#ifndef INCLUDE_EMITTED
#define INCLUDE_EMITTED 0
#endif

layout(local_size_x = 64) in;

layout(std430, binding = 12) readonly buffer EmittedBlock { float emitted_sh[]; };
layout(std430, binding = 14) readonly buffer WaveBlock { int waves[]; };
layout(std430, binding = 15) readonly buffer ProbeBlock { float probe_sh[]; };

layout(PROBE_FORMAT, binding = 0) writeonly uniform image3D probe_texture0;
layout(PROBE_FORMAT, binding = 1) writeonly uniform image3D probe_texture1;
layout(PROBE_FORMAT, binding = 2) writeonly uniform image3D probe_texture2;
layout(PROBE_FORMAT, binding = 3) writeonly uniform image3D probe_texture3;
layout(PROBE_FORMAT, binding = 4) writeonly uniform image3D probe_texture4;
layout(PROBE_FORMAT, binding = 5) writeonly uniform image3D probe_texture5;
layout(PROBE_FORMAT, binding = 6) writeonly uniform image3D probe_texture6;

uniform int probe_resolution;
uniform float dering[9];
uniform float texel_limit;  // 65504 for half floats, which overflow to infinity above it
uniform float invalid_weight;  // viewer.probes.INVALID_WEIGHT

void main() {
    int m = probe_resolution;
    int p = int(gl_GlobalInvocationID.x);
    if (p >= m * m * m) {
        return;
    }
    float f[28];
    bool known = waves[p] >= 0;  // no valid probe at all: the grid is dark, as fill_invalid leaves it
    float weight = waves[p] == 0 ? 1.0 : invalid_weight;   // ProbeGrid.probe_weights
    for (int c = 0; c < 27; ++c) {
        float value = probe_sh[27 * p + c];
#if INCLUDE_EMITTED
        value += emitted_sh[27 * p + c];
#endif
        f[c] = known ? clamp(value * dering[c / 3], -texel_limit, texel_limit) * weight : 0.0;
    }
    f[27] = weight;
    ivec3 texel = ivec3(p / (m * m), (p / m) % m, p % m);
    imageStore(probe_texture0, texel, vec4(f[0], f[1], f[2], f[3]));
    imageStore(probe_texture1, texel, vec4(f[4], f[5], f[6], f[7]));
    imageStore(probe_texture2, texel, vec4(f[8], f[9], f[10], f[11]));
    imageStore(probe_texture3, texel, vec4(f[12], f[13], f[14], f[15]));
    imageStore(probe_texture4, texel, vec4(f[16], f[17], f[18], f[19]));
    imageStore(probe_texture5, texel, vec4(f[20], f[21], f[22], f[23]));
    imageStore(probe_texture6, texel, vec4(f[24], f[25], f[26], f[27]));
}
#endif
