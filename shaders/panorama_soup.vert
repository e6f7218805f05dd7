#version 450
// Panorama, CPU-prepared triangle list (src/panorama.rs): each vertex carries the global index
// of the triangle it came from (split pieces keep their original's).
#include "panorama.glsl"

layout(location = 0) in vec3 in_pos_sensor;
layout(location = 1) in uint in_triangle;
layout(location = 0) out vec3 out_pos_sensor;
layout(location = 1) flat out uint out_triangle;

void main() {
    out_pos_sensor = in_pos_sensor;
    out_triangle = in_triangle;
    gl_Position = panorama_clip(in_pos_sensor);
}
