//! Reconstruction filters: one separable-kernel abstraction for sampling a voxel grid
//! between voxel centres, and whole-volume resampling.
//!
//! A filter is a 1D kernel `w(x)` applied along each axis:
//! `f(p) = Σ_k Σ_j Σ_i w(p_x − i) w(p_y − j) w(p_z − k) f[i, j, k]`.
//!
//! | filter | kernel `w(x)` | radius |
//! |---|---|---|
//! | nearest | 1 for the voxel nearest `p` (ties round up) | ½ |
//! | trilinear | `1 − |x|` | 1 |
//! | B-spline | `(4 − 6x² + 3|x|³)/6`, `(2 − |x|)³/6` | 2 |
//! | B-spline (interpolating) | the same, on prefiltered coefficients | 2 |
//! | Catmull–Rom | `1.5|x|³ − 2.5x² + 1`, `−0.5|x|³ + 2.5x² − 4|x| + 2` | 2 |
//! | Lanczos-N | `sinc(x)·sinc(x/N)`, weights normalised to sum to 1 | N |
//! | sinc | `sinc(x) = sin(πx)/(πx)` over every voxel of the grid | ∞ |
//!
//! **Boundary rule.** Every filter sees the volume continued by its border voxels
//! (`clamp-to-edge`, what a GPU sampler does with `ClampToEdge`). Truncated kernels
//! clamp their tap indices. The full sinc sums over the grid and adds the exact sums of
//! its infinitely many taps beyond each border, `Σ_{k≥n} sinc(x − k)` and
//! `Σ_{k<0} sinc(x − k)`, which have a closed form in the digamma function
//! ([`sinc_tail_right`], [`sinc_tail_left`]) — so the full sinc, too, reproduces a
//! constant volume, and does not ring at the borders of a volume that does not vanish
//! there.
//!
//! **Prefiltering.** `BsplineInterp` samples a grid of B-spline coefficients `c`
//! instead of the values `f`, solved from `(c[i−1] + 4c[i] + c[i+1])/6 = f[i]` along
//! each axis with the same clamp rule (`c[−1] = c[0]`, `c[n] = c[n−1]`), an exact
//! tridiagonal solve; the spline then passes through every voxel value. [`prepare`]
//! returns the grid a filter samples: the coefficients for `BsplineInterp`, the values
//! themselves otherwise.
//!
//! The Lanczos weights are normalised so that a constant volume is reproduced exactly
//! (the raw windowed-sinc weights sum to 1 only up to a ripple of ~1e-3). Interpolating
//! kernels (nearest, trilinear, Catmull–Rom, Lanczos, sinc) return the voxel value at a
//! voxel centre; the B-spline does not (it smooths).
//!
//! The `cubic-bspline-fast` filters evaluate the B-spline kernels with 8 trilinear
//! fetches instead of 64 taps (`cpu::tricubic`); [`axis_taps`] still gives their
//! 64-tap weights.
//!
//! Sources: Fluør (2006) §2.3 on interpolation; Marschner & Lobb (1994) for the test
//! signal; Keys (1981) for Catmull–Rom; Turkowski (1990) for Lanczos.

// The grid lives in `cpu::grid`; named here too for the callers that still import it
// from the filters.
pub use super::grid::Grid;
use crate::real::{Real, V3};
use crate::settings::Filter;
use crate::volume::Volume;

/// `sin(πx)`, exactly zero at integers (argument reduced to [−½, ½] first).
/// Mirrors `shaders/shared/filters.wgsl: sin_pi`.
#[inline]
pub fn sin_pi<R: Real>(x: R) -> R {
    let two = R::of(2.0);
    // r in [-1, 1]: sin(πx) = sin(πr).
    let r = x - two * (x / two).round();
    let half = R::of(0.5);
    if r > half {
        (R::PI() * (R::one() - r)).sin()
    } else if r < -half {
        -(R::PI() * (R::one() + r)).sin()
    } else {
        (R::PI() * r).sin()
    }
}

