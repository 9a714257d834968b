// Parameters of one ramp-filtering chunk (a run of whole views).
// Rust twin: src/gpu/ramp.rs: RampParams (#[repr(C)], bytemuck); layout checked in
// tests/gpu_layout.rs.
struct RampParams {
    // Detector columns, detector rows, padded length P, detector lines in this chunk.
    dims: vec4<u32>,
    // Complex lines in this chunk (two detector lines each), invocations per row of
    // workgroups (x extent of the dispatch), the weighting: none (0, parallel), the
    // circular cone beam's cosine weight (1) or per view from the table (2); the
    // chunk's first view.
    work: vec4<u32>,
    // cu, cv (pixels), du, dv (mm).
    detector: vec4<f32>,
    // SDD (mm, cone beam only), unused ×3.
    cone: vec4<f32>,
}

// One view's pre-weighting for a geometry given view by view: [r, sdd], [u, 1/spacing],
// [v, 0] (r from the source to pixel (0, 0), u and v the pixel steps, mm; sdd 0 for a
// parallel beam).
// mirrors src/gpu/ramp.rs: RampViewGpu
struct RampViewGpu {
    r: vec4<f32>,
    u: vec4<f32>,
    v: vec4<f32>,
}
