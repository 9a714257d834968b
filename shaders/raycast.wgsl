// The GPU ray caster: one invocation per pixel.
//
// No loops per sample: llvmpipe (Mesa's CPU Vulkan driver, which CI runs on) stops
// every loop of an invocation once 65535 iterations have run in total, silently. The
// tap sums and the Sobel stencil are therefore generated per filter as straight-line
// code, and the ray march is the only loop.
// Mirrors src/cpu/raycast.rs (cast_ray, classify_sample, shade_sample, phong,
// intersect_box), src/cpu/filter.rs (axis_taps, sample, the kernels) and
// src/cpu/gradient.rs (gradient_stencil). Each helper names its Rust twin.
// Prepended at load time: shaders/shared/raycast_params.wgsl, classify.wgsl,
// classify2d.wgsl, rays.wgsl (camera_ray, intersect_box, segment_bounds, phong, shared
// with D²VR), opacity.wgsl (step_opacity), skip.wgsl (empty-space skipping, clipping box, jittered ray starts) and
// modes.wgsl (MIDA, the grey window, iso-surfaces).


const FILTER_NEAREST: u32 = 0u;
const FILTER_TRILINEAR: u32 = 1u;
const FILTER_BSPLINE: u32 = 2u;
const FILTER_BSPLINE_INTERP: u32 = 3u;
const FILTER_CATMULL_ROM: u32 = 4u;
const FILTER_LANCZOS2: u32 = 5u;
const FILTER_LANCZOS3: u32 = 6u;
const FILTER_LANCZOS4: u32 = 7u;
const FILTER_BSPLINE_FAST: u32 = 8u;
const FILTER_BSPLINE_FAST_INTERP: u32 = 9u;


const PI: f32 = 3.14159265358979323846;

@group(0) @binding(0) var<uniform> params: RaycastParams;
// The volume (values, or B-spline coefficients for bspline-interp).
@group(0) @binding(1) var volume: texture_3d<f32>;
// Pre-classified opacity-weighted colours (αr, αg, αb, α), when pre-classifying.
@group(0) @binding(2) var preclassified: texture_3d<f32>;
// Precomputed index-space gradients (xyz), when asked for.
@group(0) @binding(3) var gradients: texture_3d<f32>;
@group(0) @binding(4) var linear_clamp: sampler;
@group(0) @binding(5) var<storage, read> lut: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> out_pixels: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> out_samples: array<u32>;
// The 2D transfer function's table (one dummy entry when it is off).
@group(0) @binding(8) var<storage, read> lut2d: array<vec4<f32>>;
// Empty-space skipping (shaders/shared/skip.wgsl): [min, max] per cell, and the LUT's
// prefix count of non-zero opacities.
@group(0) @binding(9) var<storage, read> skip_minmax: array<vec2<f32>>;
@group(0) @binding(10) var<storage, read> skip_prefix: array<u32>;
// Clipping mesh: per pixel of the tile (count, 0, 0, 0) then four (a₀, b₀, a₁, b₁)
// (shaders/clipmesh.wgsl); one dummy pixel when params.clip_mesh.x == 0.
@group(0) @binding(11) var<storage, read> mesh_segments: array<vec4<f32>>;

// The pixel of the tile this invocation casts (indexes mesh_segments).
var<private> mesh_pixel: u32;

// ---------------------------------------------------------------- kernels
// mirrors src/cpu/filter.rs: weight_tent
fn weight_tent(x: f32) -> f32 {
    return max(1.0 - abs(x), 0.0);
}

// mirrors src/cpu/filter.rs: weight_bspline
fn weight_bspline(x: f32) -> f32 {
    let a = abs(x);
    let sixth = 1.0 / 6.0;
    if (a < 1.0) {
        return (4.0 - 6.0 * a * a + 3.0 * a * a * a) * sixth;
    } else if (a < 2.0) {
        let t = 2.0 - a;
        return t * t * t * sixth;
    }
    return 0.0;
}

// mirrors src/cpu/filter.rs: weight_catmull_rom
fn weight_catmull_rom(x: f32) -> f32 {
    let a = abs(x);
    if (a < 1.0) {
        return 1.5 * a * a * a - 2.5 * a * a + 1.0;
    } else if (a < 2.0) {
        return -0.5 * a * a * a + 2.5 * a * a - 4.0 * a + 2.0;
    }
    return 0.0;
}

// Rust's f32::round: halves away from zero (WGSL's round() goes to even).
fn round_away(x: f32) -> f32 {
    return sign(x) * floor(abs(x) + 0.5);
}

