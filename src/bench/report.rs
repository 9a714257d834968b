//! What a benchmark run found, and the three files it is written to: `<slug>.json`
//! (everything, raw samples included), `<slug>.md` (the machine, the method, one table
//! per family) and `<slug>.svg` (the GPU speedups over the CPU f32 baseline, per case,
//! on a log scale).
//!
//! Every figure of a backend comes with its parity check against the f64 oracle; a
//! backend that failed it has no timings (a fast wrong answer never counts).

use super::machine::Machine;
use super::{BackendSet, Suite, Unit, Work, FAMILIES};
use crate::error::{Error, Result};
use crate::metrics::{error_stats, Tolerance};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Median, minimum and maximum of the timed runs, with every sample.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Stats {
    /// The middle sample (the mean of the two middle ones for an even count).
    pub median: f64,
    pub min: f64,
    pub max: f64,
    /// Every timed run, in the order they ran (seconds).
    pub samples: Vec<f64>,
}

impl Stats {
    /// None for no samples.
    pub fn of(samples: &[f64]) -> Option<Stats> {
        if samples.is_empty() {
            return None;
        }
        let mut s = samples.to_vec();
        s.sort_by(f64::total_cmp);
        let n = s.len();
        let median = if n % 2 == 1 {
            s[n / 2]
        } else {
            0.5 * (s[n / 2 - 1] + s[n / 2])
        };
        Some(Stats {
            median,
            min: s[0],
            max: s[n - 1],
            samples: samples.to_vec(),
        })
    }
}

/// How a backend fared on one case.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Status {
    /// Ran, and (for the f32 and GPU backends) matched the oracle within its tolerance.
    Passed,
    /// Ran, but its result is outside the tolerance (or not finite): not timed.
    Failed,
    /// Returned an error (message kept).
    Errored,
    /// Not run: not requested, no adapter, or no such path for this algorithm.
    Skipped,
}

/// A backend's result against the oracle's.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Parity {
    /// max |port − oracle| / max |oracle|.
    pub max_abs_rel: f64,
    /// ‖port − oracle‖₂ / ‖oracle‖₂.
    pub rel_l2: f64,
    /// NaN or infinite values in the port's result (any fails).
    pub non_finite: usize,
    /// The bounds it was held to; in the report `{"max_abs_rel": …, "rel_l2": …}`.
    #[serde(with = "report_tolerance")]
    pub tol: Tolerance,
    pub passed: bool,
    /// Why it failed, in words (empty when it passed).
    pub message: String,
}

/// Compares a result with the oracle's ([`error_stats`]): the largest absolute
/// difference relative to the oracle's largest |value|, and the relative L2 error,
/// against the tolerance's bounds. A length mismatch or any NaN/∞ in `port` fails.
pub fn parity(oracle: &[f64], port: &[f64], tol: Tolerance) -> Parity {
    let non_finite = port.iter().filter(|v| !v.is_finite()).count();
    if oracle.len() != port.len() {
        return Parity {
            max_abs_rel: f64::INFINITY,
            rel_l2: f64::INFINITY,
            non_finite,
            tol,
            passed: false,
            message: format!(
                "{} values where the oracle has {}",
                port.len(),
                oracle.len()
            ),
        };
    }
    let stats = error_stats(oracle, port, tol.max_abs);
    let mut why = Vec::new();
    if non_finite > 0 {
        why.push(format!("{non_finite} non-finite value(s)"));
    }
    why.extend(tol.exceeded(&stats));
    Parity {
        max_abs_rel: stats.max_abs_rel,
        rel_l2: stats.rel_l2,
        non_finite,
        tol,
        passed: why.is_empty(),
        message: why.join(", "),
    }
}

/// A [`Tolerance`] as the report writes it: the bench's two bounds, `max_abs_rel` and
/// `rel_l2` (the fields reports have always had, which `--merge` reads back), and
/// `max_abs` and `rmse` only where a case sets them.
mod report_tolerance {
    use crate::metrics::Tolerance;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    fn unbounded() -> f64 {
        f64::INFINITY
    }

    fn is_unbounded(v: &f64) -> bool {
        *v == f64::INFINITY
    }

    #[derive(Serialize, Deserialize)]
    struct Written {
        max_abs_rel: f64,
        rel_l2: f64,
        #[serde(default = "unbounded", skip_serializing_if = "is_unbounded")]
        max_abs: f64,
        #[serde(default = "unbounded", skip_serializing_if = "is_unbounded")]
        rmse: f64,
    }

