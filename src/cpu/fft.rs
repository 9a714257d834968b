//! The fast CPU Fourier transforms: N-D complex and real-input FFTs on RustFFT,
//! generic over `f32`/`f64`, parallel over the independent lines of each axis.
//!
//! The conventions are those of [`crate::cpu::dft`], the exact `O(N²)` oracle these
//! transforms are tested against: the same [`Direction`] (forward is `exp(−2πi·kn/N)`)
//! and [`Normalization`] (unitary `1/√N` both ways, as in Jansen et al. 2004; or numpy's
//! unscaled forward and `1/N` inverse; or no scaling), DC at index 0, row-major arrays
//! with the last axis fastest (a voxlab volume of dims `[nx, ny, nz]` is the array of
//! shape `[nz, ny, nx]`).
//!
//! **How it is organised.** An N-D transform is one pass of 1-D FFTs per axis, with one
//! RustFFT plan per axis length (RustFFT picks mixed-radix, Rader's or Bluestein's
//! algorithm, so every size costs `O(N log N)`, primes included):
//! - along the last axis the lines are contiguous: they are transformed in place, in
//!   parallel, each rayon worker holding its own scratch buffer;
//! - along any other axis a line is strided. Its elements are gathered into a contiguous
//!   line of a transposed buffer (`[line][N]`), transformed there, and scattered back,
//!   each step parallel over blocks of 16 lines or rows: neighbouring lines are
//!   neighbours in memory, so a block is read and written in runs of 16 values (a
//!   cache-friendly transpose) and RustFFT transforms the block's lines in one call.
//!   This costs one extra array of memory and keeps the code free of `unsafe`.
//!
//! The scale of the whole transform (the product of the per-axis scales) is applied once
//! at the end. The f32 instance's error against the f64 oracle is stated in `docs/fft.md`
//! (measured by `tests/fft.rs`).
//!
//! **Real input.** [`rfft_nd`] transforms real data and keeps, as numpy's `rfftn` does,
//! only the `N/2 + 1` non-negative frequencies of the last axis (the others are complex
//! conjugates: `X[−k] = conj(X[k])`); the other axes keep all their bins. [`irfft_nd`]
//! inverts it given the real output shape (the last axis length cannot be recovered
//! from `N/2 + 1` alone). As in numpy, the imaginary parts of the bins that must be real
//! (DC, and Nyquist for even `N`) are ignored.
//!
//! ```
//! use rustfft::num_complex::Complex;
//! use voxlab::cpu::dft::{Direction, Normalization};
//! use voxlab::cpu::fft::fft_nd;
//!
//! // A 2×4 array of ones: all its energy lands at DC.
//! let mut x = vec![Complex::new(1.0f32, 0.0); 8];
//! fft_nd(&mut x, &[2, 4], Direction::Forward, Normalization::Unitary);
//! assert!((x[0].re - 8.0f32.sqrt()).abs() < 1e-6);
//! assert!(x[1..].iter().all(|v| v.norm() < 1e-6));
//! ```

use crate::cpu::dft::{Direction, Normalization};
use rayon::prelude::*;
use rustfft::num_complex::Complex;
use rustfft::{Fft, FftDirection, FftNum, FftPlanner};
use std::sync::Arc;

fn zero<T: FftNum>() -> Complex<T> {
    Complex::new(T::zero(), T::zero())
}

fn fft_direction(dir: Direction) -> FftDirection {
    match dir {
        Direction::Forward => FftDirection::Forward,
        Direction::Inverse => FftDirection::Inverse,
    }
}

fn check_shape(len: usize, shape: &[usize], what: &str) {
    let total: usize = shape.iter().product();
    assert!(
        total == len,
        "{what}: shape {shape:?} describes {total} elements but the data has {len}"
    );
}

