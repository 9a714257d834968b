//! The exact discrete Fourier transform: the oracle every FFT is checked against.
//!
//! For a line of `N` complex samples `x_n`, `n = 0 … N−1`, the DFT is
//!
//! ```text
//! X_k = s · Σ_{n=0}^{N−1} x_n · exp(∓2πi·k·n/N),   k = 0 … N−1
//! ```
//!
//! with the minus sign for [`Direction::Forward`] and the plus sign for
//! [`Direction::Inverse`]. The scale `s` is set by [`Normalization`]:
//!
//! | normalisation | forward `s` | inverse `s` | |
//! |---|---|---|---|
//! | [`Normalization::Unitary`] | `1/√N` | `1/√N` | Jansen et al. (2004) eqs. (9)–(10); preserves the L2 norm |
//! | [`Normalization::Unnormalized`] | `1` | `1/N` | numpy's default (`norm="backward"`) |
//! | [`Normalization::None`] | `1` | `1` | the raw sums; a round trip multiplies by `N` |
//!
//! **Frequency order.** Bin `k` holds frequency `k` cycles per line for `k ≤ N/2` and
//! frequency `k − N` for `k > N/2`: DC is at index 0, the positive frequencies follow,
//! the negative ones fill the second half. For even `N`, bin `N/2` is the Nyquist
//! frequency (±N/2 alike). [`fftshift`] moves DC to the middle (index `N/2`, rounded
//! down), [`ifftshift`] undoes it; the `*_centered` transforms have DC in the middle of
//! both input and output.
//!
//! **Axis order.** N-D arrays are row-major (C order): the last axis of `shape` varies
//! fastest. A voxlab volume of dims `[nx, ny, nz]` (x fastest in memory) is therefore
//! the array of shape `[nz, ny, nx]`: its x axis is the last axis. The N-D transform is
//! separable, one pass of 1-D transforms along every axis, and its scale is the product
//! of the per-axis scales (for `Unitary`, `1/√(N_0·N_1·…)`).
//!
//! **Exact twiddles.** The phase `k·n/N` is reduced to `m = (k·n) mod N` in integer
//! arithmetic, so no rounding enters before the angle is formed. The angle `2π·m/N` is
//! then split into a quarter turn `q = ⌊4m/N⌋` (exact, integer) and a remainder
//! `r = 4m mod N` (exact), and the remainder angle `(π/2)·r/N` is folded into the first
//! octant `[0, π/4]` (using `cos(π/2 − φ) = sin φ`); `sin`/`cos` are only ever evaluated
//! on `[0, π/4]`, where they are accurate to about one ulp, and the quarter turn is an
//! exact swap of components and signs. Twiddles are never made by multiplying rotations
//! together (that accumulates error proportional to the number of steps). The `N`
//! twiddles of one length are tabulated once ([`twiddle`] gives one of them).
//!
//! **Summation.** Each output bin is summed in `f64` with Neumaier's compensated sum,
//! in the order `n = 0 … N−1`, separately for the real and imaginary parts: the error
//! of the sum does not grow with `N` the way a plain running sum's does. (Each product
//! `x_n·w` is rounded once, an error of at most about one ulp per term.)
//!
//! **Cost.** `O(N²)` per line (an N-D transform costs `Σ_axes (total/N_a)·N_a²`).
//! Work is spread over output bins (1-D) or independent lines (N-D) with rayon; each
//! bin is summed by one thread in a fixed order, so the result is bit-identical for any
//! thread count.
//!
//! ```
//! use rustfft::num_complex::Complex;
//! use voxlab::cpu::dft::{dft_1d, Direction, Normalization};
//!
//! // The DFT of a delta at n = 0 is constant.
//! let mut x = vec![Complex::new(0.0, 0.0); 8];
//! x[0] = Complex::new(1.0, 0.0);
//! let big_x = dft_1d(&x, Direction::Forward, Normalization::Unnormalized);
//! assert!(big_x.iter().all(|&v| v == Complex::new(1.0, 0.0)));
//! ```
//!
//! The fast path is [`crate::cpu::fft`], which uses the same [`Direction`] and
//! [`Normalization`] and is tested against this module.

use rayon::prelude::*;
use rustfft::num_complex::Complex;
use std::f64::consts::{FRAC_1_SQRT_2, FRAC_PI_2};

/// The sign of the exponent: `Forward` is `exp(−2πi·kn/N)`, `Inverse` is
/// `exp(+2πi·kn/N)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Direction {
    Forward,
    Inverse,
}

impl Direction {
    /// The other direction.
    pub fn reverse(self) -> Self {
        match self {
            Direction::Forward => Direction::Inverse,
            Direction::Inverse => Direction::Forward,
        }
    }
}

