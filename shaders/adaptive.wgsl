// The adaptive ray caster: one invocation per pixel; DVR through the pre-integrated
// transfer function, front to back, trilinear, no shading. Regular, adaptive or direct
// steps (params.dims.w). Every helper names its Rust twin in src/cpu/adaptive.rs or
// src/cpu/preintegrate.rs. The box test is shared/rays.wgsl's intersect_box, opacity
// correction shared/opacity.wgsl's step_opacity.
//
// The volume (R32Float) and the importance volume (Rgba32Float) are 3-D textures read
// texel by texel (textureLoad, exact): the size past one storage binding is the 3-D
// texture limit's.
//
// Rays come from the host (origin and direction in index space, computed in f64 and
// rounded to f32 exactly as the CPU's f32 path rounds them), so both start from the
// same numbers.

#import adaptive_params
#import opacity
#import rays

@group(0) @binding(0) var<uniform> params: AdaptiveParams;
@group(0) @binding(1) var volume: texture_3d<f32>;
@group(0) @binding(2) var<storage, read> preint: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> spectrum: array<f32>;
@group(0) @binding(4) var importance: texture_3d<f32>;
@group(0) @binding(5) var<storage, read> direct: array<f32>;
@group(0) @binding(6) var<storage, read> rays: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> pixels: array<vec4<f32>>;
@group(0) @binding(8) var<storage, read_write> counts: array<u32>;

// The whole volume's voxel (i, j, k), clamped to the whole volume; the texture holds
// the brick from params.brick.xyz on (the whole volume from 0 when not split).
fn voxel(i: i32, j: i32, k: i32) -> f32 {
    let n = vec3<i32>(params.dims.xyz);
    let c = clamp(vec3<i32>(i, j, k), vec3<i32>(0), n - vec3<i32>(1));
    return textureLoad(volume, c - params.brick.xyz, 0).x;
}

// mirrors src/cpu/filter.rs: sample (trilinear; apply_taps' order, x innermost)
fn sample_trilinear(p: vec3<f32>) -> f32 {
    let fl = floor(p);
    let f = p - fl;
    let i = vec3<i32>(fl);
    let wx0 = 1.0 - f.x;
    let wy0 = 1.0 - f.y;
    let wz0 = 1.0 - f.z;
    let x00 = 0.0 + wx0 * voxel(i.x, i.y, i.z) + f.x * voxel(i.x + 1, i.y, i.z);
    let x10 = 0.0 + wx0 * voxel(i.x, i.y + 1, i.z) + f.x * voxel(i.x + 1, i.y + 1, i.z);
    let x01 = 0.0 + wx0 * voxel(i.x, i.y, i.z + 1) + f.x * voxel(i.x + 1, i.y, i.z + 1);
    let x11 = 0.0 + wx0 * voxel(i.x, i.y + 1, i.z + 1) + f.x * voxel(i.x + 1, i.y + 1, i.z + 1);
    let y0 = 0.0 + wy0 * x00 + f.y * x10;
    let y1 = 0.0 + wy0 * x01 + f.y * x11;
    return 0.0 + wz0 * y0 + f.z * y1;
}

// mirrors src/cpu/preintegrate.rs: PreintTable::coord
fn preint_coord(t: f32) -> f32 {
    return min(max(params.window.z * t + params.window.w, 0.0), f32(params.table.x - 1u));
}

// mirrors src/cpu/preintegrate.rs: PreintTable::lookup
fn preint_lookup(front: f32, back: f32) -> vec4<f32> {
    let n = params.table.x;
    let x = preint_coord(front);
    let y = preint_coord(back);
    let x0f = floor(x);
    let y0f = floor(y);
    let fx = x - x0f;
    let fy = y - y0f;
    let x0 = min(u32(x0f), n - 1u);
    let y0 = min(u32(y0f), n - 1u);
    let x1 = min(x0 + 1u, n - 1u);
    let y1 = min(y0 + 1u, n - 1u);
    let a = preint[y0 * n + x0];
    let b = preint[y0 * n + x1];
    let c = preint[y1 * n + x0];
    let d = preint[y1 * n + x1];
    let lo = a + fx * (b - a);
    let hi = c + fx * (d - c);
    return lo + fy * (hi - lo);
}

