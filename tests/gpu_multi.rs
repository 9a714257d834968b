//! The GPU multi-volume caster (`gpu::multi`) against the CPU f64 oracle
//! (`cpu::multi`): every mode with two and three placed volumes, generated from one
//! case list; the one-volume identity scene against the GPU single-volume caster; and
//! clear errors for what the port does not cover.

mod common;

use glam::DVec3;
use voxlab::camera::{Camera, Orbit, Projection};
use voxlab::metrics::max_abs_error;
use voxlab::metrics::Tolerance;
use voxlab::multi::{rotation_translation, MultiVolume};
use voxlab::phantom::Phantom;
use voxlab::settings::{Compositing, Filter, GradientMethod, Light, Mode, RenderSettings};
use voxlab::transfer::TransferFunction;
use voxlab::AnyVolume;

#[derive(Clone, Copy, Debug)]
struct Case {
    mode: Mode,
    /// Volumes in the scene (1 … 3).
    volumes: usize,
    filter: Filter,
    shading: bool,
    compositing: Compositing,
    gradient: GradientMethod,
    ert: f64,
    ortho: bool,
    directional: bool,
}

const BASE: Case = Case {
    mode: Mode::Dvr,
    volumes: 2,
    filter: Filter::Trilinear,
    shading: false,
    compositing: Compositing::FrontToBack,
    gradient: GradientMethod::Central,
    ert: 0.99,
    ortho: false,
    directional: false,
};

/// The phantom's transfer function with its colours permuted (b, r, g) and its
/// opacities doubled (capped at 1): a second volume that looks different.
fn other_tf() -> TransferFunction {
    let mut tf = TransferFunction::preset("phantom").unwrap();
    for p in tf.points.iter_mut() {
        let [r, g, b, a] = p.rgba;
        p.rgba = [b, r, g, (2.0 * a).min(1.0)];
    }
    tf
}

/// Volume 0 (MinIP: `lift − f` per volume): the modified Shepp–Logan phantom sampled on 32×30×28; volume 1: the same
/// phantom on 28×32×30 rotated 30° about z and shifted, with [`other_tf`]; volume 2: a
/// 24³ copy rotated 90° about x, shifted the other way, unshaded.
fn scene(case: &Case) -> (Vec<MultiVolume>, Camera, RenderSettings) {
    let ph = Phantom::shepp_logan_modified();
    let tf = TransferFunction::preset("phantom").unwrap();
    // MinIP of the phantom is 0 on every ray (the box's corners are empty): MinIP
    // renders `lift − f` instead, a different constant per volume, so that the minimum
    // shows the volumes' structure.
    let sample = |dims, lift: f32| -> AnyVolume {
        let mut v = ph.sample(dims).unwrap();
        if case.mode == Mode::Minip {
            v.data_mut().iter_mut().for_each(|x| *x = lift - *x);
        }
        v.into()
    };
    let v0 = sample([32, 30, 28], 1.0);
    let v1 = sample([28, 32, 30], 1.2);
    let v2 = sample([24, 24, 24], 1.4);
    let mut vols = vec![MultiVolume::new(v0, tf.clone())];
    if case.volumes > 1 {
        vols.push(
            MultiVolume::new(v1, other_tf()).with_transform(rotation_translation(
                2,
                30.0,
                DVec3::new(70.0, -20.0, 30.0),
            )),
        );
    }
    if case.volumes > 2 {
        let mut v = MultiVolume::new(v2, tf).with_transform(rotation_translation(
            0,
            90.0,
            DVec3::new(-60.0, 40.0, -25.0),
        ));
        v.shade = false;
        vols.push(v);
    }
    let projection = if case.ortho {
        Projection::Orthographic {
            width_mm: 460.0,
            height_mm: 460.0,
        }
    } else {
        Projection::Perspective { fov_y_deg: 40.0 }
    };
    let cam = Camera::orbit(
        DVec3::ZERO,
        [300.0; 3],
        Orbit {
            azimuth_deg: 35.0,
            elevation_deg: 25.0,
            distance_mm: Some(650.0),
        },
        projection,
        56,
        48,
    )
    .unwrap();
    let mut s = RenderSettings {
        mode: case.mode,
        filter: case.filter,
        compositing: case.compositing,
        gradient: case.gradient,
        ert_threshold: case.ert,
        skip_empty: false,
        sample_count: true,
        ..RenderSettings::default()
    };
    s.shading.enabled = case.shading;
    if case.directional {
        s.shading.light = Light::Direction([0.3, -0.5, 0.8]);
    }
    (vols, cam, s)
}

