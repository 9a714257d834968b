// MIDA, the MIP/MinIP grey window and iso-surfaces for the ray caster.
// Mirrors src/cpu/modes.rs (formulas and conventions in its module docs); each helper
// names its Rust twin. Prepended to shaders/raycast.wgsl by src/gpu/raycast.rs, after
// raycast_params.wgsl, classify.wgsl and rays.wgsl; it calls sample_value,
// classify_sample, shade_sample and segment_point from shaders/raycast.wgsl.

const MODE_MIDA: u32 = 4u;
const MODE_ISO: u32 = 5u;
const MAX_ISO: u32 = 4u;

// mirrors src/cpu/modes.rs: window_map
fn window_map(v: f32) -> f32 {
    return min(max((v - params.window.y) / params.window.x + 0.5, 0.0), 1.0);
}

// mirrors src/cpu/modes.rs: mida_beta
fn mida_beta(delta: f32, gamma: f32) -> f32 {
    return 1.0 - delta * (1.0 + min(gamma, 0.0));
}

// mirrors src/cpu/modes.rs: crosses
fn crosses(v0: f32, v1: f32, tau: f32) -> bool {
    return (v0 >= tau) != (v1 >= tau);
}

// mirrors src/cpu/modes.rs: iso_hit_t
fn iso_hit_t(t0: f32, v0: f32, t1: f32, v1: f32, tau: f32) -> f32 {
    if (params.iso_flags.w == 1u) {
        return t0 + (tau - v0) / (v1 - v0) * (t1 - t0);
    }
    return t1;
}

fn iso_color(j: u32) -> vec4<f32> {
    if (j == 0u) {
        return params.iso_color_0;
    } else if (j == 1u) {
        return params.iso_color_1;
    } else if (j == 2u) {
        return params.iso_color_2;
    }
    return params.iso_color_3;
}

// (C, A) over the background; mirrors src/cpu/modes.rs: over_background
fn over_background(c: vec3<f32>, a: f32) -> vec4<f32> {
    let t = 1.0 - a;
    let bg = params.background;
    return vec4<f32>(c + t * bg.xyz * bg.w, a + t * bg.w);
}

// Opacity correction for a step of len·speed voxels (as in cast_ray).
fn corrected_alpha(a: f32, len: f32, speed: f32) -> f32 {
    if (a < 1.0) {
        return step_opacity(a, len * speed / params.misc.x);
    }
    return 1.0;
}

fn ray_light(ray: Ray) -> vec3<f32> {
    if (params.light.w == 1.0) {
        return params.light.xyz;
    }
    return -ray.dir;
}

// mirrors src/cpu/modes.rs: cast_mida
fn cast_mida(ray: Ray, o: vec3<f32>, d: vec3<f32>, t_in: f32, t_out: f32, dt: f32, n: u32, speed: f32) -> Pixel {
    let light = ray_light(ray);
    let half_vec = normalize_or_zero(light - ray.dir);
    let gamma = params.mode_params.x;
    var c = vec3<f32>(0.0);
    var a = 0.0;
    var running = 0.0;
    var best = -BIG;
    var best_p = o;
    for (var k = 0u; k < n; k++) {
        let p = segment_point(k, n, t_in, t_in, t_out, dt, o, d);
        let len = segment_length(k, n, t_in, t_in, t_out, dt);
        let v = sample_value(p);
        let sn = (v - params.mode_params.y) * params.mode_params.z;
        var delta = 0.0;
        if (k > 0u && sn > running) {
            delta = sn - running;
        }
        if (k == 0u) {
            running = sn;
        } else {
            running = max(running, sn);
        }
        if (v > best) {
            best = v;
            best_p = p;
        }
        let beta = mida_beta(delta, gamma);
        let s = classify_sample(p);
        if (s.w <= 0.0) {
            c = beta * c;
            a = beta * a;
            continue;
        }
        let alpha = corrected_alpha(s.w, len, speed);
        var rgb = s.xyz;
        if (params.flags.y == 1u) {
            rgb = shade_sample(p, rgb, light, half_vec);
        }
        let w = (1.0 - beta * a) * alpha;
        c = beta * c + w * rgb;
        a = beta * a + w;
    }
    if (gamma > 0.0) {
        // Unshaded, as on the CPU.
        let s = classify_sample(best_p);
        c = (1.0 - gamma) * c + gamma * s.w * s.xyz;
        a = (1.0 - gamma) * a + gamma * s.w;
    }
    return Pixel(over_background(c, a), n);
}

