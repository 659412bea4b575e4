// Probe projection, geometry part: the voxel each probe sees first along each direction of the
// Fibonacci set (viewer/probes/grid.py project, Tracer.first_hits), and how many directions meet the back
// of a surface (a probe inside solid geometry). Depends on geometry only, so it runs once per scene.
// One invocation per (direction, probe); probes first_probe.. in this dispatch.

#if defined COMPUTE_SHADER
#include "compute_scene.glsl"

layout(local_size_x = 64) in;

layout(std430, binding = 7) readonly buffer ProbePositionBlock { vec4 probe_position[]; };
layout(std430, binding = 8) readonly buffer DirectionBlock { vec4 directions[]; };  // xyz unit, w weight
layout(std430, binding = 11) writeonly buffer HitBlock { int hits[]; };           // [probe][direction]
layout(std430, binding = 12) buffer BackfaceBlock { uint backface[]; };           // per probe

uniform int first_probe;
uniform int probe_count;
uniform int direction_count;
uniform bool store_hits;

void main() {
    int k = int(gl_GlobalInvocationID.x);
    int p = first_probe + int(gl_GlobalInvocationID.y);
    if (k >= direction_count || p >= probe_count) {
        return;
    }
    int hit = first_hit(probe_position[p].xyz, directions[k].xyz);
    if (store_hits) {
        hits[p * direction_count + k] = hit;
    }
    if (hit == BACKFACE) {
        atomicAdd(backface[p], 1u);
    }
}
#endif
