//! The GPU Fourier transform: complex FFTs of any length in f32, two algorithms (three
//! variants) for powers of two and Bluestein's algorithm for every other length, that
//! compute the same thing as [`crate::cpu::dft::dft_nd`] (same
//! [`Direction`], same [`Normalization`], DC at index 0, row-major arrays with the last
//! axis fastest). Accuracy and timings measured on lavapipe: `docs/fft.md`.
//!
//! - [`GpuFftVariant::SplitStream`] — the teaching version: the split-stream radix-2
//!   decimation-in-frequency FFT of Jansen et al., *Fourier volume rendering on the
//!   GPU using a split-stream FFT* (VMV 2004), §4. `log2 N` stages; the bit reversal
//!   ("tangling") is folded into the first pass, which reads its input from
//!   bit-reversed indices; every pass reads its input interleaved (elements `2i`,
//!   `2i+1`) and writes its output concatenated: the butterfly is split in two, the
//!   invocations of the first half of a line computing `f_e = a + b`, those of the
//!   second half `f_o = (a − b)·w`, one output each. The last two stages are merged
//!   into one pass (four radix-4 sums, one per quarter of the output), so a line of
//!   length `N ≥ 4` takes `log2 N − 1` passes. Shader: `shaders/fft_split_stream.wgsl`.
//! - [`GpuFftVariant::Stockham`] — the fast path: Stockham autosort passes
//!   (decimation in time), radix 4 with one radix-2 pass first when `log2 N` is odd:
//!   no bit reversal, `⌈log2 N / 2⌉` passes, one invocation per butterfly. Lines of
//!   up to [`LOCAL_MAX_N`] values are read once into workgroup memory, go through
//!   every pass there (one workgroup per [`local_lines`] neighbouring lines, one
//!   dispatch per axis) and are written once; [`GpuFftVariant::StockhamGlobal`] runs every pass through the storage
//!   buffers at any length. Shader: `shaders/fft_stockham.wgsl`.
//!
//! **Axes.** An N-D transform runs the 1-D batches along every axis in turn. Lines
//! along an axis other than the last are addressed with a stride parameter
//! ([`FftParams::stride`]), not transposed: the ping-pong buffers already give every
//! pass a fresh output, so a transpose would only add passes and traffic. Along a
//! strided axis neighbouring invocations take the same element of neighbouring lines,
//! which are neighbours in memory, so the accesses stay coalesced.
//!
//! **Twiddles.** One table per axis length, `exp(∓2πi·m/N)` for `m = 0 … N−1`, made in
//! f64 with the exact [`twiddle`] of the oracle and rounded once to f32; multiplications
//! by `∓i` are exact swaps ([`times_w4`]). No twiddle is computed on the device.
//!
//! **Scale.** The normalisation factor of the whole transform is applied once, in the
//! last pass (every other pass multiplies by 1, exactly).
//!
//! **Mirrors.** Every per-element WGSL function has a Rust twin of the same name in
//! this file (`split_stream_element`, `split_stream_last_two_element`,
//! `stockham_radix4_butterfly`, …), and [`split_stream_reference`] and
//! [`stockham_reference`] run the same pass plans on the CPU in f64, so the algorithm
//! can be checked without a device.
//!
//! **Any length.** An axis whose length `n` is not a power of two runs Bluestein's
//! algorithm (Bluestein, *A linear filtering approach to the computation of discrete
//! Fourier transform*, IEEE Trans. Audio Electroacoust. 18(4), 1970): with the chirp
//! `c_j = exp(∓iπ·j²/n)`, `X_k = c_k·Σ_j (x_j·c_j)·conj(c_{k−j})`, a circular
//! convolution of length `M = 2^⌈log2(2n − 1)⌉` done by two power-of-two FFTs of the
//! same variant on work lines of `M` values: a load (`x·c`, zero-padded), the forward
//! passes, a multiplication by the kernel's spectrum `B/M`, the inverse passes and a
//! store (`c·conv`), [`axis_plan`]. The chirp (`j²` reduced modulo `2n` in integers) and
//! `B/M` are made in f64 on the CPU and rounded once to f32, like the twiddles. Shader:
//! `shaders/fft_bluestein.wgsl`; CPU twins: [`bluestein_load_element`],
//! [`bluestein_multiply_element`], [`bluestein_store_element`], run by
//! [`reference_line`].
//!
//! **Limits.** In one run the array, and Bluestein's work lines (`M` values per line of
//! the longest such axis), must each fit one storage binding
//! (`max_storage_buffer_binding_size`, 128 MiB on lavapipe, i.e. 16 Mi complex values).
//! [`fft_nd_timed`] splits a larger N-D array into slabs ([`FftSplitPlan`]) and takes a
//! larger 1-D array in four steps over a 2-D view of it; only a prime length past one
//! binding is refused, with [`Error::TooLarge`].
//!
//! ```no_run
//! use rustfft::num_complex::Complex;
//! use voxlab::cpu::dft::{Direction, Normalization};
//! use voxlab::gpu::fft::{fft_nd, GpuFftVariant};
//! use voxlab::gpu::GpuContext;
//!
//! // The transform of a delta at the origin is a constant.
//! let ctx = GpuContext::new()?;
//! let mut x = vec![Complex::new(0.0f32, 0.0); 8 * 8];
//! x[0] = Complex::new(1.0, 0.0);
//! let (dir, norm) = (Direction::Forward, Normalization::Unnormalized);
//! let y = fft_nd(&ctx, &x, &[8, 8], dir, norm, GpuFftVariant::Stockham)?;
//! assert!(y.iter().all(|&v| v == Complex::new(1.0, 0.0)));
//! # Ok::<(), voxlab::Error>(())
//! ```
#![expect(
    clippy::needless_range_loop,
    reason = "Keeps the CPU twins easily comparable to the shaders"
)]

use super::context::{GpuContext, Kernel};
use super::plan::Pieces;
use crate::cpu::dft::{twiddle, Direction, Normalization};
use crate::error::{Error, Result};
use rustfft::num_complex::Complex;
use std::time::Instant;
use wgpu::util::DeviceExt;

/// `shaders/shared/fft_params.wgsl`: the WGSL twin of [`FftParams`].
pub const PARAMS_WGSL: &str = super::shaders::FFT_PARAMS;

/// Invocations per workgroup (`WORKGROUP` in `shaders/shared/fft_common.wgsl`).
const WORKGROUP: u32 = 64;

/// The longest line the Stockham variant transforms in workgroup memory: two lines of
/// 1024 complex f32 values are 16 KiB, the least workgroup memory WebGPU guarantees
/// (`LOCAL_MAX_N` in `shaders/fft_stockham.wgsl`).
pub const LOCAL_MAX_N: usize = 1024;

/// The most lines one workgroup of the workgroup-memory path transforms: 16 complex f32
/// values are 128 bytes, a cache line of most GPUs (`LOCAL_MAX_LINES` in
/// `shaders/fft_stockham.wgsl`).
pub const LOCAL_MAX_LINES: usize = 16;

/// The lines of length `n` (a power of two, at most [`LOCAL_MAX_N`]) one workgroup of
/// [`FftPass::StockhamLocal`] transforms: as many as fill [`LOCAL_MAX_N`] values, at
/// most [`LOCAL_MAX_LINES`]. Neighbouring lines: end to end along the last axis, side by
/// side (the same element of each next to each other in memory) along the others.
/// mirrors shaders/fft_stockham.wgsl: local_lines
pub fn local_lines(n: usize) -> usize {
    LOCAL_MAX_LINES.min(LOCAL_MAX_N / n)
}

/// Which GPU FFT to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GpuFftVariant {
    /// Jansen et al.'s split-stream radix-2 DIF FFT (the teaching version).
    SplitStream,
    /// Radix-4 Stockham autosort (the fast path): lines of up to [`LOCAL_MAX_N`]
    /// values do every pass in workgroup memory (one dispatch per axis), longer lines
    /// go through the storage buffers as [`GpuFftVariant::StockhamGlobal`] does.
    Stockham,
    /// The same Stockham passes, every one through the storage buffers (one dispatch
    /// per pass), whatever the length: the plain form of the algorithm, kept to check
    /// and to time the workgroup-memory path against.
    StockhamGlobal,
}

impl GpuFftVariant {
    pub const ALL: [GpuFftVariant; 3] = [
        GpuFftVariant::SplitStream,
        GpuFftVariant::Stockham,
        GpuFftVariant::StockhamGlobal,
    ];

    /// The complete WGSL module of this variant: `shaders/fft_split_stream.wgsl` or
    /// `shaders/fft_stockham.wgsl` and their imports.
    pub fn shader_source(self) -> String {
        super::shaders::resolve(match self {
            GpuFftVariant::SplitStream => "fft_split_stream",
            GpuFftVariant::Stockham | GpuFftVariant::StockhamGlobal => "fft_stockham",
        })
    }
}

