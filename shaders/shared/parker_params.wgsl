// Parameters of one Parker-weighting dispatch (a run of whole views).
// Rust twin: src/gpu/parker.rs: ParkerParams (#[repr(C)], bytemuck); layout checked in
// tests/gpu_layout.rs.
struct ParkerParams {
    // Detector columns, detector rows, views in this chunk, first view of the chunk.
    dims: vec4<u32>,
    // Unused ×3, δ (radians).
    detector: vec4<f32>,
    // Scale A·Δβ/π, unused ×3.
    scan: vec4<f32>,
    // x extent of the dispatch in invocations, unused ×3.
    work: vec4<u32>,
}