/// How a transform of length `N` is scaled (see the module docs for the table).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Normalization {
    /// `1/√N` both ways, as in Jansen et al. (2004): the transform is unitary.
    Unitary,
    /// Forward unscaled, inverse `1/N`, as numpy's `fft`/`ifft`.
    Unnormalized,
    /// No scaling either way.
    None,
}

impl Normalization {
    /// Scales `v` as a transform of length `n` in direction `dir` must: divides by
    /// `√n`, by `n`, or leaves it alone. A single correctly rounded division.
    #[inline]
    pub fn apply(self, v: f64, n: usize, dir: Direction) -> f64 {
        match (self, dir) {
            (Normalization::Unitary, _) => v / (n as f64).sqrt(),
            (Normalization::Unnormalized, Direction::Inverse) => v / n as f64,
            _ => v,
        }
    }

    /// The factor a transform over `shape` applies: the product of the per-axis
    /// factors (`1/√total` for `Unitary`, `1/total` for an `Unnormalized` inverse).
    pub fn factor(self, shape: &[usize], dir: Direction) -> f64 {
        let total: usize = shape.iter().product();
        self.apply(1.0, total.max(1), dir)
    }
}

/// `exp(sign·2πi·m/n)` for `0 ≤ m < n`, with `sign = −1` forward and `+1` inverse,
/// computed from the exact quarter turn and a first-octant angle (see the module docs).
///
/// # Panics
/// If `n == 0` or `m >= n`.
pub fn twiddle(m: usize, n: usize, dir: Direction) -> Complex<f64> {
    assert!(m < n, "twiddle index {m} out of range for length {n}");
    let (m, n) = (m as u128, n as u128);
    let q = (4 * m) / n; // quarter turns, 0..4
    let r = (4 * m) % n; // remainder: angle (π/2)·r/n in [0, π/2)
    let (c, s) = if 2 * r == n {
        // Exactly π/4: both components are the correctly rounded √½ (f64's sin and cos
        // of the rounded π/4 differ in the last bit, which would break symmetry).
        (FRAC_1_SQRT_2, FRAC_1_SQRT_2)
    } else if 2 * r < n {
        let phi = FRAC_PI_2 * r as f64 / n as f64; // [0, π/4)
        (phi.cos(), phi.sin())
    } else {
        let phi = FRAC_PI_2 * (n - r) as f64 / n as f64; // (0, π/4)
        (phi.sin(), phi.cos())
    };
    // e^{i(qπ/2 + α)} = i^q · (cos α + i sin α)
    let (re, im) = match q {
        0 => (c, s),
        1 => (-s, c),
        2 => (-c, -s),
        _ => (s, -c),
    };
    match dir {
        Direction::Inverse => Complex::new(re, im),
        Direction::Forward => Complex::new(re, -im),
    }
}

/// The table `twiddle(m, n, dir)` for `m = 0 … n−1`.
fn twiddle_table(n: usize, dir: Direction) -> Vec<Complex<f64>> {
    (0..n).map(|m| twiddle(m, n, dir)).collect()
}

/// Neumaier's compensated sum: `sum + comp` carries the lost low-order bits.
#[derive(Clone, Copy, Default)]
struct Neumaier {
    sum: f64,
    comp: f64,
}

impl Neumaier {
    #[inline(always)]
    fn add(&mut self, x: f64) {
        let t = self.sum + x;
        if self.sum.abs() >= x.abs() {
            self.comp += (self.sum - t) + x;
        } else {
            self.comp += (x - t) + self.sum;
        }
        self.sum = t;
    }
    #[inline(always)]
    fn value(self) -> f64 {
        self.sum + self.comp
    }
}

/// One output bin `k` of the unscaled DFT of `x`, from the twiddle table `w`.
#[inline]
fn bin(x: &[Complex<f64>], w: &[Complex<f64>], k: usize) -> Complex<f64> {
    let n = x.len();
    let (mut re, mut im) = (Neumaier::default(), Neumaier::default());
    let mut m = 0usize; // (k·j) mod n, advanced by exact integer addition
    for xj in x {
        let t = w[m];
        re.add(xj.re * t.re);
        re.add(-(xj.im * t.im));
        im.add(xj.re * t.im);
        im.add(xj.im * t.re);
        m += k;
        if m >= n {
            m -= n;
        }
    }
    Complex::new(re.value(), im.value())
}