/// Parameters of one FFT pass, shared with `shaders/shared/fft_params.wgsl: FftParams`
/// (32 bytes, eight 4-byte scalars, no padding; `tests/gpu_fft.rs` checks the layout).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FftParams {
    /// Line length (Bluestein's steps: the data's length, which need not be a power of
    /// two).
    pub n: u32,
    /// `log2 n`.
    pub log2n: u32,
    /// Distance in elements between neighbours of a line (1 along the last axis).
    pub stride: u32,
    /// Number of lines.
    pub batch: u32,
    /// Split stream: the stage `s` of this pass (0 reads bit-reversed).
    pub stage: u32,
    /// 0 forward, 1 inverse.
    pub direction: u32,
    /// Stockham: `Ns`, the length of the sub-transforms already finished.
    pub span: u32,
    /// Multiplies every output (the normalisation in the last pass, else 1).
    pub scale: f32,
}

/// One pass of a 1-D transform: which kernel, and its stage (split stream) or span
/// (Stockham).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FftPass {
    /// `split_stream_pass` at stage `s`.
    SplitStream { stage: u32 },
    /// `split_stream_last_two`: stages `log2 N − 2` and `log2 N − 1` merged
    /// (`stage` is `log2 N − 2`; 0 when it is also the first pass).
    SplitStreamLastTwo { stage: u32 },
    /// `stockham_radix2` with `Ns = span`.
    Radix2 { span: u32 },
    /// `stockham_radix4` with `Ns = span`.
    Radix4 { span: u32 },
    /// `stockham_local`: every Stockham pass of lines of at most [`LOCAL_MAX_N`]
    /// values, in workgroup memory, one workgroup per [`local_lines`] neighbouring
    /// lines.
    StockhamLocal,
}

impl FftPass {
    fn entry_point(self) -> &'static str {
        match self {
            FftPass::SplitStream { .. } => "split_stream_pass",
            FftPass::SplitStreamLastTwo { .. } => "split_stream_last_two",
            FftPass::Radix2 { .. } => "stockham_radix2",
            FftPass::Radix4 { .. } => "stockham_radix4",
            FftPass::StockhamLocal => "stockham_local",
        }
    }
    /// Invocations for `batch` lines of length `n`.
    fn invocations(self, n: usize, batch: usize) -> usize {
        match self {
            FftPass::SplitStream { .. } | FftPass::SplitStreamLastTwo { .. } => n * batch,
            FftPass::Radix2 { .. } => n / 2 * batch,
            FftPass::Radix4 { .. } => n / 4 * batch,
            FftPass::StockhamLocal => WORKGROUP as usize * batch.div_ceil(local_lines(n)),
        }
    }
    fn stage(self) -> u32 {
        match self {
            FftPass::SplitStream { stage } | FftPass::SplitStreamLastTwo { stage } => stage,
            _ => 0,
        }
    }
    fn span(self) -> u32 {
        match self {
            FftPass::Radix2 { span } | FftPass::Radix4 { span } => span,
            _ => 0,
        }
    }
}

/// The passes of one line of length `2^log2n` (none for `log2n = 0`).
///
/// Split stream: stages `0 … log2n − 3` one pass each, then the last two stages merged;
/// `log2n = 1` is a single radix-2 stage. Stockham: a radix-2 pass first when `log2n`
/// is odd, then radix-4 passes, `Ns` growing by the radix each pass (for
/// [`GpuFftVariant::Stockham`] and `N ≤ LOCAL_MAX_N`, all of them in one
/// [`FftPass::StockhamLocal`]).
pub fn plan(variant: GpuFftVariant, log2n: u32) -> Vec<FftPass> {
    match variant {
        GpuFftVariant::SplitStream => match log2n {
            0 => vec![],
            1 => vec![FftPass::SplitStream { stage: 0 }],
            _ => (0..log2n - 2)
                .map(|stage| FftPass::SplitStream { stage })
                .chain([FftPass::SplitStreamLastTwo { stage: log2n - 2 }])
                .collect(),
        },
        GpuFftVariant::Stockham if log2n >= 1 && (1usize << log2n) <= LOCAL_MAX_N => {
            vec![FftPass::StockhamLocal]
        }
        GpuFftVariant::Stockham | GpuFftVariant::StockhamGlobal => {
            let mut passes = Vec::new();
            let mut span = 1u32;
            if log2n % 2 == 1 {
                passes.push(FftPass::Radix2 { span });
                span *= 2;
            }
            while span < (1u32 << log2n) {
                passes.push(FftPass::Radix4 { span });
                span *= 4;
            }
            passes
        }
    }
}

/// One dispatch of the transform along one axis: a pass of the power-of-two FFT along
/// the axis itself, or a step of Bluestein's algorithm for any other length
/// (`shaders/fft_bluestein.wgsl`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FftStep {
    /// A pass along the axis (its length is a power of two).
    Pass(FftPass),
    /// `bluestein_load`: `a_j = x_j·c_j` into the work lines of length `M`, zero-padded.
    BluesteinLoad,
    /// A pass of the length-`M` FFT of the work lines: forward before the
    /// multiplication, inverse (unscaled) after it.
    Inner { pass: FftPass, inverse: bool },
    /// `bluestein_multiply`: the work spectra times `B/M`.
    BluesteinMultiply,
    /// `bluestein_store`: `X_k = c_k·conv_k` back into the data, times the scale.
    BluesteinStore,
}

impl FftStep {
    fn entry_point(self) -> &'static str {
        match self {
            FftStep::Pass(p) | FftStep::Inner { pass: p, .. } => p.entry_point(),
            FftStep::BluesteinLoad => "bluestein_load",
            FftStep::BluesteinMultiply => "bluestein_multiply",
            FftStep::BluesteinStore => "bluestein_store",
        }
    }
}

/// The dispatches of the transform of one axis of length `n`: the variant's passes
/// ([`plan`]) for a power of two; otherwise Bluestein's algorithm, a load, the forward
/// passes of length `M = `[`bluestein_length`]`(n)`, a multiplication, the inverse
/// passes and a store (for [`GpuFftVariant::Stockham`] and `M ≤ LOCAL_MAX_N`, five
/// dispatches in all).
pub fn axis_plan(variant: GpuFftVariant, n: usize) -> Vec<FftStep> {
    match bluestein_length(n) {
        None => plan(variant, n.trailing_zeros())
            .into_iter()
            .map(FftStep::Pass)
            .collect(),
        Some(m) => {
            let inner = plan(variant, m.trailing_zeros());
            let pass = |inverse| move |pass| FftStep::Inner { pass, inverse };
            std::iter::once(FftStep::BluesteinLoad)
                .chain(inner.iter().copied().map(pass(false)))
                .chain([FftStep::BluesteinMultiply])
                .chain(inner.iter().copied().map(pass(true)))
                .chain([FftStep::BluesteinStore])
                .collect()
        }
    }
}

/// The padded length of Bluestein's algorithm for an axis of length `n`: `None` when
/// `n` is a power of two (or 0), which the FFT passes take directly; otherwise the
/// least power of two `M ≥ 2n − 1`, so that a circular convolution of length `M` holds
/// the linear one of the `n` chirped values with the `2n − 1` taps of the chirp.
pub fn bluestein_length(n: usize) -> Option<usize> {
    (n > 0 && !n.is_power_of_two()).then(|| (2 * n - 1).next_power_of_two())
}

/// The values one line of length `n` occupies on the device while it is transformed:
/// `n`, or Bluestein's `M` (less than `4n`).
pub fn device_line_length(n: usize) -> usize {
    bluestein_length(n).unwrap_or(n)
}

/// Bluestein's chirp `c_j = exp(∓iπ·j²/n)`, `j = 0 … n−1` (− forward), exact in f64:
/// `j²` is reduced modulo `2n` in integers, then `c_j = `[`twiddle`]`(j² mod 2n, 2n)`, so
/// no large angle is ever rounded.
pub fn bluestein_chirp(n: usize, dir: Direction) -> Vec<Complex<f64>> {
    let period = 2 * n as u128;
    (0..n)
        .map(|j| twiddle(((j as u128 * j as u128) % period) as usize, 2 * n, dir))
        .collect()
}

/// The spectrum of Bluestein's kernel divided by `M`: `FFT_M(b) / M`, where
/// `b_m = conj(c_m)` for `|m| < n` (negative `m` wrapped to `M + m`) and 0 elsewhere,
/// `c` the chirp of [`bluestein_chirp`]. Made in f64 ([`crate::cpu::fft::fft_nd`]),
/// once per plan; the division makes the unscaled inverse FFT of the product the
/// convolution itself.
pub fn bluestein_kernel(n: usize, m: usize, dir: Direction) -> Vec<Complex<f64>> {
    let chirp = bluestein_chirp(n, dir);
    let mut b = vec![Complex::new(0.0, 0.0); m];
    for (j, c) in chirp.iter().enumerate() {
        b[j] = c.conj();
        if j > 0 {
            b[m - j] = c.conj();
        }
    }
    crate::cpu::fft::fft_nd(&mut b, &[m], Direction::Forward, Normalization::None);
    let scale = 1.0 / m as f64;
    b.iter().map(|v| v * scale).collect()
}

