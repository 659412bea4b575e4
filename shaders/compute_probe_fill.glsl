// One wave of viewer/probes/grid.py fill_invalid: every invalid probe first reached in iteration `wave`
// takes the mean of its 6-neighbours known before it (wave number below this one; valid probes are 0).
// Wave numbers come from the probes' validity (geometry only), so each wave is one dispatch that reads
// earlier waves and writes only its own probes. Probe p = (x M + y) M + z, as ProbeGrid.positions.

#if defined COMPUTE_SHADER
layout(local_size_x = 64) in;

layout(std430, binding = 14) readonly buffer WaveBlock { int waves[]; };
layout(std430, binding = 15) buffer ProbeBlock { float probe_sh[]; };

uniform int probe_resolution;
uniform int wave;

void main() {
    int m = probe_resolution;
    int p = int(gl_GlobalInvocationID.x);
    if (p >= m * m * m || waves[p] != wave) {
        return;
    }
    ivec3 index = ivec3(p / (m * m), (p / m) % m, p % m);
    const ivec3 steps[6] = ivec3[6](ivec3(1, 0, 0), ivec3(-1, 0, 0), ivec3(0, 1, 0), ivec3(0, -1, 0),
                                    ivec3(0, 0, 1), ivec3(0, 0, -1));
    float total[27];
    for (int c = 0; c < 27; ++c) {
        total[c] = 0.0;
    }
    int count = 0;
    for (int s = 0; s < 6; ++s) {
        ivec3 q = index + steps[s];
        if (any(lessThan(q, ivec3(0))) || any(greaterThanEqual(q, ivec3(m)))) {
            continue;
        }
        int neighbour = (q.x * m + q.y) * m + q.z;
        int known = waves[neighbour];
        if (known >= 0 && known < wave) {
            count += 1;
            for (int c = 0; c < 27; ++c) {
                total[c] += probe_sh[27 * neighbour + c];
            }
        }
    }
    for (int c = 0; c < 27; ++c) {
        probe_sh[27 * p + c] = total[c] / float(count);
    }
}
#endif
