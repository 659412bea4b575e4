// One bounce of the compute solver (eq. 23-30): B_k+1 = albedo / pi * s_i * sum_j G_ij B_k,j, with
// the kernel G of viewer/physical/transport.py and the row clamp s_i = min(1, pi / sum_j G_ij) (a receiver
// gathers at most its hemisphere), the row sum taken in the same loop. Receivers first_item..end_item-1,
// senders first_sender..end_sender-1: llvmpipe gives all loops of an invocation one budget of 65535
// iterations (LP_MAX_TGSI_LOOP_ITERATIONS) and silently drops the rest, so the senders come in chunks
// (viewer/gpu/compute_solver.py sizes them), their sums kept in `accumulated` between dispatches and
// finished (clamp, albedo) by the last chunk.
//   KERNEL_PAPER 0: physical  G_ij = cos_i cos_j A_j / (r^2 + A_j / pi) V_ij; V from the visibility
//                   bitset (VISIBILITY_BITSET 1) or traced on the fly (0)
//   KERNEL_PAPER 1: paper     G_ij = cos_i A_j / (r^2 + A_j / pi) (eq. 25, no visibility)
// Each invocation gathers for RECEIVERS consecutive receivers, so that every sender read serves four
// of them: on llvmpipe a storage-buffer read costs about ten times the arithmetic of one pair.

#if defined COMPUTE_SHADER
#include "compute_scene.glsl"

#ifndef KERNEL_PAPER
#define KERNEL_PAPER 0
#endif
#ifndef VISIBILITY_BITSET
#define VISIBILITY_BITSET 1
#endif
#define RECEIVERS 4   // divides 32: a block's bits in a bitset row share one word

layout(local_size_x = 64) in;

layout(std430, binding = 7) readonly buffer VisibilityBlock { uint visibility_bits[]; };
layout(std430, binding = 8) readonly buffer VisibilityRowBlock { uint visibility_row[]; };
layout(std430, binding = 11) readonly buffer RadianceInBlock { vec4 radiance_in[]; };    // B_k
layout(std430, binding = 12) writeonly buffer RadianceOutBlock { vec4 radiance_out[]; }; // B_k+1
layout(std430, binding = 13) buffer ReflectedBlock { vec4 reflected[]; };                // sum of bounces
layout(std430, binding = 14) buffer StatsBlock { uint stats[]; };                       // max |B|, max |reflected|
layout(std430, binding = 15) buffer AccumulatedBlock { vec4 accumulated[]; };           // gathered rgb, row sum w

uniform int first_item;    // a multiple of RECEIVERS
uniform int end_item;
uniform int first_sender;  // a multiple of 32
uniform int end_sender;    // a multiple of 32, or K
uniform bool first_chunk;
uniform bool last_chunk;
uniform int row_words;     // ceil(K / 32)

vec3 receiver_position[RECEIVERS];
vec3 receiver_normal[RECEIVERS];
vec3 gathered[RECEIVERS];
float row_sum[RECEIVERS];

// Sender j's light at the receivers whose bit is set in `mask` (physical kernel: the pair faces
// each other and is visible).
void gather_physical(int j, uint mask) {
    vec4 sender = voxel_normal[j];
    vec3 q = voxel_position[j].xyz;
    vec3 light = radiance_in[j].rgb;
    for (int r = 0; r < RECEIVERS; ++r) {
        vec3 d = q - receiver_position[r];
        float r2 = dot(d, d);
        float inv_r = inversesqrt(max(r2, 1e-30));
        float g = (dot(d, receiver_normal[r]) * inv_r) * (-dot(d, sender.xyz) * inv_r)
                  * sender.w / (r2 + sender.w / PI);
        g = ((mask >> r) & 1u) != 0u ? g : 0.0;
        row_sum[r] += g;
        gathered[r] += g * light;
    }
}

int row_first_word(int i) {
    return (i + 1) >> 5;
}

