// The scene's triangles, flat-shaded per face: direct light (emitter samples + sun, shadowed), indirect
// diffuse light from the SH probe grid, and the emitters' own radiance. Writes linear HDR radiance
// (or a debug quantity, see view_mode) to a float target; present.glsl tone-maps it.
//
//   outgoing = albedo / pi * (E_direct + E_indirect) + emission      (Lambertian, DESIGN.md)
//
// The probe grid holds indirect incident radiance only (no emitters, no sun), so direct light is not
// counted twice.
//
// Defines (one compiled variant each, since llvmpipe runs both sides of a branch with masks, so a
// uniform switch would pay for the unused terms): VIEW (one of the VIEW_* below), INDIRECT (0: GI off),
// INTERLEAVE (1: interleaved direct light, VIEW_FINAL and VIEW_DIRECT only). With INTERLEAVE each pixel
// of a 2x2 block sums a different quarter of the emitter samples and writes the pieces that
// interleave_resolve.glsl recombines: everything but the reflected direct light, the direct irradiance,
// albedo / pi, and the surface's plane (inverse view depth and its screen-space gradient).
// BAKED (1: direct irradiance read from the lightmaps of viewer/gpu/direct_bake.py). HALF_INDIRECT (1:
// indirect irradiance upsampled from a half-resolution target, see indirect_half.glsl, with weights that
// keep only texels on this fragment's plane). DISPLAY (1: write the sRGB-encoded display value, exposure
// and tone curve applied as present.glsl does (display_value, tonemap.glsl, with its TONE_CURVE and RAW):
// one pass into an 8-bit image instead of a float image and a full-screen tone-mapping pass, which cost
// about a third of a frame on llvmpipe).

#define VIEW_FINAL 0
#define VIEW_DIRECT 1
#define VIEW_INDIRECT 2
#define VIEW_ALBEDO 3
#define VIEW_NORMALS 4

#ifndef VIEW
#define VIEW VIEW_FINAL
#endif
#ifndef INDIRECT
#define INDIRECT 1
#endif
#ifndef INTERLEAVE
#define INTERLEAVE 0
#endif
#ifndef BAKED
#define BAKED 0
#endif
#ifndef HALF_INDIRECT
#define HALF_INDIRECT 0
#endif
#ifndef DISPLAY
#define DISPLAY 0
#endif

#if defined VERTEX_SHADER

invariant gl_Position;  // the same depth in the depth pre-pass and the shading pass

in vec3 in_position;
in vec3 in_normal;
in vec3 in_albedo;
in vec3 in_emission;

uniform mat4 view_proj;

out vec3 v_position;
flat out vec3 v_normal;
flat out vec3 v_albedo;
flat out vec3 v_emission;
#if BAKED
in vec2 in_lightmap;             // atlas coordinate of this corner
out vec2 v_lightmap;
#endif
#if HALF_INDIRECT
#include "octahedral.glsl"
flat out uvec2 v_normal_keys;    // the octahedral codes of the front and back normals (indirect_half.glsl)
#endif

void main() {
#if BAKED
    v_lightmap = in_lightmap;
#endif
#if HALF_INDIRECT
    v_normal_keys = uvec2(octahedral_encode(in_normal), octahedral_encode(-in_normal));
#endif
    v_position = in_position;
    v_normal = in_normal;
    v_albedo = in_albedo;
    v_emission = in_emission;
    gl_Position = view_proj * vec4(in_position, 1.0);
}

#elif defined FRAGMENT_SHADER

#include "tonemap.glsl"
#include "probe_grid.glsl"
#include "direct_light.glsl"

in vec3 v_position;
flat in vec3 v_normal;
flat in vec3 v_albedo;
flat in vec3 v_emission;
#if BAKED
in vec2 v_lightmap;
uniform sampler2D lightmap;   // direct irradiance: front sides of the faces left, back sides right
#endif
#if HALF_INDIRECT
flat in uvec2 v_normal_keys;
uniform sampler2D half_irradiance;   // indirect irradiance at half resolution (indirect_half.glsl)
uniform usampler2D half_plane;       // the plane key of each of its texels
uniform float plane_tolerance;       // world distance off this fragment's plane that still counts as on it
uniform float half_scale;            // the half target's size over the full target's (1/2 or 1/4)

