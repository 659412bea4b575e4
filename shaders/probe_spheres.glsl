// Debug view: every valid probe as a small sphere; a point on it with normal d shows the probe's SH
// radiance arriving from direction d, L(d) = sum_lm c_lm Y_lm(d) (clamped at 0), so a sphere looks
// like the light it sees. Spheres are ray-traced impostors: one camera-facing quad per probe (a
// tessellated sphere per probe would be thousands of tiny triangles, slow on a CPU rasterizer).

#include "sh.glsl"

#if defined VERTEX_SHADER

uniform sampler3D probe_sh[7];

in vec2 in_corner;     // quad corner in [-1, 1]^2
in ivec3 in_probe;     // per instance: probe index (x, y, z)

uniform mat4 view;
uniform mat4 projection;
uniform vec3 probe_lo;
uniform vec3 probe_hi;
uniform ivec3 probe_count;
uniform float sphere_radius;

out vec3 v_eye_position;     // the quad point, eye space
flat out vec3 v_eye_center;  // the sphere centre, eye space
flat out vec4 v_sh[7];       // the probe's packed coefficients, fetched once per corner, not per pixel

void main() {
    vec3 center = probe_lo + (vec3(in_probe) + 0.5) * (probe_hi - probe_lo) / vec3(probe_count);
    v_eye_center = (view * vec4(center, 1.0)).xyz;
    // Quad in front of the sphere, large enough to hold its silhouette under perspective.
    vec3 toward_eye = normalize(-v_eye_center);
    vec3 right = normalize(cross(vec3(0.0, 1.0, 0.0), toward_eye));
    if (abs(toward_eye.y) > 0.999) {
        right = vec3(1.0, 0.0, 0.0);
    }
    vec3 up = cross(toward_eye, right);
    v_eye_position = v_eye_center + sphere_radius * (toward_eye + 1.5 * (in_corner.x * right + in_corner.y * up));
    for (int i = 0; i < 7; ++i) {
        v_sh[i] = texelFetch(probe_sh[i], in_probe, 0);
    }
    for (int i = 0; i < 7; ++i) {
        v_sh[i] /= v_sh[6].w;   // the textures hold the SH premultiplied by the probe's weight (alpha)
    }
    gl_Position = projection * vec4(v_eye_position, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform mat4 view;
uniform mat4 projection;
uniform float sphere_radius;

in vec3 v_eye_position;
flat in vec3 v_eye_center;
flat in vec4 v_sh[7];

out vec4 frag_color;
// The quad lies in front of its sphere, so the written depth is never nearer than the quad's own:
// this lets the depth test run before the shader (early z).
layout(depth_greater) out float gl_FragDepth;

void main() {
    // Ray from the eye (the origin of eye space) through this fragment, against the sphere.
    vec3 ray = normalize(v_eye_position);
    float b = dot(ray, v_eye_center);
    float h = b * b - dot(v_eye_center, v_eye_center) + sphere_radius * sphere_radius;
    if (h < 0.0) {
        discard;
    }
    vec3 hit = ray * (b - sqrt(h));
    vec4 clip = projection * vec4(hit, 1.0);
    gl_FragDepth = 0.5 * clip.z / clip.w + 0.5;
    // Eye-space normal back to world axes (the view matrix is a rotation plus a translation).
    vec3 normal = normalize(transpose(mat3(view)) * (hit - v_eye_center));
    frag_color = vec4(max(sh_evaluate(sh_unpack(v_sh), normal), vec3(0.0)), 1.0);
}

#endif