    pub fn serialize<S: Serializer>(t: &Tolerance, s: S) -> Result<S::Ok, S::Error> {
        Written {
            max_abs_rel: t.max_abs_rel,
            rel_l2: t.rel_l2,
            max_abs: t.max_abs,
            rmse: t.rmse,
        }
        .serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Tolerance, D::Error> {
        let w = Written::deserialize(d)?;
        Ok(Tolerance {
            max_abs: w.max_abs,
            rmse: w.rmse,
            max_abs_rel: w.max_abs_rel,
            rel_l2: w.rel_l2,
        })
    }
}

/// Work per second in a unit people quote.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Throughput {
    pub unit: Unit,
    /// `Mrays/s`, `Msamples/s`, `Gupdates/s`, `GB/s` or `GFLOP/s`.
    pub label: String,
    /// Over the median time (for the GPU: the median kernel time).
    pub value: f64,
    /// GPU only: over the median end-to-end time.
    pub value_end_to_end: Option<f64>,
    /// GPU only: `value` as a fraction of the adapter's data-sheet peak for the unit
    /// (memory bandwidth for GB/s, FP32 rate for GFLOP/s), where the part is known
    /// ([`Report::apply_peak`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub of_peak: Option<f64>,
}

/// The scale and label of a unit's throughput.
pub fn unit_scale(unit: Unit) -> (f64, &'static str) {
    match unit {
        Unit::Rays => (1e6, "Mrays/s"),
        Unit::Samples => (1e6, "Msamples/s"),
        Unit::VoxelUpdates => (1e9, "Gupdates/s"),
        Unit::Bytes => (1e9, "GB/s"),
        Unit::Flops => (1e9, "GFLOP/s"),
    }
}

/// The throughputs of `work` done in `seconds` (and, for the GPU, in `end_to_end`).
pub fn throughput(work: &[Work], seconds: f64, end_to_end: Option<f64>) -> Vec<Throughput> {
    work.iter()
        .map(|w| {
            let (scale, label) = unit_scale(w.unit);
            Throughput {
                unit: w.unit,
                label: label.to_string(),
                value: w.amount / seconds / scale,
                value_end_to_end: end_to_end.map(|t| w.amount / t / scale),
                of_peak: None,
            }
        })
        .collect()
}

/// One backend on one case.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BackendReport {
    pub status: Status,
    /// Why it was skipped, the error, or the parity failure in words.
    pub message: Option<String>,
    /// Against the oracle (None for the oracle itself and for skipped backends).
    pub parity: Option<Parity>,
    /// The warm-up runs (seconds; for the GPU, set-up + end to end).
    pub warmup_seconds: Vec<f64>,
    /// Timed runs done (fewer than asked when the time budget ran out).
    pub runs: usize,
    /// CPU: the computation's wall time.
    pub seconds: Option<Stats>,
    /// GPU: the compute passes alone.
    pub kernel: Option<Stats>,
    /// GPU: upload + passes + readback.
    pub end_to_end: Option<Stats>,
    /// GPU: the one-off set-up (shaders, pipelines) of each run.
    pub setup: Option<Stats>,
    /// GPU: whether kernel times came from timestamp queries (else the host clock).
    pub kernel_from_timestamps: Option<bool>,
    pub throughput: Vec<Throughput>,
}

impl BackendReport {
    pub fn skipped(why: impl Into<String>) -> Self {
        BackendReport {
            status: Status::Skipped,
            message: Some(why.into()),
            parity: None,
            warmup_seconds: Vec::new(),
            runs: 0,
            seconds: None,
            kernel: None,
            end_to_end: None,
            setup: None,
            kernel_from_timestamps: None,
            throughput: Vec::new(),
        }
    }

    pub fn errored(message: impl Into<String>) -> Self {
        BackendReport {
            status: Status::Errored,
            ..BackendReport::skipped(message)
        }
    }

    /// The median time speedups are computed from: CPU wall time, or GPU kernel time.
    pub fn median(&self) -> Option<f64> {
        if self.status != Status::Passed {
            return None;
        }
        self.seconds
            .as_ref()
            .or(self.kernel.as_ref())
            .map(|s| s.median)
    }
}

/// Ratios of median times (None where either side is missing or failed).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Speedups {
    /// CPU f64 over CPU f32: what single precision buys on the CPU.
    pub f64_over_f32: Option<f64>,
    /// CPU f32 over the GPU's kernel time.
    pub f32_over_gpu_kernel: Option<f64>,
    /// CPU f32 over the GPU's end-to-end time.
    pub f32_over_gpu_end_to_end: Option<f64>,
    /// CPU f64 over the GPU's kernel time (recorded, not charted: the oracle is slow by
    /// design).
    pub f64_over_gpu_kernel: Option<f64>,
}

/// One case on every backend.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CaseReport {
    pub family: String,
    pub name: String,
    pub size: String,
    pub note: String,
    /// Building the inputs (not timed with the runs).
    pub prepare_seconds: Option<f64>,
    /// Preparing the case failed: nothing ran.
    pub error: Option<String>,
    pub work: Vec<Work>,
    pub cpu_f64: BackendReport,
    pub cpu_f32: BackendReport,
    pub gpu: BackendReport,
    pub speedups: Speedups,
}

