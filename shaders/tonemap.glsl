// HDR linear radiance -> exposure -> tone curve -> sRGB-encoded display value.

#define TONEMAP_NONE 0
#define TONEMAP_REINHARD 1
#define TONEMAP_ACES 2

// Narkowicz 2015, "ACES Filmic Tone Mapping Curve" (a fit of the ACES reference rendering transform).
vec3 tonemap_aces(vec3 x) {
    return clamp(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}

vec3 tonemap_reinhard(vec3 x) {
    return x / (1.0 + x);
}

vec3 tonemap(vec3 x, int curve) {
    if (curve == TONEMAP_ACES) {
        return tonemap_aces(x);
    }
    if (curve == TONEMAP_REINHARD) {
        return tonemap_reinhard(x);
    }
    return clamp(x, 0.0, 1.0);  // none: a plain clamp, as Mitsuba's 8-bit output does
}

// The sRGB transfer function (IEC 61966-2-1).
vec3 linear_to_srgb(vec3 x) {
    x = clamp(x, 0.0, 1.0);
    return mix(12.92 * x, 1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), x));
}

vec3 srgb_to_linear(vec3 x) {
    return mix(x / 12.92, pow((x + 0.055) / 1.055, vec3(2.4)), step(vec3(0.04045), x));
}
