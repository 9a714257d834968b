//! scikit-image's Radon transform and its inverse's backprojection on the GPU
//! (`gpu::radon`) against the CPU (`cpu::radon`), one case list each: the GPU runs the
//! CPU f32 path's arithmetic, so each case is held to that path and to the f64 oracle.

mod common;

use voxlab::cpu::radon::{
    iradon_backproject, radon_square, rotation, spline_curvatures, Interpolation,
};
use voxlab::metrics::Tolerance;

/// Radon cases: (square side, angles in degrees).
fn radon_cases() -> Vec<(usize, Vec<f64>)> {
    let mut rng = common::Rng(3);
    vec![
        (17, (0..12).map(|k| 15.0 * k as f64).collect()),
        (32, (0..45).map(|_| 360.0 * rng.unit() - 90.0).collect()),
        (45, (0..30).map(|k| 6.0 * k as f64 + 0.37).collect()),
    ]
}

/// A non-negative random image, zero outside the inscribed circle.
fn disc(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = common::Rng(seed);
    let r = (n / 2) as i64;
    (0..n * n)
        .map(|i| {
            let (y, x) = ((i / n) as i64 - r, (i % n) as i64 - r);
            if x * x + y * y > r * r {
                0.0
            } else {
                rng.unit()
            }
        })
        .collect()
}

fn maps(n: usize, degrees: &[f64]) -> Vec<[f64; 6]> {
    degrees
        .iter()
        .map(|d| rotation(n, d.to_radians().cos(), d.to_radians().sin()))
        .collect()
}

/// Each bin is a float32 sum of `n` non-negative interpolated values; the GPU blends
/// rows in f32 where the CPU blends in f64, so a bin may differ by the sum's rounding
/// bound `n·2⁻²⁴·max|bin|` (measured on lavapipe: see the assertion's report).
#[test]
fn radon_on_the_gpu_is_the_cpu_transform() {
    let Some(ctx) = common::gpu("gpu_radon radon") else {
        return;
    };
    for (n, degrees) in radon_cases() {
        let img = disc(n, n as u64);
        let m = maps(n, &degrees);
        let oracle = radon_square(&img, n, &m);
        let img32: Vec<f32> = img.iter().map(|&v| v as f32).collect();
        let f32_path = radon_square(&img32, n, &m);
        let gpu = voxlab::gpu::radon::radon_square(ctx, &img32, n, &m).unwrap();
        let peak = oracle.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
        let bound = n as f64 * 2f64.powi(-24) * peak;
        let dims = [degrees.len(), n];
        let s = common::assert_parity_array(
            &format!("gpu_radon radon {n}"),
            &dims,
            &f32_path,
            &gpu,
            Tolerance::max_abs(bound),
        );
        eprintln!(
            "gpu_radon radon {n}: gpu vs cpu f32 max |Δ| {:.2e} (bound {bound:.2e})",
            s.max_abs
        );
        common::assert_parity_array(
            &format!("gpu_radon radon {n} vs f64"),
            &dims,
            &oracle,
            &gpu,
            Tolerance::max_abs(2.0 * bound),
        );
    }
}

/// iradon cases: (bins, angles, output side, interpolation, circle, angles every 15°
/// instead of random ones).
fn iradon_cases() -> Vec<(usize, usize, usize, Interpolation, bool, bool)> {
    let mut cases = Vec::new();
    for kind in [
        Interpolation::Linear,
        Interpolation::Nearest,
        Interpolation::Cubic,
    ] {
        cases.push((33, 37, 33, kind, true, false));
        cases.push((48, 60, 41, kind, false, false));
        cases.push((20, 9, 29, kind, false, false));
        // 30°, 60°, 120°, 150°: many t on a midpoint between bins in exact arithmetic.
        cases.push((40, 12, 40, kind, true, true));
    }
    cases
}

/// Smooth "filtered" lines (sums of a few sines) so that every interpolation is
/// exercised away from exact bins.
fn views(bins: usize, angles: usize, seed: u64) -> Vec<f64> {
    let mut rng = common::Rng(seed);
    let (a, b) = (rng.unit(), rng.unit());
    (0..bins * angles)
        .map(|i| {
            let (k, j) = ((i / bins) as f64, (i % bins) as f64);
            (0.37 * j + a * k).sin() + 0.5 * (0.11 * j * (1.0 + b) - 0.3 * k).cos()
        })
        .collect()
}

