//! `cargo bench --bench d2vr`: D²VR (`cpu::d2vr` in f32, `gpu::d2vr` with f32 and f16
//! projection storage) at the sizes of Xu & Mueller's Table 1 — 128 cone-beam
//! projections of 128², a 128³-equivalent virtual grid, a 256² image — and at half that
//! ("half": 64 × 64², 64³, 128²), shaded DVR of the modified Shepp–Logan head, with the
//! paper's columns: GFS (density only, gradients by central differences), GFR
//! (density + gradient from the projections), +B (bounding cylinder), +B+OC (plus early
//! ray termination at 0.95), and the fraction of samples reconstructed. The projections
//! are exact (`project_phantom`), FDK-filtered by `cpu::ramp` (Ram-Lak, FFT path, f32).
//! Each GPU image is checked against the CPU f32 image first (max relative difference
//! printed). Each
//! case: one warm-up run, then `VOXLAB_BENCH_RUNS` (default 5) timed runs; medians in
//! seconds. Under `cargo test` each case runs once on a tiny input (smoke test).

mod common;
use common::median_min_max;

use glam::DVec3;
use std::time::Instant;
use voxlab::camera::{Camera, Orbit, Projection};
use voxlab::cpu::d2vr::{render_d2vr, D2vrGradient, D2vrGrid, D2vrOptions};
use voxlab::cpu::project::project_phantom;
use voxlab::cpu::ramp::{filter_projections, FilterMethod, RampFilter};
use voxlab::ct::{Geometry, Projections};
use voxlab::gpu::d2vr::{self as gd2vr, ProjStorage};
use voxlab::gpu::GpuContext;
use voxlab::phantom::Phantom;
use voxlab::settings::{Mode, RenderSettings};
use voxlab::transfer::{ControlPoint, TransferFunction, WindowMap};

fn tf() -> TransferFunction {
    let p = |value: f64, rgba: [f64; 4]| ControlPoint { value, rgba };
    TransferFunction {
        name: "head".into(),
        domain: [0.0, 1.2],
        points: vec![
            p(0.15, [0.0, 0.0, 0.0, 0.0]),
            p(0.3, [0.8, 0.5, 0.4, 0.05]),
            p(0.5, [0.8, 0.5, 0.4, 0.05]),
            p(0.8, [1.0, 1.0, 0.9, 0.6]),
        ],
        window: WindowMap::default(),
    }
}

fn main() {
    let args = common::BenchArgs::from_env();
    let ctx = match GpuContext::new() {
        Ok(c) => Some(c),
        Err(e) => {
            eprintln!("no GPU: {e}; CPU figures only");
            None
        }
    };
    let cases: &[(&str, usize, usize, usize, usize)] = if args.smoke {
        &[("smoke", 16, 16, 16, 16)]
    } else {
        // name, projections, detector side, grid side, image side
        &[("half", 64, 64, 64, 128), ("table1", 128, 128, 128, 256)]
    };
    println!("| case | variant | CPU f32 (s) | GPU f32 (s) | GPU f16 (s) | reconstructed | GPU vs CPU (f32 / f16) |");
    println!("|---|---|---|---|---|---|---|");
    for &(name, na, det, n, img) in cases {
        if !args.wants(name) {
            continue;
        }
        // 256 mm field: the detector covers it at the isocentre (magnification 1.5).
        let g = Geometry::cone_rtk(
            600.0,
            900.0,
            det,
            det,
            384.0 / det as f64,
            384.0 / det as f64,
            Geometry::even_angles(na, 360.0),
        )
        .unwrap();
        let ph = Phantom::shepp_logan_modified();
        let raw = project_phantom(&ph, &g).unwrap();
        let raw = Projections::new(
            raw.angles,
            raw.rows,
            raw.cols,
            raw.data.iter().map(|&v| v as f32).collect(),
        )
        .unwrap();
        let q = filter_projections(&raw, &g, RampFilter::RamLak, FilterMethod::Fft).unwrap();
        let grid = D2vrGrid::centred([n; 3], 256.0 / n as f64).unwrap();
        let cam = Camera::orbit(
            DVec3::ZERO,
            [256.0; 3],
            Orbit {
                azimuth_deg: 30.0,
                elevation_deg: 20.0,
                distance_mm: None,
            },
            Projection::Orthographic {
                width_mm: 0.0,
                height_mm: 0.0,
            },
            img,
            img,
        )
        .unwrap();
        let tf = tf();
        let variants = [
            ("GFS", D2vrGradient::Gfs, false, 1.0),
            ("GFR", D2vrGradient::Gfr, false, 1.0),
            ("GFS+B", D2vrGradient::Gfs, true, 1.0),
            ("GFS+B+OC", D2vrGradient::Gfs, true, 0.95),
            ("GFR+B+OC", D2vrGradient::Gfr, true, 0.95),
        ];
        for (vname, gradient, cylinder, ert) in variants {
            let s = RenderSettings {
                mode: Mode::Dvr,
                step: 1.0,
                ert_threshold: ert,
                ..RenderSettings::default()
            };
            let o = D2vrOptions {
                gradient,
                cylinder,
                value_range: (0.0, 1.0),
            };
            let cpu_run = || {
                let t = Instant::now();
                let out = render_d2vr(&q, &g, &grid, &tf, &cam, &s, &o, None, &|_, _| {}).unwrap();
                (t.elapsed().as_secs_f64(), out)
            };
            let (_, cpu_out) = cpu_run();
            let cpu_t = median_min_max((0..args.runs).map(|_| cpu_run().0).collect()).0;
            let mut gpu_t = [f64::NAN; 2];
            let mut gpu_err = [f64::NAN; 2];
            if let Some(ctx) = &ctx {
                for (i, st) in [ProjStorage::F32, ProjStorage::F16].into_iter().enumerate() {
                    let run = || {
                        gd2vr::render_d2vr(ctx, &q, &g, &grid, &tf, &cam, &s, &o, None, st).unwrap()
                    };
                    let first = run();
                    let a = &cpu_out.render.image.data;
                    let peak = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                    gpu_err[i] = a
                        .iter()
                        .zip(&first.render.image.data)
                        .map(|(x, y)| (x - y).abs())
                        .fold(0.0, f64::max)
                        / peak;
                    gpu_t[i] =
                        median_min_max((0..args.runs).map(|_| run().timings.total).collect()).0;
                }
            }
            println!(
                "| {name} ({na}×{det}², {n}³, {img}²) | {vname} | {cpu_t:.3} | {:.3} | {:.3} | {:.1} % | {:.1e} / {:.1e} |",
                gpu_t[0],
                gpu_t[1],
                100.0 * cpu_out.stats.fraction(),
                gpu_err[0],
                gpu_err[1]
            );
        }
    }
}
