//! `voxlab bench`: the suite as a job — every case on the CPU f64 oracle, the CPU f32
//! baseline and the GPU, then `<name>.json`, `<name>.md` and `<name>.svg` in a folder
//! (docs/benchmarking.md).

use super::{report, BackendSet, Event, Options, Report, Suite};
use crate::error::{Error, Result};
use crate::jobs::Progress;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// The `voxlab bench` job.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BenchRequest {
    pub suite: Suite,
    /// Only these, comma-separated: families or case-id prefixes.
    pub only: Option<String>,
    /// Timed runs per backend (`None`: 5 for full, 3 for quick).
    pub runs: Option<usize>,
    /// Untimed warm-up runs per backend before the timed ones.
    pub warmup: usize,
    pub backends: BackendSet,
    /// Fail when no GPU adapter is found (otherwise the GPU columns say why).
    pub require_gpu: bool,
    /// Per backend and case: stop adding timed runs once 3 are done and this many
    /// seconds are spent.
    pub budget: f64,
    /// Folder for the reports (created if missing).
    pub out: PathBuf,
    /// Base name of the report files (`None`: the adapter's name, e.g. nvidia-h200).
    pub name: Option<String>,
    /// Fold this run into the existing `<out>/<name>.json`.
    pub merge: bool,
    /// Run nothing: rewrite `<out>/<name>.md` and `.svg` from `<out>/<name>.json`.
    pub rerender: bool,
}

impl Default for BenchRequest {
    fn default() -> Self {
        BenchRequest {
            suite: Suite::Full,
            only: None,
            runs: None,
            warmup: 1,
            backends: BackendSet::All,
            require_gpu: false,
            budget: 30.0,
            out: PathBuf::from("bench-results"),
            name: None,
            merge: false,
            rerender: false,
        }
    }
}

/// What a bench run did.
#[derive(Clone, Debug)]
pub struct BenchOutcome {
    /// The report files written.
    pub paths: Vec<PathBuf>,
    /// Cases run now (0 for `rerender`) and their seconds.
    pub run_cases: usize,
    pub run_seconds: f64,
    /// The report as written (merged with the earlier one for `merge`).
    pub report: Report,
    /// Parity failures and errors, one line each (empty: all within tolerance).
    pub problems: Vec<String>,
}

fn check(a: &BenchRequest) -> Result<Options> {
    let mut opts = Options::new(a.suite);
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
    opts.backends = a.backends;
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
    Ok(opts)
}

/// The ids of the cases the request selects, in suite order.
///
/// # Errors
/// Bad options or an `only` that selects nothing.
pub fn list(a: &BenchRequest) -> Result<Vec<String>> {
    check(a)?;
    let only = a.only.as_deref().map(super::parse_only).transpose()?;
    Ok(super::select_picks(super::cases(a.suite), only.as_deref())?
        .iter()
        .map(|c| c.id())
        .collect())
}

/// The earlier report `<out>/<name>.json` that `merge` and `rerender` read.
fn existing(a: &BenchRequest, flag: &str) -> Result<(String, Report)> {
    let Some(name) = &a.name else {
        return Err(Error::invalid(
            flag,
            "needs --name: the report in --out to read",
        ));
    };
    let path = a.out.join(format!("{name}.json"));
    let text = crate::source::read_text_limited(&path, flag, crate::source::MAX_JSON_BYTES)?;
    let r: Report = serde_json::from_str(&text).map_err(|e| {
        Error::invalid(
            flag,
            format!("{} is not a voxlab bench report: {e}", path.display()),
        )
    })?;
    Ok((name.clone(), r))
}

/// Runs the suite and writes the reports. `events` sees every case start, stage and
/// finish; `progress` gets the notes (which GPU, how many cases) and is asked between
/// cases whether to stop.
///
/// # Errors
/// Bad options; an unusable `out`; no GPU with `require_gpu`; [`Error::Cancelled`].
pub fn run(
    a: &BenchRequest,
    events: &dyn Fn(Event),
    progress: &dyn Progress,
) -> Result<BenchOutcome> {
    if a.merge && a.rerender {
        return Err(Error::invalid(
            "--merge",
            "merges a new run; it excludes --rerender",
        ));
    }
    let opts = check(a)?;
    let only = a.only.as_deref().map(super::parse_only).transpose()?;
    let order: Vec<String> = super::cases(a.suite).iter().map(|c| c.id()).collect();
    let cases = super::select_picks(super::cases(a.suite), only.as_deref())?;
    // Refuse an unusable output before a long run.
    report::check_out_dir(&a.out)?;
    if a.rerender {
        let (name, r) = existing(a, "--rerender")?;
        let paths = r.write(&a.out, &name)?;
        return Ok(BenchOutcome {
            paths,
            run_cases: 0,
            run_seconds: 0.0,
            problems: Vec::new(),
            report: r,
        });
    }
    let earlier = if a.merge {
        Some(existing(a, "--merge")?.1)
    } else {
        None
    };
    let ctx = if opts.backends.gpu() {
        match crate::gpu::GpuContext::shared() {
            Ok(c) => Ok(c),
            Err(e) if a.require_gpu => return Err(e),
            Err(e) => Err(format!("no adapter: {e}")),
        }
    } else {
        Err("not requested (--backends cpu)".to_string())
    };
    match &ctx {
        Ok(c) => progress.note(&format!(
            "GPU: {} ({}, {})",
            c.summary.name, c.summary.backend, c.summary.device_type
        )),
        Err(why) => progress.note(&format!("GPU: none ({why})")),
    }
    progress.note(&format!(
        "{} case(s), {} warm-up + up to {} timed run(s) per backend, {} CPU threads",
        cases.len(),
        opts.warmup,
        opts.runs,
        rayon::current_num_threads()
    ));
    let cancelled = std::cell::Cell::new(false);
    let report = super::run_suite_until(
        cases,
        &opts,
        ctx.as_deref().map_err(String::as_str),
        events,
        &|| {
            let stop = progress.cancelled();
            cancelled.set(cancelled.get() || stop);
            stop
        },
    );
    if cancelled.get() {
        return Err(Error::Cancelled);
    }
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
    let problems = report.problems();
    Ok(BenchOutcome {
        paths,
        run_cases,
        run_seconds,
        report,
        problems,
    })
}
