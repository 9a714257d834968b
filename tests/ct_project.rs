//! Joseph's voxel projector on the CPU, up the oracle ladder: an analytic truth where
//! Joseph is exact (a constant grid → value × chord), the analytic phantom projection
//! (the difference is discretisation and must shrink with resolution), and f32 vs f64.

mod common;

use glam::{DMat4, DVec3};
use voxlab::cpu::project::{project_phantom, project_volume, Grid, ProjectOptions};
use voxlab::ct::{Geometry, Projections};
use voxlab::phantom::Phantom;

fn parallel(n: usize, d: f64, angles: usize) -> Geometry {
    Geometry::parallel_stack(n, n, d, d, Geometry::even_angles(angles, 180.0)).unwrap()
}

fn cone(n: usize, d: f64, angles: usize) -> Geometry {
    Geometry::cone_rtk(
        1000.0,
        1500.0,
        n,
        n,
        d,
        d,
        Geometry::even_angles(angles, 360.0),
    )
    .unwrap()
}

/// Largest |a − b| and the largest |b| (`metrics::error_stats`, `b` the reference; ∞
/// on a NaN/Inf mismatch).
fn worst(a: &Projections<f64>, b: &Projections<f64>) -> (f64, f64) {
    let e = voxlab::metrics::error_stats(&b.data, &a.data, f64::INFINITY).infinite_if_mismatched();
    (e.max_abs, e.peak)
}

/// Mean |a − b| over the mean |b|.
fn mean_rel(a: &Projections<f64>, b: &Projections<f64>) -> f64 {
    let d: f64 = a.data.iter().zip(&b.data).map(|(x, y)| (x - y).abs()).sum();
    d / b.data.iter().map(|v| v.abs()).sum::<f64>()
}

#[test]
fn a_constant_grid_projects_to_value_times_chord() {
    // 24 × 20 × 28 voxels of 2 × 3 × 2.5 mm, value 1.5, in an oblique-free frame but
    // off-centre; angles avoid 45° ties.
    let dims = [24usize, 20, 28];
    let affine = DMat4::from_translation(DVec3::new(3.0, -2.0, 5.0))
        * DMat4::from_scale(DVec3::new(2.0, 3.0, 2.5))
        * DMat4::from_translation(-DVec3::new(11.5, 9.5, 13.5));
    let grid = Grid::<f64>::new(dims, affine, vec![1.5; 24 * 20 * 28]).unwrap();
    let angles = vec![0.0, 17.0, 90.0, 151.0, 200.0, 301.5];
    for g in [
        Geometry::parallel_stack(40, 30, 1.7, 1.9, angles.clone()).unwrap(),
        Geometry::cone_rtk(600.0, 900.0, 40, 30, 2.5, 2.8, angles.clone()).unwrap(),
    ] {
        let (checked, worst) = common::constant_grid_chords(&grid, 1.5, &g);
        eprintln!("{:?}: {checked} rays, worst relative {worst:.2e}", g.beam);
        // Measured: 1.7e-16 (parallel), 2.4e-15 (cone) relative, over 3248 rays each.
        assert!(checked > 500, "{checked}");
        assert!(worst < 1e-12, "{:?}: {worst}", g.beam);
    }
}

#[test]
fn a_sampled_phantom_converges_to_the_analytic_projection() {
    let ph = Phantom::shepp_logan_modified();
    for (name, g) in [
        ("parallel", parallel(64, 4.5, 12)),
        ("cone", cone(64, 6.5, 12)),
    ] {
        let exact = project_phantom(&ph, &g).unwrap();
        let mut errs = Vec::new();
        for n in [32usize, 64, 128] {
            let grid = Grid::<f64>::phantom(&ph, [n; 3]).unwrap();
            let p = project_volume(&grid, &g, &ProjectOptions::default()).unwrap();
            let (w, peak) = worst(&p, &exact);
            let rel = mean_rel(&p, &exact);
            eprintln!("{name} n={n}: mean rel {rel:.4e}, worst {w:.3} of peak {peak:.1}");
            errs.push(rel);
        }
        // Point-sampling a piecewise-constant phantom misplaces its edges by up to
        // half a voxel, so the error is O(h). Measured mean relative error
        // (parallel / cone): n=32: 0.126 / 0.124, n=64: 0.055 / 0.052,
        // n=128: 0.025 / 0.025 (worst pixel 12.6 of a peak of 70.7 mm, on rays
        // tangent to the thin skull).
        assert!(
            errs[1] < 0.75 * errs[0] && errs[2] < 0.75 * errs[1],
            "{name}: {errs:?}"
        );
        assert!(errs[2] < 0.05, "{name}: {errs:?}");
    }
}

