// The Stockham autosort FFT (decimation in time): every pass reads a line at stride
// N/R and writes its R outputs at stride Ns, so the result comes out in natural order
// with no bit reversal. Radix 4, with one radix-2 pass first when log2 N is odd.
// One invocation per butterfly (N/R per line), every pass through the storage buffers;
// or, for N ≤ LOCAL_MAX_N, one workgroup per run of neighbouring lines doing every pass
// in workgroup memory (stockham_local).
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
// Workgroup-memory path, N ≤ LOCAL_MAX_N: each workgroup takes LINES = local_lines(N)
// neighbouring lines, reads them from the storage buffer once, runs every pass on the
// two halves of `local_data` (the same butterflies as above, with the same twiddles)
// and writes them once. Along the last axis the lines lie end to end and the
// workgroup reads LINES·N consecutive values; along a strided axis neighbouring
// invocations read the same element of neighbouring lines, which are neighbours in
// memory (16 lines: 128 consecutive bytes), so the reads and writes stay coalesced
// either way, and a short line keeps every invocation busy.
// ---------------------------------------------------------------------------------

// Two halves of 1024 complex values: 16 KiB, the smallest workgroup memory WebGPU
// guarantees. Rust twin: src/gpu/fft.rs: LOCAL_MAX_N.
const LOCAL_MAX_N: u32 = 1024u;
// At most this many lines per workgroup: 16 complex f32 values are 128 bytes, a
// cache line of most GPUs. Rust twin: src/gpu/fft.rs: LOCAL_MAX_LINES.
const LOCAL_MAX_LINES: u32 = 16u;
var<workgroup> local_data: array<vec2<f32>, 2048>;

// The lines one workgroup transforms: as many as fill LOCAL_MAX_N values, at most
// LOCAL_MAX_LINES.
// mirrors src/gpu/fft.rs: local_lines
fn local_lines(n: u32) -> u32 {
    return min(LOCAL_MAX_LINES, LOCAL_MAX_N / n);
}

// Line l of the workgroup lies in each half at l·n, turned by l·(16 / LINES) places
// (element i at (i + turn) mod n), so that the neighbouring invocations of a strided
// read, which store the same element of neighbouring lines, write to different memory
// banks.
fn local_turn(l: u32, lines: u32) -> u32 {
    return l * (LOCAL_MAX_LINES / lines);
}

// The slot of element i of the line at `base` (a half's start plus l·n) turned by `turn`.
fn local_slot(base: u32, turn: u32, i: u32) -> u32 {
    return base + ((i + turn) & (params.n - 1u));
}

// stockham_radix4_butterfly on the line at src_base -> the line at dst_base.
// mirrors src/gpu/fft.rs: stockham_radix4_butterfly
fn local_radix4_butterfly(src_base: u32, dst_base: u32, turn: u32, ns: u32, j: u32) {
    let quarter = params.n / 4u;
    let k = j % ns;
    let step = params.n / (4u * ns);
    let v0 = local_data[local_slot(src_base, turn, j)];
    let v1 = cmul(local_data[local_slot(src_base, turn, j + quarter)], twiddles[k * step]);
    let v2 = cmul(local_data[local_slot(src_base, turn, j + 2u * quarter)], twiddles[2u * k * step]);
    let v3 = cmul(local_data[local_slot(src_base, turn, j + 3u * quarter)], twiddles[3u * k * step]);
    let y = radix4_dft(v0, v1, v2, v3);
    let out = (j / ns) * 4u * ns + k;
    local_data[local_slot(dst_base, turn, out)] = y[0];
    local_data[local_slot(dst_base, turn, out + ns)] = y[1];
    local_data[local_slot(dst_base, turn, out + 2u * ns)] = y[2];
    local_data[local_slot(dst_base, turn, out + 3u * ns)] = y[3];
}

// stockham_radix2_butterfly on the line at src_base -> the line at dst_base.
// mirrors src/gpu/fft.rs: stockham_radix2_butterfly
fn local_radix2_butterfly(src_base: u32, dst_base: u32, turn: u32, ns: u32, j: u32) {
    let k = j % ns;
    let step = params.n / (2u * ns);
    let v0 = local_data[local_slot(src_base, turn, j)];
    let v1 = cmul(local_data[local_slot(src_base, turn, j + params.n / 2u)], twiddles[k * step]);
    let out = (j / ns) * 2u * ns + k;
    local_data[local_slot(dst_base, turn, out)] = v0 + v1;
    local_data[local_slot(dst_base, turn, out + ns)] = v0 - v1;
}

// Item k of the workgroup's LINES·N values as (line, element): line after line along
// the last axis, element after element (the lines of each side by side) otherwise, so
// that neighbouring invocations touch neighbouring addresses.
fn local_item(k: u32, lines: u32) -> vec2<u32> {
    if (params.stride == 1u) {
        return vec2<u32>(k >> params.log2n, k & (params.n - 1u));
    }
    return vec2<u32>(k % lines, k / lines);
}

@compute @workgroup_size(64)
fn stockham_local(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    // Uniform across the workgroup (workgroup id and parameters only), so the early
    // return and the barriers below are in uniform control flow.
    let n = params.n;
    let lines = local_lines(n);
    let first = (wid.y * nwg.x + wid.x) * lines;
    if (first >= params.batch) {
        return;
    }
    // The last workgroup may hold fewer lines: the missing ones are neither read nor
    // written (their butterflies run on whatever their slots hold).
    let held = min(lines, params.batch - first);
    for (var k = lid; k < lines * n; k += WORKGROUP) {
        let li = local_item(k, lines);
        if (li.x < held) {
            let slot = local_slot(li.x * n, local_turn(li.x, lines), li.y);
            local_data[slot] = src[element_address(first + li.x, li.y)];
        }
    }
    workgroupBarrier();
    var src_half = 0u;
    var dst_half = LOCAL_MAX_N;
    var ns = 1u;
    // Butterfly j of the workgroup is butterfly j mod (n/R) of line j / (n/R).
    if (params.log2n % 2u == 1u) {
        let shift = params.log2n - 1u;
        for (var j = lid; j < lines * n / 2u; j += WORKGROUP) {
            let l = j >> shift;
            let base = l * n;
            let turn = local_turn(l, lines);
            local_radix2_butterfly(src_half + base, dst_half + base, turn, ns, j & (n / 2u - 1u));
        }
        workgroupBarrier();
        let t = src_half;
        src_half = dst_half;
        dst_half = t;
        ns = 2u;
    }
    while (ns < n) {
        let shift = params.log2n - 2u;
        for (var j = lid; j < lines * n / 4u; j += WORKGROUP) {
            let l = j >> shift;
            let base = l * n;
            let turn = local_turn(l, lines);
            local_radix4_butterfly(src_half + base, dst_half + base, turn, ns, j & (n / 4u - 1u));
        }
        workgroupBarrier();
        let t = src_half;
        src_half = dst_half;
        dst_half = t;
        ns *= 4u;
    }
    for (var k = lid; k < lines * n; k += WORKGROUP) {
        let li = local_item(k, lines);
        if (li.x < held) {
            let slot = local_slot(src_half + li.x * n, local_turn(li.x, lines), li.y);
            dst[element_address(first + li.x, li.y)] = local_data[slot] * params.scale;
        }
    }
}
