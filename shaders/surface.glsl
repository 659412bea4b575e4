// The scene's triangles, flat-shaded per face: direct light (emitter samples + sun, shadowed), indirect
// diffuse light from the SH probe grid, and the emitters' own radiance. Writes linear HDR radiance
// (or a debug quantity, see view_mode) to a float target; present.glsl tone-maps it.
//
//   outgoing = albedo / pi * (E_direct + E_indirect) + emission      (Lambertian, docs/ARCHITECTURE.md)
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
// BAKED (1: the direct irradiance read from the lightmap of viewer/gpu/direct_bake.py), BAKED_INDIRECT
// (1: the indirect irradiance from the lightmap of viewer/gpu/indirect_bake.py; 0: the probe grid per
// fragment, as without BAKED). DISPLAY (1: write
// the sRGB-encoded display value, exposure and tone curve applied as present.glsl does (display_value,
// tonemap.glsl, with its TONE_CURVE and RAW): one pass into an 8-bit image instead of a float image and
// a full-screen tone-mapping pass, which cost about a third of a frame on llvmpipe). TEXTURED (1: the
// albedo is the vertex albedo times the base-colour texture at the fragment's texture coordinate:
// mipmapped, trilinear, sRGB decoded to linear by the texture unit before it is filtered; the vertex
// albedo is then the face's albedo over the texture's mean colour, viewer/gpu/mesh.py). ACCUMULATE (1,
// with DISPLAY: one more jittered image of a still view, averaged with the ones before: the display value
// mixed with the mean so far at this pixel, `accumulated`, by `accumulate_weight` = 1 / images: the
// display image of viewer/gpu/targets.py RefiningTarget. The nearest fragment writes last, so the mean is
// that of the visible surfaces).

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
#ifndef BAKED_INDIRECT
#define BAKED_INDIRECT 0
#endif
#ifndef DISPLAY
#define DISPLAY 0
#endif
#ifndef TEXTURED
#define TEXTURED 0
#endif
#ifndef ACCUMULATE
#define ACCUMULATE 0
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
#if TEXTURED
in vec2 in_uv;                   // texture coordinate: (0, 0) is the image's top-left (glTF)
out vec2 v_uv;
#endif

void main() {
#if TEXTURED
    v_uv = in_uv;
#endif
#if BAKED
    v_lightmap = in_lightmap;
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
uniform sampler2D lightmap;            // direct irradiance: front sides of the faces left, back sides right
uniform vec3 direct_scale;             // times this: the lamps' colour or intensity since the bake
uniform sampler2D indirect_lightmap;   // the probe grid's indirect irradiance, the same texels
#endif
#if TEXTURED
in vec2 v_uv;
uniform sampler2D base_colour;   // the group's texture: repeat or clamp set on it, mirrored repeat here
uniform vec2 mirror_uv;          // 1 along an axis whose wrap mode is mirrored repeat, else 0

vec3 surface_albedo() {
    vec2 mirrored = 1.0 - abs(mod(v_uv, 2.0) - 1.0);
    vec2 uv = mix(v_uv, mirrored, mirror_uv);
    // the unwrapped coordinate's derivatives pick the mip level: no seam where the mirror folds
    return min(v_albedo * textureGrad(base_colour, uv, dFdx(v_uv), dFdy(v_uv)).rgb, vec3(0.999));
}
#else
vec3 surface_albedo() {
    return v_albedo;
}
#endif
layout(location = 0) out vec4 frag_color;
#if INTERLEAVE
layout(location = 1) out vec4 frag_direct_irradiance;
layout(location = 2) out vec4 frag_albedo_over_pi;
layout(location = 3) out vec4 frag_plane;
#endif
#if ACCUMULATE
uniform sampler2D accumulated;
uniform float accumulate_weight;
#endif

void main() {
    // Surfaces reflect on both sides (Mitsuba's two-sided diffuse); emitters emit from the front only.
    vec3 n = gl_FrontFacing ? v_normal : -v_normal;
    vec3 emission = gl_FrontFacing ? v_emission : vec3(0.0);
    vec3 albedo = surface_albedo();
#if VIEW == VIEW_ALBEDO
    vec3 result = albedo;
#elif VIEW == VIEW_NORMALS
    vec3 result = srgb_to_linear(n * 0.5 + 0.5);  // the sRGB encoding undoes this: it shows n/2 + 1/2 as is
#else
    vec3 result = vec3(0.0);
#if INTERLEAVE
    ivec2 block = ivec2(gl_FragCoord.xy) & 1;
    vec3 irradiance = emitter_irradiance_interleaved(v_position, n, block.x + 2 * block.y)
                    + sun_irradiance_at(v_position, n);
    frag_direct_irradiance = vec4(irradiance, 1.0);
    frag_albedo_over_pi = vec4(albedo / PI, 1.0);
    // 1 / view depth is linear in screen space on a plane: its value and gradient identify the plane.
    frag_plane = vec4(gl_FragCoord.w, dFdx(gl_FragCoord.w), dFdy(gl_FragCoord.w), 1.0);
    result += emission;
#elif BAKED
    // The back sides' lightmap lies to the right of the front sides' (direct_bake.py).
    vec2 texel = v_lightmap + vec2(gl_FrontFacing ? 0.0 : 0.5, 0.0);
    vec3 irradiance = vec3(0.0);
#if VIEW != VIEW_INDIRECT
    irradiance += direct_scale * textureLod(lightmap, texel, 0.0).rgb;
    result += emission;
#endif
#if VIEW != VIEW_DIRECT && INDIRECT && BAKED_INDIRECT
    irradiance += textureLod(indirect_lightmap, texel, 0.0).rgb;
#endif
    result += albedo / PI * irradiance;
#elif VIEW != VIEW_INDIRECT
    result += albedo / PI * direct_irradiance(v_position, n) + emission;
#endif
#if VIEW != VIEW_DIRECT && INDIRECT && !BAKED_INDIRECT
    result += albedo / PI * probe_irradiance(v_position, n);
#endif
#endif
#if DISPLAY && ACCUMULATE
    vec3 mean = mix(texelFetch(accumulated, ivec2(gl_FragCoord.xy), 0).rgb,
                    linear_to_srgb(display_value(result)), accumulate_weight);
    frag_color = vec4(mean, 1.0);
#elif DISPLAY
    frag_color = vec4(linear_to_srgb(display_value(result)), 1.0);
#else
    frag_color = vec4(result, 1.0);
#endif
}

#endif