/// DVR colours and opacities (in [0, 1]). Measured on lavapipe (Mesa 22.3.6): worst
/// max |Δ| 1.8e-3 (three volumes, shaded with forward gradients and a directional
/// light: one pixel where a gradient crosses the shading threshold's blend), otherwise
/// ≤ 4.6e-4; worst RMSE 2.0e-5. The CPU caster in f32 measures 2.7e-4 / 9.7e-6 on the
/// same scenes: the differences are f32 rounding of sample positions (rotated frames,
/// |t| ≈ 650 mm) amplified by the `phantom` preset's narrow opacity bands, as for the
/// single-volume caster (tests/gpu_raycast.rs: EXACT_DVR). Bound ≈ 3× the worst.
const DVR: Tolerance = Tolerance {
    max_abs: 5e-3,
    rmse: 6e-5,
    ..Tolerance::NONE
};

/// MIP, MinIP and X-ray, relative to the image's largest value (at least 1). Measured
/// on lavapipe: MIP max |Δ| 1.5e-5, RMSE 1.7e-6 (cpu-f32: 1.3e-5); MinIP 1.7e-5 / 1.4e-6
/// relative (cpu-f32: 1.1e-5); X-ray 4.9e-4 absolute
/// on integrals up to ≈ 10², i.e. ≈ 5e-6 relative. Bound: tests/gpu_raycast.rs'
/// EXACT_SCALAR, ≈ 3× the worst.
const SCALAR: Tolerance = Tolerance {
    max_abs: 5e-5,
    rmse: 1e-5,
    ..Tolerance::NONE
};

/// Renders a case on the oracle and the GPU and checks parity of the image and of the
/// samples-per-ray image.
fn check(name: &str, case: Case) {
    let Some(ctx) = common::gpu(name) else {
        return;
    };
    let (vols, cam, s) = scene(&case);
    let cpu = voxlab::cpu::multi::render::<f64>(&vols, &cam, &s, &|_, _| {}).unwrap();
    let gpu = voxlab::gpu::multi::render(ctx, &vols, &cam, &s, &|_, _| {})
        .unwrap()
        .output;
    let tol = if case.mode == Mode::Dvr {
        DVR
    } else {
        SCALAR.scaled(cpu.image.data.iter().fold(1.0f64, |m, x| m.max(x.abs())))
    };
    let stats = common::assert_parity(name, &cpu.image, &gpu.image, tol);
    let (a, b) = (cpu.samples.unwrap().data, gpu.samples.unwrap().data);
    // Ray lengths are identical; early ray termination may flip at the threshold for a
    // ray whose opacity lands within rounding of it, and a step count may flip where
    // (t_out − t_in)/Δ lands within rounding of an integer (not seen on lavapipe).
    let differ = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    assert!(
        differ * 100 <= a.len(),
        "{name}: {differ} rays took a different number of samples"
    );
    if case.mode != Mode::Minip {
        let lit = cpu.image.data.iter().filter(|x| **x != 0.0).count();
        assert!(
            lit * 10 > cpu.image.data.len(),
            "{name}: the scene is mostly empty"
        );
    }
    // For scale: the CPU caster in f32 against the same oracle.
    let f32_img = voxlab::cpu::multi::render::<f32>(&vols, &cam, &s, &|_, _| {})
        .unwrap()
        .image;
    let f32_stats = voxlab::metrics::error_stats(&cpu.image.data, &f32_img.data, f64::INFINITY);
    eprintln!(
        "{name}: GPU max |Δ| {:.2e}, rmse {:.2e}, {differ} sample counts differ; \
         cpu-f32 max |Δ| {:.2e}, rmse {:.2e}",
        stats.max_abs, stats.rmse, f32_stats.max_abs, f32_stats.rmse
    );
}

/// One test per case, all from this list.
macro_rules! parity_cases {
    ($($name:ident: $case:expr;)*) => {
        $(
            #[test]
            fn $name() {
                check(stringify!($name), $case);
            }
        )*
    };
}

parity_cases! {
    dvr_two_volumes_front_to_back: Case { ..BASE };
    dvr_two_volumes_back_to_front: Case { compositing: Compositing::BackToFront, ..BASE };
    dvr_three_volumes_no_early_termination: Case { volumes: 3, ert: 1.0, ..BASE };
    dvr_two_volumes_shaded: Case { shading: true, ..BASE };
    dvr_three_volumes_shaded_directional_forward: Case { volumes: 3, shading: true, directional: true, gradient: GradientMethod::Forward, ..BASE };
    dvr_two_volumes_nearest_ortho: Case { filter: Filter::Nearest, ortho: true, ..BASE };
    xray_three_volumes: Case { mode: Mode::Xray, volumes: 3, ..BASE };
    xray_two_volumes_ortho: Case { mode: Mode::Xray, ortho: true, ..BASE };
    mip_three_volumes: Case { mode: Mode::Mip, volumes: 3, ..BASE };
    minip_two_volumes_ortho: Case { mode: Mode::Minip, ortho: true, ..BASE };
}