// mirrors src/cpu/preintegrate.rs: preint_step
fn preint_step(e: vec4<f32>, len: f32) -> vec4<f32> {
    let a = min(max(e.w, 0.0), 1.0);
    if (a <= 0.0) {
        return vec4<f32>(0.0);
    }
    let a2 = step_opacity(a, len);
    let k = a2 / a;
    return vec4<f32>(e.x * k, e.y * k, e.z * k, a2);
}

// mirrors src/cpu/adaptive.rs: nearest_voxel (as a linear index)
fn nearest_voxel(p: vec3<f32>) -> vec3<u32> {
    let n = vec3<i32>(params.dims.xyz);
    let v = clamp(vec3<i32>(floor(p + vec3<f32>(0.5))), vec3<i32>(0), n - vec3<i32>(1));
    return vec3<u32>(v);
}

// mirrors src/cpu/adaptive.rs: SpectralTable::bins_of, SpectralTable::lookup
fn spectrum_lookup(lo: f32, hi: f32) -> f32 {
    let m = u32(params.spectrum.z);
    let top = params.spectrum.z;
    let d0 = params.spectrum.x;
    let inv = params.spectrum.y;
    var i = u32(min(max(floor((lo - d0) * inv), 0.0), top));
    var j = u32(min(max(ceil((hi - d0) * inv), 0.0), top));
    if (j <= i) {
        if (i >= m) {
            i = m - 1u;
        }
        j = i + 1u;
    }
    return spectrum[i * (m + 1u) + j];
}

// mirrors src/cpu/adaptive.rs: adaptive_step
fn adaptive_step(p: vec3<f32>, f0: f32, d: vec3<f32>) -> f32 {
    let t_max = params.steps.y;
    let v = nearest_voxel(p);
    let g = textureLoad(importance, vec3<i32>(v) - params.brick.xyz, 0);
    let gd = abs(d.x) * g.x + abs(d.y) * g.y + abs(d.z) * g.z;
    if (gd <= 0.0) {
        return t_max;
    }
    let a = params.window.x;
    let b = params.window.y;
    let s_min = f0 - gd * t_max;
    let s_max = f0 + gd * t_max;
    let u0 = a * s_min + b;
    let u1 = a * s_max + b;
    let nu = spectrum_lookup(min(u0, u1), max(u0, u1));
    let denom = params.steps.z * nu * abs(a) * gd;
    var t = t_max;
    if (denom > 0.0) {
        t = 1.0 / denom;
    }
    return min(max(t, params.steps.x), t_max);
}

// mirrors src/cpu/adaptive.rs: direct_step
fn direct_step(p: vec3<f32>) -> f32 {
    let v = nearest_voxel(p);
    let bs = params.table.z;
    let b = v / vec3<u32>(bs);
    return direct[b.x + params.table.w * (b.y + params.extra.x * b.z)];
}

// mirrors src/cpu/adaptive.rs: AdaptiveRay
struct AdaptiveRay {
    p0: vec3<f32>,
    dir: vec3<f32>,
    len: f32,
    ok: bool,
}

// mirrors src/cpu/adaptive.rs: AdaptiveState
struct AdaptiveState {
    c: vec3<f32>,
    a: f32,
    s: f32,
    f0: f32,
    k: u32,
    taken: u32,
    started: bool,
    done: bool,
}

// mirrors src/cpu/adaptive.rs: adaptive_ray (the whole volume's box)
fn adaptive_ray(o: vec3<f32>, d: vec3<f32>, t_min: f32) -> AdaptiveRay {
    var r = AdaptiveRay(vec3<f32>(0.0), vec3<f32>(0.0), 0.0, false);
    let hi = vec3<f32>(f32(params.dims.x) - 0.5, f32(params.dims.y) - 0.5, f32(params.dims.z) - 0.5);
    let hit = intersect_box(o, d, vec3<f32>(-0.5), hi);
    if (!hit.ok) {
        return r;
    }
    let t_in = max(hit.t0, t_min);
    let t_out = hit.t1;
    if (t_out <= t_in) {
        return r;
    }
    let speed = sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    r.p0 = o + d * t_in;
    r.dir = d * (1.0 / speed);
    r.len = (t_out - t_in) * speed;
    r.ok = true;
    return r;
}

// mirrors src/cpu/adaptive.rs: adaptive_start
fn adaptive_start(ray: AdaptiveRay) -> AdaptiveState {
    return AdaptiveState(vec3<f32>(0.0), 0.0, 0.0, sample_trilinear(ray.p0), 0u, 1u, true, false);
}

