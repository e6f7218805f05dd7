#version 450
// Raster stage: sensor-frame vertex -> face clip space; passes the sensor-frame position on
// so the fragment stage can compute the Euclidean range (perspective-correct interpolation).
#include "common.glsl"

layout(location = 0) in vec3 in_pos_sensor;
layout(location = 0) out vec3 out_pos_sensor;

void main() {
    out_pos_sensor = in_pos_sensor;
    gl_Position = pc.clip_from_sensor * vec4(in_pos_sensor, 1.0);
}
