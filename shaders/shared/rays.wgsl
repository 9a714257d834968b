// Rays, boxes, steps and Phong shading shared by the ray caster (shaders/raycast.wgsl),
// D²VR (shaders/d2vr.wgsl), the clipping-mesh pass (shaders/clipmesh.wgsl) and the
// multi-volume caster (shaders/multi.wgsl). Each declares a `params` uniform with the
// members camera_ray and phong read (RaycastParams, shaders/shared/raycast_params.wgsl;
// MultiParams, shaders/shared/multi_params.wgsl). Prepended at load time by
// src/gpu/raycast.rs, d2vr.rs, clipmesh.rs and multi.rs.

const MODE_DVR: u32 = 0u;
const MODE_MIP: u32 = 1u;
const MODE_MINIP: u32 = 2u;
const MODE_XRAY: u32 = 3u;
const BIG: f32 = 3.0e38;

fn normalize_or_zero(v: vec3<f32>) -> vec3<f32> {
    let l = length(v);
    if (l > 0.0) {
        return v * (1.0 / l);
    }
    return vec3<f32>(0.0);
}

// mirrors src/cpu/raycast.rs: phong (two-sided)
fn phong(c: vec3<f32>, n: vec3<f32>, l: vec3<f32>, h: vec3<f32>) -> vec3<f32> {
    let ndl = abs(dot(n, l));
    let ndh = abs(dot(n, h));
    let diffuse = params.shading.x + params.shading.y * ndl;
    var spec = 0.0;
    if (ndh > 0.0) {
        spec = params.shading.z * pow(ndh, params.shading.w);
    }
    return c * diffuse + vec3<f32>(spec);
}

// ---------------------------------------------------------------- rays
struct Ray {
    origin: vec3<f32>,
    dir: vec3<f32>,
    t_min: f32,
}

// mirrors src/camera.rs: Camera::ray (pixel centres at +0.5)
fn camera_ray(col: u32, row: u32) -> Ray {
    let u = (f32(col) + 0.5) / f32(params.image.x) - 0.5;
    let v = 0.5 - (f32(row) + 0.5) / f32(params.image.y);
    var r: Ray;
    if (params.eye.w == 1.0) {
        let h = params.forward.w;
        let aspect = params.right.w;
        r.origin = params.eye.xyz;
        r.dir = normalize(params.forward.xyz + params.right.xyz * (2.0 * u * h * aspect) + params.up.xyz * (2.0 * v * h));
        r.t_min = 0.0;
    } else {
        r.origin = params.eye.xyz + params.right.xyz * (u * params.right.w) + params.up.xyz * (v * params.up.w);
        r.dir = params.forward.xyz;
        r.t_min = -BIG;
    }
    return r;
}

struct Hit {
    ok: bool,
    t0: f32,
    t1: f32,
}

// mirrors src/cpu/raycast.rs: intersect_box
fn intersect_box(o: vec3<f32>, d: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>) -> Hit {
    var t0 = -BIG;
    var t1 = BIG;
    for (var a = 0u; a < 3u; a++) {
        if (d[a] == 0.0) {
            if (o[a] < lo[a] || o[a] > hi[a]) {
                return Hit(false, 0.0, 0.0);
            }
        } else {
            let inv = 1.0 / d[a];
            let ta = (lo[a] - o[a]) * inv;
            let tb = (hi[a] - o[a]) * inv;
            t0 = max(t0, min(ta, tb));
            t1 = min(t1, max(ta, tb));
        }
    }
    return Hit(t1 > t0, t0, t1);
}

// Step k covers [t_in + k dt, t_in + (k+1) dt]; the last one ends at t_out.
fn segment_bounds(k: u32, n: u32, t_in: f32, t_out: f32, dt: f32) -> vec2<f32> {
    let ta = t_in + f32(k) * dt;
    var tb = t_out;
    if (k + 1u != n) {
        tb = t_in + f32(k + 1u) * dt;
    }
    return vec2<f32>(ta, tb);
}