/// Unscaled 1-D FFTs along `axis` of the row-major array `data` of `shape`.
fn fft_axis<T: FftNum>(
    data: &mut [Complex<T>],
    shape: &[usize],
    axis: usize,
    fft: &Arc<dyn Fft<T>>,
) {
    let n = shape[axis];
    let inner: usize = shape[axis + 1..].iter().product();
    if data.is_empty() || n <= 1 {
        return;
    }
    let scratch_len = fft.get_inplace_scratch_len();
    if inner == 1 {
        data.par_chunks_mut(n).for_each_init(
            || vec![zero::<T>(); scratch_len],
            |scratch, line| fft.process_with_scratch(line, scratch),
        );
        return;
    }
    // Gather every strided line into a row of `t` ([line][n], line = outer·inner + c)
    // and transform it there. Lines are taken BLOCK at a time: neighbouring lines are
    // neighbours in memory, so one row `j` of a block is a contiguous read of BLOCK
    // values instead of BLOCK reads `inner` apart (a cache-friendly transpose).
    let mut t = vec![zero::<T>(); data.len()];
    {
        let src: &[Complex<T>] = data;
        t.par_chunks_mut(BLOCK * n).enumerate().for_each_init(
            || vec![zero::<T>(); scratch_len],
            |scratch, (b, block)| {
                let first = b * BLOCK;
                let lines = block.len() / n;
                let base: Vec<usize> = (first..first + lines)
                    .map(|l| (l / inner) * n * inner + l % inner)
                    .collect();
                for j in 0..n {
                    let off = j * inner;
                    for (li, &bl) in base.iter().enumerate() {
                        block[li * n + j] = src[bl + off];
                    }
                }
                // RustFFT transforms every length-n chunk of the block in one call.
                fft.process_with_scratch(block, scratch);
            },
        );
    }
    // Scatter back, BLOCK rows at a time: row r = outer·n + j of the array holds
    // t[(outer·inner + c)·n + j]; for one c the rows of a block read neighbours in t.
    data.par_chunks_mut(BLOCK * inner)
        .enumerate()
        .for_each(|(b, rows)| {
            let first = b * BLOCK;
            let count = rows.len() / inner;
            let src: Vec<usize> = (first..first + count)
                .map(|r| (r / n) * inner * n + r % n)
                .collect();
            for c in 0..inner {
                let off = c * n;
                for (ri, &s0) in src.iter().enumerate() {
                    rows[ri * inner + c] = t[s0 + off];
                }
            }
        });
}

/// Lines gathered (and rows scattered) together along a strided axis.
const BLOCK: usize = 16;

/// Multiplies every element by `factor` (skipped when it is 1).
fn scale<T: FftNum>(data: &mut [Complex<T>], factor: f64) {
    if factor != 1.0 {
        let f = T::from_f64(factor).expect("a scale factor is representable");
        data.par_iter_mut().for_each(|v| *v = *v * f);
    }
}

/// The N-D FFT in place of a row-major array of `shape` (last axis fastest), any sizes,
/// scaled by `norm` (the product of the per-axis scales). Parallel over the lines of
/// each axis; one plan per axis length.
///
/// # Panics
/// If the product of `shape` is not `data.len()`.
pub fn fft_nd<T: FftNum>(
    data: &mut [Complex<T>],
    shape: &[usize],
    dir: Direction,
    norm: Normalization,
) {
    check_shape(data.len(), shape, "fft_nd");
    if data.is_empty() {
        return;
    }
    let mut planner = FftPlanner::<T>::new();
    for axis in 0..shape.len() {
        let fft = planner.plan_fft(shape[axis], fft_direction(dir));
        fft_axis(data, shape, axis, &fft);
    }
    scale(data, norm.factor(shape, dir));
}

/// The forward FFT of a real line: the `N/2 + 1` non-negative frequencies.
///
/// # Panics
/// If `input` is empty.
pub fn rfft_1d<T: FftNum>(input: &[T], norm: Normalization) -> Vec<Complex<T>> {
    rfft_nd(input, &[input.len()], norm)
}

/// The shape of [`rfft_nd`]'s output for a real array of `shape`: the last axis becomes
/// `N/2 + 1`.
pub fn rfft_shape(shape: &[usize]) -> Vec<usize> {
    let mut s = shape.to_vec();
    if let Some(last) = s.last_mut() {
        *last = *last / 2 + 1;
    }
    s
}

fn check_real_shape(shape: &[usize], what: &str) {
    assert!(
        !shape.is_empty() && shape.iter().all(|&n| n > 0),
        "{what}: every axis of a real transform needs at least one sample, got {shape:?}"
    );
}

