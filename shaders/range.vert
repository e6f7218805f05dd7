#version 450
// Placeholder to prove the toolchain; replaced by the renderer.
layout(location = 0) in vec3 in_pos;
void main() { gl_Position = vec4(in_pos, 1.0); }