impl CaseReport {
    /// `family/name size`.
    pub fn id(&self) -> String {
        format!("{}/{} {}", self.family, self.name, self.size)
    }

    /// Errored if preparing or any backend errored, else Failed if any backend failed
    /// its parity check, else Passed.
    pub fn status(&self) -> Status {
        let b = [&self.cpu_f64, &self.cpu_f32, &self.gpu];
        if self.error.is_some() || b.iter().any(|r| r.status == Status::Errored) {
            Status::Errored
        } else if b.iter().any(|r| r.status == Status::Failed) {
            Status::Failed
        } else {
            Status::Passed
        }
    }

    /// What went wrong, one line per backend (empty when it passed).
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        if let Some(e) = &self.error {
            out.push(format!("{}: preparing the inputs failed: {e}", self.id()));
        }
        for (label, b) in self.backends() {
            match b.status {
                Status::Failed => out.push(format!(
                    "{}: {label} FAILED parity: {}",
                    self.id(),
                    b.message.as_deref().unwrap_or("")
                )),
                Status::Errored => out.push(format!(
                    "{}: {label} error: {}",
                    self.id(),
                    b.message.as_deref().unwrap_or("")
                )),
                _ => {}
            }
        }
        out
    }

    pub fn backends(&self) -> [(&'static str, &BackendReport); 3] {
        [
            ("CPU f64", &self.cpu_f64),
            ("CPU f32", &self.cpu_f32),
            ("GPU", &self.gpu),
        ]
    }

    /// The ratios of median times.
    pub fn compute_speedups(&mut self) {
        let f64m = self.cpu_f64.median();
        let f32m = self.cpu_f32.median();
        let gk = self.gpu.median();
        let ge = (self.gpu.status == Status::Passed)
            .then(|| self.gpu.end_to_end.as_ref().map(|s| s.median))
            .flatten();
        let r = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) if b > 0.0 => Some(a / b),
            _ => None,
        };
        self.speedups = Speedups {
            f64_over_f32: r(f64m, f32m),
            f32_over_gpu_kernel: r(f32m, gk),
            f32_over_gpu_end_to_end: r(f32m, ge),
            f64_over_gpu_kernel: r(f64m, gk),
        };
    }
}

/// A whole run: the machine, the method, every case.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Report {
    pub machine: Machine,
    pub suite: Suite,
    /// Timed runs asked for per backend (the budget may have cut some short).
    pub runs: usize,
    pub warmup: usize,
    pub backends: BackendSet,
    /// Per backend and case: no more timed runs once `min_runs` are done and this many
    /// seconds are spent.
    pub budget_seconds: f64,
    pub min_runs: usize,
    pub cases: Vec<CaseReport>,
    /// Wall time of the whole run.
    pub seconds: f64,
    /// Later runs merged into this report (`voxlab bench --merge`), oldest first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub merged: Vec<MergedRun>,
}

/// A later run whose cases replaced or joined a report's ([`Report::merge`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MergedRun {
    pub date_utc: String,
    pub command_line: String,
    /// The ids of the cases it measured.
    pub cases: Vec<String>,
    pub seconds: f64,
}

impl Report {
    /// Sets every GPU throughput's fraction of the adapter's peak (the roofline), when
    /// the machine's adapter has a known peak; clears them otherwise.
    pub fn apply_peak(&mut self) {
        let peak = self.machine.adapter.as_ref().and_then(|a| a.peak.clone());
        for c in &mut self.cases {
            for t in &mut c.gpu.throughput {
                t.of_peak = peak
                    .as_ref()
                    .and_then(|p| crate::gpu::peak::fraction(t.value, p.of_unit(t.unit)));
            }
        }
    }

