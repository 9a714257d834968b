// Parameters of one FFT pass (one dispatch).
// Rust twin: src/gpu/fft.rs: FftParams (#[repr(C)], bytemuck). Eight 4-byte scalars, no
// padding; tests/gpu_fft.rs checks the offsets with naga.

struct FftParams {
    // Length of every line (a power of two, except in Bluestein's load and store, where
    // it is the data's length and log2n is that of span = M) and its base-2 logarithm.
    n: u32,
    log2n: u32,
    // Distance in elements between neighbours of a line: 1 along the last axis, the
    // product of the later axes' lengths along any other axis.
    stride: u32,
    // Number of lines (total elements / n).
    batch: u32,
    // Split stream: the stage s of this pass (0 reads the input in bit-reversed order).
    stage: u32,
    // 0 forward (exp(-2πi·kn/N)), 1 inverse (exp(+2πi·kn/N)).
    direction: u32,
    // Stockham: Ns, the length of the sub-transforms the earlier passes have finished.
    span: u32,
    // Multiplies every output: 1 except in the last pass of the whole transform, where
    // it is the normalisation factor.
    scale: f32,
}
