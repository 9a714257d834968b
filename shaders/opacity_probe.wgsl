// Evaluates shaders/shared/opacity.wgsl on many inputs, so tests can hold ln_1p, exp_m1
// and step_opacity against f64. Host side: src/gpu/probe.rs: opacity_gpu. Each input
// is (x for ln_1p, x for exp_m1, a, r); each output is
// (ln_1p(x), exp_m1(x), step_opacity(a, r), 0).

#import opacity

@group(0) @binding(0) var<storage, read> inputs: array<vec4<f32>>;
@group(0) @binding(1) var<storage, read_write> outputs: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if (i < arrayLength(&inputs)) {
        let v = inputs[i];
        outputs[i] = vec4<f32>(ln_1p(v.x), exp_m1(v.y), step_opacity(v.z, v.w), 0.0);
    }
}
