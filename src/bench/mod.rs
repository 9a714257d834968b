//! `voxlab bench`: the same inputs on the CPU f64 oracle, the CPU f32 baseline and the
//! GPU; warm-up runs, then timed runs; medians with min/max; set-up apart from
//! execution; every timed result checked against the oracle first.
//!
//! The cases live with their families (`raycast`, `fourier`, `ct`); `cargo bench
//! --bench suite` runs the same list.

pub mod adaptive;
pub mod case;
pub mod ct;
pub mod d2vr;
pub mod fourier;
pub mod job;
pub mod machine;
pub mod multi;
pub mod process;
pub mod raycast;
pub mod report;

pub use case::{Case, CpuFn, GpuFn, GpuRun, Prepared, Run, Suite, Unit, Work};
pub use report::Report;

/// The algorithm families, in report order (`--only` takes a comma-separated subset).
pub const FAMILIES: [&str; 10] = [
    "raycast", "gradient", "adaptive", "process", "fft", "fvr", "project", "fbp", "fdk", "d2vr",
];

/// Every case of a suite, in report order.
pub fn cases(suite: Suite) -> Vec<Case> {
    let mut all = Vec::new();
    all.extend(raycast::cases(suite));
    all.extend(multi::cases(suite));
    all.extend(adaptive::cases(suite));
    all.extend(process::cases(suite));
    all.extend(fourier::cases(suite));
    all.extend(ct::cases(suite));
    all.extend(d2vr::cases(suite));
    all
}

use crate::error::{Error, Result};
use crate::gpu::GpuContext;
pub use crate::jobs::BackendSet;
use machine::Machine;
use report::{parity, throughput, BackendReport, CaseReport, Speedups, Stats, Status};
use std::time::Instant;

/// How a suite is run.
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    pub suite: Suite,
    /// Timed runs per backend (at least 1).
    pub runs: usize,
    /// Untimed runs before them; the first result of all is the one checked.
    pub warmup: usize,
    pub backends: BackendSet,
    /// Per backend and case: once `min_runs` timed runs are done and this many seconds
    /// are spent on timed runs, no more are added (a slow backend at a huge size).
    pub budget_seconds: f64,
    pub min_runs: usize,
}

impl Options {
    /// The defaults: 5 timed runs for the full suite, 3 for the quick one; 1 warm-up;
    /// every backend; a 30 s budget after 3 runs.
    pub fn new(suite: Suite) -> Self {
        Options {
            suite,
            runs: match suite {
                Suite::Quick => 3,
                Suite::Full => 5,
            },
            warmup: 1,
            backends: BackendSet::All,
            budget_seconds: 30.0,
            min_runs: 3,
        }
    }
}

/// `raycast,fft` → the families, each checked against [`FAMILIES`].
pub fn parse_families(list: &str) -> Result<Vec<&'static str>> {
    let mut out = Vec::new();
    for name in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let fam = FAMILIES
            .iter()
            .find(|f| f.eq_ignore_ascii_case(name))
            .ok_or_else(|| {
                Error::invalid(
                    "--only",
                    format!(
                        "'{name}' is not a benchmark family; the families are {}",
                        FAMILIES.join(", ")
                    ),
                )
            })?;
        if !out.contains(fam) {
            out.push(*fam);
        }
    }
    if out.is_empty() {
        return Err(Error::invalid(
            "--only",
            format!("name at least one of {}", FAMILIES.join(", ")),
        ));
    }
    Ok(out)
}

/// What `--only` picks: a whole family, or the cases whose id starts with a prefix
/// (`raycast/mip-trilinear`, `fvr/lanczos3 128³`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Pick {
    Family(&'static str),
    Cases(String),
}

/// `raycast,fft/3d` → picks: family names (checked against [`FAMILIES`]) and case-id
/// prefixes (anything with a `/`, whose family part is checked).
pub fn parse_only(list: &str) -> Result<Vec<Pick>> {
    let mut out = Vec::new();
    for item in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let pick = match item.split_once('/') {
            Some((fam, _)) => {
                parse_families(fam)?;
                Pick::Cases(item.to_string())
            }
            None => Pick::Family(parse_families(item)?[0]),
        };
        if !out.contains(&pick) {
            out.push(pick);
        }
    }
    if out.is_empty() {
        return Err(Error::invalid(
            "--only",
            format!("name at least one of {}", FAMILIES.join(", ")),
        ));
    }
    Ok(out)
}