/// One volume placed by the identity is the GPU single-volume caster: the same steps
/// and samples; DVR differs only in rounding (the multi-volume caster sums optical
/// depth, `τ += −ln1p(−α)·x`, and composites `−expm1(−τ)`; the single caster corrects
/// each α). Both take ln1p and expm1 from `shaders/shared/opacity.wgsl`, accurate to a
/// few ulps on any conformant GPU; with `1 − pow(1 − α, x)` an NVIDIA H200 differed by
/// 1.4e-6. Measured on lavapipe: DVR shaded 3.6e-7, unshaded 6.0e-8; MIP, MinIP and
/// X-ray bit-identical.
#[test]
fn one_volume_identity_equals_gpu_single_volume_caster() {
    let Some(ctx) = common::gpu("one_volume_identity_equals_gpu_single_volume_caster") else {
        return;
    };
    for (mode, shading, bound) in [
        (Mode::Dvr, true, 1e-6),
        (Mode::Dvr, false, 1e-6),
        (Mode::Mip, false, 1e-6),
        (Mode::Minip, false, 1e-6),
        (Mode::Xray, false, 1e-6),
    ] {
        let case = Case {
            mode,
            volumes: 1,
            shading,
            ..BASE
        };
        let (vols, cam, s) = scene(&case);
        let multi = voxlab::gpu::multi::render(ctx, &vols, &cam, &s, &|_, _| {})
            .unwrap()
            .output
            .image;
        let single = voxlab::gpu::raycast::render(
            ctx,
            &vols[0].volume,
            &vols[0].transfer,
            &cam,
            &s,
            &|_, _| {},
        )
        .unwrap()
        .output
        .image;
        let scale = single.data.iter().fold(1.0f64, |m, x| m.max(x.abs()));
        let d = max_abs_error(&single, &multi) / scale;
        eprintln!("{mode:?} shading {shading}: max |Δ| {d:.2e} (relative)");
        assert!(
            d <= bound,
            "{mode:?} shading {shading}: {d:.2e} > {bound:.0e}"
        );
    }
}

/// Filters, gradients and paths the port does not cover are refused with an error
/// naming what it supports.
#[test]
fn unsupported_gpu_options_are_refused() {
    let Some(ctx) = common::gpu("unsupported_gpu_options_are_refused") else {
        return;
    };
    let (vols, cam, s) = scene(&BASE);
    let refuse = |s: RenderSettings, needle: &str| {
        let e = voxlab::gpu::multi::render(ctx, &vols, &cam, &s, &|_, _| {})
            .expect_err("refused")
            .to_string();
        assert!(e.contains(needle), "{e}");
    };
    refuse(
        RenderSettings {
            filter: Filter::CatmullRom,
            ..s.clone()
        },
        "nearest or trilinear",
    );
    let mut shaded = s.clone();
    shaded.shading.enabled = true;
    refuse(
        RenderSettings {
            gradient: GradientMethod::Sobel,
            ..shaded.clone()
        },
        "central or forward",
    );
    refuse(
        RenderSettings {
            precompute_gradients: true,
            ..shaded
        },
        "on the fly",
    );
    refuse(
        RenderSettings {
            hardware_filtering: true,
            ..s
        },
        "exact trilinear",
    );
}

