// HDR linear radiance -> exposure -> tone curve -> sRGB-encoded display value.
//
// display_value() and linear_to_srgb() are the whole mapping, for present.glsl and for surface.glsl's
// DISPLAY variant alike, so that a view tone-mapped in its own pass and one tone-mapped as it is shaded
// give the same bytes. Defines: TONE_CURVE (one of the TONEMAP_* below), RAW (1: debug quantities such
// as albedo and normals, shown as they are: no exposure, no tone curve).

#define TONEMAP_NONE 0
#define TONEMAP_REINHARD 1
#define TONEMAP_ACES 2

#ifndef TONE_CURVE
#define TONE_CURVE TONEMAP_ACES
#endif
#ifndef RAW
#define RAW 0
#endif

uniform float exposure_scale;  // 2^EV

// Narkowicz 2015, "ACES Filmic Tone Mapping Curve" (a fit of the ACES reference rendering transform).
vec3 tonemap_aces(vec3 x) {
    return clamp(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}

vec3 tonemap_reinhard(vec3 x) {
    return x / (1.0 + x);
}

// Linear display value in [0, 1], before the sRGB encoding.
vec3 display_value(vec3 radiance) {
#if RAW
    return clamp(radiance, 0.0, 1.0);
#elif TONE_CURVE == TONEMAP_ACES
    return tonemap_aces(radiance * exposure_scale);
#elif TONE_CURVE == TONEMAP_REINHARD
    return clamp(tonemap_reinhard(radiance * exposure_scale), 0.0, 1.0);
#else
    return clamp(radiance * exposure_scale, 0.0, 1.0);  // none: a plain clamp, as Mitsuba's 8-bit output does
#endif
}

// The sRGB transfer function (IEC 61966-2-1).
vec3 linear_to_srgb(vec3 x) {
    x = clamp(x, 0.0, 1.0);
    return mix(12.92 * x, 1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), x));
}

vec3 srgb_to_linear(vec3 x) {
    return mix(x / 12.92, pow((x + 0.055) / 1.055, vec3(2.4)), step(vec3(0.04045), x));
}
