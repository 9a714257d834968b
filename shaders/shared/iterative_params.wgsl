// The iterative methods' vector steps (shaders/iterative.wgsl): one dispatch's
// parameters. Rust twin: src/gpu/iterative.rs: SolveParams (twenty 4-byte values,
// 80 bytes, #[repr(C)] bytemuck); tests/gpu_layout.rs checks the layout with naga.

struct SolveParams {
    // Values this dispatch covers.
    n: u32,
    // Detector pixels per view (the row-indexed steps find a ray's view by it).
    per_view: u32,
    // Invocations per row of the 2-D dispatch grid.
    row_stride: u32,
    // The reduction's term (TERM_* in shaders/iterative.wgsl).
    term: u32,
    // The grid (TV's differences).
    nx: u32,
    ny: u32,
    nz: u32,
    // TV: the axes longer than one voxel, in order, and how many.
    n_axes: u32,
    axis0: u32,
    axis1: u32,
    axis2: u32,
    // 1: clamp the image at 0.
    nonnegative: u32,
    // Places in the scalar buffer this step reads or writes (SLOT_* in
    // src/gpu/iterative.rs).
    slot0: u32,
    slot1: u32,
    slot2: u32,
    _pad0: u32,
    // Step constants (λ; σ, τ, μ; the objective's weights; the tolerance).
    f0: f32,
    f1: f32,
    f2: f32,
    _pad1: u32,
}
