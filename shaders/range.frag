#version 450
// Raster stage: per fragment, the Euclidean range of the interpolated sensor-frame position
// (metres, not depth) and the global triangle id + 1 (0 is left for "no hit" by the clear).
#include "common.glsl"

layout(location = 0) in vec3 in_pos_sensor;
layout(location = 0) out float out_range_m;
layout(location = 1) out uint out_id;

void main() {
    out_range_m = length(in_pos_sensor);
    out_id = pc.base_triangle + uint(gl_PrimitiveID) + 1u;
}
