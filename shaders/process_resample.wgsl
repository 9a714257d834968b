// Resampling with a truncated reconstruction filter, one invocation per output voxel.
// Mirrors src/cpu/process.rs: resample; mirrors src/cpu/filter.rs: sample
// (clamp-to-edge); the host side is src/gpu/process.rs. The kernels are
// shared/filters.wgsl's. Filter codes (params.op.x): 0 nearest, 1 trilinear, 2 cubic
// B-spline (on the host's prefiltered coefficients for the interpolating variant),
// 3 Catmull–Rom, 4 Lanczos of order params.op.y.

#import process_params
#import filters

const MAX_TAPS: u32 = 8u;

struct AxisTaps {
    first: i32,
    count: u32,
    w: array<f32, MAX_TAPS>,
}

// Taps along one axis at index coordinate x. Mirrors src/cpu/filter.rs: axis_taps.
fn axis_taps(x: f32) -> AxisTaps {
    var t: AxisTaps;
    let code = params.op.x;
    let fl = floor(x);
    let f = x - fl;
    let i0 = i32(fl);
    if code == 0u {
        t.first = i32(floor(x + 0.5));
        t.count = 1u;
        t.w[0] = 1.0;
    } else if code == 1u {
        t.first = i0;
        t.count = 2u;
        t.w[0] = 1.0 - f;
        t.w[1] = f;
    } else if code == 2u {
        t.first = i0 - 1;
        t.count = 4u;
        t.w[0] = weight_bspline(f + 1.0);
        t.w[1] = weight_bspline(f);
        t.w[2] = weight_bspline(1.0 - f);
        t.w[3] = weight_bspline(2.0 - f);
    } else if code == 3u {
        t.first = i0 - 1;
        t.count = 4u;
        t.w[0] = weight_catmull_rom(f + 1.0);
        t.w[1] = weight_catmull_rom(f);
        t.w[2] = weight_catmull_rom(1.0 - f);
        t.w[3] = weight_catmull_rom(2.0 - f);
    } else {
        let n = params.op.y;
        t.first = i0 - i32(n) + 1;
        t.count = 2u * n;
        var sum = 0.0;
        for (var m = 0u; m < 2u * n; m = m + 1u) {
            t.w[m] = weight_lanczos(f + f32(n) - 1.0 - f32(m), n);
            sum = sum + t.w[m];
        }
        for (var m = 0u; m < 2u * n; m = m + 1u) {
            t.w[m] = t.w[m] / sum;
        }
    }
    return t;
}

// Σ_k w_z[k] Σ_j w_y[j] Σ_i w_x[i] f[i, j, k], clamped indices, x innermost.
// Mirrors src/cpu/filter.rs: sample / apply_taps.
fn sample_volume(p: vec3<f32>) -> f32 {
    let tx = axis_taps(p.x);
    let ty = axis_taps(p.y);
    let tz = axis_taps(p.z);
    let n = params.in_dims;
    var acc_z = 0.0;
    for (var b = 0u; b < tz.count; b = b + 1u) {
        let k = clamped(tz.first + i32(b), n.z);
        var acc_y = 0.0;
        for (var a = 0u; a < ty.count; a = a + 1u) {
            let j = clamped(ty.first + i32(a), n.y);
            var acc_x = 0.0;
            for (var i = 0u; i < tx.count; i = i + 1u) {
                acc_x = acc_x + tx.w[i] * in_at(clamped(tx.first + i32(i), n.x), j, k);
            }
            acc_y = acc_y + ty.w[a] * acc_x;
        }
        acc_z = acc_z + tz.w[b] * acc_y;
    }
    return acc_z;
}

@compute @workgroup_size(WORKGROUP)
fn resample(@builtin(global_invocation_id) gid: vec3<u32>,
            @builtin(num_workgroups) nwg: vec3<u32>) {
    var v: vec3<u32>;
    if !output_voxel(gid, nwg, &v) {
        return;
    }
    let q = vec4<f32>(vec3<f32>(v), 1.0);
    let p = vec3<f32>(dot(params.m0, q), dot(params.m1, q), dot(params.m2, q));
    // dst holds the output voxels from params.op.z on (a slab of the output).
    dst[out_index(v) - params.op.z] = sample_volume(p);
}