/// The twiddle table `exp(∓2πi·m/n)`, `m = 0 … n−1`, exact in f64 ([`twiddle`]).
pub fn twiddle_table(n: usize, dir: Direction) -> Vec<Complex<f64>> {
    (0..n).map(|m| twiddle(m, n, dir)).collect()
}

// ---------------------------------------------------------------------------------
// CPU twins of the per-element shader functions (one line at a time, f64)
// ---------------------------------------------------------------------------------

/// Multiplies by `exp(∓2πi/4) = ∓i` exactly.
/// mirrors shaders/shared/fft_common.wgsl: times_w4
pub fn times_w4(v: Complex<f64>, dir: Direction) -> Complex<f64> {
    match dir {
        Direction::Forward => Complex::new(v.im, -v.re),
        Direction::Inverse => Complex::new(-v.im, v.re),
    }
}

/// The buffer index of element `j` of line `line` (see [`FftParams::stride`]).
/// mirrors shaders/shared/fft_common.wgsl: element_address
pub fn element_address(p: &FftParams, line: u32, j: u32) -> u32 {
    let s = p.stride;
    (line / s) * p.n * s + line % s + j * s
}

/// The lowest `bits` bits of `x` in reverse order (0 when `bits` is 0).
/// mirrors shaders/fft_split_stream.wgsl: reverse_low_bits
pub fn reverse_low_bits(x: u32, bits: u32) -> u32 {
    if bits == 0 {
        0
    } else {
        x.reverse_bits() >> (32 - bits)
    }
}

/// Input element `k` of the current split-stream pass (bit-reversed in pass 0).
/// mirrors shaders/fft_split_stream.wgsl: split_stream_load
fn split_stream_load(src: &[Complex<f64>], p: &FftParams, k: u32) -> Complex<f64> {
    let j = if p.stage == 0 {
        reverse_low_bits(k, p.log2n)
    } else {
        k
    };
    src[j as usize]
}

/// Output `t` of split-stream stage `s = p.stage` of one line: with `i = t mod N/2`,
/// `a = in[2i]`, `b = in[2i+1]`, the first half of the output is `f_e = a + b` and the
/// second half `f_o = (a − b)·exp(∓2πi·j·2^s/N)`, `j` the low `log2 N − s − 1` bits of
/// `i` reversed.
///
/// Why this is the DIF FFT: relabel the in-place DIF of stage `s` (pairs `2^(L−s−1)`
/// apart, natural input, bit-reversed output) by bit-reversing every index, then rotate
/// the index bits right by `s`; the pairs of every stage become `2i, 2i+1` on input and
/// `i, i + N/2` on output (the constant geometry of Jansen et al.'s Figure 7), the input
/// of stage 0 is the bit-reversed data and the output of the last stage is in natural
/// order.
/// mirrors shaders/fft_split_stream.wgsl: split_stream_element
pub fn split_stream_element(
    src: &[Complex<f64>],
    tw: &[Complex<f64>],
    p: &FftParams,
    t: u32,
) -> Complex<f64> {
    let half = p.n / 2;
    let i = t % half;
    let a = split_stream_load(src, p, 2 * i);
    let b = split_stream_load(src, p, 2 * i + 1);
    if t < half {
        return a + b; // f_e
    }
    let bits = p.log2n - p.stage - 1;
    let j = reverse_low_bits(i & ((1u32 << bits) - 1), bits);
    (a - b) * tw[(j << p.stage) as usize] // f_o
}

/// Output `t` of the merged last two split-stream stages: quarter `q = t / (N/4)`
/// reads `a0 … a3 = in[4r … 4r+3]` (`r = t mod N/4`) and computes
/// `(a0+a1) + (a2+a3)`, `(a0−a1) + w(a2−a3)`, `(a0+a1) − (a2+a3)`, `(a0−a1) − w(a2−a3)`
/// for `q = 0, 1, 2, 3`, with `w = ∓i` (the last stage's twiddles are all 1, the one
/// before has only `1` and `∓i`).
/// mirrors shaders/fft_split_stream.wgsl: split_stream_last_two_element
pub fn split_stream_last_two_element(
    src: &[Complex<f64>],
    p: &FftParams,
    dir: Direction,
    t: u32,
) -> Complex<f64> {
    let quarter = p.n / 4;
    let (q, r) = (t / quarter, t % quarter);
    let a0 = split_stream_load(src, p, 4 * r);
    let a1 = split_stream_load(src, p, 4 * r + 1);
    let a2 = split_stream_load(src, p, 4 * r + 2);
    let a3 = split_stream_load(src, p, 4 * r + 3);
    match q {
        0 => (a0 + a1) + (a2 + a3),
        1 => (a0 - a1) + times_w4(a2 - a3, dir),
        2 => (a0 + a1) - (a2 + a3),
        _ => (a0 - a1) - times_w4(a2 - a3, dir),
    }
}

/// Radix-4 Stockham butterfly `j` of one line: inputs `j + m·N/4` times
/// `exp(∓2πi·m·k/(4Ns))` (`k = j mod Ns`), a 4-point DFT, outputs at
/// `(j / Ns)·4Ns + k + m·Ns`, `m = 0 … 3`.
/// mirrors shaders/fft_stockham.wgsl: stockham_radix4_butterfly (and local_radix4_butterfly)
pub fn stockham_radix4_butterfly(
    src: &[Complex<f64>],
    tw: &[Complex<f64>],
    p: &FftParams,
    dir: Direction,
    j: u32,
    dst: &mut [Complex<f64>],
) {
    let ns = p.span;
    let quarter = p.n / 4;
    let k = j % ns;
    let step = p.n / (4 * ns);
    let v0 = src[j as usize];
    let v1 = src[(j + quarter) as usize] * tw[(k * step) as usize];
    let v2 = src[(j + 2 * quarter) as usize] * tw[(2 * k * step) as usize];
    let v3 = src[(j + 3 * quarter) as usize] * tw[(3 * k * step) as usize];
    let y = radix4_dft(v0, v1, v2, v3, dir);
    let out = ((j / ns) * 4 * ns + k) as usize;
    let ns = ns as usize;
    dst[out] = y[0];
    dst[out + ns] = y[1];
    dst[out + 2 * ns] = y[2];
    dst[out + 3 * ns] = y[3];
}

/// The 4-point DFT (unscaled), `y_m = Σ_r v_r·w₄^(m·r)` with `w₄ = ∓i`, in two radix-2
/// steps.
/// mirrors shaders/fft_stockham.wgsl: radix4_dft
pub fn radix4_dft(
    v0: Complex<f64>,
    v1: Complex<f64>,
    v2: Complex<f64>,
    v3: Complex<f64>,
    dir: Direction,
) -> [Complex<f64>; 4] {
    let (a, b, c, d) = (v0 + v2, v0 - v2, v1 + v3, times_w4(v1 - v3, dir));
    [a + c, b + d, a - c, b - d]
}

/// Radix-2 Stockham butterfly `j`: inputs `j` and `j + N/2`, the second times
/// `exp(∓2πi·k/(2Ns))`.
/// mirrors shaders/fft_stockham.wgsl: stockham_radix2_butterfly (and local_radix2_butterfly)
pub fn stockham_radix2_butterfly(
    src: &[Complex<f64>],
    tw: &[Complex<f64>],
    p: &FftParams,
    j: u32,
    dst: &mut [Complex<f64>],
) {
    let ns = p.span;
    let k = j % ns;
    let step = p.n / (2 * ns);
    let v0 = src[j as usize];
    let v1 = src[(j + p.n / 2) as usize] * tw[(k * step) as usize];
    let out = ((j / ns) * 2 * ns + k) as usize;
    dst[out] = v0 + v1;
    dst[out + ns as usize] = v0 - v1;
}

/// Work value `j` of line `line` in Bluestein's load: `x_j·c_j` for `j < n` (the
/// data's element `j`, [`element_address`]), 0 for the padding up to `M`.
/// mirrors shaders/fft_bluestein.wgsl: bluestein_load_element
pub fn bluestein_load_element(
    src: &[Complex<f64>],
    chirp: &[Complex<f64>],
    p: &FftParams,
    line: u32,
    j: u32,
) -> Complex<f64> {
    if j >= p.n {
        return Complex::new(0.0, 0.0);
    }
    src[element_address(p, line, j) as usize] * chirp[j as usize]
}

/// Work value `g` (line `g / M`, bin `g mod M`) times the kernel's spectrum `B/M`.
/// mirrors shaders/fft_bluestein.wgsl: bluestein_multiply_element
pub fn bluestein_multiply_element(
    src: &[Complex<f64>],
    kernel: &[Complex<f64>],
    p: &FftParams,
    g: u32,
) -> Complex<f64> {
    src[g as usize] * kernel[(g % p.span) as usize]
}

