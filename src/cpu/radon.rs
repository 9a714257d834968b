//! The Radon transform of a 2-D image as scikit-image's `radon` computes it: the image
//! (cropped to its inscribed square, or zero-padded to its circumscribed one) is
//! rotated about its centre pixel by bilinear interpolation and its columns summed.
//!
//! For angle θ (cos c, sin s) and the square's centre `m = n / 2` (integer division),
//! output pixel (row `r`, column `k`) reads the image at
//!
//! ```text
//! x = c·k + s·r − m(c + s − 1)      (column)
//! y = −s·k + c·r − m(c − s − 1)     (row)
//! ```
//!
//! with bilinear weights from `⌊x⌋, ⌈x⌉, ⌊y⌋, ⌈y⌉` and zero outside the square
//! (skimage's `warp(..., order=1, mode='constant', cval=0)`), and the sinogram's bin
//! `k` of that angle is `Σ_r` of those values, summed over `r` in order
//! (`rotated.sum(0)`). The arithmetic is skimage's, step for step, in the image's
//! precision: coordinates in `R` (the matrix rounded to `R`), the bilinear blend with
//! skimage's mix of f64 and `R` products (`bilinear`), rounded back to `R`, and the
//! rows summed in `R`. With the same cosines and sines the result is bit-identical to
//! skimage's in f64 and in f32 (python/tests/test_radon.py).
//!
//! The inverse, scikit-image's `iradon` backprojection, is [`iradon_backproject`]:
//! every output pixel sums each filtered view read by an interpolation
//! ([`Interpolation`], [`iradon_sample`]) at `t = y·cos θ − x·sin θ`.
//!
//! The transform is linear: a unit pixel at the centre gives 1 in bin `m` of every
//! angle, and every angle's bins sum to the image's sum when no mass leaves the square.

use crate::real::Real;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Where the image lies on its square: the square's side and the image's offset in
/// it (`row0`, `col0`: negative when the square crops the image).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Square {
    pub side: usize,
    pub row0: isize,
    pub col0: isize,
}

impl Square {
    /// `circle`: the centred square of side `min(rows, cols)` (scikit-image crops the
    /// longer axis, `ceil(excess / 2)` before). Otherwise the square of side
    /// `⌈√2 · max(rows, cols)⌉`, the image padded so that its centre pixel
    /// `(rows / 2, cols / 2)` lands on the square's `side / 2`.
    pub fn of(rows: usize, cols: usize, circle: bool) -> Square {
        if circle {
            let side = rows.min(cols);
            let crop = |n: usize| -> isize { -((n - side).div_ceil(2) as isize) };
            Square {
                side,
                row0: crop(rows),
                col0: crop(cols),
            }
        } else {
            let diagonal = std::f64::consts::SQRT_2 * rows.max(cols) as f64;
            let pad = |n: usize| -> (usize, isize) {
                let p = (diagonal - n as f64).ceil() as usize;
                let before = (n + p) / 2 - n / 2;
                (n + p, before as isize)
            };
            let (side, row0) = pad(rows);
            let (_, col0) = pad(cols);
            Square { side, row0, col0 }
        }
    }
}

/// True when some pixel outside the inscribed circle is non-zero: the pixel
/// `(i, j)` with `(i − rows/2)² + (j − cols/2)² > (min(rows, cols)/2)²` (integer
/// division, skimage's test before it warns).
pub fn outside_circle<R: Real>(image: &[R], rows: usize, cols: usize) -> bool {
    let radius = (rows.min(cols) / 2) as i64;
    let (ci, cj) = ((rows / 2) as i64, (cols / 2) as i64);
    image.chunks(cols.max(1)).enumerate().any(|(i, row)| {
        row.iter().enumerate().any(|(j, &v)| {
            let (di, dj) = (i as i64 - ci, j as i64 - cj);
            di * di + dj * dj > radius * radius && v != R::zero()
        })
    })
}

/// The image placed on its square (row-major, `side²`).
pub fn square<R: Real>(image: &[R], rows: usize, cols: usize, sq: Square) -> Vec<R> {
    let n = sq.side;
    let mut out = vec![R::zero(); n * n];
    for (i, row) in image.chunks(cols.max(1)).enumerate().take(rows) {
        let si = i as isize + sq.row0;
        if si < 0 || si >= n as isize {
            continue;
        }
        for (j, &v) in row.iter().enumerate() {
            let sj = j as isize + sq.col0;
            if sj >= 0 && sj < n as isize {
                out[si as usize * n + sj as usize] = v;
            }
        }
    }
    out
}

/// The square image's pixel `(r, c)`, zero outside (skimage's `get_pixel2d`, mode
/// `'C'`, cval 0).
#[inline(always)]
fn pixel<R: Real>(img: &[R], n: usize, r: i64, c: i64) -> R {
    if r < 0 || c < 0 || r >= n as i64 || c >= n as i64 {
        R::zero()
    } else {
        img[r as usize * n + c as usize]
    }
}

/// Bilinear interpolation at row `r`, column `c` (skimage's `bilinear_interpolation`
/// as its compiled code evaluates it: the weights `1 − d` are doubles, `1.0 − d`, so
/// each row blend is `(1 − dc)·left` in f64 plus `dc·right` in `R`, summed in f64, and
/// the column blend `(1 − dr)·top + dr·bottom` is in f64, rounded to `R`). In f64 this
/// is the plain bilinear formula.
///
/// mirrors shaders/radon.wgsl: bilinear
#[inline(always)]
fn bilinear<R: Real>(img: &[R], n: usize, r: R, c: R) -> R {
    let (minr, minc) = (r.floor(), c.floor());
    let (maxr, maxc) = (r.ceil(), c.ceil());
    let (dr, dc) = (r - minr, c - minc);
    let (r0, r1) = (minr.f64() as i64, maxr.f64() as i64);
    let (c0, c1) = (minc.f64() as i64, maxc.f64() as i64);
    let blend = |left: R, right: R| (1.0 - dc.f64()) * left.f64() + (dc * right).f64();
    let top = blend(pixel(img, n, r0, c0), pixel(img, n, r0, c1));
    let bottom = blend(pixel(img, n, r1, c0), pixel(img, n, r1, c1));
    R::of((1.0 - dr.f64()) * top + dr.f64() * bottom)
}

