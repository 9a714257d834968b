// The MIDA and iso-surface marches of the ray caster, twins of src/cpu/modes.rs (each
// function names its Rust twin). Imported through the generated module cast_mida_iso
// (src/gpu/raycast.rs: modes_wgsl) only by renders that draw MIDA or iso-surfaces:
// each march inlines the filter's tap sum many times over (samples, gradients, shadow
// rays), and with the 512-tap Lanczos-4 a software driver's compiler (llvmpipe) ran
// out of memory on shaders that never take those branches. Calls sample_value,
// classify_sample, shade_sample, segment_point and segment_length of
// shaders/raycast.wgsl.

#import modes

// The run of steps a MIDA or iso-surface ray takes: all n of them, or in a brick
// (params.brick.w = 1) the run it owns; (1, first, last), or x = 0 for none.
fn carried_run(n: u32, t_in: f32, t_out: f32, dt: f32, o: vec3<f32>, d: vec3<f32>) -> vec3<u32> {
    if (params.brick.w == 1.0) {
        return own_range(n, t_in, t_in, t_out, dt, o, d);
    }
    return vec3<u32>(1u, 0u, n - 1u);
}

// mirrors src/cpu/modes.rs: MidaState
struct MidaState {
    c: vec3<f32>,
    a: f32,
    running: f32,
    best: f32,
    best_rgba: vec4<f32>,
    started: bool,
}

fn mida_start() -> MidaState {
    return MidaState(vec3<f32>(0.0), 0.0, 0.0, -BIG, vec4<f32>(0.0), false);
}

// mirrors src/cpu/modes.rs: mida_sample
fn mida_sample(st: ptr<function, MidaState>, p: vec3<f32>, len: f32, speed: f32, light: vec3<f32>, half_vec: vec3<f32>) {
    let v = sample_value(p);
    let sn = (v - params.mode_params.y) * params.mode_params.z;
    var delta = 0.0;
    if ((*st).started && sn > (*st).running) {
        delta = sn - (*st).running;
    }
    if ((*st).started) {
        (*st).running = max((*st).running, sn);
    } else {
        (*st).running = sn;
    }
    (*st).started = true;
    let beta = mida_beta(delta, params.mode_params.x);
    let s = classify_sample(p);
    if (v > (*st).best) {
        (*st).best = v;
        (*st).best_rgba = s;
    }
    if (s.w <= 0.0) {
        (*st).c = beta * (*st).c;
        (*st).a = beta * (*st).a;
        return;
    }
    let alpha = corrected_alpha(s.w, len, speed);
    var rgb = s.xyz;
    if (params.flags.y == 1u) {
        rgb = shade_sample(p, rgb, light, half_vec);
    }
    let w = (1.0 - beta * (*st).a) * alpha;
    (*st).c = beta * (*st).c + w * rgb;
    (*st).a = beta * (*st).a + w;
}

// mirrors src/cpu/modes.rs: mida_finish (unshaded MIP colour, as on the CPU)
fn mida_finish(st: MidaState) -> vec4<f32> {
    let gamma = params.mode_params.x;
    var c = st.c;
    var a = st.a;
    if (gamma > 0.0) {
        c = (1.0 - gamma) * c + gamma * st.best_rgba.w * st.best_rgba.xyz;
        a = (1.0 - gamma) * a + gamma * st.best_rgba.w;
    }
    return over_background(c, a);
}

// A brick's MIDA state, three vec4 per pixel in out_pixels (carried_pixel):
// (c, a), (running, best, started, 0), best_rgba. mirrors src/gpu/raycast.rs: carried_mida
fn mida_load(i: u32) -> MidaState {
    let x = out_pixels[3u * i + 1u];
    return MidaState(out_pixels[3u * i].xyz, out_pixels[3u * i].w, x.x, x.y, out_pixels[3u * i + 2u], x.z == 1.0);
}

fn mida_store(i: u32, st: MidaState) {
    out_pixels[3u * i] = vec4<f32>(st.c, st.a);
    out_pixels[3u * i + 1u] = vec4<f32>(st.running, st.best, select(0.0, 1.0, st.started), 0.0);
    out_pixels[3u * i + 2u] = st.best_rgba;
}

