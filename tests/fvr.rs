//! Fourier volume rendering against truth: axis views equal array sums (nearest and
//! Dirichlet slices lie on grid frequencies), the exact Dirichlet slice equals the
//! DFT-exact projection of the padded grid for oblique views, and the Shepp–Logan
//! phantom's projections against its analytic line integrals and the ray caster.

mod common;

use common::{s, scratch, stderr, voxlab, Rng};
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::PI;
use voxlab::camera::AxisView;
use voxlab::cpu::fvr::{fvr_project, FvrGeometry, FvrSpectrum, FvrView, Kernel};
use voxlab::cpu::raycast::render;
use voxlab::phantom::Phantom;
use voxlab::settings::{Filter, Mode, RenderSettings};
use voxlab::transfer::TransferFunction;
use voxlab::{AnyVolume, Volume};

const AXES: [AxisView; 6] = [
    AxisView::PlusX,
    AxisView::MinusX,
    AxisView::PlusY,
    AxisView::MinusY,
    AxisView::PlusZ,
    AxisView::MinusZ,
];

const KERNELS: [Kernel; 5] = [
    Kernel::Nearest,
    Kernel::Trilinear,
    Kernel::Lanczos2,
    Kernel::Lanczos3,
    Kernel::Lanczos4,
];

/// A random volume with isotropic voxels of `spacing` mm.
fn random_volume(dims: [usize; 3], spacing: f64, seed: u64) -> Volume<f32> {
    let mut rng = Rng(seed);
    let n = dims.iter().product();
    let data = (0..n).map(|_| rng.unit() as f32 - 0.3).collect();
    Volume::new(dims, [spacing; 3], data).unwrap()
}

/// `vol.sum(axis) × spacing`, laid out as the axis view's image.
fn axis_sum(v: &Volume<f32>, view: AxisView, spacing: f64) -> Vec<f64> {
    let d = v.dims();
    let (a, _) = view.axis();
    let (ca, ra) = view.image_axes();
    let mut out = vec![0.0; d[ca] * d[ra]];
    for row in 0..d[ra] {
        for col in 0..d[ca] {
            let mut acc = 0.0;
            for t in 0..d[a] {
                let mut idx = [0usize; 3];
                idx[a] = t;
                idx[ca] = col;
                idx[ra] = row;
                acc += *v.get(idx[0], idx[1], idx[2]) as f64;
            }
            out[row * d[ca] + col] = acc * spacing;
        }
    }
    out
}

/// Largest |a − b| relative to the largest |b| (`metrics::error_stats`, `b` the
/// reference; ∞ on a NaN/Inf mismatch).
fn max_rel(a: &[f64], b: &[f64]) -> f64 {
    voxlab::metrics::error_stats(b, a, f64::INFINITY)
        .infinite_if_mismatched()
        .max_abs_rel
}

/// Root-mean-square error relative to the root-mean-square of `b`: the relative L2
/// error ‖a − b‖ / ‖b‖ (`metrics::error_stats`; ∞ on a NaN/Inf mismatch).
fn rel_rmse(a: &[f64], b: &[f64]) -> f64 {
    voxlab::metrics::error_stats(b, a, f64::INFINITY)
        .infinite_if_mismatched()
        .rel_l2
}

#[test]
fn axis_views_with_nearest_and_dirichlet_equal_the_sum_along_the_axis() {
    // Odd and even sides, so that the volume centre sits on and between grid points.
    let v = random_volume([7, 6, 5], 0.7, 1);
    for padding in [1, 2, 3] {
        let spec = FvrSpectrum::new(&v, padding).unwrap();
        for view in AXES {
            let want = axis_sum(&v, view, 0.7);
            for kernel in [Kernel::Nearest, Kernel::Dirichlet] {
                let img = fvr_project(&spec, FvrView::Axis(view), kernel, false).unwrap();
                let (ca, ra) = view.image_axes();
                assert_eq!((img.width, img.height), (v.dims()[ca], v.dims()[ra]));
                let e = max_rel(&img.data, &want);
                assert!(e < 1e-9, "{view:?} {kernel:?} padding {padding}: {e:e}");
            }
            // Every interpolating kernel is exact on grid frequencies too.
            for kernel in [Kernel::Trilinear, Kernel::Lanczos3] {
                let img = fvr_project(&spec, FvrView::Axis(view), kernel, false).unwrap();
                let e = max_rel(&img.data, &want);
                assert!(e < 1e-9, "{view:?} {kernel:?} padding {padding}: {e:e}");
            }
        }
    }
}