/// The rotation of angle θ about pixel `(m, m)`, `m = n / 2`, as the inverse map
/// from output (column `k`, row `r`) to input: `[c, s, −m(c + s − 1), −s, c,
/// −m(c − s − 1)]` (`x = h₀k + h₁r + h₂`, `y = h₃k + h₄r + h₅`), computed in f64.
/// (scikit-image builds the same matrix in the angles' own precision; its Python
/// shell passes that matrix to [`radon_square`] as it is.)
pub fn rotation(n: usize, cos: f64, sin: f64) -> [f64; 6] {
    let m = (n / 2) as f64;
    [
        cos,
        sin,
        -m * (cos + sin - 1.0),
        -sin,
        cos,
        -m * (cos - sin - 1.0),
    ]
}

/// One sinogram column: the square image warped by the inverse map `h` (see
/// [`rotation`]; rounded to `R`, as skimage's `matrix.astype(image.dtype)`), summed
/// over rows.
///
/// mirrors shaders/radon.wgsl: radon_column
pub fn radon_column<R: Real>(img: &[R], n: usize, h: &[f64; 6]) -> Vec<R> {
    let h: [R; 6] = h.map(R::of);
    let mut acc = vec![R::zero(); n];
    for r in 0..n {
        let y = R::of(r as f64);
        for (k, a) in acc.iter_mut().enumerate() {
            let x = R::of(k as f64);
            let col = h[0] * x + h[1] * y + h[2];
            let row = h[3] * x + h[4] * y + h[5];
            *a = *a + bilinear(img, n, row, col);
        }
    }
    acc
}

/// The sinogram `(side, angles)` (row-major: bin, then angle) of a square image
/// (`side²`, row-major), one inverse map per angle ([`rotation`]). Columns are
/// independent and run in parallel; the result does not depend on the thread count.
pub fn radon_square<R: Real>(img: &[R], n: usize, maps: &[[f64; 6]]) -> Vec<R> {
    let cols: Vec<Vec<R>> = maps.par_iter().map(|h| radon_column(img, n, h)).collect();
    let a = maps.len();
    let mut out = vec![R::zero(); n * a];
    for (j, col) in cols.iter().enumerate() {
        for (i, &v) in col.iter().enumerate() {
            out[i * a + j] = v;
        }
    }
    out
}

crate::choice_enum! {
    /// How scikit-image's `iradon` reads a filtered projection between its bin centres
    /// `x_j = j − n//2` (its `interpolation`); 0 before the first centre and after the
    /// last, as `iradon`'s interpolants (`left=0, right=0`, `fill_value=0`).
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
    pub enum Interpolation: "interpolation", default Linear {
        /// `np.interp`: the straight line between the two neighbouring bins.
        Linear = "linear",
        /// `interp1d(kind="nearest")`: the nearest bin; halfway between two, the left.
        Nearest = "nearest",
        /// `interp1d(kind="cubic")`: the not-a-knot cubic spline through every bin.
        Cubic = "cubic",
    }
}

impl Interpolation {
    /// Its number in `shaders/radon.wgsl` (`IradonParams.kind`).
    pub fn id(self) -> u32 {
        match self {
            Interpolation::Linear => 0,
            Interpolation::Nearest => 1,
            Interpolation::Cubic => 2,
        }
    }
}

/// The fewest bins a cubic spline needs (scipy's `make_interp_spline` with `k = 3`).
pub const CUBIC_MIN_BINS: usize = 4;

/// The second derivatives `M_j` of the not-a-knot cubic spline through `(j, y_j)`
/// (unit spacing; scipy's `make_interp_spline(x, y, k=3)`, `interp1d(kind="cubic")`).
///
/// Between bins `j` and `j + 1` the spline is
/// `S(t) = (M_j a³ + M_{j+1} b³)/6 + (y_j − M_j/6) a + (y_{j+1} − M_{j+1}/6) b` with
/// `a = x_{j+1} − t`, `b = t − x_j` ([`iradon_sample`]). Continuity of `S'` gives
/// `M_{j−1} + 4M_j + M_{j+1} = 6(y_{j+1} − 2y_j + y_{j−1})` for `1 ≤ j ≤ n − 2`, and
/// "not a knot" (a continuous third derivative at `x_1` and `x_{n−2}`) gives
/// `M_0 = 2M_1 − M_2` and `M_{n−1} = 2M_{n−2} − M_{n−3}`. Put into the first and last
/// equations these leave `6M_1 = r_1` and `6M_{n−2} = r_{n−2}`; the rows between are a
/// tridiagonal system with diagonal 4, solved by elimination (diagonally dominant,
/// so stable), in f64. `y` needs at least [`CUBIC_MIN_BINS`] values (else the result
/// is empty).
pub fn spline_curvatures(y: &[f64]) -> Vec<f64> {
    let n = y.len();
    if n < CUBIC_MIN_BINS {
        return Vec::new();
    }
    let r = |j: usize| 6.0 * (y[j + 1] - 2.0 * y[j] + y[j - 1]);
    let mut m = vec![0.0; n];
    m[1] = r(1) / 6.0;
    m[n - 2] = r(n - 2) / 6.0;
    // Rows j = 2 … n − 3: M_{j−1} + 4M_j + M_{j+1} = r_j, with M_1 and M_{n−2} known.
    let inner = n.saturating_sub(4);
    if inner > 0 {
        let mut diag = vec![0.0; inner];
        let mut rhs = vec![0.0; inner];
        for (i, j) in (2..n - 2).enumerate() {
            let mut b = r(j);
            if j == 2 {
                b -= m[1];
            }
            if j == n - 3 {
                b -= m[n - 2];
            }
            let (d, prev) = if i == 0 {
                (4.0, 0.0)
            } else {
                let w = 1.0 / diag[i - 1];
                (4.0 - w, rhs[i - 1] * w)
            };
            diag[i] = d;
            rhs[i] = b - prev;
        }
        for i in (0..inner).rev() {
            let next = if i + 1 < inner { m[i + 3] } else { 0.0 };
            m[i + 2] = (rhs[i] - next) / diag[i];
        }
    }
    m[0] = 2.0 * m[1] - m[2];
    m[n - 1] = 2.0 * m[n - 2] - m[n - 3];
    m
}