// mirrors src/cpu/modes.rs: cast_mida. A brick (params.brick.w = 1) takes the run of
// steps it owns from the state the bricks in front of it left, and leaves the state
// for the bricks behind (the host finishes the pixel: src/gpu/raycast.rs: render_bricked).
fn cast_mida(ray: Ray, o: vec3<f32>, d: vec3<f32>, t_in: f32, t_out: f32, dt: f32, n: u32, speed: f32) -> Pixel {
    let lh = light_half(ray.dir);
    let light = lh.l;
    let half_vec = lh.h;
    let brick = params.brick.w == 1.0;
    let run = carried_run(n, t_in, t_out, dt, o, d);
    if (run.x == 0u) {
        return Pixel(vec4<f32>(0.0), 0u);
    }
    var st = mida_start();
    if (brick) {
        st = mida_load(mesh_pixel);
        if (!st.started) {
            st = mida_start();
        }
    }
    for (var k = run.y; k <= run.z; k++) {
        let p = segment_point(k, n, t_in, t_in, t_out, dt, o, d);
        let len = segment_length(k, n, t_in, t_in, t_out, dt);
        mida_sample(&st, p, len, speed, light, half_vec);
    }
    if (brick) {
        mida_store(mesh_pixel, st);
        return Pixel(vec4<f32>(0.0), run.z + 1u - run.y);
    }
    return Pixel(mida_finish(st), n);
}

// How a shadow ray's march ended (mirrors src/cpu/modes.rs: ShadowEnd): it left the
// box (lit), it crossed an iso-value (in shadow), or in a brick its next sample lies in
// another brick (paused).
const SHADOW_LIT: u32 = 0u;
const SHADOW_DARK: u32 = 1u;
const SHADOW_PAUSED: u32 = 2u;

// A shadow ray's march: the next sample k (from 1) and the first sample's value (once
// k > 1). mirrors src/cpu/modes.rs: ShadowMarch
struct ShadowMarch {
    k: u32,
    first: f32,
}

// Whether the brick owns the point q of the whole volume's index space (its faces at
// half voxels, the volume's outer faces open): each point is owned by one brick.
// mirrors src/cpu/raycast.rs: Owned::contains
fn owns_point(q: vec3<f32>) -> bool {
    return all(q >= params.own_lo.xyz) && all(q < params.own_hi.xyz);
}

// The samples p + (k + 1) Δ l of the shadow ray from the hit p, from m.k on, until the
// box's far side t_exit; in a brick (bricked) only while the next sample is its own.
// mirrors src/cpu/modes.rs: shadow_steps
fn shadow_steps(m: ptr<function, ShadowMarch>, p: vec3<f32>, l: vec3<f32>, t_exit: f32, bricked: bool) -> u32 {
    let dt = params.box_hi.w / length(l);
    let count = params.iso_flags.x;
    loop {
        let k = (*m).k;
        let t = f32(k) * dt;
        if (k >= 2u && t >= t_exit) {
            return SHADOW_LIT;
        }
        let q = p + l * t;
        if (bricked && !owns_point(q)) {
            return SHADOW_PAUSED;
        }
        let v = sample_value(q);
        (*m).k = k + 1u;
        if (k == 1u) {
            (*m).first = v;
            continue;
        }
        for (var j = 0u; j < count; j++) {
            if (crosses((*m).first, v, params.iso_values[j])) {
                return SHADOW_DARK;
            }
        }
    }
    return SHADOW_LIT;
}

// mirrors src/cpu/modes.rs: in_shadow
fn in_shadow(p: vec3<f32>, l: vec3<f32>) -> bool {
    let hit = intersect_box(p, l, vec3<f32>(-0.5), params.box_hi.xyz);
    if (!hit.ok) {
        return false;
    }
    var m = ShadowMarch(1u, 0.0);
    return shadow_steps(&m, p, l, hit.t1, false) == SHADOW_DARK;
}

// mirrors src/cpu/modes.rs: IsoState. In a brick, an opaque hit's shadow ray is
// marched afterwards, through the bricks in the light's order (shadow_pass): the hit
// keeps both endings, lit in c and in shadow in dark_c, and its point.
struct IsoState {
    c: vec3<f32>,
    a: f32,
    t0: f32,
    v0: f32,
    started: bool,
    done: bool,
    dark_c: vec3<f32>,
    hit: vec3<f32>,
    // 1 lit (or no shadows), -1 in shadow, k + 1 the shadow ray's next sample k
    // (read on the host by src/gpu/raycast.rs: carried_iso, shadow_waits).
    shadow: f32,
}