/// The axis views have the ray caster's layout: its X-ray at step 1 (which samples
/// voxel centres) is the same image.
#[test]
fn axis_views_equal_the_ray_casters_xray_pixel_by_pixel() {
    use voxlab::camera::Camera;
    let v = random_volume([9, 8, 6], 0.8, 5);
    let spec = FvrSpectrum::new(&v, 2).unwrap();
    let settings = RenderSettings {
        mode: Mode::Xray,
        filter: Filter::Trilinear,
        step: 1.0,
        ..RenderSettings::default()
    };
    let tf = TransferFunction::preset("grayscale").unwrap();
    let vol: AnyVolume = v.clone().into();
    for view in AXES {
        let img = fvr_project(&spec, FvrView::Axis(view), Kernel::Lanczos3, false).unwrap();
        let cam = Camera::axis_view(v.dims(), v.affine(), view, img.width, img.height).unwrap();
        let rc = render::<f64>(&vol, &tf, &cam, &settings, &|_, _| {}).unwrap();
        let e = max_rel(&img.data, &rc.image.data);
        assert!(e < 1e-9, "{view:?}: {e:e}");
    }
}

/// The projection the Dirichlet slice must give: each voxel splatted onto the image
/// plane with the periodic Dirichlet kernel `D(t) = (1/M) Σ_{k=−M/2}^{M/2−1} e^{−2πikt/M}`
/// in both image axes, `P(x, y) = Σ_n f(n) D(x_n − x) D(y_n − y)`.
fn dirichlet_projection(v: &Volume<f32>, g: &FvrGeometry, m: usize, spacing: f64) -> Vec<f64> {
    let d = |t: f64| -> (f64, f64) {
        let (mut re, mut im) = (0.0, 0.0);
        for k in -(m as i64 / 2)..(m as i64 / 2) {
            let a = -2.0 * PI * k as f64 * t / m as f64;
            re += a.cos();
            im += a.sin();
        }
        (re / m as f64, im / m as f64)
    };
    let dims = v.dims();
    let mut out = vec![0.0; g.width * g.height];
    for row in 0..g.height {
        for col in 0..g.width {
            let p = g.pixel_point(col, row);
            let mut acc = 0.0;
            for k in 0..dims[2] {
                for j in 0..dims[1] {
                    for i in 0..dims[0] {
                        let r = DVec3::new(i as f64, j as f64, k as f64) - p;
                        let (ar, ai) = d(r.dot(g.right));
                        let (br, bi) = d(r.dot(g.up));
                        acc += *v.get(i, j, k) as f64 * (ar * br - ai * bi);
                    }
                }
            }
            out[row * g.width + col] = acc * spacing;
        }
    }
    out
}

#[test]
fn an_oblique_dirichlet_slice_is_the_dft_exact_projection() {
    let v = random_volume([6, 6, 6], 1.5, 7);
    let view = FvrView::Basis {
        forward: DVec3::new(0.3, -0.5, 0.81),
        right: DVec3::new(1.0, 0.2, 0.0),
        up: DVec3::Z,
    };
    for padding in [1, 2] {
        let spec = FvrSpectrum::new(&v, padding).unwrap();
        let g = spec.geometry(view).unwrap();
        let img = fvr_project(&spec, view, Kernel::Dirichlet, false).unwrap();
        let want = dirichlet_projection(&v, &g, spec.side(), 1.5);
        let e = max_rel(&img.data, &want);
        eprintln!("Dirichlet oblique, padding {padding}: max rel error {e:.2e}");
        assert!(e < 1e-10, "padding {padding}: {e:e}");
        // The interpolating kernels approach it as they widen.
        let errs: Vec<f64> = KERNELS
            .iter()
            .map(|&k| rel_rmse(&fvr_project(&spec, view, k, false).unwrap().data, &want))
            .collect();
        eprintln!("  vs nearest … lanczos4: {errs:?}");
        assert!(errs[3] < errs[1], "Lanczos-3 must beat trilinear: {errs:?}");
    }
}