/// One filtered projection `y` (bins `x_j = j − n//2`) read at `t` by `kind`, as
/// scikit-image's `iradon` reads it: 0 outside `[x_0, x_{n−1}]`;
/// - linear: `np.interp`'s arithmetic, `(y_{j+1} − y_j)·(t − x_j) + y_j` with
///   `x_j = ⌊t⌋` (`y_j` itself at a bin centre and at the last one);
/// - nearest: `y_j` of the nearest centre, the left one at a tie (`interp1d`'s
///   `searchsorted(side="left")` over the midpoints), deciding with `t + t_lo`
///   (see [`Angle`]: `t_lo` is what rounding `cos θ` and `sin θ` to `R` left out of
///   `t`, 0 in f64);
/// - cubic: the spline of [`spline_curvatures`] `m` (same length as `y`).
///
/// In f64 with numpy's `t` these are numpy's and scipy's numbers (linear and nearest
/// bit for bit; the cubic spline to rounding).
///
/// mirrors shaders/radon.wgsl: iradon_sample
#[inline(always)]
pub fn iradon_sample<R: Real>(kind: Interpolation, y: &[R], m: &[R], t: R, t_lo: R) -> R {
    let n = y.len();
    let h = (n / 2) as f64;
    let (first, last) = (R::of(-h), R::of((n - 1) as f64 - h));
    // Also refuses NaN: every comparison with it is false.
    if !(t >= first && t <= last) {
        return R::zero();
    }
    // ⌊t⌋ without a libm call (|t| < n here); x_j = f exactly: `j` is f's bin, in
    // 0 … n − 1.
    let (f, i) = t.floor_index();
    let j = (i.unwrap_or(0) + (n / 2) as i64) as usize;
    match kind {
        Interpolation::Linear => {
            if j == n - 1 || f == t {
                y[j]
            } else {
                (y[j + 1] - y[j]) * (t - f) + y[j]
            }
        }
        Interpolation::Nearest => {
            // Against the midpoint itself (`t − f` rounds for t just above −1 … 0);
            // `t − mid` is exact near the midpoint, so `t_lo` decides a tie.
            if (t - (f + R::of(0.5))) + t_lo > R::zero() {
                y[j + 1]
            } else {
                y[j]
            }
        }
        Interpolation::Cubic => {
            let j = j.min(n - 2);
            let xj = R::of(j as f64 - h);
            let (a, b) = (xj + R::one() - t, t - xj);
            let sixth = R::one() / R::of(6.0);
            (m[j] * a * a * a + m[j + 1] * b * b * b) * sixth
                + (y[j] - m[j] * sixth) * a
                + (y[j + 1] - m[j + 1] * sixth) * b
        }
    }
}

/// One angle of [`iradon_backproject`]: `cos θ` and `sin θ` rounded to `R`, and what
/// that rounding left out (`c_lo = cos θ − c`, rounded; 0 in f64).
///
/// scikit-image's `t = y·cos θ − x·sin θ` lands exactly on a midpoint between bins in
/// exact arithmetic at angles such as 30°, 60°, 120° (where `x` or `y` is 0), and
/// numpy's f64 cosines (`cos 60° = 0.5000000000000001`) push it a rounding to one side.
/// In f32 the cosine rounds to 0.5 and `t` to the midpoint itself; `t_lo =
/// y·c_lo − x·s_lo` keeps the push, so nearest-bin reads in f32 choose the bin numpy's
/// f64 `t` chooses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Angle<R> {
    pub c: R,
    pub s: R,
    pub c_lo: R,
    pub s_lo: R,
}

impl<R: Real> Angle<R> {
    /// `(cos θ, sin θ)` in f64, split for `R`.
    pub fn new(cos: f64, sin: f64) -> Self {
        let (c, s) = (R::of(cos), R::of(sin));
        Angle {
            c,
            s,
            c_lo: R::of(cos - c.f64()),
            s_lo: R::of(sin - s.f64()),
        }
    }
}

/// Adds one filtered projection's value to an `A` accumulator as scikit-image's
/// `reconstructed += interpolant(t)` does: interpolated in f64 and added to the output
/// dtype (`fl_A(acc + v)`). In f32 throughout (`R = A = f32`, the GPU's arithmetic) a
/// plain f32 addition.
#[inline(always)]
fn accumulate<R: Real, A: Real>(acc: A, v: R) -> A {
    if R::NAME == "f64" {
        A::of(acc.f64() + v.f64())
    } else {
        acc + A::of(v.f64())
    }
}

