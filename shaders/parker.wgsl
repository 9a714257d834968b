// Parker's short-scan weights applied to a chunk of projection views in place.
// mirrors src/cpu/parker.rs: weigh

#import parker_params

@group(0) @binding(0) var<uniform> params: ParkerParams;
// β of every view of the scan: gantry angle from the first view, radians.
@group(0) @binding(1) var<storage, read> betas: array<f32>;
// The chunk's views, (view, row, col) with the column fastest.
@group(0) @binding(2) var<storage, read_write> data: array<f32>;
// γ of every detector column, radians.
@group(0) @binding(3) var<storage, read> gammas: array<f32>;

const PI: f32 = 3.14159265358979;

// sin x for x in [0, π/2] by its Taylor polynomial to x¹¹ (truncation below 6e-8):
// WGSL lets a built-in sin be off by 2⁻¹¹ absolute, far more than the weights allow.
fn sin_quadrant(x: f32) -> f32 {
    let x2 = x * x;
    return x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0
        + x2 * (1.0 / 362880.0 + x2 * (-1.0 / 39916800.0))))));
}

// mirrors src/cpu/parker.rs: parker_weight
fn parker_weight(beta: f32, gamma: f32, delta: f32) -> f32 {
    let quarter = PI / 4.0;
    if (beta < 0.0 || beta > PI + 2.0 * delta) {
        return 0.0;
    }
    if (beta < 2.0 * delta - 2.0 * gamma) {
        let s = sin_quadrant(clamp(quarter * beta / (delta - gamma), 0.0, quarter * 2.0));
        return s * s;
    }
    if (beta <= PI - 2.0 * gamma) {
        return 1.0;
    }
    let s = sin_quadrant(clamp(quarter * (PI + 2.0 * delta - beta) / (delta + gamma), 0.0, quarter * 2.0));
    return s * s;
}

@compute @workgroup_size(64)
fn parker_weigh(@builtin(global_invocation_id) gid: vec3<u32>) {
    let idx = gid.x + gid.y * params.work.x;
    let cols = params.dims.x;
    let per_view = cols * params.dims.y;
    if (idx >= per_view * params.dims.z) {
        return;
    }
    let view = params.dims.w + idx / per_view;
    let col = idx % cols;
    let beta = betas[view];
    let w = params.scan.x * parker_weight(beta, gammas[col], params.detector.w);
    data[idx] = data[idx] * w;
}
