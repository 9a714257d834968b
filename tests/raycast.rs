//! The CPU ray caster against analytic truth: exact chord integrals of ellipsoids,
//! array reductions along axis views, Beer–Lambert through a slab, MIP/MinIP of
//! spheres; then f32 against f64 and thread-count independence.

use glam::{DMat4, DVec3};
use voxlab::camera::{AxisView, Camera, Orbit, Projection};
use voxlab::cpu::raycast::{render, render_field, PhantomField};
use voxlab::phantom::{Phantom, Primitive};
use voxlab::settings::{Classification, Compositing, Filter, GradientMethod, Mode, RenderSettings};
use voxlab::transfer::{ControlPoint, TransferFunction, WindowMap};
use voxlab::{AnyVolume, Volume};

fn no_progress() -> &'static (dyn Fn(usize, usize) + Sync) {
    &|_, _| {}
}

fn gray_tf() -> TransferFunction {
    TransferFunction::preset("grayscale").unwrap()
}

fn settings(mode: Mode, filter: Filter, step: f64) -> RenderSettings {
    RenderSettings {
        mode,
        filter,
        step,
        ..RenderSettings::default()
    }
}

/// X-ray images of an analytic phantom (no grid, no filter: exact point values) from
/// a perspective camera, per pixel against the exact chord integrals. The midpoint rule
/// errs only in the steps that contain a boundary, by at most density × step length
/// each, so the error is bounded by Σ|density| × 2 × (step in mm) and halves with the
/// step.
#[test]
fn xray_of_ellipsoids_converges_to_the_exact_line_integrals() {
    for name in ["ellipsoid", "shepp-logan-modified"] {
        let phantom = Phantom::by_name(name).unwrap();
        let dims = [64; 3];
        let affine = phantom.grid_affine(dims);
        let spacing = 2.0 * phantom.half_extent_mm / 64.0;
        let field = PhantomField {
            phantom: &phantom,
            dims,
            method: GradientMethod::Central,
        };
        let cam = Camera::orbit(
            DVec3::ZERO,
            [256.0; 3],
            Orbit {
                azimuth_deg: 37.0,
                elevation_deg: 23.0,
                distance_mm: None,
            },
            Projection::Perspective { fov_y_deg: 30.0 },
            40,
            40,
        )
        .unwrap();
        let exact: Vec<f64> = (0..40 * 40)
            .map(|i| {
                let r = cam.ray(i % 40, i / 40);
                phantom.line_integral_world(r.origin, r.dir, 0.0, f64::INFINITY)
            })
            .collect();
        let peak = exact.iter().cloned().fold(0.0, f64::max);
        eprintln!("{name}: largest exact line integral {peak:.3} value·mm");
        assert!(peak > 50.0, "rays must cross the phantom");
        let abs_density: f64 = match &phantom.kind {
            voxlab::phantom::PhantomKind::Primitives(p) => p.iter().map(|q| q.density.abs()).sum(),
            _ => unreachable!(),
        };
        let mut last_rms = f64::INFINITY;
        for step in [2.0, 1.0, 0.5, 0.25] {
            let out = render_field::<f64, _>(
                &field,
                affine,
                &gray_tf(),
                &cam,
                &settings(Mode::Xray, Filter::Trilinear, step),
                no_progress(),
            )
            .unwrap();
            let e = voxlab::metrics::error_stats(&exact, &out.image.data, f64::INFINITY)
                .infinite_if_mismatched();
            let (rms, max) = (e.rmse, e.max_abs);
            let bound = abs_density * 2.0 * step * spacing * 1.000001;
            eprintln!("{name} step {step}: rms {rms:.4} max {max:.4} (bound {bound:.4}) value·mm");
            assert!(
                max <= bound,
                "{name} step {step}: max error {max} above the bound {bound}"
            );
            assert!(
                rms < 0.75 * last_rms,
                "{name}: error must shrink with the step"
            );
            last_rms = rms;
        }
    }
}

/// A small volume with distinct values, anisotropic spacing and an offset origin.
fn test_volume() -> Volume<f32> {
    let dims = [7, 5, 6];
    let mut v = Volume::from_fn(dims, [1.0; 3], |i, j, k| {
        (((i * 31 + j * 17 + k * 7) % 23) as f32 - 9.0) * 0.37
    })
    .unwrap();
    let affine = DMat4::from_translation(DVec3::new(10.0, -4.0, 3.0))
        * DMat4::from_scale(DVec3::new(0.7, 1.3, 2.1));
    v.set_affine(affine).unwrap();
    v
}

