//! The GPU ray caster against the CPU f64 oracle: every mode, filter, camera and
//! option, generated from one case list.

mod common;

use glam::DVec3;
use voxlab::camera::{AxisView, Camera, Orbit, Projection};
use voxlab::metrics::Tolerance;
use voxlab::phantom::Phantom;
use voxlab::settings::Filter::*;
use voxlab::settings::{
    Classification, Compositing, Filter, GradientMethod, Light, Mode, RenderSettings,
};
use voxlab::transfer::TransferFunction;
use voxlab::AnyVolume;

#[derive(Clone, Copy, Debug)]
enum Cam {
    /// Perspective orbit camera.
    Orbit,
    /// Orthographic orbit camera.
    Ortho,
    /// Axis view along −y (pixels on voxel centres).
    Axis,
}

#[derive(Clone, Copy, Debug)]
struct Case {
    mode: Mode,
    filter: Filter,
    cam: Cam,
    classification: Classification,
    compositing: Compositing,
    gradient: GradientMethod,
    precompute: bool,
    shading: bool,
    hardware: bool,
    ert: f64,
    directional: bool,
}

const BASE: Case = Case {
    mode: Mode::Dvr,
    filter: Filter::Trilinear,
    cam: Cam::Orbit,
    classification: Classification::Post,
    compositing: Compositing::FrontToBack,
    gradient: GradientMethod::Central,
    precompute: false,
    shading: true,
    hardware: false,
    ert: 0.99,
    directional: false,
};

fn scene(
    case: &Case,
    n: usize,
    size: usize,
) -> (AnyVolume, TransferFunction, Camera, RenderSettings) {
    let vol: AnyVolume = Phantom::shepp_logan_modified()
        .sample([n, n + 3, n - 2])
        .unwrap()
        .into();
    let tf = TransferFunction::preset("phantom").unwrap();
    let orbit = |projection| {
        Camera::orbit(
            DVec3::ZERO,
            [256.0; 3],
            Orbit {
                azimuth_deg: 30.0,
                elevation_deg: 20.0,
                distance_mm: Some(540.0),
            },
            projection,
            size,
            size * 3 / 4,
        )
        .unwrap()
    };
    let cam = match case.cam {
        Cam::Orbit => orbit(Projection::Perspective { fov_y_deg: 30.0 }),
        Cam::Ortho => orbit(Projection::Orthographic {
            width_mm: 270.0,
            height_mm: 270.0 * 0.75,
        }),
        Cam::Axis => {
            let d = vol.dims();
            Camera::axis_view(d, vol.affine(), AxisView::MinusY, d[0], d[2]).unwrap()
        }
    };
    let mut s = RenderSettings {
        mode: case.mode,
        filter: case.filter,
        classification: case.classification,
        compositing: case.compositing,
        gradient: case.gradient,
        precompute_gradients: case.precompute,
        hardware_filtering: case.hardware,
        ert_threshold: case.ert,
        sample_count: true,
        ..RenderSettings::default()
    };
    s.shading.enabled = case.shading;
    if case.directional {
        s.shading.light = Light::Direction([0.3, -1.0, 0.6]);
    }
    (vol, tf, cam, s)
}

/// Renders a case on the CPU oracle and the GPU; None when the GPU test is skipped.
fn run(
    name: &str,
    case: Case,
    n: usize,
    size: usize,
) -> Option<(
    voxlab::frame::Frame,
    voxlab::frame::Frame,
    Vec<f64>,
    Vec<f64>,
)> {
    let ctx = common::gpu(name)?;
    let (vol, tf, cam, s) = scene(&case, n, size);
    let cpu = voxlab::cpu::raycast::render::<f64>(&vol, &tf, &cam, &s, &|_, _| {}).unwrap();
    let gpu = voxlab::gpu::raycast::render(ctx, &vol, &tf, &cam, &s, &|_, _| {})
        .unwrap()
        .output;
    Some((
        cpu.image,
        gpu.image,
        cpu.samples.unwrap().data,
        gpu.samples.unwrap().data,
    ))
}

/// DVR on [0, 1] RGBA, exact path, lavapipe (Mesa 22.3.6), Shepp–Logan 32×35×30 at
/// 48×36: the worst of 24 filter × camera cases was max |Δ| 2.4e-4 (Lanczos-3,
/// orthographic), RMSE 1.3e-5. The differences are f32 rounding of sample positions
/// (|t| ≈ 540 mm) amplified by the `phantom` preset's narrow opacity bands (slope ≈ 12
/// per unit value). Bound: 4× the worst measurement.
const EXACT_DVR: Tolerance = Tolerance {
    max_abs: 1e-3,
    rmse: 5e-5,
    ..Tolerance::NONE
};