/// `sinc(x) = sin(πx)/(πx)`, `sinc(0) = 1`. Mirrors `shaders/shared/filters.wgsl: sinc`.
#[inline]
pub fn sinc<R: Real>(x: R) -> R {
    if x == R::zero() {
        R::one()
    } else {
        sin_pi(x) / (R::PI() * x)
    }
}

/// Tent kernel. Mirrors `shaders/shared/filters.wgsl: weight_tent`.
#[inline(always)]
pub fn weight_tent<R: Real>(x: R) -> R {
    (R::one() - x.abs()).max(R::zero())
}

/// Cubic B-spline kernel. Mirrors `shaders/shared/filters.wgsl: weight_bspline`.
#[inline(always)]
pub fn weight_bspline<R: Real>(x: R) -> R {
    let a = x.abs();
    let sixth = R::one() / R::of(6.0);
    if a < R::one() {
        (R::of(4.0) - R::of(6.0) * a * a + R::of(3.0) * a * a * a) * sixth
    } else if a < R::of(2.0) {
        let t = R::of(2.0) - a;
        t * t * t * sixth
    } else {
        R::zero()
    }
}

/// Catmull–Rom kernel (Keys, a = −½). Mirrors `shaders/shared/filters.wgsl: weight_catmull_rom`.
#[inline(always)]
pub fn weight_catmull_rom<R: Real>(x: R) -> R {
    let a = x.abs();
    if a < R::one() {
        R::of(1.5) * a * a * a - R::of(2.5) * a * a + R::one()
    } else if a < R::of(2.0) {
        R::of(-0.5) * a * a * a + R::of(2.5) * a * a - R::of(4.0) * a + R::of(2.0)
    } else {
        R::zero()
    }
}

/// Lanczos-N kernel `sinc(x) sinc(x/N)` for `|x| < N`.
/// Mirrors `shaders/shared/filters.wgsl: weight_lanczos`.
#[inline(always)]
pub fn weight_lanczos<R: Real>(x: R, n: usize) -> R {
    let nr = R::of(n as f64);
    if x.abs() >= nr {
        R::zero()
    } else {
        sinc(x) * sinc(x / nr)
    }
}

/// The most taps any truncated kernel uses per axis (Lanczos-4: 8).
pub const MAX_TAPS: usize = 8;

/// The voxels (before clamping) and weights one axis contributes: indices
/// `first .. first + count`.
#[derive(Clone, Copy, Debug)]
pub struct AxisTaps<R> {
    pub first: isize,
    pub count: usize,
    pub w: [R; MAX_TAPS],
}

/// Taps along one axis for index coordinate `x` (truncated kernels only).
/// Mirrors `shaders/process_resample.wgsl: axis_taps`.
#[inline]
pub fn axis_taps<R: Real>(filter: Filter, x: R) -> AxisTaps<R> {
    let mut w = [R::zero(); MAX_TAPS];
    let i0 = x.floor();
    let f = x - i0;
    let i0 = i0.to_isize().unwrap_or(0);
    match filter {
        Filter::Nearest => {
            w[0] = R::one();
            let first = (x + R::of(0.5)).floor().to_isize().unwrap_or(0);
            AxisTaps { first, count: 1, w }
        }
        Filter::Trilinear => {
            w[0] = R::one() - f;
            w[1] = f;
            AxisTaps {
                first: i0,
                count: 2,
                w,
            }
        }
        Filter::Bspline
        | Filter::BsplineInterp
        | Filter::BsplineFast
        | Filter::BsplineFastInterp
        | Filter::CatmullRom => {
            let k = if filter != Filter::CatmullRom {
                weight_bspline::<R>
            } else {
                weight_catmull_rom::<R>
            };
            w[0] = k(f + R::one());
            w[1] = k(f);
            w[2] = k(R::one() - f);
            w[3] = k(R::of(2.0) - f);
            AxisTaps {
                first: i0 - 1,
                count: 4,
                w,
            }
        }
        Filter::Lanczos2 | Filter::Lanczos3 | Filter::Lanczos4 => {
            let n = filter.radius();
            let mut sum = R::zero();
            for (m, wm) in w.iter_mut().enumerate().take(2 * n) {
                // Tap i0 − n + 1 + m lies at offset x − i = f + n − 1 − m.
                *wm = weight_lanczos(f + R::of((n as f64) - 1.0 - m as f64), n);
                sum = sum + *wm;
            }
            for wm in w.iter_mut().take(2 * n) {
                *wm = *wm / sum;
            }
            AxisTaps {
                first: i0 - n as isize + 1,
                count: 2 * n,
                w,
            }
        }
        Filter::Sinc => unreachable!("the full sinc has no truncated taps"),
    }
}

