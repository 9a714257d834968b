//! `voxlab bench`: every benchmark case on the CPU f64 oracle, the CPU f32 baseline and
//! the GPU, through [`voxlab::bench::job::run`] (docs/benchmarking.md).

use crate::cli::{choice, Terminal};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::bench::job::BenchRequest;
use voxlab::bench::{Event, Suite};
use voxlab::jobs::{BackendSet, Progress};
use voxlab::Result;

/// Arguments of `voxlab bench`.
#[derive(Args)]
pub struct BenchArgs {
    /// quick: tiny inputs, every algorithm (a correctness smoke test, under a minute);
    /// full: the real sizes.
    #[arg(long, value_parser = choice::<Suite>(), default_value = "full")]
    pub suite: Suite,
    /// Only these, comma-separated: families (raycast, gradient, adaptive, process, fft,
    /// fvr, project, fbp, fdk, d2vr) or case-id prefixes as --list prints them
    /// (raycast/mip-trilinear, "fvr/lanczos3 128").
    #[arg(long)]
    pub only: Option<String>,
    /// Timed runs per backend (default 5 for full, 3 for quick).
    #[arg(long)]
    pub runs: Option<usize>,
    /// Untimed warm-up runs per backend before the timed ones.
    #[arg(long, default_value_t = 1)]
    pub warmup: usize,
    /// cpu, gpu or all. The CPU f64 oracle always runs once, as the reference.
    #[arg(long, value_parser = choice::<BackendSet>(), default_value = "all")]
    pub backends: BackendSet,
    /// Fail when no GPU adapter is found (otherwise the GPU columns say why and the
    /// run goes on).
    #[arg(long)]
    pub require_gpu: bool,
    /// Per backend and case: stop adding timed runs once 3 are done and this many
    /// seconds are spent.
    #[arg(long, default_value_t = 30.0)]
    pub budget: f64,
    /// Print the cases and run nothing.
    #[arg(long)]
    pub list: bool,
    /// Folder for the reports (created if missing).
    #[arg(long, default_value = "bench-results")]
    pub out: PathBuf,
    /// Base name of the report files (default: the adapter's name, e.g. nvidia-h200).
    #[arg(long)]
    pub name: Option<String>,
    /// Fold this run into the existing <out>/<name>.json (same machine, adapter and
    /// suite): its cases replace those with the same id, the others are kept, and the
    /// report lists the later run. For re-running a few cases of a long suite.
    #[arg(long, conflicts_with = "rerender")]
    pub merge: bool,
    /// Run nothing: rewrite <out>/<name>.md and .svg from <out>/<name>.json (after an
    /// upgrade changed the report's layout).
    #[arg(long)]
    pub rerender: bool,
}

pub fn run(a: BenchArgs) -> Result<ExitCode> {
    let req = BenchRequest {
        suite: a.suite,
        only: a.only.clone(),
        runs: a.runs,
        warmup: a.warmup,
        backends: a.backends,
        require_gpu: a.require_gpu,
        budget: a.budget,
        out: a.out.clone(),
        name: a.name.clone(),
        merge: a.merge,
        rerender: a.rerender,
    };
    if a.list {
        let ids = voxlab::bench::job::list(&req)?;
        for id in &ids {
            println!("{id}");
        }
        println!("{} case(s)", ids.len());
        return Ok(ExitCode::SUCCESS);
    }
    let term = Terminal::bars().plain_notes();
    let events = |e: Event| match e {
        Event::Started { index, total, id } => {
            if index == 0 {
                term.begin(id, "cases", total as u64);
            }
            term.message(id.to_string());
        }
        Event::Stage { id, stage } => term.message(format!("{id}: {stage}")),
        Event::Finished {
            index,
            total,
            report,
        } => {
            term.suspend(|| eprintln!("{}", voxlab::bench::summary_line(report)));
            term.advance(index as u64 + 1, total as u64);
        }
    };
    let outcome = voxlab::bench::job::run(&req, &events, &term)?;
    drop(term);
    for p in &outcome.paths {
        println!("wrote {}", p.display());
    }
    if a.rerender {
        return Ok(ExitCode::SUCCESS);
    }
    if outcome.problems.is_empty() {
        println!(
            "{} case(s) in {:.1} s; the report's {} case(s) are all within tolerance",
            outcome.run_cases,
            outcome.run_seconds,
            outcome.report.cases.len()
        );
        Ok(ExitCode::SUCCESS)
    } else {
        for p in &outcome.problems {
            eprintln!("voxlab: {p}");
        }
        eprintln!(
            "voxlab: {} problem(s) in {} case(s)",
            outcome.problems.len(),
            outcome.report.cases.len()
        );
        Ok(ExitCode::from(3))
    }
}