/// MIP, MinIP and X-ray, exact path, relative to the data scale (see `check`): worst
/// measured 1.3e-5 (MIP, Catmull–Rom, orthographic) and 4.5e-6 (X-ray), RMSE 3e-6.
/// Bound: about 4× the worst.
const EXACT_SCALAR: Tolerance = Tolerance {
    max_abs: 5e-5,
    rmse: 1e-5,
    ..Tolerance::NONE
};

/// The hardware trilinear path. Real GPUs compute the sampler's interpolation weights
/// with a few fractional bits (`subTexelPrecisionBits`: 8 on NVIDIA, 4 is the Vulkan
/// minimum we do not expect to meet), so each of the three 1-D weights may be off by up
/// to 2⁻⁸. Trilinear interpolation is three nested lerps, so a filtered value may be off
/// by up to 3 × 2⁻⁸ × the largest difference between neighbouring voxels (≤ the data
/// range, 1 here); on scalar images that is the bound, and the RMSE bound is a quarter
/// of it. On an NVIDIA H200 (driver 580.159) the MIP case measured max |Δ| 6.4e-3
/// (1.6 × 2⁻⁸) and RMSE 1.4e-3: the weights' errors add up across the axes, so the
/// single-axis bound of 2⁻⁸ first written here was too tight. DVR maps values through
/// opacity bands of slope up to 12 per unit: its bound is 12 × 3 × 2⁻⁸ and the RMSE a
/// quarter of it (the benchmark's 256³ → 512² case measured 5.2e-2 on the H200, above
/// 12 × 2⁻⁸).
/// lavapipe filters in full f32 and meets the exact bounds; only a real GPU tests these.
const HARDWARE_SCALAR: Tolerance = Tolerance {
    max_abs: 3.0 / 256.0,
    rmse: 3.0 / 1024.0,
    ..Tolerance::NONE
};
const HARDWARE_DVR: Tolerance = Tolerance {
    max_abs: 36.0 / 256.0,
    rmse: 9.0 / 256.0,
    ..Tolerance::NONE
};

/// A compact (`R16Unorm`) texture's hardware frame against the `R32Float` texture's on
/// lavapipe, which filters both in f32: the only difference is the normalised texel
/// `u / 65535` rounded to f32 (2⁻²⁴ relative) and mapped back with `· range + offset`,
/// about 65535 · 2⁻²⁴ ≈ 3.9e-3 raw units per texel. Scalar modes relative to the
/// image's peak, DVR on [0, 1] RGBA through the `phantom` preset's opacity bands.
/// Measured (u8, u16, i16 phantoms of 26×29×24, 48×36): MIP max |Δ|/peak 1.2e-7 (u8),
/// 1.3e-7 (u16), 5.6e-7 (i16: its peak, 10 000, is a sixth of the type's range),
/// RMSE/peak ≤ 6.8e-8; DVR max |Δ| ≤ 2.6e-6, RMSE ≤ 8.3e-8. Bounds: about 4–7× the worst.
const COMPACT_SCALAR: Tolerance = Tolerance {
    max_abs: 4e-6,
    rmse: 4e-7,
    ..Tolerance::NONE
};
const COMPACT_DVR: Tolerance = Tolerance {
    max_abs: 1e-5,
    rmse: 4e-7,
    ..Tolerance::NONE
};

/// Renders a case on the oracle and the GPU and checks parity of the image and of the
/// samples-per-ray image.
fn check(name: &str, case: Case, n: usize, size: usize, tol: Tolerance) {
    let Some((cpu, gpu, cpu_samples, gpu_samples)) = run(name, case, n, size) else {
        return;
    };
    let tol = if case.mode == Mode::Dvr {
        tol
    } else {
        // Relative to the data's scale: the phantom's value range [0, 1], or the image's
        // largest value where that is larger (X-ray integrates along the ray).
        tol.scaled(cpu.data.iter().fold(1.0f64, |m, x| m.max(x.abs())))
    };
    let stats = common::assert_parity(name, &cpu, &gpu, tol);
    // Ray lengths are identical; early ray termination may flip at the threshold for
    // a ray whose opacity lands within rounding of it (not seen on lavapipe).
    let differ = cpu_samples
        .iter()
        .zip(&gpu_samples)
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        differ * 200 <= cpu_samples.len(),
        "{name}: {differ} rays took a different number of samples"
    );
    eprintln!(
        "{name}: max |Δ| {:.2e}, rmse {:.2e}, {differ} sample counts differ",
        stats.max_abs, stats.rmse
    );
}

/// One test per case, all from this list.
macro_rules! parity_cases {
    ($($name:ident: $case:expr, $n:expr, $size:expr, $tol:expr;)*) => {
        $(
            #[test]
            fn $name() {
                check(stringify!($name), $case, $n, $size, $tol);
            }
        )*
    };
}