/// Samples at index-space point `p` with `filter`. `grid` must be what [`prepare`]
/// returned for that filter (the values themselves for every filter but
/// `BsplineInterp`). Mirrors `shaders/process_resample.wgsl: sample_volume`.
#[inline]
pub fn sample<R: Real>(grid: &Grid<R>, filter: Filter, p: V3<R>) -> R {
    match filter {
        Filter::Sinc => sample_sinc(grid, p),
        Filter::BsplineFast | Filter::BsplineFastInterp => super::tricubic::sample_fast(grid, p),
        Filter::Nearest => {
            let r = |x: R| (x + R::of(0.5)).floor().to_isize().unwrap_or(0);
            grid.at_clamped(r(p.x()), r(p.y()), r(p.z()))
        }
        Filter::Trilinear => sample_trilinear(grid, p),
        _ => {
            let (tx, ty, tz) = (
                axis_taps(filter, p.x()),
                axis_taps(filter, p.y()),
                axis_taps(filter, p.z()),
            );
            apply_taps(grid, &tx, &ty, &tz)
        }
    }
}

/// [`apply_taps`] for the trilinear filter, written out: the same taps, weights and
/// sums in the same order (so the same value to the last bit), without the general
/// loops, and with the floor taken by truncation where the coordinate is a moderate
/// number (the ray caster's hot path).
#[inline]
fn sample_trilinear<R: Real>(grid: &Grid<R>, p: V3<R>) -> R {
    let lim = R::of(1e9);
    let moderate = |x: R| x > -lim && x < lim;
    if !(moderate(p.x()) && moderate(p.y()) && moderate(p.z())) {
        let t = |x: R| axis_taps(Filter::Trilinear, x);
        return apply_taps(grid, &t(p.x()), &t(p.y()), &t(p.z()));
    }
    let [nx, ny, nz] = grid.dims;
    // ⌊x⌋ by truncation, one down for negative non-integers; clamped tap indices.
    let axis = |x: R, n: usize| {
        let t = x.to_i64().unwrap_or(0);
        let i0 = if R::of(t as f64) > x { t - 1 } else { t };
        let f = x - R::of(i0 as f64);
        let c = |i: i64| i.clamp(0, n as i64 - 1) as usize;
        (c(i0), c(i0 + 1), R::one() - f, f)
    };
    let (x0, x1, wx0, wx1) = axis(p.x(), nx);
    let (y0, y1, wy0, wy1) = axis(p.y(), ny);
    let (z0, z1, wz0, wz1) = axis(p.z(), nz);
    let d = &grid.data;
    let line = |j: usize, k: usize| {
        let row = nx * (j + ny * k);
        R::zero() + wx0 * d[row + x0] + wx1 * d[row + x1]
    };
    let plane = |k: usize| R::zero() + wy0 * line(y0, k) + wy1 * line(y1, k);
    R::zero() + wz0 * plane(z0) + wz1 * plane(z1)
}

