//! `cargo bench --bench d2vr`: D²VR (`cpu::d2vr` in f32, `gpu::d2vr` with f32 and f16
//! projection storage, and f32 projections in textures filtered by the texture unit) at the sizes of Xu & Mueller's Table 1 — 128 cone-beam
//! projections of 128², a 128³-equivalent virtual grid, a 256² image — and at half that
//! ("half": 64 × 64², 64³, 128²), shaded DVR of the modified Shepp–Logan head, with the
//! paper's columns: GFS (density only, gradients by central differences), GFR
//! (density + gradient from the projections), +B (bounding cylinder), +B+OC (plus early
//! ray termination at 0.95), +M (the occupancy mask), and the fraction of samples
//! reconstructed. The scenes and variants are `voxlab::bench::d2vr`'s: exact projections
//! (`project_phantom`), FDK-filtered by `cpu::ramp` (Ram-Lak, FFT path, f64, rendered
//! from their f32 rounding).
//! Each GPU image is checked against the CPU f32 image first (max relative difference
//! printed). Each
//! case: one warm-up run, then `VOXLAB_BENCH_RUNS` (default 5) timed runs; medians in
//! seconds. Under `cargo test` each case runs once on a tiny input (smoke test).

mod common;
use common::median_min_max;

use std::time::Instant;
use voxlab::bench::d2vr::{
    d2vr_mask, d2vr_scene, d2vr_settings, d2vr_variants, D2vrConfig, HALF, TABLE1, TINY,
};
use voxlab::cpu::d2vr::render_d2vr;
use voxlab::gpu::d2vr::{self as gd2vr, ProjStorage};
use voxlab::gpu::plan::Sampling;
use voxlab::gpu::GpuContext;

fn main() {
    let args = common::BenchArgs::from_env();
    let ctx = match GpuContext::shared() {
        Ok(c) => Some(c),
        Err(e) => {
            eprintln!("no GPU: {e}; CPU figures only");
            None
        }
    };
    let configs = if args.smoke {
        vec![D2vrConfig {
            name: "smoke",
            ..TINY
        }]
    } else {
        vec![HALF, TABLE1]
    };
    println!("| case | variant | CPU f32 (s) | GPU f32 (s) | GPU f32 textures (s) | GPU f16 (s) | reconstructed | GPU vs CPU (f32 / textures / f16) |");
    println!("|---|---|---|---|---|---|---|---|");
    for c in configs {
        if !args.wants(c.name) {
            continue;
        }
        let sc = d2vr_scene(&c).unwrap();
        let q = &sc.filtered_f32;
        let (g, grid, tf, cam) = (&sc.geometry, &sc.grid, &sc.tf, &sc.camera);
        let mask = d2vr_mask(&sc).unwrap();
        for v in d2vr_variants() {
            let (s, o) = d2vr_settings(&v);
            let m = v.mask.then_some(&mask);
            let cpu_run = || {
                let t = Instant::now();
                let out = render_d2vr(q, g, grid, tf, cam, &s, &o, m, &|_, _| {}).unwrap();
                (t.elapsed().as_secs_f64(), out)
            };
            let (_, cpu_out) = cpu_run();
            let cpu_t = median_min_max((0..args.runs).map(|_| cpu_run().0).collect()).0;
            let mut gpu_t = [f64::NAN; 3];
            let mut gpu_err = [f64::NAN; 3];
            let formats = [
                (ProjStorage::F32, Sampling::Exact),
                (ProjStorage::F32, Sampling::Hardware),
                (ProjStorage::F16, Sampling::Exact),
            ];
            if let Some(ctx) = ctx {
                for (i, (st, sm)) in formats.into_iter().enumerate() {
                    let run = || gd2vr::render_d2vr(ctx, q, g, grid, tf, cam, &s, &o, m, st, sm);
                    // An adapter that cannot filter f32 textures leaves the column empty.
                    let Ok(first) = run() else {
                        continue;
                    };
                    let a = &cpu_out.render.image.data;
                    let peak = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                    gpu_err[i] = a
                        .iter()
                        .zip(&first.render.image.data)
                        .map(|(x, y)| (x - y).abs())
                        .fold(0.0, f64::max)
                        / peak;
                    gpu_t[i] = median_min_max(
                        (0..args.runs)
                            .map(|_| run().unwrap().timings.total)
                            .collect(),
                    )
                    .0;
                }
            }
            println!(
                "| {} ({}×{}², {}³, {}²) | {} | {cpu_t:.3} | {:.3} | {:.3} | {:.3} | {:.1} % | {:.1e} / {:.1e} / {:.1e} |",
                c.name,
                c.views,
                c.detector,
                c.grid,
                c.image,
                v.name,
                gpu_t[0],
                gpu_t[1],
                gpu_t[2],
                100.0 * cpu_out.stats.fraction(),
                gpu_err[0],
                gpu_err[1],
                gpu_err[2]
            );
        }
    }
}
