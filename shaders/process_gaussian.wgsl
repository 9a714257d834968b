// One separable pass of the Gaussian filter, one invocation per output voxel.
// Mirrors src/cpu/process.rs: gaussian; the host side is src/gpu/process.rs.

#import process_params

// The normalised weights w[t + r], t = −r … r (params.op.y = r).
@group(0) @binding(3) var<storage, read> weights: array<f32>;

// Σ_t w[t + r] f[reflect(n + t)] along params.op.z, taps in order.
// Mirrors src/cpu/process.rs: convolve_axis_at.
fn convolve_axis_at(v: vec3<u32>) -> f32 {
    let axis = params.op.z;
    let r = i32(params.op.y);
    let n = params.in_dims[axis];
    var acc = 0.0;
    var p = v;
    for (var t = 0; t <= 2 * r; t = t + 1) {
        p[axis] = reflect_index(i32(v[axis]) + t - r, n);
        acc = acc + weights[t] * in_at(p.x, p.y, p.z);
    }
    return acc;
}

@compute @workgroup_size(WORKGROUP)
fn gaussian_pass(@builtin(global_invocation_id) gid: vec3<u32>,
                 @builtin(num_workgroups) nwg: vec3<u32>) {
    var v: vec3<u32>;
    if !output_voxel(gid, nwg, &v) {
        return;
    }
    dst[out_index(v)] = convolve_axis_at(v);
}
