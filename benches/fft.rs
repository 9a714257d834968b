//! `cargo bench --bench fft`: the N-D complex FFT on the CPU in f64 and f32
//! (`cpu::fft::fft_nd`, all rayon threads) and on the GPU (Stockham and split-stream,
//! `gpu::fft::fft_nd_timed`), on the same random inputs (forward, unnormalised), plus
//! the low-pass task of Jansen et al.'s Table 1: a 2-D forward FFT, a multiplication by
//! a Gaussian low-pass in frequency space, and the inverse FFT.
//!
//! GPU figures: the passes from timestamp queries ("kernel") and end to end (upload,
//! passes, readback; set-up — shaders, pipelines, twiddle tables — excluded). For the
//! low-pass task the GPU runs the two transforms and the multiplication happens on the
//! host between them, so its end-to-end time includes two round trips. Each GPU result
//! is checked against the CPU f64 result first (relative L2 ≤ 1e-6·log2 N); a fast
//! wrong answer aborts the benchmark. Each case: one warm-up run, then
//! `VOXLAB_BENCH_RUNS` (default 5) timed runs; medians are printed as a Markdown
//! table, in milliseconds. `VOXLAB_BENCH_LARGE=1` adds 256³. Pass a substring to run
//! only matching cases: `cargo bench --bench fft -- 3d`. Under `cargo test` (no
//! `--bench` argument) each case runs once on a tiny input, as a smoke test.

mod common;
use common::median_min_max;

use rayon::prelude::*;
use rustfft::num_complex::Complex;
use std::time::Instant;
use voxlab::bench::fourier::fft_input;
use voxlab::cpu::dft::{Direction, Normalization};
use voxlab::cpu::fft::fft_nd;
use voxlab::gpu::fft::{fft_nd_timed, GpuFftVariant};
use voxlab::gpu::GpuContext;
use voxlab::jobs::fft::rel_l2;

const FWD: Direction = Direction::Forward;
const INV: Direction = Direction::Inverse;
const NORM: Normalization = Normalization::Unnormalized;

fn median(t: Vec<f64>) -> f64 {
    median_min_max(t).0
}

/// The Gaussian low-pass `exp(−|f|² / (2σ²))`, `f` in cycles per sample (numpy's
/// `fftfreq` layout, DC at index 0), σ = 0.1.
fn gaussian(shape: &[usize]) -> Vec<f64> {
    let (ny, nx) = (shape[0], shape[1]);
    let freq = |k: usize, n: usize| {
        let k = if k < n.div_ceil(2) {
            k as f64
        } else {
            k as f64 - n as f64
        };
        k / n as f64
    };
    let s2 = 2.0 * 0.1f64.powi(2);
    (0..ny * nx)
        .map(|i| {
            let (fy, fx) = (freq(i / nx, ny), freq(i % nx, nx));
            (-(fx * fx + fy * fy) / s2).exp()
        })
        .collect()
}

/// The task on the CPU: forward, multiply, inverse (in place).
fn lowpass_cpu<T: rustfft::FftNum>(d: &mut [Complex<T>], shape: &[usize], g: &[T]) {
    fft_nd(d, shape, FWD, NORM);
    d.par_iter_mut().zip(g).for_each(|(v, &w)| *v = *v * w);
    fft_nd(d, shape, INV, NORM);
}

/// One GPU run of a case: (result, kernel seconds, end-to-end seconds).
fn gpu_run(
    ctx: &GpuContext,
    x: &[Complex<f32>],
    shape: &[usize],
    variant: GpuFftVariant,
    filter: Option<&[f32]>,
) -> voxlab::Result<(Vec<Complex<f32>>, f64, f64)> {
    let start = Instant::now();
    let a = fft_nd_timed(ctx, x, shape, FWD, NORM, variant)?;
    let Some(g) = filter else {
        let t = a.timings;
        return Ok((a.data, t.kernel, t.total - t.setup));
    };
    let mut mid = a.data;
    mid.par_iter_mut().zip(g).for_each(|(v, &w)| *v *= w);
    let b = fft_nd_timed(ctx, &mid, shape, INV, NORM, variant)?;
    let setup = a.timings.setup + b.timings.setup;
    let e2e = start.elapsed().as_secs_f64() - setup;
    Ok((b.data, a.timings.kernel + b.timings.kernel, e2e))
}