/// Output `k` of line `line` in Bluestein's store: the convolution's value `k` times
/// `c_k`, times the scale.
/// mirrors shaders/fft_bluestein.wgsl: bluestein_store_element
pub fn bluestein_store_element(
    src: &[Complex<f64>],
    chirp: &[Complex<f64>],
    p: &FftParams,
    line: u32,
    k: u32,
) -> Complex<f64> {
    src[(line * p.span + k) as usize] * chirp[k as usize] * p.scale as f64
}

/// Bluestein's algorithm on one line of any length on the CPU, in f64, through the
/// twins of `shaders/fft_bluestein.wgsl` and the variant's power-of-two passes: the
/// unscaled transform, as the GPU computes it.
fn bluestein_reference(
    line: &[Complex<f64>],
    dir: Direction,
    variant: GpuFftVariant,
    m: usize,
) -> Vec<Complex<f64>> {
    let n = line.len();
    let chirp = bluestein_chirp(n, dir);
    let kernel = bluestein_kernel(n, m, dir);
    let p = FftParams {
        n: n as u32,
        log2n: m.trailing_zeros(),
        stride: 1,
        batch: 1,
        stage: 0,
        direction: (dir == Direction::Inverse) as u32,
        span: m as u32,
        scale: 1.0,
    };
    let a: Vec<_> = (0..m as u32)
        .map(|j| bluestein_load_element(line, &chirp, &p, 0, j))
        .collect();
    let spectrum = reference_line(&a, Direction::Forward, variant);
    let product: Vec<_> = (0..m as u32)
        .map(|g| bluestein_multiply_element(&spectrum, &kernel, &p, g))
        .collect();
    let conv = reference_line(&product, Direction::Inverse, variant);
    (0..n as u32)
        .map(|k| bluestein_store_element(&conv, &chirp, &p, 0, k))
        .collect()
}

/// The parameters of `pass` on lines of length `n` (scale 1, one contiguous line).
fn line_params(n: usize, dir: Direction, pass: FftPass) -> FftParams {
    FftParams {
        n: n as u32,
        log2n: n.trailing_zeros(),
        stride: 1,
        batch: 1,
        stage: pass.stage(),
        direction: (dir == Direction::Inverse) as u32,
        span: pass.span(),
        scale: 1.0,
    }
}

/// Runs the plan of `variant` ([`axis_plan`]) on one line on the CPU, in f64, with the
/// twins of the shader functions: the unscaled transform, as the GPU computes it
/// (Bluestein's algorithm for a length that is not a power of two).
pub fn reference_line(
    line: &[Complex<f64>],
    dir: Direction,
    variant: GpuFftVariant,
) -> Vec<Complex<f64>> {
    let n = line.len();
    if let Some(m) = bluestein_length(n) {
        return bluestein_reference(line, dir, variant, m);
    }
    if n == 0 {
        return Vec::new();
    }
    let tw = twiddle_table(n, dir);
    let mut src = line.to_vec();
    let mut dst = vec![Complex::new(0.0, 0.0); n];
    let log2n = n.trailing_zeros();
    // The workgroup-memory pass runs the same butterflies as the global plan.
    let passes = plan(variant, log2n)
        .into_iter()
        .flat_map(|pass| match pass {
            FftPass::StockhamLocal => plan(GpuFftVariant::StockhamGlobal, log2n),
            other => vec![other],
        });
    for pass in passes {
        let p = line_params(n, dir, pass);
        match pass {
            FftPass::SplitStream { .. } => {
                for t in 0..n {
                    dst[t] = split_stream_element(&src, &tw, &p, t as u32);
                }
            }
            FftPass::SplitStreamLastTwo { .. } => {
                for t in 0..n {
                    dst[t] = split_stream_last_two_element(&src, &p, dir, t as u32);
                }
            }
            FftPass::Radix2 { .. } => {
                for j in 0..n / 2 {
                    stockham_radix2_butterfly(&src, &tw, &p, j as u32, &mut dst);
                }
            }
            FftPass::Radix4 { .. } => {
                for j in 0..n / 4 {
                    stockham_radix4_butterfly(&src, &tw, &p, dir, j as u32, &mut dst);
                }
            }
            FftPass::StockhamLocal => unreachable!("expanded above"),
        }
        std::mem::swap(&mut src, &mut dst);
    }
    src
}

/// The split-stream FFT of one line on the CPU (unscaled), through the shader twins.
pub fn split_stream_reference(line: &[Complex<f64>], dir: Direction) -> Vec<Complex<f64>> {
    reference_line(line, dir, GpuFftVariant::SplitStream)
}

/// The Stockham FFT of one line on the CPU (unscaled), through the shader twins.
pub fn stockham_reference(line: &[Complex<f64>], dir: Direction) -> Vec<Complex<f64>> {
    reference_line(line, dir, GpuFftVariant::Stockham)
}

// ---------------------------------------------------------------------------------
// The GPU transform
// ---------------------------------------------------------------------------------

/// The N-D FFT on the GPU of a row-major array of `shape` (last axis fastest): 1-D
/// transforms along every axis, scaled by `norm` as the whole transform must
/// (`cpu::dft::dft_nd`'s conventions). Uploads, runs, reads back.
///
/// # Errors
/// [`Error::Invalid`] when the shape does not describe the data; [`Error::TooLarge`]
/// when the array (or Bluestein's work lines) exceeds one storage binding and cannot be
/// split (a prime 1-D length); [`Error::Gpu`] when the device fails.
pub fn fft_nd(
    ctx: &GpuContext,
    data: &[Complex<f32>],
    shape: &[usize],
    dir: Direction,
    norm: Normalization,
    variant: GpuFftVariant,
) -> Result<Vec<Complex<f32>>> {
    Ok(fft_nd_timed(ctx, data, shape, dir, norm, variant)?.data)
}

/// Where the time of a GPU FFT went, in seconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct FftTimings {
    /// Validation, shader compilation, pipelines, twiddle tables, empty buffers.
    pub setup: f64,
    /// The data upload (host to device, waited for).
    pub upload: f64,
    /// Every pass: from timestamp queries (start of the first pass to the end of the
    /// last) when the adapter has them, otherwise the wall-clock time of the
    /// waited-for submission.
    pub kernel: f64,
    /// Whether `kernel` comes from timestamp queries.
    pub kernel_from_timestamps: bool,
    /// Copying the result back to the host.
    pub readback: f64,
    /// Everything, end to end.
    pub total: f64,
    /// The compute dispatches of the transform (one per pass; several transforms
    /// when it was split).
    pub dispatches: usize,
}

/// What [`fft_nd_timed`] returns: the transform, and where the time went.
#[derive(Clone, Debug)]
pub struct GpuFftOutput {
    pub data: Vec<Complex<f32>>,
    pub timings: FftTimings,
}

/// [`fft_nd`], with timings of the set-up, upload, passes and readback.
///
/// # Errors
/// As [`fft_nd`].
pub fn fft_nd_timed(
    ctx: &GpuContext,
    data: &[Complex<f32>],
    shape: &[usize],
    dir: Direction,
    norm: Normalization,
    variant: GpuFftVariant,
) -> Result<GpuFftOutput> {
    let axes: Vec<usize> = (0..shape.len()).collect();
    match split_plan(ctx, shape)? {
        None => transform(ctx, Input::Host(data), shape, &axes, dir, norm, variant),
        Some(plan) => fft_nd_planned(ctx, data, shape, dir, norm, variant, &plan),
    }
}

/// How [`fft_nd_timed`] splits an array of `shape` on `ctx`: `None` when it fits one
/// binding of the planner's limits.
///
/// # Errors
/// As [`FftSplitPlan::new`].
pub fn split_plan(ctx: &GpuContext, shape: &[usize]) -> Result<Option<FftSplitPlan>> {
    if !too_large_for_one_binding(ctx, shape) {
        return Ok(None);
    }
    FftSplitPlan::new(&ctx.limits, shape).map(Some)
}

/// Whether the array of `shape`, or Bluestein's work lines for it, exceed one binding
/// of the planner's limits (or the shader's 32-bit indices).
fn too_large_for_one_binding(ctx: &GpuContext, shape: &[usize]) -> bool {
    let axes: Vec<usize> = (0..shape.len()).collect();
    let len = shape.iter().product::<usize>().max(work_len(shape, &axes));
    (len as u64).saturating_mul(8) > super::plan::binding_limit(&ctx.limits)
        || len > u32::MAX as usize / 4
}

