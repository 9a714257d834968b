// Backprojection for FBP and FDK: one invocation per voxel, a loop over a chunk of views.
// Rust twin: src/gpu/fbp.rs (dispatch), src/cpu/fbp.rs (the oracle). Compiled with
// shaders/shared/ct_geometry.wgsl (CtView, project_point) prepended.

// FbpParams is declared in shaders/shared/fbp_params.wgsl (prepended at load time).

@group(0) @binding(0) var<uniform> params: FbpParams;
@group(0) @binding(1) var<storage, read> views: array<CtView>;
@group(0) @binding(2) var<storage, read> proj: array<f32>;
@group(0) @binding(3) var<storage, read_write> out_vol: array<f32>;

fn tap(base: u32, cols: i32, rows: i32, i: i32, j: i32) -> f32 {
    if i < 0 || j < 0 || i >= cols || j >= rows {
        return 0.0;
    }
    return proj[base + u32(j * cols + i)];
}

// Bilinear interpolation with zeros outside the `cols × rows` image at `base`.
// mirrors src/ct.rs: bilinear_zero
fn bilinear_zero(base: u32, cols: u32, rows: u32, x: f32, y: f32) -> f32 {
    let fx = floor(x);
    let fy = floor(y);
    if !(fx >= -1.0 && fx < f32(cols) && fy >= -1.0 && fy < f32(rows)) {
        return 0.0;
    }
    let tx = x - fx;
    let ty = y - fy;
    let ix = i32(fx);
    let iy = i32(fy);
    let c = i32(cols);
    let r = i32(rows);
    let top = tap(base, c, r, ix, iy) * (1.0 - tx) + tap(base, c, r, ix + 1, iy) * tx;
    let bottom = tap(base, c, r, ix, iy + 1) * (1.0 - tx) + tap(base, c, r, ix + 1, iy + 1) * tx;
    return top * (1.0 - ty) + bottom * ty;
}

// Adds this chunk's share of π/(2A)·Σ_k w_k·bilinear_zero(q_k, col_k, row_k).
// mirrors src/cpu/fbp.rs: backproject_point
@compute @workgroup_size(64)
fn backproject_point(@builtin(global_invocation_id) gid: vec3<u32>) {
    let idx = gid.x + gid.y * params.dims.w;
    let nx = params.dims.x;
    let ny = params.dims.y;
    if idx >= nx * ny * params.dims.z {
        return;
    }
    let i = f32(idx % nx);
    let j = f32((idx / nx) % ny);
    let k = f32(idx / (nx * ny));
    let p = params.origin.xyz + i * params.step_i.xyz + j * params.step_j.xyz + k * params.step_k.xyz;
    let cols = params.det.x;
    let rows = params.det.y;
    var acc = 0.0;
    for (var v = params.det.z; v < params.det.z + params.det.w; v++) {
        let r = project_point(views[v], p);
        if r.w > 0.0 {
            acc += r.z * bilinear_zero(v * cols * rows, cols, rows, r.x, r.y);
        }
    }
    out_vol[idx] += acc * params.scale.x;
}