/// The cases `picks` select (all for None), in report order.
///
/// # Errors
/// [`Error::Invalid`] when a case-id prefix matches no case.
pub fn select_picks(cases: Vec<Case>, picks: Option<&[Pick]>) -> Result<Vec<Case>> {
    let Some(picks) = picks else {
        return Ok(cases);
    };
    for p in picks {
        if let Pick::Cases(prefix) = p {
            if !cases.iter().any(|c| c.id().starts_with(prefix.as_str())) {
                return Err(Error::invalid(
                    "--only",
                    format!("no case id starts with '{prefix}' (see --list)"),
                ));
            }
        }
    }
    Ok(cases
        .into_iter()
        .filter(|c| {
            picks.iter().any(|p| match p {
                Pick::Family(f) => c.family == *f,
                Pick::Cases(prefix) => c.id().starts_with(prefix.as_str()),
            })
        })
        .collect())
}

/// The cases of the given families (all of them for None), in report order.
pub fn select(cases: Vec<Case>, only: Option<&[&str]>) -> Vec<Case> {
    match only {
        None => cases,
        Some(f) => cases
            .into_iter()
            .filter(|c| f.contains(&c.family))
            .collect(),
    }
}

/// What the runner is doing, for a progress display.
pub enum Event<'a> {
    /// A case begins (`index` counts from 0).
    Started {
        index: usize,
        total: usize,
        id: &'a str,
    },
    /// A stage within the case: `prepare`, `CPU f64`, `CPU f32`, `GPU`.
    Stage { id: &'a str, stage: &'a str },
    /// A case is done.
    Finished {
        index: usize,
        total: usize,
        report: &'a CaseReport,
    },
}

/// One run's time and output, whichever backend made it.
trait Sample {
    /// The seconds that count against the time budget.
    fn seconds(&self) -> f64;
    fn take_output(&mut self) -> Vec<f64>;
}

impl Sample for Run {
    fn seconds(&self) -> f64 {
        self.seconds
    }
    fn take_output(&mut self) -> Vec<f64> {
        std::mem::take(&mut self.output)
    }
}

impl Sample for GpuRun {
    fn seconds(&self) -> f64 {
        self.end_to_end + self.setup
    }
    fn take_output(&mut self) -> Vec<f64> {
        std::mem::take(&mut self.output)
    }
}

/// What measuring one backend gave.
enum Measured<T> {
    Done {
        warmups: Vec<f64>,
        timed: Vec<T>,
        parity: Option<report::Parity>,
    },
    Failed(report::Parity),
    Errored(String),
    /// The backend refused the size ([`Error::TooLarge`], e.g. a GPU's storage-binding
    /// limit): not a wrong answer, so the case still passes, and the report says why.
    TooLarge(String),
}

/// Warm-ups, then timed runs (stopping early on the budget). The first result of all
/// goes to `first`: the oracle keeps it as the reference; the others are checked, and
/// a failed check ends the backend before any timed run.
fn measure<T: Sample>(
    opts: &Options,
    warmup: usize,
    runs: usize,
    mut call: impl FnMut() -> Result<T>,
    mut first: impl FnMut(Vec<f64>) -> std::result::Result<Option<report::Parity>, Box<Measured<T>>>,
) -> Measured<T> {
    let mut warmups = Vec::new();
    let mut timed = Vec::new();
    let mut parity = None;
    let mut checked = false;
    let mut spent = 0.0;
    for i in 0.. {
        let warm = i < warmup;
        if !warm
            && (timed.len() >= runs
                || (timed.len() >= opts.min_runs.min(runs) && spent >= opts.budget_seconds))
        {
            break;
        }
        let start = Instant::now();
        let mut r = match call() {
            Ok(r) => r,
            Err(e @ Error::TooLarge { .. }) => return Measured::TooLarge(e.to_string()),
            Err(e) => return Measured::Errored(e.to_string()),
        };
        let wall = start.elapsed().as_secs_f64();
        let out = r.take_output();
        if !checked {
            checked = true;
            match first(out) {
                Ok(p) => parity = p,
                Err(m) => return *m,
            }
        }
        if warm {
            warmups.push(r.seconds());
        } else {
            spent += wall.max(r.seconds());
            timed.push(r);
        }
    }
    Measured::Done {
        warmups,
        timed,
        parity,
    }
}

