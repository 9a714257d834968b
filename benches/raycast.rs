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
}