/// `Σ_k w_z[k] Σ_j w_y[j] Σ_i w_x[i] f[i, j, k]` with clamped indices, summed x
/// innermost in a fixed order (the result never depends on threads).
#[inline]
pub fn apply_taps<R: Real>(
    grid: &Grid<R>,
    tx: &AxisTaps<R>,
    ty: &AxisTaps<R>,
    tz: &AxisTaps<R>,
) -> R {
    let [nx, ny, nz] = grid.dims;
    let c = |x: isize, n: usize| x.clamp(0, n as isize - 1) as usize;
    let mut ix = [0usize; MAX_TAPS];
    for (a, slot) in ix.iter_mut().enumerate().take(tx.count) {
        *slot = c(tx.first + a as isize, nx);
    }
    let mut acc_z = R::zero();
    for b in 0..tz.count {
        let k = c(tz.first + b as isize, nz);
        let mut acc_y = R::zero();
        for a in 0..ty.count {
            let j = c(ty.first + a as isize, ny);
            let row = &grid.data[nx * (j + ny * k)..];
            let mut acc_x = R::zero();
            for (i, &xi) in ix.iter().enumerate().take(tx.count) {
                acc_x = acc_x + tx.w[i] * row[xi];
            }
            acc_y = acc_y + ty.w[a] * acc_x;
        }
        acc_z = acc_z + tz.w[b] * acc_y;
    }
    acc_z
}

/// Digamma function ψ(x) for x > 0 (recurrence up to x ≥ 10, then the asymptotic
/// series; about 1e-15 relative).
pub fn digamma(mut x: f64) -> f64 {
    let mut acc = 0.0;
    while x < 10.0 {
        acc -= 1.0 / x;
        x += 1.0;
    }
    let x2 = 1.0 / (x * x);
    let series = x2
        * (1.0 / 12.0
            - x2 * (1.0 / 120.0
                - x2 * (1.0 / 252.0
                    - x2 * (1.0 / 240.0 - x2 * (1.0 / 132.0 - x2 * 691.0 / 32760.0)))));
    acc + x.ln() - 0.5 / x - series
}

/// `β(z) = Σ_{m≥0} (−1)^m / (z + m) = ½ [ψ((z + 1)/2) − ψ(z/2)]`, for z > 0.
fn alternating_harmonic(z: f64) -> f64 {
    0.5 * (digamma(0.5 * (z + 1.0)) - digamma(0.5 * z))
}

/// `Σ_{k≥n} sinc(x − k)`: the weight of all taps beyond the last voxel, which the
/// clamp rule gives the value of voxel `n − 1`. Equals `−(−1)^n sin(πx)/π · β(n − x)`.
pub fn sinc_tail_right(x: f64, n: usize) -> f64 {
    let s = sin_pi(x);
    if s == 0.0 {
        return 0.0;
    }
    let sign = if n.is_multiple_of(2) { 1.0 } else { -1.0 };
    -sign * s / std::f64::consts::PI * alternating_harmonic(n as f64 - x)
}

/// `Σ_{k<0} sinc(x − k) = −sin(πx)/π · β(x + 1)`: the weight of all taps before the
/// first voxel.
pub fn sinc_tail_left(x: f64) -> f64 {
    let s = sin_pi(x);
    if s == 0.0 {
        return 0.0;
    }
    -s / std::f64::consts::PI * alternating_harmonic(x + 1.0)
}

/// The full-sinc weights of the `n` voxels of one axis at coordinate `x`, the two
/// infinite tails folded onto the border voxels (clamp-to-edge).
pub fn sinc_weights<R: Real>(x: R, n: usize) -> Vec<R> {
    let mut w: Vec<R> = (0..n).map(|i| sinc(x - R::of(i as f64))).collect();
    let xf = x.f64();
    w[0] = w[0] + R::of(sinc_tail_left(xf));
    w[n - 1] = w[n - 1] + R::of(sinc_tail_right(xf, n));
    w
}

