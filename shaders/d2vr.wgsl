// D²VR on the GPU: image-aligned slab marching. Each dispatch handles samples
// [chunk.x, chunk.y) of every ray, one invocation per pixel; the per-pixel
// accumulation (colour + opacity, or the MIP/MinIP/X-ray value) and the work counters
// persist in storage buffers between dispatches. Each sample is reconstructed from all
// views (the loop over views is the only inner loop), so no invocation runs near
// llvmpipe's 65535-iteration limit (see shaders/raycast.wgsl): the host sizes chunks.
// Same sample positions, step rule, classification, shading and compositing as
// src/cpu/raycast.rs: cast_ray with the field of src/cpu/d2vr.rs: ProjectionField.
// The generated module d2vr_projections (src/gpu/d2vr.rs: projections_wgsl) binds the
// filtered projections in runs of whole views (binding 3, then 8, 9, …) and defines
// `fn projection(k: u32, x: f32, y: f32) -> f32`, view k at detector column x, row y,
// zero outside the detector, and `fn projection_grad(k, x, y) -> vec3<f32>`, that
// value and its derivatives along x and y. Exact: storage buffers of f32 bits or f16
// pairs read through shared/ct_bilinear.wgsl. Hardware: bordered 2-D texture arrays;
// the value filtered by the texture unit, the gradient's four taps gathered.
// An image larger than one binding of accumulators runs in bands of rows
// [chunk.z, chunk.z + chunk.w); acc and counts hold the band.

#import ct_geometry
#import raycast_params
#import d2vr_params
#import classify
#import rays
#import camera
#import shading
#import opacity
#import d2vr_projections

@group(0) @binding(0) var<uniform> params: RaycastParams;
@group(0) @binding(1) var<uniform> dp: D2vrParams;
@group(0) @binding(2) var<storage, read> views: array<CtView>;
@group(0) @binding(4) var<storage, read> lut: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> occupancy: array<u32>;
// Per pixel of the band: DVR (r, g, b, a) accumulated front to back; else x =
// MIP/MinIP/X-ray value.
@group(0) @binding(6) var<storage, read_write> acc: array<vec4<f32>>;
// Per pixel: samples on the ray (0 = miss), samples visited, value and gradient
// reconstructions.
@group(0) @binding(7) var<storage, read_write> counts: array<vec4<u32>>;

// mirrors src/cpu/d2vr.rs: ProjectionField::reconstruct_sample
fn reconstruct_sample(w: vec3<f32>) -> f32 {
    var sum = 0.0;
    for (var k = 0u; k < dp.det.z; k++) {
        let pr = project_point(views[k], w);
        if (pr.w != 0.0) {
            sum = sum + pr.z * projection(k, pr.x, pr.y);
        }
    }
    return sum * dp.cylinder.w;
}

// mirrors src/cpu/d2vr.rs: ProjectionField::reconstruct_gradient
fn reconstruct_gradient(w: vec3<f32>) -> vec3<f32> {
    let ph = vec4<f32>(w, 1.0);
    var g = vec3<f32>(0.0);
    for (var k = 0u; k < dp.det.z; k++) {
        let v = views[k];
        let den = dot(v.r2, ph);
        if (den <= 0.0) {
            continue;
        }
        let inv = 1.0 / den;
        let col = dot(v.r0, ph) * inv;
        let row = dot(v.r1, ph) * inv;
        let s = v.r3.x * inv;
        let wt = s * s;
        let q = projection_grad(k, col, row);
        let dcol = (v.r0.xyz - col * v.r2.xyz) * inv;
        let drow = (v.r1.xyz - row * v.r2.xyz) * inv;
        let dw = -2.0 * wt * v.r2.xyz * inv;
        g = g + q.x * dw + wt * (q.y * dcol + q.z * drow);
    }
    return g * dp.cylinder.w;
}

fn to_world(p: vec3<f32>) -> vec3<f32> {
    let ph = vec4<f32>(p, 1.0);
    return vec3<f32>(dot(dp.to_world_0, ph), dot(dp.to_world_1, ph), dot(dp.to_world_2, ph));
}

// mirrors src/cpu/d2vr.rs: OccupancyMask::at
fn occupied(p: vec3<f32>) -> bool {
    let i = floor(p + vec3<f32>(0.5));
    let n = vec3<f32>(params.dims.xyz);
    if (!(all(i >= vec3<f32>(0.0)) && all(i < n))) {
        return false;
    }
    let u = vec3<u32>(i);
    return occupancy[(u.z * params.dims.y + u.y) * params.dims.x + u.x] != 0u;
}

// mirrors src/cpu/d2vr.rs: ProjectionField::culled
fn culled(p: vec3<f32>, w: vec3<f32>) -> bool {
    if (dp.flags.y == 1u) {
        if (w.x * w.x + w.z * w.z > dp.cylinder.x || w.y < dp.cylinder.y || w.y > dp.cylinder.z) {
            return true;
        }
    }
    if (dp.flags.z == 1u && !occupied(p)) {
        return true;
    }
    return false;
}

// Value at index point p; y = 1 when it was reconstructed (not culled).
// mirrors src/cpu/d2vr.rs: ProjectionField::value_uncounted
fn field_value(p: vec3<f32>) -> vec2<f32> {
    let w = to_world(p);
    if (culled(p, w)) {
        return vec2<f32>(0.0, 0.0);
    }
    return vec2<f32>(reconstruct_sample(w), 1.0);
}

