// Parameters of the adaptive ray caster and its set-up passes (pre-integration, the
// importance volume). Rust twin: src/gpu/adaptive.rs: AdaptiveParams (#[repr(C)],
// bytemuck); tests/gpu_layout.rs checks the offsets with naga.

struct AdaptiveParams {
    // step (T_min, voxels), T_max (voxels), 2 · oversampling, early-termination opacity
    steps: vec4<f32>,
    // window map a, b; pre-integration table: raw value → coordinate scale, offset
    window: vec4<f32>,
    // spectral table: domain start d0, bins / (d1 − d0), bins, 0
    spectrum: vec4<f32>,
    // RGBA behind the volume
    background: vec4<f32>,
    // grid nx, ny, nz; sampling: 0 regular, 1 adaptive, 2 direct
    dims: vec4<u32>,
    // image width, height; first row of this dispatch, rows in it
    image: vec4<u32>,
    // pre-integration entries per axis n, spectral bins, direct block edge, blocks along x
    table: vec4<u32>,
    // blocks along y, z; importance passes: axis, max-filter radius
    extra: vec4<u32>,
}
