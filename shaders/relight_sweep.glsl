// One sweep of the relight (viewer/physical/relight.py): R_out = R_0 + albedo * T R_in for every voxel, with T the
// geometry stage's sparse transport matrix in CSR form (row = receiver: the share of its gather rays that
// reach each voxel). One invocation per receiver; the sweep is the paper's bounce (eq. 30).

#if defined COMPUTE_SHADER
layout(local_size_x = 64) in;

layout(std430, binding = 0) readonly buffer RowBlock { int row_start[]; };
layout(std430, binding = 1) readonly buffer ColumnBlock { int column[]; };
layout(std430, binding = 2) readonly buffer WeightBlock { float weight[]; };
layout(std430, binding = 3) readonly buffer FirstBlock { vec4 first_bounce[]; };
layout(std430, binding = 4) readonly buffer AlbedoBlock { vec4 albedo[]; };
layout(std430, binding = 5) readonly buffer InBlock { vec4 reflected_in[]; };
layout(std430, binding = 6) writeonly buffer OutBlock { vec4 reflected_out[]; };

uniform int voxel_count;

void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= voxel_count) {
        return;
    }
    vec3 gathered = vec3(0.0);
    for (int e = row_start[i]; e < row_start[i + 1]; ++e) {
        gathered += weight[e] * reflected_in[column[e]].rgb;
    }
    reflected_out[i] = vec4(first_bounce[i].rgb + albedo[i].rgb * gathered, 0.0);
}
#endif