parity_cases! {
    // Every filter: shaded DVR in perspective and MIP orthographic, MinIP and X-ray.
    dvr_nearest_perspective: Case { filter: Nearest, ..BASE }, 32, 48, EXACT_DVR;
    dvr_trilinear_perspective: Case { filter: Trilinear, ..BASE }, 32, 48, EXACT_DVR;
    dvr_bspline_perspective: Case { filter: Bspline, ..BASE }, 32, 48, EXACT_DVR;
    dvr_bspline_interp_perspective: Case { filter: BsplineInterp, ..BASE }, 32, 48, EXACT_DVR;
    dvr_catmull_rom_perspective: Case { filter: CatmullRom, ..BASE }, 32, 48, EXACT_DVR;
    dvr_lanczos2_perspective: Case { filter: Lanczos2, ..BASE }, 32, 48, EXACT_DVR;
    dvr_lanczos3_perspective: Case { filter: Lanczos3, ..BASE }, 32, 48, EXACT_DVR;
    dvr_lanczos4_perspective: Case { filter: Lanczos4, ..BASE }, 32, 48, EXACT_DVR;
    mip_nearest_ortho: Case { mode: Mode::Mip, filter: Nearest, cam: Cam::Ortho, ..BASE }, 32, 48, EXACT_SCALAR;
    mip_trilinear_ortho: Case { mode: Mode::Mip, filter: Trilinear, cam: Cam::Ortho, ..BASE }, 32, 48, EXACT_SCALAR;
    mip_bspline_ortho: Case { mode: Mode::Mip, filter: Bspline, cam: Cam::Ortho, ..BASE }, 32, 48, EXACT_SCALAR;
    mip_bspline_interp_ortho: Case { mode: Mode::Mip, filter: BsplineInterp, cam: Cam::Ortho, ..BASE }, 32, 48, EXACT_SCALAR;
    mip_catmull_rom_ortho: Case { mode: Mode::Mip, filter: CatmullRom, cam: Cam::Ortho, ..BASE }, 32, 48, EXACT_SCALAR;
    mip_lanczos2_ortho: Case { mode: Mode::Mip, filter: Lanczos2, cam: Cam::Ortho, ..BASE }, 32, 48, EXACT_SCALAR;
    mip_lanczos3_ortho: Case { mode: Mode::Mip, filter: Lanczos3, cam: Cam::Ortho, ..BASE }, 32, 48, EXACT_SCALAR;
    mip_lanczos4_ortho: Case { mode: Mode::Mip, filter: Lanczos4, cam: Cam::Ortho, ..BASE }, 32, 48, EXACT_SCALAR;
    minip_trilinear_axis: Case { mode: Mode::Minip, filter: Trilinear, cam: Cam::Axis, ..BASE }, 32, 48, EXACT_SCALAR;
    minip_catmull_rom_perspective: Case { mode: Mode::Minip, filter: CatmullRom, ..BASE }, 32, 48, EXACT_SCALAR;
    minip_lanczos3_ortho: Case { mode: Mode::Minip, filter: Lanczos3, cam: Cam::Ortho, ..BASE }, 32, 48, EXACT_SCALAR;
    xray_nearest_axis: Case { mode: Mode::Xray, filter: Nearest, cam: Cam::Axis, ..BASE }, 32, 48, EXACT_SCALAR;
    xray_trilinear_perspective: Case { mode: Mode::Xray, filter: Trilinear, ..BASE }, 32, 48, EXACT_SCALAR;
    xray_bspline_interp_ortho: Case { mode: Mode::Xray, filter: BsplineInterp, cam: Cam::Ortho, ..BASE }, 32, 48, EXACT_SCALAR;
    xray_lanczos4_axis: Case { mode: Mode::Xray, filter: Lanczos4, cam: Cam::Axis, ..BASE }, 32, 48, EXACT_SCALAR;
    // Cameras for DVR.
    dvr_trilinear_ortho: Case { cam: Cam::Ortho, ..BASE }, 32, 48, EXACT_DVR;
    dvr_catmull_rom_axis: Case { filter: CatmullRom, cam: Cam::Axis, ..BASE }, 32, 48, EXACT_DVR;
    // Options.
    dvr_preclassified: Case { classification: Classification::Pre, ..BASE }, 32, 48, EXACT_DVR;
    dvr_preclassified_catmull_rom: Case { classification: Classification::Pre, filter: CatmullRom, ..BASE }, 32, 48, EXACT_DVR;
    dvr_preclassified_bspline_interp: Case { classification: Classification::Pre, filter: BsplineInterp, ..BASE }, 32, 48, EXACT_DVR;
    dvr_back_to_front: Case { compositing: Compositing::BackToFront, ..BASE }, 32, 48, EXACT_DVR;
    dvr_no_early_termination: Case { ert: 1.0, ..BASE }, 32, 48, EXACT_DVR;
    dvr_unshaded: Case { shading: false, ..BASE }, 32, 48, EXACT_DVR;
    dvr_directional_light: Case { directional: true, ..BASE }, 32, 48, EXACT_DVR;
    dvr_forward_gradients: Case { gradient: GradientMethod::Forward, ..BASE }, 32, 48, EXACT_DVR;
    dvr_sobel_gradients: Case { gradient: GradientMethod::Sobel, ..BASE }, 32, 48, EXACT_DVR;
    dvr_precomputed_central: Case { precompute: true, ..BASE }, 32, 48, EXACT_DVR;
    dvr_precomputed_sobel_catmull_rom: Case { precompute: true, gradient: GradientMethod::Sobel, filter: CatmullRom, ..BASE }, 32, 48, EXACT_DVR;
    dvr_precomputed_forward_bspline_interp: Case { precompute: true, gradient: GradientMethod::Forward, filter: BsplineInterp, ..BASE }, 32, 48, EXACT_DVR;
    // The hardware trilinear path.
    mip_hardware_trilinear: Case { mode: Mode::Mip, hardware: true, cam: Cam::Ortho, ..BASE }, 32, 48, HARDWARE_SCALAR;
    dvr_hardware_trilinear: Case { hardware: true, ..BASE }, 32, 48, HARDWARE_DVR;
    // The reference size: 128³-class volume at 256².
    dvr_trilinear_128_at_256: Case { ..BASE }, 128, 256, EXACT_DVR;
}

