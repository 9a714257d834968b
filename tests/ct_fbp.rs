//! Ramp filtering, FBP and FDK on the CPU: analytic truths and the f64 oracle.

mod common;

use common::Rng;
use voxlab::cpu::ramp::{
    effective_response, filter_projections, frequency_response, padded_length, ramp_kernel,
    spatial_ramp, FilterMethod, RampFilter,
};
use voxlab::ct::{Geometry, Projections};

fn random_projections(g: &Geometry, seed: u64) -> Projections<f64> {
    let mut rng = Rng(seed);
    let mut p = Projections::<f64>::zeros(g).unwrap();
    for v in &mut p.data {
        *v = rng.unit() * 10.0 - 3.0;
    }
    p
}

fn max_abs(a: &[f64]) -> f64 {
    a.iter().fold(0.0f64, |m, v| m.max(v.abs()))
}

#[test]
fn padded_length_is_skimages() {
    assert_eq!(padded_length(1), 64);
    assert_eq!(padded_length(32), 64);
    assert_eq!(padded_length(33), 128);
    assert_eq!(padded_length(256), 512);
    assert_eq!(padded_length(363), 1024);
}

#[test]
fn ramp_kernel_and_response_are_a_dft_pair() {
    for p in [64usize, 256] {
        let h = spatial_ramp(p);
        assert_eq!(h[0], 0.25);
        assert_eq!(h[2], 0.0);
        assert_eq!(h[p - 1], h[1]);
        assert!((h[3] + 1.0 / (9.0 * std::f64::consts::PI.powi(2))).abs() < 1e-17);
        let resp = frequency_response(p, RampFilter::RamLak);
        // H ≈ 2|f|: the band-limited ramp. Measured worst |H − 2|f|| over all k:
        // 6.3e-3 at P = 64, 1.6e-3 at P = 256 (≈ 0.405/P, attained at DC).
        for (k, &hv) in resp.iter().enumerate().skip(1) {
            let f = (k.min(p - k)) as f64 / p as f64;
            assert!((hv - 2.0 * f).abs() < 2.0 / p as f64, "P {p} k {k}: {hv}");
        }
        assert!(resp[0] > 0.0 && resp[0] < 2.0 / p as f64, "{}", resp[0]);
        // Every filter: the spatial kernel's exact DFT is the even part of H.
        for f in RampFilter::ALL {
            let g = ramp_kernel(p, f);
            let even = effective_response(p, f);
            for (k, &ek) in even.iter().enumerate() {
                let s: f64 = g
                    .iter()
                    .enumerate()
                    .map(|(n, v)| {
                        v * (2.0 * std::f64::consts::PI * (k * n) as f64 / p as f64).cos()
                    })
                    .sum();
                // Measured worst: 6.8e-15 (P = 64), 3.0e-14 (P = 256).
                assert!((s - ek).abs() < 1e-13, "{f:?} P {p} k {k}: {s} vs {ek}");
            }
        }
    }
}

#[test]
fn windows_match_scikit_image_values() {
    // Spot values of scikit-image's `_get_fourier_filter(64, name)` computed from its
    // formulas: window × ramp at k = 1 and k = 32 (Nyquist).
    let p = 64;
    let ramp = frequency_response(p, RampFilter::RamLak);
    let w = |f| {
        let h = frequency_response(p, f);
        (h[1] / ramp[1], h[32] / ramp[32])
    };
    let pi = std::f64::consts::PI;
    let (a, b) = w(RampFilter::SheppLogan);
    assert!((a - (pi / 64.0).sin() / (pi / 64.0)).abs() < 1e-15);
    assert!((b - (-pi / 2.0).sin() / (-pi / 2.0)).abs() < 1e-15);
    let (a, b) = w(RampFilter::Cosine);
    assert!((a - (pi * 33.0 / 64.0).sin()).abs() < 1e-15 && b.abs() < 1e-15);
    let (a, b) = w(RampFilter::Hann);
    assert!((a - (0.5 - 0.5 * (2.0 * pi * 33.0 / 63.0).cos())).abs() < 1e-15);
    assert!((b - 0.0).abs() < 1e-15);
    let (_, b) = w(RampFilter::Hamming);
    assert!((b - 0.08).abs() < 1e-15);
}

