//! `cargo bench --bench raycast`: the ray caster on the CPU f64 oracle, the CPU f32
//! baseline and the GPU, on the same inputs. GPU figures: kernel time from timestamp
//! queries, and end to end (upload, set-up passes, kernel, readback; shader compilation
//! and pipeline creation reported apart as set-up). Speedups are quoted against f32.
//! The scene and the variants are `voxlab::bench::raycast`'s (`raycast_scene`,
//! `raycast_variants`). Each GPU result is checked against the f64 oracle first, to the
//! case's max-difference bound (a fast wrong answer does not count). Each case: one warm-up run, then `VOXLAB_BENCH_RUNS`
//! (default 5) timed runs; the median, minimum and maximum are printed with the
//! f64/f32 ratio of medians. Set-up (phantom sampling) is outside the timed region.
//! Pass a substring to run only matching cases: `cargo bench --bench raycast -- mip`.
//! Under `cargo test` (no `--bench` argument) each case runs once on a tiny input, as
//! a smoke test of the benchmark code.
//!
//! Then "GPU frame, one-shot" against "GPU frame, session reused" (cases
//! `session/<variant>-<n>-at-<size>`, on the scene above and on half its edge at half
//! its image size): the same orbit of frames (azimuth 30°, 40°, …), each rendered by
//! `gpu::raycast::render` (the volume converted and uploaded, the shaders compiled and
//! the set-up passes run every frame) and by one `gpu::raycast::RaycastSession` made
//! before the timed frames and warmed by one untimed frame (per frame: the parameter
//! block, the rays, the readback). Printed: wall-clock seconds per frame and their
//! ratio, the share of set-up + upload + set-up passes in each frame's total, and the
//! kernel medians (the same rays in both). The session's frames are checked equal to
//! the one-shot frames bit for bit before they are timed.

mod common;
use common::median_min_max;

use std::time::Instant;
use voxlab::bench::raycast::{raycast_scene, raycast_tolerances, raycast_variants};
use voxlab::cpu::raycast::render;

fn main() {
    let args = common::BenchArgs::from_env();
    let (smoke, runs) = (args.smoke, args.runs);
    let (n, size) = if smoke { (16, 16) } else { (128, 256) };
    let (vol, tf, cam) = raycast_scene(n, size).unwrap();
    let cases = raycast_variants();
    println!(
        "ray caster, Shepp–Logan {n}³, {size}×{size} image, step 0.5, {} threads, {runs} runs after 1 warm-up",
        rayon::current_num_threads()
    );
    let gpu = voxlab::gpu::GpuContext::shared().ok();
    match &gpu {
        Some(ctx) => println!(
            "GPU: {} ({}, {})",
            ctx.summary.name, ctx.summary.backend, ctx.summary.driver_info
        ),
        None => println!("GPU: none found; GPU columns left empty"),
    }
    println!(
        "{:<30} {:>22} {:>22} {:>8} {:>12} | {:>22} {:>22} {:>8} {:>9} {:>9}",
        "case",
        "f64 median (min–max) s",
        "f32 median (min–max) s",
        "f64/f32",
        "Msamples/s",
        "GPU kernel (min–max) s",
        "GPU end-to-end s",
        "setup s",
        "f32/kern",
        "f32/e2e"
    );
    for (name, s) in cases {
        if !args.wants(name) {
            continue;
        }
        let mut samples = 0;
        let mut time = |f32_path: bool| {
            let mut t = Vec::new();
            for i in 0..=runs {
                let start = Instant::now();
                let out = if f32_path {
                    render::<f32>(&vol, &tf, &cam, &s, &|_, _| {})
                } else {
                    render::<f64>(&vol, &tf, &cam, &s, &|_, _| {})
                }
                .unwrap();
                samples = out.total_samples;
                if i > 0 {
                    t.push(start.elapsed().as_secs_f64());
                }
            }
            median_min_max(t)
        };
        let (m64, lo64, hi64) = time(false);
        let (m32, lo32, hi32) = time(true);
        let mut gpu_cols = String::from("(no GPU)");
        if let Some(ctx) = &gpu {
            let oracle = render::<f64>(&vol, &tf, &cam, &s, &|_, _| {}).unwrap();
            let (mut kern, mut e2e, mut setup) = (Vec::new(), Vec::new(), Vec::new());
            for i in 0..=runs {
                let g = voxlab::gpu::raycast::render(ctx, &vol, &tf, &cam, &s, &|_, _| {}).unwrap();
                if i == 0 {
                    let r = voxlab::metrics::check_parity(
                        name,
                        &oracle.image,
                        &g.output.image,
                        voxlab::metrics::Tolerance::max_abs_rel(
                            raycast_tolerances(&s).1.max_abs_rel,
                        ),
                        None,
                    )
                    .unwrap();
                    assert!(r.passed, "GPU result wrong, not timed: {}", r.message);
                    continue;
                }
                kern.push(g.timings.kernel);
                e2e.push(g.timings.total - g.timings.setup);
                setup.push(g.timings.setup);
            }
            let (mk, lok, hik) = median_min_max(kern);
            let (me, _, _) = median_min_max(e2e);
            let (ms, _, _) = median_min_max(setup);
            gpu_cols = format!(
                "{mk:>8.4} ({lok:.4}–{hik:.4}) {me:>22.4} {ms:>8.3} {:>9.2} {:>9.2}",
                m32 / mk,
                m32 / me
            );
        }
        println!(
            "{name:<30} {m64:>8.3} ({lo64:.3}–{hi64:.3}) {m32:>8.3} ({lo32:.3}–{hi32:.3}) {:>8.2} {:>12.1} | {gpu_cols}",
            m64 / m32,
            samples as f64 / m32 / 1e6
        );
    }
    if let Some(ctx) = gpu {
        sessions(ctx, &args, n, size);
    }
}

