//! `cargo bench --bench fvr`: Fourier volume rendering against the ray caster's X-ray
//! mode, in the layout of Jansen et al. (VMV 2004) Table 2: per volume size, the time
//! of one projection.
//!
//! For each cube side `n` (64, 128, 256) the modified Shepp–Logan phantom is sampled
//! on `n³` voxels and padded by 2 (`M = 2n`): the volume and view of `voxlab bench`'s
//! fvr cases (`voxlab::bench::fourier`). Reported, in milliseconds:
//! - **pre-processing** (once per volume, not per view): pad, centre and the f64 3-D
//!   FFT of the `M³` cube (`FvrSpectrum::new`, all rayon threads), and the upload of the
//!   spectrum to the GPU (complex f32, with the slice pipeline and inverse FFT plan made
//!   once — `GpuFvrSpectrum::upload`); a single run each;
//! - **per-view FVR** on the CPU (`cpu::fvr::fvr_project`, f64 slice + f64 inverse
//!   `M²` FFT; and in f32 from `FvrSpectrum::to_f32`, f32 slice + f32 FFT, the pairing
//!   of the f32 ray caster) and on the GPU (`gpu::fvr::fvr_project`: slice dispatch, inverse FFT,
//!   readback, crop), oblique view (azimuth 30°, elevation 20°), trilinear and
//!   Lanczos-3 slicing, with de-apodisation;
//! - **ray-cast X-ray** of the same volume and view (`voxlab::jobs::render`, `Mode::Xray`,
//!   trilinear, step 1 voxel) on the CPU in f32 (the fair CPU baseline) and on the GPU,
//!   at the FVR's own image (`n²`, pixel = voxel, the same pixel rays) and at 512²
//!   (Jansen's image size, over the same field of view);
//! - the ratios ray cast / FVR (CPU f64 FVR, and CPU f32 FVR at 512²), and the relative L2 difference between the FVR image
//!   and the CPU ray caster's image through the same pixels (a fast wrong answer must
//!   not count: it is printed beside the times and asserted below 15 %; a wrong
//!   projection is off by order 1. The two methods interpolate differently — a
//!   trilinear slice of the spectrum is not a trilinear ray through the voxels — and
//!   the phantom's skull is thinner than a voxel, so a few per cent is their honest
//!   disagreement: `tests/fvr.rs` measures both against the analytic projection).
//!
//! Each timing: one warm-up, then the median of `VOXLAB_BENCH_RUNS` (default 5) runs.
//! The GPU spectrum must fit one storage binding; larger ones print "refused". Pass a
//! substring to run only matching cases (`cargo bench --bench fvr -- 128`). Under
//! `cargo test` (no `--bench`) one tiny case runs once, as a smoke test.

mod common;
use common::median_min_max;

use std::time::Instant;
use voxlab::bench::fourier::{fvr_volume, FVR_PADDING, FVR_VIEW};
use voxlab::camera::Camera;
use voxlab::cpu::fvr::{fvr_project, FvrSpectrum, Kernel};
use voxlab::jobs::render::{Backend, Renderer, Scene};
use voxlab::settings::{Filter, Mode, RenderSettings};
use voxlab::transfer::TransferFunction;
use voxlab::volume::AnyVolume;

/// One warm-up, then the median of `runs` timed calls of `f` (seconds), and the
/// warm-up's result.
fn timed<T>(runs: usize, mut f: impl FnMut() -> T) -> (T, f64) {
    let first = f();
    let t = (0..runs)
        .map(|_| {
            let s = Instant::now();
            std::hint::black_box(f());
            s.elapsed().as_secs_f64()
        })
        .collect();
    (first, median_min_max(t).0)
}

/// ‖a − b‖ / ‖b‖, `b` the reference (`metrics::error_stats`; ∞ on a NaN/Inf mismatch).
fn rel_l2(a: &[f64], b: &[f64]) -> f64 {
    voxlab::metrics::error_stats(b, a, f64::INFINITY)
        .infinite_if_mismatched()
        .rel_l2
}

fn ms(t: f64) -> String {
    if t.is_finite() {
        format!("{:.1}", t * 1e3)
    } else {
        "—".into()
    }
}

fn ratio(a: f64, b: f64) -> String {
    if (a / b).is_finite() {
        format!("{:.1}×", a / b)
    } else {
        "—".into()
    }
}

