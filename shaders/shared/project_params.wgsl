// Joseph forward projection: the dispatch parameters and one view's rays.
// Rust twins: src/gpu/project.rs: ProjectParams (eight u32, 32 bytes) and
// src/cpu/project.rs: JosephView<f32> (nine rows of four f32, 144 bytes), both
// #[repr(C)] bytemuck; tests/gpu_layout.rs checks the layouts with naga.

struct ProjectParams {
    // Grid size in voxels (x fastest).
    nx: u32,
    ny: u32,
    nz: u32,
    // Detector size.
    cols: u32,
    rows: u32,
    // The first view of this dispatch and how many views it covers.
    view_offset: u32,
    n_views: u32,
    // Invocations per row of the 2-D dispatch grid (workgroups along x × 64).
    row_stride: u32,
}

// One view's rays in the grid's index frame, affine in the detector indices (c, r):
// start a0 + c·a_u + r·a_v, index direction d0 + c·d_u + r·d_v, world direction
// w0 + c·w_u + r·w_v; a0.w is the smallest ray parameter (0 cone, −1e30 parallel).
struct JosephView {
    a0: vec4<f32>,
    a_u: vec4<f32>,
    a_v: vec4<f32>,
    d0: vec4<f32>,
    d_u: vec4<f32>,
    d_v: vec4<f32>,
    w0: vec4<f32>,
    w_u: vec4<f32>,
    w_v: vec4<f32>,
}
