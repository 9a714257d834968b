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
//! - along any other axis a line is strided. Lines are taken 32 at a time: neighbouring
//!   lines are neighbours in memory, so a block of 32 is, in every row, one contiguous
//!   run of 32 values. The runs are gathered into a small contiguous buffer
//!   (`[line][N]`, a cache-friendly transpose), RustFFT transforms the 32 lines in one
//!   call, and the runs are written back in place; parallel over blocks. One read and
//!   one write of the array per axis, no full-size copy, and no `unsafe` (each block
//!   borrows its own disjoint runs).
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
use std::any::{Any, TypeId};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

fn zero<T: FftNum>() -> Complex<T> {
    Complex::new(T::zero(), T::zero())
}

/// The RustFFT plan of length `n`, made once per element type, length and direction
/// and shared by every later call (planning allocates twiddles and, for some lengths,
/// chooses among algorithms: a view of Fourier volume rendering or a small transform
/// must not pay for it every time).
fn cached_plan<T: FftNum>(n: usize, dir: FftDirection) -> Arc<dyn Fft<T>> {
    type Plans = HashMap<(TypeId, usize, bool), Box<dyn Any + Send + Sync>>;
    static PLANS: OnceLock<Mutex<Plans>> = OnceLock::new();
    let key = (TypeId::of::<T>(), n, dir == FftDirection::Forward);
    let mut plans = PLANS
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some(p) = plans
        .get(&key)
        .and_then(|b| b.downcast_ref::<Arc<dyn Fft<T>>>())
    {
        return Arc::clone(p);
    }
    // Bounded: a program that cycles through many lengths replans now and then.
    if plans.len() >= 256 {
        plans.clear();
    }
    let p = FftPlanner::<T>::new().plan_fft(n, dir);
    plans.insert(key, Box::new(Arc::clone(&p)));
    p
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
    // Lines along a strided axis, BLOCK neighbouring lines at a time: neighbouring
    // lines are neighbours in memory, so row `j` of a block is one contiguous run of
    // BLOCK values. Each block's runs are borrowed (disjoint `&mut` slices, one per
    // row), gathered into a small contiguous buffer `[line][n]` that stays in cache,
    // transformed there by one RustFFT call, and written back: one read and one write
    // of the array per axis, no full-size copy, no `unsafe`.
    let per_slab = inner.div_ceil(BLOCK);
    let mut blocks: Vec<Vec<&mut [Complex<T>]>> =
        Vec::with_capacity(data.len() / (n * inner) * per_slab);
    for slab in data.chunks_mut(n * inner) {
        let start = blocks.len();
        blocks.extend((0..per_slab).map(|_| Vec::with_capacity(n)));
        for row in slab.chunks_mut(inner) {
            for (k, run) in row.chunks_mut(BLOCK).enumerate() {
                blocks[start + k].push(run);
            }
        }
    }
    let scratch_len = fft.get_outofplace_scratch_len();
    blocks.into_par_iter().for_each_init(
        || {
            (
                vec![zero::<T>(); BLOCK * n],
                vec![zero::<T>(); BLOCK * n],
                vec![zero::<T>(); scratch_len],
            )
        },
        |(a, b, scratch), mut rows| {
            let lines = rows[0].len();
            let (a, b) = (&mut a[..lines * n], &mut b[..lines * n]);
            for (j, run) in rows.iter().enumerate() {
                for (l, v) in run.iter().enumerate() {
                    a[l * n + j] = *v;
                }
            }
            // RustFFT transforms every length-n chunk in one call (out of place: its
            // in-place transform would copy through its scratch anyway).
            fft.process_outofplace_with_scratch(a, b, scratch);
            for (j, run) in rows.iter_mut().enumerate() {
                for (l, v) in run.iter_mut().enumerate() {
                    *v = b[l * n + j];
                }
            }
        },
    );
}

/// Neighbouring lines transformed together along a strided axis (32 complex values are
/// 256 bytes in f32, four cache lines).
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
    let d = shape.len();
    let plans: Vec<Arc<dyn Fft<T>>> = shape
        .iter()
        .map(|&n| cached_plan::<T>(n, fft_direction(dir)))
        .collect();
    // With three axes or more, the last two are transformed slab by slab while a slab
    // is in cache (one read and one write of the array for both axes instead of two).
    let mut separate = d;
    if d >= 3 {
        let (ny, nx) = (shape[d - 2], shape[d - 1]);
        if ny * nx * std::mem::size_of::<Complex<T>>() <= SLAB_BYTES {
            slab_2d(data, ny, nx, &plans[d - 2], &plans[d - 1]);
            separate = d - 2;
        }
    }
    for (axis, plan) in plans.iter().enumerate().take(separate) {
        fft_axis(data, shape, axis, plan);
    }
    scale(data, norm.factor(shape, dir));
}

/// Largest `[ny][nx]` slab transformed in one piece by [`slab_2d`] (a typical L2).
const SLAB_BYTES: usize = 1 << 20;

/// The 2-D FFT of every contiguous `[ny][nx]` slab of `data`, one slab per task: the
/// rows in place, then the columns BLOCK at a time through a small transposed buffer.
fn slab_2d<T: FftNum>(
    data: &mut [Complex<T>],
    ny: usize,
    nx: usize,
    fy: &Arc<dyn Fft<T>>,
    fx: &Arc<dyn Fft<T>>,
) {
    let scratch_len = fx
        .get_inplace_scratch_len()
        .max(fy.get_outofplace_scratch_len());
    data.par_chunks_mut(ny * nx).for_each_init(
        || {
            (
                vec![zero::<T>(); BLOCK * ny],
                vec![zero::<T>(); BLOCK * ny],
                vec![zero::<T>(); scratch_len],
            )
        },
        |(a, b, scratch), slab| {
            if nx > 1 {
                fx.process_with_scratch(slab, &mut scratch[..fx.get_inplace_scratch_len()]);
            }
            if ny <= 1 {
                return;
            }
            let oop = fy.get_outofplace_scratch_len();
            for c0 in (0..nx).step_by(BLOCK) {
                let lines = BLOCK.min(nx - c0);
                let (a, b) = (&mut a[..lines * ny], &mut b[..lines * ny]);
                for j in 0..ny {
                    let run = &slab[j * nx + c0..j * nx + c0 + lines];
                    for (l, v) in run.iter().enumerate() {
                        a[l * ny + j] = *v;
                    }
                }
                fy.process_outofplace_with_scratch(a, b, &mut scratch[..oop]);
                for j in 0..ny {
                    let run = &mut slab[j * nx + c0..j * nx + c0 + lines];
                    for (l, v) in run.iter_mut().enumerate() {
                        *v = b[l * ny + j];
                    }
                }
            }
        },
    );
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
    (0..n).map(|k| split_two_real(z[k], z[(n - k) % n])).unzip()
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
