// Two real FFTs through one complex FFT: the split of src/gpu/fft.rs: two_real_ffts.
// The bindings are shared/fft_common.wgsl's: params.n = N, src = Z, the FFT of
// z = a + i·b; dst = [A_0 … A_{N−1}, B_0 … B_{N−1}].

#import fft_params
#import fft_common

// A_k = (Z_k + conj(Z_{N−k})) / 2 and B_k = (Z_k − conj(Z_{N−k})) / (2i), from
// zk = Z_k and zm = Z_{(N−k) mod N}; (d / 2i) = −i·d / 2 is a swap and a sign.
// mirrors src/cpu/fft.rs: split_two_real
fn split_two_real(zk: vec2<f32>, zm: vec2<f32>) -> array<vec2<f32>, 2> {
    let zc = vec2<f32>(zm.x, -zm.y);
    let s = zk + zc;
    let d = zk - zc;
    return array<vec2<f32>, 2>(0.5 * s, 0.5 * vec2<f32>(d.y, -d.x));
}

@compute @workgroup_size(64)
fn two_real_split(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let k = invocation(wid, nwg, lid);
    let n = params.n;
    if (k >= n) {
        return;
    }
    let ab = split_two_real(src[k], src[(n - k) % n]);
    dst[k] = ab[0];
    dst[n + k] = ab[1];
}