    /// Folds `newer` (a later run on the same machine and adapter, same suite) into
    /// this report: its cases replace those with the same id and the others join in
    /// `order` (the ids of the whole suite, in report order; ids not in it go last).
    /// The machine description stays this report's, with the later run listed under
    /// [`Report::merged`]; every case keeps the figures of the run that measured it.
    ///
    /// # Errors
    /// [`Error::Invalid`] when the suites, CPU models, core counts or adapters differ:
    /// figures from two machines must not share a table.
    pub fn merge(&mut self, newer: Report, order: &[String]) -> Result<()> {
        let (a, b) = (&self.machine, &newer.machine);
        let adapter = |m: &Machine| {
            m.adapter
                .as_ref()
                .map(|a| (a.name.clone(), a.driver_info.clone()))
        };
        let same = self.suite == newer.suite
            && a.cpu_model == b.cpu_model
            && a.logical_cores == b.logical_cores
            && a.rayon_threads == b.rayon_threads
            && adapter(a) == adapter(b);
        if !same {
            return Err(Error::invalid(
                "--merge",
                format!(
                    "the existing report was measured on {} / {} ({} threads, {} suite), \
                     this run on {} / {} ({} threads, {} suite): write it under another \
                     --name instead",
                    a.cpu_model,
                    a.adapter_name(),
                    a.rayon_threads,
                    suite_name(self.suite),
                    b.cpu_model,
                    b.adapter_name(),
                    b.rayon_threads,
                    suite_name(newer.suite)
                ),
            ));
        }
        let ids: Vec<String> = newer.cases.iter().map(CaseReport::id).collect();
        for case in newer.cases {
            let id = case.id();
            match self.cases.iter_mut().find(|c| c.id() == id) {
                Some(old) => *old = case,
                None => self.cases.push(case),
            }
        }
        let rank = |id: &str| order.iter().position(|o| o == id).unwrap_or(usize::MAX);
        self.cases.sort_by_key(|c| rank(&c.id()));
        self.merged.extend(newer.merged);
        self.merged.push(MergedRun {
            date_utc: b.date_utc.clone(),
            command_line: b.command_line.clone(),
            cases: ids,
            seconds: newer.seconds,
        });
        self.apply_peak();
        Ok(())
    }

    /// Every failure and error, one line each.
    pub fn problems(&self) -> Vec<String> {
        self.cases.iter().flat_map(CaseReport::problems).collect()
    }

    /// True when no case failed a parity check or errored: the exit status CI reads.
    pub fn passed(&self) -> bool {
        self.cases.iter().all(|c| c.status() == Status::Passed)
    }

    /// The adapter's name (without a parenthesised part) as a file name:
    /// `nvidia-h200`, `llvmpipe`; `cpu-only` without a GPU.
    pub fn default_slug(&self) -> String {
        match &self.machine.adapter {
            Some(a) => {
                // "llvmpipe (LLVM 15.0.6, 256 bits)" → "llvmpipe".
                let base = a.name.split('(').next().unwrap_or("");
                let s = slugify(if base.trim().is_empty() {
                    &a.name
                } else {
                    base
                });
                if s.is_empty() {
                    "gpu".to_string()
                } else {
                    s
                }
            }
            None => "cpu-only".to_string(),
        }
    }

    /// The report as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a report serialises")
    }

    /// The Markdown report: machine, method, one table per family.
    pub fn to_markdown(&self) -> String {
        markdown(self)
    }

    /// The chart of GPU speedups over CPU f32.
    pub fn to_svg(&self) -> String {
        svg(self)
    }

    /// Writes `<slug>.json`, `<slug>.md` and `<slug>.svg` into `dir` (created if
    /// missing), each atomically. Returns the three paths.
    pub fn write(&self, dir: &Path, slug: &str) -> Result<Vec<PathBuf>> {
        check_out_dir(dir)?;
        if slug.is_empty() || slug.contains(['/', '\\']) || slug.starts_with('.') {
            return Err(Error::invalid(
                "--name",
                format!("'{slug}' is not a plain file name"),
            ));
        }
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let files = [
            ("json", self.to_json()),
            ("md", self.to_markdown()),
            ("svg", self.to_svg()),
        ];
        let mut paths = Vec::new();
        for (ext, text) in files {
            let path = dir.join(format!("{slug}.{ext}"));
            crate::io::write_atomic(&path, |w| {
                w.write_all(text.as_bytes())
                    .map_err(|e| Error::io(&path, e))
            })?;
            paths.push(path);
        }
        Ok(paths)
    }
}

fn suite_name(s: Suite) -> &'static str {
    match s {
        Suite::Quick => "quick",
        Suite::Full => "full",
    }
}

/// Refuses an output folder that is an existing file (or lies under one).
pub fn check_out_dir(dir: &Path) -> Result<()> {
    crate::io::check_output_dir("--out", dir)
}

/// Lower-case ASCII letters and digits, runs of anything else as one `-`.
pub fn slugify(s: &str) -> String {
    let mut out = String::new();
    for c in s.chars() {
        if c.is_ascii_alphanumeric() {
            out.push(c.to_ascii_lowercase());
        } else if !out.is_empty() && !out.ends_with('-') {
            out.push('-');
        }
    }
    out.trim_end_matches('-').to_string()
}

/// Seconds with three significant digits in ns, µs, ms or s.
pub fn fmt_seconds(s: f64) -> String {
    if !s.is_finite() {
        return "—".to_string();
    }
    let (v, unit) = if s >= 1.0 {
        (s, "s")
    } else if s >= 1e-3 {
        (s * 1e3, "ms")
    } else if s >= 1e-6 {
        (s * 1e6, "µs")
    } else {
        (s * 1e9, "ns")
    };
    format!("{} {unit}", sig3(v))
}