/// The scaled DFT of one line into `out`, serially (used by the N-D passes).
fn dft_line(
    x: &[Complex<f64>],
    w: &[Complex<f64>],
    out: &mut [Complex<f64>],
    dir: Direction,
    norm: Normalization,
) {
    let n = x.len();
    for (k, o) in out.iter_mut().enumerate() {
        let v = bin(x, w, k);
        *o = Complex::new(norm.apply(v.re, n, dir), norm.apply(v.im, n, dir));
    }
}

/// The exact 1-D DFT of `input` (see the module docs for the formula and scales).
/// Parallel over output bins; bit-identical for any thread count. `O(N²)`.
pub fn dft_1d(input: &[Complex<f64>], dir: Direction, norm: Normalization) -> Vec<Complex<f64>> {
    let n = input.len();
    if n == 0 {
        return Vec::new();
    }
    let w = twiddle_table(n, dir);
    (0..n)
        .into_par_iter()
        .map(|k| {
            let v = bin(input, &w, k);
            Complex::new(norm.apply(v.re, n, dir), norm.apply(v.im, n, dir))
        })
        .collect()
}

/// Checks that `shape` describes `len` elements.
fn check_shape(len: usize, shape: &[usize]) {
    let total: usize = shape.iter().product();
    assert!(
        total == len,
        "shape {shape:?} describes {total} elements but the data has {len}"
    );
}

/// Applies `f(line_in, line_out)` to every line along `axis` of a row-major array of
/// `shape`, in parallel over lines; `f` sees contiguous copies of the strided lines.
pub(crate) fn map_lines<T, F>(data: &[T], shape: &[usize], axis: usize, f: F) -> Vec<T>
where
    T: Copy + Default + Send + Sync,
    F: Fn(&[T], &mut [T]) + Sync,
{
    let n = shape[axis];
    let inner: usize = shape[axis + 1..].iter().product();
    let total = data.len();
    if total == 0 {
        return Vec::new();
    }
    let lines = total / n;
    // Transform every line into a buffer laid out [line][n], line = outer·inner + c.
    let mut t = vec![T::default(); total];
    t.par_chunks_mut(n).enumerate().for_each_init(
        || vec![T::default(); n],
        |buf, (l, out)| {
            let (o, c) = (l / inner, l % inner);
            let base = o * n * inner + c;
            for (j, b) in buf.iter_mut().enumerate() {
                *b = data[base + j * inner];
            }
            f(buf, out);
        },
    );
    debug_assert_eq!(t.len(), lines * n);
    if inner == 1 {
        return t;
    }
    // Scatter back to row-major: output row r = o·n + j holds t[(o·inner + c)·n + j].
    let mut out = vec![T::default(); total];
    out.par_chunks_mut(inner).enumerate().for_each(|(r, row)| {
        let (o, j) = (r / n, r % n);
        for (c, v) in row.iter_mut().enumerate() {
            *v = t[(o * inner + c) * n + j];
        }
    });
    out
}

/// The exact N-D DFT of a row-major array of `shape` (last axis fastest): 1-D DFTs
/// along every axis in turn, each scaled by its own factor, so the total scale is the
/// product of the per-axis ones. Parallel over lines; bit-identical for any thread
/// count.
///
/// # Panics
/// If the product of `shape` is not `data.len()`.
pub fn dft_nd(
    data: &[Complex<f64>],
    shape: &[usize],
    dir: Direction,
    norm: Normalization,
) -> Vec<Complex<f64>> {
    check_shape(data.len(), shape);
    let mut cur = data.to_vec();
    for axis in 0..shape.len() {
        if cur.is_empty() {
            break;
        }
        let w = twiddle_table(shape[axis], dir);
        cur = map_lines(&cur, shape, axis, |x, out| dft_line(x, &w, out, dir, norm));
    }
    cur
}

/// Rolls every axis `a` of a row-major array by `shift(n_a)`: `out[(i + s) mod n] = in[i]`.
fn roll_nd<T: Copy + Default>(
    data: &[T],
    shape: &[usize],
    shift: impl Fn(usize) -> usize,
) -> Vec<T> {
    check_shape(data.len(), shape);
    let mut cur = data.to_vec();
    let mut next = vec![T::default(); data.len()];
    if data.is_empty() {
        return cur;
    }
    for (axis, &n) in shape.iter().enumerate() {
        let inner: usize = shape[axis + 1..].iter().product();
        let s = shift(n) % n;
        for (src, dst) in cur.chunks(n * inner).zip(next.chunks_mut(n * inner)) {
            for i in 0..n {
                let j = (i + s) % n;
                dst[j * inner..(j + 1) * inner].copy_from_slice(&src[i * inner..(i + 1) * inner]);
            }
        }
        std::mem::swap(&mut cur, &mut next);
    }
    cur
}