/// How [`fft_nd_timed`] transforms an array past one binding of the planner's limits
/// ([`crate::gpu::plan`]), in two phases that keep the unsplit order of the axes:
/// first the lines along axis 0, in slabs of the array cut along axis 1 (gathered on
/// the host); then every other axis, in slabs cut along axis 0 (contiguous). Both
/// phases run unscaled and the host applies the transform's factor once, as the
/// unsplit path's last pass does, so each line sees the same operations: a split
/// N-D transform equals the unsplit one bit for bit.
///
/// A 1-D array of length `N = N2·N1` is taken in four steps (Bailey, *FFTs in external
/// or hierarchical memory*, J. Supercomputing 4, 1990) over the view `[N2, N1]`
/// (`x[n1 + N1·n2]` at row `n2`, column `n1`): the phase-1 FFTs of length `N2` down
/// the columns; the twiddles `exp(∓2πi·n1·k2/N)` on the host (exact in f64, one
/// rounding); the phase-2 FFTs of length `N1` along the rows; and the transpose
/// `X[k2 + N2·k1] = Z[k2][k1]` on the host. Another factorisation of the same sum, so
/// it agrees with the unsplit transform to rounding, not to the bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FftSplitPlan {
    /// Phase 1: slices along axis 1 per slab.
    pub axis0_lines: Pieces,
    /// Phase 2: slices along axis 0 per slab.
    pub other_axes: Pieces,
    /// A 1-D transform's four-step view `[N2, N1]` (`None` for an N-D array).
    pub four_step: Option<[usize; 2]>,
}

/// The four-step view `[N2, N1]` of a 1-D length `n`: `N2` the largest divisor of `n`
/// not above `√n`, `N1 = n / N2`; `None` when there is none but 1 (a prime, 1).
pub fn four_step_factors(n: usize) -> Option<[usize; 2]> {
    let root = n.isqrt();
    (2..=root)
        .rev()
        .find(|d| n.is_multiple_of(*d))
        .map(|d| [d, n / d])
}

impl FftSplitPlan {
    /// The plan for `shape` under `limits`.
    ///
    /// # Errors
    /// [`Error::TooLarge`] for a prime 1-D length (no four-step view), or when one slab's slice
    /// alone exceeds a binding.
    pub fn new(limits: &wgpu::Limits, shape: &[usize]) -> Result<Self> {
        // The shaders index values in 32 bits (at most u32::MAX / 4 values per buffer).
        let limit = super::plan::binding_limit(limits).min(u32::MAX as u64 / 4 * 8);
        if let [n] = *shape {
            let Some(view) = four_step_factors(n) else {
                return Err(Error::too_large(
                    "GPU FFT data",
                    format!(
                        "a 1-D transform of {n} values exceeds one storage binding of \
                         {limit} bytes (max_storage_buffer_binding_size) and {n} has no \
                         factor to split it into four steps: use cpu::fft::fft_nd"
                    ),
                ));
            };
            return Ok(FftSplitPlan {
                four_step: Some(view),
                ..Self::new(limits, &view)?
            });
        }
        if shape.len() < 2 {
            return Err(Error::invalid("fft shape", "a 0-D array has no axis"));
        }
        // A slice's bytes on the device: its values, or Bluestein's work lines for
        // them (M values a line instead of n), whichever is larger.
        let inner: usize = shape[2..].iter().product();
        let axis0_lines = Pieces::plan(
            "GPU FFT data",
            "column of lines along axis 0",
            shape[1],
            (device_line_length(shape[0]) * inner) as u64 * 8,
            limit,
            1,
        )?;
        let slice: usize = shape[1..].iter().product();
        let other_slice = (1..shape.len())
            .filter(|&a| shape[a] > 0)
            .map(|a| slice / shape[a] * device_line_length(shape[a]))
            .max()
            .unwrap_or(0);
        let other_axes = Pieces::plan(
            "GPU FFT data",
            "slice across axis 0",
            shape[0],
            other_slice as u64 * 8,
            limit,
            1,
        )?;
        Ok(FftSplitPlan {
            axis0_lines,
            other_axes,
            four_step: None,
        })
    }

    /// The array the two phases cut: the four-step view of a 1-D transform, else
    /// `shape` itself.
    pub fn view(&self, shape: &[usize]) -> Vec<usize> {
        match self.four_step {
            Some(view) => view.to_vec(),
            None => shape.to_vec(),
        }
    }

    /// One line for the user: "FFT in 4 slabs along axis 1, then 4 along axis 0".
    pub fn describe(&self) -> String {
        let slabs = format!(
            "{} along axis 1 (axis 0's lines), then {} along axis 0 (the other axes)",
            super::plan::count_of(self.axis0_lines.count(), "slab"),
            super::plan::count_of(self.other_axes.count(), "slab"),
        );
        match self.four_step {
            Some([n2, n1]) => format!("FFT in four steps as {n2} × {n1}: {slabs}"),
            None => format!("FFT in {slabs}"),
        }
    }
}

/// [`fft_nd_timed`] in the slabs of `plan` (any plan for `shape`, split or not).
///
/// # Errors
/// As [`fft_nd`]; [`Error::Invalid`] for a plan made for another shape.
pub fn fft_nd_planned(
    ctx: &GpuContext,
    data: &[Complex<f32>],
    shape: &[usize],
    dir: Direction,
    norm: Normalization,
    variant: GpuFftVariant,
    plan: &FftSplitPlan,
) -> Result<GpuFftOutput> {
    let t_start = Instant::now();
    let view = plan.view(shape);
    let view_fits = match plan.four_step {
        Some([n2, n1]) => shape.len() == 1 && n2 * n1 == shape[0],
        None => shape.len() >= 2,
    };
    if !view_fits
        || plan.axis0_lines.total != view[1]
        || plan.other_axes.total != view[0]
        || shape.iter().try_fold(1usize, |a, &n| a.checked_mul(n)) != Some(data.len())
    {
        return Err(Error::invalid(
            "fft split plan",
            format!("does not fit shape {shape:?} with {} values", data.len()),
        ));
    }
    let shape = &view[..];
    let (n0, n1) = (shape[0], shape[1]);
    let inner: usize = shape[2..].iter().product();
    let others: Vec<usize> = (1..shape.len()).collect();
    let mut timings = FftTimings {
        kernel_from_timestamps: true,
        ..Default::default()
    };
    let mut add = |t: &FftTimings| {
        timings.setup += t.setup;
        timings.upload += t.upload;
        timings.kernel += t.kernel;
        timings.readback += t.readback;
        timings.dispatches += t.dispatches;
        timings.kernel_from_timestamps &= t.kernel_from_timestamps;
    };
    let mut work = data.to_vec();
    // Phase 1: axis 0's lines, a band of axis-1 indices at a time.
    let row = n1 * inner;
    for band in plan.axis0_lines.ranges() {
        let w = band.len() * inner;
        let mut sub = Vec::with_capacity(n0 * w);
        for i in 0..n0 {
            sub.extend_from_slice(&work[i * row + band.start * inner..][..w]);
        }
        let mut sub_shape = shape.to_vec();
        sub_shape[1] = band.len();
        let out = transform(
            ctx,
            Input::Host(&sub),
            &sub_shape,
            &[0],
            dir,
            Normalization::None,
            variant,
        )?;
        add(&out.timings);
        for i in 0..n0 {
            work[i * row + band.start * inner..][..w].copy_from_slice(&out.data[i * w..][..w]);
        }
    }
    if plan.four_step.is_some() {
        four_step_twiddles(&mut work, n0, n1, dir);
    }
    // Phase 2: the other axes, a contiguous slab of axis-0 indices at a time.
    for slab in plan.other_axes.ranges() {
        let part = &mut work[slab.start * row..slab.end * row];
        let mut sub_shape = shape.to_vec();
        sub_shape[0] = slab.len();
        let out = transform(
            ctx,
            Input::Host(part),
            &sub_shape,
            &others,
            dir,
            Normalization::None,
            variant,
        )?;
        add(&out.timings);
        part.copy_from_slice(&out.data);
    }
    let factor = norm.apply(1.0, data.len(), dir) as f32;
    if factor != 1.0 {
        work.iter_mut().for_each(|v| *v *= factor);
    }
    if plan.four_step.is_some() {
        // X[k2 + N2·k1] = Z[k2][k1]: the transpose of the [N2, N1] view.
        let mut out = vec![Complex::new(0.0, 0.0); work.len()];
        for (k2, row) in work.chunks(n1).enumerate() {
            for (k1, v) in row.iter().enumerate() {
                out[k1 * n0 + k2] = *v;
            }
        }
        work = out;
    }
    timings.total = t_start.elapsed().as_secs_f64();
    Ok(GpuFftOutput {
        data: work,
        timings,
    })
}

/// The four-step twiddles: `Y[k2][n1] ·= exp(∓2πi·n1·k2/N)` over the `[N2, N1]` view
/// (`N = N2·N1`), the factor in f64 by the oracle's exact [`twiddle`] (its index
/// reduced modulo `N`) and the product rounded once to f32.
fn four_step_twiddles(work: &mut [Complex<f32>], n2: usize, n1: usize, dir: Direction) {
    use rayon::prelude::*;
    let n = n2 * n1;
    work.par_chunks_mut(n1).enumerate().for_each(|(k2, row)| {
        for (j, v) in row.iter_mut().enumerate() {
            let w = twiddle(j * k2 % n, n, dir);
            let p = Complex::new(v.re as f64, v.im as f64) * w;
            *v = Complex::new(p.re as f32, p.im as f32);
        }
    });
}

