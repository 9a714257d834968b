// The arithmetic of bilinear interpolation with zeros outside a `cols × rows` image,
// apart from where its four taps come from: shared/ct_bilinear.wgsl reads them from
// the importer's storage (its `tap`), D²VR's texture path gathers them from a bordered
// texture (src/gpu/d2vr.rs: projections_wgsl). Reads no binding.

// The cell of detector point (x, y): its first tap (the floor) and the fractions.
// `inside` is false far outside the image (or for NaN), where every tap is zero; the
// other members are then unset.
struct BilinearCell {
    corner: vec2<i32>,
    t: vec2<f32>,
    inside: bool,
}

// mirrors src/ct.rs: bilinear_taps (the cell; the importer reads the taps)
fn bilinear_cell(cols: u32, rows: u32, x: f32, y: f32) -> BilinearCell {
    let fx = floor(x);
    let fy = floor(y);
    var c: BilinearCell;
    c.inside = fx >= -1.0 && fx < f32(cols) && fy >= -1.0 && fy < f32(rows);
    if (c.inside) {
        c.corner = vec2<i32>(i32(fx), i32(fy));
        c.t = vec2<f32>(x - fx, y - fy);
    }
    return c;
}

// The bilinear value of the taps q = (a, b, c, d) at (i, j), (i+1, j), (i, j+1),
// (i+1, j+1), at fractions t.
// mirrors src/ct.rs: bilinear_zero (after the taps)
fn bilinear_mix(q: vec4<f32>, t: vec2<f32>) -> f32 {
    let top = q.x * (1.0 - t.x) + q.y * t.x;
    let bottom = q.z * (1.0 - t.x) + q.w * t.x;
    return top * (1.0 - t.y) + bottom * t.y;
}

// (value, ∂/∂x, ∂/∂y) of the same bilinear patch.
// mirrors src/cpu/d2vr.rs: bilinear_zero_grad (after the taps)
fn bilinear_mix_grad(q: vec4<f32>, t: vec2<f32>) -> vec3<f32> {
    let top = q.x * (1.0 - t.x) + q.y * t.x;
    let bottom = q.z * (1.0 - t.x) + q.w * t.x;
    return vec3<f32>(top * (1.0 - t.y) + bottom * t.y, (q.y - q.x) * (1.0 - t.y) + (q.w - q.z) * t.y, bottom - top);
}
