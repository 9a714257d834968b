//! The `voxlab bench` suite under `cargo bench --bench suite [-- FILTER]`: the same
//! case list through the same runner, printing the Markdown report. FILTER is a family
//! (`fft`) or a substring of a case's id (`dvr-shaded`). Under `cargo test --benches`
//! (no `--bench` flag) it runs the quick suite once per backend, as a smoke test. The
//! process fails when a case fails its parity check or errors.

mod common;

use common::BenchArgs;
use voxlab::bench::{cases, run_suite, summary_line, Event, Options, Suite, FAMILIES};
use voxlab::gpu::GpuContext;

fn main() {
    let args = BenchArgs::from_env();
    let suite = if args.smoke {
        Suite::Quick
    } else {
        Suite::Full
    };
    let mut opts = Options::new(suite);
    opts.runs = args.runs;
    let selected: Vec<_> = cases(suite)
        .into_iter()
        .filter(|c| match args.filter.as_deref() {
            None => true,
            Some(f) if FAMILIES.contains(&f) => c.family == f,
            Some(f) => c.id().contains(f),
        })
        .collect();
    let why: String;
    let gpu = match GpuContext::shared() {
        Ok(ctx) => Ok(ctx),
        Err(e) => {
            why = format!("no adapter: {e}");
            eprintln!("GPU: none ({why})");
            Err(why.as_str())
        }
    };
    eprintln!(
        "{} case(s), {:?} suite, {} warm-up + up to {} timed run(s) per backend",
        selected.len(),
        suite,
        opts.warmup,
        opts.runs
    );
    let report = run_suite(selected, &opts, gpu, &|e| {
        if let Event::Finished { report, .. } = e {
            eprintln!("{}", summary_line(report));
        }
    });
    println!("{}", report.to_markdown());
    if !report.passed() {
        eprintln!("{} problem(s)", report.problems().len());
        std::process::exit(1);
    }
}