fn main() {
    let args = common::BenchArgs::from_env();
    let (smoke, runs) = (args.smoke, args.runs);
    let large = std::env::var("VOXLAB_BENCH_LARGE").is_ok_and(|v| v == "1");
    // (name, shape, low-pass task?)
    let mut cases: Vec<(String, Vec<usize>, bool)> = Vec::new();
    let (sizes2, sizes3, lp): (Vec<usize>, Vec<usize>, Vec<usize>) = if smoke {
        (vec![16], vec![8], vec![16])
    } else {
        let mut s3 = vec![64, 128];
        if large {
            s3.push(256);
        }
        (vec![256, 512, 1024], s3, vec![512, 1024])
    };
    for n in sizes2 {
        cases.push((format!("2d {n}²"), vec![n, n], false));
    }
    for n in sizes3 {
        cases.push((format!("3d {n}³"), vec![n, n, n], false));
    }
    for n in lp {
        cases.push((format!("low-pass {n}²"), vec![n, n], true));
    }
    let gpu = GpuContext::shared().ok();
    println!(
        "FFT, forward unnormalised complex, {} threads, {runs} runs after 1 warm-up; medians in ms",
        rayon::current_num_threads()
    );
    match &gpu {
        Some(ctx) => println!(
            "GPU: {} ({}, {})",
            ctx.summary.name, ctx.summary.backend, ctx.summary.driver_info
        ),
        None => println!("GPU: none found; GPU columns left empty"),
    }
    println!();
    println!(
        "| case | N | CPU f64 | CPU f32 | f32 GFLOP/s | Stockham kernel | Stockham e2e | Stockham rel L2 | split-stream kernel | split-stream e2e | split-stream rel L2 |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (name, shape, task) in cases {
        if !args.wants(&name) {
            continue;
        }
        let total: usize = shape.iter().product();
        let x = fft_input(&shape);
        let x32: Vec<Complex<f32>> = x
            .iter()
            .map(|v| Complex::new(v.re as f32, v.im as f32))
            .collect();
        let g64 = if task { gaussian(&shape) } else { Vec::new() };
        let g32: Vec<f32> = g64.iter().map(|&v| v as f32).collect();
        let mut reference = Vec::new();
        let mut t64 = Vec::new();
        for i in 0..=runs {
            let mut d = x.clone();
            let start = Instant::now();
            if task {
                lowpass_cpu(&mut d, &shape, &g64);
            } else {
                fft_nd(&mut d, &shape, FWD, NORM);
            }
            let t = start.elapsed().as_secs_f64();
            if i == 0 {
                reference = d;
            } else {
                t64.push(t);
            }
        }
        let mut t32 = Vec::new();
        for i in 0..=runs {
            let mut d = x32.clone();
            let start = Instant::now();
            if task {
                lowpass_cpu(&mut d, &shape, &g32);
            } else {
                fft_nd(&mut d, &shape, FWD, NORM);
            }
            if i > 0 {
                t32.push(start.elapsed().as_secs_f64());
            }
        }
        let (m64, m32) = (median(t64), median(t32));
        // The task counts two transforms.
        let transforms = if task { 2.0 } else { 1.0 };
        let gflops = transforms * 5.0 * total as f64 * (total as f64).log2() / m32 / 1e9;
        let mut cols = String::new();
        for variant in [GpuFftVariant::Stockham, GpuFftVariant::SplitStream] {
            let Some(ctx) = &gpu else {
                cols.push_str(" | | |");
                continue;
            };
            let filter = task.then_some(&g32[..]);
            // An array the adapter refuses (too large for one binding) leaves the cells
            // empty; any other failure aborts.
            let (out, _, _) = match gpu_run(ctx, &x32, &shape, variant, filter) {
                Ok(r) => r,
                Err(e @ voxlab::Error::TooLarge { .. }) => {
                    eprintln!("{name} {variant:?}: {e}");
                    cols.push_str(" refused | | |");
                    continue;
                }
                Err(e) => panic!("{name} {variant:?}: {e}"),
            };
            let err = rel_l2(&out, &reference);
            let tol = 1e-6 * (total as f64).log2();
            assert!(
                err <= tol,
                "{name} {variant:?}: GPU result wrong ({err:e} > {tol:e}), not timed"
            );
            let (mut kern, mut e2e) = (Vec::new(), Vec::new());
            for _ in 0..runs {
                let (_, k, e) = gpu_run(ctx, &x32, &shape, variant, filter).unwrap();
                kern.push(k);
                e2e.push(e);
            }
            cols.push_str(&format!(
                " {:.2} | {:.2} | {err:.1e} |",
                median(kern) * 1e3,
                median(e2e) * 1e3
            ));
        }
        println!(
            "| {name} | {total} | {:.2} | {:.2} | {gflops:.2} |{cols}",
            m64 * 1e3,
            m32 * 1e3
        );
    }
}
