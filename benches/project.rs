//! `cargo bench --bench project`: Joseph forward projection
//! (`cpu::project::project_volume` in f64 and f32, all rayon threads, and
//! `gpu::project::project_volume_timed`) of the modified Shepp–Logan phantom sampled
//! on an n³ grid (`voxlab::bench::ct::project_scene`, the scenes of `voxlab bench`'s
//! project cases), for a cone beam (RTK's geometry, SID 1000 mm, SDD 1500 mm, 360°) and
//! a parallel stack, plus the exact analytic projection for scale.
//!
//! GPU figures: "project" (dispatches and readbacks) and "total" (also the upload and
//! shader compilation). Every GPU and f32 result is first checked against the CPU
//! f64 result (max relative error within `voxlab::bench::ct::project_tol`; a fast
//! wrong answer aborts). One warm-up, then `VOXLAB_BENCH_RUNS` (default 5) timed runs;
//! medians in milliseconds as a Markdown table, with rays per second. Default case: 128³ → 180 × 128² cone.
//! `VOXLAB_BENCH_LARGE=1` adds 256³ → 360 × 256². Pass a substring to run only
//! matching cases: `cargo bench --bench project -- cone`. Under `cargo test` each case
//! runs once on a 16³ grid, as a smoke test.

mod common;
use common::{median_min_max, BenchArgs};

use std::time::Instant;
use voxlab::bench::ct::{project_geometry, project_scene, project_tol};
use voxlab::cpu::project::{project_phantom, project_volume, Grid, ProjectOptions};
use voxlab::ct::{Geometry, Projections};
use voxlab::gpu::project::project_volume_timed;
use voxlab::gpu::GpuContext;
use voxlab::phantom::Phantom;

fn time<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut out = f();
    let mut t = Vec::new();
    for _ in 0..runs {
        let s = Instant::now();
        out = f();
        t.push(s.elapsed().as_secs_f64());
    }
    (median_min_max(t).0, out)
}

/// max |p − oracle| / max |oracle| (`metrics::error_stats`; ∞ on a NaN/Inf mismatch).
fn max_rel<T: Copy + Into<f64>>(p: &Projections<T>, oracle: &Projections<f64>) -> f64 {
    voxlab::metrics::error_stats(&oracle.data, &p.data, f64::INFINITY)
        .infinite_if_mismatched()
        .max_abs_rel
}

fn main() {
    let args = BenchArgs::from_env();
    let ph = Phantom::shepp_logan_modified();
    let mut cases: Vec<(String, usize, Geometry)> = Vec::new();
    let mut sizes = vec![(128usize, 180usize)];
    if std::env::var("VOXLAB_BENCH_LARGE").as_deref() == Ok("1") {
        sizes.push((256, 360));
    }
    if args.smoke {
        sizes = vec![(16, 8)];
    }
    for (n, views) in sizes {
        // A 256 mm field at the isocentre: n detector pixels.
        let cone = project_geometry(n, views, true).unwrap();
        let par = project_geometry(n, views, false).unwrap();
        cases.push((format!("cone {n}³ → {views}×{n}²"), n, cone));
        cases.push((format!("parallel {n}³ → {views}×{n}²"), n, par));
    }
    let ctx = GpuContext::shared().ok();
    if let Some(c) = &ctx {
        println!("GPU: {}", c.describe());
    } else {
        println!("GPU: none (GPU columns empty)");
    }
    println!(
        "| case | analytic f64 | CPU f64 | CPU f32 | GPU project | GPU total | Mrays/s (CPU f64 / f32 / GPU) | f32 / GPU max rel err |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let opts = ProjectOptions::default();
    for (name, n, g) in cases {
        if !args.wants(&name) {
            continue;
        }
        let (g64, _) = project_scene(n, 1, false).unwrap();
        let g32 = Grid::<f32>::new(g64.dims, g64.affine, g64.to_f32()).unwrap();
        let rays = (g.n_angles() * g.rows * g.cols) as f64 / 1e6;
        let (ta, _) = time(args.runs.min(1), || project_phantom(&ph, &g).unwrap());
        let (t64, oracle) = time(args.runs, || project_volume(&g64, &g, &opts).unwrap());
        let (t32, p32) = time(args.runs, || project_volume(&g32, &g, &opts).unwrap());
        let e32 = max_rel(&p32, &oracle);
        let tol = project_tol(&g, n).max_abs_rel;
        assert!(e32 < tol, "{name}: CPU f32 max rel {e32}");
        let (gp, gt, eg) = match &ctx {
            Some(c) => {
                let mut tp = Vec::new();
                let mut tt = Vec::new();
                let mut last = None;
                for i in 0..=args.runs {
                    let (p, t) = project_volume_timed(c, &g32, &g, &opts).unwrap();
                    if i > 0 {
                        tp.push(t.project);
                        tt.push(t.total);
                    }
                    last = Some(p);
                }
                let e = max_rel(&last.unwrap(), &oracle);
                assert!(e < tol, "{name}: GPU max rel {e}");
                (median_min_max(tp).0, median_min_max(tt).0, e)
            }
            None => (f64::NAN, f64::NAN, f64::NAN),
        };
        println!(
            "| {name} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.1} / {:.1} / {:.1} | {e32:.1e} / {eg:.1e} |",
            ta * 1e3,
            t64 * 1e3,
            t32 * 1e3,
            gp * 1e3,
            gt * 1e3,
            rays / t64,
            rays / t32,
            rays / gp,
        );
    }
}
