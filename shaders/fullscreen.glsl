// One triangle that covers the screen, (-1,-1), (3,-1), (-1,3), from gl_VertexID alone (a vertex array
// without buffers, drawn with 3 vertices): the vertex shader of the full-screen passes, at `depth` in
// normalized device coordinates.

vec4 fullscreen_corner(float depth) {
    vec2 corner = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    return vec4(corner, depth, 1.0);
}
