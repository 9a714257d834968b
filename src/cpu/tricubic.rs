//! Fast tricubic B-spline filtering: the 64-tap cubic B-spline as 8 trilinear fetches.
//!
//! The cubic B-spline weights are all positive, so along one axis the four taps pair
//! into two linear interpolations (Sigg & Hadwiger 2005, *Fast Third-Order Texture
//! Filtering*, GPU Gems 2 ch. 20; in 3D: Ruijters, ter Haar Romeny & Suetens 2008, and
//! the tri-cubic option of Gavrilov & Turlapov's InVols). At index coordinate `x`, with
//! `i = floor(x)`, `f = x − i` and the weights of `cpu::filter::axis_taps`,
//!
//! ```text
//! w0 = B(f + 1) = (1 − f)³/6          w2 = B(1 − f) = (4 − 6(1−f)² + 3(1−f)³)/6
//! w1 = B(f)     = (4 − 6f² + 3f³)/6   w3 = B(2 − f) = f³/6
//! ```
//!
//! the 1-D sum of the taps `i − 1 … i + 2` is
//!
//! ```text
//! w0 f[i−1] + w1 f[i] + w2 f[i+1] + w3 f[i+2]
//!   = g0 · lerp(f[i−1], f[i],   w1/g0)   at coordinate  c0 = i − 1 + w1/g0 = x − h0
//!   + g1 · lerp(f[i+1], f[i+2], w3/g1)   at coordinate  c1 = i + 1 + w3/g1 = x + h1
//! with g0 = w0 + w1,  g1 = w2 + w3,  h0 = 1 + f − w1/g0,  h1 = 1 − f + w3/g1,
//! ```
//!
//! and a linear interpolation at `c` is exactly what a trilinear fetch at `c` returns.
//! In 3D the tensor product gives 8 trilinear fetches at the corners
//! `(c_a^x, c_b^y, c_c^z)`, `a, b, c ∈ {0, 1}`, weighted `g_a^x g_b^y g_c^z`: 8 fetches
//! (64 voxel reads by hand, 8 texture-unit operations on a GPU) instead of 64 taps.
//! `g0 ≥ w1 ≥ 1/6` and `g1 ≥ w2 ≥ 1/6`, so the divisions are safe, and
//! `w1/g0 ∈ [½, 1]`, `w3/g1 ∈ [0, ⅕]`: each fetch stays between its two voxels.
//!
//! **Boundary.** The oracle clamps every tap index to the grid (clamp-to-edge). A
//! trilinear fetch at `c0` reads the voxels `i − 1` and `i` with the same clamp, so the
//! fast sum equals the oracle's at the borders too (and a GPU sampler with
//! `ClampToEdge` clamps its two texel indices the same way). When `w1/g0` rounds to 1
//! the fetch lands on voxel `i` with fraction 0 and the result is unchanged.
//!
//! **Exactness.** [`sample_fast`] passes each fetch its voxel `i − 1` (or `i + 1`) and
//! fraction `w1/g0` (or `w3/g1`) directly, never the rounded coordinate, and lerps in
//! `R`; it equals `cpu::filter::sample` with `Bspline` to rounding (≤ 1e-12 in f64,
//! `tests/tricubic.rs`). `BsplineFastInterp` samples the prefiltered coefficients of
//! `cpu::filter::prepare` the same way.
//!
//! The GPU twin: `shaders/shared/tricubic.wgsl` (`fast_bspline_axis`, `trilinear_fetch`,
//! `sample_fast_bspline`, and the texture-unit variant `sample_fast_bspline_hw`).

use super::grid::Grid;
use crate::real::{Real, V3};

/// One axis of the fast B-spline: the two fetches' first voxels `(i − 1, i + 1)`, their
/// fractions `(w1/g0, w3/g1)` and weights `(g0, g1)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FastAxis<R> {
    pub base: [isize; 2],
    pub frac: [R; 2],
    pub g: [R; 2],
}

