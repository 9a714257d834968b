// The smallest end-to-end check that a device computes: y[i] = a * x[i] + b.
// CPU twin: src/gpu/probe.rs: saxpy_cpu. Parameters: src/gpu/probe.rs: ProbeParams.

struct Params {
    a: f32,
    b: f32,
    n: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> x: array<f32>;
@group(0) @binding(2) var<storage, read_write> y: array<f32>;

@compute @workgroup_size(64)
fn saxpy(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if (i < params.n) {
        y[i] = params.a * x[i] + params.b;
    }
}
