// The cylindrical panorama (src/projection.rs, `Panorama`): push constants mirrored on the CPU
// by `raster::PanoramaPush` (`#[repr(C)]`, size asserted at compile time) and the mapping of a
// sensor-frame point to clip space. Change all three together.

layout(push_constant) uniform PanoramaPush {
    // az0, el_top, y scale = 2 / (height * el_step), NEAR_M: `Panorama::shader_map`.
    vec4 map;
    // This draw wraps phi into [window - pi, window + pi) (src/panorama.rs).
    float window;
    // Global index of the mesh's first triangle (direct draws): id = base + gl_PrimitiveID + 1.
    uint base_triangle;
} pc;

const float PI = 3.14159265358979;
const float TAU = 6.28318530717959;

// phi = az0 - azimuth, wrapped into the window; x_ndc = phi / pi - 1 (px = phi width / 2 pi);
// y_ndc = (el_top - elevation) * scale - 1; reversed-Z z_ndc = NEAR_M / range with w = range.
vec4 panorama_clip(vec3 p) {
    float range = length(p);
    // Shift by whole turns only: a vertex inside two windows gets the same phi bit for bit,
    // so pieces drawn in different windows meet exactly.
    float phi = pc.map.x - atan(p.y, p.x);
    phi -= TAU * floor((phi - pc.window + PI) / TAU);
    float el = atan(p.z, length(p.xy));
    float x = phi / PI - 1.0;
    float y = (pc.map.y - el) * pc.map.z - 1.0;
    return vec4(x * range, y * range, pc.map.w, range);
}