fn main() {
    let args = common::BenchArgs::from_env();
    let (smoke, runs) = (args.smoke, args.runs);
    let sizes: Vec<usize> = if smoke { vec![32] } else { vec![64, 128, 256] };
    let big_image = if smoke { 64 } else { 512 };
    let view = FVR_VIEW;
    let settings = RenderSettings {
        mode: Mode::Xray,
        filter: Filter::Trilinear,
        step: 1.0,
        ..RenderSettings::default()
    };
    let tf = TransferFunction::preset("grayscale").expect("the grayscale preset");
    let cpu = Renderer::new(Backend::CpuF32).expect("the CPU renderer");
    let gpu = Renderer::new(Backend::Gpu).ok();
    println!(
        "FVR vs ray-cast X-ray, {} threads, {runs} runs after 1 warm-up; medians in ms",
        rayon::current_num_threads()
    );
    match gpu.as_ref().and_then(|r| r.gpu()) {
        Some(ctx) => println!(
            "GPU: {} ({}, {})",
            ctx.summary.name, ctx.summary.backend, ctx.summary.driver_info
        ),
        None => println!("GPU: none found; GPU columns left empty"),
    }
    println!();
    println!(
        "| volume | M | pre-proc CPU (3-D FFT) | GPU upload | kernel | FVR CPU | FVR CPU f32 | FVR GPU | ray cast CPU f32 n² | ray cast CPU f32 {big_image}² | ray cast GPU n² | CPU ray cast n² / FVR CPU | CPU ray cast {big_image}² / FVR CPU | CPU ray cast {big_image}² / FVR CPU f32 | GPU ray cast / FVR GPU | rel L2 FVR vs ray cast |"
    );
    println!("|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for n in sizes {
        let name = format!("{n}³");
        if !args.wants(&name) {
            continue;
        }
        let vol = fvr_volume(n).expect("the phantom volume");
        let t = Instant::now();
        let spectrum = FvrSpectrum::new(&vol, FVR_PADDING).expect("the spectrum");
        let pre = t.elapsed().as_secs_f64();
        let m = spectrum.side();
        let g = spectrum.geometry(view).expect("the view");
        let cam = g.camera().expect("the camera");
        let big_cam = Camera {
            width: big_image,
            height: big_image,
            ..cam.clone()
        };
        let scene = |camera: Camera| Scene {
            volume: AnyVolume::from(vol.clone()),
            transfer: tf.clone(),
            camera,
        };
        let (scene_n, scene_big) = (scene(cam), scene(big_cam));
        let render = |r: &Renderer, s: &Scene| r.render(s, &settings, &|_, _| {}).expect("render");
        let (rc, rc_cpu) = timed(runs, || render(&cpu, &scene_n));
        let (_, rc_cpu_big) = timed(runs, || render(&cpu, &scene_big));
        let rc_gpu = gpu
            .as_ref()
            .map_or(f64::NAN, |r| timed(runs, || render(r, &scene_n)).1);
        let reference = rc.output.image.data;

        let uploaded = gpu.as_ref().and_then(|r| r.gpu()).map(|ctx| {
            let t = Instant::now();
            let up = voxlab::gpu::fvr::GpuFvrSpectrum::upload(ctx, &spectrum);
            (ctx, up, t.elapsed().as_secs_f64())
        });
        let spectrum32 = spectrum.to_f32();
        for kernel in [Kernel::Trilinear, Kernel::Lanczos3] {
            let (img, fvr_cpu) = timed(runs, || {
                fvr_project(&spectrum, view, kernel, true).expect("FVR on the CPU")
            });
            let (img32, fvr_cpu32) = timed(runs, || {
                fvr_project(&spectrum32, view, kernel, true).expect("f32 FVR on the CPU")
            });
            let e32 = rel_l2(&img32.data, &img.data);
            assert!(
                e32 < 1e-4,
                "{name}: f32 FVR differs from f64 FVR ({e32:.2e})"
            );
            let err = rel_l2(&img.data, &reference);
            assert!(
                err < 0.15,
                "{name} {}: FVR and ray cast disagree ({err:.2e}), not timed",
                kernel.name()
            );
            let (up_col, fvr_gpu) = match &uploaded {
                None => ("—".to_string(), f64::NAN),
                Some((_, Err(e), _)) => {
                    eprintln!("{name}: GPU spectrum: {e}");
                    ("refused".to_string(), f64::NAN)
                }
                Some((ctx, Ok(up), t_up)) => {
                    let (gimg, t) = timed(runs, || {
                        voxlab::gpu::fvr::fvr_project(ctx, up, view, kernel, true)
                            .expect("FVR on the GPU")
                    });
                    let e = rel_l2(&gimg.data, &img.data);
                    assert!(e < 1e-4, "{name}: GPU FVR differs from CPU FVR ({e:.2e})");
                    (ms(*t_up), t)
                }
            };
            println!(
                "| {name} | {m} | {} | {up_col} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {err:.2e} |",
                ms(pre),
                kernel.name(),
                ms(fvr_cpu),
                ms(fvr_cpu32),
                ms(fvr_gpu),
                ms(rc_cpu),
                ms(rc_cpu_big),
                ms(rc_gpu),
                ratio(rc_cpu, fvr_cpu),
                ratio(rc_cpu_big, fvr_cpu),
                ratio(rc_cpu_big, fvr_cpu32),
                ratio(rc_gpu, fvr_gpu),
            );
        }
    }
}