/// Bound of `max |gpu − cpu f32| / max |cpu f32|`: the same f32 operations in the same
/// order, so 0 where the device rounds as the CPU does (lavapipe: measured 0 for every
/// case); 1e-6 allows a device that contracts `a·b − c·d` into a fused multiply-add.
/// Nearest-bin reads change by a whole bin where `t` rounds across a midpoint, so that
/// case is held to the RMS of the sums instead (one flip in a 41² image of sums over 60
/// views is ≈ 2e-4 of the peak there).
const F32_PATH_REL: f64 = 1e-6;

/// Bound of `max |gpu − f64| / max |f64|`: `t`, the interpolation and the sums in f32
/// against f64 (measured on lavapipe: ≤ 5.4e-7 over the cases).
const F64_REL: f64 = 2e-6;

/// Pixels where some view's `t` (in f64) lies within 1e-4 of a midpoint between two bins:
/// there f32's `t` may choose the other bin (nearest), so the f64 comparison of the
/// nearest case leaves them out.
fn near_midpoints(size: usize, trig: &[(f64, f64)], circle: bool) -> Vec<bool> {
    let r = (size / 2) as i64;
    (0..size * size)
        .map(|i| {
            let (x, y) = ((i / size) as i64 - r, (i % size) as i64 - r);
            if circle && x * x + y * y > r * r {
                return false;
            }
            trig.iter().any(|&(c, s)| {
                let t = y as f64 * c - x as f64 * s;
                (t - t.floor() - 0.5).abs() < 1e-5
            })
        })
        .collect()
}

#[test]
fn iradon_backprojection_on_the_gpu_is_the_cpu_f32_path() {
    let Some(ctx) = common::gpu("gpu_radon iradon") else {
        return;
    };
    for (case, (bins, angles, size, kind, circle, every_15)) in
        iradon_cases().into_iter().enumerate()
    {
        let label = format!(
            "gpu_radon iradon {bins}x{angles}->{size} {kind} circle={circle}{}",
            if every_15 { " every 15°" } else { "" }
        );
        let v64 = views(bins, angles, case as u64 + 1);
        let v32: Vec<f32> = v64.iter().map(|&v| v as f32).collect();
        let m64: Vec<f64> = match kind {
            Interpolation::Cubic => v64.chunks(bins).flat_map(spline_curvatures).collect(),
            _ => Vec::new(),
        };
        let m32: Vec<f32> = m64.iter().map(|&v| v as f32).collect();
        let mut rng = common::Rng(case as u64 + 100);
        let trig: Vec<(f64, f64)> = (0..angles)
            .map(|k| {
                let a = if every_15 {
                    (15.0 * k as f64).to_radians()
                } else {
                    std::f64::consts::PI * rng.unit()
                };
                (a.cos(), a.sin())
            })
            .collect();
        let none = |_: usize, _: usize| {};
        let oracle: Vec<f64> =
            iradon_backproject::<f64, f64>(&v64, &m64, bins, &trig, size, kind, circle, &none);
        let f32_path: Vec<f32> =
            iradon_backproject::<f32, f32>(&v32, &m32, bins, &trig, size, kind, circle, &none);
        let gpu = voxlab::gpu::radon::iradon_backproject(
            ctx, &v32, &m32, bins, &trig, size, kind, circle,
        )
        .unwrap();
        let dims = [size, size];
        let tol = match kind {
            Interpolation::Nearest => Tolerance {
                rmse: 1e-4 * peak(&f32_path),
                ..Tolerance::NONE
            },
            _ => Tolerance {
                max_abs_rel: F32_PATH_REL,
                ..Tolerance::NONE
            },
        };
        let s = common::assert_parity_array(&label, &dims, &f32_path, &gpu, tol);
        eprintln!("{label}: gpu vs cpu f32 max |Δ|/peak {:.2e}", s.max_abs_rel);
        // And the f32 arithmetic against the f64 oracle.
        let mut port: Vec<f64> = gpu.iter().map(|&v| v as f64).collect();
        // Random angles: where f32's `t` is within its rounding of a midpoint, nearest
        // may read the other bin; left out. Every 15°: the midpoints met are exact
        // ties that `Angle`'s remainders decide as f64 does, so nothing is left out.
        if kind == Interpolation::Nearest && !every_15 {
            let near = near_midpoints(size, &trig, circle);
            let left_out = near.iter().filter(|&&n| n).count();
            assert!(
                left_out * 20 < size * size,
                "{label}: {left_out} pixels near a midpoint"
            );
            for (i, _) in near.iter().enumerate().filter(|(_, &n)| n) {
                port[i] = oracle[i];
            }
        }
        let s = common::assert_parity_array(
            &format!("{label} vs f64"),
            &dims,
            &oracle,
            &port,
            Tolerance {
                max_abs_rel: F64_REL,
                ..Tolerance::NONE
            },
        );
        eprintln!("{label}: gpu vs f64 max |Δ|/peak {:.2e}", s.max_abs_rel);
    }
}

