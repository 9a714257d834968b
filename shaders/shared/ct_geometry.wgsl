// CT geometry shared by the FBP/FDK backprojector and D²VR.
// Rust twin: src/ct.rs: ViewMatrix<f32> (#[repr(C)], four rows of four f32, 64 bytes);
// tests/gpu_layout.rs checks the layout with naga. The exact detector reads are
// shared/ct_bilinear.wgsl.

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