/// Three significant digits, no exponent for everyday magnitudes.
fn sig3(v: f64) -> String {
    let a = v.abs();
    if a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 10.0 {
        format!("{v:.1}")
    } else if a >= 1.0 {
        format!("{v:.2}")
    } else if a >= 0.01 {
        format!("{v:.3}")
    } else if a == 0.0 {
        "0".to_string()
    } else {
        format!("{v:.2e}")
    }
}

fn fmt_ratio(r: Option<f64>) -> String {
    r.map_or("—".to_string(), |r| format!("{}×", sig3(r)))
}

/// A time cell: the median and the range, or why there is none.
fn time_cell(b: &BackendReport, stats: Option<&Stats>) -> String {
    match b.status {
        Status::Passed => match stats {
            Some(s) if s.samples.len() > 1 => format!(
                "{} ({}–{}, n={})",
                fmt_seconds(s.median),
                sig3_seconds_bare(s.min, s.median),
                sig3_seconds_bare(s.max, s.median),
                s.samples.len()
            ),
            Some(s) => format!("{} (n=1)", fmt_seconds(s.median)),
            None => "not timed".to_string(),
        },
        Status::Failed => "FAILED".to_string(),
        Status::Errored => "ERROR".to_string(),
        Status::Skipped => "—".to_string(),
    }
}

/// `v` in the unit `reference` is shown in, without the unit.
fn sig3_seconds_bare(v: f64, reference: f64) -> String {
    let scale = if reference >= 1.0 {
        1.0
    } else if reference >= 1e-3 {
        1e3
    } else if reference >= 1e-6 {
        1e6
    } else {
        1e9
    };
    sig3(v * scale)
}

fn parity_cell(b: &BackendReport) -> String {
    match (&b.status, &b.parity) {
        (Status::Passed, Some(p)) if p.rel_l2 == 0.0 => "0 (exact)".to_string(),
        (Status::Passed, Some(p)) => format!("{:.1e}", p.rel_l2),
        (Status::Failed, Some(p)) => format!(
            "**FAILED** (rel L2 {:.2e}, max {:.2e}{})",
            p.rel_l2,
            p.max_abs_rel,
            if p.non_finite > 0 {
                format!(", {} NaN/∞", p.non_finite)
            } else {
                String::new()
            }
        ),
        (Status::Errored, _) => format!(
            "**ERROR**: {}",
            b.message.as_deref().unwrap_or("").replace('|', "\\|")
        ),
        _ => "—".to_string(),
    }
}

fn throughput_cell(c: &CaseReport) -> String {
    let mut parts = Vec::new();
    for (i, w) in c.work.iter().enumerate() {
        let (_, label) = unit_scale(w.unit);
        let pick = |b: &BackendReport| {
            (b.status == Status::Passed)
                .then(|| b.throughput.get(i).map(|t| sig3(t.value)))
                .flatten()
                .unwrap_or_else(|| "—".to_string())
        };
        parts.push(format!(
            "{} / {} / {} {label}",
            pick(&c.cpu_f64),
            pick(&c.cpu_f32),
            pick(&c.gpu)
        ));
    }
    parts.join("<br>")
}

fn fmt_bytes(b: u64) -> String {
    format!("{:.1} GiB", b as f64 / (1u64 << 30) as f64)
}

