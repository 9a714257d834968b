// Parameters of one FVR slice extraction (one dispatch).
// Rust twin: src/gpu/fvr.rs: FvrParams (#[repr(C)], bytemuck). Twenty 4-byte scalars,
// no padding (80 bytes); tests/gpu_fvr.rs checks the offsets with naga.

struct FvrParams {
    // The cube side M (even); the slice is M × M.
    m: u32,
    // 0 nearest, 1 trilinear, 2 Lanczos (order `radius`), 3 Dirichlet (the exact sum).
    kernel: u32,
    // Taps per axis / 2: 1 for trilinear, a for Lanczos-a (unused for nearest).
    radius: u32,
    // The M × M planes per z-slab of the spectrum (M when it is one slab).
    slab_depth: u32,
    // The in-plane unit axes `r` and `u` of the view, index frame [x, y, z].
    right_x: f32,
    right_y: f32,
    right_z: f32,
    up_x: f32,
    up_y: f32,
    up_z: f32,
    // The sub-voxel offsets δ_r, δ_u of the phase ramp (0 for axis views).
    dr: f32,
    du: f32,
    // The volume's size in voxels and its placement offset in the cube (the Dirichlet
    // kernel sums the volume itself).
    nx: u32,
    ny: u32,
    nz: u32,
    ox: u32,
    oy: u32,
    oz: u32,
    pad0: u32,
    pad1: u32,
}