// mirrors src/cpu/filter.rs: sin_pi (exactly zero at integers)
fn sin_pi(x: f32) -> f32 {
    let r = x - 2.0 * round_away(x / 2.0);
    if (r > 0.5) {
        return sin(PI * (1.0 - r));
    } else if (r < -0.5) {
        return -sin(PI * (1.0 + r));
    }
    return sin(PI * r);
}

// mirrors src/cpu/filter.rs: sinc
fn sinc(x: f32) -> f32 {
    if (x == 0.0) {
        return 1.0;
    }
    return sin_pi(x) / (PI * x);
}

// mirrors src/cpu/filter.rs: weight_lanczos
fn weight_lanczos(x: f32, n: u32) -> f32 {
    let nr = f32(n);
    if (abs(x) >= nr) {
        return 0.0;
    }
    return sinc(x) * sinc(x / nr);
}

fn lanczos_radius(filter_kind: u32) -> u32 {
    if (filter_kind == FILTER_LANCZOS2) {
        return 2u;
    } else if (filter_kind == FILTER_LANCZOS3) {
        return 3u;
    }
    return 4u;
}

// The unnormalised weight of tap m at fractional position f = x − floor(x). With the
// generated accumulate_taps (first tap, count, Lanczos normalisation) this mirrors
// src/cpu/filter.rs: axis_taps.
fn tap_weight(filter_kind: u32, f: f32, m: u32) -> f32 {
    if (filter_kind == FILTER_TRILINEAR) {
        if (m == 0u) {
            return 1.0 - f;
        }
        return f;
    }
    if (filter_kind == FILTER_BSPLINE || filter_kind == FILTER_BSPLINE_INTERP || filter_kind == FILTER_CATMULL_ROM) {
        // Taps at offsets f + 1, f, 1 − f, 2 − f.
        var d = f + 1.0;
        if (m == 1u) {
            d = f;
        } else if (m == 2u) {
            d = 1.0 - f;
        } else if (m == 3u) {
            d = 2.0 - f;
        }
        if (filter_kind == FILTER_CATMULL_ROM) {
            return weight_catmull_rom(d);
        }
        return weight_bspline(d);
    }
    // Tap i0 − n + 1 + m lies at offset x − i = f + n − 1 − m.
    let n = lanczos_radius(filter_kind);
    return weight_lanczos(f + (f32(n) - 1.0 - f32(m)), n);
}

fn clamp_index(i: i32, n: u32) -> i32 {
    return clamp(i, 0, i32(n) - 1);
}

// mirrors src/cpu/filter.rs: sample; p in index coordinates.
// sample_tex(t, p) is generated by src/gpu/raycast.rs: sample_tex_wgsl with only the
// render's reconstruction path:
// - exact: every tap is a textureLoad, weights computed in voxel coordinates, summed by
//   accumulate_taps, generated as straight-line code in the CPU's order (mirrors
//   src/cpu/filter.rs: apply_taps);
// - hardware (trilinear only): one filtered textureSampleLevel;
// - the fast B-splines: 8 trilinear fetches (shaders/shared/tricubic.wgsl), by hand or,
//   on the hardware path, through the sampler;
// - nearest: one textureLoad.
// A runtime switch over all of them, inlined 54 times by the Sobel stencil, took the
// NVIDIA compiler minutes.

fn sample_value(p: vec3<f32>) -> f32 {
    return sample_tex(volume, p).x;
}

// ---------------------------------------------------------------- gradients

// gradient_at(p), mirroring src/cpu/gradient.rs: gradient_stencil on the reconstructed
// field (h = 1 voxel), is generated by src/gpu/raycast.rs: gradient_wgsl for the
// render's method, so only the stencil in use is compiled.

// mirrors src/cpu/raycast.rs: GridField::gradient
fn field_gradient(p: vec3<f32>) -> vec3<f32> {
    if (params.flags.z == 1u) {
        return sample_tex(gradients, p).xyz;
    }
    return gradient_at(p);
}

// ---------------------------------------------------------------- classification
// classify(t): shaders/shared/classify.wgsl (mirrors src/transfer.rs: LutR::classify).