/// MIP, MinIP and X-ray along each of the six axis views equal the max, min and
/// sum × spacing of the array along that axis, pixel for pixel, laid out like NumPy's
/// reduction of the (nz, ny, nx) array (row = slower remaining axis).
#[test]
fn axis_views_equal_array_reductions() {
    let v = test_volume();
    let dims = v.dims();
    let spacing = v.spacing();
    let any: AnyVolume = v.clone().into();
    let vmax = v.data().iter().fold(0.0f64, |m, x| m.max(x.abs() as f64));
    for view in ["+x", "-x", "+y", "-y", "+z", "-z"] {
        let view: AxisView = view.parse().unwrap();
        let (a, _) = view.axis();
        let (ca, ra) = view.image_axes();
        let cam = Camera::axis_view(dims, v.affine(), view, dims[ca], dims[ra]).unwrap();
        for filter in [
            Filter::Nearest,
            Filter::Trilinear,
            Filter::CatmullRom,
            Filter::BsplineInterp,
            Filter::Lanczos3,
        ] {
            for mode in [Mode::Mip, Mode::Minip, Mode::Xray] {
                let out = render::<f64>(
                    &any,
                    &gray_tf(),
                    &cam,
                    &settings(mode, filter, 1.0),
                    no_progress(),
                )
                .unwrap();
                let f32_out = render::<f32>(
                    &any,
                    &gray_tf(),
                    &cam,
                    &settings(mode, filter, 1.0),
                    no_progress(),
                )
                .unwrap();
                for row in 0..dims[ra] {
                    for col in 0..dims[ca] {
                        let line: Vec<f64> = (0..dims[a])
                            .map(|t| {
                                let mut idx = [0usize; 3];
                                idx[a] = t;
                                idx[ca] = col;
                                idx[ra] = row;
                                *v.get(idx[0], idx[1], idx[2]) as f64
                            })
                            .collect();
                        let want = match mode {
                            Mode::Mip => line.iter().cloned().fold(f64::MIN, f64::max),
                            Mode::Minip => line.iter().cloned().fold(f64::MAX, f64::min),
                            _ => line.iter().sum::<f64>() * spacing[a],
                        };
                        let got = out.image.pixel(col, row)[0];
                        let got32 = f32_out.image.pixel(col, row)[0];
                        // The scale of the result: the largest |value|, times the path
                        // length for X-ray.
                        let scale = if mode == Mode::Xray {
                            vmax * dims[a] as f64 * spacing[a]
                        } else {
                            vmax
                        };
                        assert!(
                            (got - want).abs() <= 1e-12 * scale,
                            "{view:?} {filter:?} {mode:?} ({col},{row}): {got} vs {want}"
                        );
                        // f32: sample positions are computed from t ≈ the eye distance,
                        // so they carry ~|t|·6e-8 of rounding, times the data's slope.
                        // Measured worst: 3.7e-7 × scale (X-ray, trilinear).
                        assert!(
                            (got32 - want).abs() <= 1e-5 * scale,
                            "f32 {view:?} {filter:?} {mode:?}: {got32} vs {want}"
                        );
                    }
                }
            }
        }
    }
}