/// Full-sinc reconstruction over every voxel of the grid, clamp-to-edge beyond it.
pub fn sample_sinc<R: Real>(grid: &Grid<R>, p: V3<R>) -> R {
    let [nx, ny, nz] = grid.dims;
    let (wx, wy, wz) = (
        sinc_weights(p.x(), nx),
        sinc_weights(p.y(), ny),
        sinc_weights(p.z(), nz),
    );
    let mut acc_z = R::zero();
    for (k, &wk) in wz.iter().enumerate() {
        if wk == R::zero() {
            continue;
        }
        let mut acc_y = R::zero();
        for (j, &wj) in wy.iter().enumerate() {
            if wj == R::zero() {
                continue;
            }
            let row = &grid.data[nx * (j + ny * k)..nx * (j + ny * k) + nx];
            let mut acc_x = R::zero();
            for (&wi, &f) in wx.iter().zip(row) {
                acc_x = acc_x + wi * f;
            }
            acc_y = acc_y + wj * acc_x;
        }
        acc_z = acc_z + wk * acc_y;
    }
    acc_z
}

/// Solves `(c[i−1] + 4c[i] + c[i+1])/6 = f[i]` with `c[−1] = c[0]`, `c[n] = c[n−1]`
/// in place (Thomas algorithm; the system is strictly diagonally dominant).
pub fn bspline_prefilter_line<R: Real>(f: &mut [R]) {
    let n = f.len();
    if n == 1 {
        return; // (c + 4c + c)/6 = c.
    }
    let sixth = R::one() / R::of(6.0);
    let (a, b, c) = (sixth, R::of(4.0) * sixth, sixth);
    // Diagonal: row 0 and row n−1 absorb the clamped neighbour.
    let diag = |i: usize| if i == 0 || i == n - 1 { b + a } else { b };
    let mut cp = vec![R::zero(); n];
    let mut d = diag(0);
    cp[0] = c / d;
    f[0] = f[0] / d;
    for i in 1..n {
        d = diag(i) - a * cp[i - 1];
        if i + 1 < n {
            cp[i] = c / d;
        }
        f[i] = (f[i] - a * f[i - 1]) / d;
    }
    for i in (0..n - 1).rev() {
        f[i] = f[i] - cp[i] * f[i + 1];
    }
}

/// The B-spline coefficient grid: [`bspline_prefilter_line`] along x, then y, then z.
pub fn bspline_coefficients<R: Real>(grid: &Grid<R>) -> Grid<R> {
    use rayon::prelude::*;
    let [nx, ny, nz] = grid.dims;
    let mut c = grid.clone();
    c.data.par_chunks_mut(nx).for_each(bspline_prefilter_line);
    for axis in [1usize, 2] {
        let (n, stride) = if axis == 1 { (ny, nx) } else { (nz, nx * ny) };
        let lines: Vec<usize> = (0..nx * ny * nz)
            .filter(|&idx| (idx / stride) % n == 0)
            .collect();
        let results: Vec<Vec<R>> = lines
            .par_iter()
            .map(|&start| {
                let mut line: Vec<R> = (0..n).map(|m| c.data[start + m * stride]).collect();
                bspline_prefilter_line(&mut line);
                line
            })
            .collect();
        for (&start, line) in lines.iter().zip(&results) {
            for (m, &v) in line.iter().enumerate() {
                c.data[start + m * stride] = v;
            }
        }
    }
    c
}

/// The grid `filter` samples: B-spline coefficients for `BsplineInterp` and
/// `BsplineFastInterp`, a copy of the values otherwise.
pub fn prepare<R: Real>(grid: &Grid<R>, filter: Filter) -> Grid<R> {
    if filter.prefiltered() {
        bspline_coefficients(grid)
    } else {
        grid.clone()
    }
}