/// [`fft_nd_timed`] of complex f32 values (`[re, im]` pairs) already on the device:
/// `buffer` holds exactly the array (its size is `8 ·` the product of `shape`) and needs
/// `STORAGE | COPY_SRC`; it is overwritten. The result is read back as usual; no upload
/// (`upload` is 0).
///
/// # Errors
/// As [`fft_nd`]; also when the buffer's size is not the array's.
pub fn fft_nd_buffer_timed(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
    shape: &[usize],
    dir: Direction,
    norm: Normalization,
    variant: GpuFftVariant,
) -> Result<GpuFftOutput> {
    let len = shape.iter().try_fold(1usize, |a, &n| a.checked_mul(n));
    if len.map(|l| l as u64 * 8) != Some(buffer.size()) {
        return Err(Error::invalid(
            "fft buffer",
            format!(
                "{} bytes do not hold an array of shape {shape:?}",
                buffer.size()
            ),
        ));
    }
    let axes: Vec<usize> = (0..shape.len()).collect();
    let input = Input::Device(buffer, len.unwrap_or(0));
    transform(ctx, input, shape, &axes, dir, norm, variant)
}

/// Where a transform's input is.
#[derive(Clone, Copy)]
enum Input<'a> {
    Host(&'a [Complex<f32>]),
    /// A buffer of this many complex values.
    Device(&'a wgpu::Buffer, usize),
}

impl Input<'_> {
    fn len(self) -> usize {
        match self {
            Input::Host(d) => d.len(),
            Input::Device(_, n) => n,
        }
    }
}

/// A batch of 1-D FFTs of length `n` of the contiguous lines of `data` (the last axis
/// of the array `[data.len() / n, n]`), each scaled by `norm` for length `n`.
///
/// # Errors
/// As [`fft_nd`]; also when `n` is 0 or does not divide `data.len()`.
pub fn fft_lines(
    ctx: &GpuContext,
    data: &[Complex<f32>],
    n: usize,
    dir: Direction,
    norm: Normalization,
    variant: GpuFftVariant,
) -> Result<Vec<Complex<f32>>> {
    if n == 0 || !data.len().is_multiple_of(n) {
        return Err(Error::invalid(
            "fft line length",
            format!("{n} does not divide the {} values", data.len()),
        ));
    }
    let input = Input::Host(data);
    Ok(transform(ctx, input, &[data.len() / n, n], &[1], dir, norm, variant)?.data)
}

/// Checks the input and refuses what the GPU FFT cannot do in one binding.
fn validate(ctx: &GpuContext, len: usize, shape: &[usize], axes: &[usize]) -> Result<()> {
    let total = shape.iter().try_fold(1usize, |a, &n| a.checked_mul(n));
    if total != Some(len) {
        return Err(Error::invalid(
            "fft shape",
            format!("shape {shape:?} does not describe {len} values"),
        ));
    }
    let limit = crate::gpu::plan::binding_limit(&ctx.limits);
    let work = work_len(shape, axes);
    for (what, values) in [("data", len), ("Bluestein work lines", work)] {
        let bytes = (values as u64).saturating_mul(8);
        if bytes > limit || values > u32::MAX as usize / 4 {
            return Err(Error::too_large(
                format!("GPU FFT {what}"),
                format!(
                    "{values} complex values ({bytes} bytes) exceed the adapter's \
                     storage-binding limit of {limit} bytes \
                     (max_storage_buffer_binding_size): use cpu::fft::fft_nd"
                ),
            ));
        }
    }
    Ok(())
}

/// The complex values of each of Bluestein's two work buffers for the transform of
/// `axes` of `shape`: the most any one such axis needs, `M` per line
/// ([`bluestein_length`]); 0 when every length is a power of two.
pub fn work_len(shape: &[usize], axes: &[usize]) -> usize {
    let total: usize = shape.iter().product();
    axes.iter()
        .filter_map(|&a| bluestein_length(shape[a]).map(|m| total / shape[a] * m))
        .max()
        .unwrap_or(0)
}

/// The device memory of one unsplit transform of `axes` of `shape` (bytes): the two
/// ping-pong data buffers, Bluestein's two work buffers and the tables (twiddles,
/// chirps, kernels); and the largest single buffer.
pub fn device_bytes(shape: &[usize], axes: &[usize]) -> (u64, u64) {
    let data = 8 * shape.iter().map(|&a| a as u64).product::<u64>();
    let work = 8 * work_len(shape, axes) as u64;
    let tables: u64 = axes
        .iter()
        .map(|&a| {
            let n = shape[a] as u64;
            match bluestein_length(shape[a]) {
                // The chirp, the kernel, and the inner forward and inverse twiddles.
                Some(m) => 8 * (n + 3 * m as u64),
                None => 8 * n,
            }
        })
        .sum();
    (2 * data + 2 * work + tables, data.max(work))
}

/// The workgroup counts for `invocations` (rows of at most the per-dimension limit).
fn workgroups(ctx: &GpuContext, invocations: u32) -> (u32, u32) {
    let groups = invocations.div_ceil(WORKGROUP).max(1);
    let x = groups.min(ctx.limits.max_compute_workgroups_per_dimension.max(1));
    (x, groups.div_ceil(x))
}

fn transform(
    ctx: &GpuContext,
    input: Input<'_>,
    shape: &[usize],
    axes: &[usize],
    dir: Direction,
    norm: Normalization,
    variant: GpuFftVariant,
) -> Result<GpuFftOutput> {
    let t_start = Instant::now();
    validate(ctx, input.len(), shape, axes)?;
    let plan = GpuFftPlan::with_axes(ctx, shape, axes, dir, norm, variant)?;
    let setup = t_start.elapsed().as_secs_f64();
    let mut out = plan.execute(ctx, input)?;
    out.timings.setup = setup;
    out.timings.total = t_start.elapsed().as_secs_f64();
    Ok(out)
}

/// The bindings of every FFT pass (parameters, source, destination, table).
const FFT_BINDINGS: [wgpu::BindGroupLayoutEntry; 4] = [
    super::context::buffer_entry(0, wgpu::BufferBindingType::Uniform),
    super::context::buffer_entry(1, wgpu::BufferBindingType::Storage { read_only: true }),
    super::context::buffer_entry(2, wgpu::BufferBindingType::Storage { read_only: false }),
    super::context::buffer_entry(3, wgpu::BufferBindingType::Storage { read_only: true }),
];

/// The pipeline of `entry` in the WGSL `source` (named `file`) over [`FFT_BINDINGS`],
/// kept by the device for every plan ([`GpuContext::program`]): compiled by the first
/// that asks.
fn fft_kernel(ctx: &GpuContext, file: &str, source: &str, entry: &str) -> Result<Kernel> {
    ctx.kernel(file, source, Some(&FFT_BINDINGS), entry)
}

/// A GPU FFT made ready once for one shape, direction, normalisation and variant: the
/// shader module, the pipelines, the twiddle tables, the per-pass parameters and the
/// second ping-pong buffer are built by [`GpuFftPlan::new`] and reused by every
/// [`GpuFftPlan::execute_buffer`] (only the bind groups are made per call, which is
/// cheap). Use it when the same transform runs many times, as the inverse 2-D FFT of
/// every Fourier-volume-rendering view does ([`crate::gpu::fvr`]).
pub struct GpuFftPlan {
    shape: Vec<usize>,
    total: usize,
    factor: f32,
    /// Every dispatch of the whole transform, in order.
    steps: Vec<Step>,
    /// Which data buffer holds the result after the last step (0: the input's).
    result: usize,
    /// The bind group layout and pipeline layout of every FFT pass (also used by the
    /// two-real split), one per device.
    /// The passes' pipelines by entry point, kept by the device for every plan.
    pipelines: Vec<(&'static str, Kernel)>,
    /// The tables the steps bind (twiddles, Bluestein's chirps and kernels).
    tables: Vec<wgpu::Buffer>,
    /// The second ping-pong buffer (`None` when there is no pass).
    pong: Option<wgpu::Buffer>,
    /// Bluestein's two work buffers (`None` when every axis is a power of two).
    work: Option<[wgpu::Buffer; 2]>,
    query: Option<super::context::TimestampPair>,
}

/// A buffer a step reads or writes: one of the two data buffers (0 the input's, 1 the
/// plan's own) or one of Bluestein's two work buffers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Slot {
    Data(usize),
    Work(usize),
}

/// One recorded dispatch of a [`GpuFftPlan`].
struct Step {
    entry: &'static str,
    /// Its [`FftParams`].
    uniform: wgpu::Buffer,
    src: Slot,
    dst: Slot,
    /// Index into [`GpuFftPlan::tables`] of what binding 3 holds.
    table: usize,
    invocations: u32,
}

/// The tables a plan uploads, each once.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Table {
    Twiddles(usize, Direction),
    Chirp(usize, Direction),
    Kernel(usize, Direction),
}

