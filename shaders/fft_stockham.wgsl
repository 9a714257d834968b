// The Stockham autosort FFT (decimation in time): every pass reads a line at stride
// N/R and writes its R outputs at stride Ns, so the result comes out in natural order
// with no bit reversal. Radix 4, with one radix-2 pass first when log2 N is odd.
// One invocation per butterfly (N/R per line).
// Orchestration and the CPU twin of every function: src/gpu/fft.rs.

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
    let a = v0 + v2;
    let b = v0 - v2;
    let c = v1 + v3;
    let d = times_w4(v1 - v3);
    let out = (j / ns) * 4u * ns + k;
    let s = params.scale;
    dst[element_address(line, out)] = (a + c) * s;
    dst[element_address(line, out + ns)] = (b + d) * s;
    dst[element_address(line, out + 2u * ns)] = (a - c) * s;
    dst[element_address(line, out + 3u * ns)] = (b - d) * s;
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