/// Resamples the index-space box `[lo, hi]` (cell edges, e.g. `[-0.5, n − 0.5]` for the
/// whole volume) of `grid` onto a grid of `dims` whose cells tile that box: new voxel
/// `i` samples old index coordinate `lo + (i + ½)(hi − lo)/dims`.
pub fn resample_box<R: Real>(
    grid: &Grid<R>,
    filter: Filter,
    lo: [f64; 3],
    hi: [f64; 3],
    dims: [usize; 3],
) -> Grid<R> {
    use rayon::prelude::*;
    let prepared = prepare(grid, filter);
    let grid = &prepared;
    let coord = |a: usize, i: usize| lo[a] + (i as f64 + 0.5) * (hi[a] - lo[a]) / dims[a] as f64;
    let mut data = vec![R::zero(); dims[0] * dims[1] * dims[2]];
    data.par_chunks_mut(dims[0] * dims[1])
        .enumerate()
        .for_each(|(k, slice)| {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let p = V3::new(R::of(coord(0, i)), R::of(coord(1, j)), R::of(coord(2, k)));
                    slice[i + dims[0] * j] = sample(grid, filter, p);
                }
            }
        });
    Grid { dims, data }
}

/// Resamples a whole volume to new dimensions with `filter` (in f64), keeping its box
/// in the world: the new affine places the new voxel centres where they were sampled.
pub fn resample_volume(
    vol: &Volume<f32>,
    filter: Filter,
    dims: [usize; 3],
) -> crate::Result<Volume<f32>> {
    crate::volume::check_dims(dims)?;
    let old = vol.dims();
    let lo = [-0.5; 3];
    let hi = [
        old[0] as f64 - 0.5,
        old[1] as f64 - 0.5,
        old[2] as f64 - 0.5,
    ];
    let grid = Grid::<f64>::from_volume(vol);
    let out = resample_box(&grid, filter, lo, hi, dims);
    // new index i ↦ old index lo + (i + ½) s with s = n_old / n_new.
    let s = glam::DVec3::new(
        old[0] as f64 / dims[0] as f64,
        old[1] as f64 / dims[1] as f64,
        old[2] as f64 / dims[2] as f64,
    );
    let to_old = glam::DMat4::from_translation(glam::DVec3::splat(-0.5) + 0.5 * s)
        * glam::DMat4::from_scale(s);
    Volume::with_affine(
        dims,
        vol.affine() * to_old,
        out.data.iter().map(|&x| x as f32).collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The written-out trilinear path equals the general tap loop to the last bit,
    /// inside, on and beyond the borders, and at huge and non-finite coordinates.
    #[test]
    fn trilinear_fast_path_equals_the_tap_loop() {
        fn check<R: Real>() {
            let dims = [5, 4, 3];
            let data: Vec<R> = (0..60)
                .map(|i| R::of(((i * 37) % 11) as f64 / 7.0 - 0.3))
                .collect();
            let grid = Grid { dims, data };
            let coords = [
                -1.7, -1.0, -0.5, -0.25, 0.0, 0.3, 1.0, 1.5, 2.999, 3.0, 3.5, 4.2, 6.0, 1e12, -1e12,
            ];
            let mut n = 0;
            for &x in &coords {
                for &y in &coords[..9] {
                    for &z in &[-0.4, 0.0, 0.7, 2.5, 9.0, f64::NAN] {
                        let p = V3::new(R::of(x), R::of(y), R::of(z));
                        let t = |c: R| axis_taps(Filter::Trilinear, c);
                        let want = apply_taps(&grid, &t(p.x()), &t(p.y()), &t(p.z()));
                        let got = sample(&grid, Filter::Trilinear, p);
                        assert!(
                            got.to_f64().unwrap().to_bits() == want.to_f64().unwrap().to_bits()
                                || (got.is_nan() && want.is_nan()),
                            "{x} {y} {z}"
                        );
                        n += 1;
                    }
                }
            }
            assert_eq!(n, 15 * 9 * 6);
        }
        check::<f32>();
        check::<f64>();
    }

    #[test]
    fn sin_pi_is_zero_at_integers() {
        for k in -20..=20 {
            assert_eq!(sin_pi(k as f64), 0.0);
        }
        assert!((sin_pi(0.5f64) - 1.0).abs() < 1e-16);
        assert!((sin_pi(2.25f64) - (0.25 * std::f64::consts::PI).sin()).abs() < 1e-15);
    }

    #[test]
    fn truncated_kernels_partition_unity() {
        for filter in Filter::ALL.into_iter().filter(|f| *f != Filter::Sinc) {
            for k in 0..50 {
                let x = -3.0 + k as f64 * 0.1373;
                let t = axis_taps(filter, x);
                let s: f64 = t.w[..t.count].iter().sum();
                assert!((s - 1.0).abs() < 1e-14, "{filter:?} at {x}: {s}");
            }
        }
    }

    #[test]
    fn interpolating_kernels_are_exact_at_voxel_centres() {
        let g = Grid::from_fn([6, 5, 4], |i, j, k| ((i * 7 + j * 3 + k * 11) % 13) as f64);
        for filter in Filter::ALL.into_iter().filter(|f| *f != Filter::Bspline) {
            let c = prepare(&g, filter);
            for (i, j, k) in [(0, 0, 0), (2, 3, 1), (5, 4, 3), (3, 2, 2)] {
                let p = V3::new(i as f64, j as f64, k as f64);
                let want = g.at_clamped(i, j, k);
                assert!((sample(&c, filter, p) - want).abs() < 1e-12, "{filter:?}");
            }
        }
    }

    #[test]
    fn sinc_weights_sum_to_one_with_their_tails() {
        // Σ_k sinc(x − k) = 1 over all integers: the grid taps plus both tails.
        for n in [1usize, 2, 7, 40] {
            for m in 0..30 {
                let x = -0.5 + (n as f64) * (m as f64 + 0.37) / 30.0;
                let s: f64 = sinc_weights(x, n).iter().sum();
                assert!((s - 1.0).abs() < 1e-13, "n={n} x={x}: {s}");
            }
        }
    }

    #[test]
    fn digamma_known_values() {
        let euler = 0.577_215_664_901_532_9;
        assert!((digamma(1.0) + euler).abs() < 1e-14);
        assert!((digamma(0.5) + euler + 2.0 * 2f64.ln()).abs() < 1e-14);
        assert!((digamma(7.25) - digamma(6.25) - 1.0 / 6.25).abs() < 1e-14);
    }

    #[test]
    fn prefilter_inverts_the_bspline_at_voxels() {
        let f: Vec<f64> = (0..9).map(|i| ((i * 37) % 11) as f64 - 3.0).collect();
        let mut c = f.clone();
        bspline_prefilter_line(&mut c);
        for i in 0..9 {
            let at = |k: isize| c[k.clamp(0, 8) as usize];
            let i = i as isize;
            let back = (at(i - 1) + 4.0 * at(i) + at(i + 1)) / 6.0;
            assert!((back - f[i as usize]).abs() < 1e-13);
        }
    }

    #[test]
    fn resampling_to_the_same_size_is_the_identity() {
        let v = Volume::from_fn([5, 4, 3], [1.0, 2.0, 3.0], |i, j, k| {
            (i + 2 * j + 3 * k) as f32
        })
        .unwrap();
        let r = resample_volume(&v, Filter::CatmullRom, [5, 4, 3]).unwrap();
        assert_eq!(r.data(), v.data());
        assert!((r.affine() - v.affine()).abs_diff_eq(glam::DMat4::ZERO, 1e-12));
        // Doubling keeps the world box: the new first voxel centre is a quarter voxel in.
        let d = resample_volume(&v, Filter::Trilinear, [10, 8, 6]).unwrap();
        let p = d.affine().transform_point3(glam::DVec3::ZERO);
        assert!((p - glam::DVec3::new(-0.25, -0.5, -0.75)).length() < 1e-12);
    }
}
