// The GPU multi-volume ray caster: one invocation per pixel, up to three volumes.
//
// The twin of src/cpu/multi.rs (cast_multi, combine_sample, shade_layer), with
// src/transfer.rs (LutR::classify), src/cpu/filter.rs (sample: nearest and trilinear
// through apply_taps), src/cpu/gradient.rs (gradient_stencil: central, forward) and
// src/cpu/raycast.rs (shade_gradient). Each helper names its Rust twin. Shared with
// the ray caster: camera_ray (shared/camera.wgsl), intersect_box and normalize_or_zero
// (shared/rays.wgsl), phong and light_half (shared/shading.wgsl), clamp_index (shared/filters.wgsl),
// ln_1p and exp_m1 (shared/opacity.wgsl).
//
// Loops: llvmpipe stops every loop of an invocation after 65535 iterations in all, so
// the ray march is the only long loop; the per-volume work is written out three times
// (straight-line calls guarded by the volume count), and src/gpu/multi.rs refuses steps
// that would take a ray past the limit.

#import multi_params
#import rays
#import camera
#import shading
#import opacity
#import filters

@group(0) @binding(0) var<uniform> params: MultiParams;
@group(0) @binding(1) var volume_0: texture_3d<f32>;
@group(0) @binding(2) var volume_1: texture_3d<f32>;
@group(0) @binding(3) var volume_2: texture_3d<f32>;
// The three lookup tables, one after the other (params.lut[i].w = first entry).
@group(0) @binding(4) var<storage, read> luts: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> out_pixels: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> out_samples: array<u32>;

const FILTER_NEAREST: u32 = 0u;

// ln_1p and exp_m1: shaders/shared/opacity.wgsl; clamp_index: shaders/shared/filters.wgsl.

// mirrors src/cpu/filter.rs: sample (nearest, and trilinear = axis_taps + apply_taps:
// Σ_k w_z[k] Σ_j w_y[j] Σ_i w_x[i] f[i, j, k], x innermost, clamped indices). Indices
// are the whole volume's (n voxels), clamped to it, then moved to the texture, which
// holds the volume from voxel o on (a split render's part of it).
fn sample_grid(t: texture_3d<f32>, n: vec3<u32>, o: vec3<i32>, p: vec3<f32>) -> f32 {
    if (params.image.w == FILTER_NEAREST) {
        let q = vec3<i32>(floor(p + vec3<f32>(0.5)));
        return textureLoad(t, vec3<i32>(clamp_index(q.x, n.x), clamp_index(q.y, n.y), clamp_index(q.z, n.z)) - o, 0).x;
    }
    let fl = floor(p);
    let f = p - fl;
    let i0 = vec3<i32>(fl);
    let x0 = clamp_index(i0.x, n.x) - o.x;
    let x1 = clamp_index(i0.x + 1, n.x) - o.x;
    let y0 = clamp_index(i0.y, n.y) - o.y;
    let y1 = clamp_index(i0.y + 1, n.y) - o.y;
    let z0 = clamp_index(i0.z, n.z) - o.z;
    let z1 = clamp_index(i0.z + 1, n.z) - o.z;
    let wx0 = 1.0 - f.x;
    let wy0 = 1.0 - f.y;
    let wz0 = 1.0 - f.z;
    let a00 = wx0 * textureLoad(t, vec3<i32>(x0, y0, z0), 0).x + f.x * textureLoad(t, vec3<i32>(x1, y0, z0), 0).x;
    let a01 = wx0 * textureLoad(t, vec3<i32>(x0, y1, z0), 0).x + f.x * textureLoad(t, vec3<i32>(x1, y1, z0), 0).x;
    let a10 = wx0 * textureLoad(t, vec3<i32>(x0, y0, z1), 0).x + f.x * textureLoad(t, vec3<i32>(x1, y0, z1), 0).x;
    let a11 = wx0 * textureLoad(t, vec3<i32>(x0, y1, z1), 0).x + f.x * textureLoad(t, vec3<i32>(x1, y1, z1), 0).x;
    let b0 = wy0 * a00 + f.y * a01;
    let b1 = wy0 * a10 + f.y * a11;
    return wz0 * b0 + f.z * b1;
}

