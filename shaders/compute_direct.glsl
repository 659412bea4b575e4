// First bounce of the compute solver: irradiance straight from the emitters and the sun, per voxel
// (viewer/physical/transport.py direct_irradiance and sun_irradiance), and the light it reflects, over the fine
// light samples with the bounces' kernel:
//   physical (KERNEL_PAPER 0): E_i = sum_s Le_s cos_i cos_s A_s / (r^2 + A_s / pi) V(i, voxel of s),
//       visibility traced once per (receiver, emitting voxel) and shared by that voxel's samples;
//   paper (KERNEL_PAPER 1):    E_i = s_i sum_s Le_s cos_i A_s / (r^2 + A_s / pi) [cos_s > 0], no
//       visibility and no emitter cosine, but emitters one-sided; the weights clamped to the
//       hemisphere like the rows of G (s_i = min(1, pi / sum_s weight));
// plus E_sun max(0, n_i.l) V_sun (the share of the voxel the sun reaches); B1_i = albedo_i / pi * E_i.
// One invocation per receiver; receivers first_item.. in this dispatch, emitting voxels
// first_emitter..end_emitter-1 (chunks within llvmpipe's loop budget, see compute_bounce.glsl), the
// lamp sum and weight sum kept in direct_irradiance between chunks; the last adds the sun and reflects.

#if defined COMPUTE_SHADER
#include "compute_scene.glsl"

#ifndef KERNEL_PAPER
#define KERNEL_PAPER 0
#endif
#ifndef SUN_SIDE
#define SUN_SIDE 3
#endif

layout(local_size_x = 64) in;

struct LightSample {
    vec4 position_area;  // xyz piece centroid, w piece area
    vec4 normal;         // xyz front normal
    vec4 radiance;       // rgb emitted radiance
};

layout(std430, binding = 9) readonly buffer LightSampleBlock { LightSample light_samples[]; };
layout(std430, binding = 10) readonly buffer EmitterBlock { ivec4 emitters[]; };  // samples x..y-1 lie in voxel z
layout(std430, binding = 12) writeonly buffer BounceBlock { vec4 bounce[]; };      // B1
layout(std430, binding = 13) writeonly buffer ReflectedBlock { vec4 reflected[]; };
layout(std430, binding = 14) buffer StatsBlock { uint stats[]; };                 // max |B|, max |reflected|
layout(std430, binding = 15) buffer DirectBlock { vec4 direct_irradiance[]; };  // rgb E, w weight sum

uniform int first_item;
uniform int first_emitter;
uniform int end_emitter;
uniform bool first_chunk;
uniform bool last_chunk;
uniform bool sun_enabled;
uniform vec3 sun_direction;   // unit, towards the sun
uniform vec3 sun_irradiance;
uniform float sun_reach;      // 3 N h: far enough to leave the grid (Tracer.escapes)

// viewer/rays/sun.py: the share of the voxel's surface the sun reaches. SUN_SIDE x SUN_SIDE points on
// the plane through `start`, spanning the voxel and kept within its cell (and `surface_offset` of it);
// a point reached from `start` only through a surface (a floor beside a wall runs on behind it) starts
// its ray at `start`.
float sun_cover(vec3 p, vec3 n, vec3 start) {
    vec3 helper = abs(n.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0);
    vec3 t = normalize(cross(n, helper));
    vec3 b = cross(n, t);
    vec3 lo = grid_lo + floor((p - grid_lo) / voxel_size) * voxel_size - surface_offset;
    vec3 hi = lo + voxel_size + 2.0 * surface_offset;
    float seen = 0.0;
    for (int u = 0; u < SUN_SIDE; ++u) {
        for (int v = 0; v < SUN_SIDE; ++v) {
            vec2 step = (vec2(u, v) + 0.5) / float(SUN_SIDE) - 0.5;
            vec3 q = clamp(start + voxel_size * (step.x * t + step.y * b), lo, hi);
            vec3 from = segment_clear(start, q) ? q : start;
            seen += segment_clear(from, from + sun_direction * sun_reach) ? 1.0 : 0.0;
        }
    }
    return seen / float(SUN_SIDE * SUN_SIDE);
}

void main() {
    int i = first_item + int(gl_GlobalInvocationID.x);
    if (i >= voxel_count) {
        return;
    }
    vec3 p = voxel_position[i].xyz;
    vec3 n = voxel_normal[i].xyz;
    vec3 start = p + surface_offset * n;
    vec4 lamp = first_chunk ? vec4(0.0) : direct_irradiance[i];  // rgb irradiance, w sum of weights
    for (int e = first_emitter; e < end_emitter; ++e) {
        ivec4 emitter = emitters[e];
        vec4 gathered = vec4(0.0);
        for (int s = emitter.x; s < emitter.y; ++s) {
            LightSample light = light_samples[s];
            vec3 d = light.position_area.xyz - p;
            float r2 = dot(d, d);
            vec3 w = d / sqrt(max(r2, 1e-30));
            float cos_i = dot(w, n);
            float area = light.position_area.w;
            float cos_s = -dot(w, light.normal.xyz);
#if KERNEL_PAPER
            float weight = cos_i > 0.0 && cos_s > 0.0 ? cos_i * area / (r2 + area / PI) : 0.0;
#else
            float weight = cos_i > 0.0 && cos_s > 0.0 ? cos_i * cos_s * area / (r2 + area / PI) : 0.0;
#endif
            gathered += weight * vec4(light.radiance.rgb, 1.0);
        }
#if !KERNEL_PAPER
        int v = emitter.z;
        if (!(gathered.w > 0.0 && segment_clear(start, voxel_position[v].xyz + surface_offset * voxel_normal[v].xyz))) {
            gathered = vec4(0.0);
        }
#endif
        lamp += gathered;
    }
    if (!last_chunk) {
        direct_irradiance[i] = lamp;
        return;
    }
#if KERNEL_PAPER
    vec3 irradiance = lamp.w > PI ? PI / lamp.w * lamp.rgb : lamp.rgb;
#else
    vec3 irradiance = lamp.rgb;
#endif
    if (sun_enabled) {
        float cos_sun = dot(n, sun_direction);
        if (cos_sun > 0.0) {
            irradiance += cos_sun * sun_cover(p, n, start) * sun_irradiance;
        }
    }
    direct_irradiance[i] = vec4(irradiance, 0.0);
    vec3 first = voxel_material[i].rgb / PI * irradiance;
    bounce[i] = vec4(first, 0.0);
    reflected[i] = vec4(first, 0.0);
    uint largest = floatBitsToUint(max(first.r, max(first.g, first.b)));  // >= 0: orders as a uint
    atomicMax(stats[0], largest);
    atomicMax(stats[1], largest);
}
#endif