/// GPU frames of an orbit, one-shot against one session (see the module docs).
fn sessions(ctx: &voxlab::gpu::GpuContext, args: &common::BenchArgs, n: usize, size: usize) {
    use voxlab::settings::{Filter, RenderSettings};
    let bspline = RenderSettings {
        filter: Filter::BsplineInterp,
        ..RenderSettings::default()
    };
    println!(
        "\nGPU frame, one-shot vs session reused ({} frames of an orbit)\n{:<40} {:>24} {:>24} {:>9} {:>14} {:>14} {:>11} {:>11}",
        args.runs,
        "case",
        "one-shot median (min–max) s",
        "session median (min–max) s",
        "one/sess",
        "one-shot s+u+p",
        "session s+u+p",
        "one kern s",
        "sess kern s"
    );
    // The benchmark's scene, and an interactive one: half the edge at half the size.
    for (n, size) in [(n, size), (n / 2, size / 2)] {
        for (variant, s) in [
            ("dvr-shaded-trilinear", RenderSettings::default()),
            ("dvr-shaded-bspline-interp", bspline.clone()),
        ] {
            let name = format!("session/{variant}-{n}-at-{size}");
            if args.wants(&name) {
                session_case(ctx, args, &name, n, size, &s);
            }
        }
    }
}

/// One row of [`sessions`].
fn session_case(
    ctx: &voxlab::gpu::GpuContext,
    args: &common::BenchArgs,
    name: &str,
    n: usize,
    size: usize,
    s: &voxlab::settings::RenderSettings,
) {
    use voxlab::camera::{Camera, Orbit, Projection};
    use voxlab::gpu::raycast::{render as one_shot, GpuTimings, RaycastSession};
    let (vol, tf, _) = raycast_scene(n, size).unwrap();
    let (vol, tf) = (&vol, &tf);
    let camera = |k: usize| {
        let orbit = Orbit {
            azimuth_deg: 30.0 + 10.0 * k as f64,
            elevation_deg: 20.0,
            distance_mm: Some(540.0),
        };
        let perspective = Projection::Perspective { fov_y_deg: 30.0 };
        Camera::orbit(
            glam::DVec3::ZERO,
            [256.0; 3],
            orbit,
            perspective,
            size,
            size,
        )
        .unwrap()
    };
    // The share of set-up, uploads and set-up passes in a frame's total.
    let overhead = |t: &GpuTimings| (t.setup + t.upload + t.prepare) / t.total;
    let bits = |f: &voxlab::frame::Frame| f.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    let mut session = RaycastSession::new(ctx, vol).unwrap();
    session.render(tf, &camera(0), s, &|_, _| {}).unwrap();
    let (mut t_one, mut t_sess, mut o_one, mut o_sess) = (vec![], vec![], vec![], vec![]);
    let (mut k_one, mut k_sess) = (vec![], vec![]);
    for k in 1..=args.runs {
        let cam = camera(k);
        let start = Instant::now();
        let a = one_shot(ctx, vol, tf, &cam, s, &|_, _| {}).unwrap();
        t_one.push(start.elapsed().as_secs_f64());
        let start = Instant::now();
        let b = session.render(tf, &cam, s, &|_, _| {}).unwrap();
        t_sess.push(start.elapsed().as_secs_f64());
        assert!(
            bits(&a.output.image) == bits(&b.output.image),
            "{name}: the session's frame differs from the one-shot frame; not timed"
        );
        o_one.push(overhead(&a.timings));
        o_sess.push(overhead(&b.timings));
        k_one.push(a.timings.kernel);
        k_sess.push(b.timings.kernel);
    }
    // Once; a prefiltered filter samples the B-spline coefficients (a set-up product)
    // and never reads the raw values' texture.
    let uploads = usize::from(!s.filter.prefiltered());
    assert_eq!(session.stats().volume_uploads, uploads, "{name}");
    let (m1, lo1, hi1) = median_min_max(t_one);
    let (ms, los, his) = median_min_max(t_sess);
    println!(
        "{name:<40} {m1:>8.4} ({lo1:.4}–{hi1:.4}) {ms:>8.4} ({los:.4}–{his:.4}) {:>9.2} {:>13.1}% {:>13.1}% {:>11.4} {:>11.4}",
        m1 / ms,
        100.0 * median_min_max(o_one).0,
        100.0 * median_min_max(o_sess).0,
        median_min_max(k_one).0,
        median_min_max(k_sess).0,
    );
}