impl Table {
    fn values(self) -> Vec<Complex<f64>> {
        match self {
            Table::Twiddles(n, dir) => twiddle_table(n, dir),
            Table::Chirp(n, dir) => bluestein_chirp(n, dir),
            Table::Kernel(n, dir) => bluestein_kernel(n, device_line_length(n), dir),
        }
    }
}

impl GpuFftPlan {
    /// Prepares the N-D transform of every axis of an array of `shape`.
    ///
    /// # Errors
    /// As [`fft_nd`] (one storage binding, no split), [`Error::Gpu`] when a
    /// shader fails to compile.
    pub fn new(
        ctx: &GpuContext,
        shape: &[usize],
        dir: Direction,
        norm: Normalization,
        variant: GpuFftVariant,
    ) -> Result<Self> {
        let axes: Vec<usize> = (0..shape.len()).collect();
        let total = shape
            .iter()
            .try_fold(1usize, |a, &n| a.checked_mul(n))
            .ok_or_else(|| Error::too_large("fft shape", format!("{shape:?} overflows")))?;
        validate(ctx, total, shape, &axes)?;
        Self::with_axes(ctx, shape, &axes, dir, norm, variant)
    }

    /// Prepares a batch of `lines` 1-D transforms of length `n` (the last axis of the
    /// array `[lines, n]`), each scaled by `norm` for length `n`: the plan of
    /// [`fft_lines`], kept for reuse with [`GpuFftPlan::encode_in_place`].
    ///
    /// # Errors
    /// As [`fft_lines`].
    pub fn lines(
        ctx: &GpuContext,
        lines: usize,
        n: usize,
        dir: Direction,
        norm: Normalization,
        variant: GpuFftVariant,
    ) -> Result<Self> {
        let shape = [lines, n];
        let total = lines
            .checked_mul(n)
            .ok_or_else(|| Error::too_large("fft shape", format!("{shape:?} overflows")))?;
        validate(ctx, total, &shape, &[1])?;
        Self::with_axes(ctx, &shape, &[1], dir, norm, variant)
    }

    /// Records the whole transform of the array in `buffer` (`[re, im]` f32 pairs,
    /// exactly the array's size, `STORAGE`; it may be overwritten) into `enc`, with no
    /// readback, and returns the buffer that will hold the result (`buffer` or the
    /// plan's own second buffer, valid until the plan records again).
    pub fn encode_in_place<'a>(
        &'a self,
        ctx: &GpuContext,
        enc: &mut wgpu::CommandEncoder,
        buffer: &'a wgpu::Buffer,
    ) -> &'a wgpu::Buffer {
        self.encode(ctx, enc, buffer)
    }

    /// The shape this plan transforms.
    pub fn shape(&self) -> &[usize] {
        &self.shape
    }

    /// The compute dispatches one run records: one per step of [`axis_plan`] of every
    /// axis (none when every transformed axis has length 1).
    pub fn dispatches(&self) -> usize {
        if self.pong.is_some() {
            self.steps.len()
        } else {
            0
        }
    }

    /// The plan for the already validated `shape` along `axes`.
    fn with_axes(
        ctx: &GpuContext,
        shape: &[usize],
        axes: &[usize],
        dir: Direction,
        norm: Normalization,
        variant: GpuFftVariant,
    ) -> Result<Self> {
        let total: usize = shape.iter().product();
        let transformed: usize = axes.iter().map(|&a| shape[a]).product();
        let factor = norm.apply(1.0, transformed, dir) as f32;
        let planned: Vec<(usize, FftStep)> = axes
            .iter()
            .flat_map(|&axis| {
                axis_plan(variant, shape[axis])
                    .into_iter()
                    .map(move |s| (axis, s))
            })
            .collect();
        let dev = &ctx.device;
        let mut plan = GpuFftPlan {
            shape: shape.to_vec(),
            total,
            factor,
            steps: Vec::with_capacity(planned.len()),
            result: 0,
            pipelines: Vec::new(),
            tables: Vec::new(),
            pong: None,
            work: None,
            query: None,
        };
        if total == 0 || planned.is_empty() {
            return Ok(plan);
        }
        // The two shaders' sources; their modules are compiled only for the pipelines
        // the device does not keep yet.
        let variant_source = (
            match variant {
                GpuFftVariant::SplitStream => "fft_split_stream.wgsl",
                GpuFftVariant::Stockham | GpuFftVariant::StockhamGlobal => "fft_stockham.wgsl",
            },
            variant.shader_source(),
        );
        let bluestein_source = planned
            .iter()
            .any(|(_, s)| *s == FftStep::BluesteinLoad)
            .then(|| {
                (
                    "fft_bluestein.wgsl",
                    super::shaders::resolve("fft_bluestein"),
                )
            });
        let mut table_keys: Vec<Table> = Vec::new();
        let mut table_of = |key: Table| match table_keys.iter().position(|&k| k == key) {
            Some(i) => i,
            None => {
                table_keys.push(key);
                table_keys.len() - 1
            }
        };
        // The data's ping-pong buffer holding the current values, and the work's.
        let (mut data, mut work) = (0usize, 0usize);
        let last = planned.len() - 1;
        for (i, &(axis, step)) in planned.iter().enumerate() {
            let n = shape[axis];
            let m = device_line_length(n);
            let batch = total / n;
            let mut params = FftParams {
                n: n as u32,
                log2n: m.trailing_zeros(),
                stride: shape[axis + 1..].iter().product::<usize>() as u32,
                batch: batch as u32,
                stage: 0,
                direction: (dir == Direction::Inverse) as u32,
                span: m as u32,
                scale: if i == last { factor } else { 1.0 },
            };
            let (src, dst, table, invocations) = match step {
                FftStep::Pass(pass) => {
                    params.stage = pass.stage();
                    params.span = pass.span();
                    data ^= 1;
                    let items = pass.invocations(n, batch);
                    (
                        Slot::Data(data ^ 1),
                        Slot::Data(data),
                        table_of(Table::Twiddles(n, dir)),
                        items,
                    )
                }
                FftStep::BluesteinLoad => {
                    work = 0;
                    let chirp = table_of(Table::Chirp(n, dir));
                    (Slot::Data(data), Slot::Work(0), chirp, m * batch)
                }
                FftStep::Inner { pass, inverse } => {
                    let inner_dir = if inverse {
                        Direction::Inverse
                    } else {
                        Direction::Forward
                    };
                    params = FftParams {
                        n: m as u32,
                        log2n: m.trailing_zeros(),
                        stride: 1,
                        batch: batch as u32,
                        stage: pass.stage(),
                        direction: inverse as u32,
                        span: pass.span(),
                        scale: 1.0,
                    };
                    work ^= 1;
                    let items = pass.invocations(m, batch);
                    (
                        Slot::Work(work ^ 1),
                        Slot::Work(work),
                        table_of(Table::Twiddles(m, inner_dir)),
                        items,
                    )
                }
                FftStep::BluesteinMultiply => {
                    work ^= 1;
                    let kernel = table_of(Table::Kernel(n, dir));
                    (Slot::Work(work ^ 1), Slot::Work(work), kernel, m * batch)
                }
                FftStep::BluesteinStore => {
                    data ^= 1;
                    let chirp = table_of(Table::Chirp(n, dir));
                    (Slot::Work(work), Slot::Data(data), chirp, n * batch)
                }
            };
            let entry = step.entry_point();
            if !plan.pipelines.iter().any(|(e, _)| *e == entry) {
                let (file, source) = match step {
                    FftStep::Pass(_) | FftStep::Inner { .. } => &variant_source,
                    _ => bluestein_source
                        .as_ref()
                        .expect("resolved for Bluestein's steps"),
                };
                let kernel = fft_kernel(ctx, file, source, entry)?;
                plan.pipelines.push((entry, kernel));
            }
            plan.steps.push(Step {
                entry,
                uniform: dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("fft params"),
                    contents: bytemuck::bytes_of(&params),
                    usage: super::context::PARAMS_USAGE,
                }),
                src,
                dst,
                table,
                invocations: invocations as u32,
            });
        }
        plan.result = data;
        plan.tables = table_keys
            .iter()
            .map(|key| {
                let t: Vec<[f32; 2]> = key
                    .values()
                    .iter()
                    .map(|w| [w.re as f32, w.im as f32])
                    .collect();
                dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("fft table"),
                    contents: bytemuck::cast_slice(&t),
                    usage: wgpu::BufferUsages::STORAGE,
                })
            })
            .collect();
        plan.pong = Some(ctx.storage_buffer("fft data b", (total * 8) as u64)?);
        let work_len = work_len(shape, axes);
        if work_len > 0 {
            let bytes = (work_len * 8) as u64;
            plan.work = Some([
                ctx.storage_buffer("fft Bluestein work a", bytes)?,
                ctx.storage_buffer("fft Bluestein work b", bytes)?,
            ]);
        }
        plan.query = ctx.timestamps();
        Ok(plan)
    }

    /// Runs the plan on complex f32 values already on the device (`[re, im]` pairs,
    /// `STORAGE | COPY_SRC`, exactly the array's size; overwritten) and reads the
    /// result back. `setup` in the timings is 0 (the plan was built before).
    ///
    /// # Errors
    /// [`Error::Invalid`] when the buffer's size is not the array's; [`Error::Gpu`] on
    /// device failure.
    pub fn execute_buffer(&self, ctx: &GpuContext, buffer: &wgpu::Buffer) -> Result<GpuFftOutput> {
        if self.total as u64 * 8 != buffer.size() {
            return Err(Error::invalid(
                "fft buffer",
                format!(
                    "{} bytes do not hold an array of shape {:?}",
                    buffer.size(),
                    self.shape
                ),
            ));
        }
        self.execute(ctx, Input::Device(buffer, self.total))
    }

    /// Records every pass on the array in `ping` (which it may overwrite) into `enc`,
    /// with the timestamp writes and their resolve when the adapter has them, and
    /// returns the buffer that will hold the result: `ping` or the plan's own second
    /// buffer. With no pass (all axes of length 1) nothing is recorded and the result
    /// is `ping` unscaled.
    fn encode<'a>(
        &'a self,
        ctx: &GpuContext,
        enc: &mut wgpu::CommandEncoder,
        ping: &'a wgpu::Buffer,
    ) -> &'a wgpu::Buffer {
        let Some(pong) = &self.pong else {
            return ping;
        };
        let data = [ping, pong];
        let buffer = |slot| match (slot, &self.work) {
            (Slot::Data(i), _) => data[i],
            (Slot::Work(i), Some(work)) => &work[i],
            (Slot::Work(_), None) => unreachable!("Bluestein's steps come with work buffers"),
        };
        let query = self.query.as_ref();
        let last = self.steps.len() - 1;
        for (i, step) in self.steps.iter().enumerate() {
            let Kernel { layout, pipeline } = &self
                .pipelines
                .iter()
                .find(|(e, _)| *e == step.entry)
                .expect("every entry point has a pipeline")
                .1;
            let bind = ctx.bind_group(
                "fft pass",
                layout,
                &[
                    step.uniform.as_entire_binding(),
                    buffer(step.src).as_entire_binding(),
                    buffer(step.dst).as_entire_binding(),
                    self.tables[step.table].as_entire_binding(),
                ],
            );
            let (x, y) = workgroups(ctx, step.invocations);
            let mut cpass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(step.entry),
                // The first pass writes the start, the last the end (a pass must
                // write at least one, so the middle ones write none).
                timestamp_writes: query.filter(|_| i == 0 || i == last).map(|q| {
                    wgpu::ComputePassTimestampWrites {
                        query_set: &q.set,
                        beginning_of_pass_write_index: (i == 0).then_some(0),
                        end_of_pass_write_index: (i == last).then_some(1),
                    }
                }),
            });
            cpass.set_pipeline(pipeline);
            cpass.set_bind_group(0, &bind, &[]);
            cpass.dispatch_workgroups(x, y, 1);
        }
        if let Some(q) = query {
            q.resolve(enc);
        }
        data[self.result]
    }

    fn execute(&self, ctx: &GpuContext, input: Input<'_>) -> Result<GpuFftOutput> {
        let t_start = Instant::now();
        let done = |data: Vec<Complex<f32>>, timings: FftTimings| {
            Ok(GpuFftOutput {
                data,
                timings: FftTimings {
                    total: t_start.elapsed().as_secs_f64(),
                    ..timings
                },
            })
        };
        if input.len() == 0 {
            return done(Vec::new(), FftTimings::default());
        }
        let factor = self.factor;
        if self.pong.is_none() {
            // Every transformed axis has length 1: the transform is the identity.
            let data = match input {
                Input::Host(d) => d.to_vec(),
                Input::Device(b, n) => read_complex(ctx, b, n)?,
            };
            return done(
                data.iter().map(|v| v * factor).collect(),
                FftTimings::default(),
            );
        }
        let dev = &ctx.device;
        let t_up = Instant::now();
        let uploaded;
        let (ping, upload) = match input {
            Input::Host(data) => {
                let host: Vec<[f32; 2]> = data.iter().map(|v| [v.re, v.im]).collect();
                uploaded = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("fft data a"),
                    contents: bytemuck::cast_slice(&host),
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                });
                ctx.wait()?;
                (&uploaded, t_up.elapsed().as_secs_f64())
            }
            Input::Device(b, _) => (b, 0.0),
        };
        let query = self.query.as_ref();
        let t_k = Instant::now();
        let mut enc = dev.create_command_encoder(&Default::default());
        let result = self.encode(ctx, &mut enc, ping);
        ctx.queue.submit([enc.finish()]);
        ctx.wait()?;
        let kernel = match query {
            Some(q) => q.seconds(ctx)?,
            None => t_k.elapsed().as_secs_f64(),
        };
        let t_r = Instant::now();
        let result = read_complex(ctx, result, self.total)?;
        let readback = t_r.elapsed().as_secs_f64();
        done(
            result,
            FftTimings {
                setup: 0.0,
                upload,
                kernel,
                kernel_from_timestamps: query.is_some(),
                readback,
                total: 0.0,
                dispatches: self.dispatches(),
            },
        )
    }
}