// mirrors src/cpu/raycast.rs: classify_sample; returns (rgb, alpha per reference step)
fn classify_sample(p: vec3<f32>) -> vec4<f32> {
    if (params.flags.x == 0u) {
        if (params.tf2d_b.w == 1.0) {
            // The world-space gradient magnitude, as shade_sample sees it.
            let g = field_gradient(p);
            let gw = vec3<f32>(dot(params.normal_0.xyz, g), dot(params.normal_1.xyz, g), dot(params.normal_2.xyz, g));
            return classify2d(sample_value(p), length(gw));
        }
        return classify(sample_value(p));
    }
    let s = sample_tex(preclassified, p);
    let a = min(max(s.w, 0.0), 1.0);
    if (a <= 0.0) {
        return vec4<f32>(0.0);
    }
    let rgb = min(max(s.xyz / a, vec3<f32>(0.0)), vec3<f32>(1.0));
    return vec4<f32>(rgb, a);
}

// mirrors src/cpu/raycast.rs: shade_sample
fn shade_sample(p: vec3<f32>, rgb: vec3<f32>, l: vec3<f32>, h: vec3<f32>) -> vec3<f32> {
    let g = field_gradient(p);
    let mag = length(g);
    let w = min(max((mag / params.misc.z - 0.5) * 2.0, 0.0), 1.0);
    if (w <= 0.0) {
        return rgb;
    }
    let gw = vec3<f32>(dot(params.normal_0.xyz, g), dot(params.normal_1.xyz, g), dot(params.normal_2.xyz, g));
    let n = -normalize_or_zero(gw);
    let lit = phong(rgb, n, l, h);
    return rgb + w * (lit - rgb);
}

struct Pixel {
    value: vec4<f32>,
    samples: u32,
}

// mirrors src/cpu/raycast.rs: cast_ray; u offsets the steps by u·Δs.
fn cast_ray(ray: Ray, u: f32) -> Pixel {
    let mode = params.image.z;
    let o = vec3<f32>(
        dot(params.to_index_0, vec4<f32>(ray.origin, 1.0)),
        dot(params.to_index_1, vec4<f32>(ray.origin, 1.0)),
        dot(params.to_index_2, vec4<f32>(ray.origin, 1.0)),
    );
    let d = vec3<f32>(dot(params.to_index_0.xyz, ray.dir), dot(params.to_index_1.xyz, ray.dir), dot(params.to_index_2.xyz, ray.dir));
    var miss = vec4<f32>(params.misc.w, 0.0, 0.0, 0.0);
    if (mode == MODE_DVR || mode == MODE_MIDA || mode == MODE_ISO) {
        miss = params.background;
    }
    let hit = intersect_box(o, d, vec3<f32>(-0.5), params.box_hi.xyz);
    if (!hit.ok) {
        return Pixel(miss, 0u);
    }
    var t_in = max(hit.t0, ray.t_min);
    var t_out = hit.t1;
    if (params.accel.w != 0u) {
        let clip = clip_interval(o, d, ray.origin, ray.dir);
        if (!clip.ok) {
            return Pixel(miss, 0u);
        }
        t_in = max(t_in, clip.t0);
        t_out = min(t_out, clip.t1);
    }
    if (t_out <= t_in) {
        return Pixel(miss, 0u);
    }
    let speed = length(d);
    let dt = params.box_hi.w / speed;
    let t_s = t_in - u * dt;
    let n = u32(max(ceil((t_out - t_s) / dt - 1e-3), 1.0));

    // shaders/shared/modes.wgsl: MIDA and iso-surfaces march the unjittered grid.
    let n0 = u32(max(ceil((t_out - t_in) / dt - 1e-3), 1.0));
    if (mode == MODE_MIDA) {
        return cast_mida(ray, o, d, t_in, t_out, dt, n0, speed);
    }
    if (mode == MODE_ISO || (mode == MODE_DVR && params.iso_flags.x > 0u)) {
        return cast_iso(ray, o, d, t_in, t_out, dt, n0, speed, mode == MODE_DVR);
    }
    // The clipping mesh keeps the step grid and takes only the samples inside it.
    var mr = mesh_ranges_all(n);
    if (params.clip_mesh.x == 1u) {
        mr = mesh_ranges(n, t_in, t_out, t_s, dt);
        if (mode == MODE_MIP || mode == MODE_MINIP || mode == MODE_XRAY) {
            return cast_scalar_ranges(mode, mr, miss, n, t_in, t_s, t_out, dt, o, d);
        }
    }
    if (mode == MODE_MIP || mode == MODE_MINIP) {
        var best = sample_value(segment_point(0u, n, t_in, t_s, t_out, dt, o, d));
        for (var k = 1u; k < n; k++) {
            let v = sample_value(segment_point(k, n, t_in, t_s, t_out, dt, o, d));
            if (mode == MODE_MIP) {
                best = max(best, v);
            } else {
                best = min(best, v);
            }
        }
        if (params.window.z == 1.0) {
            best = window_map(best);
        }
        return Pixel(vec4<f32>(best, 0.0, 0.0, 0.0), n);
    }
    if (mode == MODE_XRAY) {
        var sum = 0.0;
        for (var k = 0u; k < n; k++) {
            sum = sum + sample_value(segment_point(k, n, t_in, t_s, t_out, dt, o, d)) * segment_length(k, n, t_in, t_s, t_out, dt);
        }
        return Pixel(vec4<f32>(sum, 0.0, 0.0, 0.0), n);
    }

    // DVR
    let view = -ray.dir;
    var light = view;
    if (params.light.w == 1.0) {
        light = params.light.xyz;
    }
    let half_vec = normalize_or_zero(light + view);
    let back_to_front = params.flags.w == 1u;
    var c = vec3<f32>(0.0);
    var a = 0.0;
    var taken = 0u;
    let skip = params.accel.x == 1u;
    var ranges = ranges_new(skip, t_s, dt, n, back_to_front);
    var walk = ranges_walk(o, d, t_in, t_out, back_to_front);
    var terminated = false;
    loop {
    let range = ranges_next(&ranges, &walk);
    if (range.x == 0) {
        break;
    }
    // Intersected with the mesh's ranges (mirrors src/cpu/clipmesh.rs: ClippedRanges).
    for (var m = 0u; m < mr.count; m++) {
    var j = m;
    if (back_to_front) {
        j = mr.count - 1u - m;
    }
    let k_lo = max(u32(range.y), mr.range[j].x);
    let k_hi = min(u32(range.z), mr.range[j].y);
    if (k_lo > k_hi) {
        continue;
    }
    for (var i = k_lo; i <= k_hi; i++) {
        var k = i;
        if (back_to_front) {
            k = k_lo + k_hi - i;
        }
        let p = segment_point(k, n, t_in, t_s, t_out, dt, o, d);
        let len = segment_length(k, n, t_in, t_s, t_out, dt);
        taken = taken + 1u;
        let s = classify_sample(p);
        if (s.w <= 0.0) {
            continue;
        }
        // Opacity correction for a step of len·speed voxels: a full step's exponent is
        // the step over the reference step exactly (mirrors src/cpu/march.rs:
        // Steps::exponent).
        var alpha = 1.0;
        if (s.w < 1.0) {
            var e = len * speed / params.misc.x;
            if (full_step(k, n)) {
                e = params.box_hi.w / params.misc.x;
            }
            alpha = step_opacity(s.w, e);
        }
        var rgb = s.xyz;
        if (params.flags.y == 1u) {
            rgb = shade_sample(p, rgb, light, half_vec);
        }
        if (back_to_front) {
            c = alpha * rgb + (1.0 - alpha) * c;
            a = alpha + (1.0 - alpha) * a;
        } else {
            let w = (1.0 - a) * alpha;
            c = c + w * rgb;
            a = a + w;
            if (a >= params.misc.y) {
                terminated = true;
                break;
            }
        }
    }
    if (terminated) {
        break;
    }
    }
    if (terminated) {
        break;
    }
    }
    let t = 1.0 - a;
    let bg = params.background;
    return Pixel(vec4<f32>(c + t * bg.xyz * bg.w, a + t * bg.w), taken);
}

