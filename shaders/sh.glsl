// Real orthonormal spherical harmonics, bands 0..2 (9 coefficients per colour channel).
// Order and constants as in viewer/probes/sh.py and docs/ARCHITECTURE.md:
// (l,m) = 00, 1-1, 10, 11, 2-2, 2-1, 20, 21, 22,
// for a unit direction in world axes pointing from the probe towards where the light comes from.

#ifndef PI
#define PI 3.14159265358979
#endif

struct SH9 {
    vec3 c[9];   // RGB coefficient of each basis function
};

void sh_basis(vec3 d, out float y[9]) {
    y[0] = 0.282095;
    y[1] = 0.488603 * d.y;
    y[2] = 0.488603 * d.z;
    y[3] = 0.488603 * d.x;
    y[4] = 1.092548 * d.x * d.y;
    y[5] = 1.092548 * d.y * d.z;
    y[6] = 0.315392 * (3.0 * d.z * d.z - 1.0);
    y[7] = 1.092548 * d.x * d.z;
    y[8] = 0.546274 * (d.x * d.x - d.y * d.y);
}

// The 27 numbers packed coefficient-major as RGB triples into seven RGBA texels
// (c0.rgb c1.r | c1.gb c2.rg | c2.b c3.rgb | ...), as ProbeGrid.texture_data() writes them.
SH9 sh_unpack(vec4 t[7]) {
    float f[28] = float[28](
        t[0].x, t[0].y, t[0].z, t[0].w, t[1].x, t[1].y, t[1].z, t[1].w,
        t[2].x, t[2].y, t[2].z, t[2].w, t[3].x, t[3].y, t[3].z, t[3].w,
        t[4].x, t[4].y, t[4].z, t[4].w, t[5].x, t[5].y, t[5].z, t[5].w,
        t[6].x, t[6].y, t[6].z, t[6].w);
    SH9 sh;
    for (int i = 0; i < 9; ++i) {
        sh.c[i] = vec3(f[3 * i], f[3 * i + 1], f[3 * i + 2]);
    }
    return sh;
}

// Radiance L(d) = sum_lm c_lm Y_lm(d).
vec3 sh_evaluate(SH9 sh, vec3 d) {
    float y[9];
    sh_basis(d, y);
    vec3 result = vec3(0.0);
    for (int i = 0; i < 9; ++i) {
        result += sh.c[i] * y[i];
    }
    return result;
}

// Irradiance E(n) = sum_lm A_l c_lm Y_lm(n), the cosine-lobe convolution with A_0 = pi, A_1 = 2pi/3,
// A_2 = pi/4 (Ramamoorthi & Hanrahan 2001, "An efficient representation for irradiance environment maps").
vec3 sh_irradiance(SH9 sh, vec3 n) {
    const float lobe[9] = float[9](PI, 2.0 * PI / 3.0, 2.0 * PI / 3.0, 2.0 * PI / 3.0,
                                   PI / 4.0, PI / 4.0, PI / 4.0, PI / 4.0, PI / 4.0);
    float y[9];
    sh_basis(n, y);
    vec3 result = vec3(0.0);
    for (int i = 0; i < 9; ++i) {
        result += sh.c[i] * (lobe[i] * y[i]);
    }
    return result;
}
