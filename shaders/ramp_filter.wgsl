// Ramp filtering of CT projections (src/cpu/ramp.rs has the construction and the f64
// oracle; src/gpu/ramp.rs dispatches). Two detector lines share one complex line of
// the padded length P (`z = a + i·b`): the response is real and even, so it acts on
// both parts separately. Three entry points around the batched FFT of src/gpu/fft.rs:
// `ramp_pad` (pre-weight, pack, zero-pad) → FFT → `ramp_multiply` → inverse FFT →
// `ramp_crop`.

#import ramp_params

@group(0) @binding(0) var<uniform> params: RampParams;
// The detector lines of the chunk (pad reads, crop writes), `cols` values each.
@group(0) @binding(1) var<storage, read_write> lines: array<f32>;
// The packed complex lines, `[re, im]` pairs, P per line.
@group(0) @binding(2) var<storage, read_write> packed: array<vec2<f32>>;
// The effective response times 1/(P·spacing), P values (NumPy FFT order); for views
// given by vectors times 1/P only (each view's 1/spacing is in its weight).
@group(0) @binding(3) var<storage, read> response: array<f32>;
// Every view's pre-weighting (weighting 2), one dummy entry otherwise.
@group(0) @binding(4) var<storage, read> views: array<RampViewGpu>;

fn invocation(gid: vec3<u32>) -> u32 {
    return gid.x + gid.y * params.work.y;
}

// The FDK cosine weight SDD/√(SDD² + u² + v²) at detector position (u, v) mm.
// mirrors src/cpu/ramp.rs: cosine_weight
fn cosine_weight(sdd: f32, u: f32, v: f32) -> f32 {
    return sdd / sqrt(sdd * sdd + u * u + v * v);
}

// The pre-weight of pixel (col, row) of a view given by vectors: 1/spacing times, for
// a cone beam, the cosine SDD/|X − S| of the ray's angle with the detector normal.
// mirrors src/cpu/ramp.rs: RampView::weight
fn view_weight(w: RampViewGpu, col: f32, row: f32) -> f32 {
    if w.r.w == 0.0 {
        return w.u.w;
    }
    let x = w.r.xyz + w.u.xyz * col + w.v.xyz * row;
    return w.u.w * w.r.w / length(x);
}

// Detector line `line` (view-major, then row) at column `c`, cosine-weighted for a
// cone beam; zero past the chunk's last line.
// mirrors src/gpu/ramp.rs: preweighted_sample
fn preweighted_sample(line: u32, c: u32) -> f32 {
    let cols = params.dims.x;
    if line >= params.dims.w {
        return 0.0;
    }
    let x = lines[line * cols + c];
    if params.work.z == 0u {
        return x;
    }
    if params.work.z == 2u {
        let rows = params.dims.y;
        return x * view_weight(views[params.work.w + line / rows], f32(c), f32(line % rows));
    }
    let u = (f32(c) - params.detector.x) * params.detector.z;
    let v = (f32(line % params.dims.y) - params.detector.y) * params.detector.w;
    return x * cosine_weight(params.cone.x, u, v);
}

@compute @workgroup_size(64)
fn ramp_pad(@builtin(global_invocation_id) gid: vec3<u32>) {
    let idx = invocation(gid);
    let p = params.dims.z;
    if idx >= params.work.x * p {
        return;
    }
    let pair = idx / p;
    let k = idx % p;
    var z = vec2<f32>(0.0, 0.0);
    if k < params.dims.x {
        z = vec2<f32>(preweighted_sample(2u * pair, k), preweighted_sample(2u * pair + 1u, k));
    }
    packed[idx] = z;
}

@compute @workgroup_size(64)
fn ramp_multiply(@builtin(global_invocation_id) gid: vec3<u32>) {
    let idx = invocation(gid);
    let p = params.dims.z;
    if idx >= params.work.x * p {
        return;
    }
    packed[idx] = packed[idx] * response[idx % p];
}

@compute @workgroup_size(64)
fn ramp_crop(@builtin(global_invocation_id) gid: vec3<u32>) {
    let idx = invocation(gid);
    let cols = params.dims.x;
    if idx >= params.dims.w * cols {
        return;
    }
    let line = idx / cols;
    let c = idx % cols;
    let z = packed[(line / 2u) * params.dims.z + c];
    if line % 2u == 0u {
        lines[idx] = z.x;
    } else {
        lines[idx] = z.y;
    }
}
