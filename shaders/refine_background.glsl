// The background of one more image of a refining display target (viewer/gpu/targets.py RefiningTarget):
// a full-screen triangle at the far plane, drawn after the surfaces with the depth test "<=", so it
// shades only the pixels no surface covered in this image and mixes the clear colour (black) into their
// running mean, as surface.glsl's ACCUMULATE mixes a surface's display value into it.

#if defined VERTEX_SHADER

void main() {
    // One triangle that covers the screen at the far plane: (-1,-1), (3,-1), (-1,3).
    vec2 corner = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    gl_Position = vec4(corner, 1.0, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform sampler2D accumulated;
uniform float accumulate_weight;

out vec4 frag_color;

void main() {
    vec3 mean = texelFetch(accumulated, ivec2(gl_FragCoord.xy), 0).rgb * (1.0 - accumulate_weight);
    frag_color = vec4(mean, 1.0);
}

#endif
