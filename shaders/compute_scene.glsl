// The voxel grid on the GPU for the compute-shader solver, and the two questions it asks of it: is a
// segment blocked (visibility), and which voxel does a ray hit first (probes). A line-by-line port of
// viewer/rays/raymarch.py's Tracer, so that the GPU and numpy solvers agree to float precision:
// - a ray advances by the cell's distance-field step (at least half a voxel), at most 8 N steps;
// - a segment is blocked where it crosses a voxel's surface: its plane, clipped to its cell and to a
//   patch of squared radius `reach` around its centroid;
// - a ray hits the voxel of an occupied cell that faces it most; in its start cell only a voxel whose
//   plane lies ahead of the origin counts, and an occupied cell with nothing facing is a BACKFACE.
// Buffer bindings 0..6 are the scene's (viewer/gpu/compute_scene.py); programs use 7..15.

#ifndef PI
#define PI 3.14159265358979
#endif
#define MISS (-1)
#define BACKFACE (-2)

layout(std430, binding = 0) readonly buffer VoxelPositionBlock { vec4 voxel_position[]; }; // centroid, w reach
layout(std430, binding = 1) readonly buffer VoxelNormalBlock { vec4 voxel_normal[]; };     // unit normal, w area
layout(std430, binding = 2) readonly buffer VoxelMaterialBlock { vec4 voxel_material[]; }; // albedo, w emitter 0/1
layout(std430, binding = 3) readonly buffer VoxelClusterBlock { ivec4 voxel_cluster[]; };  // cluster cell, w cluster
// Cell c holds voxels x..y-1; z is the bits of its safe step in voxels. One read per marching step:
// on llvmpipe every storage-buffer read is a gather, and three separate tables cost 30-70% more.
layout(std430, binding = 4) readonly buffer CellBlock { uvec4 cells[]; };
layout(std430, binding = 6) readonly buffer ClusterBitsBlock { uint cluster_bits[]; }; // upper triangle, square rows

uniform vec3 grid_lo;
uniform float voxel_size;
uniform int grid_n;
uniform int voxel_count;
uniform int march_limit;       // 8 N, as the Tracer
uniform float surface_offset;  // SURFACE_OFFSET * h: visibility rays start and end this far off the surface
uniform bool clustered;        // far voxel pairs take their clusters' visibility (transport._Visibility)
uniform int cluster_words;     // uints per row of cluster_bits

int cell_index(vec3 p) {
    ivec3 c = ivec3(floor((p - grid_lo) / voxel_size));
    if (any(lessThan(c, ivec3(0))) || any(greaterThanEqual(c, ivec3(grid_n)))) {
        return -1;
    }
    return c.x + c.y * grid_n + c.z * grid_n * grid_n;
}

// Tracer._crosses_a_surface: does the segment a + t d, 0 < t < len, cross a surface of this cell
// (whose voxels are voxels.x..voxels.y-1)?
// The loops here leave by `break`, never by `return`: Mesa 22.3's llvmpipe miscompiles a `return`
// inside a loop of a function that is called from within two nested loops (bounce, on the fly).
bool crosses_a_surface(vec3 a, vec3 d, float len, int cell, uvec2 voxels) {
    bool crossed = false;
    for (uint k = voxels.x; k < voxels.y; ++k) {
        vec4 patch_centre = voxel_position[k];
        vec3 n = voxel_normal[k].xyz;
        float dn = dot(d, n);
        float t = dot(patch_centre.xyz - a, n) / (abs(dn) > 1e-12 ? dn : 1e-12);
        vec3 x = a + t * d;
        vec3 off_centre = x - patch_centre.xyz;
        if (abs(dn) > 1e-12 && t > 0.0 && t < len && dot(off_centre, off_centre) <= patch_centre.w
                && cell_index(x) == cell) {
            crossed = true;
            break;
        }
    }
    return crossed;
}

// Tracer.segments_clear for one segment (a inside the grid).
bool segment_clear(vec3 a, vec3 b) {
    vec3 d = b - a;
    float len = length(d);
    d /= max(len, 1e-30);
    float t = 0.0;
    int checked = -1;  // the last occupied cell tested: each visit tests a cell once
    bool clear = true;
    for (int iteration = 0; iteration < march_limit && t < len; ++iteration) {
        int cell = cell_index(a + t * d);
        if (cell < 0) {
            break;  // the grid is convex: a segment that has left it meets nothing more
        }
        uvec4 info = cells[cell];
        if (cell != checked && info.y > info.x) {
            checked = cell;
            if (crosses_a_surface(a, d, len, cell, info.xy)) {
                clear = false;
                break;
            }
        }
        t += uintBitsToFloat(info.z) * voxel_size;
    }
    return clear;
}

// Tracer.first_hits for one ray: the voxel index, MISS or BACKFACE.
int first_hit(vec3 origin, vec3 d) {
    int start = cell_index(origin);
    int hit = MISS;
    float t = 0.0;
    for (int iteration = 0; iteration < march_limit && start >= 0; ++iteration) {
        int cell = cell_index(origin + t * d);
        if (cell < 0) {
            break;
        }
        uvec4 info = cells[cell];
        if (info.y > info.x) {
            float score = 0.0;
            for (uint k = info.x; k < info.y; ++k) {
                vec3 n = voxel_normal[k].xyz;
                float facing = -dot(d, n);
                bool ahead = dot(origin - voxel_position[k].xyz, n) >= 0.0;
                if (facing > score && (ahead || cell != start)) {
                    hit = int(k);
                    score = facing;
                }
            }
            if (hit == MISS && cell != start) {
                hit = BACKFACE;
            }
            if (hit != MISS) {
                break;
            }
        }
        t += uintBitsToFloat(info.z) * voxel_size;
    }
    return hit;
}

bool cluster_visible(int a, int b) {
    int row = min(a, b), column = max(a, b);
    return ((cluster_bits[row * cluster_words + (column >> 5)] >> (column & 31)) & 1u) != 0u;
}

// V_ij as transport._Visibility decides it, for a pair that faces each other, traced from the lower
// index (numpy traces each unordered pair once, from i < j): voxel to voxel for pairs with an emitter
// and for neighbouring clusters, the clusters' visibility otherwise.
bool pair_visible(int i, int j) {
    int low = min(i, j), high = max(i, j);
    if (clustered) {
        ivec4 a = voxel_cluster[low], b = voxel_cluster[high];
        ivec3 gap = abs(a.xyz - b.xyz);
        bool exact = voxel_material[low].w > 0.0 || voxel_material[high].w > 0.0
                     || max(gap.x, max(gap.y, gap.z)) <= 1;
        if (!exact) {
            return cluster_visible(a.w, b.w);
        }
    }
    return segment_clear(voxel_position[low].xyz + surface_offset * voxel_normal[low].xyz,
                         voxel_position[high].xyz + surface_offset * voxel_normal[high].xyz);
}