/// Adds one view, read by `kind`, to the sums of a run of pixels of one row (`x` =
/// `xr`, the pixels' `y` in `ys`): `t = y·c − x·s` and, for nearest, `t_lo`.
#[inline(always)]
fn add_view<R: Real, A: Real>(
    kind: Interpolation,
    acc: &mut [A],
    ys: &[R],
    view: &[R],
    m: &[R],
    a: &Angle<R>,
    xr: R,
) {
    let (xs, xs_lo) = (xr * a.s, xr * a.s_lo);
    for (sum, &yr) in acc.iter_mut().zip(ys) {
        let t = yr * a.c - xs;
        let t_lo = if kind == Interpolation::Nearest {
            yr * a.c_lo - xs_lo
        } else {
            R::zero()
        };
        *sum = accumulate(*sum, iradon_sample(kind, view, m, t, t_lo));
    }
}

/// scikit-image's `iradon` backprojection of filtered projections: `views` holds one
/// filtered line of `bins` values per angle (angle-major), `trig` each angle's
/// `(cos θ, sin θ)` (numpy's, to reproduce its `t`), `curvatures` the lines'
/// [`spline_curvatures`] for [`Interpolation::Cubic`] (else empty). Output pixel
/// (row, col) of the `size × size` image, with `x = row − size//2` and
/// `y = col − size//2`, is
///
/// `f = π/(2A) · Σ_k sample_k(y·cos θ_k − x·sin θ_k)`
///
/// summed over the angles in order in `A`, zero outside the inscribed circle when
/// `circle` (`x² + y² > (size//2)²`), then scaled as `rec·π/(2A)` in `A`. `R` is the
/// precision of `t` and the interpolation (f64 as scikit-image; f32 as the GPU); `A`
/// the output's (scikit-image's: the sinogram's float type). Rows run in parallel;
/// the result does not depend on the thread count. `rows_done(done, total)` is called
/// after each row.
///
/// mirrors shaders/radon.wgsl: iradon_backproject
#[allow(clippy::too_many_arguments)]
pub fn iradon_backproject<R: Real, A: Real>(
    views: &[R],
    curvatures: &[R],
    bins: usize,
    trig: &[(f64, f64)],
    size: usize,
    kind: Interpolation,
    circle: bool,
    rows_done: &(dyn Fn(usize, usize) + Sync),
) -> Vec<A> {
    let radius = (size / 2) as i64;
    let trig: Vec<Angle<R>> = trig.iter().map(|&(c, s)| Angle::new(c, s)).collect();
    let pi = A::of(std::f64::consts::PI);
    let denominator = A::of(2.0 * trig.len() as f64);
    let done = AtomicUsize::new(0);
    let mut out = vec![A::zero(); size * size];
    out.par_chunks_mut(size.max(1))
        .enumerate()
        .panic_fuse()
        .for_each(|(row, line)| {
            // The row's pixels inside the circle (all of them without it): a run of
            // columns, since the disc is convex.
            let x = row as i64 - radius;
            let inside = |col: &usize| {
                let y = *col as i64 - radius;
                !circle || x * x + y * y <= radius * radius
            };
            let Some(lo) = (0..size).find(inside) else {
                rows_done(done.fetch_add(1, Ordering::Relaxed) + 1, size);
                return;
            };
            let hi = (lo..size).rfind(inside).unwrap_or(lo) + 1;
            let xr = R::of(x as f64);
            let ys: Vec<R> = (lo..hi)
                .map(|col| R::of(col as f64 - radius as f64))
                .collect();
            // Angle by angle over the run: every pixel still sums its views in order.
            let mut acc = vec![A::zero(); hi - lo];
            for (k, a) in trig.iter().enumerate() {
                let view = &views[k * bins..(k + 1) * bins];
                // One loop per interpolation, so that none tests `kind` per pixel.
                match kind {
                    Interpolation::Linear => {
                        add_view(Interpolation::Linear, &mut acc, &ys, view, &[], a, xr)
                    }
                    Interpolation::Nearest => {
                        add_view(Interpolation::Nearest, &mut acc, &ys, view, &[], a, xr)
                    }
                    Interpolation::Cubic => {
                        let m = &curvatures[k * bins..(k + 1) * bins];
                        add_view(Interpolation::Cubic, &mut acc, &ys, view, m, a, xr)
                    }
                }
            }
            for (o, sum) in line[lo..hi].iter_mut().zip(acc) {
                *o = sum * pi / denominator;
            }
            rows_done(done.fetch_add(1, Ordering::Relaxed) + 1, size);
        });
    out
}

// ---------------------------------------------------------------------------------
// SART (scikit-image's `iradon_sart`)
// ---------------------------------------------------------------------------------