fn checker<T>(
    reference: &[f64],
    tol: crate::metrics::Tolerance,
) -> impl FnMut(Vec<f64>) -> std::result::Result<Option<report::Parity>, Box<Measured<T>>> + '_ {
    move |out| {
        let p = parity(reference, &out, tol);
        if p.passed {
            Ok(Some(p))
        } else {
            Err(Box::new(Measured::Failed(p)))
        }
    }
}

fn cpu_report(m: Measured<Run>, work: &[Work]) -> BackendReport {
    match m {
        Measured::Done {
            warmups,
            timed,
            parity,
        } => {
            let secs: Vec<f64> = timed.iter().map(|r| r.seconds).collect();
            let stats = Stats::of(&secs);
            BackendReport {
                status: Status::Passed,
                message: stats
                    .is_none()
                    .then(|| "reference only (not timed)".to_string()),
                parity,
                warmup_seconds: warmups,
                runs: timed.len(),
                throughput: stats
                    .as_ref()
                    .map_or(Vec::new(), |s| throughput(work, s.median, None)),
                seconds: stats,
                ..BackendReport::skipped("")
            }
        }
        Measured::Failed(p) => failed(p),
        Measured::Errored(e) => BackendReport::errored(e),
        Measured::TooLarge(e) => BackendReport::skipped(format!("too large here: {e}")),
    }
}

fn failed(p: report::Parity) -> BackendReport {
    BackendReport {
        status: Status::Failed,
        message: Some(p.message.clone()),
        parity: Some(p),
        ..BackendReport::skipped("")
    }
}

fn gpu_report(m: Measured<GpuRun>, work: &[Work]) -> BackendReport {
    match m {
        Measured::Done {
            warmups,
            timed,
            parity,
        } => {
            let col = |f: fn(&GpuRun) -> f64| Stats::of(&timed.iter().map(f).collect::<Vec<_>>());
            let kernel = col(|r| r.kernel);
            let end_to_end = col(|r| r.end_to_end);
            let throughput = match (&kernel, &end_to_end) {
                (Some(k), Some(e)) => throughput(work, k.median, Some(e.median)),
                _ => Vec::new(),
            };
            BackendReport {
                status: Status::Passed,
                message: None,
                parity,
                warmup_seconds: warmups,
                runs: timed.len(),
                seconds: None,
                setup: col(|r| r.setup),
                kernel_from_timestamps: Some(
                    !timed.is_empty() && timed.iter().all(|r| r.kernel_from_timestamps),
                ),
                kernel,
                end_to_end,
                throughput,
            }
        }
        Measured::Failed(p) => failed(p),
        Measured::Errored(e) => BackendReport::errored(e),
        Measured::TooLarge(e) => BackendReport::skipped(format!("too large here: {e}")),
    }
}

/// Runs one case on every backend `opts` asks for.
pub fn run_case(
    case: &Case,
    opts: &Options,
    gpu: std::result::Result<&GpuContext, &str>,
    progress: &dyn Fn(Event),
) -> CaseReport {
    let id = case.id();
    let stage = |s: &str| progress(Event::Stage { id: &id, stage: s });
    let mut report = CaseReport {
        family: case.family.to_string(),
        name: case.name.clone(),
        size: case.size.clone(),
        note: String::new(),
        prepare_seconds: None,
        error: None,
        work: Vec::new(),
        cpu_f64: BackendReport::skipped("not run"),
        cpu_f32: BackendReport::skipped("not run"),
        gpu: BackendReport::skipped("not run"),
        speedups: Speedups::default(),
    };
    stage("prepare");
    let t = Instant::now();
    let prepared = (case.prepare)();
    report.prepare_seconds = Some(t.elapsed().as_secs_f64());
    let mut p = match prepared {
        Ok(p) => p,
        Err(e) => {
            report.error = Some(e.to_string());
            return report;
        }
    };
    report.note = p.note.clone();
    report.work = p.work.clone();
    let runs = opts.runs.max(1);

    // The oracle: its first result is the reference.
    stage("CPU f64");
    let mut reference = Vec::new();
    let (w, n) = if opts.backends.cpu() {
        (opts.warmup, runs)
    } else {
        (1, 0)
    };
    let m = measure(opts, w, n, &mut p.cpu_f64, |out: Vec<f64>| {
        let bad = out.iter().filter(|v| !v.is_finite()).count();
        if bad > 0 {
            return Err(Box::new(Measured::Errored(format!(
                "the oracle's result holds {bad} non-finite value(s)"
            ))));
        }
        reference = out;
        Ok(None)
    });
    report.cpu_f64 = cpu_report(m, &p.work);
    if report.cpu_f64.status != Status::Passed {
        let why = "not run: the oracle has no result";
        report.cpu_f32 = BackendReport::skipped(why);
        report.gpu = BackendReport::skipped(why);
        return report;
    }

    report.cpu_f32 = match (&mut p.cpu_f32, opts.backends.cpu()) {
        (None, _) => BackendReport::skipped("no f32 CPU path"),
        (Some(_), false) => BackendReport::skipped("not requested (--backends gpu)"),
        (Some(f), true) => {
            stage("CPU f32");
            let m = measure(opts, opts.warmup, runs, f, checker(&reference, p.tol_f32));
            cpu_report(m, &p.work)
        }
    };

    report.gpu = match (&mut p.gpu, gpu) {
        (None, _) => BackendReport::skipped("no GPU port"),
        (Some(_), Err(why)) => BackendReport::skipped(why),
        (Some(f), Ok(ctx)) => {
            stage("GPU");
            let m = measure(
                opts,
                opts.warmup,
                runs,
                || f(ctx),
                checker(&reference, p.tol_gpu),
            );
            gpu_report(m, &p.work)
        }
    };
    report.compute_speedups();
    report
}