// mirrors src/cpu/modes.rs: in_shadow
fn in_shadow(p: vec3<f32>, l: vec3<f32>) -> bool {
    let hit = intersect_box(p, l, vec3<f32>(-0.5), params.box_hi.xyz);
    if (!hit.ok) {
        return false;
    }
    let dt = params.box_hi.w / length(l);
    let first = sample_value(p + l * dt);
    let count = params.iso_flags.x;
    for (var k = 2u; ; k++) {
        let t = f32(k) * dt;
        if (t >= hit.t1) {
            return false;
        }
        let v = sample_value(p + l * t);
        for (var j = 0u; j < count; j++) {
            if (crosses(first, v, params.iso_values[j])) {
                return true;
            }
        }
    }
    return false;
}

// mirrors src/cpu/modes.rs: cast_iso (dvr: DVR samples between the surfaces)
fn cast_iso(ray: Ray, o: vec3<f32>, d: vec3<f32>, t_in: f32, t_out: f32, dt: f32, n: u32, speed: f32, dvr: bool) -> Pixel {
    let light = ray_light(ray);
    let half_vec = normalize_or_zero(light - ray.dir);
    let l_index = vec3<f32>(dot(params.to_index_0.xyz, light), dot(params.to_index_1.xyz, light), dot(params.to_index_2.xyz, light));
    let count = params.iso_flags.x;
    let opaque = params.iso_flags.y == 1u;
    let shade = params.flags.y == 1u;
    var c = vec3<f32>(0.0);
    var a = 0.0;
    let b0 = segment_bounds(0u, n, t_in, t_out, dt);
    var t0 = (b0.x + b0.y) * 0.5;
    var v0 = sample_value(o + d * t0);
    var taken = 1u;
    if (dvr) {
        let s = classify_sample(segment_point(0u, n, t_in, t_in, t_out, dt, o, d));
        if (s.w > 0.0) {
            let p = segment_point(0u, n, t_in, t_in, t_out, dt, o, d);
            let alpha = corrected_alpha(s.w, segment_length(0u, n, t_in, t_in, t_out, dt), speed);
            var rgb = s.xyz;
            if (shade) {
                rgb = shade_sample(p, rgb, light, half_vec);
            }
            let w = (1.0 - a) * alpha;
            c = c + w * rgb;
            a = a + w;
        }
    }
    var done = false;
    for (var k = 1u; k < n; k++) {
        if (a >= params.misc.y || done) {
            break;
        }
        let bk = segment_bounds(k, n, t_in, t_out, dt);
        let t1 = (bk.x + bk.y) * 0.5;
        let v1 = sample_value(o + d * t1);
        taken = taken + 1u;
        // The crossings of this interval in depth order (ties: list order).
        var hit_t = vec4<f32>(0.0);
        var hit_j = vec4<u32>(0u);
        var nh = 0u;
        for (var j = 0u; j < count; j++) {
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
            if (shade) {
                rgb = shade_sample(p, rgb, light, half_vec);
            }
            if (opaque) {
                if (params.iso_flags.z == 1u && in_shadow(p, l_index)) {
                    rgb = iso.xyz * params.shading.x;
                }
                c = c + (1.0 - a) * rgb;
                a = a + (1.0 - a);
                done = true;
                break;
            }
            let w = (1.0 - a) * iso.w;
            c = c + w * rgb;
            a = a + w;
        }
        if (done) {
            break;
        }
        if (dvr) {
            let p = segment_point(k, n, t_in, t_in, t_out, dt, o, d);
            let s = classify_sample(p);
            if (s.w > 0.0) {
                let alpha = corrected_alpha(s.w, segment_length(k, n, t_in, t_in, t_out, dt), speed);
                var rgb = s.xyz;
                if (shade) {
                    rgb = shade_sample(p, rgb, light, half_vec);
                }
                let w = (1.0 - a) * alpha;
                c = c + w * rgb;
                a = a + w;
            }
        }
        t0 = t1;
        v0 = v1;
    }
    return Pixel(over_background(c, a), taken);
}
