//! `cargo bench --bench raycast`: the ray caster on the CPU f64 oracle, the CPU f32
//! baseline and the GPU, on the same inputs. GPU figures: kernel time from timestamp
//! queries, and end to end (upload, set-up passes, kernel, readback; shader compilation
//! and pipeline creation reported apart as set-up). Speedups are quoted against f32.
//! Each GPU result is checked against the f64 oracle first (a fast wrong answer does
//! not count). Each case: one warm-up run, then `VOXLAB_BENCH_RUNS`
//! (default 5) timed runs; the median, minimum and maximum are printed with the
//! f64/f32 ratio of medians. Set-up (phantom sampling) is outside the timed region.
//! Pass a substring to run only matching cases: `cargo bench --bench raycast -- mip`.
//! Under `cargo test` (no `--bench` argument) each case runs once on a tiny input, as
//! a smoke test of the benchmark code.

mod common;
use common::median_min_max;

use std::time::Instant;
use voxlab::camera::{Camera, Orbit, Projection};
use voxlab::cpu::raycast::render;
use voxlab::phantom::Phantom;
use voxlab::settings::{Filter, Mode, RenderSettings};
use voxlab::transfer::TransferFunction;
use voxlab::AnyVolume;

fn main() {
    let args = common::BenchArgs::from_env();
    let (smoke, runs) = (args.smoke, args.runs);
    let (n, size) = if smoke { (16, 16) } else { (128, 256) };
    let vol: AnyVolume = Phantom::shepp_logan_modified()
        .sample([n; 3])
        .unwrap()
        .into();
    let tf = TransferFunction::preset("phantom").unwrap();
    let cam = Camera::orbit(
        glam::DVec3::ZERO,
        [256.0; 3],
        Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            distance_mm: Some(540.0),
        },
        Projection::Perspective { fov_y_deg: 30.0 },
        size,
        size,
    )
    .unwrap();
    let cases: Vec<(&str, RenderSettings)> = vec![
        ("dvr-shaded-trilinear", RenderSettings::default()),
        (
            "dvr-shaded-catmull-rom",
            RenderSettings {
                filter: Filter::CatmullRom,
                ..RenderSettings::default()
            },
        ),
        (
            "mip-trilinear",
            RenderSettings {
                mode: Mode::Mip,
                ..RenderSettings::default()
            },
        ),
        (
            "xray-trilinear",
            RenderSettings {
                mode: Mode::Xray,
                ..RenderSettings::default()
            },
        ),
    ];
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
        "{:<24} {:>22} {:>22} {:>8} {:>12} | {:>22} {:>22} {:>8} {:>9} {:>9}",
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
                        voxlab::metrics::Tolerance {
                            max_abs: 1e-3
                                * oracle
                                    .image
                                    .finite_range()
                                    .map_or(1.0, |r| r.1.abs().max(1.0)),
                            rmse: f64::INFINITY,
                        },
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
            "{name:<24} {m64:>8.3} ({lo64:.3}–{hi64:.3}) {m32:>8.3} ({lo32:.3}–{hi32:.3}) {:>8.2} {:>12.1} | {gpu_cols}",
            m64 / m32,
            samples as f64 / m32 / 1e6
        );
    }
}
