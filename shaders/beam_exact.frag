#version 450
// The beam of this texel against this triangle, in f32 and conservatively: a beam is dropped
// only when it is certainly outside the triangle (strictly outside one edge plane through the
// origin and strictly inside another, as the ray caster's pre-test, with twice its tolerance),
// certainly facing a culled back side, or certainly behind the sensor. Every beam the exact
// f64 test hits therefore survives; the depth test keeps the nearest survivor, whose id the
// CPU re-tests exactly (src/backend/raster/beam_exact.rs).
#include "beam_exact.glsl"

layout(std430, set = 0, binding = 0) readonly buffer Directions {
    // Per beam, row-major: the f32 unit direction (w unused).
    vec4 dirs[];
};

layout(location = 0) flat in vec3 in_n0;
layout(location = 1) flat in vec3 in_n1;
layout(location = 2) flat in vec3 in_n2;
layout(location = 3) flat in vec4 in_plane;
layout(location = 4) flat in uvec2 in_id_flags;
// Per edge plane: 2e-6 |n|_1 + 1e-30 (twice the caster's tolerance).
layout(location = 5) flat in vec3 in_tol;

layout(location = 0) out uint out_id;

void main() {
    uint col = uint(gl_FragCoord.x);
    uint row = uint(gl_FragCoord.y);
    vec3 d = dirs[row * pc.columns + col].xyz;
    vec3 e = vec3(dot(in_n0, d), dot(in_n1, d), dot(in_n2, d));
    bool outside = any(lessThan(e, -in_tol));
    bool inside = any(greaterThan(e, in_tol));
    if (outside && inside) {
        discard;
    }
    // Unit normal (b - a) x (c - a) and its offset dot(n, a): the beam meets the plane at
    // t = w / dot(n, d). A front face is seen with dot(n, d) < 0.
    float dn = dot(in_plane.xyz, d);
    bool culled = (in_id_flags.y & 1u) != 0u;
    if (culled && dn > 1e-5) {
        discard;
    }
    float t = in_plane.w / dn;
    if (abs(dn) > 1e-5) {
        if (!(t > 0.0)) {
            discard;
        }
    } else {
        // Nearly edge-on: keep it, behind every surface seen face-on.
        t = 1e30;
    }
    // Reversed depth, nearer = greater, exact ordering for t > 0.
    gl_FragDepth = 1.0 / (1.0 + t);
    out_id = in_id_flags.x;
}