/// Past the 3-D texture limit or the device memory the scene renders in cells, each
/// holding its part of every volume, the rays' states handed from cell to cell: the
/// unsplit image and samples per ray, bit for bit (the same shader and the same steps in
/// the same order; only where the samples are read from differs). Every mode, both
/// compositing orders, shaded (the gradients' ghost voxels) and nearest, from four views:
/// perspective, orthographic along x (rays in the cutting planes), oblique orthographic,
/// and perspective from inside the scene; cut by a 20-texel texture limit (every volume
/// exceeds it) and, separately, by the memory alone.
#[test]
fn cells_past_the_texture_limit_or_the_memory_render_the_unsplit_image() {
    use voxlab::gpu::context::GpuContext;
    use voxlab::gpu::multi::{render, scene_split, CARRIED_VEC4S};
    use voxlab::gpu::plan::DeviceMemory;
    use voxlab::gpu::raycast::{bricks_in_view, bricks_seen};
    let Some(ctx) = common::gpu("multi cells") else {
        return;
    };
    let mut textures = GpuContext::new().unwrap();
    textures.limits.max_texture_dimension_3d = 20;
    let mut memory = GpuContext::new().unwrap();
    let views = [
        (
            "perspective",
            35.0,
            25.0,
            None,
            Projection::Perspective { fov_y_deg: 40.0 },
        ),
        (
            "along x",
            90.0,
            0.0,
            None,
            Projection::Orthographic {
                width_mm: 460.0,
                height_mm: 460.0,
            },
        ),
        (
            "oblique orthographic",
            -40.0,
            -55.0,
            None,
            Projection::Orthographic {
                width_mm: 460.0,
                height_mm: 460.0,
            },
        ),
        // The eye inside volume 0, 20 mm from the world's origin.
        (
            "inside",
            200.0,
            10.0,
            Some(20.0),
            Projection::Perspective { fov_y_deg: 80.0 },
        ),
    ];
    let cases = [
        Case { volumes: 3, ..BASE },
        Case {
            compositing: Compositing::BackToFront,
            ..BASE
        },
        Case {
            volumes: 3,
            shading: true,
            directional: true,
            ..BASE
        },
        Case {
            filter: Filter::Nearest,
            ert: 1.0,
            ..BASE
        },
        Case {
            mode: Mode::Mip,
            volumes: 3,
            ..BASE
        },
        Case {
            mode: Mode::Minip,
            ..BASE
        },
        Case {
            mode: Mode::Xray,
            volumes: 3,
            ..BASE
        },
    ];
    // Cells no ray meets (behind the eye inside the scene) are skipped, and the others
    // cast the pixels whose rays may meet them: counted here.
    let (mut skipped, mut cast, mut every) = (0, 0, 0);
    for case in cases {
        let (vols, _, s) = scene(&case);
        for (view, az, el, dist, projection) in views {
            let cam = Camera::orbit(
                DVec3::ZERO,
                [300.0; 3],
                Orbit {
                    azimuth_deg: az,
                    elevation_deg: el,
                    distance_mm: dist.or(Some(650.0)),
                },
                projection,
                56,
                48,
            )
            .unwrap();
            // The tables, one band of carried states and counts, and 48 KiB of textures
            // (a fifth of the volumes').
            let band = (56 * 48 * (16 * CARRIED_VEC4S + 4)) as u64;
            let luts = (vols.len() * s.lut_size * 16) as u64;
            let budget = 48 << 10;
            memory.memory = Some(DeviceMemory {
                bytes: band + luts + budget,
                source: "the test".into(),
            });
            let want = render(ctx, &vols, &cam, &s, &|_, _| {}).unwrap();
            assert!(want.split.is_none());
            for (limit, c) in [("texture", &textures), ("memory", &memory)] {
                let c: &GpuContext = c;
                let name = format!("{:?} {} volumes, {view} ({limit})", case.mode, vols.len());
                let cut = scene_split(c, &vols, &cam, &s).unwrap().expect("a split");
                assert!(cut.cells.len() >= 4, "{name}: {} cells", cut.cells.len());
                for part in cut.cells.iter().flat_map(|c| c.parts.iter().flatten()) {
                    match limit {
                        "texture" => assert!(part.dims().iter().all(|&n| n <= 20), "{name}"),
                        _ => assert!(4 * part.voxels() as u64 <= budget, "{name}"),
                    }
                }
                assert!(limit == "texture" || cut.largest <= budget, "{name}");
                skipped += bricks_in_view(&cam, cut.affine, &cut.boxes)
                    .iter()
                    .filter(|&&v| !v)
                    .count();
                let seen = bricks_seen(&cam, cut.affine, &cut.boxes);
                cast += seen.iter().flatten().map(|r| r.len()).sum::<usize>();
                every += seen.iter().flatten().count() * cam.width * cam.height;
                let got = render(c, &vols, &cam, &s, &|_, _| {}).unwrap();
                let line = got.split.as_deref().expect("the split's line");
                assert!(
                    line.starts_with(&format!(
                        "multi-volume ray casting in {} cells",
                        cut.cells.len()
                    )),
                    "{name}: {line}"
                );
                let (a, b) = (&want.output, &got.output);
                let differ = a
                    .image
                    .data
                    .iter()
                    .zip(&b.image.data)
                    .filter(|(x, y)| x != y)
                    .count();
                let worst = max_abs_error(&a.image, &b.image);
                assert_eq!(
                    differ, 0,
                    "{name}: {differ} values differ, by up to {worst:.3e}"
                );
                assert_eq!(
                    a.samples.as_ref().unwrap().data,
                    b.samples.as_ref().unwrap().data,
                    "{name}: the samples per ray"
                );
                let lit = a.image.data.iter().filter(|x| **x != 0.0).count();
                assert!(
                    lit * 10 > a.image.data.len(),
                    "{name}: the view is mostly empty"
                );
            }
        }
    }
    assert!(skipped > 0, "no cell was out of view");
    eprintln!("{skipped} cells skipped; the cells in view cast {cast} of {every} rays");
    assert!(cast * 2 < every, "{cast} rays cast of {every}");
}