fn iso_start() -> IsoState {
    return IsoState(vec3<f32>(0.0), 0.0, 0.0, 0.0, false, false, vec3<f32>(0.0), vec3<f32>(0.0), 1.0);
}

// What an iso-surface ray's steps share. mirrors src/cpu/modes.rs: IsoRay
struct IsoRay {
    light: vec3<f32>,
    half_vec: vec3<f32>,
    l_index: vec3<f32>,
    dvr: bool,
}

// Step k's DVR sample composited under st.
fn iso_dvr_sample(st: ptr<function, IsoState>, k: u32, n: u32, t_in: f32, t_out: f32, dt: f32, o: vec3<f32>, d: vec3<f32>, speed: f32, r: IsoRay) {
    let p = segment_point(k, n, t_in, t_in, t_out, dt, o, d);
    let s = classify_sample(p);
    if (s.w <= 0.0) {
        return;
    }
    let alpha = corrected_alpha(s.w, segment_length(k, n, t_in, t_in, t_out, dt), speed);
    var rgb = s.xyz;
    if (params.flags.y == 1u) {
        rgb = shade_sample(p, rgb, r.light, r.half_vec);
    }
    let w = (1.0 - (*st).a) * alpha;
    (*st).c = (*st).c + w * rgb;
    (*st).a = (*st).a + w;
}

// mirrors src/cpu/modes.rs: iso_step (false: the ray had ended, the step not taken)
fn iso_step(st: ptr<function, IsoState>, k: u32, n: u32, t_in: f32, t_out: f32, dt: f32, o: vec3<f32>, d: vec3<f32>, speed: f32, r: IsoRay) -> bool {
    if (k == 0u) {
        let b0 = segment_bounds(0u, n, t_in, t_out, dt);
        (*st).t0 = (b0.x + b0.y) * 0.5;
        (*st).v0 = sample_value(o + d * (*st).t0);
        (*st).started = true;
        if (r.dvr) {
            iso_dvr_sample(st, 0u, n, t_in, t_out, dt, o, d, speed, r);
        }
        return true;
    }
    if ((*st).a >= params.misc.y || (*st).done) {
        return false;
    }
    let t0 = (*st).t0;
    let v0 = (*st).v0;
    let bk = segment_bounds(k, n, t_in, t_out, dt);
    let t1 = (bk.x + bk.y) * 0.5;
    let v1 = sample_value(o + d * t1);
    // The crossings of this interval in depth order (ties: list order).
    var hit_t = vec4<f32>(0.0);
    var hit_j = vec4<u32>(0u);
    var nh = 0u;
    for (var j = 0u; j < params.iso_flags.x; j++) {
        let tau = params.iso_values[j];
        if (crosses(v0, v1, tau)) {
            let t = iso_hit_t(t0, v0, t1, v1, tau);
            var q = nh;
            while (q > 0u && hit_t[q - 1u] > t) {
                hit_t[q] = hit_t[q - 1u];
                hit_j[q] = hit_j[q - 1u];
                q = q - 1u;
            }
            hit_t[q] = t;
            hit_j[q] = j;
            nh = nh + 1u;
        }
    }
    for (var h = 0u; h < nh; h++) {
        let iso = iso_color(hit_j[h]);
        let p = o + d * hit_t[h];
        var rgb = iso.xyz;
        if (params.flags.y == 1u) {
            rgb = shade_sample(p, rgb, r.light, r.half_vec);
        }
        if (params.iso_flags.y == 1u) {
            if (params.iso_flags.z == 1u) {
                let dark = iso.xyz * params.shading.x;
                if (params.brick.w == 1.0) {
                    // Both endings; the shadow ray is marched through the bricks later.
                    (*st).dark_c = (*st).c + (1.0 - (*st).a) * dark;
                    (*st).hit = p;
                    let box_exit = intersect_box(p, r.l_index, vec3<f32>(-0.5), params.box_hi.xyz);
                    (*st).shadow = select(1.0, 2.0, box_exit.ok);
                } else if (in_shadow(p, r.l_index)) {
                    rgb = dark;
                }
            }
            (*st).c = (*st).c + (1.0 - (*st).a) * rgb;
            (*st).a = (*st).a + (1.0 - (*st).a);
            (*st).done = true;
            return true;
        }
        let w = (1.0 - (*st).a) * iso.w;
        (*st).c = (*st).c + w * rgb;
        (*st).a = (*st).a + w;
    }
    if (r.dvr) {
        iso_dvr_sample(st, k, n, t_in, t_out, dt, o, d, speed, r);
    }
    (*st).t0 = t1;
    (*st).v0 = v1;
    return true;
}

