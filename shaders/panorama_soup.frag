#version 450
// Panorama, CPU-prepared triangle list: range and the carried global triangle id + 1.

layout(location = 0) in vec3 in_pos_sensor;
layout(location = 1) flat in uint in_triangle;
layout(location = 0) out float out_range_m;
layout(location = 1) out uint out_id;

void main() {
    out_range_m = length(in_pos_sensor);
    out_id = in_triangle + 1u;
}
