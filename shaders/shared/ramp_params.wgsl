// Parameters of one ramp-filtering chunk (a run of whole views).
// Rust twin: src/gpu/ramp.rs: RampParams (#[repr(C)], bytemuck); layout checked in
// tests/gpu_layout.rs.
struct RampParams {
    // Detector columns, detector rows, padded length P, detector lines in this chunk.
    dims: vec4<u32>,
    // Complex lines in this chunk (two detector lines each), invocations per row of
    // workgroups (x extent of the dispatch), cone beam (1) or parallel (0), unused.
    work: vec4<u32>,
    // cu, cv (pixels), du, dv (mm).
    detector: vec4<f32>,
    // SDD (mm, cone beam only), unused ×3.
    cone: vec4<f32>,
}