fn markdown(r: &Report) -> String {
    let m = &r.machine;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# voxlab benchmark: {} ({} suite)\n",
        m.adapter_name(),
        match r.suite {
            Suite::Quick => "quick",
            Suite::Full => "full",
        }
    );
    if m.adapter.as_ref().is_some_and(|a| a.device_type == "Cpu") {
        let _ = writeln!(
            s,
            "**The adapter here is a CPU emulating a GPU** (a software rasteriser such as \
             Mesa's lavapipe): its \"GPU\" columns time the WGSL port compiled for the same \
             CPU cores that run the CPU columns. They show the method and check the port; \
             they say nothing about GPU speed, and speedups near or below 1× are expected.\n"
        );
    }
    let _ = writeln!(s, "## Machine\n");
    let _ = writeln!(s, "| | |\n|---|---|");
    let _ = writeln!(s, "| date (UTC) | {} |", m.date_utc);
    let _ = writeln!(s, "| OS / arch | {} / {} |", m.os, m.arch);
    let _ = writeln!(
        s,
        "| CPU | {} ({} logical cores, {} rayon threads) |",
        m.cpu_model, m.logical_cores, m.rayon_threads
    );
    let _ = writeln!(
        s,
        "| memory | {} |",
        m.memory_bytes.map_or("unknown".to_string(), fmt_bytes)
    );
    match &m.adapter {
        Some(a) => {
            let _ = writeln!(
                s,
                "| GPU | {} ({}, {}{}) |",
                a.name,
                a.backend,
                a.device_type,
                if a.device_type == "Cpu" {
                    ": a CPU emulating a GPU"
                } else {
                    ""
                }
            );
            let _ = writeln!(s, "| driver | {} {} |", a.driver, a.driver_info);
            let _ = writeln!(
                s,
                "| kernel timing | {} |",
                if a.timestamp_queries {
                    "timestamp queries"
                } else {
                    "host clock around waited submissions (no timestamp queries)"
                }
            );
        }
        None => {
            let _ = writeln!(
                s,
                "| GPU | none: {} |",
                m.no_adapter_reason.as_deref().unwrap_or("not used")
            );
        }
    }
    let _ = writeln!(
        s,
        "| software | voxlab {}, wgpu {}, {} |",
        m.voxlab_version, m.wgpu_version, m.rustc_version
    );
    let _ = writeln!(s, "| command | `{}` |", m.command_line.replace('|', "\\|"));
    let _ = writeln!(s, "| total time | {} |", fmt_seconds(r.seconds));
    for later in &r.merged {
        let _ = writeln!(
            s,
            "| later run, merged | {} `{}` ({}; {} case(s): {}) |",
            later.date_utc,
            later.command_line.replace('|', "\\|"),
            fmt_seconds(later.seconds),
            later.cases.len(),
            later.cases.join(", ")
        );
    }
    let _ = writeln!(s);
    let _ = writeln!(s, "## Method\n");
    let _ = writeln!(
        s,
        "Each case builds its inputs first (\"prep\", not timed with the runs). Each backend \
         then runs {} warm-up run(s) and up to {} timed run(s); a backend stops adding runs \
         once {} are done and {} s are spent. Times are medians, with the minimum–maximum \
         range and the run count n. The first result of the CPU f64 oracle is the reference; \
         the first result of CPU f32 and of the GPU is checked against it before any timing \
         (parity: max |Δ| / max |oracle| and relative L2, both within the case's tolerance, \
         no NaN/∞); a backend that fails is marked FAILED and not timed. GPU kernel = the \
         compute passes alone; end to end = upload + passes + readback; set-up (shaders, \
         pipelines, parameter buffers) is apart: the device keeps the pipelines the warm-up \
         compiled, so the timed runs' set-up is what a call pays once they are compiled \
         (the warm-up's seconds, compilation included, are in the JSON's warmup_seconds). \
         Speedups are quoted against CPU f32, the fair baseline: the \
         f64 oracle is slow by design. Throughput columns are CPU f64 / CPU f32 / GPU kernel.\n",
        r.warmup,
        r.runs,
        r.min_runs.min(r.runs),
        r.budget_seconds
    );
    for fam in FAMILIES {
        let cases: Vec<&CaseReport> = r.cases.iter().filter(|c| c.family == fam).collect();
        if cases.is_empty() {
            continue;
        }
        let _ = writeln!(s, "## {fam}\n");
        let _ = writeln!(
            s,
            "| case | size | CPU f64 | CPU f32 | f64/f32 | GPU kernel | GPU end to end | GPU set-up | f32/kernel | f32/e2e | throughput (f64 / f32 / GPU) | parity f32 | parity GPU |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|---|");
        for c in &cases {
            if let Some(e) = &c.error {
                let _ = writeln!(
                    s,
                    "| {} | {} | **ERROR**: {} | | | | | | | | | | |",
                    c.name,
                    c.size,
                    e.replace('|', "\\|")
                );
                continue;
            }
            let k = if c.gpu.kernel_from_timestamps == Some(false) {
                " (wall)"
            } else {
                ""
            };
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {}{} | {} | {} | {} | {} | {} | {} | {} |",
                c.name,
                c.size,
                time_cell(&c.cpu_f64, c.cpu_f64.seconds.as_ref()),
                time_cell(&c.cpu_f32, c.cpu_f32.seconds.as_ref()),
                fmt_ratio(c.speedups.f64_over_f32),
                time_cell(&c.gpu, c.gpu.kernel.as_ref()),
                if c.gpu.status == Status::Passed {
                    k
                } else {
                    ""
                },
                time_cell(&c.gpu, c.gpu.end_to_end.as_ref()),
                c.gpu
                    .setup
                    .as_ref()
                    .filter(|_| c.gpu.status == Status::Passed)
                    .map_or("—".to_string(), |x| fmt_seconds(x.median)),
                fmt_ratio(c.speedups.f32_over_gpu_kernel),
                fmt_ratio(c.speedups.f32_over_gpu_end_to_end),
                throughput_cell(c),
                parity_cell(&c.cpu_f32),
                parity_cell(&c.gpu),
            );
        }
        let notes: Vec<String> = cases
            .iter()
            .filter_map(|c| {
                let mut bits = Vec::new();
                if let Some(p) = c.prepare_seconds {
                    bits.push(format!("prep {}", fmt_seconds(p)));
                }
                for (label, b) in c.backends() {
                    if b.status == Status::Skipped {
                        if let Some(m) = &b.message {
                            bits.push(format!("{label}: {m}"));
                        }
                    }
                }
                let note = c.note.trim();
                let bits = bits.join("; ");
                match (note.is_empty(), bits.is_empty()) {
                    (true, true) => None,
                    (false, true) => Some(format!("- {} {}: {note}", c.name, c.size)),
                    (true, false) => Some(format!("- {} {}: {bits}", c.name, c.size)),
                    (false, false) => Some(format!("- {} {}: {note} ({bits})", c.name, c.size)),
                }
            })
            .collect();
        if !notes.is_empty() {
            let _ = writeln!(s, "\n{}", notes.join("\n"));
        }
        let _ = writeln!(s);
    }
    roofline(r, &mut s);
    let problems = r.problems();
    let _ = writeln!(s, "## Result\n");
    if problems.is_empty() {
        let _ = writeln!(
            s,
            "All {} case(s) passed their parity checks.",
            r.cases.len()
        );
    } else {
        let _ = writeln!(s, "{} problem(s):\n", problems.len());
        for p in problems {
            let _ = writeln!(s, "- {}", p.replace('|', "\\|"));
        }
    }
    s
}