// A full step (neither the first nor the last) has midpoint t_s + (k + 1/2) dt and
// length dt exactly; the first starts at t_in, the last ends at t_out.
// mirrors src/cpu/march.rs: Steps::full, Steps::segment
fn full_step(k: u32, n: u32) -> bool {
    return k > 0u && k + 1u < n;
}

fn segment_point(k: u32, n: u32, t_in: f32, t_s: f32, t_out: f32, dt: f32, o: vec3<f32>, d: vec3<f32>) -> vec3<f32> {
    if (full_step(k, n)) {
        return o + d * (t_s + (f32(k) + 0.5) * dt);
    }
    let b = step_bounds(k, n, t_in, t_s, t_out, dt);
    return o + d * ((b.x + b.y) * 0.5);
}

fn segment_length(k: u32, n: u32, t_in: f32, t_s: f32, t_out: f32, dt: f32) -> f32 {
    if (full_step(k, n)) {
        return dt;
    }
    let b = step_bounds(k, n, t_in, t_s, t_out, dt);
    return b.y - b.x;
}

@compute @workgroup_size(8, 8)
fn raycast(@builtin(global_invocation_id) id: vec3<u32>) {
    let col = id.x;
    let local_row = id.y;
    if (col >= params.image.x || local_row >= params.flags2.w) {
        return;
    }
    let row = params.flags2.z + local_row;
    let idx = local_row * params.image.x + col;
    mesh_pixel = idx;
    let px = cast_ray(camera_ray(col, row), ray_offset(col, row));
    out_pixels[idx] = px.value;
    out_samples[idx] = px.samples;
}