#[test]
fn f32_follows_f64() {
    let ph = Phantom::shepp_logan_modified();
    let g64 = Grid::<f64>::phantom(&ph, [48; 3]).unwrap();
    let g32 = Grid::<f32>::phantom(&ph, [48; 3]).unwrap();
    for (name, g) in [
        ("parallel", parallel(48, 6.0, 10)),
        ("cone", cone(48, 8.0, 10)),
    ] {
        let a = project_volume(&g64, &g, &ProjectOptions::default()).unwrap();
        let b = project_volume(&g32, &g, &ProjectOptions::default()).unwrap();
        let b = Projections::new(
            b.angles,
            b.rows,
            b.cols,
            b.data.iter().map(|&v| v as f64).collect(),
        )
        .unwrap();
        let (w, peak) = worst(&b, &a);
        eprintln!(
            "{name}: f32 worst {w:.3e} of peak {peak:.1} ({:.2e})",
            w / peak
        );
        // Measured: 4.2e-6 (parallel), 1.5e-5 (cone: the source is ~190 voxels away,
        // so f32 positions carry ~1e-5 voxel errors into a discontinuous field).
        assert!(w / peak < 5e-5, "{name}: {w} / {peak}");
    }
}

// ---------------------------------------------------------------------------------
// Peers: scikit-image's radon and RTK's Joseph projector (tests/data/ct/README.md)
// ---------------------------------------------------------------------------------

use common::ct_data as peer;

/// Max |a − b| / max |b| and the RMS difference / max |b| (`metrics::error_stats`,
/// `b` the reference; ∞ on a NaN/Inf mismatch).
fn rel_max_rms(a: &[f64], b: &[f64]) -> (f64, f64) {
    let e = voxlab::metrics::error_stats(b, a, f64::INFINITY).infinite_if_mismatched();
    (e.max_abs_rel, e.rmse / e.peak)
}

#[test]
fn rtk_joseph_projections_agree() {
    use voxlab::io::npy::read_npy_f64;
    // The volume in RTK's frame (= the CT frame): voxel i at (i − 15.5)·2 mm.
    let (shape, vol, _) = read_npy_f64(&peer("rtk_volume32.npy")).unwrap();
    assert_eq!(shape, vec![32, 32, 32]);
    let affine =
        DMat4::from_scale(DVec3::splat(2.0)) * DMat4::from_translation(DVec3::splat(-15.5));
    let grid = Grid::new([32; 3], affine, vol).unwrap();
    // The peer's geometry file (with its extra sections) is the RTK geometry.
    let g = voxlab::io::projections::read_geometry(&peer("rtk_geometry.json")).unwrap();
    assert_eq!(
        g,
        Geometry::cone_rtk(
            1000.0,
            1500.0,
            48,
            40,
            3.0,
            3.0,
            Geometry::even_angles(60, 360.0)
        )
        .unwrap()
    );
    let rtk = voxlab::io::projections::read_projections_for::<f64>(&peer("rtk_joseph32.npy"), &g)
        .unwrap();
    let ours = project_volume(&grid, &g, &ProjectOptions::default()).unwrap();
    let (max, rms) = rel_max_rms(&ours.data, &rtk.data);
    eprintln!("RTK Joseph: max rel {max:.3e}, rms rel {rms:.3e}");
    // The same method on the same grid: only RTK's float32 arithmetic and storage
    // differ. Measured: max 1.4e-7, RMS 1.3e-8 (of the peak).
    assert!(max < 1e-6 && rms < 1e-7, "{max} {rms}");
}

#[test]
fn skimage_radon_sinograms_agree() {
    use voxlab::io::npy::read_npy_f64;
    let theta = voxlab::io::projections::read_angles_txt(&peer("skimage_theta.txt")).unwrap();
    for n in [64usize, 63] {
        let (shape, img, _) = read_npy_f64(&peer(&format!("skimage_image{n}.npy"))).unwrap();
        assert_eq!(shape, vec![n, n]);
        // The image in the plane Y = 0: X = col − n//2, Z = row − n//2 (1 mm pixels);
        // grid axes (col, row, 1) → (X, Z, Y).
        let c = (n / 2) as f64;
        let affine = DMat4::from_cols(
            glam::DVec4::new(1.0, 0.0, 0.0, 0.0),
            glam::DVec4::new(0.0, 0.0, 1.0, 0.0),
            glam::DVec4::new(0.0, 1.0, 0.0, 0.0),
            glam::DVec4::new(-c, 0.0, -c, 1.0),
        );
        let grid = Grid::new([n, n, 1], affine, img).unwrap();
        let g = Geometry::parallel_skimage(n, theta.clone()).unwrap();
        let radon = voxlab::io::projections::read_projections_for::<f64>(
            &peer(&format!("skimage_radon{n}.npy")),
            &g,
        )
        .unwrap();
        let ours = project_volume(&grid, &g, &ProjectOptions::default()).unwrap();
        let (max, rms) = rel_max_rms(&ours.data, &radon.data);
        eprintln!("skimage radon {n}: max rel {max:.3e}, rms rel {rms:.3e}");
        // Not the same discretisation: radon rotates the image (bilinear warp onto the
        // pixel grid) and sums its columns — samples 1 pixel apart along the ray,
        // interpolated in 2-D — while Joseph samples once per plane, 1/|cos| apart,
        // interpolated in 1-D. Both converge to the line integral; they differ by
        // O(h) at edges. Measured (n = 64 / 63): max 3.4e-2 / 3.8e-2, RMS 3.2e-3 /
        // 3.5e-3 of the peak.
        assert!(max < 0.08 && rms < 0.008, "{n}: {max} {rms}");
    }
}
