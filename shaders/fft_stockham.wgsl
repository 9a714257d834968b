// The Stockham autosort FFT (decimation in time): every pass reads a line at stride
// N/R and writes its R outputs at stride Ns, so the result comes out in natural order
// with no bit reversal. Radix 4, with one radix-2 pass first when log2 N is odd.
// One invocation per butterfly (N/R per line), every pass through the storage buffers;
// or, for N ≤ LOCAL_MAX_N, one workgroup per line doing every pass in workgroup memory
// (stockham_local).
// Orchestration and the CPU twin of every function: src/gpu/fft.rs.

#import fft_params
#import fft_common

// Radix-4 butterfly j of a line: inputs j + m·N/4 (m = 0 … 3) times
// exp(∓2πi·m·k/(4Ns)), k = j mod Ns, then a 4-point DFT, written to
// (j / Ns)·4Ns + k + m·Ns.
// mirrors src/gpu/fft.rs: stockham_radix4_butterfly
fn stockham_radix4_butterfly(line: u32, j: u32) {
    let ns = params.span;
    let quarter = params.n / 4u;
    let k = j % ns;
    let step = params.n / (4u * ns); // exp(∓2πi·k/(4Ns)) = twiddles[k·step]
    let v0 = src[element_address(line, j)];
    let v1 = cmul(src[element_address(line, j + quarter)], twiddles[k * step]);
    let v2 = cmul(src[element_address(line, j + 2u * quarter)], twiddles[2u * k * step]);
    let v3 = cmul(src[element_address(line, j + 3u * quarter)], twiddles[3u * k * step]);
    let y = radix4_dft(v0, v1, v2, v3);
    let out = (j / ns) * 4u * ns + k;
    let s = params.scale;
    dst[element_address(line, out)] = y[0] * s;
    dst[element_address(line, out + ns)] = y[1] * s;
    dst[element_address(line, out + 2u * ns)] = y[2] * s;
    dst[element_address(line, out + 3u * ns)] = y[3] * s;
}

// The 4-point DFT (unscaled): y_m = Σ_r v_r·w₄^(m·r), w₄ = ∓i, in two radix-2 steps.
// mirrors src/gpu/fft.rs: radix4_dft
fn radix4_dft(v0: vec2<f32>, v1: vec2<f32>, v2: vec2<f32>, v3: vec2<f32>) -> array<vec2<f32>, 4> {
    let a = v0 + v2;
    let b = v0 - v2;
    let c = v1 + v3;
    let d = times_w4(v1 - v3);
    return array<vec2<f32>, 4>(a + c, b + d, a - c, b - d);
}

// Radix-2 butterfly j: inputs j and j + N/2, the second times exp(∓2πi·k/(2Ns)).
// mirrors src/gpu/fft.rs: stockham_radix2_butterfly
fn stockham_radix2_butterfly(line: u32, j: u32) {
    let ns = params.span;
    let k = j % ns;
    let step = params.n / (2u * ns);
    let v0 = src[element_address(line, j)];
    let v1 = cmul(src[element_address(line, j + params.n / 2u)], twiddles[k * step]);
    let out = (j / ns) * 2u * ns + k;
    dst[element_address(line, out)] = (v0 + v1) * params.scale;
    dst[element_address(line, out + ns)] = (v0 - v1) * params.scale;
}

@compute @workgroup_size(64)
fn stockham_radix4(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let g = invocation(wid, nwg, lid);
    let per_line = params.n / 4u;
    if (g >= per_line * params.batch) {
        return;
    }
    let lj = line_and_item(g, per_line);
    stockham_radix4_butterfly(lj.x, lj.y);
}

@compute @workgroup_size(64)
fn stockham_radix2(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let g = invocation(wid, nwg, lid);
    let per_line = params.n / 2u;
    if (g >= per_line * params.batch) {
        return;
    }
    let lj = line_and_item(g, per_line);
    stockham_radix2_butterfly(lj.x, lj.y);
}

// ---------------------------------------------------------------------------------
// Workgroup-memory path: one workgroup per line, N ≤ LOCAL_MAX_N. The line is read from
// the storage buffer once, every pass runs on the two halves of `local_data` (the same
// butterflies as above, with the same twiddles), and the result is written once.
// ---------------------------------------------------------------------------------

// Two lines of 1024 complex values: 16 KiB, the smallest workgroup memory WebGPU
// guarantees. Rust twin: src/gpu/fft.rs: LOCAL_MAX_N.
const LOCAL_MAX_N: u32 = 1024u;
var<workgroup> local_data: array<vec2<f32>, 2048>;

// stockham_radix4_butterfly on local_data[src_half …] -> local_data[dst_half …].
// mirrors src/gpu/fft.rs: stockham_radix4_butterfly
fn local_radix4_butterfly(src_half: u32, dst_half: u32, ns: u32, j: u32) {
    let quarter = params.n / 4u;
    let k = j % ns;
    let step = params.n / (4u * ns);
    let v0 = local_data[src_half + j];
    let v1 = cmul(local_data[src_half + j + quarter], twiddles[k * step]);
    let v2 = cmul(local_data[src_half + j + 2u * quarter], twiddles[2u * k * step]);
    let v3 = cmul(local_data[src_half + j + 3u * quarter], twiddles[3u * k * step]);
    let y = radix4_dft(v0, v1, v2, v3);
    let out = dst_half + (j / ns) * 4u * ns + k;
    local_data[out] = y[0];
    local_data[out + ns] = y[1];
    local_data[out + 2u * ns] = y[2];
    local_data[out + 3u * ns] = y[3];
}

// stockham_radix2_butterfly on local_data[src_half …] -> local_data[dst_half …].
// mirrors src/gpu/fft.rs: stockham_radix2_butterfly
fn local_radix2_butterfly(src_half: u32, dst_half: u32, ns: u32, j: u32) {
    let k = j % ns;
    let step = params.n / (2u * ns);
    let v0 = local_data[src_half + j];
    let v1 = cmul(local_data[src_half + j + params.n / 2u], twiddles[k * step]);
    let out = dst_half + (j / ns) * 2u * ns + k;
    local_data[out] = v0 + v1;
    local_data[out + ns] = v0 - v1;
}

@compute @workgroup_size(64)
fn stockham_local(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    // Uniform across the workgroup (workgroup id and parameters only), so the early
    // return and the barriers below are in uniform control flow.
    let line = wid.y * nwg.x + wid.x;
    if (line >= params.batch) {
        return;
    }
    let n = params.n;
    for (var k = lid; k < n; k += WORKGROUP) {
        local_data[k] = src[element_address(line, k)];
    }
    workgroupBarrier();
    var src_half = 0u;
    var dst_half = LOCAL_MAX_N;
    var ns = 1u;
    if (params.log2n % 2u == 1u) {
        for (var j = lid; j < n / 2u; j += WORKGROUP) {
            local_radix2_butterfly(src_half, dst_half, ns, j);
        }
        workgroupBarrier();
        let t = src_half;
        src_half = dst_half;
        dst_half = t;
        ns = 2u;
    }
    while (ns < n) {
        for (var j = lid; j < n / 4u; j += WORKGROUP) {
            local_radix4_butterfly(src_half, dst_half, ns, j);
        }
        workgroupBarrier();
        let t = src_half;
        src_half = dst_half;
        dst_half = t;
        ns *= 4u;
    }
    for (var k = lid; k < n; k += WORKGROUP) {
        dst[element_address(line, k)] = local_data[src_half + k] * params.scale;
    }
}
