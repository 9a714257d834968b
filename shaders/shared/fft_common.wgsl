// Bindings and helpers shared by the FFT stages (shaders/fft_split_stream.wgsl,
// fft_stockham.wgsl and fft_two_real.wgsl). Complex numbers are vec2<f32> (re, im).

#import fft_params

@group(0) @binding(0) var<uniform> params: FftParams;
@group(0) @binding(1) var<storage, read> src: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read_write> dst: array<vec2<f32>>;
// twiddles[m] = exp(∓2πi·m/n), m = 0 … n−1, made exactly in f64 on the CPU
// (cpu::dft::twiddle) and rounded once to f32.
@group(0) @binding(3) var<storage, read> twiddles: array<vec2<f32>>;

const WORKGROUP: u32 = 64u;

fn cmul(a: vec2<f32>, b: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

// Multiplies by exp(∓2πi/4) = ∓i exactly (a swap and a sign).
// mirrors src/gpu/fft.rs: times_w4
fn times_w4(v: vec2<f32>) -> vec2<f32> {
    if (params.direction == 0u) {
        return vec2<f32>(v.y, -v.x);
    }
    return vec2<f32>(-v.y, v.x);
}

// The buffer index of element j of line `line`: lines along the last axis are
// contiguous (stride 1); along other axes, line l starts at
// (l / stride)·n·stride + l % stride and its elements are `stride` apart.
// mirrors src/gpu/fft.rs: element_address
fn element_address(line: u32, j: u32) -> u32 {
    let s = params.stride;
    return (line / s) * params.n * s + line % s + j * s;
}

// The linear invocation number of a 2-D dispatch (rows of at most 65535 workgroups).
fn invocation(wid: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wid.y * nwg.x + wid.x) * WORKGROUP + lid;
}

// Splits invocation g into (line, item), `per_line` items per line. Along the last
// axis neighbouring invocations take neighbouring items of one line; along a strided
// axis they take the same item of neighbouring lines, which are neighbours in memory.
fn line_and_item(g: u32, per_line: u32) -> vec2<u32> {
    if (params.stride == 1u) {
        return vec2<u32>(g / per_line, g % per_line);
    }
    return vec2<u32>(g % params.batch, g / params.batch);
}
