// scikit-image's Radon transform (rotate, then sum the columns) and the pixel-driven
// backprojection of its iradon, in f32: the GPU port of src/cpu/radon.rs.
// radon_column: one invocation per (bin, angle); iradon_backproject: one per output
// pixel. Layouts as on the CPU: the square image row-major, the sinogram (bin, angle)
// row-major, the filtered views one line of n bins per angle.

#import radon_params

@group(0) @binding(0) var<uniform> params: RadonParams;
// radon: the square image; iradon: the filtered views.
@group(0) @binding(1) var<storage, read> src: array<f32>;
// radon: six inverse-map coefficients per angle; iradon: the views' spline curvatures
// (cubic) or one unused value.
@group(0) @binding(2) var<storage, read> aux: array<f32>;
// iradon: per angle cos θ, sin θ (rounded to f32) and what that rounding left out
// (src/cpu/radon.rs: Angle); radon: one unused entry.
@group(0) @binding(3) var<storage, read> trig: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> out: array<f32>;

// The square image's pixel (r, c), zero outside (skimage's get_pixel2d, mode 'C').
fn pixel(n: i32, r: i32, c: i32) -> f32 {
    if (r < 0 || c < 0 || r >= n || c >= n) {
        return 0.0;
    }
    return src[u32(r) * u32(n) + u32(c)];
}

// Bilinear interpolation at row r, column c, all in f32 (the CPU takes the weights
// 1 − d and the blends in f64, as scikit-image's compiled code does; WGSL has no f64).
// mirrors src/cpu/radon.rs: bilinear
fn bilinear(n: i32, r: f32, c: f32) -> f32 {
    let minr = floor(r);
    let minc = floor(c);
    let maxr = ceil(r);
    let maxc = ceil(c);
    let dr = r - minr;
    let dc = c - minc;
    let r0 = i32(minr);
    let r1 = i32(maxr);
    let c0 = i32(minc);
    let c1 = i32(maxc);
    let top = (1.0 - dc) * pixel(n, r0, c0) + dc * pixel(n, r0, c1);
    let bottom = (1.0 - dc) * pixel(n, r1, c0) + dc * pixel(n, r1, c1);
    return (1.0 - dr) * top + dr * bottom;
}

// Bin k of one angle's column: the image warped by the angle's inverse map, summed
// over the rows in order.
// mirrors src/cpu/radon.rs: radon_column
@compute @workgroup_size(64)
fn radon_column(@builtin(global_invocation_id) gid: vec3<u32>) {
    let idx = gid.x + gid.y * params.work.x;
    let n = params.dims.x;
    let angles = params.dims.y;
    if (idx >= n * angles) {
        return;
    }
    let k = idx / angles;
    let a = idx % angles;
    let h0 = aux[6u * a];
    let h1 = aux[6u * a + 1u];
    let h2 = aux[6u * a + 2u];
    let h3 = aux[6u * a + 3u];
    let h4 = aux[6u * a + 4u];
    let h5 = aux[6u * a + 5u];
    let x = f32(k);
    var acc = 0.0;
    for (var r = 0u; r < n; r++) {
        let y = f32(r);
        let col = h0 * x + h1 * y + h2;
        let row = h3 * x + h4 * y + h5;
        acc += bilinear(i32(n), row, col);
    }
    out[idx] = acc;
}

// View `k`'s filtered line (bins x_j = j − n/2) read at t: linear (np.interp), nearest
// (a tie to the left, decided with t + t_lo) or the cubic spline of the curvatures; 0
// outside [x_0, x_{n−1}].
// mirrors src/cpu/radon.rs: iradon_sample
fn iradon_sample(kind: u32, base: u32, n: u32, t: f32, t_lo: f32) -> f32 {
    let h = f32(n / 2u);
    if (!(t >= -h && t <= f32(n - 1u) - h)) {
        return 0.0;
    }
    let f = floor(t);
    let j = u32(f + h);
    if (kind == 0u) {
        if (j == n - 1u || f == t) {
            return src[base + j];
        }
        return (src[base + j + 1u] - src[base + j]) * (t - f) + src[base + j];
    }
    if (kind == 1u) {
        // Against the midpoint itself (t − f rounds for t just above −1 … 0); t − mid
        // is exact near the midpoint, so t_lo decides a tie.
        if ((t - (f + 0.5)) + t_lo > 0.0) {
            return src[base + j + 1u];
        }
        return src[base + j];
    }
    let i = min(j, n - 2u);
    let xi = f32(i) - h;
    let a = xi + 1.0 - t;
    let b = t - xi;
    let sixth = 1.0 / 6.0;
    let m0 = aux[base + i];
    let m1 = aux[base + i + 1u];
    return (m0 * a * a * a + m1 * b * b * b) * sixth
        + (src[base + i] - m0 * sixth) * a
        + (src[base + i + 1u] - m1 * sixth) * b;
}

// Output pixel (row, col): π/(2A)·Σ_k sample_k(y·cos θ_k − x·sin θ_k) with
// x = row − size/2, y = col − size/2, zero outside the inscribed circle when asked.
// mirrors src/cpu/radon.rs: iradon_backproject
@compute @workgroup_size(64)
fn iradon_backproject(@builtin(global_invocation_id) gid: vec3<u32>) {
    let idx = gid.x + gid.y * params.work.x;
    let n = params.dims.x;
    let angles = params.dims.y;
    let size = params.dims.z;
    if (idx >= size * size) {
        return;
    }
    let radius = i32(size / 2u);
    let x = i32(idx / size) - radius;
    let y = i32(idx % size) - radius;
    if (params.work.y == 1u && x * x + y * y > radius * radius) {
        out[idx] = 0.0;
        return;
    }
    let xr = f32(x);
    let yr = f32(y);
    var acc = 0.0;
    for (var k = 0u; k < angles; k++) {
        let a = trig[k];
        let t = yr * a.x - xr * a.y;
        let t_lo = yr * a.z - xr * a.w;
        acc += iradon_sample(params.dims.w, k * n, n, t, t_lo);
    }
    out[idx] = acc * params.scale.x / params.scale.y;
}
