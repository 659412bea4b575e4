// Debug view: every occupied voxel cell as a cube, coloured by its albedo (shaded by a fixed light so
// the shape reads) or by its outgoing radiance (HDR, tone-mapped like the scene). Cube edges are
// darkened so single voxels stay visible on flat walls.

#if defined VERTEX_SHADER

in vec3 in_position;    // unit cube corner in [-0.5, 0.5]^3
in vec3 in_normal;
in vec3 in_center;      // per instance: the cell centre
in vec3 in_color;       // per instance: albedo or radiance

uniform mat4 view_proj;
uniform float cube_size;

out vec3 v_local;
flat out vec3 v_normal;
flat out vec3 v_color;

void main() {
    v_local = in_position;
    v_normal = in_normal;
    v_color = in_color;
    gl_Position = view_proj * vec4(in_center + in_position * cube_size, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform bool shade;   // albedo: light the faces; radiance: show the value as it is

in vec3 v_local;
flat in vec3 v_normal;
flat in vec3 v_color;

out vec4 frag_color;

void main() {
    // Distance to the face's border: the largest in-face coordinate (the normal axis is 0.5 everywhere).
    vec3 in_face = abs(v_local) * (1.0 - abs(v_normal));
    float edge = smoothstep(0.42, 0.5, max(in_face.x, max(in_face.y, in_face.z)));
    float light = shade ? 0.45 + 0.55 * max(dot(v_normal, normalize(vec3(0.35, 0.8, 0.5))), 0.0) : 1.0;
    frag_color = vec4(v_color * light * (1.0 - 0.35 * edge), 1.0);
}

#endif