// A brick's iso-surface state, the CARRIED_VEC4S vec4 in out_pixels: (c, a); until an
// opaque surface ends the ray (t0, v0, started, 0), then (dark_c, shadow); (hit, the
// shadow ray's first value). mirrors src/gpu/raycast.rs: carried_iso
fn iso_load(i: u32) -> IsoState {
    let x = out_pixels[3u * i + 1u];
    let y = out_pixels[3u * i + 2u];
    let c = out_pixels[3u * i].xyz;
    let a = out_pixels[3u * i].w;
    if (x.w != 0.0) {
        return IsoState(c, a, 0.0, 0.0, true, true, x.xyz, y.xyz, x.w);
    }
    return IsoState(c, a, x.x, x.y, x.z == 1.0, false, vec3<f32>(0.0), y.xyz, 1.0);
}

fn iso_store(i: u32, st: IsoState) {
    out_pixels[3u * i] = vec4<f32>(st.c, st.a);
    if (st.done) {
        out_pixels[3u * i + 1u] = vec4<f32>(st.dark_c, st.shadow);
        out_pixels[3u * i + 2u] = vec4<f32>(st.hit, 0.0);
    } else {
        out_pixels[3u * i + 1u] = vec4<f32>(st.t0, st.v0, select(0.0, 1.0, st.started), 0.0);
    }
}

// A brick's pass of the shadow rays (params.own_lo.w = 1): each ray whose opaque hit
// waits on its shadow ray takes the samples of it this brick owns, from where the
// bricks before left it; the bricks run in the light's order (src/gpu/raycast.rs:
// render_bricked), and a ray ends lit (shadow 1), in shadow (-1) or waiting at its
// next sample k (k + 1), its first sample's value in the third vec4's w.
fn shadow_pass(i: u32, l: vec3<f32>) -> Pixel {
    let code = out_pixels[3u * i + 1u].w;
    if (code < 2.0) {
        return Pixel(vec4<f32>(0.0), 0u);
    }
    let y = out_pixels[3u * i + 2u];
    let p = y.xyz;
    var m = ShadowMarch(u32(code) - 1u, y.w);
    let box_exit = intersect_box(p, l, vec3<f32>(-0.5), params.box_hi.xyz);
    let end = shadow_steps(&m, p, l, box_exit.t1, true);
    var next = f32(m.k + 1u);
    if (end == SHADOW_LIT) {
        next = 1.0;
    } else if (end == SHADOW_DARK) {
        next = -1.0;
    }
    out_pixels[3u * i + 1u].w = next;
    out_pixels[3u * i + 2u].w = m.first;
    return Pixel(vec4<f32>(0.0), 0u);
}

// mirrors src/cpu/modes.rs: cast_iso (dvr: DVR samples between the surfaces). A brick
// takes the run of steps it owns from the state the bricks in front left, as cast_mida.
fn cast_iso(ray: Ray, o: vec3<f32>, d: vec3<f32>, t_in: f32, t_out: f32, dt: f32, n: u32, speed: f32, dvr: bool) -> Pixel {
    let lh = light_half(ray.dir);
    let light = lh.l;
    let l_index = vec3<f32>(dot(params.to_index_0.xyz, light), dot(params.to_index_1.xyz, light), dot(params.to_index_2.xyz, light));
    let r = IsoRay(light, lh.h, l_index, dvr);
    let brick = params.brick.w == 1.0;
    if (brick && params.own_lo.w == 1.0) {
        return shadow_pass(mesh_pixel, l_index);
    }
    let run = carried_run(n, t_in, t_out, dt, o, d);
    if (run.x == 0u) {
        return Pixel(vec4<f32>(0.0), 0u);
    }
    var st = iso_start();
    if (brick) {
        st = iso_load(mesh_pixel);
    }
    var taken = 0u;
    for (var k = run.y; k <= run.z; k++) {
        if (!iso_step(&st, k, n, t_in, t_out, dt, o, d, speed, r)) {
            break;
        }
        taken = taken + 1u;
    }
    if (brick) {
        iso_store(mesh_pixel, st);
        return Pixel(vec4<f32>(0.0), taken);
    }
    return Pixel(over_background(st.c, st.a), taken);
}
