// One iteration of scikit-image's SART (iradon_sart) on the device, in f32: the GPU port
// of src/cpu/radon.rs's SART. Per view (in the golden-ratio order the host chose):
// sart_deviation (one invocation per ray: the ray's sum and squared weights through the
// image, its deviation), sart_scatter (one invocation per ray of one phase: rays i ≡ phase
// mod 3 are three bins apart, so their updates never touch the same pixel), sart_apply
// (one invocation per pixel: image += λ·update, clipped, and the update cleared).
// The rays' set-up (SartRay, its cosines in f64) and the Hamming windows are made on the
// host, as the CPU makes them in f32.

#import radon_params

// dims: n, angles, the view, the phase; work: x extent of the dispatch, clip on;
// scale: λ, clip low, clip high.
@group(0) @binding(0) var<uniform> params: RadonParams;
// The sinogram's views, one line of n bins per angle.
@group(0) @binding(1) var<storage, read> lines: array<f32>;
// Every view's rays (angle-major): src/gpu/radon.rs: SartRayGpu.
@group(0) @binding(2) var<storage, read> rays: array<SartRayGpu>;
// The Hamming windows of every sample count, at each ray's `window` offset.
@group(0) @binding(3) var<storage, read> windows: array<f32>;
@group(0) @binding(4) var<storage, read_write> image: array<f32>;
@group(0) @binding(5) var<storage, read_write> update: array<f32>;
// Each ray's deviation (p − Σw·x)/Σw² of the current view.
@group(0) @binding(6) var<storage, read_write> deviation: array<f32>;

// One ray of one view (src/gpu/radon.rs: SartRayGpu).
struct SartRayGpu {
    ds: f32,
    dx: f32,
    dy: f32,
    x0: f32,
    y0: f32,
    // Samples k = 0 … ns; 0 with no samples (the ray misses the circle).
    ns: u32,
    // Where its Hamming window starts in `windows`.
    window: u32,
    // 1 when the ray has samples.
    live: u32,
}

// Sample k's pixel (row i, column j) and fractions.
fn sample_at(r: SartRayGpu, n: u32, k: u32) -> vec4<f32> {
    let centre = f32(n / 2u);
    let kr = f32(k);
    let ii = r.x0 + kr * r.dx + centre;
    let jj = r.y0 + kr * r.dy + centre;
    let fi = floor(ii);
    let fj = floor(jj);
    return vec4<f32>(fi, fj, ii - fi, jj - fj);
}

// The four bilinear weights of a sample (the CPU takes two of them in f64).
// mirrors src/cpu/radon.rs: sart_weights
fn sart_weights(di: f32, dj: f32, ds: f32) -> vec4<f32> {
    return vec4<f32>((1.0 - di) * (1.0 - dj) * ds, (1.0 - di) * dj * ds, di * (1.0 - dj) * ds, di * dj * ds);
}

// Which taps scikit-image uses: i > 0, j > 0 and the far taps inside the image.
// mirrors src/cpu/radon.rs: sart_taps
fn sart_taps(n: u32, i: i32, j: i32) -> vec4<bool> {
    let last = i32(n) - 1;
    return vec4<bool>(i > 0 && j > 0, i > 0 && j < last, i < last && j > 0, i < last && j < last);
}

// The ray's sum through the image and the sum of its squared weights.
// mirrors src/cpu/radon.rs: sart_ray_sum
fn sart_ray_sum(r: SartRayGpu, n: u32) -> vec2<f32> {
    var sum = 0.0;
    var norm = 0.0;
    for (var k = 0u; k <= r.ns; k++) {
        let s = sample_at(r, n, k);
        let i = i32(s.x);
        let j = i32(s.y);
        let w = sart_weights(s.z, s.w, r.ds);
        let t = sart_taps(n, i, j);
        for (var q = 0; q < 4; q++) {
            if (t[q]) {
                let p = image[u32(i + q / 2) * n + u32(j + q % 2)];
                sum += w[q] * p;
                norm += w[q] * w[q];
            }
        }
    }
    return vec2<f32>(sum, norm);
}

@compute @workgroup_size(64)
fn sart_deviation(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = params.dims.x;
    let i = gid.x + gid.y * params.work.x;
    if (i >= n) {
        return;
    }
    let view = params.dims.z;
    let r = rays[view * n + i];
    var d = 0.0;
    if (r.live == 1u) {
        let sn = sart_ray_sum(r, n);
        if (sn.y > 0.0) {
            d = -(sn.x - lines[view * n + i]) / sn.y;
        }
    }
    deviation[i] = d;
}

// Spreads ray i's deviation back along it: deviation · w · hamming to every tap.
// mirrors src/cpu/radon.rs: sart_ray_update
@compute @workgroup_size(64)
fn sart_scatter(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = params.dims.x;
    let i = (gid.x + gid.y * params.work.x) * 3u + params.dims.w;
    if (i >= n) {
        return;
    }
    let r = rays[params.dims.z * n + i];
    if (r.live != 1u) {
        return;
    }
    let dev = deviation[i];
    for (var k = 0u; k <= r.ns; k++) {
        let s = sample_at(r, n, k);
        let pi = i32(s.x);
        let pj = i32(s.y);
        let w = sart_weights(s.z, s.w, r.ds);
        let t = sart_taps(n, pi, pj);
        let h = windows[r.window + k];
        for (var q = 0; q < 4; q++) {
            if (t[q]) {
                let at = u32(pi + q / 2) * n + u32(pj + q % 2);
                update[at] += dev * w[q] * h;
            }
        }
    }
}

// image += λ·update, clipped to [low, high] when asked (numpy's clip); the update is
// cleared for the next view.
// mirrors src/cpu/radon.rs: np_clip
@compute @workgroup_size(64)
fn sart_apply(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = params.dims.x;
    let p = gid.x + gid.y * params.work.x;
    if (p >= n * n) {
        return;
    }
    var x = image[p] + params.scale.x * update[p];
    if (params.work.y == 1u) {
        x = min(max(x, params.scale.y), params.scale.z);
    }
    image[p] = x;
    update[p] = 0.0;
}
