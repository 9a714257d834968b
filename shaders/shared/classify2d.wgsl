// The 2D transfer-function lookup over (value, gradient magnitude), read with manual
// bilinear interpolation, for the ray caster. Reads the importer's
// `params: RaycastParams` and `lut2d: array<vec4<f32>>` (value fastest).
// params.tf2d_a = (value scale, value offset, nv − 1, ng − 1);
// params.tf2d_b = (gradient scale, 1/g0, log axis ? 1 : 0, enabled ? 1 : 0).

// mirrors src/transfer2d.rs: Lut2R::gradient_coordinate
fn gradient_coordinate(g: f32) -> f32 {
    var y = params.tf2d_b.x * g;
    if (params.tf2d_b.z == 1.0) {
        y = params.tf2d_b.x * log(1.0 + g * params.tf2d_b.y);
    }
    return min(max(y, 0.0), params.tf2d_a.w);
}

// mirrors src/transfer2d.rs: Lut2R::classify2d
fn classify2d(t: f32, g: f32) -> vec4<f32> {
    let x = min(max(params.tf2d_a.x * t + params.tf2d_a.y, 0.0), params.tf2d_a.z);
    let y = gradient_coordinate(g);
    let x0 = floor(x);
    let y0 = floor(y);
    let fx = x - x0;
    let fy = y - y0;
    let nv = u32(params.tf2d_a.z) + 1u;
    let ng = u32(params.tf2d_a.w) + 1u;
    let i0 = min(u32(x0), nv - 1u);
    let j0 = min(u32(y0), ng - 1u);
    let i1 = min(i0 + 1u, nv - 1u);
    let j1 = min(j0 + 1u, ng - 1u);
    let a = lut2d[j0 * nv + i0];
    let b = lut2d[j0 * nv + i1];
    let c = lut2d[j1 * nv + i0];
    let d = lut2d[j1 * nv + i1];
    let r0 = a + fx * (b - a);
    let r1 = c + fx * (d - c);
    return r0 + fy * (r1 - r0);
}
