//! `cargo bench --bench ct`: CPU FBP and FDK (ramp filter + backprojection) in f32 and
//! f64, on exact Shepp–Logan projections (`cpu::project::project_phantom`): the scenes of
//! `voxlab bench`'s fbp and fdk cases (`voxlab::bench::ct::{fbp_scene, fdk_scene}`).
//!
//! Cases: parallel FBP of an `n²` image from 402 views over 180° (`n` = 512, detector
//! `n` bins), and FDK of a `n³` volume from 180 cone-beam views over 360° of `n²`
//! detectors (SID 1000 mm, SDD 1500 mm), `n` = 128 (`VOXLAB_BENCH_LARGE=1` adds 256).
//! Times are the whole reconstruction (filtering included, projection excluded),
//! medians of `VOXLAB_BENCH_RUNS` (default 5) runs after one warm-up, in milliseconds.
//! GPU rows: `gpu::fbp::fbp` end to end (CPU f32 ramp filter, upload, backprojection
//! dispatches, readback), when an adapter is found.
//! Under `cargo test` (no `--bench`) each case runs once at a tiny size.

mod common;
use common::{median_min_max, BenchArgs};

use std::time::Instant;
use voxlab::bench::ct::{fbp_scene, fdk_scene};
use voxlab::cpu::fbp::{fbp, Grid};
use voxlab::cpu::ramp::{filter_projections, FilterMethod, RampFilter};
use voxlab::ct::{Geometry, Projections};

fn none(_: usize, _: usize) {}

fn time<R: voxlab::real::Real + rustfft::FftNum>(
    args: &BenchArgs,
    p: &Projections<f64>,
    g: &Geometry,
    grid: &Grid,
) -> (f64, f64, f64) {
    let p = Projections::new(
        p.angles,
        p.rows,
        p.cols,
        p.data.iter().map(|&v| R::of(v)).collect(),
    )
    .unwrap();
    let (mut t, mut tf) = (Vec::new(), Vec::new());
    for run in 0..=args.runs {
        let t0 = Instant::now();
        let v = fbp(&p, g, RampFilter::RamLak, grid, &none).unwrap();
        std::hint::black_box(&v);
        let total = t0.elapsed().as_secs_f64() * 1e3;
        // The filtering share, timed on its own.
        let t1 = Instant::now();
        let q = filter_projections(&p, g, RampFilter::RamLak, FilterMethod::Fft).unwrap();
        std::hint::black_box(&q);
        if run > 0 {
            t.push(total);
            tf.push(t1.elapsed().as_secs_f64() * 1e3);
        }
    }
    let f = median_min_max(tf);
    println!(
        "|   (ramp filtering alone) | {} | {:.1} | {:.1} | {:.1} |",
        R::NAME,
        f.0,
        f.1,
        f.2
    );
    median_min_max(t)
}

fn time_gpu(
    args: &BenchArgs,
    ctx: &voxlab::gpu::GpuContext,
    p: &Projections<f64>,
    g: &Geometry,
    grid: &Grid,
) -> (f64, f64, f64) {
    let p = Projections::new(
        p.angles,
        p.rows,
        p.cols,
        p.data.iter().map(|&v| v as f32).collect(),
    )
    .unwrap();
    let mut t = Vec::new();
    for run in 0..=args.runs {
        let t0 = Instant::now();
        let v = voxlab::gpu::fbp::fbp(ctx, &p, g, RampFilter::RamLak, grid).unwrap();
        std::hint::black_box(&v);
        if run > 0 {
            t.push(t0.elapsed().as_secs_f64() * 1e3);
        }
    }
    median_min_max(t)
}

fn main() {
    let gpu = voxlab::gpu::GpuContext::shared().ok();
    let args = BenchArgs::from_env();
    let large = std::env::var("VOXLAB_BENCH_LARGE").is_ok_and(|v| v == "1");
    println!("| case | precision | median ms | min | max |\n|---|---|---|---|---|");
    let fbp_n = if args.smoke { 32 } else { 512 };
    let views = if args.smoke { 20 } else { 402 };
    let name = format!("fbp {fbp_n}² from {views} views");
    if args.wants(&name) {
        let (p, g, grid) = fbp_scene(fbp_n, views).unwrap();
        for (prec, r) in [
            ("f32", time::<f32>(&args, &p, &g, &grid)),
            ("f64", time::<f64>(&args, &p, &g, &grid)),
        ] {
            println!("| {name} | {prec} | {:.1} | {:.1} | {:.1} |", r.0, r.1, r.2);
        }
        if let Some(ctx) = &gpu {
            let r = time_gpu(&args, ctx, &p, &g, &grid);
            println!(
                "| {name} | GPU f32 (end to end) | {:.1} | {:.1} | {:.1} |",
                r.0, r.1, r.2
            );
        }
    }
    let sizes: Vec<usize> = if args.smoke {
        vec![16]
    } else if large {
        vec![128, 256]
    } else {
        vec![128]
    };
    for n in sizes {
        let views = if args.smoke { 12 } else { 180 };
        let name = format!("fdk {n}³ from {views} × {n}² views");
        if !args.wants(&name) {
            continue;
        }
        let (p, g, grid) = fdk_scene(n, views).unwrap();
        for (prec, r) in [
            ("f32", time::<f32>(&args, &p, &g, &grid)),
            ("f64", time::<f64>(&args, &p, &g, &grid)),
        ] {
            println!("| {name} | {prec} | {:.1} | {:.1} | {:.1} |", r.0, r.1, r.2);
        }
        if let Some(ctx) = &gpu {
            let r = time_gpu(&args, ctx, &p, &g, &grid);
            println!(
                "| {name} | GPU f32 (end to end) | {:.1} | {:.1} | {:.1} |",
                r.0, r.1, r.2
            );
        }
    }
}