// ---------------------------------------------------------------- clipping mesh
struct MeshRanges {
    count: u32,
    range: array<vec2<u32>, 8>,
}

// mirrors src/cpu/clipmesh.rs: MeshRanges::all
fn mesh_ranges_all(n: u32) -> MeshRanges {
    var r: MeshRanges;
    r.count = 1u;
    r.range[0] = vec2<u32>(0u, n - 1u);
    return r;
}

// mirrors src/cpu/clipmesh.rs: step_mid
fn step_mid(k: i32, n: u32, t_in: f32, t_s: f32, t_out: f32, dt: f32) -> f32 {
    let b = step_bounds(u32(k), n, t_in, t_s, t_out, dt);
    return (b.x + b.y) * 0.5;
}

// mirrors src/cpu/clipmesh.rs: MeshRanges::new (the samples whose midpoint lies in a
// segment of this pixel's ray, from shaders/clipmesh.wgsl)
fn mesh_ranges(n: u32, t_in: f32, t_out: f32, t_s: f32, dt: f32) -> MeshRanges {
    var out: MeshRanges;
    out.count = 0u;
    let base = mesh_pixel * 5u;
    let count = u32(mesh_segments[base].x);
    let last = i32(n) - 1;
    for (var s = 0u; s < count; s++) {
        let v = mesh_segments[base + 1u + s / 2u];
        var seg = v.xy;
        if (s % 2u == 1u) {
            seg = v.zw;
        }
        let a = seg.x;
        let b = seg.y;
        // Estimate, then correct against the exact midpoints.
        let ga = i32(floor(min(max((a - t_s) / dt - 0.5, -2.0), f32(n) + 2.0)));
        let gb = i32(floor(min(max((b - t_s) / dt - 0.5, -2.0), f32(n) + 2.0)));
        var lo = clamp(ga - 1, 0, last);
        while (lo <= last && step_mid(lo, n, t_in, t_s, t_out, dt) < a) {
            lo += 1;
        }
        while (lo > 0 && step_mid(lo - 1, n, t_in, t_s, t_out, dt) >= a) {
            lo -= 1;
        }
        var hi = clamp(gb + 2, 0, last);
        while (hi >= 0 && step_mid(hi, n, t_in, t_s, t_out, dt) > b) {
            hi -= 1;
        }
        while (hi < last && step_mid(hi + 1, n, t_in, t_s, t_out, dt) <= b) {
            hi += 1;
        }
        if (lo > hi) {
            continue;
        }
        // Keep the ranges disjoint and increasing.
        if (out.count > 0u && u32(lo) <= out.range[out.count - 1u].y) {
            out.range[out.count - 1u].y = max(out.range[out.count - 1u].y, u32(hi));
            continue;
        }
        out.range[out.count] = vec2<u32>(u32(lo), u32(hi));
        out.count += 1u;
    }
    return out;
}

// mirrors src/cpu/clipmesh.rs: cast_scalar_ranges (MIP, MinIP, X-ray over the ranges)
fn cast_scalar_ranges(mode: u32, mr: MeshRanges, miss: vec4<f32>, n: u32, t_in: f32, t_s: f32, t_out: f32, dt: f32, o: vec3<f32>, d: vec3<f32>) -> Pixel {
    var taken = 0u;
    var best = 0.0;
    var sum = 0.0;
    for (var r = 0u; r < mr.count; r++) {
        for (var k = mr.range[r].x; k <= mr.range[r].y; k++) {
            let v = sample_value(segment_point(k, n, t_in, t_s, t_out, dt, o, d));
            if (mode == MODE_XRAY) {
                sum = sum + v * segment_length(k, n, t_in, t_s, t_out, dt);
            } else if (taken == 0u) {
                best = v;
            } else if (mode == MODE_MIP) {
                best = max(best, v);
            } else {
                best = min(best, v);
            }
            taken += 1u;
        }
    }
    if (taken == 0u) {
        return Pixel(miss, 0u);
    }
    if (mode == MODE_XRAY) {
        return Pixel(vec4<f32>(sum, 0.0, 0.0, 0.0), taken);
    }
    if (params.window.z == 1.0) {
        best = window_map(best);
    }
    return Pixel(vec4<f32>(best, 0.0, 0.0, 0.0), taken);
}
