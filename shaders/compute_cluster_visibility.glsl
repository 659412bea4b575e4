// Visibility between clusters of voxels (transport._Visibility): at 32^3 voxels and above, far voxel
// pairs without an emitter take the visibility of their clusters' centroids, traced once here. One
// invocation per 32 pairs (row, word); only the upper triangle (row < column) is traced, and pairs of
// neighbouring clusters are skipped (their voxels are traced voxel to voxel).

#if defined COMPUTE_SHADER
#include "compute_scene.glsl"

layout(local_size_x = 64) in;

layout(std430, binding = 7) readonly buffer ClusterPositionBlock { vec4 cluster_position[]; };  // centroid
layout(std430, binding = 8) readonly buffer ClusterNormalBlock { vec4 cluster_normal[]; };      // unit normal
layout(std430, binding = 9) readonly buffer ClusterCellBlock { ivec4 cluster_cell[]; };
layout(std430, binding = 10) buffer ClusterVisibleBlock { uint cluster_visible_bits[]; };

uniform int cluster_count;
uniform int first_row;
uniform int first_bit;  // this dispatch traces bits first_bit..end_bit-1 of every word
uniform int end_bit;    // (all 32 exceed llvmpipe's loop budget on large grids)

void main() {
    int word = int(gl_GlobalInvocationID.x);
    int row = first_row + int(gl_GlobalInvocationID.y);
    if (word >= cluster_words || row >= cluster_count) {
        return;
    }
    uint bits = first_bit == 0 ? 0u : cluster_visible_bits[row * cluster_words + word];
    if (word >= (row + 1) >> 5) {
        vec3 a = cluster_position[row].xyz + surface_offset * cluster_normal[row].xyz;
        ivec3 cell = cluster_cell[row].xyz;
        for (int b = first_bit; b < end_bit; ++b) {
            int column = word * 32 + b;
            if (column <= row || column >= cluster_count) {
                continue;
            }
            ivec3 gap = abs(cluster_cell[column].xyz - cell);
            if (max(gap.x, max(gap.y, gap.z)) <= 1) {
                continue;
            }
            vec3 other = cluster_position[column].xyz + surface_offset * cluster_normal[column].xyz;
            if (segment_clear(a, other)) {
                bits |= 1u << b;
            }
        }
    }
    cluster_visible_bits[row * cluster_words + word] = bits;
}
#endif
