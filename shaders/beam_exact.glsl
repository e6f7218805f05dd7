// The exact beam raster (src/backend/raster/beam_exact.rs): one texel per beam (column x row
// of the sensor grid), each triangle drawn as its conservative beam-grid bound and tested
// exactly per beam in the fragment shader. Push constants mirrored on the CPU by
// `beam_exact::BeamPush` (`#[repr(C)]`, size asserted at compile time); the per-instance
// layout by `beam_exact::Instance`. Change them together.

layout(push_constant) uniform BeamPush {
    // 2 / columns, 2 / rows: texel units -> NDC.
    vec2 ndc_per_texel;
    // Columns of the grid (row stride of the direction table).
    uint columns;
    uint _pad;
} pc;
