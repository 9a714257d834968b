// Rays and boxes: the one ray–box slab test, the step bounds of a march, and the ray
// struct and constants every caster shares (shaders/raycast.wgsl, d2vr.wgsl,
// clipmesh.wgsl, multi.wgsl, adaptive.wgsl, shared/skip.wgsl). Reads no bindings:
// camera rays are in shared/camera.wgsl, Phong shading in shared/shading.wgsl.

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

// ---------------------------------------------------------------- rays
struct Ray {
    origin: vec3<f32>,
    dir: vec3<f32>,
    t_min: f32,
}

struct Hit {
    ok: bool,
    t0: f32,
    t1: f32,
}

// mirrors src/real.rs: intersect_box
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