/// A constant TF over a constant volume: emission–absorption has the closed form
/// `A = 1 − exp(−τ L)` with `τ = −ln(1 − α₀)` per voxel and `L` the path length in
/// voxels; colour `c·A`. Opacity correction makes this exact for any step, both
/// compositing orders and either classification.
#[test]
fn dvr_through_a_homogeneous_slab_is_beer_lambert() {
    let dims = [8, 10, 12];
    let v: AnyVolume = Volume::filled(dims, [1.0, 1.0, 1.0], 0.5f32)
        .unwrap()
        .into();
    let alpha0 = 0.07;
    let rgb = [0.2, 0.6, 0.9];
    let tf = TransferFunction {
        name: "constant".into(),
        domain: [0.0, 1.0],
        points: vec![ControlPoint {
            value: 0.0,
            rgba: [rgb[0], rgb[1], rgb[2], alpha0],
        }],
        window: WindowMap::default(),
        interpolation: Default::default(),
        faux_shading: None,
    };
    let tau = -(1.0f64 - alpha0).ln();
    let cams = [
        Camera::axis_view(dims, v.affine(), AxisView::PlusZ, 8, 10).unwrap(),
        Camera::look_at(
            DVec3::new(-20.0, -15.0, 30.0),
            DVec3::new(3.5, 4.5, 5.5),
            DVec3::Z,
            Projection::Perspective { fov_y_deg: 40.0 },
            24,
            24,
        )
        .unwrap(),
    ];
    for cam in &cams {
        for step in [0.3, 1.0, 2.5] {
            for compositing in [Compositing::FrontToBack, Compositing::BackToFront] {
                for classification in [Classification::Post, Classification::Pre] {
                    let s = RenderSettings {
                        step,
                        compositing,
                        classification,
                        ert_threshold: 1.0,
                        background: [0.0; 4],
                        ..RenderSettings::default()
                    };
                    let out = render::<f64>(&v, &tf, cam, &s, no_progress()).unwrap();
                    let mut hits = 0;
                    for row in 0..cam.height {
                        for col in 0..cam.width {
                            let r = cam.ray(col, row);
                            let lo = DVec3::splat(-0.5);
                            let hi = DVec3::new(7.5, 9.5, 11.5);
                            let len = match voxlab::real::slab_interval(r.origin, r.dir, lo, hi) {
                                Some((a, b)) => (b - a.max(r.t_min)).max(0.0),
                                None => 0.0,
                            };
                            let a = 1.0 - (-tau * len).exp();
                            let p = out.image.pixel(col, row);
                            hits += (len > 0.0) as usize;
                            assert!(
                                (p[3] - a).abs() < 1e-12,
                                "alpha {} vs {a} (len {len}, step {step})",
                                p[3]
                            );
                            for c in 0..3 {
                                assert!((p[c] - rgb[c] * a).abs() < 1e-12);
                            }
                        }
                    }
                    assert!(hits > 0);
                }
            }
        }
    }
    // Along +z every ray crosses 12 voxels.
    let s = RenderSettings {
        ert_threshold: 1.0,
        background: [0.0; 4],
        ..RenderSettings::default()
    };
    let out = render::<f64>(&v, &tf, &cams[0], &s, no_progress()).unwrap();
    let a12 = 1.0 - (1.0 - alpha0).powi(12);
    assert!((out.image.pixel(3, 4)[3] - a12).abs() < 1e-12);
}

/// Early ray termination stops a front-to-back ray right after its opacity reaches
/// the threshold, taking fewer samples.
#[test]
fn early_ray_termination_stops_at_the_threshold() {
    let dims = [4, 4, 64];
    let v: AnyVolume = Volume::filled(dims, [1.0; 3], 1.0f32).unwrap().into();
    let tf = TransferFunction {
        name: String::new(),
        domain: [0.0, 1.0],
        points: vec![ControlPoint {
            value: 0.0,
            rgba: [1.0, 1.0, 1.0, 0.1],
        }],
        window: WindowMap::default(),
        interpolation: Default::default(),
        faux_shading: None,
    };
    let cam = Camera::axis_view(dims, v.affine(), AxisView::PlusZ, 4, 4).unwrap();
    let base = RenderSettings {
        step: 1.0,
        sample_count: true,
        background: [0.0; 4],
        ..RenderSettings::default()
    };
    let full = render::<f64>(
        &v,
        &tf,
        &cam,
        &RenderSettings {
            ert_threshold: 1.0,
            ..base.clone()
        },
        no_progress(),
    )
    .unwrap();
    let ert = render::<f64>(
        &v,
        &tf,
        &cam,
        &RenderSettings {
            ert_threshold: 0.5,
            ..base
        },
        no_progress(),
    )
    .unwrap();
    // 1 − 0.9^k ≥ 0.5 first at k = 7.
    assert_eq!(full.samples.unwrap().data[0], 64.0);
    assert_eq!(ert.samples.unwrap().data[0], 7.0);
    assert!((ert.image.data[3] - (1.0 - 0.9f64.powi(7))).abs() < 1e-12);
}