/// The full sinc and a hardware path for other filters are refused, clearly.
#[test]
fn unsupported_gpu_options_are_refused() {
    let Some(ctx) = common::gpu("unsupported_gpu_options_are_refused") else {
        return;
    };
    let (vol, tf, cam, s) = scene(
        &Case {
            filter: Sinc,
            ..BASE
        },
        8,
        8,
    );
    let e = voxlab::gpu::raycast::render(ctx, &vol, &tf, &cam, &s, &|_, _| {}).unwrap_err();
    assert!(e.to_string().contains("CPU only"), "{e}");
    let (vol, tf, cam, s) = scene(
        &Case {
            filter: CatmullRom,
            hardware: true,
            ..BASE
        },
        8,
        8,
    );
    let e = voxlab::gpu::raycast::render(ctx, &vol, &tf, &cam, &s, &|_, _| {}).unwrap_err();
    assert!(e.to_string().contains("trilinear"), "{e}");
}

/// A parity failure leaves its evidence behind: cpu, gpu and diff images and stats.
#[test]
fn a_failing_parity_check_writes_its_images() {
    let Some((cpu, gpu, _, _)) = run(
        "a_failing_parity_check_writes_its_images",
        Case {
            filter: Nearest,
            shading: false,
            ..BASE
        },
        16,
        16,
    ) else {
        return;
    };
    let mut wrong = gpu.clone();
    wrong.data[7] += 0.5;
    let dir =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target/parity/deliberately-wrong");
    let r =
        voxlab::metrics::check_parity("deliberately-wrong", &cpu, &wrong, EXACT_DVR, Some(&dir))
            .unwrap();
    assert!(!r.passed);
    assert!(
        r.message.contains("col 1, row 0, channel 3"),
        "{}",
        r.message
    );
    for f in ["cpu.png", "gpu.png", "diff.png", "stats.json"] {
        assert!(dir.join(f).is_file());
    }
}

// ---------------------------------------------------------------------------------
// A render session: one upload, frames equal to one-shot renders
// ---------------------------------------------------------------------------------

/// The image and samples-per-ray image as bit patterns (NaN equals NaN, -0 is not 0).
fn frame_bits(o: &voxlab::cpu::raycast::RenderOutput) -> (Vec<u64>, Vec<u64>) {
    let bits = |f: &voxlab::frame::Frame| f.data.iter().map(|v| v.to_bits()).collect();
    (bits(&o.image), o.samples.as_ref().map_or(Vec::new(), bits))
}

/// The counters that say what a frame made: (pipelines compiled or taken from the
/// device, which an earlier session on it may have compiled; tables uploaded; set-up
/// passes).
fn made(s: voxlab::gpu::raycast::SessionStats) -> (usize, usize, usize) {
    (
        s.pipelines_compiled + s.pipelines_shared,
        s.table_uploads,
        s.prepare_passes,
    )
}

