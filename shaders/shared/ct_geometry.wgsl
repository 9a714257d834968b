// CT geometry shared by the FBP/FDK backprojector and D²VR.
// Rust twin: src/ct.rs: ViewMatrix<f32> (#[repr(C)], four rows of four f32, 64 bytes);
// tests/gpu_layout.rs checks the layout with naga. The detector reads go through the
// importer's `fn tap(i: u32) -> f32`, element i of its projections (a storage buffer
// of f32, or of f16 pairs in D²VR), so both shaders share one bilinear_zero.

// The projective map of one view: with P̃ = (P, 1), den = r2·P̃, col = (r0·P̃)/den,
// row = (r1·P̃)/den, and the FDK distance weight (r3.x/den)² (1 for a parallel beam).
struct CtView {
    r0: vec4<f32>,
    r1: vec4<f32>,
    r2: vec4<f32>,
    r3: vec4<f32>,
}

// Detector indices (x = col, y = row) and weight (z) of world point p; w = 0 when p
// is behind a cone-beam source (nothing projects there).
// mirrors src/ct.rs: ViewMatrix::project
fn project_point(v: CtView, p: vec3<f32>) -> vec4<f32> {
    let ph = vec4<f32>(p, 1.0);
    let den = dot(v.r2, ph);
    if den <= 0.0 {
        return vec4<f32>(0.0, 0.0, 0.0, 0.0);
    }
    let inv = 1.0 / den;
    let w = v.r3.x * inv;
    return vec4<f32>(dot(v.r0, ph) * inv, dot(v.r1, ph) * inv, w * w, 1.0);
}

// The projection value at detector pixel (i, j) of the `cols × rows` image at `base`,
// zero outside it.
fn tap_zero(base: u32, cols: u32, rows: u32, i: i32, j: i32) -> f32 {
    if (i < 0 || j < 0 || i >= i32(cols) || j >= i32(rows)) {
        return 0.0;
    }
    return tap(base + u32(j) * cols + u32(i));
}

// Bilinear interpolation with zeros outside the `cols × rows` image at `base`.
// mirrors src/ct.rs: bilinear_zero
fn bilinear_zero(base: u32, cols: u32, rows: u32, x: f32, y: f32) -> f32 {
    let fx = floor(x);
    let fy = floor(y);
    if (!(fx >= -1.0 && fx < f32(cols) && fy >= -1.0 && fy < f32(rows))) {
        return 0.0;
    }
    let tx = x - fx;
    let ty = y - fy;
    let ix = i32(fx);
    let iy = i32(fy);
    let a = tap_zero(base, cols, rows, ix, iy);
    let b = tap_zero(base, cols, rows, ix + 1, iy);
    let c = tap_zero(base, cols, rows, ix, iy + 1);
    let d = tap_zero(base, cols, rows, ix + 1, iy + 1);
    let top = a * (1.0 - tx) + b * tx;
    let bottom = c * (1.0 - tx) + d * tx;
    return top * (1.0 - ty) + bottom * ty;
}
