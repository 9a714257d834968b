// Bluestein's algorithm: the DFT of a line of any length n as a circular convolution of
// length M = 2^⌈log2(2n − 1)⌉, so that the power-of-two FFTs of fft_stockham.wgsl (or
// fft_split_stream.wgsl) do the work. With the chirp c_j = exp(∓iπ·j²/n), and
// jk = (j² + k² − (k − j)²) / 2,
//
//     X_k = Σ_j x_j·exp(∓2πi·jk/n) = c_k · Σ_j (x_j·c_j)·conj(c_{k−j}),
//
// the convolution of a_j = x_j·c_j (zero-padded to M) with b_m = conj(c_m),
// m = −(n − 1) … n − 1 (wrapped mod M). Three kernels around two length-M FFTs of the
// work lines (M contiguous values per line):
//   bluestein_load      a = x·c, zero-padded to M       (data -> work)
//   bluestein_multiply  FFT_M(a) times B/M, B = FFT_M(b) (work -> work)
//   bluestein_store     X = c·conv, times the scale      (work -> data)
// The chirp (reduced j² mod 2n in integers, then exp in f64) and B/M (an f64 FFT) are
// made on the CPU and rounded once to f32. Orchestration and the CPU twin of every
// function: src/gpu/fft.rs.
//
// Parameters: n, stride, batch describe the data's lines (as for every pass); span is M
// and log2n is log2 M. Binding 3 (`twiddles`) holds the step's table: the chirp
// c_0 … c_{n−1} for load and store, B/M (M values) for multiply.

#import fft_params
#import fft_common

// Work value j of line `line`: x_j·c_j for j < n, 0 for the padding.
// mirrors src/gpu/fft.rs: bluestein_load_element
fn bluestein_load_element(line: u32, j: u32) -> vec2<f32> {
    if (j >= params.n) {
        return vec2<f32>(0.0, 0.0);
    }
    return cmul(src[element_address(line, j)], twiddles[j]);
}

// Work value g (line g / M, bin g mod M) times the kernel's spectrum B/M.
// mirrors src/gpu/fft.rs: bluestein_multiply_element
fn bluestein_multiply_element(g: u32) -> vec2<f32> {
    return cmul(src[g], twiddles[g % params.span]);
}

// Output k of line `line`: the convolution's value k times c_k, times the scale.
// mirrors src/gpu/fft.rs: bluestein_store_element
fn bluestein_store_element(line: u32, k: u32) -> vec2<f32> {
    return cmul(src[line * params.span + k], twiddles[k]) * params.scale;
}

@compute @workgroup_size(64)
fn bluestein_load(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let g = invocation(wid, nwg, lid);
    let m = params.span;
    if (g >= m * params.batch) {
        return;
    }
    dst[g] = bluestein_load_element(g / m, g % m);
}

@compute @workgroup_size(64)
fn bluestein_multiply(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let g = invocation(wid, nwg, lid);
    if (g >= params.span * params.batch) {
        return;
    }
    dst[g] = bluestein_multiply_element(g);
}

@compute @workgroup_size(64)
fn bluestein_store(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let g = invocation(wid, nwg, lid);
    if (g >= params.n * params.batch) {
        return;
    }
    // Along a strided axis neighbouring invocations write neighbouring lines.
    let lk = line_and_item(g, params.n);
    dst[element_address(lk.x, lk.y)] = bluestein_store_element(lk.x, lk.y);
}
