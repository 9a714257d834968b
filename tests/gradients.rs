//! Gradient stencils against the exact derivatives of polynomial fields.
//! Theory (unit spacing): forward differences are exact on linear fields and off by
//! `f_aa / 2` on quadratics; central differences and Sobel are exact on quadratics;
//! central differences are off by `f_aaa / 6` on cubics.

use voxlab::cpu::gradient::{
    gradient_at, gradient_at_voxel, gradient_magnitude, precompute_gradients,
};
use voxlab::cpu::grid::Grid;
use voxlab::real::V3;
use voxlab::settings::{Filter, GradientMethod};

const N: [usize; 3] = [9, 8, 7];

fn grid(f: impl Fn(f64, f64, f64) -> f64) -> Grid<f64> {
    Grid::from_fn(N, |i, j, k| f(i as f64, j as f64, k as f64))
}

/// Asserts the stencil's gradient at every interior voxel equals `want`.
fn check(g: &Grid<f64>, method: GradientMethod, want: impl Fn(f64, f64, f64) -> [f64; 3]) {
    for k in 1..N[2] - 1 {
        for j in 1..N[1] - 1 {
            for i in 1..N[0] - 1 {
                let got = gradient_at_voxel(g, i, j, k, method);
                let w = want(i as f64, j as f64, k as f64);
                for (a, wa) in w.iter().enumerate() {
                    assert!(
                        (got.0[a] - wa).abs() < 1e-10,
                        "{method:?} at ({i},{j},{k}) axis {a}: {} vs {}",
                        got.0[a],
                        wa
                    );
                }
            }
        }
    }
}

#[test]
fn every_stencil_is_exact_on_linear_fields() {
    let g = grid(|x, y, z| 2.0 * x - 3.0 * y + 0.5 * z + 7.0);
    for m in [
        GradientMethod::Central,
        GradientMethod::Forward,
        GradientMethod::Sobel,
    ] {
        check(&g, m, |_, _, _| [2.0, -3.0, 0.5]);
    }
}

/// f = x² + 2xy − y z + 3 z²; ∇f = (2x + 2y, 2x − z, −y + 6z).
fn quad(x: f64, y: f64, z: f64) -> f64 {
    x * x + 2.0 * x * y - y * z + 3.0 * z * z
}
fn quad_grad(x: f64, y: f64, z: f64) -> [f64; 3] {
    [2.0 * x + 2.0 * y, 2.0 * x - z, -y + 6.0 * z]
}

#[test]
fn central_and_sobel_are_exact_on_quadratics() {
    let g = grid(quad);
    check(&g, GradientMethod::Central, quad_grad);
    check(&g, GradientMethod::Sobel, quad_grad);
}

#[test]
fn forward_difference_is_off_by_half_the_second_derivative() {
    // f(x+1) − f(x) = f' + f''/2 (+ the mixed terms' forward shifts, zero here for the
    // pure squares): f_xx = 2, f_yy = 0, f_zz = 6.
    let g = grid(|x, y, z| x * x + 3.0 * z * z + y);
    check(&g, GradientMethod::Forward, |x, _, z| {
        [2.0 * x + 1.0, 1.0, 6.0 * z + 3.0]
    });
}

#[test]
fn central_difference_is_off_by_a_sixth_of_the_third_derivative() {
    let g = grid(|x, _, _| x * x * x);
    check(&g, GradientMethod::Central, |x, _, _| {
        [3.0 * x * x + 1.0, 0.0, 0.0]
    });
}

#[test]
fn on_the_fly_gradient_of_a_trilinear_field_is_exact_on_linear_data() {
    let g = grid(|x, y, z| 2.0 * x - 3.0 * y + 0.5 * z);
    for m in [
        GradientMethod::Central,
        GradientMethod::Forward,
        GradientMethod::Sobel,
    ] {
        for p in [[2.3, 3.7, 2.1], [4.5, 2.25, 3.9]] {
            let got = gradient_at(&g, Filter::Trilinear, V3(p), m);
            for (a, w) in [2.0, -3.0, 0.5].iter().enumerate() {
                assert!((got.0[a] - w).abs() < 1e-12, "{m:?}");
            }
        }
    }
}

#[test]
fn precomputed_gradients_and_magnitude_match_the_stencil() {
    let g = grid(quad);
    let [gx, gy, gz] = precompute_gradients(&g, GradientMethod::Central);
    let mag = gradient_magnitude(&g, GradientMethod::Central);
    let (i, j, k) = (4usize, 3usize, 2usize);
    let idx = i + N[0] * (j + N[1] * k);
    let w = quad_grad(i as f64, j as f64, k as f64);
    assert!((gx.data[idx] - w[0]).abs() < 1e-12);
    assert!((gy.data[idx] - w[1]).abs() < 1e-12);
    assert!((gz.data[idx] - w[2]).abs() < 1e-12);
    let m = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
    assert!((mag.data[idx] - m).abs() < 1e-12);
}
