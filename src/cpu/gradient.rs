//! Gradient estimation: central difference, forward difference and 3D Sobel, on the fly
//! (stencils applied to the reconstructed field at any point) or precomputed at the
//! voxel centres into a gradient volume that is then interpolated like the data.
//!
//! Gradients here are in index space (value per voxel); `cpu::raycast` turns them into
//! world-space normals with the inverse transpose of the affine's linear part.
//!
//! What each stencil gets right (spacing h = 1 voxel), proved in `tests/gradients.rs`:
//! - forward `f(x+h) − f(x)`: exact on linear fields; on `x²` it is off by `h`;
//! - central `(f(x+h) − f(x−h))/2`: exact on quadratics; off by `h²/6 f‴` on cubics;
//! - Sobel: the central difference averaged with weights `[1 2 1]/4` over the other two
//!   axes (total weight 1/32 per tap pair): exact on quadratics too, smoother on noise.
//!
//! Precomputed gradients at the border use clamped neighbours, so the outermost voxel
//! layer holds one-sided (halved) estimates. Source: Fluør (2006) §2.5 (gradient
//! estimation) and its GPU-vs-CPU timing discussion.

use super::filter::sample;
use super::grid::Grid;
use crate::real::{Real, V3};
use crate::settings::{Filter, GradientMethod};

/// Sobel smoothing weights `[1, 2, 1] / 4` at offsets −1, 0, 1.
const SOBEL_SMOOTH: [f64; 3] = [0.25, 0.5, 0.25];

/// The stencil applied to any scalar function `f` of index-space position `p`
/// (unit spacing). Mirrors `src/gpu/raycast.rs: gradient_wgsl` (which writes it out in
/// WGSL as the ray caster's `gradient_at`); mirrors `shaders/multi.wgsl: layer_gradient`.
#[inline]
pub fn gradient_stencil<R: Real>(
    f: impl Fn(V3<R>) -> R,
    p: V3<R>,
    method: GradientMethod,
) -> V3<R> {
    let e = |a: usize, s: f64| {
        let mut v = V3::zero();
        v.0[a] = R::of(s);
        v
    };
    let half = R::of(0.5);
    match method {
        GradientMethod::Central => V3::new(
            (f(p + e(0, 1.0)) - f(p + e(0, -1.0))) * half,
            (f(p + e(1, 1.0)) - f(p + e(1, -1.0))) * half,
            (f(p + e(2, 1.0)) - f(p + e(2, -1.0))) * half,
        ),
        GradientMethod::Forward => {
            let f0 = f(p);
            V3::new(
                f(p + e(0, 1.0)) - f0,
                f(p + e(1, 1.0)) - f0,
                f(p + e(2, 1.0)) - f0,
            )
        }
        GradientMethod::Sobel => {
            let mut g = [R::zero(); 3];
            for (a, ga) in g.iter_mut().enumerate() {
                // The two axes other than a.
                let (b, c) = ((a + 1) % 3, (a + 2) % 3);
                let mut acc = R::zero();
                for (ob, wb) in SOBEL_SMOOTH.iter().enumerate() {
                    for (oc, wc) in SOBEL_SMOOTH.iter().enumerate() {
                        let q = p + e(b, ob as f64 - 1.0) + e(c, oc as f64 - 1.0);
                        let d = f(q + e(a, 1.0)) - f(q + e(a, -1.0));
                        acc = acc + R::of(wb * wc) * d;
                    }
                }
                *ga = acc * half;
            }
            V3(g)
        }
    }
}

/// On-the-fly gradient of the field reconstructed with `filter`, at point `p`.
#[inline]
pub fn gradient_at<R: Real>(
    grid: &Grid<R>,
    filter: Filter,
    p: V3<R>,
    method: GradientMethod,
) -> V3<R> {
    gradient_stencil(|q| sample(grid, filter, q), p, method)
}

/// The gradient at voxel `(i, j, k)` from the voxel values (clamped at the border).
pub fn gradient_at_voxel<R: Real>(
    grid: &Grid<R>,
    i: usize,
    j: usize,
    k: usize,
    method: GradientMethod,
) -> V3<R> {
    let p = V3::new(R::of(i as f64), R::of(j as f64), R::of(k as f64));
    gradient_stencil(
        |q| {
            let r = |x: R| x.round().to_isize().unwrap_or(0);
            grid.at_clamped(r(q.x()), r(q.y()), r(q.z()))
        },
        p,
        method,
    )
}

/// Precomputes the gradient at every voxel into three grids (x, y, z components).
pub fn precompute_gradients<R: Real>(grid: &Grid<R>, method: GradientMethod) -> [Grid<R>; 3] {
    use rayon::prelude::*;
    let [nx, ny, nz] = grid.dims;
    let slices: Vec<Vec<V3<R>>> = (0..nz)
        .into_par_iter()
        .map(|k| {
            let mut s = Vec::with_capacity(nx * ny);
            for j in 0..ny {
                for i in 0..nx {
                    s.push(gradient_at_voxel(grid, i, j, k, method));
                }
            }
            s
        })
        .collect();
    let comp = |a: usize| Grid {
        dims: grid.dims,
        data: slices.iter().flatten().map(|g| g.0[a]).collect(),
    };
    [comp(0), comp(1), comp(2)]
}

/// The gradient-magnitude field `|∇f|` at every voxel (index-space units).
pub fn gradient_magnitude<R: Real>(grid: &Grid<R>, method: GradientMethod) -> Grid<R> {
    let [gx, gy, gz] = precompute_gradients(grid, method);
    Grid {
        dims: grid.dims,
        data: (0..gx.data.len())
            .map(|n| V3::new(gx.data[n], gy.data[n], gz.data[n]).length())
            .collect(),
    }
}