/// A second session on the device compiles no ray-casting pipeline the first did: it
/// takes it from the device (`GpuContext::kept`), and renders the same image bit for
/// bit. (A context of its own, so no other test's sessions come between.)
#[test]
fn a_second_session_takes_the_first_sessions_pipeline() {
    use voxlab::gpu::raycast::RaycastSession;
    if common::gpu("a_second_session_takes_the_first_sessions_pipeline").is_none() {
        return;
    }
    let ctx = voxlab::gpu::GpuContext::new().expect("a second context on the test adapter");
    let (vol, tf, cam, s) = scene(&BASE, 24, 32);
    let mut first = RaycastSession::new(&ctx, &vol).unwrap();
    let a = first.render(&tf, &cam, &s, &|_, _| {}).unwrap();
    let (f, mut second) = (first.stats(), RaycastSession::new(&ctx, &vol).unwrap());
    let b = second.render(&tf, &cam, &s, &|_, _| {}).unwrap();
    let g = second.stats();
    // The first compiles the ray caster's and the min/max grid's pipelines; the
    // second takes both.
    assert_eq!((f.pipelines_compiled, f.pipelines_shared), (2, 0));
    assert_eq!((g.pipelines_compiled, g.pipelines_shared), (0, 2));
    assert!(frame_bits(&a.output) == frame_bits(&b.output));
    // A frame of another shader compiles it, and the first session then takes it.
    let mip = RenderSettings {
        mode: Mode::Mip,
        ..s.clone()
    };
    second.render(&tf, &cam, &mip, &|_, _| {}).unwrap();
    first.render(&tf, &cam, &mip, &|_, _| {}).unwrap();
    assert_eq!(second.stats().pipelines_compiled, 1);
    assert_eq!(first.stats().pipelines_shared, 1);
}

