// The transfer-function lookup shared by the ray caster, its set-up passes and D²VR.
// Reads the importer's `params: RaycastParams` and `lut: array<vec4<f32>>`.

// mirrors src/transfer.rs: LutR::classify
fn classify(t: f32) -> vec4<f32> {
    let last = params.lut.z;
    let x = min(max(params.lut.x * t + params.lut.y, 0.0), last);
    let i0f = floor(x);
    let f = x - i0f;
    let n = u32(last) + 1u;
    let i0 = min(u32(i0f), n - 1u);
    let i1 = min(i0 + 1u, n - 1u);
    let a = lut[i0];
    let b = lut[i1];
    return a + f * (b - a);
}