/// The roofline section: every GPU kernel throughput in GB/s or GFLOP/s against the
/// adapter's data-sheet peak ([`crate::gpu::peak`]), or why there is none.
fn roofline(r: &Report, s: &mut String) {
    let Some(adapter) = &r.machine.adapter else {
        return;
    };
    let _ = writeln!(s, "## Roofline\n");
    let Some(peak) = &adapter.peak else {
        let _ = writeln!(
            s,
            "{} is not in the table of GPUs whose peaks voxlab knows (`src/gpu/peak.rs`): \
             no fraction of peak is given.\n",
            adapter.name
        );
        return;
    };
    let _ = writeln!(
        s,
        "GPU kernel throughput against the {}'s data-sheet peaks: {} GB/s memory \
         bandwidth, {} TFLOP/s FP32. The bytes are those each case counts (one read and \
         one write of its data per pass): where a kernel reads its data more than once, \
         its real traffic is higher than the figure.\n",
        peak.part,
        sig3(peak.memory_gbps),
        sig3(peak.fp32_tflops)
    );
    let _ = writeln!(
        s,
        "| case | size | GPU kernel | achieved | peak | of peak |\n|---|---|---|---|---|---|"
    );
    let mut any = false;
    for c in r.cases.iter().filter(|c| c.gpu.status == Status::Passed) {
        for t in &c.gpu.throughput {
            let (Some(f), Some(p)) = (t.of_peak, peak.of_unit(t.unit)) else {
                continue;
            };
            any = true;
            let _ = writeln!(
                s,
                "| {}/{} | {} | {} | {} {} | {} {} | {:.1} % |",
                c.family,
                c.name,
                c.size,
                c.gpu
                    .kernel
                    .as_ref()
                    .map_or("—".to_string(), |k| fmt_seconds(k.median)),
                sig3(t.value),
                t.label,
                sig3(p),
                t.label,
                100.0 * f
            );
        }
    }
    if !any {
        let _ = writeln!(s, "| (no case counts bytes or FLOPs) | | | | | |");
    }
    let _ = writeln!(s);
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Horizontal bars of f32/GPU-kernel and f32/GPU-end-to-end per case, on a log axis,
/// grouped by family.
fn svg(r: &Report) -> String {
    const LEFT: f64 = 340.0;
    const PLOT_W: f64 = 560.0;
    const RIGHT: f64 = 60.0;
    const TOP: f64 = 70.0;
    const BAR: f64 = 9.0;
    const CASE_H: f64 = 26.0;
    const FAMILY_H: f64 = 24.0;
    const KERNEL: &str = "#3b6ea8";
    const E2E: &str = "#e08a2c";
    // The axis: decades covering every ratio, and at least 0.1× … 10×.
    let ratios: Vec<f64> = r
        .cases
        .iter()
        .flat_map(|c| {
            [
                c.speedups.f32_over_gpu_kernel,
                c.speedups.f32_over_gpu_end_to_end,
            ]
        })
        .flatten()
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    let lo = ratios.iter().fold(0.1f64, |a, &v| a.min(v)).log10().floor();
    let hi = ratios.iter().fold(10.0f64, |a, &v| a.max(v)).log10().ceil();
    let x = |v: f64| LEFT + (v.log10() - lo) / (hi - lo) * PLOT_W;
    let mut rows = 0.0;
    let mut families = 0.0;
    for fam in FAMILIES {
        let n = r.cases.iter().filter(|c| c.family == fam).count();
        if n > 0 {
            families += 1.0;
            rows += n as f64;
        }
    }
    let plot_h = (families * FAMILY_H + rows * CASE_H).max(CASE_H);
    let width = LEFT + PLOT_W + RIGHT;
    let height = TOP + plot_h + 60.0;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(
        s,
        r#"<rect x="0" y="0" width="{width}" height="{height}" fill="white"/>"#
    );
    let _ = writeln!(
        s,
        r#"<text x="{}" y="24" font-size="16" text-anchor="middle">{}</text>"#,
        width / 2.0,
        xml_escape(&format!(
            "GPU speedup over CPU f32 ({} threads): {}",
            r.machine.rayon_threads,
            r.machine.adapter_name()
        ))
    );
    // Legend.
    let _ = writeln!(
        s,
        r#"<rect x="{LEFT}" y="38" width="14" height="{BAR}" fill="{KERNEL}"/><text x="{}" y="46">f32 / GPU kernel</text>"#,
        LEFT + 20.0
    );
    let _ = writeln!(
        s,
        r#"<rect x="{}" y="38" width="14" height="{BAR}" fill="{E2E}"/><text x="{}" y="46">f32 / GPU end to end (upload + kernel + readback)</text>"#,
        LEFT + 150.0,
        LEFT + 170.0
    );
    // Grid: one line per decade, the 1× line darker.
    let bottom = TOP + plot_h;
    let mut d = lo;
    while d <= hi + 0.5 {
        let v = 10f64.powf(d);
        let xv = x(v);
        let (stroke, w) = if d == 0.0 {
            ("#000", 1.5)
        } else {
            ("#ccc", 1.0)
        };
        let _ = writeln!(
            s,
            r#"<line x1="{xv:.1}" y1="{TOP}" x2="{xv:.1}" y2="{bottom}" stroke="{stroke}" stroke-width="{w}"/>"#
        );
        let label = if d < 0.0 {
            format!("{:.*}×", (-d) as usize, v)
        } else {
            format!("{v:.0}×")
        };
        let _ = writeln!(
            s,
            r#"<text x="{xv:.1}" y="{}" text-anchor="middle">{label}</text>"#,
            bottom + 16.0
        );
        d += 1.0;
    }
    let _ = writeln!(
        s,
        r#"<text x="{}" y="{}" text-anchor="middle">speedup (median CPU f32 time / median GPU time), log scale; right of 1× the GPU is faster</text>"#,
        LEFT + PLOT_W / 2.0,
        bottom + 36.0
    );
    let mut y = TOP;
    for fam in FAMILIES {
        let cases: Vec<&CaseReport> = r.cases.iter().filter(|c| c.family == fam).collect();
        if cases.is_empty() {
            continue;
        }
        let _ = writeln!(
            s,
            r#"<text x="8" y="{}" font-weight="bold">{}</text>"#,
            y + 16.0,
            xml_escape(fam)
        );
        y += FAMILY_H;
        for c in cases {
            let _ = writeln!(
                s,
                r#"<text x="{}" y="{}" text-anchor="end">{}</text>"#,
                LEFT - 8.0,
                y + 16.0,
                xml_escape(&format!("{} {}", c.name, c.size))
            );
            let bars = [
                (c.speedups.f32_over_gpu_kernel, KERNEL, y + 3.0),
                (c.speedups.f32_over_gpu_end_to_end, E2E, y + 4.0 + BAR),
            ];
            let mut any = false;
            for (v, colour, by) in bars {
                if let Some(v) = v.filter(|v| v.is_finite() && *v > 0.0) {
                    any = true;
                    let (x0, x1) = (x(1.0), x(v));
                    let _ = writeln!(
                        s,
                        r#"<rect x="{:.1}" y="{by:.1}" width="{:.1}" height="{BAR}" fill="{colour}"><title>{}</title></rect>"#,
                        x0.min(x1),
                        (x1 - x0).abs().max(1.0),
                        fmt_ratio(Some(v))
                    );
                    let _ = writeln!(
                        s,
                        r#"<text x="{:.1}" y="{:.1}" font-size="9" text-anchor="{}">{}</text>"#,
                        if v >= 1.0 { x1 + 3.0 } else { x1 - 3.0 },
                        by + BAR - 1.0,
                        if v >= 1.0 { "start" } else { "end" },
                        fmt_ratio(Some(v))
                    );
                }
            }
            if !any {
                let why = match (c.status(), c.gpu.status, c.cpu_f32.status) {
                    (_, Status::Failed, _) => "GPU FAILED parity",
                    (_, Status::Errored, _) => "GPU error",
                    (Status::Errored, _, _) => "error",
                    (_, _, Status::Failed) => "CPU f32 FAILED parity",
                    (_, Status::Skipped, _) => "no GPU result",
                    _ => "no CPU f32 result",
                };
                let _ = writeln!(
                    s,
                    r##"<text x="{:.1}" y="{}" fill="#a00">{why}</text>"##,
                    x(1.0) + 6.0,
                    y + 16.0
                );
            }
            y += CASE_H;
        }
    }
    s.push_str("</svg>\n");
    s
}
