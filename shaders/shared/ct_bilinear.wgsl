// The exact detector read shared by the FBP/FDK backprojector and D²VR: bilinear
// interpolation with zeros outside the detector, in the shader's own arithmetic. The
// reads go through the importer's `fn tap(i: u32) -> f32`, element i of its
// projections (a storage buffer of f32, or of f16 pairs in D²VR), so both shaders
// share one bilinear_zero.

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