#[test]
fn filtering_a_delta_gives_the_kernel() {
    let cols = 40;
    let g = Geometry::parallel_skimage(cols, vec![0.0]).unwrap();
    let pl = padded_length(cols);
    for f in RampFilter::ALL {
        for m in [FilterMethod::Direct, FilterMethod::Fft] {
            let mut p = Projections::<f64>::zeros(&g).unwrap();
            p.data[7] = 1.0;
            let q = filter_projections(&p, &g, f, m).unwrap();
            let k = ramp_kernel(pl, f);
            for n in 0..cols {
                let want = k[(n + pl - 7) % pl];
                // Measured: Direct exact (0), FFT below 1e-16.
                assert!((q.data[n] - want).abs() < 1e-15, "{f:?} {m:?} {n}");
            }
        }
    }
}

#[test]
fn direct_and_fft_filtering_agree() {
    let cases = [
        Geometry::parallel_skimage(63, Geometry::even_angles(5, 180.0)).unwrap(),
        Geometry::parallel_stack(50, 3, 0.7, 1.2, Geometry::even_angles(3, 180.0)).unwrap(),
        Geometry::cone_rtk(
            1000.0,
            1500.0,
            48,
            7,
            1.3,
            0.9,
            Geometry::even_angles(3, 360.0),
        )
        .unwrap(),
    ];
    for (i, g) in cases.iter().enumerate() {
        let p = random_projections(g, 11 + i as u64);
        for f in RampFilter::ALL {
            let d = filter_projections(&p, g, f, FilterMethod::Direct).unwrap();
            let q = filter_projections(&p, g, f, FilterMethod::Fft).unwrap();
            let scale = max_abs(&d.data);
            let err: Vec<f64> = d.data.iter().zip(&q.data).map(|(a, b)| a - b).collect();
            // f64 FFT vs direct: measured worst 1.1e-15 relative to the data scale.
            assert!(
                max_abs(&err) < 1e-14 * scale,
                "case {i} {f:?}: {}",
                max_abs(&err)
            );
            let p32 = Projections::new(
                p.angles,
                p.rows,
                p.cols,
                p.data.iter().map(|&v| v as f32).collect(),
            )
            .unwrap();
            let q32 = filter_projections(&p32, g, f, FilterMethod::Fft).unwrap();
            let err: Vec<f64> = d
                .data
                .iter()
                .zip(&q32.data)
                .map(|(a, &b)| a - b as f64)
                .collect();
            // f32 FFT vs the f64 oracle: measured worst 1.8e-7 relative to the data scale.
            assert!(
                max_abs(&err) < 1e-6 * scale,
                "case {i} {f:?} f32: {}",
                max_abs(&err)
            );
        }
    }
}

#[test]
fn filtered_values_scale_with_the_spacing() {
    let angles = vec![0.0, 90.0];
    let g1 = Geometry::parallel_stack(30, 2, 1.0, 1.0, angles.clone()).unwrap();
    let g2 = Geometry::parallel_stack(30, 2, 2.5, 1.0, angles).unwrap();
    let p = random_projections(&g1, 5);
    for m in [FilterMethod::Direct, FilterMethod::Fft] {
        let a = filter_projections(&p, &g1, RampFilter::Hann, m).unwrap();
        let b = filter_projections(&p, &g2, RampFilter::Hann, m).unwrap();
        for (x, y) in a.data.iter().zip(&b.data) {
            assert!((x / 2.5 - y).abs() < 1e-14 * x.abs().max(1.0));
        }
    }
    // Cone: divided by du·SID/SDD, after the cosine weight.
    let g = Geometry::cone_rtk(1000.0, 1500.0, 1, 1, 2.0, 1.0, vec![0.0]).unwrap();
    let mut p = Projections::<f64>::zeros(&g).unwrap();
    p.data[0] = 1.0;
    let q = filter_projections(&p, &g, RampFilter::RamLak, FilterMethod::Direct).unwrap();
    assert!((q.data[0] - 0.5 / (2.0 * 1000.0 / 1500.0)).abs() < 1e-15);
}

#[test]
fn bad_input_is_refused() {
    let g = Geometry::parallel_skimage(8, vec![0.0, 1.0]).unwrap();
    let p = Projections::<f64>::new(1, 1, 8, vec![0.0; 8]).unwrap();
    assert!(filter_projections(&p, &g, RampFilter::RamLak, FilterMethod::Fft).is_err());
    let mut p = Projections::<f64>::zeros(&g).unwrap();
    p.data[3] = f64::NAN;
    assert!(filter_projections(&p, &g, RampFilter::RamLak, FilterMethod::Direct).is_err());
}