/// The two spectra `(A, B)` of [`two_real_ffts`].
pub type TwoSpectra = (Vec<Complex<f32>>, Vec<Complex<f32>>);

/// The unscaled forward FFTs of two real lines of the same length (any length) through
/// one complex GPU FFT: the port of [`crate::cpu::fft::two_real_ffts`]. `z = a + i·b` is
/// uploaded, transformed once (Stockham) and split on the device by the Hermitian
/// symmetry of real-input spectra, `A_k = (Z_k + conj(Z_{N−k})) / 2` and
/// `B_k = (Z_k − conj(Z_{N−k})) / (2i)` (`shaders/fft_two_real.wgsl: split_two_real`,
/// one invocation per `k`); both full spectra (`N` bins each) are read back. This is
/// how Jansen et al. (§3) transform real data at the cost of half a complex transform
/// each.
///
/// # Errors
/// [`Error::Invalid`] when the lengths differ;
/// [`Error::TooLarge`] when the `2N` outputs exceed one storage binding;
/// [`Error::Gpu`] on device failure.
pub fn two_real_ffts(ctx: &GpuContext, a: &[f32], b: &[f32]) -> Result<TwoSpectra> {
    if a.len() != b.len() {
        return Err(Error::invalid(
            "two_real_ffts",
            format!("lines of {} and {} samples", a.len(), b.len()),
        ));
    }
    let n = a.len();
    if n == 0 {
        return Ok((Vec::new(), Vec::new()));
    }
    validate(ctx, 2 * n, &[2 * n], &[])?;
    let plan = GpuFftPlan::new(
        ctx,
        &[n],
        Direction::Forward,
        Normalization::Unnormalized,
        GpuFftVariant::Stockham,
    )?;
    let dev = &ctx.device;
    let source = super::shaders::resolve("fft_two_real");
    let Kernel { layout, pipeline } =
        fft_kernel(ctx, "fft_two_real.wgsl", &source, "two_real_split")?;
    let z: Vec<[f32; 2]> = a.iter().zip(b).map(|(&x, &y)| [x, y]).collect();
    let zbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("two real z"),
        contents: bytemuck::cast_slice(&z),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
    });
    let params = FftParams {
        n: n as u32,
        log2n: n.trailing_zeros(),
        stride: 1,
        batch: 1,
        scale: 1.0,
        ..FftParams::default()
    };
    let ubuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("two real params"),
        contents: bytemuck::bytes_of(&params),
        usage: super::context::PARAMS_USAGE,
    });
    let out = ctx.storage_buffer("two real spectra", (2 * n * 8) as u64)?;
    let mut enc = dev.create_command_encoder(&Default::default());
    let spectrum = plan.encode(ctx, &mut enc, &zbuf);
    // Binding 3 (twiddles) is unused by the split; it is bound to the input again.
    let bind = ctx.bind_group(
        "two real split",
        &layout,
        &[
            ubuf.as_entire_binding(),
            spectrum.as_entire_binding(),
            out.as_entire_binding(),
            spectrum.as_entire_binding(),
        ],
    );
    let (x, y) = workgroups(ctx, n as u32);
    {
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("two_real_split"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups(x, y, 1);
    }
    ctx.queue.submit([enc.finish()]);
    ctx.wait()?;
    let mut both = read_complex(ctx, &out, 2 * n)?;
    let second = both.split_off(n);
    Ok((both, second))
}

/// Reads `n` complex f32 values back from `buffer`.
fn read_complex(ctx: &GpuContext, buffer: &wgpu::Buffer, n: usize) -> Result<Vec<Complex<f32>>> {
    let out = ctx.read_buffer(buffer, (n * 8) as u64)?;
    // (A byte vector need not be aligned for f32: copy rather than cast in place.)
    Ok(bytemuck::pod_collect_to_vec::<u8, [f32; 2]>(&out)
        .iter()
        .map(|v| Complex::new(v[0], v[1]))
        .collect())
}
