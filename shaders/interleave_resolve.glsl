// Recombines interleaved direct light (surface.glsl with INTERLEAVE): each pixel of a 2x2 block summed
// a different quarter of the emitter samples. A 3x3 tent filter (weights 1 2 1 x 1 2 1) gives each of
// the four subsets exactly a quarter of the total weight, so on a flat region the result is the full
// sum; neighbours on another plane are left out (their weight renormalised away), so shadows and
// colours do not bleed across geometric edges.
//   radiance = (emission + indirect) + albedo / pi * filtered direct irradiance

#if defined VERTEX_SHADER

#include "fullscreen.glsl"

void main() {
    gl_Position = fullscreen_corner(0.0);
}

#elif defined FRAGMENT_SHADER

uniform sampler2D rest_image;               // emission + indirect radiance
uniform sampler2D direct_irradiance_image;  // this pixel's subset estimate
uniform sampler2D albedo_image;             // albedo / pi
uniform sampler2D plane_image;              // 1/depth, its x and y gradients, coverage

out vec4 frag_color;

void main() {
    ivec2 centre = ivec2(gl_FragCoord.xy);
    ivec2 last = textureSize(plane_image, 0) - 1;
    vec4 plane = texelFetch(plane_image, centre, 0);
    vec3 rest = texelFetch(rest_image, centre, 0).rgb;
    if (plane.w == 0.0) {  // background
        frag_color = vec4(rest, 1.0);
        return;
    }
    vec3 total = vec3(0.0);
    float weight = 0.0;
    for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
            ivec2 q = clamp(centre + ivec2(dx, dy), ivec2(0), last);
            vec4 other = texelFetch(plane_image, q, 0);
            float predicted = plane.x + float(dx) * plane.y + float(dy) * plane.z;
            bool same_plane = other.w > 0.0 && abs(other.x - predicted) <= 1e-3 * plane.x
                && length(other.yz - plane.yz) <= 0.05 * length(plane.yz) + 1e-5 * plane.x;
            float w = same_plane ? float((2 - abs(dx)) * (2 - abs(dy))) : 0.0;
            total += w * texelFetch(direct_irradiance_image, q, 0).rgb;
            weight += w;
        }
    }
    vec3 albedo_over_pi = texelFetch(albedo_image, centre, 0).rgb;
    frag_color = vec4(rest + albedo_over_pi * total / max(weight, 1e-6), 1.0);
}

#endif