/// The CPU f32 path (spectrum rounded to complex f32, slice and inverse FFT in f32)
/// against the f64 oracle, for every kernel on an axis and an oblique view: the GPU
/// port's bound (`bench::fourier::fvr_gpu_tol`, 5e-6 max and rel L2 at these sizes)
/// holds it. Measured (max rel / rel L2, worst over kernels and views): M = 32
/// 1.5e-7 / 8.5e-8; M = 64 1.4e-7 / 8.2e-8.
#[test]
fn the_f32_path_matches_the_oracle_within_the_gpu_bound() {
    let v = Phantom::shepp_logan_modified().sample([16; 3]).unwrap();
    let v2 = Phantom::shepp_logan_modified().sample([32; 3]).unwrap();
    for (vol, padding) in [(&v, 2), (&v2, 2)] {
        let spec = FvrSpectrum::new(vol, padding).unwrap();
        let spec32 = spec.to_f32();
        let tol = voxlab::bench::fourier::fvr_gpu_tol(spec.side());
        let mut worst = (0.0f64, 0.0f64);
        for view in [FvrView::Axis(AxisView::PlusY), oblique()] {
            for k in [
                Kernel::Nearest,
                Kernel::Trilinear,
                Kernel::Lanczos2,
                Kernel::Lanczos3,
                Kernel::Lanczos4,
                Kernel::Dirichlet,
            ] {
                let want = fvr_project(&spec, view, k, true).unwrap().data;
                let got = fvr_project(&spec32, view, k, true).unwrap().data;
                let (mr, l2) = (max_rel(&got, &want), rel_rmse(&got, &want));
                worst = (worst.0.max(mr), worst.1.max(l2));
                assert!(
                    mr < tol.max_abs_rel && l2 < tol.rel_l2,
                    "M = {} {k:?} {view:?}: max rel {mr:.2e}, rel L2 {l2:.2e}",
                    spec.side()
                );
            }
        }
        eprintln!(
            "M = {}: f32 vs f64 worst max rel {:.2e}, rel L2 {:.2e}",
            spec.side(),
            worst.0,
            worst.1
        );
    }
}

#[test]
fn a_large_dirichlet_slice_is_refused() {
    let v = random_volume([64, 64, 64], 1.0, 3);
    let spec = FvrSpectrum::new(&v, 2).unwrap();
    let e = fvr_project(
        &spec,
        FvrView::Axis(AxisView::PlusZ),
        Kernel::Dirichlet,
        false,
    )
    .unwrap_err();
    assert!(e.to_string().contains("small volumes"), "{e}");
}

/// The analytic X-ray of `phantom` through every pixel centre of `g`.
fn analytic(phantom: &Phantom, g: &FvrGeometry) -> Vec<f64> {
    (0..g.width * g.height)
        .map(|i| {
            let (o, d) = g.pixel_ray_world(i % g.width, i / g.width);
            phantom.line_integral_world(o, d, f64::NEG_INFINITY, f64::INFINITY)
        })
        .collect()
}

/// The CPU ray caster's X-ray (trilinear, f64) through the same pixels.
fn raycast(v: &Volume<f32>, g: &FvrGeometry, step: f64) -> Vec<f64> {
    let settings = RenderSettings {
        mode: Mode::Xray,
        filter: Filter::Trilinear,
        step,
        ..RenderSettings::default()
    };
    let tf = TransferFunction::preset("grayscale").unwrap();
    let vol: AnyVolume = v.clone().into();
    render::<f64>(&vol, &tf, &g.camera().unwrap(), &settings, &|_, _| {})
        .unwrap()
        .image
        .data
}

fn oblique() -> FvrView {
    FvrView::Orbit {
        azimuth_deg: 30.0,
        elevation_deg: 20.0,
    }
}