/// A unit-density cube (filling the volume) holding a sphere of net value 0.3 and a
/// sphere of net value 1.5: MIP sees 1.5 exactly on rays through the second sphere and
/// 1 elsewhere; MinIP sees 0.3 on rays through the first and 1 elsewhere.
#[test]
fn mip_and_minip_of_spheres() {
    let (ca, ra, cb, rb) = (
        DVec3::new(-0.35, 0.1, 0.0),
        0.3,
        DVec3::new(0.4, -0.2, 0.2),
        0.25,
    );
    let phantom = Phantom::from_primitives(
        "mip test",
        vec![
            Primitive::cuboid(1.0, DVec3::splat(-1.0), DVec3::splat(1.0)),
            Primitive::sphere(-0.7, ca, ra),
            Primitive::sphere(0.5, cb, rb),
        ],
    );
    let dims = [48; 3];
    let field = PhantomField {
        phantom: &phantom,
        dims,
        method: GradientMethod::Central,
    };
    let affine = phantom.grid_affine(dims);
    let h = phantom.half_extent_mm;
    let cam = Camera::orbit(
        DVec3::ZERO,
        [2.0 * h; 3],
        Orbit {
            azimuth_deg: 25.0,
            elevation_deg: 15.0,
            distance_mm: None,
        },
        Projection::Orthographic {
            width_mm: 2.0 * h,
            height_mm: 2.0 * h,
        },
        48,
        48,
    )
    .unwrap();
    let voxel = 2.0 / 48.0;
    let mip = render_field::<f64, _>(
        &field,
        affine,
        &gray_tf(),
        &cam,
        &settings(Mode::Mip, Filter::Nearest, 0.25),
        no_progress(),
    )
    .unwrap();
    let minip = render_field::<f64, _>(
        &field,
        affine,
        &gray_tf(),
        &cam,
        &settings(Mode::Minip, Filter::Nearest, 0.25),
        no_progress(),
    )
    .unwrap();
    let (mut through_a, mut through_b) = (0, 0);
    for row in 0..48 {
        for col in 0..48 {
            let r = cam.ray(col, row);
            let (o, d) = (r.origin / h, r.dir);
            let dist = |c: DVec3| (o - c - d * (o - c).dot(d)).length();
            // Inside the cube along the whole image (the orbit fits the cube's sphere).
            if voxlab::real::slab_interval(o, d, DVec3::splat(-1.0), DVec3::ONE).is_none() {
                continue;
            }
            let (m, n) = (mip.image.pixel(col, row)[0], minip.image.pixel(col, row)[0]);
            // A chord of at least two voxels is certainly sampled at step ¼ voxel.
            let hit = |c: DVec3, rad: f64| dist(c) < (rad * rad - voxel * voxel).sqrt();
            let miss = |c: DVec3, rad: f64| dist(c) > rad;
            if hit(cb, rb) {
                through_b += 1;
                assert!((m - 1.5).abs() < 1e-12, "MIP through B: {m}");
            } else if miss(cb, rb) {
                assert!((m - 1.0).abs() < 1e-12, "MIP outside B: {m}");
            }
            if hit(ca, ra) {
                through_a += 1;
                assert!((n - 0.3).abs() < 1e-12, "MinIP through A: {n}");
            } else if miss(ca, ra) {
                assert!((n - 1.0).abs() < 1e-12, "MinIP outside A: {n}");
            }
        }
    }
    assert!(through_a > 20 && through_b > 20, "{through_a} {through_b}");
}

fn shepp_scene(n: usize) -> (AnyVolume, TransferFunction, Camera) {
    let v: AnyVolume = Phantom::shepp_logan_modified()
        .sample([n; 3])
        .unwrap()
        .into();
    let cam = Camera::orbit(
        DVec3::ZERO,
        [256.0; 3],
        Orbit::default(),
        Projection::Perspective { fov_y_deg: 30.0 },
        64,
        64,
    )
    .unwrap();
    (v, TransferFunction::preset("phantom").unwrap(), cam)
}