/// The order in which `iradon_sart` visits the views: Kohler's golden-ratio scheme as
/// scikit-image's `order_angles_golden_ratio` computes it, in the angles' precision `R`
/// (numpy's arithmetic on `R` scalars: the step `180/φ²` rounded to `R`, numpy's
/// floored remainder, and its choice between the two neighbours, the distances taken
/// as `min(d mod 180, d mod −180)`). Every index is yielded once.
pub fn golden_order<R: Real>(theta: &[R]) -> Vec<usize> {
    let interval = R::of(180.0);
    let phi = (1.0 + 5f64.sqrt()) / 2.0;
    let increment = R::of(180.0 / (phi * phi));
    // numpy's remainder: fmod, then the divisor's sign.
    let rem = |a: R, b: R| {
        let m = a % b;
        if m != R::zero() && ((b < R::zero()) != (m < R::zero())) {
            m + b
        } else if m == R::zero() {
            R::zero().copysign(b)
        } else {
            m
        }
    };
    let mut remaining: Vec<usize> = (0..theta.len()).collect();
    remaining.sort_by(|&a, &b| {
        theta[a]
            .partial_cmp(&theta[b])
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let mut order = Vec::with_capacity(theta.len());
    if remaining.is_empty() {
        return order;
    }
    let mut angle = theta[remaining[0]];
    order.push(remaining.remove(0));
    while !remaining.is_empty() {
        let n = remaining.len();
        angle = rem(angle + increment, interval);
        // searchsorted(side="left") over the remaining angles (ascending).
        let above = remaining.partition_point(|&k| theta[k] < angle);
        let below = (above + n - 1) % n;
        let above = above % n;
        let distance = |k: usize| {
            let d = (angle - theta[remaining[k]]).abs();
            let (a, b) = (rem(d, interval), rem(d, -interval));
            if b < a {
                b
            } else {
                a
            }
        };
        let pick = if distance(below) < distance(above) {
            below
        } else {
            above
        };
        order.push(remaining.remove(pick));
    }
    order
}

/// One ray of scikit-image's SART through an `n × n` image: its samples
/// `(x, y) = (x₀ + k·dx, y₀ + k·dy)`, `k = 0 … ns`, `ds` apart, inside the circle of
/// radius `n//2 − 1` about pixel `(n//2, n//2)` (`bilinear_ray_sum`'s set-up, with its
/// mix of f64 and `R`: the angle, `√`, `cos` and `sin` in f64, rounded to `R` where
/// scikit-image stores them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SartRay<R> {
    pub ns: usize,
    pub ds: R,
    pub dx: R,
    pub dy: R,
    pub x0: R,
    pub y0: R,
}

impl<R: Real> SartRay<R> {
    /// The ray at `ray_position` (bins, `i + projection_shift`) of the view at
    /// `theta_deg` degrees; `None` when it misses the circle.
    pub fn new(n: usize, theta_deg: R, ray_position: R) -> Option<Self> {
        let theta = R::of(theta_deg.f64() / 180.0 * std::f64::consts::PI);
        let radius = R::of((n / 2) as f64 - 1.0);
        let centre = R::of((n / 2) as f64);
        let t = ray_position - centre;
        let s0 = if radius * radius >= t * t {
            R::of((radius * radius - t * t).f64().sqrt())
        } else {
            R::zero()
        };
        let ns = 2 * (R::of(2.0) * s0).f64().ceil() as i64;
        if ns <= 0 {
            return None;
        }
        // (2.0·s0)/Ns: a double literal, so the division is in f64.
        let ds = R::of(2.0 * s0.f64() / R::of(ns as f64).f64());
        let (c, s) = (theta.f64().cos(), theta.f64().sin());
        Some(SartRay {
            ns: ns as usize,
            ds,
            dx: R::of(-ds.f64() * c),
            dy: R::of(-ds.f64() * s),
            x0: R::of(s0.f64() * c - t.f64() * s),
            y0: R::of(s0.f64() * s + t.f64() * c),
        })
    }

    /// Sample `k`: the pixel `(i, j)` (row, column) below and left of it and the
    /// fractions `(di, dj)`.
    #[inline(always)]
    pub fn sample(&self, n: usize, k: usize) -> (i64, i64, R, R) {
        let centre = R::of((n / 2) as f64);
        let kr = R::of(k as f64);
        let (ii, jj) = (
            self.x0 + kr * self.dx + centre,
            self.y0 + kr * self.dy + centre,
        );
        // ⌊·⌋ without a libm call (|x| < n here).
        let ((fi, _), (fj, _)) = (ii.f64().floor_index(), jj.f64().floor_index());
        (
            fi as i64,
            fj as i64,
            R::of(ii.f64() - fi),
            R::of(jj.f64() - fj),
        )
    }
}

/// The four bilinear weights of a SART sample, in scikit-image's compiled arithmetic:
/// the three with a `1 − d` factor (a double literal there) in f64, `di·dj·ds` in `R`,
/// each rounded to `R`.
///
/// mirrors shaders/radon_sart.wgsl: sart_weights
#[inline(always)]
fn sart_weights<R: Real>(di: R, dj: R, ds: R) -> [R; 4] {
    let (d, e, s) = (di.f64(), dj.f64(), ds.f64());
    [
        R::of((1.0 - d) * (1.0 - e) * s),
        R::of((1.0 - d) * e * s),
        R::of(d * (1.0 - e) * s),
        di * dj * ds,
    ]
}

/// Which of a sample's four taps (i, j), (i, j+1), (i+1, j), (i+1, j+1) scikit-image
/// uses: `i > 0`, `j > 0` and the far taps inside the image (its tests, which leave row
/// and column 0 out).
///
/// mirrors shaders/radon_sart.wgsl: sart_taps
#[inline(always)]
fn sart_taps(n: usize, i: i64, j: i64) -> [bool; 4] {
    let last = n as i64 - 1;
    [
        i > 0 && j > 0,
        i > 0 && j < last,
        i < last && j > 0,
        i < last && j < last,
    ]
}

/// A ray's sum through the image and the sum of its squared weights
/// (`bilinear_ray_sum`), summed along the ray in `R`.
///
/// mirrors shaders/radon_sart.wgsl: sart_ray_sum
pub fn sart_ray_sum<R: Real>(img: &[R], n: usize, ray: &SartRay<R>) -> (R, R) {
    let samples: Vec<_> = (0..=ray.ns).map(|k| ray.sample(n, k)).collect();
    sart_sum_of(img, n, ray.ds, &samples)
}

/// [`sart_ray_sum`] over a ray's samples already taken (`SartRay::sample`, in order).
fn sart_sum_of<R: Real>(img: &[R], n: usize, ds: R, samples: &[(i64, i64, R, R)]) -> (R, R) {
    let (mut sum, mut norm) = (R::zero(), R::zero());
    for &(i, j, di, dj) in samples {
        let w = sart_weights(di, dj, ds);
        let taps = sart_taps(n, i, j);
        for (t, (di, dj)) in [(0, 0), (0, 1), (1, 0), (1, 1)].into_iter().enumerate() {
            if taps[t] {
                let p = img[(i + di) as usize * n + (j + dj) as usize];
                sum = sum + w[t] * p;
                norm = norm + w[t] * w[t];
            }
        }
    }
    (sum, norm)
}

/// The Hamming window scikit-image weights a ray's update with at sample `k` of `ns`:
/// `0.53836 − 0.46164·cos(2πk/(ns − 1))`, evaluated in f64 and rounded to `R` (the GPU
/// takes these values from the host: WGSL's `cos` may be off by 2⁻¹¹).
#[inline(always)]
pub fn sart_window<R: Real>(k: usize, ns: usize) -> R {
    let beta = R::of(0.46164);
    let c = (2.0 * std::f64::consts::PI * k as f64 / (ns as f64 - 1.0)).cos();
    R::of((R::one() - beta).f64() - beta.f64() * c)
}

/// The Hamming windows of the sample counts met so far ([`sart_window`] for `k = 0 …
/// ns`), made once per count: every view's rays of one length share one.
#[derive(Clone, Debug, Default)]
pub struct SartWindows<R> {
    by_count: Vec<Vec<R>>,
}

impl<R: Real> SartWindows<R> {
    /// Makes the window of `ns` samples if it is not there yet.
    pub fn add(&mut self, ns: usize) {
        if self.by_count.len() <= ns {
            self.by_count.resize(ns + 1, Vec::new());
        }
        if self.by_count[ns].is_empty() {
            self.by_count[ns] = (0..=ns).map(|k| sart_window(k, ns)).collect();
        }
    }

    /// The window of `ns` samples (made by [`SartWindows::add`]).
    pub fn of(&self, ns: usize) -> &[R] {
        &self.by_count[ns]
    }
}

/// Adds a ray's update (`bilinear_ray_update`): `deviation · w · ds · hamming` to each
/// tap of each sample, in scikit-image's compiled arithmetic (the three taps with a
/// `1 − d` factor in f64, added to the `R` image in f64 and rounded; the fourth in
/// `R`), samples in order. Only the rows
/// `rows` are written (the caller's band of the image).
///
/// mirrors shaders/radon_sart.wgsl: sart_scatter
#[allow(clippy::too_many_arguments)]
fn sart_ray_update<R: Real>(
    update: &mut [R],
    n: usize,
    ds: R,
    samples: &[(i64, i64, R, R)],
    deviation: R,
    window: &[R],
    rows: std::ops::Range<usize>,
) {
    let band = rows.start as i64..rows.end as i64;
    let first = rows.start;
    // The samples that touch the band (a sample in row i touches rows i and i + 1):
    // a run, since a ray's row never turns back.
    let Some((&(i0, ..), &(i1, ..))) = samples.first().zip(samples.last()) else {
        return;
    };
    let touches = |i: i64| i + 1 >= band.start && i < band.end;
    let (from, to) = if i0 <= i1 {
        (
            samples.partition_point(|s| s.0 + 1 < band.start),
            samples.partition_point(|s| s.0 < band.end),
        )
    } else {
        (
            samples.partition_point(|s| s.0 >= band.end),
            samples.partition_point(|s| s.0 + 1 >= band.start),
        )
    };
    for (k, &(i, j, di, dj)) in samples.iter().enumerate().take(to).skip(from) {
        if !touches(i) {
            continue;
        }
        let taps = sart_taps(n, i, j);
        let h = window[k];
        let (dv, d, e, s, hv) = (deviation.f64(), di.f64(), dj.f64(), ds.f64(), h.f64());
        let mut add = |r: i64, c: i64, v: R, wide: Option<f64>| {
            if band.contains(&r) {
                let at = (r as usize - first) * n + c as usize;
                update[at] = match wide {
                    Some(w) => R::of(update[at].f64() + w),
                    None => update[at] + v,
                };
            }
        };
        if taps[0] {
            add(i, j, R::zero(), Some(dv * (1.0 - d) * (1.0 - e) * s * hv));
        }
        if taps[1] {
            add(i, j + 1, R::zero(), Some(dv * (1.0 - d) * e * s * hv));
        }
        if taps[2] {
            let w = (deviation * di).f64() * (1.0 - e) * s * hv;
            add(i + 1, j, R::zero(), Some(w));
        }
        if taps[3] {
            add(i + 1, j + 1, deviation * di * dj * ds * h, None);
        }
    }
}

/// The bands of rows the SART update is written in, in parallel: within a band every
/// pixel receives its rays' contributions in the rays' order and the samples' order,
/// as one thread writing the whole image would, whatever the number of threads.
const SART_BANDS: usize = 16;

/// One view's update (`sart_projection_update`): each ray's deviation
/// `(p − Σw·x)/Σw²` (`R`), spread back along the ray with its weights and the Hamming
/// window. Rays sum in parallel; the update is written in bands of rows in parallel,
/// every pixel's contributions in scikit-image's order, so the result is
/// scikit-image's bit for bit in f64 with the same cosines.
pub fn sart_projection_update<R: Real>(
    img: &[R],
    n: usize,
    theta_deg: R,
    projection: &[R],
    shift: R,
    windows: &mut SartWindows<R>,
) -> Vec<R> {
    /// A ray, its samples (row, column, fractions) and its deviation.
    type Traced<R> = (SartRay<R>, Vec<(i64, i64, R, R)>, R);
    let rays: Vec<Option<Traced<R>>> = projection
        .par_iter()
        .enumerate()
        .map(|(i, &p)| {
            let ray = SartRay::new(n, theta_deg, R::of(i as f64) + shift)?;
            let samples: Vec<_> = (0..=ray.ns).map(|k| ray.sample(n, k)).collect();
            let (sum, norm) = sart_sum_of(img, n, ray.ds, &samples);
            let deviation = if norm > R::zero() {
                -(sum - p) / norm
            } else {
                R::zero()
            };
            Some((ray, samples, deviation))
        })
        .collect();
    for (ray, ..) in rays.iter().flatten() {
        windows.add(ray.ns);
    }
    let windows = &*windows;
    let mut update = vec![R::zero(); n * n];
    let rows_per_band = n.div_ceil(SART_BANDS).max(1);
    update
        .par_chunks_mut(rows_per_band * n)
        .enumerate()
        .for_each(|(b, band)| {
            let rows = b * rows_per_band..(b * rows_per_band + band.len() / n);
            for (ray, samples, deviation) in rays.iter().flatten() {
                let w = windows.of(ray.ns);
                sart_ray_update(band, n, ray.ds, samples, *deviation, w, rows.clone());
            }
        });
    update
}

/// numpy's `clip(x, lo, hi)`, `minimum(maximum(x, lo), hi)`: a NaN anywhere gives NaN,
/// and `lo > hi` gives `hi`.
///
/// mirrors shaders/radon_sart.wgsl: sart_apply
#[inline(always)]
pub fn np_clip<R: Real>(x: R, lo: R, hi: R) -> R {
    let m = if x.is_nan() || lo.is_nan() || x >= lo {
        if lo.is_nan() {
            lo
        } else {
            x
        }
    } else {
        lo
    };
    if m.is_nan() || hi.is_nan() || m <= hi {
        if hi.is_nan() {
            hi
        } else {
            m
        }
    } else {
        hi
    }
}

/// One call of scikit-image's `iradon_sart`: every view once, in the golden-ratio order
/// ([`golden_order`]), `image += λ·update` after each (`λ` rounded to `R`), then
/// clipped to `clip` when given. `sinogram` is `(n, angles)` row-major (bin, then
/// angle), `image` the `n × n` start (updated in place). `view_done(done, total)` is
/// called after each view.
#[allow(clippy::too_many_arguments)]
pub fn iradon_sart<R: Real>(
    sinogram: &[R],
    n: usize,
    theta_deg: &[R],
    image: &mut [R],
    shifts: &[R],
    clip: Option<[R; 2]>,
    relaxation: f64,
    view_done: &dyn Fn(usize, usize),
) {
    let angles = theta_deg.len();
    let lambda = R::of(relaxation);
    let mut windows = SartWindows::default();
    for (done, k) in golden_order(theta_deg).into_iter().enumerate() {
        let projection: Vec<R> = (0..n).map(|b| sinogram[b * angles + k]).collect();
        let update =
            sart_projection_update(image, n, theta_deg[k], &projection, shifts[k], &mut windows);
        image
            .par_iter_mut()
            .zip(&update)
            .for_each(|(x, &u)| *x = *x + lambda * u);
        if let Some([lo, hi]) = clip {
            image.par_iter_mut().for_each(|x| *x = np_clip(*x, lo, hi));
        }
        view_done(done + 1, angles);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_centre_pixel_projects_to_the_centre_bin_at_every_angle() {
        for n in [7usize, 8] {
            let mut img = vec![0.0f64; n * n];
            img[(n / 2) * n + n / 2] = 1.0;
            let angles: Vec<(f64, f64)> = [0.0f64, 90.0, 180.0, 270.0]
                .iter()
                .map(|d| (d.to_radians().cos(), d.to_radians().sin()))
                .collect();
            let maps: Vec<[f64; 6]> = angles.iter().map(|&(c, s)| rotation(n, c, s)).collect();
            let s = radon_square(&img, n, &maps);
            for (j, &(c, si)) in angles.iter().enumerate() {
                let col: Vec<f64> = (0..n).map(|i| s[i * angles.len() + j]).collect();
                // Quarter turns land within rounding of the grid: all mass in bin n/2.
                let total: f64 = col.iter().sum();
                assert!((total - 1.0).abs() < 1e-12, "{n} {c} {si}: {col:?}");
                assert!((col[n / 2] - 1.0).abs() < 1e-12, "{col:?}");
            }
        }
    }

    #[test]
    fn angle_zero_sums_the_columns() {
        let (rows, cols) = (5usize, 5usize);
        let img: Vec<f64> = (0..rows * cols).map(|i| (i * 7 % 11) as f64).collect();
        let s = radon_square(&img, 5, &[rotation(5, 1.0, 0.0)]);
        for k in 0..cols {
            let want: f64 = (0..rows).map(|r| img[r * cols + k]).sum();
            assert_eq!(s[k], want);
        }
    }

    #[test]
    fn the_not_a_knot_spline_reproduces_cubics() {
        // A cubic through the bins is its own not-a-knot spline: the curvatures are
        // its second derivative and every reading between bins is the cubic itself.
        let n = 11usize;
        let h = (n / 2) as f64;
        let p = |x: f64| 0.7 - 1.3 * x + 0.25 * x * x - 0.04 * x * x * x;
        let p2 = |x: f64| 0.5 - 0.24 * x;
        let y: Vec<f64> = (0..n).map(|j| p(j as f64 - h)).collect();
        let m = spline_curvatures(&y);
        for (j, &mj) in m.iter().enumerate() {
            assert!((mj - p2(j as f64 - h)).abs() < 1e-12, "M[{j}] = {mj}");
        }
        for t in [-5.0, -4.7, -0.5, 0.0, 0.31, 2.99, 4.5, 5.0] {
            let s = iradon_sample(Interpolation::Cubic, &y, &m, t, 0.0);
            assert!((s - p(t)).abs() < 1e-12, "S({t}) = {s}, p = {}", p(t));
        }
        // Four bins are the fewest; fewer give no spline.
        assert_eq!(spline_curvatures(&y[..4]).len(), 4);
        assert!(spline_curvatures(&y[..3]).is_empty());
    }

    #[test]
    fn linear_and_nearest_read_as_numpy_and_scipy_do() {
        // Bins at x = −2 … 2 (n = 5, centre 2).
        let y = [1.0, 3.0, 2.0, 8.0, 4.0f64];
        let m: [f64; 0] = [];
        let lin = |t: f64| iradon_sample(Interpolation::Linear, &y, &m, t, 0.0);
        let near = |t: f64| iradon_sample(Interpolation::Nearest, &y, &m, t, 0.0);
        assert_eq!(lin(-2.0), 1.0);
        assert_eq!(lin(-1.25), 1.0 + 2.0 * 0.75);
        assert_eq!(lin(0.5), 2.0 + 6.0 * 0.5);
        assert_eq!(lin(2.0), 4.0);
        // np.interp(left=0, right=0): nothing past the first and last centres.
        assert_eq!(lin(-2.0000001), 0.0);
        assert_eq!(lin(2.0000001), 0.0);
        assert_eq!(lin(f64::NAN), 0.0);
        // interp1d(kind="nearest"): a midpoint goes to the left bin.
        assert_eq!(near(-1.5), 1.0);
        assert_eq!(near(-1.4999999), 3.0);
        assert_eq!(near(0.5), 2.0);
        assert_eq!(near(0.5000001), 8.0);
        assert_eq!(near(2.0), 4.0);
        assert_eq!(near(-2.1), 0.0);
        // Just right of the midpoint −0.5 (t − ⌊t⌋ would round to 0.5 here).
        assert_eq!(near(-0.49999999999999994), 2.0);
        assert_eq!(near(-0.5), 3.0);
        // In f32 a midpoint's side comes from `t_lo` (the rounding of cos and sin).
        let y32 = y.map(|v| v as f32);
        let near32 = |t: f32, lo: f32| iradon_sample(Interpolation::Nearest, &y32, &[], t, lo);
        assert_eq!(near32(0.5, 0.0), 2.0);
        assert_eq!(near32(0.5, 1e-16), 8.0);
        assert_eq!(near32(0.5, -1e-16), 2.0);
        // cos 60° in f64 is 0.5 + 2⁻⁵³: in f32 0.5 and a remainder of 2⁻⁵³.
        let a = Angle::<f32>::new(60f64.to_radians().cos(), 60f64.to_radians().sin());
        assert_eq!((a.c, a.c_lo), (0.5, 2f32.powi(-53)));
        assert_eq!(Angle::<f64>::new(0.3, 0.7).c_lo, 0.0);
    }

    #[test]
    fn one_view_backprojects_to_its_smear() {
        // At θ = 0, t = y (the column's offset): every row is the view, × π/2.
        let n = 9usize;
        let view: Vec<f64> = (0..n).map(|j| (j * j) as f64 - 3.0).collect();
        let none = |_: usize, _: usize| {};
        for kind in [
            Interpolation::Linear,
            Interpolation::Nearest,
            Interpolation::Cubic,
        ] {
            let m = spline_curvatures(&view);
            let img: Vec<f64> =
                iradon_backproject::<f64, f64>(&view, &m, n, &[(1.0, 0.0)], n, kind, false, &none);
            for (i, &v) in img.iter().enumerate() {
                let want = view[i % n] * std::f64::consts::PI / 2.0;
                assert!(
                    (v - want).abs() <= 1e-12 * want.abs().max(1.0),
                    "{kind} {i}"
                );
            }
            // The circle mask zeroes the corners.
            let masked: Vec<f64> =
                iradon_backproject::<f64, f64>(&view, &m, n, &[(1.0, 0.0)], n, kind, true, &none);
            assert_eq!(masked[0], 0.0);
            assert_eq!(masked[n * (n / 2) + n / 2], img[n * (n / 2) + n / 2]);
        }
    }

    #[test]
    fn the_golden_order_visits_every_view_once_from_the_smallest_angle() {
        for m in [1usize, 2, 7, 180] {
            let theta: Vec<f64> = (0..m)
                .map(|k| (k * 37 % m) as f64 * 180.0 / m as f64)
                .collect();
            let order = golden_order(&theta);
            let mut seen = order.clone();
            seen.sort_unstable();
            assert_eq!(seen, (0..m).collect::<Vec<_>>());
            assert_eq!(theta[order[0]], 0.0);
        }
        // 180/φ² ≈ 68.75°: from 0° of 0°, 1°, … 179° the next is 69°.
        let theta: Vec<f64> = (0..180).map(f64::from).collect();
        assert_eq!(&golden_order(&theta)[..2], &[0, 69]);
    }

    #[test]
    fn np_clip_is_numpys() {
        assert_eq!(np_clip(0.5, 0.0, 1.0), 0.5);
        assert_eq!(np_clip(-1.0, 0.0, 1.0), 0.0);
        assert_eq!(np_clip(2.0, 0.0, 1.0), 1.0);
        assert!(np_clip(f64::NAN, 0.0, 1.0).is_nan());
        // lo > hi: numpy gives hi.
        assert_eq!(np_clip(0.5, 2.0, 1.0), 1.0);
    }

    #[test]
    fn squares_are_skimages() {
        assert_eq!(
            Square::of(6, 9, true),
            Square {
                side: 6,
                row0: 0,
                col0: -2
            }
        );
        // ⌈√2·9⌉ = 13: rows 6 → pad 7, before (13/2 − 6/2) = 3; cols 9 → pad 4, before 2.
        assert_eq!(
            Square::of(6, 9, false),
            Square {
                side: 13,
                row0: 3,
                col0: 2
            }
        );
        let mut img = vec![0.0f32; 9];
        assert!(!outside_circle(&img, 3, 3));
        img[0] = 1.0; // corner: (1² + 1²) > 1²
        assert!(outside_circle(&img, 3, 3));
    }
}