/// numpy's `fft.fftshift` over every axis: moves DC (index 0) to index `n/2` (rounded
/// down), i.e. rolls each axis by `⌊n/2⌋`. `fftshift([0,1,2,3,4]) = [3,4,0,1,2]`.
///
/// # Panics
/// If the product of `shape` is not `data.len()`.
pub fn fftshift<T: Copy + Default>(data: &[T], shape: &[usize]) -> Vec<T> {
    roll_nd(data, shape, |n| n / 2)
}

/// numpy's `fft.ifftshift`, the inverse of [`fftshift`]: rolls each axis by `−⌊n/2⌋`.
/// For odd sizes it differs from `fftshift`: `ifftshift([0,1,2,3,4]) = [2,3,4,0,1]`.
///
/// # Panics
/// If the product of `shape` is not `data.len()`.
pub fn ifftshift<T: Copy + Default>(data: &[T], shape: &[usize]) -> Vec<T> {
    roll_nd(data, shape, |n| n - n / 2)
}

/// The centred 1-D DFT, `fftshift(dft(ifftshift(x)))` as in numpy: the input's origin
/// and the output's DC are both at index `N/2` (rounded down).
pub fn dft_1d_centered(
    input: &[Complex<f64>],
    dir: Direction,
    norm: Normalization,
) -> Vec<Complex<f64>> {
    let shape = [input.len()];
    fftshift(&dft_1d(&ifftshift(input, &shape), dir, norm), &shape)
}

/// The centred N-D DFT, `fftshift(dft_nd(ifftshift(x)))`: origin and DC at index
/// `n/2` (rounded down) of every axis.
///
/// # Panics
/// If the product of `shape` is not `data.len()`.
pub fn dft_nd_centered(
    data: &[Complex<f64>],
    shape: &[usize],
    dir: Direction,
    norm: Normalization,
) -> Vec<Complex<f64>> {
    fftshift(&dft_nd(&ifftshift(data, shape), shape, dir, norm), shape)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The twiddles agree with a direct `sin`/`cos` of `2πm/N` (which is accurate for
    /// small N) and are exactly symmetric where the exact values are.
    #[test]
    fn twiddles_match_direct_evaluation_and_symmetries() {
        for n in [1usize, 2, 3, 4, 5, 7, 8, 12, 17, 64, 1000] {
            for m in 0..n {
                let w = twiddle(m, n, Direction::Inverse);
                let a = 2.0 * std::f64::consts::PI * m as f64 / n as f64;
                assert!((w.re - a.cos()).abs() < 1e-15, "n {n} m {m}");
                assert!((w.im - a.sin()).abs() < 1e-15, "n {n} m {m}");
                let f = twiddle(m, n, Direction::Forward);
                assert_eq!(f, w.conj());
                if m > 0 {
                    assert_eq!(twiddle(n - m, n, Direction::Inverse), w.conj());
                }
            }
        }
        // Exact values at the quarter turns.
        assert_eq!(twiddle(0, 4, Direction::Inverse), Complex::new(1.0, 0.0));
        assert_eq!(twiddle(1, 4, Direction::Inverse), Complex::new(0.0, 1.0));
        assert_eq!(twiddle(2, 4, Direction::Inverse), Complex::new(-1.0, 0.0));
        assert_eq!(twiddle(3, 4, Direction::Inverse), Complex::new(0.0, -1.0));
    }

    /// For a large N the twiddles stay on the unit circle to about one ulp.
    #[test]
    fn twiddles_have_unit_modulus_for_large_n() {
        let n = 1usize << 40;
        let mut worst = 0.0f64;
        for m in (0..n).step_by((n / 9973) | 1) {
            let w = twiddle(m, n, Direction::Forward);
            worst = worst.max((w.norm_sqr() - 1.0).abs());
        }
        assert!(worst < 4.0 * f64::EPSILON, "worst |w|²−1 = {worst:e}");
    }

    #[test]
    fn neumaier_recovers_cancelled_terms() {
        let mut s = Neumaier::default();
        for x in [1.0, 1e100, 1.0, -1e100] {
            s.add(x);
        }
        assert_eq!(s.value(), 2.0);
    }

    #[test]
    fn shifts_follow_numpy() {
        let x: Vec<u32> = (0..5).collect();
        assert_eq!(fftshift(&x, &[5]), [3, 4, 0, 1, 2]);
        assert_eq!(ifftshift(&x, &[5]), [2, 3, 4, 0, 1]);
        let y: Vec<u32> = (0..4).collect();
        assert_eq!(fftshift(&y, &[4]), [2, 3, 0, 1]);
        assert_eq!(ifftshift(&y, &[4]), [2, 3, 0, 1]);
    }
}
