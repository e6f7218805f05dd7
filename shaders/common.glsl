// Layouts shared by the raster shaders and mirrored on the CPU by `raster::PushConstants`
// (src/raster.rs, `#[repr(C)]`, size asserted at compile time). Change both together.

// One block for both stages: 64 bytes matrix + 4 bytes base triangle (+ 12 bytes CPU padding).
layout(push_constant) uniform PushConstants {
    // Column-major, sensor frame -> clip (reversed-Z, infinite far): projection.rs.
    mat4 clip_from_sensor;
    // Global index of the mesh's first triangle: id = base_triangle + gl_PrimitiveID + 1.
    uint base_triangle;
} pc;
