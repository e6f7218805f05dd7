#version 450
// Panorama, direct draws: sensor-frame vertex from the shared vertex buffer -> panorama clip
// space; the sensor-frame position goes on for the range.
#include "panorama.glsl"

layout(location = 0) in vec3 in_pos_sensor;
layout(location = 0) out vec3 out_pos_sensor;

void main() {
    out_pos_sensor = in_pos_sensor;
    gl_Position = panorama_clip(in_pos_sensor);
}