// Index-space gradient; w = reconstructions spent.
// mirrors src/cpu/d2vr.rs: ProjectionField::gradient
fn field_gradient(p: vec3<f32>) -> vec4<f32> {
    if (dp.flags.x == 0u) {
        var g = vec3<f32>(0.0);
        var n = 0.0;
        for (var a = 0u; a < 3u; a++) {
            var e = vec3<f32>(0.0);
            e[a] = 1.0;
            let hi = field_value(p + e);
            let lo = field_value(p - e);
            n = n + hi.y + lo.y;
            g[a] = (hi.x - lo.x) * 0.5;
        }
        return vec4<f32>(g, n);
    }
    let w = to_world(p);
    if (culled(p, w)) {
        return vec4<f32>(0.0);
    }
    let gw = reconstruct_gradient(w);
    return vec4<f32>(dot(dp.jt_0.xyz, gw), dot(dp.jt_1.xyz, gw), dot(dp.jt_2.xyz, gw), 1.0);
}

// mirrors src/cpu/shade.rs: shade_sample (w of the result: reconstructions spent)
fn shade_sample(p: vec3<f32>, rgb: vec3<f32>, l: vec3<f32>, h: vec3<f32>) -> vec4<f32> {
    let gr = field_gradient(p);
    let g = gr.xyz;
    let mag = length(g);
    let w = min(max((mag / params.misc.z - 0.5) * 2.0, 0.0), 1.0);
    if (w <= 0.0) {
        return vec4<f32>(rgb, gr.w);
    }
    let gw = vec3<f32>(dot(params.normal_0.xyz, g), dot(params.normal_1.xyz, g), dot(params.normal_2.xyz, g));
    let n = -normalize_or_zero(gw);
    let lit = phong(rgb, n, l, h);
    return vec4<f32>(rgb + w * (lit - rgb), gr.w);
}

// Samples [chunk.x, chunk.y) of each pixel's ray.
// mirrors src/cpu/raycast.rs: cast_ray (front to back)
@compute @workgroup_size(8, 8)
fn d2vr_chunk(@builtin(global_invocation_id) id: vec3<u32>) {
    let col = id.x;
    let row = dp.chunk.z + id.y;
    if (col >= params.image.x || id.y >= dp.chunk.w || row >= params.image.y) {
        return;
    }
    let idx = id.y * params.image.x + col;
    let mode = params.image.z;
    let ray = camera_ray(col, row);
    let o = vec3<f32>(
        dot(params.to_index_0, vec4<f32>(ray.origin, 1.0)),
        dot(params.to_index_1, vec4<f32>(ray.origin, 1.0)),
        dot(params.to_index_2, vec4<f32>(ray.origin, 1.0)),
    );
    let d = vec3<f32>(dot(params.to_index_0.xyz, ray.dir), dot(params.to_index_1.xyz, ray.dir), dot(params.to_index_2.xyz, ray.dir));
    let hit = intersect_box(o, d, vec3<f32>(-0.5), params.box_hi.xyz);
    if (!hit.ok) {
        return;
    }
    let t_in = max(hit.t0, ray.t_min);
    let t_out = hit.t1;
    if (t_out <= t_in) {
        return;
    }
    let speed = length(d);
    let dt = params.box_hi.w / speed;
    let n = u32(max(ceil((t_out - t_in) / dt - 1e-3), 1.0));
    var cnt = counts[idx];
    cnt.x = n;
    var s = acc[idx];
    let k1 = min(dp.chunk.y, n);
    if (mode != MODE_DVR) {
        for (var k = dp.chunk.x; k < k1; k++) {
            let b = segment_bounds(k, n, t_in, t_out, dt);
            let v = field_value(o + d * ((b.x + b.y) * 0.5));
            cnt.z = cnt.z + u32(v.y);
            cnt.y = cnt.y + 1u;
            if (mode == MODE_XRAY) {
                s.x = s.x + v.x * (b.y - b.x);
            } else if (k == 0u) {
                s.x = v.x;
            } else if (mode == MODE_MIP) {
                s.x = max(s.x, v.x);
            } else {
                s.x = min(s.x, v.x);
            }
        }
        acc[idx] = s;
        counts[idx] = cnt;
        return;
    }
    // DVR, front to back; a ray that reached the ERT threshold stays finished.
    if (s.w >= params.misc.y) {
        counts[idx] = cnt;
        return;
    }
    let lh = light_half(ray.dir);
    let light = lh.l;
    let half_vec = lh.h;
    for (var k = dp.chunk.x; k < k1; k++) {
        let b = segment_bounds(k, n, t_in, t_out, dt);
        let p = o + d * ((b.x + b.y) * 0.5);
        let len = b.y - b.x;
        cnt.y = cnt.y + 1u;
        let v = field_value(p);
        cnt.z = cnt.z + u32(v.y);
        let c = classify(v.x);
        if (c.w <= 0.0) {
            continue;
        }
        var alpha = 1.0;
        if (c.w < 1.0) {
            alpha = step_opacity(c.w, len * speed / params.misc.x);
        }
        var rgb = c.xyz;
        if (params.flags.y == 1u) {
            let sh = shade_sample(p, rgb, light, half_vec);
            rgb = sh.xyz;
            cnt.w = cnt.w + u32(sh.w);
        }
        let wgt = (1.0 - s.w) * alpha;
        s = vec4<f32>(s.xyz + wgt * rgb, s.w + wgt);
        if (s.w >= params.misc.y) {
            break;
        }
    }
    acc[idx] = s;
    counts[idx] = cnt;
}
