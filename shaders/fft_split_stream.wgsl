// The split-stream radix-2 FFT of Jansen et al. (VMV 2004), §4: decimation in
// frequency, with the input read in bit-reversed order in the first pass ("tangling"
// moved to the beginning), inputs read interleaved and outputs written concatenated,
// and every butterfly split in two: invocations in the first half of a line compute
// f_e = a + b, those in the second half f_o = (a − b)·w. One output per invocation.
// The last two stages are merged into one pass whose four quarters of the output are
// four small radix-4 kernels.
// Orchestration and the CPU twin of every function: src/gpu/fft.rs.

#import fft_params
#import fft_common

// Input element k of the current pass: in pass 0 the bit-reversed element of the
// original data (the tangling), later passes read straight.
// mirrors src/gpu/fft.rs: split_stream_load
fn split_stream_load(line: u32, k: u32) -> vec2<f32> {
    var j = k;
    if (params.stage == 0u) {
        j = reverse_low_bits(k, params.log2n);
    }
    return src[element_address(line, j)];
}

// The lowest `bits` bits of x in reverse order (0 when bits is 0).
// mirrors src/gpu/fft.rs: reverse_low_bits
fn reverse_low_bits(x: u32, bits: u32) -> u32 {
    if (bits == 0u) {
        return 0u;
    }
    return reverseBits(x) >> (32u - bits);
}

// Output t of stage s = params.stage: reads inputs 2i and 2i+1 (i = t mod N/2) and
// writes f_e to the first half of the line, f_o to the second.
// mirrors src/gpu/fft.rs: split_stream_element
fn split_stream_element(line: u32, t: u32) -> vec2<f32> {
    let half = params.n / 2u;
    let i = t % half;
    let a = split_stream_load(line, 2u * i);
    let b = split_stream_load(line, 2u * i + 1u);
    if (t < half) {
        return a + b; // f_e
    }
    // f_o: twiddle exp(∓2πi·j·2^s/N), j = the low (log2 N − s − 1) bits of i reversed.
    let bits = params.log2n - params.stage - 1u;
    let j = reverse_low_bits(i & ((1u << bits) - 1u), bits);
    return cmul(a - b, twiddles[j << params.stage]);
}

// Output t of the merged last two stages: quarter q = t / (N/4) of the output reads
// the four inputs 4r … 4r+3 (r = t mod N/4) and computes one of four sums.
// mirrors src/gpu/fft.rs: split_stream_last_two_element
fn split_stream_last_two_element(line: u32, t: u32) -> vec2<f32> {
    let quarter = params.n / 4u;
    let q = t / quarter;
    let r = t % quarter;
    let a0 = split_stream_load(line, 4u * r);
    let a1 = split_stream_load(line, 4u * r + 1u);
    let a2 = split_stream_load(line, 4u * r + 2u);
    let a3 = split_stream_load(line, 4u * r + 3u);
    switch q {
        case 0u: {
            return (a0 + a1) + (a2 + a3);
        }
        case 1u: {
            return (a0 - a1) + times_w4(a2 - a3);
        }
        case 2u: {
            return (a0 + a1) - (a2 + a3);
        }
        default: {
            return (a0 - a1) - times_w4(a2 - a3);
        }
    }
}

@compute @workgroup_size(64)
fn split_stream_pass(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let g = invocation(wid, nwg, lid);
    if (g >= params.n * params.batch) {
        return;
    }
    let lt = line_and_item(g, params.n);
    dst[element_address(lt.x, lt.y)] = split_stream_element(lt.x, lt.y) * params.scale;
}

@compute @workgroup_size(64)
fn split_stream_last_two(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let g = invocation(wid, nwg, lid);
    if (g >= params.n * params.batch) {
        return;
    }
    let lt = line_and_item(g, params.n);
    dst[element_address(lt.x, lt.y)] = split_stream_last_two_element(lt.x, lt.y) * params.scale;
}