fn peak<T: Copy + Into<f64>>(a: &[T]) -> f64 {
    a.iter().fold(0.0f64, |m, &v| m.max(v.into().abs()))
}

/// SART cases: (n, views, shifts, clip).
fn sart_cases() -> Vec<(usize, usize, bool, Option<[f32; 2]>)> {
    vec![
        (32, 20, false, None),
        (45, 37, true, None),
        (40, 24, true, Some([0.0, 0.8])),
    ]
}

/// One SART iteration on the GPU against the CPU's f32 path (the same steps, a pixel's
/// sums in three phases of rays instead of the rays' order, the weights in f32 where
/// the CPU takes three of them in f64: measured ≤ 4e-7 of the peak on lavapipe), and
/// both against the f64 oracle (the deviations divide by Σw², so f32 rounding grows:
/// measured ≤ 9e-5).
#[test]
fn sart_on_the_gpu_is_the_cpu_f32_iteration() {
    let Some(ctx) = common::gpu("gpu_radon sart") else {
        return;
    };
    use voxlab::cpu::radon::{golden_order, iradon_sart};
    for (n, views, shifted, clip) in sart_cases() {
        let label = format!("gpu_radon sart {n}² from {views} views");
        let img = disc(n, n as u64 + 7);
        let degrees: Vec<f64> = (0..views)
            .map(|k| 180.0 * k as f64 / views as f64)
            .collect();
        let sino = radon_square(&img, n, &maps(n, &degrees));
        let mut rng = common::Rng(n as u64);
        let shifts: Vec<f64> = (0..views)
            .map(|_| if shifted { 2.0 * rng.unit() - 1.0 } else { 0.0 })
            .collect();
        let f32s = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
        let (sino32, deg32, shifts32) = (f32s(&sino), f32s(&degrees), f32s(&shifts));
        let mut oracle = vec![0.0f64; n * n];
        let clip64 = clip.map(|c| c.map(f64::from));
        iradon_sart(
            &sino,
            n,
            &degrees,
            &mut oracle,
            &shifts,
            clip64,
            0.15,
            &|_, _| {},
        );
        let mut f32_path = vec![0.0f32; n * n];
        iradon_sart(
            &sino32,
            n,
            &deg32,
            &mut f32_path,
            &shifts32,
            clip,
            0.15,
            &|_, _| {},
        );
        let order = golden_order(&deg32);
        let gpu = voxlab::gpu::radon::iradon_sart(
            ctx,
            &sino32,
            n,
            &deg32,
            &order,
            &vec![0.0; n * n],
            &shifts32,
            clip,
            0.15,
        )
        .unwrap();
        let dims = [n, n];
        let s = common::assert_parity_array(
            &label,
            &dims,
            &f32_path,
            &gpu,
            Tolerance {
                max_abs_rel: 2e-6,
                ..Tolerance::NONE
            },
        );
        eprintln!("{label}: gpu vs cpu f32 {:.2e}", s.max_abs_rel);
        let s = common::assert_parity_array(
            &format!("{label} vs f64"),
            &dims,
            &oracle,
            &gpu,
            Tolerance {
                max_abs_rel: 2e-4,
                ..Tolerance::NONE
            },
        );
        eprintln!("{label}: gpu vs f64 {:.2e}", s.max_abs_rel);
    }
}