// Volume i's reconstructed field at index point p.
// mirrors src/cpu/field.rs: GridField::value
fn layer_value(i: u32, p: vec3<f32>) -> f32 {
    let n = params.dims[i].xyz;
    let o = params.origin[i].xyz;
    if (i == 0u) {
        return sample_grid(volume_0, n, o, p);
    } else if (i == 1u) {
        return sample_grid(volume_1, n, o, p);
    }
    return sample_grid(volume_2, n, o, p);
}

// Volume i's index-space gradient of the reconstructed field (h = 1 voxel).
// mirrors src/cpu/gradient.rs: gradient_stencil (central, forward)
fn layer_gradient(i: u32, p: vec3<f32>) -> vec3<f32> {
    let ex = vec3<f32>(1.0, 0.0, 0.0);
    let ey = vec3<f32>(0.0, 1.0, 0.0);
    let ez = vec3<f32>(0.0, 0.0, 1.0);
    if (params.gradient.x == 1u) {
        let f0 = layer_value(i, p);
        return vec3<f32>(layer_value(i, p + ex) - f0, layer_value(i, p + ey) - f0, layer_value(i, p + ez) - f0);
    }
    return vec3<f32>(
        (layer_value(i, p + ex) - layer_value(i, p - ex)) * 0.5,
        (layer_value(i, p + ey) - layer_value(i, p - ey)) * 0.5,
        (layer_value(i, p + ez) - layer_value(i, p - ez)) * 0.5,
    );
}

// mirrors src/transfer.rs: LutR::classify (volume i's table)
fn classify_layer(i: u32, t: f32) -> vec4<f32> {
    let l = params.lut[i];
    let last = l.z;
    let x = min(max(l.x * t + l.y, 0.0), last);
    let i0f = floor(x);
    let f = x - i0f;
    let n = u32(last) + 1u;
    let base = u32(l.w);
    let i0 = min(u32(i0f), n - 1u);
    let i1 = min(i0 + 1u, n - 1u);
    let a = luts[base + i0];
    let b = luts[base + i1];
    return a + f * (b - a);
}

// mirrors src/cpu/multi.rs: shade (through src/cpu/raycast.rs: shade_gradient)
fn shade_layer(i: u32, p: vec3<f32>, rgb: vec3<f32>, l: vec3<f32>, h: vec3<f32>) -> vec3<f32> {
    let g = layer_gradient(i, p);
    let mag = length(g);
    let w = min(max((mag / params.box_hi[i].w - 0.5) * 2.0, 0.0), 1.0);
    if (w <= 0.0) {
        return rgb;
    }
    let gw = vec3<f32>(dot(params.normal[3u * i].xyz, g), dot(params.normal[3u * i + 1u].xyz, g), dot(params.normal[3u * i + 2u].xyz, g));
    let n = -normalize_or_zero(gw);
    let lit = phong(rgb, n, l, h);
    return rgb + w * (lit - rgb);
}

// One volume's view of one ray (mirrors src/cpu/multi.rs: Span).
struct Span {
    o: vec3<f32>,
    d: vec3<f32>,
    t_in: f32,
    t_out: f32,
    hit: bool,
}