/// One session renders frames that change the camera, the transfer function, the mode,
/// the filter (a prefiltered B-spline too), pre-classification, precomputed gradients,
/// skipping and a 2-D transfer function. Every frame equals a fresh one-shot render of
/// the same inputs bit for bit and the f64 oracle within the parity bounds above, the
/// volume is uploaded once, and each frame makes exactly what its change needs.
#[test]
fn a_session_renders_every_frame_like_a_one_shot_render() {
    use voxlab::gpu::raycast::{render, RaycastSession};
    let Some(ctx) = common::gpu("a_session_renders_every_frame_like_a_one_shot_render") else {
        return;
    };
    let (vol, tf1, orbit_cam, base) = scene(&BASE, 32, 48);
    let (_, _, ortho_cam, _) = scene(
        &Case {
            cam: Cam::Ortho,
            ..BASE
        },
        32,
        48,
    );
    let mut tf2 = tf1.clone();
    for p in &mut tf2.points {
        p.rgba[3] *= 0.5;
    }
    let turned = |az: f64| {
        Camera::orbit(
            DVec3::ZERO,
            [256.0; 3],
            Orbit {
                azimuth_deg: az,
                elevation_deg: 20.0,
                distance_mm: Some(540.0),
            },
            Projection::Perspective { fov_y_deg: 30.0 },
            48,
            36,
        )
        .unwrap()
    };
    let with = |f: &dyn Fn(&mut RenderSettings)| {
        let mut s = base.clone();
        f(&mut s);
        s
    };
    let tf2d = voxlab::transfer2d::TransferFunction2D::from_1d(&tf2, base.lut_size, 0.1);
    // (what changes, transfer function, camera, settings, and what the frame must make:
    // pipelines compiled, tables uploaded, set-up passes).
    type Step = (
        &'static str,
        TransferFunction,
        Camera,
        RenderSettings,
        (usize, usize, usize),
    );
    #[rustfmt::skip]
    let frames: Vec<Step> = vec![
        // The ray caster's and the min/max grid's pipelines; the LUT, the (empty) 2-D
        // LUT and the opacity prefix; the min/max grid.
        ("first frame", tf1.clone(), orbit_cam.clone(), base.clone(), (2, 3, 1)),
        ("camera", tf1.clone(), turned(75.0), base.clone(), (0, 0, 0)),
        // New LUT entries: the table and the prefix, not the min/max grid (data values).
        ("transfer function", tf2.clone(), turned(75.0), base.clone(), (0, 2, 0)),
        ("mode: MIP", tf2.clone(), ortho_cam.clone(), with(&|s| s.mode = Mode::Mip), (1, 0, 0)),
        // Catmull–Rom reaches 2 voxels: the min/max grid is made again.
        ("filter: Catmull-Rom", tf2.clone(), turned(120.0), with(&|s| s.filter = CatmullRom), (1, 0, 1)),
        // The B-spline coefficients, and the min/max grid of them.
        ("filter: interpolating B-spline", tf2.clone(), turned(120.0), with(&|s| s.filter = BsplineInterp), (1, 0, 2)),
        // Pre-classification is a parameter, not a shader: the first frame's pipeline,
        // the pre-classification pass and its pipeline, the trilinear min/max grid.
        ("pre-classified", tf2.clone(), turned(120.0), with(&|s| s.classification = Classification::Pre), (1, 0, 2)),
        // Prefiltered pre-classification (on the CPU), no skipping; the B-spline's pipeline.
        ("pre-classified B-spline", tf2.clone(), turned(150.0), with(&|s| {
            s.classification = Classification::Pre;
            s.filter = BsplineInterp;
        }), (0, 0, 1)),
        // The gradient pass and its pipeline. The ray caster without on-the-fly
        // gradients is the MIP frame's shader (the mode is a parameter), and the
        // trilinear min/max grid is still there.
        ("precomputed Sobel gradients", tf2.clone(), turned(150.0), with(&|s| {
            s.precompute_gradients = true;
            s.gradient = GradientMethod::Sobel;
        }), (1, 0, 1)),
        ("skipping off", tf2.clone(), turned(180.0), with(&|s| s.skip_empty = false), (0, 0, 0)),
        ("skipping, 16-voxel blocks", tf2.clone(), turned(180.0), with(&|s| s.block_size = 16), (0, 0, 1)),
        ("2-D transfer function", tf2.clone(), turned(210.0), with(&|s| s.transfer_2d = Some(tf2d.clone())), (0, 1, 0)),
        // Back to the first frame's transfer functions and blocks: the LUT, the prefix
        // and the (empty) 2-D LUT again, the 32-voxel min/max grid again; its pipeline
        // was kept.
        ("first settings again", tf1.clone(), turned(240.0), base.clone(), (0, 3, 1)),
    ];
    let mut session = RaycastSession::new(ctx, &vol).unwrap();
    // The first frame uploads the volume.
    assert_eq!(session.stats().volume_uploads, 0);
    let mut before = made(session.stats());
    for (i, (what, tf, cam, s)) in frames
        .iter()
        .map(|(w, tf, c, s, _)| (w, tf, c, s))
        .enumerate()
    {
        let name = format!("session_frame_{i:02}");
        let got = session.render(tf, cam, s, &|_, _| {}).unwrap();
        let after = made(session.stats());
        let delta = (after.0 - before.0, after.1 - before.1, after.2 - before.2);
        assert_eq!(
            delta, frames[i].4,
            "{what}: (pipelines, tables, set-up passes) made"
        );
        before = after;
        let stats = session.stats();
        assert_eq!(
            stats.volume_uploads, 1,
            "{what}: the volume was uploaded again"
        );
        assert_eq!(stats.frames, i + 1);
        // A frame that makes nothing says so in its timings.
        if i > 0 {
            assert_eq!(
                got.timings.upload == 0.0,
                delta.1 == 0,
                "{what}: {:?}",
                got.timings
            );
            assert_eq!(
                got.timings.prepare == 0.0,
                delta.2 == 0,
                "{what}: {:?}",
                got.timings
            );
        }
        let fresh = render(ctx, &vol, tf, cam, s, &|_, _| {}).unwrap();
        assert!(
            frame_bits(&got.output) == frame_bits(&fresh.output),
            "{what}: the session's frame differs from a one-shot render"
        );
        let cpu = voxlab::cpu::raycast::render::<f64>(&vol, tf, cam, s, &|_, _| {}).unwrap();
        let tol = if s.mode == Mode::Dvr {
            EXACT_DVR
        } else {
            EXACT_SCALAR.scaled(cpu.image.data.iter().fold(1.0f64, |m, x| m.max(x.abs())))
        };
        let e = common::assert_parity(&name, &cpu.image, &got.output.image, tol);
        eprintln!("{what}: max |Δ| {:.2e} against the oracle", e.max_abs);
    }
}

/// The Shepp–Logan head as an integer volume: `round(v · scale) + offset`.
fn integer_phantom(dims: [usize; 3], scale: f64, offset: f64) -> Vec<f64> {
    let ph = Phantom::shepp_logan_modified().sample(dims).unwrap();
    ph.data()
        .iter()
        .map(|&v| (f64::from(v) * scale).round() + offset)
        .collect()
}

/// [`integer_phantom`] as a volume of `T` (unit spacing).
fn typed_phantom<T: voxlab::Voxel>(
    dims: [usize; 3],
    scale: f64,
    offset: f64,
    to: fn(f64) -> T,
) -> AnyVolume
where
    voxlab::Volume<T>: Into<AnyVolume>,
{
    let data = integer_phantom(dims, scale, offset)
        .into_iter()
        .map(to)
        .collect();
    voxlab::Volume::new(dims, [1.0; 3], data).unwrap().into()
}

