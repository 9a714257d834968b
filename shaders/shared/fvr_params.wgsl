// Parameters of one FVR slice extraction (one dispatch).
// Rust twin: src/gpu/fvr.rs: FvrParams (#[repr(C)], bytemuck). Twelve 4-byte scalars,
// no padding (48 bytes); tests/gpu_fvr.rs checks the offsets with naga.

struct FvrParams {
    // The cube side M (even); the slice is M × M.
    m: u32,
    // 0 nearest, 1 trilinear, 2 Lanczos (order `radius`).
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
}
