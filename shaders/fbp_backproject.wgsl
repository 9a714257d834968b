// Backprojection for FBP and FDK: one invocation per voxel, a loop over a chunk of views.
// Rust twin: src/gpu/fbp.rs (dispatch), src/cpu/fbp.rs (the oracle). The geometry
// (CtView, project_point, bilinear_zero) is shared/ct_geometry.wgsl.

#import ct_geometry
#import fbp_params

@group(0) @binding(0) var<uniform> params: FbpParams;
@group(0) @binding(1) var<storage, read> views: array<CtView>;
@group(0) @binding(2) var<storage, read> proj: array<f32>;
@group(0) @binding(3) var<storage, read_write> out_vol: array<f32>;

// Element i of the filtered projections, for shared/ct_geometry.wgsl: bilinear_zero.
fn tap(i: u32) -> f32 {
    return proj[i];
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
    // The slab's slices are the grid's slices slab.x …: the same voxel position, bit
    // for bit, as the unsplit volume's.
    let k = f32(idx / (nx * ny) + params.slab.x);
    let p = params.origin.xyz + i * params.step_i.xyz + j * params.step_j.xyz + k * params.step_k.xyz;
    let cols = params.det.x;
    let rows = params.det.y;
    var acc = 0.0;
    for (var v = params.det.z; v < params.det.z + params.det.w; v++) {
        let r = project_point(views[v], p);
        if r.w > 0.0 {
            acc += r.z * bilinear_zero((v - params.slab.y) * cols * rows, cols, rows, r.x, r.y);
        }
    }
    out_vol[idx] += acc * params.scale.x;
}
