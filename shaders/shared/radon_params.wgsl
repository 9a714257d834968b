// Parameters of scikit-image's Radon transform and its inverse on the GPU.
// Rust twin: src/gpu/radon.rs: RadonParams (#[repr(C)], bytemuck); layout checked in
// tests/gpu_layout.rs.
struct RadonParams {
    // radon: square side n, angles, unused ×2; iradon: detector bins n, angles, output
    // side, interpolation (0 linear, 1 nearest, 2 cubic).
    dims: vec4<u32>,
    // x extent of the dispatch in invocations, circle mask (iradon), unused ×2.
    work: vec4<u32>,
    // iradon: π and 2A rounded to f32 (the scale rec·π/(2A)), unused ×2.
    scale: vec4<f32>,
}
