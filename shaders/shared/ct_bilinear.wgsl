// The exact detector read shared by the FBP/FDK backprojector and D²VR: bilinear
// interpolation with zeros outside the detector, in the shader's own arithmetic. The
// reads go through the importer's `fn tap(i: u32) -> f32`, element i of its
// projections (a storage buffer of f32, or of f16 pairs in D²VR), so both shaders
// share one bilinear_zero. The cell and the weights are shared/bilinear_cell.wgsl's,
// which D²VR's texture path uses on gathered taps.

#import bilinear_cell

// The projection value at detector pixel (i, j) of the `cols × rows` image at `base`,
// zero outside it.
fn tap_zero(base: u32, cols: u32, rows: u32, i: i32, j: i32) -> f32 {
    if (i < 0 || j < 0 || i >= i32(cols) || j >= i32(rows)) {
        return 0.0;
    }
    return tap(base + u32(j) * cols + u32(i));
}

// The four taps of the cell whose first tap is `corner`: (i, j), (i+1, j), (i, j+1),
// (i+1, j+1), zero outside the image.
fn taps_zero(base: u32, cols: u32, rows: u32, corner: vec2<i32>) -> vec4<f32> {
    let i = corner.x;
    let j = corner.y;
    return vec4<f32>(
        tap_zero(base, cols, rows, i, j),
        tap_zero(base, cols, rows, i + 1, j),
        tap_zero(base, cols, rows, i, j + 1),
        tap_zero(base, cols, rows, i + 1, j + 1),
    );
}

// Bilinear interpolation with zeros outside the `cols × rows` image at `base`.
// mirrors src/ct.rs: bilinear_zero
fn bilinear_zero(base: u32, cols: u32, rows: u32, x: f32, y: f32) -> f32 {
    let c = bilinear_cell(cols, rows, x, y);
    if (!c.inside) {
        return 0.0;
    }
    return bilinear_mix(taps_zero(base, cols, rows, c.corner), c.t);
}

// (q, ∂q/∂x, ∂q/∂y) of the same interpolation.
// mirrors src/cpu/d2vr.rs: bilinear_zero_grad
fn bilinear_zero_grad(base: u32, cols: u32, rows: u32, x: f32, y: f32) -> vec3<f32> {
    let c = bilinear_cell(cols, rows, x, y);
    if (!c.inside) {
        return vec3<f32>(0.0);
    }
    return bilinear_mix_grad(taps_zero(base, cols, rows, c.corner), c.t);
}