/// Hardware-filtered frames of u8, u16 and i16 volumes read an `R16Unorm` texture (2
/// bytes per voxel, and nothing else of the volume on the device), give
/// the f64 oracle's image within the hardware path's bounds, and on lavapipe (which
/// filters in f32) the `R32Float` texture's image within rounding. An exact frame then
/// adds the `R32Float` texture. The skipping grid, built on the CPU when the session has
/// no `R32Float` texture, equals the GPU-built one (the frames agree bit for bit).
#[test]
fn hardware_frames_of_integer_volumes_read_compact_textures() {
    use voxlab::gpu::raycast::{CompactVolume, RaycastSession};
    let Some(ctx) = common::gpu("hardware_frames_of_integer_volumes_read_compact_textures") else {
        return;
    };
    let dims = [26, 29, 24];
    let n = (dims[0] * dims[1] * dims[2]) as u64;
    let norm16 = ctx
        .features
        .contains(wgpu::Features::TEXTURE_FORMAT_16BIT_NORM);
    let compact = |range, offset| norm16.then_some(CompactVolume { range, offset });
    // (name, volume, scale, offset, compact form)
    let cases: [(&str, AnyVolume, f64, f64, Option<CompactVolume>); 3] = [
        (
            "u8",
            typed_phantom(dims, 250.0, 0.0, |v| v as u8),
            250.0,
            0.0,
            compact(255, 0),
        ),
        (
            "u16",
            typed_phantom(dims, 60000.0, 0.0, |v| v as u16),
            60000.0,
            0.0,
            compact(65535, 0),
        ),
        (
            "i16",
            typed_phantom(dims, 20000.0, -10000.0, |v| v as i16),
            20000.0,
            -10000.0,
            compact(65535, -32768),
        ),
    ];
    let cam = Camera::orbit(
        DVec3::new(12.5, 14.0, 11.5),
        [26.0, 29.0, 24.0],
        Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            distance_mm: Some(80.0),
        },
        Projection::Perspective { fov_y_deg: 30.0 },
        48,
        36,
    )
    .unwrap();
    for (name, vol, scale, offset, compact) in cases {
        assert_eq!(CompactVolume::of(ctx, &vol), compact, "{name}");
        let mut tf = TransferFunction::preset("phantom").unwrap();
        tf.window = voxlab::transfer::WindowMap {
            a: 1.0 / scale,
            b: -offset / scale,
        };
        for mode in [Mode::Dvr, Mode::Mip] {
            let hw = RenderSettings {
                mode,
                hardware_filtering: true,
                sample_count: true,
                ..RenderSettings::default()
            };
            let what = format!("{name} {mode:?}");
            let mut fast = RaycastSession::new(ctx, &vol).unwrap();
            let got = fast.render(&tf, &cam, &hw, &|_, _| {}).unwrap().output;
            let bytes = compact.map_or(4, |_| CompactVolume::BYTES_PER_VOXEL);
            assert_eq!(
                (fast.stats().volume_uploads, fast.stats().volume_bytes),
                (1, bytes * n),
                "{what}"
            );
            let mut wide = RaycastSession::new(ctx, &vol).unwrap();
            wide.set_compact_textures(false);
            let want = wide.render(&tf, &cam, &hw, &|_, _| {}).unwrap().output;
            assert_eq!(wide.stats().volume_bytes, 4 * n, "{what}");
            let cpu =
                voxlab::cpu::raycast::render::<f64>(&vol, &tf, &cam, &hw, &|_, _| {}).unwrap();
            let peak = cpu.image.data.iter().fold(1.0f64, |m, x| m.max(x.abs()));
            let (hardware, lavapipe) = match mode {
                Mode::Dvr => (HARDWARE_DVR, COMPACT_DVR),
                _ => (HARDWARE_SCALAR.scaled(peak), COMPACT_SCALAR.scaled(peak)),
            };
            common::assert_parity(
                &format!("compact_{name}_{mode:?}"),
                &cpu.image,
                &got.image,
                hardware,
            );
            let e = common::assert_parity(
                &format!("compact_vs_r32_{name}_{mode:?}"),
                &want.image,
                &got.image,
                if ctx.summary.is_cpu() {
                    lavapipe
                } else {
                    hardware
                },
            );
            eprintln!(
                "{what}: compact against R32Float max |Δ| {:.2e}, rmse {:.2e}",
                e.max_abs, e.rmse
            );
            // An exact frame reads the R32Float texture: uploaded now, beside the other.
            let exact = RenderSettings {
                hardware_filtering: false,
                ..hw.clone()
            };
            fast.render(&tf, &cam, &exact, &|_, _| {}).unwrap();
            let stats = fast.stats();
            let both = if compact.is_some() {
                (2, (4 + bytes) * n)
            } else {
                (1, 4 * n)
            };
            assert_eq!((stats.volume_uploads, stats.volume_bytes), both, "{what}");
            // A session whose skipping grid came from the R32Float texture on the GPU
            // (the exact frame first) draws the hardware frame bit for bit as the one
            // whose grid the CPU built.
            let mut gpu_grid = RaycastSession::new(ctx, &vol).unwrap();
            gpu_grid.render(&tf, &cam, &exact, &|_, _| {}).unwrap();
            let again = gpu_grid.render(&tf, &cam, &hw, &|_, _| {}).unwrap().output;
            assert!(
                frame_bits(&again) == frame_bits(&got),
                "{what}: skipping grids differ"
            );
        }
    }
}