/// Runs every case (preparing each just before it runs, and dropping its inputs right
/// after), and describes the machine. `gpu` is the adapter to use, or why there is
/// none (the GPU columns then say so and the run still succeeds).
pub fn run_suite(
    cases: Vec<Case>,
    opts: &Options,
    gpu: std::result::Result<&GpuContext, &str>,
    progress: &dyn Fn(Event),
) -> report::Report {
    run_suite_until(cases, opts, gpu, progress, &|| false)
}

/// [`run_suite`] that asks `stop` before each case and, when it says so, returns the
/// cases done so far.
pub fn run_suite_until(
    cases: Vec<Case>,
    opts: &Options,
    gpu: std::result::Result<&GpuContext, &str>,
    progress: &dyn Fn(Event),
    stop: &dyn Fn() -> bool,
) -> report::Report {
    let machine = Machine::current(gpu);
    let start = Instant::now();
    let total = cases.len();
    let mut reports = Vec::with_capacity(total);
    for (index, case) in cases.iter().enumerate() {
        if stop() {
            break;
        }
        let id = case.id();
        progress(Event::Started {
            index,
            total,
            id: &id,
        });
        let r = run_case(case, opts, gpu, progress);
        progress(Event::Finished {
            index,
            total,
            report: &r,
        });
        reports.push(r);
    }
    let mut report = report::Report {
        machine,
        suite: opts.suite,
        runs: opts.runs.max(1),
        warmup: opts.warmup,
        backends: opts.backends,
        budget_seconds: opts.budget_seconds,
        min_runs: opts.min_runs,
        cases: reports,
        seconds: start.elapsed().as_secs_f64(),
        merged: Vec::new(),
    };
    report.apply_peak();
    report
}

/// One line for a finished case: its status and headline figures.
pub fn summary_line(r: &CaseReport) -> String {
    use report::fmt_seconds;
    let t = |b: &BackendReport, s: Option<&Stats>| match b.status {
        Status::Passed => s.map_or("ref".to_string(), |s| fmt_seconds(s.median)),
        Status::Failed => "FAILED".to_string(),
        Status::Errored => "ERROR".to_string(),
        Status::Skipped => "—".to_string(),
    };
    let status = match r.status() {
        Status::Passed => "ok",
        Status::Failed => "FAILED",
        Status::Errored => "ERROR",
        Status::Skipped => "skipped",
    };
    let mut line = format!(
        "{status:6} {}: f64 {}, f32 {}, GPU kernel {} / e2e {}",
        r.id(),
        t(&r.cpu_f64, r.cpu_f64.seconds.as_ref()),
        t(&r.cpu_f32, r.cpu_f32.seconds.as_ref()),
        t(&r.gpu, r.gpu.kernel.as_ref()),
        t(&r.gpu, r.gpu.end_to_end.as_ref()),
    );
    if let Some(s) = r.speedups.f32_over_gpu_kernel {
        let _ = std::fmt::Write::write_fmt(&mut line, format_args!(", f32/kernel {s:.2}×"));
    }
    for p in r.problems() {
        line.push_str("\n       ");
        line.push_str(&p);
    }
    line
}
