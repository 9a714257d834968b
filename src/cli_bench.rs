//! `voxlab bench`: every benchmark case on the CPU f64 oracle, the CPU f32 baseline and
//! the GPU; writes `<slug>.json`, `<slug>.md` and `<slug>.svg` (docs/benchmarking.md).

use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::bench::{self, report, Backends, Event, Options, Suite};
use voxlab::{Error, Result};

/// Arguments of `voxlab bench`.
#[derive(Args)]
pub struct BenchArgs {
    /// quick: tiny inputs, every algorithm (a correctness smoke test, under a minute);
    /// full: the real sizes.
    #[arg(long, default_value = "full")]
    suite: String,
    /// Only these, comma-separated: families (raycast, gradient, adaptive, process, fft,
    /// fvr, project, fbp, fdk, d2vr) or case-id prefixes as --list prints them
    /// (raycast/mip-trilinear, "fvr/lanczos3 128").
    #[arg(long)]
    only: Option<String>,
    /// Timed runs per backend (default 5 for full, 3 for quick).
    #[arg(long)]
    runs: Option<usize>,
    /// Untimed warm-up runs per backend before the timed ones.
    #[arg(long, default_value_t = 1)]
    warmup: usize,
    /// cpu, gpu or all. The CPU f64 oracle always runs once, as the reference.
    #[arg(long, default_value = "all")]
    backends: String,
    /// Fail when no GPU adapter is found (otherwise the GPU columns say why and the
    /// run goes on).
    #[arg(long)]
    require_gpu: bool,
    /// Per backend and case: stop adding timed runs once 3 are done and this many
    /// seconds are spent.
    #[arg(long, default_value_t = 30.0)]
    budget: f64,
    /// Print the cases and run nothing.
    #[arg(long)]
    list: bool,
    /// Folder for the reports (created if missing).
    #[arg(long, default_value = "bench-results")]
    out: PathBuf,
    /// Base name of the report files (default: the adapter's name, e.g. nvidia-h200).
    #[arg(long)]
    name: Option<String>,
    /// Fold this run into the existing <out>/<name>.json (same machine, adapter and
    /// suite): its cases replace those with the same id, the others are kept, and the
    /// report lists the later run. For re-running a few cases of a long suite.
    #[arg(long, conflicts_with = "rerender")]
    merge: bool,
    /// Run nothing: rewrite <out>/<name>.md and .svg from <out>/<name>.json (after an
    /// upgrade changed the report's layout).
    #[arg(long)]
    rerender: bool,
}

pub fn run(a: BenchArgs) -> Result<ExitCode> {
    let suite = match a.suite.as_str() {
        "quick" => Suite::Quick,
        "full" => Suite::Full,
        other => {
            return Err(Error::invalid(
                "--suite",
                format!("'{other}' is not quick or full"),
            ))
        }
    };
    let only = a.only.as_deref().map(bench::parse_only).transpose()?;
    let mut opts = Options::new(suite);
    if let Some(n) = a.runs {
        if n == 0 {
            return Err(Error::invalid("--runs", "must be at least 1"));
        }
        opts.runs = n;
    }
    if !(a.budget.is_finite() && a.budget > 0.0) {
        return Err(Error::invalid(
            "--budget",
            "must be a positive number of seconds",
        ));
    }
    opts.warmup = a.warmup;
    opts.budget_seconds = a.budget;
    opts.backends = Backends::parse(&a.backends)?;
    if let Some(n) = &a.name {
        if report::slugify(n) != *n {
            return Err(Error::invalid(
                "--name",
                format!(
                    "'{n}': use lower-case letters, digits and single dashes (e.g. '{}')",
                    report::slugify(n)
                ),
            ));
        }
    }
    let order: Vec<String> = bench::cases(suite).iter().map(|c| c.id()).collect();
    let cases = bench::select_picks(bench::cases(suite), only.as_deref())?;
    if a.list {
        for c in &cases {
            println!("{}", c.id());
        }
        println!("{} case(s)", cases.len());
        return Ok(ExitCode::SUCCESS);
    }
    // Refuse an unusable output before a long run.
    report::check_out_dir(&a.out)?;
    let existing = |flag: &str| -> Result<(String, bench::Report)> {
        let Some(name) = &a.name else {
            return Err(Error::invalid(
                flag,
                "needs --name: the report in --out to read",
            ));
        };
        let path = a.out.join(format!("{name}.json"));
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        let r: bench::Report = serde_json::from_str(&text).map_err(|e| {
            Error::invalid(
                flag,
                format!("{} is not a voxlab bench report: {e}", path.display()),
            )
        })?;
        Ok((name.clone(), r))
    };
    if a.rerender {
        let (name, r) = existing("--rerender")?;
        for p in r.write(&a.out, &name)? {
            println!("wrote {}", p.display());
        }
        return Ok(ExitCode::SUCCESS);
    }
    let earlier = if a.merge {
        Some(existing("--merge")?.1)
    } else {
        None
    };

    let ctx = if opts.backends.gpu() {
        match voxlab::gpu::GpuContext::shared() {
            Ok(c) => Ok(c),
            Err(e) if a.require_gpu => return Err(e),
            Err(e) => Err(format!("no adapter: {e}")),
        }
    } else {
        Err("not requested (--backends cpu)".to_string())
    };
    match &ctx {
        Ok(c) => eprintln!(
            "GPU: {} ({}, {})",
            c.summary.name, c.summary.backend, c.summary.device_type
        ),
        Err(why) => eprintln!("GPU: none ({why})"),
    }
    eprintln!(
        "{} case(s), {} warm-up + up to {} timed run(s) per backend, {} CPU threads",
        cases.len(),
        opts.warmup,
        opts.runs,
        rayon::current_num_threads()
    );
    let pb = crate::progress_bar(cases.len() as u64, "benchmarking", "cases");
    let progress = |e: Event| match e {
        Event::Started { id, .. } => pb.set_message(id.to_string()),
        Event::Stage { id, stage } => pb.set_message(format!("{id}: {stage}")),
        Event::Finished { report, .. } => {
            pb.suspend(|| eprintln!("{}", bench::summary_line(report)));
            pb.inc(1);
        }
    };
    let report = bench::run_suite(
        cases,
        &opts,
        ctx.as_deref().map_err(String::as_str),
        &progress,
    );
    pb.finish_and_clear();
    let slug = a.name.clone().unwrap_or_else(|| report.default_slug());
    let run_cases = report.cases.len();
    let run_seconds = report.seconds;
    let report = match earlier {
        Some(mut e) => {
            e.merge(report, &order)?;
            e
        }
        None => report,
    };
    let paths = report.write(&a.out, &slug)?;
    for p in &paths {
        println!("wrote {}", p.display());
    }
    let problems = report.problems();
    if problems.is_empty() {
        println!(
            "{run_cases} case(s) in {run_seconds:.1} s; the report's {} case(s) are all \
             within tolerance",
            report.cases.len()
        );
        Ok(ExitCode::SUCCESS)
    } else {
        for p in &problems {
            eprintln!("voxlab: {p}");
        }
        eprintln!(
            "voxlab: {} problem(s) in {} case(s)",
            problems.len(),
            report.cases.len()
        );
        Ok(ExitCode::from(3))
    }
}
