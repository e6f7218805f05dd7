#version 450
// Panorama, direct draws: Euclidean range and global triangle id + 1, as range.frag.
#include "panorama.glsl"

layout(location = 0) in vec3 in_pos_sensor;
layout(location = 0) out float out_range_m;
layout(location = 1) out uint out_id;

void main() {
    out_range_m = length(in_pos_sensor);
    out_id = pc.base_triangle + uint(gl_PrimitiveID) + 1u;
}
