// Resampling with a truncated reconstruction filter, one invocation per output voxel.
// Mirrors src/cpu/process.rs: resample and src/cpu/filter.rs: sample (clamp-to-edge);
// the host side is src/gpu/process.rs. Prepended: shaders/shared/process_params.wgsl.
// Filter codes (params.op.x): 0 nearest, 1 trilinear, 2 cubic B-spline (on the host's
// prefiltered coefficients for the interpolating variant), 3 Catmull–Rom, 4 Lanczos of
// order params.op.y.

const PI: f32 = 3.14159265358979;
const MAX_TAPS: u32 = 8u;

struct AxisTaps {
    first: i32,
    count: u32,
    w: array<f32, MAX_TAPS>,
}

// Mirrors src/cpu/filter.rs: sin_pi (argument reduced to [−1, 1] first).
fn sin_pi(x: f32) -> f32 {
    let r = x - 2.0 * round(x / 2.0);
    if r > 0.5 {
        return sin(PI * (1.0 - r));
    }
    if r < -0.5 {
        return -sin(PI * (1.0 + r));
    }
    return sin(PI * r);
}

// Mirrors src/cpu/filter.rs: sinc.
fn sinc(x: f32) -> f32 {
    if x == 0.0 {
        return 1.0;
    }
    return sin_pi(x) / (PI * x);
}

// Mirrors src/cpu/filter.rs: weight_bspline.
fn weight_bspline(x: f32) -> f32 {
    let a = abs(x);
    if a < 1.0 {
        return (4.0 - 6.0 * a * a + 3.0 * a * a * a) / 6.0;
    }
    if a < 2.0 {
        let t = 2.0 - a;
        return t * t * t / 6.0;
    }
    return 0.0;
}

// Mirrors src/cpu/filter.rs: weight_catmull_rom.
fn weight_catmull_rom(x: f32) -> f32 {
    let a = abs(x);
    if a < 1.0 {
        return 1.5 * a * a * a - 2.5 * a * a + 1.0;
    }
    if a < 2.0 {
        return -0.5 * a * a * a + 2.5 * a * a - 4.0 * a + 2.0;
    }
    return 0.0;
}

// Mirrors src/cpu/filter.rs: weight_lanczos.
fn weight_lanczos(x: f32, n: u32) -> f32 {
    let nr = f32(n);
    if abs(x) >= nr {
        return 0.0;
    }
    return sinc(x) * sinc(x / nr);
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

fn clamped(i: i32, n: u32) -> u32 {
    return u32(clamp(i, 0, i32(n) - 1));
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
    dst[out_index(v)] = sample_volume(p);
}
