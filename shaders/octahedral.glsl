// Unit vectors in 16 bits: the octahedral map (Cigolle et al. 2014, "A Survey of Efficient
// Representations for Independent Unit Vectors"), 8 bits per coordinate, each in 1..255, so that the
// code 0 stays free for "no normal" (a cleared texel). indirect_half.glsl and surface.glsl compare codes.

vec2 octahedral_wrap(vec2 v) {
    return (1.0 - abs(v.yx)) * vec2(v.x >= 0.0 ? 1.0 : -1.0, v.y >= 0.0 ? 1.0 : -1.0);
}

uint octahedral_encode(vec3 n) {
    n /= abs(n.x) + abs(n.y) + abs(n.z);
    vec2 e = n.z >= 0.0 ? n.xy : octahedral_wrap(n.xy);
    uvec2 q = uvec2(clamp(round((e * 0.5 + 0.5) * 254.0), 0.0, 254.0)) + 1u;   // 1..255: 0 stays free
    return q.x | (q.y << 8);
}
