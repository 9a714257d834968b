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
    // width of this dispatch's pixels (the image's, or a brick's rectangle's), image
    // height; first row of this dispatch, rows in it
    image: vec4<u32>,
    // pre-integration entries per axis n, spectral bins, direct block edge, blocks along x
    table: vec4<u32>,
    // blocks along y, z; importance passes: axis, max-filter radius
    extra: vec4<u32>,
    // a brick: the whole volume's voxel at its texture's texel 0; 1 when the rays carry
    // their state from brick to brick (0 and 0 when not split)
    brick: vec4<i32>,
    // the box a brick owns the steps starting in (index coordinates, the whole volume's
    // faces open: ±f32::MAX); w unused
    own_lo: vec4<f32>,
    own_hi: vec4<f32>,
}