// Bilinear upsampling of the half-resolution indirect irradiance that leaves out the texels of other
// planes (another facing normal, or off this fragment's plane by more than plane_tolerance), so no light
// bleeds across geometric edges. Normals are compared by their octahedral codes (a plane's faces share
// one normal, so one code). One gather reads the four planes; the filtering is then steered into
// one hardware bilinear fetch by moving the sample point: the per-axis weights of the texels that remain
// (exact when an edge splits the footprint 2 + 2, a small leak of the far texel when it splits 3 + 1).
// Where no texel is on the plane, the plain bilinear filter is used.
vec3 upsampled_indirect(vec3 p, vec3 n, uint normal_key) {
    vec2 size = vec2(textureSize(half_plane, 0));
    vec2 u = gl_FragCoord.xy * half_scale - 0.5;
    vec2 f = fract(u);
    vec2 base = floor(u);
    uvec4 keys = textureGather(half_plane, (base + 1.0) / size, 0);  // (0,1), (1,1), (1,0), (0,0)
    vec4 w = vec4((1.0 - f.x) * f.y, f.x * f.y, f.x * (1.0 - f.y), (1.0 - f.x) * (1.0 - f.y));
    float offset = dot(n, p);
    vec4 on_plane;
    for (int k = 0; k < 4; ++k) {
        bool same = (keys[k] >> 16) == normal_key
                 && abs(unpackHalf2x16(keys[k] & 0xffffu).x - offset) <= plane_tolerance;
        on_plane[k] = same ? 1.0 : 0.0;
    }
    vec4 kept = w * on_plane;
    float total = kept.x + kept.y + kept.z + kept.w;
    vec2 g = total > 0.0 ? vec2(kept.y + kept.z, kept.x + kept.y) / total : f;
    // Where an edge cuts off one corner (3 + 1), the per-axis weights still give the corner some weight:
    // move the sample point to the nearer side away from it.
    const vec2 corners[4] = vec2[4](vec2(0.0, 1.0), vec2(1.0, 1.0), vec2(1.0, 0.0), vec2(0.0, 0.0));
    for (int k = 0; k < 4; ++k) {
        vec2 away = abs(corners[k] - g);   // how far g already is from the corner, per axis
        bool off = on_plane[k] == 0.0 && total > 0.0;
        bool along_x = away.x >= away.y;   // the shorter move
        g.x = off && along_x ? 1.0 - corners[k].x : g.x;
        g.y = off && !along_x ? 1.0 - corners[k].y : g.y;
    }
    return textureLod(half_irradiance, (base + 0.5 + g) / size, 0.0).rgb;
}
#endif

layout(location = 0) out vec4 frag_color;
#if INTERLEAVE
layout(location = 1) out vec4 frag_direct_irradiance;
layout(location = 2) out vec4 frag_albedo_over_pi;
layout(location = 3) out vec4 frag_plane;
#endif

void main() {
    // Surfaces reflect on both sides (Mitsuba's two-sided diffuse); emitters emit from the front only.
    vec3 n = gl_FrontFacing ? v_normal : -v_normal;
    vec3 emission = gl_FrontFacing ? v_emission : vec3(0.0);
#if VIEW == VIEW_ALBEDO
    vec3 result = v_albedo;
#elif VIEW == VIEW_NORMALS
    vec3 result = srgb_to_linear(n * 0.5 + 0.5);  // the sRGB encoding undoes this: it shows n/2 + 1/2 as is
#else
    vec3 result = vec3(0.0);
#if INTERLEAVE
    ivec2 block = ivec2(gl_FragCoord.xy) & 1;
    vec3 irradiance = emitter_irradiance_interleaved(v_position, n, block.x + 2 * block.y)
                    + sun_irradiance_at(v_position, n);
    frag_direct_irradiance = vec4(irradiance, 1.0);
    frag_albedo_over_pi = vec4(v_albedo / PI, 1.0);
    // 1 / view depth is linear in screen space on a plane: its value and gradient identify the plane.
    frag_plane = vec4(gl_FragCoord.w, dFdx(gl_FragCoord.w), dFdy(gl_FragCoord.w), 1.0);
    result += emission;
#elif VIEW != VIEW_INDIRECT
#if BAKED
    // The back sides' lightmap lies to the right of the front sides' (direct_bake.py).
    vec3 direct = textureLod(lightmap, v_lightmap + vec2(gl_FrontFacing ? 0.0 : 0.5, 0.0), 0.0).rgb;
#else
    vec3 direct = direct_irradiance(v_position, n);
#endif
    result += v_albedo / PI * direct + emission;
#endif
#if VIEW != VIEW_DIRECT && INDIRECT
#if HALF_INDIRECT
    result += v_albedo / PI * upsampled_indirect(v_position, n, gl_FrontFacing ? v_normal_keys.x : v_normal_keys.y);
#else
    result += v_albedo / PI * probe_irradiance(v_position, n);
#endif
#endif
#endif
#if DISPLAY
    frag_color = vec4(linear_to_srgb(display_value(result)), 1.0);
#else
    frag_color = vec4(result, 1.0);
#endif
}

#endif