fn span_of(i: u32, ray: Ray) -> Span {
    let r0 = params.to_index[3u * i];
    let r1 = params.to_index[3u * i + 1u];
    let r2 = params.to_index[3u * i + 2u];
    var s: Span;
    s.o = vec3<f32>(dot(r0, vec4<f32>(ray.origin, 1.0)), dot(r1, vec4<f32>(ray.origin, 1.0)), dot(r2, vec4<f32>(ray.origin, 1.0)));
    s.d = vec3<f32>(dot(r0.xyz, ray.dir), dot(r1.xyz, ray.dir), dot(r2.xyz, ray.dir));
    s.hit = false;
    let hit = intersect_box(s.o, s.d, vec3<f32>(-0.5), params.box_hi[i].xyz);
    if (hit.ok) {
        let a = max(hit.t0, ray.t_min);
        if (hit.t1 > a) {
            s.t_in = a;
            s.t_out = hit.t1;
            s.hit = true;
        }
    }
    return s;
}

fn inside(s: Span, tm: f32) -> bool {
    return s.hit && tm >= s.t_in && tm <= s.t_out;
}

// The running sums of combine_sample over the volumes.
struct Mix {
    tau: f32,
    weighted: vec3<f32>,
    opaque: u32,
    opaque_rgb: vec3<f32>,
}

// One volume's part of combine_sample (the loop body of the Rust twin).
fn mix_layer(m: ptr<function, Mix>, i: u32, s: Span, tm: f32, len: f32, light: vec3<f32>, half_vec: vec3<f32>) {
    if (!inside(s, tm)) {
        return;
    }
    let p = s.o + s.d * tm;
    let q = classify_layer(i, layer_value(i, p));
    let alpha = q.w;
    if (alpha <= 0.0) {
        return;
    }
    var rgb = q.xyz;
    if (params.dims[i].w == 1u) {
        rgb = shade_layer(i, p, rgb, light, half_vec);
    }
    if (alpha >= 1.0) {
        (*m).opaque = (*m).opaque + 1u;
        (*m).opaque_rgb = (*m).opaque_rgb + rgb;
        return;
    }
    // τ_i = σ_i · len, σ_i = −ln(1 − α_i) · |d_i| / Δ_ref.
    let t = -ln_1p(-alpha) * (len * length(s.d) / params.misc.y);
    (*m).tau = (*m).tau + t;
    (*m).weighted = (*m).weighted + t * rgb;
}

// mirrors src/cpu/multi.rs: combine_sample; returns (rgb, alpha), alpha < 0 when the
// step is transparent (the Rust twin's None).
fn combine_sample(s0: Span, s1: Span, s2: Span, tm: f32, len: f32, light: vec3<f32>, half_vec: vec3<f32>) -> vec4<f32> {
    var m = Mix(0.0, vec3<f32>(0.0), 0u, vec3<f32>(0.0));
    let count = params.flags.x;
    mix_layer(&m, 0u, s0, tm, len, light, half_vec);
    if (count > 1u) {
        mix_layer(&m, 1u, s1, tm, len, light, half_vec);
    }
    if (count > 2u) {
        mix_layer(&m, 2u, s2, tm, len, light, half_vec);
    }
    if (m.opaque > 0u) {
        let inv = 1.0 / f32(m.opaque);
        return vec4<f32>(m.opaque_rgb * inv, 1.0);
    }
    if (m.tau <= 0.0) {
        return vec4<f32>(0.0, 0.0, 0.0, -1.0);
    }
    return vec4<f32>(m.weighted / m.tau, -exp_m1(-m.tau));
}

// The value a MIP/MinIP/X-ray step sees from volume i (found = inside its box).
fn value_at(i: u32, s: Span, tm: f32) -> vec2<f32> {
    if (!inside(s, tm)) {
        return vec2<f32>(0.0, 0.0);
    }
    return vec2<f32>(layer_value(i, s.o + s.d * tm), 1.0);
}

// The running extreme (x; y = 1 once a value was seen) after value v (y = 1 if seen).
fn take_extreme(b: vec2<f32>, v: vec2<f32>, mip: bool) -> vec2<f32> {
    if (v.y != 1.0) {
        return b;
    }
    if (b.y != 1.0) {
        return v;
    }
    if (mip) {
        return vec2<f32>(max(b.x, v.x), 1.0);
    }
    return vec2<f32>(min(b.x, v.x), 1.0);
}

