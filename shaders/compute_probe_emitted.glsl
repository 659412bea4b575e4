// Light arriving at each probe straight from the emitters and the sun (viewer/probes/grid.py _emitter_sh and
// _sun_sh): every fine light sample is a patch of solid angle omega_s = cos_s A_s / (r^2 + A_s / pi)
// in direction w_s, seen unless its emitting voxel is occluded (traced once per probe and voxel);
// the sun is a delta, c_lm = E_sun Y_lm(l), where it is not shadowed. One invocation per probe;
// emitting voxels first_emitter..end_emitter-1 per dispatch (llvmpipe's loop budget, see
// compute_bounce.glsl), summed in probe_sh; the first chunk adds the sun.

#if defined COMPUTE_SHADER
#include "compute_scene.glsl"
#include "sh.glsl"

layout(local_size_x = 64) in;

struct LightSample {
    vec4 position_area;
    vec4 normal;
    vec4 radiance;
};

layout(std430, binding = 7) readonly buffer ProbePositionBlock { vec4 probe_position[]; };
layout(std430, binding = 9) readonly buffer LightSampleBlock { LightSample light_samples[]; };
layout(std430, binding = 10) readonly buffer EmitterBlock { ivec4 emitters[]; };
layout(std430, binding = 15) buffer ProbeBlock { float probe_sh[]; };

uniform int first_probe;
uniform int probe_count;
uniform int first_emitter;
uniform int end_emitter;
uniform bool first_chunk;
uniform bool sun_enabled;
uniform vec3 sun_direction;
uniform vec3 sun_irradiance;
uniform float sun_reach;

float solid_angle(LightSample light, vec3 origin, out vec3 w) {
    vec3 d = light.position_area.xyz - origin;
    float r2 = dot(d, d);
    w = d / sqrt(max(r2, 1e-30));
    float cos_s = -dot(w, light.normal.xyz);
    float area = light.position_area.w;
    return cos_s > 0.0 ? cos_s * area / (r2 + area / PI) : 0.0;
}

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
    float y[9];
    vec3 w;
    for (int e = first_emitter; e < end_emitter; ++e) {
        ivec4 emitter = emitters[e];
        bool needed = false;
        for (int s = emitter.x; s < emitter.y && !needed; ++s) {
            needed = solid_angle(light_samples[s], origin, w) > 0.0;
        }
        int v = emitter.z;
        if (!needed || !segment_clear(origin, voxel_position[v].xyz + surface_offset * voxel_normal[v].xyz)) {
            continue;
        }
        for (int s = emitter.x; s < emitter.y; ++s) {
            LightSample light = light_samples[s];
            float omega = solid_angle(light, origin, w);
            if (omega > 0.0) {
                sh_basis(w, y);
                for (int l = 0; l < 9; ++l) {
                    c[l] += (omega * y[l]) * light.radiance.rgb;
                }
            }
        }
    }
    if (sun_enabled && first_chunk && segment_clear(origin, origin + sun_direction * sun_reach)) {
        sh_basis(sun_direction, y);
        for (int l = 0; l < 9; ++l) {
            c[l] += y[l] * sun_irradiance;
        }
    }
    for (int l = 0; l < 9; ++l) {
        probe_sh[27 * p + 3 * l] = c[l].r;
        probe_sh[27 * p + 3 * l + 1] = c[l].g;
        probe_sh[27 * p + 3 * l + 2] = c[l].b;
    }
}
#endif