// mirrors src/cpu/adaptive.rs: adaptive_advance
fn adaptive_advance(ray: AdaptiveRay, st_in: AdaptiveState) -> AdaptiveState {
    var st = st_in;
    let s = st.s;
    let p = ray.p0 + ray.dir * s;
    let sampling = params.dims.w;
    var s1 = f32(st.k + 1u) * params.steps.x;
    if (sampling == 1u) {
        s1 = s + adaptive_step(p, st.f0, ray.dir);
    } else if (sampling == 2u) {
        s1 = s + direct_step(p);
    }
    s1 = min(s1, ray.len);
    let f1 = sample_trilinear(ray.p0 + ray.dir * s1);
    st.taken += 1u;
    let e = preint_step(preint_lookup(st.f0, f1), s1 - s);
    let w = 1.0 - st.a;
    st.c = st.c + w * e.xyz;
    st.a = st.a + w * e.w;
    if (st.a >= params.steps.w) {
        st.done = true;
        return st;
    }
    st.s = s1;
    st.f0 = f1;
    st.k += 1u;
    return st;
}

// Whether this dispatch's brick owns the step starting at p (the whole volume's when
// not split: its faces are open). Each point lies in one brick.
fn owns(p: vec3<f32>) -> bool {
    return all(p >= params.own_lo.xyz) && all(p < params.own_hi.xyz);
}

// The steps of the ray this dispatch owns: from the state the bricks in front of it
// left (none when not split) while the step's start lies in this brick.
fn adaptive_run(ray: AdaptiveRay, st_in: AdaptiveState) -> AdaptiveState {
    var st = st_in;
    if (!st.started) {
        if (!owns(ray.p0)) {
            return st;
        }
        st = adaptive_start(ray);
    }
    loop {
        if (st.done || !(st.s < ray.len) || !owns(ray.p0 + ray.dir * st.s)) {
            break;
        }
        st = adaptive_advance(ray, st);
    }
    return st;
}

// A brick's ray state, three vec4 a pixel (gpu::adaptive::carried_state is the Rust
// reader): (c, a), (s, f0, k, taken), (started, done, 0, 0).
fn state_load(local: u32) -> AdaptiveState {
    let x = pixels[3u * local];
    let y = pixels[3u * local + 1u];
    let z = pixels[3u * local + 2u];
    return AdaptiveState(x.xyz, x.w, y.x, y.y, u32(y.z), u32(y.w), z.x == 1.0, z.y == 1.0);
}

fn state_store(local: u32, st: AdaptiveState) {
    pixels[3u * local] = vec4<f32>(st.c, st.a);
    pixels[3u * local + 1u] = vec4<f32>(st.s, st.f0, f32(st.k), f32(st.taken));
    pixels[3u * local + 2u] = vec4<f32>(select(0.0, 1.0, st.started), select(0.0, 1.0, st.done), 0.0, 0.0);
}

@compute @workgroup_size(8, 8, 1)
fn adaptive(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = params.image.x;
    if (gid.x >= w || gid.y >= params.image.w) {
        return;
    }
    // The band's rays (rows image.z … image.z + image.w − 1), as its pixels.
    let local = gid.y * w + gid.x;
    let ro = rays[2u * local];
    let rd = rays[2u * local + 1u];
    let ray = adaptive_ray(ro.xyz, rd.xyz, ro.w);
    let carried = params.brick.w == 1;
    if (carried) {
        // A brick: take the state the bricks in front left, run the steps it owns,
        // leave the state for the bricks behind (the host finishes the pixel).
        if (ray.ok) {
            state_store(local, adaptive_run(ray, state_load(local)));
        }
        return;
    }
    let bg = params.background;
    if (!ray.ok) {
        pixels[local] = vec4<f32>(bg.x * bg.w, bg.y * bg.w, bg.z * bg.w, bg.w);
        counts[local] = 0u;
        return;
    }
    var st = AdaptiveState(vec3<f32>(0.0), 0.0, 0.0, 0.0, 0u, 0u, false, false);
    st = adaptive_run(ray, st);
    // mirrors src/cpu/shade.rs: over_background
    let t = 1.0 - st.a;
    pixels[local] = vec4<f32>(st.c + t * bg.xyz * bg.w, st.a + t * bg.w);
    counts[local] = st.taken;
}