// Step k of n over [t_in, t_out]: (midpoint, length), as the Rust twin's `segment`: a
// full step (neither the first nor the last) is dt long, its midpoint t_in + (k + 1/2) dt.
fn segment(k: u32, n: u32, t_in: f32, t_out: f32, dt: f32) -> vec2<f32> {
    if (k > 0u && k + 1u < n) {
        return vec2<f32>(t_in + (f32(k) + 0.5) * dt, dt);
    }
    var ta = t_in;
    if (k != 0u) {
        ta = t_in + f32(k) * dt;
    }
    var tb = t_out;
    if (k + 1u != n) {
        tb = t_in + f32(k + 1u) * dt;
    }
    return vec2<f32>((ta + tb) * 0.5, tb - ta);
}

struct Pixel {
    value: vec4<f32>,
    samples: u32,
}

// A ray's state, handed from cell to cell of a split render (src/gpu/multi.rs:
// CARRIED_VEC4S vec4s a pixel): acc = what it gathered (DVR colour and opacity; MIP and
// MinIP the extreme and 1 once one was found; X-ray the sum); at = where it is (the
// next step of the loop, the samples taken, 1 once ended early, the ray's steps n, 0
// while it met no volume).
struct Carried {
    acc: vec4<f32>,
    at: vec4<f32>,
}

// Whether this pass takes the step whose midpoint is p (volume 0's index space).
fn owns(p: vec3<f32>) -> bool {
    return all(p >= params.own_lo.xyz) && all(p < params.own_hi.xyz);
}

// mirrors src/cpu/multi.rs: cast_multi
// The steps of the ray from where `st` left it, while this pass owns them (all of them
// when the render is not split); finish_multi makes the pixel.
fn cast_multi(ray: Ray, st_in: Carried) -> Carried {
    var st = st_in;
    let mode = params.image.z;
    let count = params.flags.x;
    let s0 = span_of(0u, ray);
    var s1 = s0;
    s1.hit = false;
    var s2 = s1;
    if (count > 1u) {
        s1 = span_of(1u, ray);
    }
    if (count > 2u) {
        s2 = span_of(2u, ray);
    }
    var t_in = BIG;
    var t_out = -BIG;
    if (s0.hit) {
        t_in = min(t_in, s0.t_in);
        t_out = max(t_out, s0.t_out);
    }
    if (s1.hit) {
        t_in = min(t_in, s1.t_in);
        t_out = max(t_out, s1.t_out);
    }
    if (s2.hit) {
        t_in = min(t_in, s2.t_in);
        t_out = max(t_out, s2.t_out);
    }
    if (!(t_out > t_in) || st.at.z == 1.0) {
        return st;
    }
    // The step: `step` voxels of volume 0 along the ray (world mm per step).
    let dt = params.misc.x / length(s0.d);
    let n = u32(max(ceil((t_out - t_in) / dt - 1e-3), 1.0));
    st.at.w = f32(n);
    var i = u32(st.at.x);

    if (mode == MODE_MIP || mode == MODE_MINIP) {
        var best = st.acc.xy;
        let mip = mode == MODE_MIP;
        loop {
            if (i >= n) {
                break;
            }
            let tm = segment(i, n, t_in, t_out, dt).x;
            if (!owns(s0.o + s0.d * tm)) {
                break;
            }
            best = take_extreme(best, value_at(0u, s0, tm), mip);
            best = take_extreme(best, value_at(1u, s1, tm), mip);
            best = take_extreme(best, value_at(2u, s2, tm), mip);
            i = i + 1u;
        }
        st.acc = vec4<f32>(best, 0.0, 0.0);
    } else if (mode == MODE_XRAY) {
        var sum = st.acc.x;
        loop {
            if (i >= n) {
                break;
            }
            let seg = segment(i, n, t_in, t_out, dt);
            if (!owns(s0.o + s0.d * seg.x)) {
                break;
            }
            let f = value_at(0u, s0, seg.x).x + value_at(1u, s1, seg.x).x + value_at(2u, s2, seg.x).x;
            sum = sum + f * seg.y;
            i = i + 1u;
        }
        st.acc = vec4<f32>(sum, 0.0, 0.0, 0.0);
    } else {
        // DVR
        let lh = light_half(ray.dir);
        let light = lh.l;
        let half_vec = lh.h;
        let back_to_front = params.flags.y == 1u;
        var c = st.acc.xyz;
        var a = st.acc.w;
        var taken = u32(st.at.y);
        loop {
            if (i >= n) {
                break;
            }
            var k = i;
            if (back_to_front) {
                k = n - 1u - i;
            }
            let seg = segment(k, n, t_in, t_out, dt);
            if (!owns(s0.o + s0.d * seg.x)) {
                break;
            }
            i = i + 1u;
            taken = taken + 1u;
            let s = combine_sample(s0, s1, s2, seg.x, seg.y, light, half_vec);
            if (s.w < 0.0) {
                continue;
            }
            let alpha = s.w;
            if (back_to_front) {
                c = alpha * s.xyz + (1.0 - alpha) * c;
                a = alpha + (1.0 - alpha) * a;
            } else {
                let w = (1.0 - a) * alpha;
                c = c + w * s.xyz;
                a = a + w;
                if (a >= params.misc.z) {
                    st.at.z = 1.0;
                    break;
                }
            }
        }
        st.acc = vec4<f32>(c, a);
        st.at.y = f32(taken);
    }
    st.at.x = f32(i);
    return st;
}

