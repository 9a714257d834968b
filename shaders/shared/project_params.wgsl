// Joseph forward projection: the dispatch parameters and one view's rays.
// Rust twins: src/gpu/project.rs: ProjectParams (twelve u32, 48 bytes) and
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
    // Where in the output the first view of this dispatch goes (values).
    out_offset: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
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

// One dispatch of the transpose (shaders/joseph_pair_transpose.wgsl). Rust twin:
// src/gpu/joseph_pair.rs: TransposeParams (twelve u32, 48 bytes).
struct TransposeParams {
    nx: u32,
    ny: u32,
    nz: u32,
    cols: u32,
    rows: u32,
    // The voxels of this dispatch: voxel_offset .. voxel_offset + n_voxels.
    voxel_offset: u32,
    n_voxels: u32,
    // The slots (places in the view list and in the projections) it sums: lo .. hi.
    slot_lo: u32,
    slot_hi: u32,
    // 1: add to what the output holds (a later slot range); 0: overwrite.
    accumulate: u32,
    // Invocations per row of the 2-D dispatch grid.
    row_stride: u32,
    // The voxel the output buffer starts at (a slab of the grid's, past one binding).
    out_base: u32,
}

// One view's footprint map (src/cpu/project.rs: JosephFootprint<f32>, three rows of
// four f32, 48 bytes): parallel (c, r, ·) = rows · (X, 1) with t = (0, 0, 0, 1);
// cone (t·c, t·r, t) = rows · (X, 1).
struct JosephFootprint {
    c: vec4<f32>,
    r: vec4<f32>,
    t: vec4<f32>,
}
