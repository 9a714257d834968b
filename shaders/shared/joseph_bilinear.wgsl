// The exact read of Joseph's projector: bilinear interpolation, continued by zeros, of
// one index plane of the grid, in the shader's own arithmetic. Reads the importer's
// `vol: array<f32>` ([z][y][x]); the texture variant of src/gpu/project.rs:
// volume_wgsl needs none of it.

// Bilinear interpolation, continued by zeros, of the index plane starting at `base`.
// mirrors src/cpu/project.rs: slice_bilinear
fn slice_bilinear(base: u32, sa: u32, na: u32, sb: u32, nb: u32, x: f32, y: f32) -> f32 {
    let fx = floor(x);
    let fy = floor(y);
    if !(fx >= -1.0 && fx < f32(na) && fy >= -1.0 && fy < f32(nb)) {
        return 0.0;
    }
    let tx = x - fx;
    let ty = y - fy;
    let ix = i32(fx);
    let iy = i32(fy);
    var tap: array<f32, 4>;
    for (var q = 0; q < 4; q++) {
        let i = ix + (q & 1);
        let j = iy + (q >> 1u);
        if i < 0 || j < 0 || i >= i32(na) || j >= i32(nb) {
            tap[q] = 0.0;
        } else {
            tap[q] = vol[base + u32(i) * sa + u32(j) * sb];
        }
    }
    let top = tap[0] * (1.0 - tx) + tap[1] * tx;
    let bottom = tap[2] * (1.0 - tx) + tap[3] * tx;
    return top * (1.0 - ty) + bottom * ty;
}
