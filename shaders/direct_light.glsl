// Direct irradiance from the scene's area emitters and the sun, with shadows.
//
// Emitters: N fixed samples (viewer/gpu/lights.py), each carrying Phi_k = Le * a_k (radiance times the
// emitter area it stands for):  E(p, n) = sum_k Phi_k cos_p cos_k / (r^2 + a_k / pi) V_k, where the
// a_k / pi term is the near-field clamp of the transport solver's kernel. V_k comes from one shadow
// cube per sample (five faces: the back face would only see behind the one-sided emitter) stored as
// tiles of one depth atlas (viewer/gpu/shadows.py) and read with hardware 2x2 percentage-closer
// filtering; the N overlapping hard shadows make the penumbra.
// Sun: irradiance * cos_p * V, V from one orthographic shadow map.

struct LightSample {
    vec4 position_area;   // xyz position on the emitter, w the area a_k
    vec4 normal_atlas_u;  // xyz front normal, w the atlas u of the sample's first shadow tile
    vec4 tangent_atlas_v; // xyz tangent (frames the shadow cube), w the atlas v of its tiles
    vec4 power;           // rgb Le * a_k
};

#ifndef MAX_LIGHT_SAMPLES
#define MAX_LIGHT_SAMPLES 256   // 256 x 64 bytes: the 16 KiB every GL implementation allows a uniform block
#endif

layout(std140, binding = 0) uniform LightSampleBlock {
    LightSample light_samples[MAX_LIGHT_SAMPLES];
};

uniform int light_sample_count;
uniform sampler2DShadow emitter_shadow_atlas;
uniform vec2 shadow_tile_scale;   // one tile's size in atlas uv; a sample's five tiles lie in a row
uniform float shadow_tile_texels; // one tile's width in texels
uniform float shadow_near;
uniform float shadow_far;
uniform float shadow_lift;        // cube centres sit this far in front of the emitter surface
uniform float shadow_bias;        // normal offset, in shadow-map texels at the receiver's distance

uniform bool sun_enabled;
uniform vec3 sun_direction;       // unit, towards the sun
uniform vec3 sun_irradiance;      // on a surface facing the sun
uniform mat4 sun_view_proj;
uniform sampler2DShadow sun_shadow_map;
uniform float sun_texel;          // world size of one sun shadow-map texel

#ifndef PI
#define PI 3.14159265358979
#endif

// Visibility of sample s from p (p in front of the emitter): pick the cube face, project, compare.
// d = p - the sample's position.
float emitter_visibility(LightSample s, vec3 d) {
    vec3 n = s.normal_atlas_u.xyz;
    vec3 t = s.tangent_atlas_v.xyz;
    vec3 a = vec3(dot(d, t), dot(d, cross(n, t)), dot(d, n) - shadow_lift);
    // (right, up, forward) on the chosen face, as viewer/gpu/shadows.py renders them (FACE_AXES).
    // Selects, not branches: llvmpipe runs both sides of a divergent branch anyway.
    vec3 m = abs(a);
    bool front = a.z >= max(m.x, m.y);
    bool along_t = m.x >= m.y;
    vec3 f = front ? a : (along_t ? vec3(a.y, a.z, m.x) : vec3(a.x, a.z, m.y));
    float face = front ? 0.0 : (along_t ? (a.x > 0.0 ? 1.0 : 2.0) : (a.y > 0.0 ? 3.0 : 4.0));
    float half_texel = 0.5 / shadow_tile_texels;
    f.z = max(f.z, 1e-3 * shadow_near);  // d = 0 (a receiver on the sample itself); a length: scene-relative
    vec2 uv = clamp(f.xy / f.z * 0.5 + 0.5, vec2(half_texel), vec2(1.0 - half_texel));
    vec2 atlas = vec2(s.normal_atlas_u.w + face * shadow_tile_scale.x, s.tangent_atlas_v.w) + uv * shadow_tile_scale;
    // Window depth of the perspective projection with these near and far planes.
    float depth = 0.5 + 0.5 * ((shadow_far + shadow_near) - 2.0 * shadow_far * shadow_near / f.z)
                / (shadow_far - shadow_near);
    return textureLod(emitter_shadow_atlas, vec3(atlas, depth), 0.0);  // no derivatives: no mipmaps
}

// Contribution of one sample, shadowed.
vec3 emitter_sample_irradiance(LightSample s, vec3 p, vec3 n) {
    vec3 d = p - s.position_area.xyz;
    float r2 = dot(d, d);
    float inv_r = inversesqrt(max(r2, 1e-12 * shadow_near * shadow_near));  // d = 0, in any unit
    float cos_p = -dot(n, d) * inv_r;
    float cos_k = dot(s.normal_atlas_u.xyz, d) * inv_r;
    // Normal offset grows with a shadow texel's footprint at this distance (2 r / tile texels).
    float offset = shadow_bias * 2.0 * r2 * inv_r / shadow_tile_texels;
    float visible = emitter_visibility(s, d + n * offset);
    float geometry = max(cos_p, 0.0) * max(cos_k, 0.0) / (r2 + s.position_area.w / PI);
    return s.power.rgb * (geometry * visible);
}

// Interleaved sampling: the sum over samples subset, subset + 4, subset + 8, ... (subset 0..3), scaled
// up to estimate the sum over all of them. Neighbouring pixels take different subsets and
// interleave_resolve.glsl recombines them.
vec3 emitter_irradiance_interleaved(vec3 p, vec3 n, int subset) {
    vec3 total = vec3(0.0);
    for (int k = subset; k < light_sample_count; k += 4) {
        total += emitter_sample_irradiance(light_samples[k], p, n);
    }
    int used = (light_sample_count - subset + 3) / 4;
    return used > 0 ? total * (float(light_sample_count) / float(used)) : vec3(0.0);
}

vec3 emitter_irradiance(vec3 p, vec3 n) {
    vec3 total = vec3(0.0);
    for (int k = 0; k < light_sample_count; ++k) {
        total += emitter_sample_irradiance(light_samples[k], p, n);
    }
    return total;
}

vec3 sun_irradiance_at(vec3 p, vec3 n) {
    if (!sun_enabled) {
        return vec3(0.0);
    }
    float cos_p = dot(n, sun_direction);
    if (cos_p <= 0.0) {
        return vec3(0.0);
    }
    vec4 clip = sun_view_proj * vec4(p + n * (shadow_bias * sun_texel), 1.0);
    vec3 uvz = clip.xyz / clip.w * 0.5 + 0.5;
    float visible = 1.0;
    if (all(greaterThan(uvz, vec3(0.0))) && all(lessThan(uvz, vec3(1.0)))) {
        visible = texture(sun_shadow_map, uvz);
    }
    return sun_irradiance * cos_p * visible;
}

vec3 direct_irradiance(vec3 p, vec3 n) {
    return emitter_irradiance(p, n) + sun_irradiance_at(p, n);
}