/// f32 against the f64 oracle on shaded DVR of Shepp–Logan (64³, 64², step ½).
/// Measured worst pixel differences (x86-64): trilinear 2.7e-5, Catmull–Rom 5.5e-5 in
/// RGBA units, from sample positions rounded at |t| ≈ 600 mm (about 1e-5 voxel) and
/// amplified where normals turn fast at edges. The bound, 3e-4, is 5× the worst
/// measurement, leaving room for other CPUs and compilers (FMA contraction, libm),
/// while a real precision bug (a wrong step, a missed or doubled sample) moves pixels
/// by 1e-2 or more.
#[test]
fn f32_agrees_with_the_f64_oracle() {
    let (v, tf, cam) = shepp_scene(64);
    for filter in [Filter::Trilinear, Filter::CatmullRom] {
        let s = RenderSettings {
            filter,
            ..RenderSettings::default()
        };
        let a = render::<f64>(&v, &tf, &cam, &s, no_progress()).unwrap();
        let b = render::<f32>(&v, &tf, &cam, &s, no_progress()).unwrap();
        let max = a
            .image
            .data
            .iter()
            .zip(&b.image.data)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        let mean: f64 = a.image.data.iter().sum::<f64>() / a.image.data.len() as f64;
        eprintln!("{filter:?}: f32 vs f64 max |Δ| = {max:.2e} (mean pixel value {mean:.3})");
        assert!(mean > 0.05, "the image must not be empty");
        assert!(max < 3e-4, "{filter:?}: max |Δ| {max}");
    }
}

/// The oracle's output does not depend on the thread count, bit for bit.
#[test]
fn f64_oracle_is_identical_for_any_thread_count() {
    let (v, tf, cam) = shepp_scene(48);
    let s = RenderSettings {
        classification: Classification::Pre,
        precompute_gradients: true,
        gradient: GradientMethod::Sobel,
        ..RenderSettings::default()
    };
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| render::<f64>(&v, &tf, &cam, &s, no_progress()).unwrap())
    };
    let one = run(1);
    for threads in [2, 3, 8] {
        let many = run(threads);
        assert!(
            one.image
                .data
                .iter()
                .zip(&many.image.data)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "{threads} threads differ from 1"
        );
    }
}

/// Pre-classification classifies the voxel values (not a filter's prefiltered
/// coefficients): along an axis view with step 1 every sample sits on a voxel centre,
/// where interpolating filters return the classified voxel exactly, so the image is the
/// front-to-back composite of `classify(f[k])` over k.
#[test]
fn preclassification_composites_classified_voxels_on_axis_views() {
    let v = test_volume();
    let dims = v.dims();
    let any: AnyVolume = v.clone().into();
    let tf = TransferFunction {
        name: String::new(),
        domain: [-4.0, 6.0],
        points: vec![
            ControlPoint {
                value: -4.0,
                rgba: [0.1, 0.2, 0.9, 0.05],
            },
            ControlPoint {
                value: 1.0,
                rgba: [0.9, 0.3, 0.1, 0.4],
            },
            ControlPoint {
                value: 6.0,
                rgba: [1.0, 1.0, 0.5, 0.2],
            },
        ],
        window: WindowMap::default(),
        interpolation: Default::default(),
        faux_shading: None,
    };
    let lut = tf.lut(4096).to_real::<f64>();
    let cam = Camera::axis_view(dims, v.affine(), AxisView::PlusZ, dims[0], dims[1]).unwrap();
    for filter in [
        Filter::Nearest,
        Filter::Trilinear,
        Filter::CatmullRom,
        Filter::BsplineInterp,
        Filter::Lanczos3,
    ] {
        let s = RenderSettings {
            filter,
            step: 1.0,
            classification: Classification::Pre,
            ert_threshold: 1.0,
            background: [0.0; 4],
            ..RenderSettings::default()
        };
        let s = RenderSettings {
            shading: voxlab::settings::Shading {
                enabled: false,
                ..s.shading
            },
            ..s
        };
        let out = render::<f64>(&any, &tf, &cam, &s, no_progress()).unwrap();
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let (mut c, mut a) = ([0.0f64; 3], 0.0f64);
                for k in 0..dims[2] {
                    let rgba = lut.classify(*v.get(i, j, k) as f64);
                    let w = (1.0 - a) * rgba[3];
                    for ch in 0..3 {
                        c[ch] += w * rgba[ch];
                    }
                    a += w;
                }
                let p = out.image.pixel(i, j);
                assert!(
                    (p[3] - a).abs() < 1e-12,
                    "{filter:?} alpha at ({i},{j}): {} vs {a}",
                    p[3]
                );
                for ch in 0..3 {
                    assert!(
                        (p[ch] - c[ch]).abs() < 1e-12,
                        "{filter:?} colour at ({i},{j})"
                    );
                }
            }
        }
    }
}