/// The fast B-spline's fetch positions and weights along one axis at index coordinate
/// `x`. Mirrors `shaders/shared/tricubic.wgsl: fast_bspline_axis`.
#[inline(always)]
pub fn fast_bspline_axis<R: Real>(x: R) -> FastAxis<R> {
    let fl = x.floor();
    let f = x - fl;
    let i = fl.to_isize().unwrap_or(0);
    let sixth = R::one() / R::of(6.0);
    let one = R::one();
    let e = one - f;
    let w0 = e * e * e * sixth;
    let w1 = (R::of(4.0) - R::of(6.0) * f * f + R::of(3.0) * f * f * f) * sixth;
    let w2 = (R::of(4.0) - R::of(6.0) * e * e + R::of(3.0) * e * e * e) * sixth;
    let w3 = f * f * f * sixth;
    let g0 = w0 + w1;
    let g1 = w2 + w3;
    FastAxis {
        base: [i - 1, i + 1],
        frac: [w1 / g0, w3 / g1],
        g: [g0, g1],
    }
}

/// The exact trilinear interpolation between voxels `base … base + 1` at fractions
/// `frac` (indices clamped to the grid), summed x innermost like
/// `cpu::filter::apply_taps`. Mirrors `shaders/shared/tricubic.wgsl: trilinear_fetch`.
#[inline(always)]
pub fn trilinear_fetch<R: Real>(grid: &Grid<R>, base: [isize; 3], frac: [R; 3]) -> R {
    let one = R::one();
    let lerp_x = |j: isize, k: isize| {
        (one - frac[0]) * grid.at_clamped(base[0], j, k)
            + frac[0] * grid.at_clamped(base[0] + 1, j, k)
    };
    let lerp_xy =
        |k: isize| (one - frac[1]) * lerp_x(base[1], k) + frac[1] * lerp_x(base[1] + 1, k);
    (one - frac[2]) * lerp_xy(base[2]) + frac[2] * lerp_xy(base[2] + 1)
}

/// The cubic B-spline at index-space point `p` from 8 exact trilinear fetches; equals
/// `cpu::filter::sample(grid, Filter::Bspline, p)` to rounding. `grid` holds the voxel
/// values (`BsplineFast`) or their B-spline coefficients (`BsplineFastInterp`).
/// Mirrors `shaders/shared/tricubic.wgsl: sample_fast_bspline`.
#[inline]
pub fn sample_fast<R: Real>(grid: &Grid<R>, p: V3<R>) -> R {
    let (ax, ay, az) = (
        fast_bspline_axis(p.x()),
        fast_bspline_axis(p.y()),
        fast_bspline_axis(p.z()),
    );
    let mut acc_z = R::zero();
    for c in 0..2 {
        let mut acc_y = R::zero();
        for b in 0..2 {
            let mut acc_x = R::zero();
            for a in 0..2 {
                let v = trilinear_fetch(
                    grid,
                    [ax.base[a], ay.base[b], az.base[c]],
                    [ax.frac[a], ay.frac[b], az.frac[c]],
                );
                acc_x = acc_x + ax.g[a] * v;
            }
            acc_y = acc_y + ay.g[b] * acc_x;
        }
        acc_z = acc_z + az.g[c] * acc_y;
    }
    acc_z
}

/// The 8 fetch points of the fast B-spline at `p` in index coordinates, with their
/// weights: what a GPU's texture unit is asked for (`sample_fast_bspline_hw`).
pub fn fetch_points(p: [f64; 3]) -> [([f64; 3], f64); 8] {
    let axes = p.map(fast_bspline_axis::<f64>);
    let mut out = [([0.0; 3], 0.0); 8];
    for (n, slot) in out.iter_mut().enumerate() {
        let s = [n & 1, (n >> 1) & 1, n >> 2];
        let mut q = [0.0; 3];
        let mut w = 1.0;
        for d in 0..3 {
            q[d] = axes[d].base[s[d]] as f64 + axes[d].frac[s[d]];
            w *= axes[d].g[s[d]];
        }
        *slot = (q, w);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fetch_weights_sum_to_one() {
        let pts = fetch_points([0.3, 7.9, -0.5]);
        let s: f64 = pts.iter().map(|(_, w)| w).sum();
        assert!((s - 1.0).abs() < 1e-15);
    }
}