/// The forward N-D FFT of a real row-major array of `shape`, laid out as numpy's
/// `rfftn`: shape [`rfft_shape`]`(shape)`, i.e. only the `N/2 + 1` non-negative
/// frequencies of the last axis, all bins of the others.
///
/// # Panics
/// If the product of `shape` is not `input.len()`, or an axis is empty.
pub fn rfft_nd<T: FftNum>(input: &[T], shape: &[usize], norm: Normalization) -> Vec<Complex<T>> {
    check_shape(input.len(), shape, "rfft_nd");
    check_real_shape(shape, "rfft_nd");
    let n = *shape.last().expect("checked non-empty");
    let h = n / 2 + 1;
    let mut planner = FftPlanner::<T>::new();
    // Last axis: full complex FFT of each row, keep the first h bins.
    let fft = planner.plan_fft(n, FftDirection::Forward);
    let scratch_len = fft.get_inplace_scratch_len();
    let mut out = vec![zero::<T>(); input.len() / n * h];
    out.par_chunks_mut(h)
        .zip(input.par_chunks(n))
        .for_each_init(
            || (vec![zero::<T>(); n], vec![zero::<T>(); scratch_len]),
            |(line, scratch), (o, x)| {
                for (l, &v) in line.iter_mut().zip(x) {
                    *l = Complex::new(v, T::zero());
                }
                fft.process_with_scratch(line, scratch);
                o.copy_from_slice(&line[..h]);
            },
        );
    let half = rfft_shape(shape);
    for (axis, &len) in shape[..shape.len() - 1].iter().enumerate() {
        let fft = planner.plan_fft(len, FftDirection::Forward);
        fft_axis(&mut out, &half, axis, &fft);
    }
    scale(&mut out, norm.factor(shape, Direction::Forward));
    out
}

/// The inverse of [`rfft_nd`]: from the half spectrum (shape [`rfft_shape`]`(shape)`)
/// back to the real array of `shape`. The missing bins of the last axis are the complex
/// conjugates of the stored ones; imaginary parts that must vanish are ignored.
///
/// # Panics
/// If `input` does not have `rfft_shape(shape)`'s element count, or an axis is empty.
pub fn irfft_nd<T: FftNum>(input: &[Complex<T>], shape: &[usize], norm: Normalization) -> Vec<T> {
    check_real_shape(shape, "irfft_nd");
    let half = rfft_shape(shape);
    check_shape(input.len(), &half, "irfft_nd");
    let n = *shape.last().expect("checked non-empty");
    let h = n / 2 + 1;
    let mut spec = input.to_vec();
    let mut planner = FftPlanner::<T>::new();
    for (axis, &len) in shape[..shape.len() - 1].iter().enumerate() {
        let fft = planner.plan_fft(len, FftDirection::Inverse);
        fft_axis(&mut spec, &half, axis, &fft);
    }
    let fft = planner.plan_fft(n, FftDirection::Inverse);
    let scratch_len = fft.get_inplace_scratch_len();
    let f = T::from_f64(norm.factor(shape, Direction::Inverse)).expect("representable");
    let mut out = vec![T::zero(); spec.len() / h * n];
    out.par_chunks_mut(n).zip(spec.par_chunks(h)).for_each_init(
        || (vec![zero::<T>(); n], vec![zero::<T>(); scratch_len]),
        |(line, scratch), (o, x)| {
            line[..h].copy_from_slice(x);
            for k in h..n {
                line[k] = x[n - k].conj();
            }
            fft.process_with_scratch(line, scratch);
            for (v, l) in o.iter_mut().zip(line.iter()) {
                *v = l.re * f;
            }
        },
    );
    out
}

/// The unscaled forward FFTs of two real lines of the same length through one complex
/// FFT: `z = a + i·b` is transformed once and split by symmetry,
/// `A_k = (Z_k + conj(Z_{N−k})) / 2` and `B_k = (Z_k − conj(Z_{N−k})) / (2i)`
/// (indices mod `N`). All `N` bins of each spectrum are returned.
///
/// # Panics
/// If `a` and `b` differ in length.
pub fn two_real_ffts(a: &[f64], b: &[f64]) -> (Vec<Complex<f64>>, Vec<Complex<f64>>) {
    assert!(
        a.len() == b.len(),
        "two_real_ffts: lines of {} and {} samples",
        a.len(),
        b.len()
    );
    let n = a.len();
    let mut z: Vec<Complex<f64>> = a.iter().zip(b).map(|(&x, &y)| Complex::new(x, y)).collect();
    fft_nd(
        &mut z,
        &[n],
        Direction::Forward,
        Normalization::Unnormalized,
    );
    (0..n)
        .map(|k| split_two_real(z[k], z[(n - k) % n]))
        .unzip()
}

/// One bin of both real spectra from the complex spectrum `Z` of `a + i·b`:
/// `zk = Z_k`, `zm = Z_{(N−k) mod N}`; returns
/// `(A_k, B_k) = ((Z_k + conj(Z_{N−k})) / 2, (Z_k − conj(Z_{N−k})) / (2i))`.
// mirrors shaders/fft_two_real.wgsl: split_two_real
pub fn split_two_real(zk: Complex<f64>, zm: Complex<f64>) -> (Complex<f64>, Complex<f64>) {
    let zc = zm.conj();
    // (zk − zc) / (2i) = −i·(zk − zc) / 2.
    let d = zk - zc;
    ((zk + zc) * 0.5, Complex::new(d.im, -d.re) * 0.5)
}
