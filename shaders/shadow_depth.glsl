// Depth only: the scene seen from a light (a face of an emitter sample's shadow cube, or the sun).

#if defined VERTEX_SHADER

invariant gl_Position;  // the same depth in the depth pre-pass and the shading pass

in vec3 in_position;
uniform mat4 view_proj;

void main() {
    gl_Position = view_proj * vec4(in_position, 1.0);
}

#elif defined FRAGMENT_SHADER

void main() {
}

#endif