// The pixel and its samples from a ray's state after its last step (the tail of the
// Rust twin, cast_multi): the background where it met no volume, MIP/MinIP's miss value
// where it found none, DVR over the background.
fn finish_multi(st: Carried) -> Pixel {
    let mode = params.image.z;
    var miss = vec4<f32>(params.misc.w, 0.0, 0.0, 0.0);
    if (mode == MODE_DVR) {
        miss = params.background;
    }
    let n = u32(st.at.w);
    if (n == 0u) {
        return Pixel(miss, 0u);
    }
    if (mode == MODE_MIP || mode == MODE_MINIP) {
        if (st.acc.y == 1.0) {
            return Pixel(vec4<f32>(st.acc.x, 0.0, 0.0, 0.0), n);
        }
        return Pixel(miss, n);
    }
    if (mode == MODE_XRAY) {
        return Pixel(vec4<f32>(st.acc.x, 0.0, 0.0, 0.0), n);
    }
    let c = st.acc.xyz;
    let a = st.acc.w;
    let t = 1.0 - a;
    let bg = params.background;
    return Pixel(vec4<f32>(c + t * bg.xyz * bg.w, a + t * bg.w), u32(st.at.y));
}

@compute @workgroup_size(8, 8)
fn multi(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= params.tile.z || id.y >= params.tile.w) {
        return;
    }
    let col = params.tile.x + id.x;
    let row = params.tile.y + id.y;
    let idx = id.y * params.tile.z + id.x;
    let carried = params.carry.x == 1u;
    var st = Carried(vec4<f32>(0.0), vec4<f32>(0.0));
    if (carried) {
        st = Carried(out_pixels[2u * idx], out_pixels[2u * idx + 1u]);
    }
    st = cast_multi(camera_ray(col, row), st);
    if (params.carry.y == 1u) {
        let px = finish_multi(st);
        st.acc = px.value;
        out_samples[idx] = px.samples;
    }
    if (carried) {
        out_pixels[2u * idx] = st.acc;
        out_pixels[2u * idx + 1u] = st.at;
    } else {
        out_pixels[idx] = st.acc;
    }
}