/// `render --dry-run`'s device plan counts the volume textures a frame reads: 4 bytes a
/// voxel (R32Float) on the exact path, 2 (R16Unorm) on the hardware path of a u16
/// volume, 6 when a hardware frame also makes pre-classified colours on the GPU (and 16
/// for those colours, an `Rgba32Float` volume; as many again for precomputed gradients).
#[test]
fn the_render_plan_counts_the_volume_textures_a_frame_reads() {
    use voxlab::jobs::input::VolumeInput;
    use voxlab::jobs::render::{plan, RenderRequest, SceneRequest};
    let Some(ctx) = common::gpu("the_render_plan_counts_the_volume_textures_a_frame_reads") else {
        return;
    };
    let dims = [20, 18, 16];
    let n = (dims[0] * dims[1] * dims[2]) as u64;
    let v = typed_phantom(dims, 60000.0, 0.0, |x| x as u16);
    let peak = |hardware: bool, classification: Classification, gradients: bool| {
        let req = RenderRequest {
            scene: SceneRequest {
                input: VolumeInput {
                    source: "array".into(),
                    memory: Some(std::sync::Arc::new(v.clone())),
                    ..VolumeInput::default()
                },
                width: Some(8),
                height: Some(8),
                hardware_filtering: hardware,
                classification,
                precompute_gradients: gradients,
                ..SceneRequest::default()
            },
            backend: voxlab::jobs::Backend::Gpu,
            ..RenderRequest::default()
        };
        plan(&req, &()).unwrap().device.unwrap().peak_bytes
    };
    // The image's output buffers: 20 bytes a pixel.
    let image = 8 * 8 * 20;
    let norm16 = ctx
        .features
        .contains(wgpu::Features::TEXTURE_FORMAT_16BIT_NORM);
    let (post, pre) = (Classification::Post, Classification::Pre);
    assert_eq!(peak(false, post, false), 4 * n + image);
    assert_eq!(peak(false, pre, false), (4 + 16) * n + image);
    assert_eq!(peak(false, post, true), (4 + 16) * n + image);
    let (hw, hw_pre) = if norm16 { (2, 6) } else { (4, 4) };
    assert_eq!(peak(true, post, false), hw * n + image);
    assert_eq!(peak(true, pre, false), (hw_pre + 16) * n + image);
    assert_eq!(peak(true, pre, true), (hw_pre + 32) * n + image);
}

/// Orbiting the camera with everything else unchanged uploads nothing and prepares
/// nothing after the first frame, and the first frame reports the volume's upload.
#[test]
fn an_orbit_uploads_the_volume_once() {
    use voxlab::gpu::raycast::RaycastSession;
    let Some(ctx) = common::gpu("an_orbit_uploads_the_volume_once") else {
        return;
    };
    let (vol, tf, _, s) = scene(&BASE, 32, 32);
    let mut session = RaycastSession::new(ctx, &vol).unwrap();
    let mut first = None;
    for k in 0..8 {
        let cam = Camera::orbit(
            DVec3::new(16.0, 17.0, 15.0),
            [256.0; 3],
            Orbit {
                azimuth_deg: 45.0 * k as f64,
                elevation_deg: 15.0,
                distance_mm: Some(540.0),
            },
            Projection::Perspective { fov_y_deg: 30.0 },
            32,
            32,
        )
        .unwrap();
        let g = session.render(&tf, &cam, &s, &|_, _| {}).unwrap();
        let t = g.timings;
        let stats = session.stats();
        match first {
            None => {
                assert!(t.upload > 0.0 && t.prepare > 0.0, "{t:?}");
                assert!(
                    t.total >= t.setup + t.upload + t.prepare + t.kernel,
                    "{t:?}"
                );
                first = Some(stats);
            }
            Some(f) => {
                assert_eq!(t.upload, 0.0, "frame {k}: {t:?}");
                assert_eq!(t.prepare, 0.0, "frame {k}: {t:?}");
                assert_eq!(made(stats), made(f), "frame {k} made something");
            }
        }
        assert_eq!(stats.volume_uploads, 1);
        assert_eq!(stats.frames, k + 1);
        if k == 5 {
            let one = voxlab::gpu::raycast::render(ctx, &vol, &tf, &cam, &s, &|_, _| {}).unwrap();
            assert!(frame_bits(&one.output) == frame_bits(&g.output));
            assert!(
                one.timings.upload > 0.0,
                "a one-shot render uploads: {:?}",
                one.timings
            );
        }
    }
}