#[test]
fn shepp_logan_64_error_per_kernel_and_padding() {
    let phantom = Phantom::shepp_logan();
    let v = phantom.sample([64; 3]).unwrap();
    eprintln!("Shepp–Logan 64³, relative RMSE against the analytic projection");
    for (name, view) in [
        ("+y", FvrView::Axis(AxisView::PlusY)),
        ("oblique", oblique()),
    ] {
        let mut by_padding = Vec::new();
        for padding in [1, 2] {
            let spec = FvrSpectrum::new(&v, padding).unwrap();
            let g = spec.geometry(view).unwrap();
            let truth = analytic(&phantom, &g);
            let rc = raycast(&v, &g, 0.1);
            eprintln!(
                "  {name:8} padding {padding} ray caster (trilinear, step 0.1) {:.4}",
                rel_rmse(&rc, &truth)
            );
            let mut errs = Vec::new();
            for k in KERNELS {
                let e = rel_rmse(&fvr_project(&spec, view, k, false).unwrap().data, &truth);
                let ed = rel_rmse(&fvr_project(&spec, view, k, true).unwrap().data, &truth);
                eprintln!(
                    "  {name:8} padding {padding} {:10} {:.4} (deapodized {:.4})",
                    k.name(),
                    e,
                    ed
                );
                errs.push(e);
            }
            if name == "oblique" {
                assert!(errs[3] < errs[0] && errs[3] < errs[1], "{errs:?}");
            }
            by_padding.push(errs);
        }
        if name == "oblique" {
            // Padding removes most of the trilinear slice's ghosting.
            assert!(by_padding[1][1] < by_padding[0][1], "{by_padding:?}");
        }
    }
}

/// The target "Lanczos-3 with ×2 padding within 1 % relative RMSE of the analytic
/// projection at 128³" is not reachable on the sampled Shepp–Logan phantom: its skull is
/// thinner than a voxel, and the point-sampled volume's own projection (the ray
/// caster's X-ray at step 0.1, or the exact sum along an axis) is already 5.4 % (axis)
/// and 8.3 % (oblique) away from the analytic one. What is asserted instead: Lanczos-3
/// reaches that floor within 10 %, and beats nearest and trilinear slices. (The 1 %
/// target itself is met on a smooth volume: see the Gaussian blob test.)
#[test]
fn shepp_logan_128_lanczos3_reaches_the_sampled_volumes_floor() {
    let phantom = Phantom::shepp_logan();
    let v = phantom.sample([128; 3]).unwrap();
    let spec = FvrSpectrum::new(&v, 2).unwrap();
    for (name, view) in [
        ("+y", FvrView::Axis(AxisView::PlusY)),
        ("oblique", oblique()),
    ] {
        let g = spec.geometry(view).unwrap();
        let truth = analytic(&phantom, &g);
        let floor = rel_rmse(&raycast(&v, &g, 0.1), &truth);
        let mut errs = Vec::new();
        for k in [Kernel::Nearest, Kernel::Trilinear, Kernel::Lanczos3] {
            let img = fvr_project(&spec, view, k, false).unwrap();
            errs.push(rel_rmse(&img.data, &truth));
        }
        let l3 = fvr_project(&spec, view, Kernel::Lanczos3, false).unwrap();
        let vs_ray = rel_rmse(&l3.data, &raycast(&v, &g, 0.1));
        eprintln!(
            "Shepp–Logan 128³ {name}, padding 2: nearest {:.4}, trilinear {:.4}, \
             lanczos3 {:.4}; ray caster (step 0.1) {floor:.4}; lanczos3 vs ray caster {vs_ray:.4}",
            errs[0], errs[1], errs[2]
        );
        if name == "oblique" {
            assert!(errs[2] < errs[0] && errs[2] < errs[1], "{errs:?}");
        }
        assert!(
            errs[2] <= 1.1 * floor,
            "{name}: Lanczos-3 {:.4} is not within 10 % of the floor {floor:.4}",
            errs[2]
        );
        eprintln!(
            "  the 1 % target against the analytic projection: {} ({:.2} %)",
            if errs[2] < 0.01 { "met" } else { "not met" },
            100.0 * errs[2]
        );
    }
}

