// Parameters of one backprojection dispatch.
// Rust twin: src/gpu/fbp.rs: FbpParams (#[repr(C)], bytemuck); tests/gpu_layout.rs
// checks the offsets with naga.

// Grid: voxel (i, j, k) sits at origin + i·step_i + j·step_j + k·step_k (CT world mm).
struct FbpParams {
    origin: vec4<f32>,
    step_i: vec4<f32>,
    step_j: vec4<f32>,
    step_k: vec4<f32>,
    // nx, ny, the slices of this slab, invocations per row of workgroups (x extent)
    dims: vec4<u32>,
    // detector cols, rows, first view, number of views in this dispatch
    det: vec4<u32>,
    // x: the backprojection constant π/(2A)
    scale: vec4<f32>,
    // x: the grid slice k of this slab's first slice (z-slabs of a split volume);
    // y: the first view the projection buffer holds (batches of views)
    slab: vec4<u32>,
}
