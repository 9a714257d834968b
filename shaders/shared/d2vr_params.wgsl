// Parameters of one D²VR chunk dispatch (besides the ray caster's RaycastParams).
// Rust twin: src/gpu/d2vr.rs: D2vrParams (#[repr(C)], bytemuck). Every member is a
// 16-byte vector; tests/gpu_layout.rs-style naga check in tests/gpu_d2vr.rs.

struct D2vrParams {
    // Rows of the virtual grid's index-to-world affine (3×4), CT frame, mm.
    to_world_0: vec4<f32>,
    to_world_1: vec4<f32>,
    to_world_2: vec4<f32>,
    // Rows of Jᵀ (J the affine's linear part): world gradient → index gradient.
    jt_0: vec4<f32>,
    jt_1: vec4<f32>,
    jt_2: vec4<f32>,
    // Effective cylinder: radius², y_lo, y_hi; w = the backprojection scale π/(2A).
    cylinder: vec4<f32>,
    // Detector columns, rows, number of views, storage (0 f32, 1 f16 pairs).
    det: vec4<u32>,
    // Gradient (0 GFS, 1 GFR), cylinder on, occupancy on; w = values per projection
    // binding (whole views; with one binding, every value).
    flags: vec4<u32>,
    // Samples [x, y) of every ray in this dispatch; the band's first row z and its
    // rows w.
    chunk: vec4<u32>,
}
