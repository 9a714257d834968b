//! `cargo bench --bench iterative`: the pieces of one iteration of the CPU solvers on
//! the peers' problem (`scripts/peers/iterative_peers.py`): Joseph's matched pair
//! (`cpu::project::JosephPair`) on a 256² parallel grid seen from 180 views of 256
//! bins (scikit-image's geometry), in f64 and f32 on all rayon threads — the forward
//! pass `A x` and the transpose `Aᵀ y` over every view (as `JosephPair::transpose`
//! runs it — in f32 on a CPU with AVX-512F a gather — and by planes, the pair
//! `without_gather`), the same over one view (an
//! OS-SART update with one view per subset), and a whole SIRT iteration
//! (`cpu::iterative::solve`, 10 iterations, divided by 10). A second table times
//! OS-SART with one view per subset as the peers' comparison runs it (λ = 0.15, the
//! inscribed disc as the support, 10 passes): the time per pass, and that time over
//! the 180 subsets (each pass also projects every view once for the residual it
//! logs: the `A x` column above).
//!
//! One warm-up, then `VOXLAB_BENCH_RUNS` (default 5) timed runs; medians in
//! milliseconds as a Markdown table. Pass a substring to run only matching rows:
//! `cargo bench --bench iterative -- f32`. Under `cargo test` each row runs once on a
//! 32² grid from 12 views, as a smoke test.

mod common;
use common::{median_min_max, BenchArgs};

use std::time::Instant;
use voxlab::cpu::fbp::parallel_stack_grid;
use voxlab::cpu::iterative::{solve, IterativeOptions, MatchedPair, Method, Problem};
use voxlab::cpu::project::JosephPair;
use voxlab::ct::Geometry;
use voxlab::real::Real;

fn time<T>(runs: usize, mut f: impl FnMut() -> T) -> f64 {
    f();
    let mut t = Vec::new();
    for _ in 0..runs {
        let s = Instant::now();
        std::hint::black_box(f());
        t.push(s.elapsed().as_secs_f64());
    }
    median_min_max(t).0
}

/// The pair of the peers' problem and a test image.
fn problem<R: Real>(n: usize, views: usize) -> (JosephPair<R>, Vec<R>) {
    let g = Geometry::parallel_skimage(n, Geometry::even_angles(views, 180.0)).unwrap();
    let grid = parallel_stack_grid(n, &g);
    let pair = JosephPair::<R>::new(grid.dims, grid.affine, &g).unwrap();
    let x: Vec<R> = (0..pair.n_voxels())
        .map(|i| R::of(((i * 7919) % 1000) as f64 / 1000.0))
        .collect();
    (pair, x)
}

fn row<R: Real>(args: &BenchArgs, n: usize, views: usize) {
    let name = format!("{n}² from {views} views, {}", R::NAME);
    if !args.wants(&name) {
        return;
    }
    let (pair, x) = problem::<R>(n, views);
    let all: Vec<usize> = (0..views).collect();
    let b = pair.forward(&x, &all);
    let one = [views / 3];
    let fwd = time(args.runs, || pair.forward(&x, &all));
    let tr = time(args.runs, || pair.transpose(&b, &all));
    let planes = problem::<R>(n, views).0.without_gather();
    let tr_planes = time(args.runs, || planes.transpose(&b, &all));
    let b1 = pair.forward(&x, &one);
    let fwd1 = time(args.runs, || pair.forward(&x, &one));
    let tr1 = time(args.runs, || pair.transpose(&b1, &one));
    let opts = IterativeOptions {
        method: Method::Sirt,
        iterations: 10,
        ..IterativeOptions::default()
    };
    let prob = Problem {
        pair: &pair as &dyn MatchedPair<R>,
        b: &b,
        support: None,
    };
    let x0 = vec![R::zero(); pair.n_voxels()];
    let sirt = time(args.runs.min(3), || {
        solve(&prob, x0.clone(), &opts, &mut |_, _, _| Ok(())).unwrap()
    }) / 10.0;
    let ms = |t: f64| format!("{:.2}", t * 1e3);
    println!(
        "| {name} | {} | {} | {} | {} | {} | {} |",
        ms(fwd),
        ms(tr),
        ms(tr_planes),
        ms(fwd1),
        ms(tr1),
        ms(sirt)
    );
}

/// OS-SART with one view per subset, as `scripts/peers/iterative_peers.py` runs it.
fn sart_row<R: Real>(args: &BenchArgs, n: usize, views: usize) {
    let name = format!("{n}² from {views} views, {}", R::NAME);
    if !args.wants(&name) {
        return;
    }
    let (pair, x) = problem::<R>(n, views);
    let all: Vec<usize> = (0..views).collect();
    let b = pair.forward(&x, &all);
    // The inscribed disc (radius n/2 about pixel n/2), as `voxlab reconstruct`.
    let h = (n / 2) as i64;
    let support: Vec<bool> = (0..n * n)
        .map(|i| {
            let (c, r) = ((i % n) as i64 - h, (i / n) as i64 - h);
            c * c + r * r <= h * h
        })
        .collect();
    let passes = 10;
    let opts = IterativeOptions {
        method: Method::OsSart,
        iterations: passes,
        subsets: views,
        relaxation: 0.15,
        ..IterativeOptions::default()
    };
    let prob = Problem {
        pair: &pair as &dyn MatchedPair<R>,
        b: &b,
        support: Some(&support),
    };
    let x0 = vec![R::zero(); pair.n_voxels()];
    let pass = time(args.runs.min(3), || {
        solve(&prob, x0.clone(), &opts, &mut |_, _, _| Ok(())).unwrap()
    }) / passes as f64;
    println!(
        "| {name} | {:.2} | {:.1} |",
        pass * 1e3,
        pass * 1e6 / views as f64
    );
}

fn main() {
    let args = BenchArgs::from_env();
    let (n, views) = if args.smoke { (32, 12) } else { (256, 180) };
    println!("threads: {}", rayon::current_num_threads());
    println!(
        "| problem | A x (ms) | Aᵀ y (ms) | Aᵀ y by planes | A x, one view | Aᵀ y, one view | SIRT iteration |"
    );
    println!("|---|---|---|---|---|---|---|");
    row::<f64>(&args, n, views);
    row::<f32>(&args, n, views);
    println!();
    println!(
        "| OS-SART, one view per subset, λ = 0.15, disc support | pass (ms) | per subset (µs) |"
    );
    println!("|---|---|---|");
    sart_row::<f64>(&args, n, views);
    sart_row::<f32>(&args, n, views);
}
