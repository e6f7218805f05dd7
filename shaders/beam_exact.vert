#version 450
// One instance = one triangle's bound (columns c0..=c1, rows r0..r1 - 1, already wrapped into
// the grid): a quad whose edges lie on texel edges, so it covers exactly the bound's texel
// centres. The triangle's edge planes, its plane and its id go on flat to the fragments.
#include "beam_exact.glsl"

layout(location = 0) in vec3 in_n0;
layout(location = 1) in vec3 in_n1;
layout(location = 2) in vec3 in_n2;
layout(location = 3) in vec4 in_plane;
layout(location = 4) in uvec2 in_rect;
layout(location = 5) in uvec2 in_id_flags;
layout(location = 6) in vec3 in_tol;

layout(location = 0) flat out vec3 out_n0;
layout(location = 1) flat out vec3 out_n1;
layout(location = 2) flat out vec3 out_n2;
layout(location = 3) flat out vec4 out_plane;
layout(location = 4) flat out uvec2 out_id_flags;
layout(location = 5) flat out vec3 out_tol;

void main() {
    // Corners of two triangles: (0,0) (1,0) (0,1) | (0,1) (1,0) (1,1).
    int k = gl_VertexIndex;
    bool right = k == 1 || k == 4 || k == 5;
    bool bottom = k == 2 || k == 3 || k == 5;
    float x = float(right ? (in_rect.x >> 16) + 1u : in_rect.x & 0xffffu);
    float y = float(bottom ? (in_rect.y >> 16) + 1u : in_rect.y & 0xffffu);
    gl_Position = vec4(x * pc.ndc_per_texel.x - 1.0, y * pc.ndc_per_texel.y - 1.0, 0.5, 1.0);
    out_n0 = in_n0;
    out_n1 = in_n1;
    out_n2 = in_n2;
    out_plane = in_plane;
    out_id_flags = in_id_flags;
    out_tol = in_tol;
}
