// Which voxel pairs exchange light under the physical kernel: bit (i, j) is cos_i > 0, cos_j > 0 and
// V_ij, traced once per unordered pair (the matrix is symmetric). Stored as the upper triangle
// (j > i), row i from word (i + 1) / 32 on, at visibility_row[i]: K^2 / 16 bytes, 48 MB at 64^3.
// One invocation per 32 pairs (row, word); rows first_row.. in this dispatch.

#if defined COMPUTE_SHADER
#include "compute_scene.glsl"

layout(local_size_x = 64) in;

layout(std430, binding = 7) buffer VisibilityBlock { uint visibility_bits[]; };
layout(std430, binding = 8) readonly buffer VisibilityRowBlock { uint visibility_row[]; };

uniform int first_row;
uniform int first_bit;  // this dispatch traces bits first_bit..end_bit-1 of every word
uniform int end_bit;    // (all 32 exceed llvmpipe's loop budget on large grids)
uniform int row_words;  // ceil(K / 32)

void main() {
    int word = int(gl_GlobalInvocationID.x);
    int i = first_row + int(gl_GlobalInvocationID.y);
    int first_word = (i + 1) >> 5;
    if (i >= voxel_count || word < first_word || word >= row_words) {
        return;
    }
    vec3 p = voxel_position[i].xyz;
    vec3 n = voxel_normal[i].xyz;
    uint bits = first_bit == 0 ? 0u : visibility_bits[visibility_row[i] + uint(word - first_word)];
    for (int b = first_bit; b < end_bit; ++b) {
        int j = word * 32 + b;
        if (j <= i || j >= voxel_count) {
            continue;
        }
        vec3 d = voxel_position[j].xyz - p;
        if (dot(d, n) > 0.0 && dot(d, voxel_normal[j].xyz) < 0.0 && pair_visible(i, j)) {
            bits |= 1u << b;
        }
    }
    visibility_bits[visibility_row[i] + uint(word - first_word)] = bits;
}
#endif