void main() {
    int i0 = first_item + RECEIVERS * int(gl_GlobalInvocationID.x);
    if (i0 >= end_item) {
        return;
    }
    int in_slice = min(RECEIVERS, end_item - i0);
    for (int r = 0; r < RECEIVERS; ++r) {
        int i = min(i0 + r, voxel_count - 1);
        receiver_position[r] = voxel_position[i].xyz;
        receiver_normal[r] = voxel_normal[i].xyz;
        gathered[r] = vec3(0.0);
        row_sum[r] = 0.0;
    }
#if KERNEL_PAPER
    for (int j = first_sender; j < end_sender; ++j) {
        vec4 sender = voxel_normal[j];
        vec3 q = voxel_position[j].xyz;
        vec3 light = radiance_in[j].rgb;
        for (int r = 0; r < RECEIVERS; ++r) {
            vec3 d = q - receiver_position[r];
            float r2 = dot(d, d);
            float cos_i = dot(d, receiver_normal[r]) * inversesqrt(max(r2, 1e-30));
            float g = cos_i > 0.0 && r2 > 0.0 ? cos_i * sender.w / (r2 + sender.w / PI) : 0.0;
            row_sum[r] += g;
            gathered[r] += g * light;
        }
    }
#elif VISIBILITY_BITSET
    // senders j < i: bit (j, i) lies in row j, and the block's four bits share one word of it
    int column_word = i0 >> 5;
    int shift = i0 & 31;
    int above = min(i0 + RECEIVERS - 1, end_sender);
    for (int j = first_sender; j < above; ++j) {
        uint word = visibility_bits[visibility_row[j] + uint(column_word - row_first_word(j))];
        uint mask = (word >> shift) & ((1u << RECEIVERS) - 1u);
        if (mask != 0u) {
            gather_physical(j, mask);
        }
    }
    // senders j > i: the receivers' own rows, a word at a time, visiting only the set bits
    uint words[RECEIVERS];
    int end_word = min(row_words, (end_sender + 31) >> 5);
    for (int w = max(row_first_word(i0), first_sender >> 5); w < end_word; ++w) {
        uint any_set = 0u;
        for (int r = 0; r < RECEIVERS; ++r) {
            int i = i0 + r;
            bool stored = r < in_slice && w >= row_first_word(i);
            words[r] = stored ? visibility_bits[visibility_row[i] + uint(w - row_first_word(i))] : 0u;
            any_set |= words[r];
        }
        while (any_set != 0u) {
            int b = findLSB(any_set);
            any_set &= any_set - 1u;
            uint mask = 0u;
            for (int r = 0; r < RECEIVERS; ++r) {
                mask |= ((words[r] >> b) & 1u) << r;
            }
            gather_physical(w * 32 + b, mask);
        }
    }
#else
    for (int j = first_sender; j < end_sender; ++j) {
        vec3 q = voxel_position[j].xyz;
        vec3 sender_normal = voxel_normal[j].xyz;
        uint mask = 0u;
        for (int r = 0; r < in_slice; ++r) {
            vec3 d = q - receiver_position[r];
            if (j != i0 + r && dot(d, receiver_normal[r]) > 0.0 && dot(d, sender_normal) < 0.0
                    && pair_visible(i0 + r, j)) {
                mask |= 1u << r;
            }
        }
        if (mask != 0u) {
            gather_physical(j, mask);
        }
    }
#endif
    for (int r = 0; r < in_slice; ++r) {
        int i = i0 + r;
        vec4 sums = vec4(gathered[r], row_sum[r]);
        if (!first_chunk) {
            sums += accumulated[i];
        }
        if (!last_chunk) {
            accumulated[i] = sums;
            continue;
        }
        float clamp_scale = sums.w > PI ? PI / sums.w : 1.0;
        vec3 next = voxel_material[i].rgb / PI * (clamp_scale * sums.rgb);
        vec3 total = reflected[i].rgb + next;
        radiance_out[i] = vec4(next, 0.0);
        reflected[i] = vec4(total, 0.0);
        atomicMax(stats[0], floatBitsToUint(max(next.r, max(next.g, next.b))));
        atomicMax(stats[1], floatBitsToUint(max(total.r, max(total.g, total.b))));
    }
}
#endif