#[test]
fn cli_writes_an_fvr_image_on_each_cpu_backend_and_auto_and_refuses_others() {
    let dir = scratch("cli");
    let out = dir.join("p.npy");
    let o = voxlab(&[
        "fvr",
        "phantom:shepp-logan:24",
        "--view",
        "+z",
        "--kernel",
        "nearest",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let bytes = std::fs::read(&out).unwrap();
    assert!(bytes.starts_with(b"\x93NUMPY"));
    // The values are the phantom's sum along z × spacing.
    let phantom = Phantom::shepp_logan();
    let v = phantom.sample([24; 3]).unwrap();
    let want = axis_sum(&v, AxisView::PlusZ, v.spacing()[0]);
    let got: Vec<f64> = bytes[bytes.len() - 4 * want.len()..]
        .chunks(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()) as f64)
        .collect();
    assert!(max_rel(&got, &want) < 1e-5);
    let png = dir.join("p.png");
    let o = voxlab(&[
        "fvr",
        "phantom:sphere:16",
        "--azimuth",
        "40",
        "--elevation",
        "10",
        "--out",
        s(&png),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(png.is_file());
    // auto is every family's backend: a hardware GPU, else the CPU oracle.
    std::fs::remove_file(&png).unwrap();
    let o = voxlab(&[
        "fvr",
        "phantom:sphere:16",
        "--backend",
        "auto",
        "--out",
        s(&png),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(png.is_file());
    let o = voxlab(&[
        "fvr",
        "phantom:sphere:16",
        "--backend",
        "tpu",
        "--out",
        s(&dir.join("q.png")),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("invalid value 'tpu' for '--backend")
            && stderr(&o).contains("cpu, cpu-f32, gpu, auto"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.join("q.png").exists());
    // The f32 path writes the same axis sum within f32 rounding.
    let o = voxlab(&[
        "fvr",
        "phantom:shepp-logan:24",
        "--view",
        "+z",
        "--kernel",
        "nearest",
        "--backend",
        "cpu-f32",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let bytes = std::fs::read(&out).unwrap();
    let got: Vec<f64> = bytes[bytes.len() - 4 * want.len()..]
        .chunks(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()) as f64)
        .collect();
    assert!(max_rel(&got, &want) < 1e-5);
    // The padded cube counts against the voxel limit, before anything is allocated.
    let o = voxlab(&[
        "--max-voxels",
        "100000",
        "fvr",
        "phantom:sphere:40",
        "--out",
        s(&png),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("80³ voxels exceed"), "{}", stderr(&o));
}

/// A smooth, nearly band-limited volume: a Gaussian blob whose X-ray is known in closed
/// form, `√(2π)·σ·exp(−d²/2σ²)` at distance `d` from its centre. Here the 1 % target of
/// Lanczos-3 with ×2 padding is met against the analytic projection.
#[test]
fn gaussian_blob_lanczos3_within_one_percent_of_its_analytic_projection() {
    let (sigma, spacing) = (3.0, 0.5);
    let c = DVec3::new(27.3, 36.1, 30.2);
    let v = Volume::from_fn([64; 3], [spacing; 3], |i, j, k| {
        let p = DVec3::new(i as f64, j as f64, k as f64) - c;
        (-p.length_squared() / (2.0 * sigma * sigma)).exp() as f32
    })
    .unwrap();
    let view = oblique();
    for padding in [1, 2] {
        let spec = FvrSpectrum::new(&v, padding).unwrap();
        let g = spec.geometry(view).unwrap();
        let truth: Vec<f64> = (0..g.width * g.height)
            .map(|i| {
                let p = g.pixel_point(i % g.width, i / g.width) - c;
                let d2 = (p - g.forward * p.dot(g.forward)).length_squared();
                (2.0 * PI).sqrt() * sigma * (-d2 / (2.0 * sigma * sigma)).exp() * spacing
            })
            .collect();
        let errs: Vec<f64> = KERNELS
            .iter()
            .map(|&k| rel_rmse(&fvr_project(&spec, view, k, false).unwrap().data, &truth))
            .collect();
        eprintln!(
            "Gaussian blob 64³, padding {padding}: nearest {:.5} trilinear {:.5} lanczos2 \
             {:.5} lanczos3 {:.5} lanczos4 {:.5}",
            errs[0], errs[1], errs[2], errs[3], errs[4]
        );
        assert!(errs[3] < errs[1] && errs[1] < errs[0], "{errs:?}");
        let l3 = fvr_project(&spec, view, Kernel::Lanczos3, false).unwrap();
        let rc = raycast(&v, &g, 0.1);
        eprintln!(
            "  ray caster (step 0.1) vs truth {:.5}; Lanczos-3 vs ray caster {:.5}",
            rel_rmse(&rc, &truth),
            rel_rmse(&l3.data, &rc)
        );
        if padding == 2 {
            assert!(errs[3] < 0.01, "Lanczos-3, padding 2: {:.4}", errs[3]);
        }
    }
}

/// Writes the error figures of `docs/fvr.md` and prints its 128³ table
/// (`cargo test --release --test fvr docs_figures -- --ignored --nocapture`).
#[test]
#[ignore = "writes docs/images; run by hand"]
fn docs_figures() {
    use voxlab::frame::Frame;
    use voxlab::io::{write_frame, PngOptions};
    let phantom = Phantom::shepp_logan();
    let v = phantom.sample([128; 3]).unwrap();
    let dir = common::root().join("docs/images");
    for (name, view) in [
        ("+y", FvrView::Axis(AxisView::PlusY)),
        ("oblique", oblique()),
    ] {
        for padding in [1, 2] {
            let spec = FvrSpectrum::new(&v, padding).unwrap();
            let g = spec.geometry(view).unwrap();
            let truth = analytic(&phantom, &g);
            let errs: Vec<String> = KERNELS
                .iter()
                .map(|&k| {
                    let e = rel_rmse(&fvr_project(&spec, view, k, false).unwrap().data, &truth);
                    format!("{} {e:.4}", k.name())
                })
                .collect();
            eprintln!("128³ {name} padding {padding}: {}", errs.join(", "));
            if name != "oblique" {
                continue;
            }
            let k = if padding == 1 {
                Kernel::Trilinear
            } else {
                Kernel::Lanczos3
            };
            {
                let img = fvr_project(&spec, view, k, false).unwrap();
                let mut err = Frame::new(g.width, g.height, 1);
                for (e, (a, b)) in err.data.iter_mut().zip(img.data.iter().zip(&truth)) {
                    *e = (a - b).abs();
                }
                let png = PngOptions {
                    sixteen_bit: false,
                    range: Some((0.0, 20.0)),
                };
                let file = format!("fvr-oblique-{}-pad{padding}-error.png", k.name());
                write_frame(&dir.join(&file), &err, png).unwrap();
                let png = PngOptions {
                    sixteen_bit: false,
                    range: Some((0.0, truth.iter().cloned().fold(0.0, f64::max))),
                };
                let file = format!("fvr-oblique-{}-pad{padding}.png", k.name());
                write_frame(&dir.join(&file), &img, png).unwrap();
            }
        }
    }
    // The cell-averaged phantom against the pixel-averaged truth, same scale.
    let v = phantom.sample_cell_average([128; 3], 8).unwrap();
    let spec = FvrSpectrum::new(&v, 2).unwrap();
    let g = spec.geometry(oblique()).unwrap();
    let truth = analytic_pixel_average(&phantom, &g, 16);
    let img = fvr_project(&spec, oblique(), Kernel::Lanczos3, false).unwrap();
    let mut err = Frame::new(g.width, g.height, 1);
    for (e, (a, b)) in err.data.iter_mut().zip(img.data.iter().zip(&truth)) {
        *e = (a - b).abs();
    }
    let png = PngOptions {
        sixteen_bit: false,
        range: Some((0.0, 20.0)),
    };
    write_frame(
        &dir.join("fvr-oblique-lanczos3-pad2-cell-error.png"),
        &err,
        png,
    )
    .unwrap();
    eprintln!(
        "cell-averaged, Lanczos-3, padding 2, oblique: {:.4} against the pixel-averaged truth",
        rel_rmse(&img.data, &truth)
    );
}

/// The analytic X-ray of `phantom` averaged over each pixel's `s × s` footprint in the
/// image plane (`order²` Gauss–Legendre rays per pixel): what a detector with square
/// pixels of the voxel size measures.
fn analytic_pixel_average(phantom: &Phantom, g: &FvrGeometry, order: usize) -> Vec<f64> {
    let (x, w) = voxlab::phantom::gauss_legendre_rule(order);
    let rule: Vec<(f64, f64)> = x
        .iter()
        .zip(&w)
        .map(|(&x, &w)| (0.5 * x, 0.5 * w))
        .collect();
    let d = g.affine.transform_vector3(g.forward).normalize();
    (0..g.width * g.height)
        .into_par_iter()
        .map(|i| {
            let p = g.pixel_point(i % g.width, i / g.width);
            let mut acc = 0.0;
            for &(b, wb) in &rule {
                for &(a, wa) in &rule {
                    let o = g.affine.transform_point3(p + g.right * a + g.up * b);
                    acc += wa
                        * wb
                        * phantom.line_integral_world(o, d, f64::NEG_INFINITY, f64::INFINITY);
                }
            }
            acc
        })
        .collect()
}

/// The analytic X-ray of the cell-averaged phantom `f * box` (box = one voxel cube):
/// the analytic X-ray averaged over the cube's shadow on the image plane
/// (`order³` Gauss–Legendre rays per pixel). For an axis view the shadow is the
/// pixel's square and this equals [`analytic_pixel_average`].
fn analytic_voxel_shadow(phantom: &Phantom, g: &FvrGeometry, order: usize) -> Vec<f64> {
    let (x, w) = voxlab::phantom::gauss_legendre_rule(order);
    let rule: Vec<(f64, f64)> = x
        .iter()
        .zip(&w)
        .map(|(&x, &w)| (0.5 * x, 0.5 * w))
        .collect();
    let d = g.affine.transform_vector3(g.forward).normalize();
    (0..g.width * g.height)
        .into_par_iter()
        .map(|i| {
            let p = g.pixel_point(i % g.width, i / g.width);
            let mut acc = 0.0;
            for &(c, wc) in &rule {
                for &(b, wb) in &rule {
                    for &(a, wa) in &rule {
                        let o = g.affine.transform_point3(p + DVec3::new(a, b, c));
                        acc += wa
                            * wb
                            * wc
                            * phantom.line_integral_world(o, d, f64::NEG_INFINITY, f64::INFINITY);
                    }
                }
            }
            acc
        })
        .collect()
}

#[test]
#[ignore = "prints the accuracy table of docs/fvr.md; run by hand"]
fn shepp_logan_accuracy_table() {
    let n: usize = std::env::var("FVR_N")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(128);
    for phantom in [Phantom::shepp_logan(), Phantom::shepp_logan_modified()] {
        let t = std::time::Instant::now();
        let point = phantom.sample([n; 3]).unwrap();
        let cell = phantom.sample_cell_average([n; 3], 8).unwrap();
        let cell16 = phantom.sample_cell_average([n; 3], 16).unwrap();
        let dd: f64 = cell
            .data()
            .iter()
            .zip(cell16.data())
            .map(|(a, b)| ((a - b) as f64).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "{} {n}³: voxelised in {:.1} s; cell order 8 vs 16 max diff {dd:.2e}",
            phantom.name,
            t.elapsed().as_secs_f64()
        );
        for (vname, view) in [
            ("+y", FvrView::Axis(AxisView::PlusY)),
            ("oblique", oblique()),
        ] {
            let g0 = FvrSpectrum::new(&random_volume([n; 3], 1.0, 1), 1)
                .unwrap()
                .geometry(view)
                .unwrap();
            let _ = g0;
            let mut truths = None;
            for (volname, v) in [("point", &point), ("cell", &cell)] {
                for padding in [1, 2] {
                    let spec = FvrSpectrum::new(v, padding).unwrap();
                    let g = spec.geometry(view).unwrap();
                    if truths.is_none() {
                        let t = std::time::Instant::now();
                        let tc = analytic(&phantom, &g);
                        let tp = analytic_pixel_average(&phantom, &g, 8);
                        let ts = analytic_voxel_shadow(&phantom, &g, 6);
                        let tp16 = analytic_pixel_average(&phantom, &g, 16);
                        eprintln!("  truths in {:.1} s; pixel avg 8 vs 16: {:.2e}; centre vs pixel avg {:.4}; pixel avg vs shadow {:.4}",
                            t.elapsed().as_secs_f64(), rel_rmse(&tp, &tp16), rel_rmse(&tc, &tp16), rel_rmse(&ts, &tp16));
                        truths = Some((tc, tp16, ts));
                    }
                    let (tc, tp, ts) = truths.as_ref().unwrap();
                    let rc = raycast(v, &g, 0.1);
                    eprintln!(
                        "  {vname:7} {volname:5} pad {padding} raycaster      centre {:.4} pixel {:.4} shadow {:.4}",
                        rel_rmse(&rc, tc), rel_rmse(&rc, tp), rel_rmse(&rc, ts)
                    );
                    for k in KERNELS {
                        let img = fvr_project(&spec, view, k, false).unwrap();
                        eprintln!(
                            "  {vname:7} {volname:5} pad {padding} {:14} centre {:.4} pixel {:.4} shadow {:.4}",
                            k.name(), rel_rmse(&img.data, tc), rel_rmse(&img.data, tp), rel_rmse(&img.data, ts)
                        );
                    }
                }
            }
        }
    }
}

/// The 1 % target, stated precisely. The volume is the Shepp–Logan phantom *cell-averaged*
/// at 128³ (`Phantom::sample_cell_average`: each voxel the mean of the phantom over its
/// cell), and the truth is the analytic line integral *averaged over each detector
/// pixel's s × s footprint* (16² Gauss–Legendre rays per pixel): for an axis view the
/// sum of the cell averages is exactly that average, so it is the projection a sampled
/// volume can be held to. Lanczos-3, ×2 padding:
/// - `+y`: measured 0.00030 (1 % met); bound 0.001;
/// - oblique (azimuth 30°, elevation 20°): measured 0.0248 (1 % not met: the cell
///   averages are not band-limited, and an oblique slice interpolates their aliased
///   spectrum); bound 0.03.
///
/// Against the pixel-centre truth the same images measure 0.0529 and 0.0596: a pixel
/// average and a pixel-centre value differ by 4.9–5.3 % RMS on this phantom's
/// sub-voxel skull (printed below), whatever renders the volume.
#[test]
fn shepp_logan_128_cell_averaged_lanczos3_against_the_pixel_averaged_projection() {
    let phantom = Phantom::shepp_logan();
    let v = phantom.sample_cell_average([128; 3], 8).unwrap();
    let spec = FvrSpectrum::new(&v, 2).unwrap();
    for (name, view, bound) in [
        ("+y", FvrView::Axis(AxisView::PlusY), 0.001),
        ("oblique", oblique(), 0.03),
    ] {
        let g = spec.geometry(view).unwrap();
        let centre = analytic(&phantom, &g);
        let pixel = analytic_pixel_average(&phantom, &g, 16);
        let img = fvr_project(&spec, view, Kernel::Lanczos3, false).unwrap();
        let (ep, ec) = (rel_rmse(&img.data, &pixel), rel_rmse(&img.data, &centre));
        eprintln!(
            "cell-averaged Shepp–Logan 128³ {name}, Lanczos-3, padding 2: vs pixel-averaged \
             {ep:.4}, vs pixel-centre {ec:.4} (centre vs averaged truth {:.4})",
            rel_rmse(&centre, &pixel)
        );
        assert!(ep < bound, "{name}: {ep:.4} ≥ {bound}");
    }
}

/// One number of `docs/fvr.md`'s scaling remarks: the cell-averaged Shepp–Logan at
/// `FVR_N`³ (default 128), oblique, Lanczos-3, with padding `FVR_PADDING` (default 2),
/// against the pixel-averaged and pixel-centre truths.
#[test]
#[ignore = "a by-hand measurement for docs/fvr.md"]
fn shepp_logan_cell_averaged_oblique_one_point() {
    let env = |k: &str, d: usize| {
        std::env::var(k)
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(d)
    };
    let (n, padding) = (env("FVR_N", 128), env("FVR_PADDING", 2));
    let phantom = Phantom::shepp_logan();
    let t = std::time::Instant::now();
    let v = phantom.sample_cell_average([n; 3], 8).unwrap();
    let spec = FvrSpectrum::new(&v, padding).unwrap();
    let g = spec.geometry(oblique()).unwrap();
    let pixel = analytic_pixel_average(&phantom, &g, 16);
    let centre = analytic(&phantom, &g);
    for k in [Kernel::Lanczos3, Kernel::Lanczos4] {
        let img = fvr_project(&spec, oblique(), k, false).unwrap();
        eprintln!(
            "{n}³ padding {padding} {}: vs pixel-averaged {:.4}, vs pixel-centre {:.4} ({:.0} s)",
            k.name(),
            rel_rmse(&img.data, &pixel),
            rel_rmse(&img.data, &centre),
            t.elapsed().as_secs_f64()
        );
    }
}
