//! The parity vocabulary: how far a port's output is from the oracle's, and whether
//! that is within tolerance. Used by every CPU–GPU test, by the benchmark's parity gate
//! (`voxlab bench`) and by `voxlab compare`.
//!
//! - [`error_stats`] measures two real arrays, [`error_stats_complex`] two complex ones
//!   (a complex difference counts by its modulus |z − w|): an [`ErrorStats`].
//! - A [`Tolerance`] bounds any of max |Δ|, the RMSE, max |Δ| relative to the oracle's
//!   peak, and the relative L2 error; a bound left at ∞ is no bound.
//! - [`check_parity`] (frames), [`check_parity_array`] (real N-D arrays, x fastest) and
//!   [`check_parity_complex`] (complex N-D arrays, x fastest) hold a port against an
//!   oracle and a tolerance. A NaN or infinity on one side only, or two different ones,
//!   always fails. The message names the worst element by its index and, on failure,
//!   the bounds exceeded and the first mismatches.
//!
//! On failure the checks write their evidence into a folder (the tests use
//! `target/parity/<case>/`): always `stats.json`; for frames and 2-D arrays `cpu.png`,
//! `gpu.png` and `diff.png` (a heat map of |Δ| with its colour scale); for arrays
//! `cpu.npy` and `gpu.npy` (f64, complex values as a last axis of 2: re, im).
//!
//! ```
//! use voxlab::metrics::{check_parity_array, Tolerance};
//! let oracle = [1.0, 2.0, 3.0, 4.0];
//! let port = [1.0f32, 2.0, 3.0, 4.001];
//! let tol = Tolerance::max_abs_rel(1e-3).with_rel_l2(1e-3);
//! let r = check_parity_array("doc", &[2, 2], &oracle, &port, tol, None).unwrap();
//! assert!(r.passed, "{}", r.message);
//! assert_eq!(r.stats.worst_index, 3);
//! ```

use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::io::{write_frame, PngOptions};
use rustfft::num_complex::Complex;
use serde::Serialize;
use std::path::Path;

/// How two arrays differ. Differences are taken where both sides are finite; the
/// oracle's norm and peak over every finite oracle value.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ErrorStats {
    /// Elements compared (complex values count once).
    pub n: usize,
    /// Largest |oracle − port| (for complex values the modulus |z − w|).
    pub max_abs: f64,
    /// Index of the largest difference: in the flat array (x fastest); in a frame
    /// `(row · width + col) · channels + channel`.
    pub worst_index: usize,
    /// Root mean square of the differences, √(Σ|Δ|² / n).
    pub rmse: f64,
    /// ‖oracle − port‖₂ / ‖oracle‖₂, as √(Σ|Δ|² / Σ|oracle|²) (0 when both are zero, ∞
    /// when only the oracle is).
    pub rel_l2: f64,
    /// 20 log10(peak / rmse), with peak the largest |oracle| (∞ when identical).
    pub psnr_db: f64,
    /// Elements whose difference exceeds the tolerance's `max_abs`, NaN/Inf mismatches
    /// included.
    pub n_over: usize,
    /// Elements where exactly one side is NaN or infinite, or both are but differ.
    pub non_finite_mismatches: usize,
    /// The largest |oracle|. (Not in the serialised stats, whose fields `voxlab compare`
    /// writes as they are; [`check_parity`]'s `stats.json` has it beside them.)
    #[serde(skip)]
    pub peak: f64,
    /// `max_abs / peak`: 0 when `max_abs` is 0, ∞ when only `peak` is. (Not serialised,
    /// like `peak`.)
    #[serde(skip)]
    pub max_abs_rel: f64,
    /// The mean difference, Σ|Δ| / n. (Not serialised, like `peak`.)
    #[serde(skip)]
    pub mean_abs: f64,
}

impl ErrorStats {
    /// The same statistics with every error measure (`max_abs`, `max_abs_rel`, `rmse`,
    /// `rel_l2`, `mean_abs`) infinite when a NaN/Inf mismatch was found, so that any
    /// bound asserted on one of them fails: for code that bounds one number itself
    /// rather than through a [`Tolerance`].
    pub fn infinite_if_mismatched(mut self) -> Self {
        if self.non_finite_mismatches > 0 {
            self.max_abs = f64::INFINITY;
            self.max_abs_rel = f64::INFINITY;
            self.rmse = f64::INFINITY;
            self.rel_l2 = f64::INFINITY;
            self.mean_abs = f64::INFINITY;
        }
        self
    }
}

/// What counts as agreement: every bound must hold. A bound at ∞ is no bound; build
/// one with the constructors and `with_*`, e.g.
/// `Tolerance::max_abs(1e-3).with_rmse(5e-5)`, or as a literal with `..Tolerance::NONE`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Tolerance {
    /// No element may differ by more than this.
    pub max_abs: f64,
    /// The root-mean-square difference may not exceed this.
    pub rmse: f64,
    /// `max |Δ| / max |oracle|` ([`ErrorStats::max_abs_rel`]) may not exceed this.
    pub max_abs_rel: f64,
    /// The relative L2 error ‖oracle − port‖₂ / ‖oracle‖₂ may not exceed this.
    pub rel_l2: f64,
}

impl Tolerance {
    /// No bound at all (only NaN/Inf mismatches fail).
    pub const NONE: Tolerance = Tolerance {
        max_abs: f64::INFINITY,
        rmse: f64::INFINITY,
        max_abs_rel: f64::INFINITY,
        rel_l2: f64::INFINITY,
    };

    /// Only a bound on the largest absolute difference.
    pub const fn max_abs(bound: f64) -> Self {
        Tolerance {
            max_abs: bound,
            ..Self::NONE
        }
    }

    /// Only a bound on the RMSE.
    pub const fn rmse(bound: f64) -> Self {
        Tolerance {
            rmse: bound,
            ..Self::NONE
        }
    }

    /// Only a bound on the largest absolute difference relative to the oracle's peak.
    pub const fn max_abs_rel(bound: f64) -> Self {
        Tolerance {
            max_abs_rel: bound,
            ..Self::NONE
        }
    }

    /// Only a bound on the relative L2 error.
    pub const fn rel_l2(bound: f64) -> Self {
        Tolerance {
            rel_l2: bound,
            ..Self::NONE
        }
    }

    /// The same with a bound on the largest absolute difference.
    pub const fn with_max_abs(self, bound: f64) -> Self {
        Tolerance {
            max_abs: bound,
            ..self
        }
    }

    /// The same with a bound on the RMSE.
    pub const fn with_rmse(self, bound: f64) -> Self {
        Tolerance {
            rmse: bound,
            ..self
        }
    }

    /// The same with a bound on max |Δ| relative to the oracle's peak.
    pub const fn with_max_abs_rel(self, bound: f64) -> Self {
        Tolerance {
            max_abs_rel: bound,
            ..self
        }
    }

    /// The same with a bound on the relative L2 error.
    pub const fn with_rel_l2(self, bound: f64) -> Self {
        Tolerance {
            rel_l2: bound,
            ..self
        }
    }

    /// The same bounds with the absolute ones (`max_abs`, `rmse`) scaled by `scale` (for
    /// outputs in data units); the relative ones stay.
    pub fn scaled(self, scale: f64) -> Self {
        Tolerance {
            max_abs: self.max_abs * scale,
            rmse: self.rmse * scale,
            ..self
        }
    }

    /// The bounds `stats` exceeds, in words (`"rel L2 3.210e-6 > 1.0e-6"`); empty when
    /// every bound holds. A NaN statistic exceeds its bound. NaN/Inf mismatches are not
    /// listed here: they fail a check whatever the tolerance.
    pub fn exceeded(&self, stats: &ErrorStats) -> Vec<String> {
        let mut why = Vec::new();
        if !within(stats.max_abs, self.max_abs) {
            why.push(format!(
                "max |Δ| {:.3e} > {:.1e}",
                stats.max_abs, self.max_abs
            ));
        }
        if !within(stats.max_abs_rel, self.max_abs_rel) {
            why.push(format!(
                "max |Δ|/max|oracle| {:.3e} > {:.1e}",
                stats.max_abs_rel, self.max_abs_rel
            ));
        }
        if !within(stats.rmse, self.rmse) {
            why.push(format!("rmse {:.3e} > {:.1e}", stats.rmse, self.rmse));
        }
        if !within(stats.rel_l2, self.rel_l2) {
            why.push(format!("rel L2 {:.3e} > {:.1e}", stats.rel_l2, self.rel_l2));
        }
        why
    }

    /// Whether `stats` is within every bound and has no NaN/Inf mismatch.
    pub fn admits(&self, stats: &ErrorStats) -> bool {
        stats.non_finite_mismatches == 0 && self.exceeded(stats).is_empty()
    }

    /// The largest difference one element may have: `max_abs`, or `max_abs_rel` of
    /// the oracle's `peak` where that is smaller (used to list the mismatches).
    fn element_bound(&self, peak: f64) -> f64 {
        self.max_abs.min(self.max_abs_rel * peak)
    }
}

/// `value ≤ bound`; a NaN value is never within.
fn within(value: f64, bound: f64) -> bool {
    value <= bound
}

/// One compared value: a real number, or a complex one compared by the modulus of
/// the difference.
trait Value: Copy {
    fn finite(self) -> bool;
    /// Both non-finite alike (NaN and NaN, or the same infinity; per part for complex).
    fn same(self, other: Self) -> bool;
    /// |self − other| and |self − other|².
    fn diff(self, other: Self) -> (f64, f64);
    /// |self| and |self|².
    fn magnitude(self) -> (f64, f64);
    fn show(self) -> String;
    fn json(self) -> serde_json::Value;
}

impl Value for f64 {
    fn finite(self) -> bool {
        self.is_finite()
    }
    fn same(self, other: f64) -> bool {
        (self.is_nan() && other.is_nan()) || self == other
    }
    fn diff(self, other: f64) -> (f64, f64) {
        let d = (self - other).abs();
        (d, d * d)
    }
    fn magnitude(self) -> (f64, f64) {
        (self.abs(), self * self)
    }
    fn show(self) -> String {
        format!("{self:.6e}")
    }
    fn json(self) -> serde_json::Value {
        finite_or_string(self)
    }
}

impl Value for Complex<f64> {
    fn finite(self) -> bool {
        self.re.is_finite() && self.im.is_finite()
    }
    fn same(self, other: Self) -> bool {
        self.re.same(other.re) && self.im.same(other.im)
    }
    fn diff(self, other: Self) -> (f64, f64) {
        let d = self - other;
        (d.norm(), d.norm_sqr())
    }
    fn magnitude(self) -> (f64, f64) {
        (self.norm(), self.norm_sqr())
    }
    fn show(self) -> String {
        format!("({:.6e}, {:.6e})", self.re, self.im)
    }
    fn json(self) -> serde_json::Value {
        serde_json::json!([finite_or_string(self.re), finite_or_string(self.im)])
    }
}

/// A number for JSON, with NaN and ±∞ spelt out (JSON has no such numbers).
fn finite_or_string(v: f64) -> serde_json::Value {
    if v.is_finite() {
        serde_json::json!(v)
    } else {
        serde_json::json!(v.to_string())
    }
}

/// The statistics of `n` pairs `(oracle, port)`; `max_abs` decides `n_over`.
fn measure<V: Value>(n: usize, pair: impl Fn(usize) -> (V, V), max_abs: f64) -> ErrorStats {
    let mut s = ErrorStats {
        n,
        ..Default::default()
    };
    let (mut sum, mut sum_sq, mut ref_sq, mut peak) = (0.0, 0.0, 0.0, 0.0f64);
    for i in 0..n {
        let (a, b) = pair(i);
        if a.finite() {
            let (m, m2) = a.magnitude();
            ref_sq += m2;
            peak = peak.max(m);
        }
        if !(a.finite() && b.finite()) {
            if !a.same(b) {
                s.non_finite_mismatches += 1;
                s.n_over += 1;
            }
            continue;
        }
        let (d, d2) = a.diff(b);
        if d > s.max_abs {
            s.max_abs = d;
            s.worst_index = i;
        }
        if d > max_abs {
            s.n_over += 1;
        }
        sum += d;
        sum_sq += d2;
    }
    let n = s.n.max(1) as f64;
    s.mean_abs = sum / n;
    s.rmse = (sum_sq / n).sqrt();
    s.rel_l2 = if ref_sq > 0.0 {
        (sum_sq / ref_sq).sqrt()
    } else if sum_sq > 0.0 {
        f64::INFINITY
    } else {
        0.0
    };
    s.psnr_db = if s.rmse > 0.0 {
        20.0 * (peak.max(f64::MIN_POSITIVE) / s.rmse).log10()
    } else {
        f64::INFINITY
    };
    s.peak = peak;
    s.max_abs_rel = if s.max_abs == 0.0 {
        0.0
    } else if peak == 0.0 {
        f64::INFINITY
    } else {
        s.max_abs / peak
    };
    s
}

/// The largest |a − b| over two real arrays (or frames) of one length, in f64; ∞ when
/// one holds a NaN or infinity the other lacks there, so that any bound on it fails.
/// For code that bounds this one number itself rather than through a [`Tolerance`].
pub fn max_abs_error<A, B>(a: &(impl AsRef<[A]> + ?Sized), b: &(impl AsRef<[B]> + ?Sized)) -> f64
where
    A: Copy + Into<f64>,
    B: Copy + Into<f64>,
{
    error_stats(a.as_ref(), b.as_ref(), f64::INFINITY)
        .infinite_if_mismatched()
        .max_abs
}

/// Computes the statistics of `port` against `oracle` (real values, f32 or f64 on
/// either side); `max_abs` decides `n_over`. Panics when the lengths differ.
pub fn error_stats<A, B>(oracle: &[A], port: &[B], max_abs: f64) -> ErrorStats
where
    A: Copy + Into<f64>,
    B: Copy + Into<f64>,
{
    assert_eq!(
        oracle.len(),
        port.len(),
        "compared arrays must have one length"
    );
    measure(
        oracle.len(),
        |i| (oracle[i].into(), port[i].into()),
        max_abs,
    )
}

/// Computes the statistics of complex `port` against complex `oracle`, each element
/// compared as a whole: `max_abs` is the largest modulus |z − w| (not the largest
/// difference of a real or imaginary part), `rel_l2` is √(Σ|z − w|² / Σ|z|²) (the
/// same as over the interleaved parts). `max_abs` decides `n_over`. Panics when the
/// lengths differ.
pub fn error_stats_complex<A, B>(
    oracle: &[Complex<A>],
    port: &[Complex<B>],
    max_abs: f64,
) -> ErrorStats
where
    A: Copy + Into<f64>,
    B: Copy + Into<f64>,
{
    assert_eq!(
        oracle.len(),
        port.len(),
        "compared arrays must have one length"
    );
    measure(
        oracle.len(),
        |i| (widen(oracle[i]), widen(port[i])),
        max_abs,
    )
}

fn widen<T: Copy + Into<f64>>(z: Complex<T>) -> Complex<f64> {
    Complex::new(z.re.into(), z.im.into())
}

/// The outcome of a parity check.
#[derive(Clone, Debug)]
pub struct ParityReport {
    pub case: String,
    pub stats: ErrorStats,
    pub tolerance: Tolerance,
    pub passed: bool,
    /// A human-readable summary: the statistics and where the worst element is; on
    /// failure also the bounds exceeded, the first mismatches and where the evidence
    /// was written.
    pub message: String,
}

/// What a check found, before its evidence is written.
struct Finding {
    stats: ErrorStats,
    passed: bool,
    message: String,
    json: serde_json::Value,
}

/// Measures, judges and describes `n` pairs; `locate` names an element by its flat
/// index (as text and as JSON).
fn judge<V: Value>(
    case: &str,
    n: usize,
    pair: impl Fn(usize) -> (V, V),
    tol: Tolerance,
    locate: impl Fn(usize) -> (String, serde_json::Value),
) -> Finding {
    let stats = measure(n, &pair, tol.max_abs);
    let why = tol.exceeded(&stats);
    let passed = stats.non_finite_mismatches == 0 && why.is_empty();
    let mut message = format!(
        "{case}: {} on {n} elements",
        if passed { "passed" } else { "FAILED" }
    );
    if tol.max_abs < f64::INFINITY {
        message += &format!(
            ", {} over {:.1e}",
            stats.n_over - stats.non_finite_mismatches,
            tol.max_abs
        );
    }
    message += &format!("; max |Δ| {:.3e}", stats.max_abs);
    let mut json = serde_json::json!({
        "case": case,
        "passed": passed,
        "stats": stats,
        "peak": stats.peak,
        "max_abs_rel": stats.max_abs_rel,
        "mean_abs": stats.mean_abs,
        "tolerance": tol,
    });
    if n > 0 {
        let (o, p) = pair(stats.worst_index);
        let (at, at_json) = locate(stats.worst_index);
        message += &format!(" at {at} (oracle {}, port {})", o.show(), p.show());
        json["worst"] =
            serde_json::json!({ "index": at_json, "oracle": o.json(), "port": p.json() });
    }
    message += &format!(
        ", max |Δ|/peak {:.3e} (peak {:.3e}), mean |Δ| {:.3e}, rmse {:.3e}, rel L2 {:.3e}, \
         PSNR {:.1} dB",
        stats.max_abs_rel, stats.peak, stats.mean_abs, stats.rmse, stats.rel_l2, stats.psnr_db
    );
    if stats.non_finite_mismatches > 0 {
        message += &format!("; {} NaN/Inf mismatches", stats.non_finite_mismatches);
    }
    if !passed {
        if !why.is_empty() {
            message += &format!("; exceeded: {}", why.join(", "));
        }
        // Over the element bound, or non-finite unlike the oracle; when only a norm
        // bound failed, the largest differences instead.
        let bound = tol.element_bound(stats.peak);
        let over = |i: usize| {
            let (a, b) = pair(i);
            if a.finite() && b.finite() {
                a.diff(b).0 > bound
            } else {
                !a.same(b)
            }
        };
        let mut first: Vec<usize> = (0..n).filter(|&i| over(i)).take(FIRST).collect();
        let label = if first.is_empty() {
            first = largest(n, &pair, FIRST);
            "largest differences"
        } else {
            "first mismatches"
        };
        let listed: Vec<String> = first
            .iter()
            .map(|&i| {
                let (a, b) = pair(i);
                format!("{} {} vs {}", locate(i).0, a.show(), b.show())
            })
            .collect();
        if !listed.is_empty() {
            message += &format!("; {label}: {}", listed.join(", "));
        }
        json["mismatches"] = first
            .iter()
            .map(|&i| {
                let (a, b) = pair(i);
                serde_json::json!({ "index": locate(i).1, "oracle": a.json(), "port": b.json() })
            })
            .collect();
    }
    json["message"] = serde_json::json!(message);
    Finding {
        stats,
        passed,
        message,
        json,
    }
}

/// How many mismatches a failure lists.
const FIRST: usize = 5;

/// The indices of the `k` largest finite differences, largest first.
fn largest<V: Value>(n: usize, pair: impl Fn(usize) -> (V, V), k: usize) -> Vec<usize> {
    let mut top: Vec<(f64, usize)> = Vec::with_capacity(k + 1);
    for i in 0..n {
        let (a, b) = pair(i);
        if !(a.finite() && b.finite()) {
            continue;
        }
        let d = a.diff(b).0;
        if d > 0.0 && (top.len() < k || d > top[top.len() - 1].0) {
            let at = top.partition_point(|t| t.0 >= d);
            top.insert(at, (d, i));
            top.truncate(k);
        }
    }
    top.into_iter().map(|t| t.1).collect()
}

/// Finishes a check: on failure writes the evidence (`write` fills `dir`, then
/// `stats.json` goes beside it) and says where.
fn report(
    case: &str,
    mut f: Finding,
    tol: Tolerance,
    out_dir: Option<&Path>,
    write: impl FnOnce(&Path) -> Result<()>,
) -> Result<ParityReport> {
    if !f.passed {
        if let Some(dir) = out_dir {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
            write(dir)?;
            f.message += &format!("; evidence in {}", dir.display());
            f.json["message"] = serde_json::json!(f.message);
            write_json(&dir.join("stats.json"), &f.json)?;
        }
    }
    Ok(ParityReport {
        case: case.to_string(),
        stats: f.stats,
        tolerance: tol,
        passed: f.passed,
        message: f.message,
    })
}

/// Compares two frames of one size against a tolerance. When it fails and `out_dir`
/// is given, writes `cpu.png`, `gpu.png`, `diff.png` and `stats.json` there.
pub fn check_parity(
    case: &str,
    oracle: &Frame,
    port: &Frame,
    tol: Tolerance,
    out_dir: Option<&Path>,
) -> Result<ParityReport> {
    if (oracle.width, oracle.height, oracle.channels) != (port.width, port.height, port.channels) {
        return Err(Error::invalid(
            "parity check",
            format!(
                "{case}: frames differ in shape ({}×{}×{} vs {}×{}×{})",
                oracle.width,
                oracle.height,
                oracle.channels,
                port.width,
                port.height,
                port.channels
            ),
        ));
    }
    let (w, ch) = (oracle.width, oracle.channels);
    let locate = |i: usize| {
        let (px, k) = (i / ch, i % ch);
        let (c, r) = (px % w, px / w);
        (
            format!("col {c}, row {r}, channel {k}"),
            serde_json::json!({ "col": c, "row": r, "channel": k }),
        )
    };
    let f = judge(
        case,
        oracle.data.len(),
        |i| (oracle.data[i], port.data[i]),
        tol,
        locate,
    );
    report(case, f, tol, out_dir, |dir| write_images(dir, oracle, port))
}

/// Compares two real arrays of dimensions `dims`, x fastest as a volume's (element
/// `[i, j, k]` is at `i + dims[0]·(j + dims[1]·k)`; a plain slice is `&[len]`; a
/// row-major array of shape `[nz, ny, nx]` has dims `[nx, ny, nz]`) against a tolerance,
/// naming elements by their index. When it fails and `out_dir` is given, writes
/// `stats.json`, `cpu.npy` and `gpu.npy` there, and for a 2-D array also `cpu.png`,
/// `gpu.png` and `diff.png` (x across, y down).
pub fn check_parity_array<A, B>(
    case: &str,
    dims: &[usize],
    oracle: &[A],
    port: &[B],
    tol: Tolerance,
    out_dir: Option<&Path>,
) -> Result<ParityReport>
where
    A: Copy + Into<f64>,
    B: Copy + Into<f64>,
{
    check_shape(case, dims, oracle.len(), port.len())?;
    let f = judge(
        case,
        oracle.len(),
        |i| (oracle[i].into(), port[i].into()),
        tol,
        |i| locate(dims, i),
    );
    report(case, f, tol, out_dir, |dir| {
        let o: Vec<f64> = oracle.iter().map(|&x| x.into()).collect();
        let p: Vec<f64> = port.iter().map(|&x| x.into()).collect();
        let c_order: Vec<usize> = dims.iter().rev().copied().collect();
        crate::io::npy::write_npy_f64(&dir.join("cpu.npy"), &c_order, &o)?;
        crate::io::npy::write_npy_f64(&dir.join("gpu.npy"), &c_order, &p)?;
        if let [w, h] = *dims {
            let frame = |data| Frame {
                width: w,
                height: h,
                channels: 1,
                data,
            };
            write_images(dir, &frame(o), &frame(p))?;
        }
        Ok(())
    })
}

/// Compares two complex arrays of dimensions `dims` (x fastest, as in
/// [`check_parity_array`]) against a tolerance, each element by the modulus of its
/// difference (see [`error_stats_complex`]). When it fails and `out_dir` is given,
/// writes `stats.json`, `cpu.npy` and `gpu.npy` (f64, a last axis of 2: re, im).
pub fn check_parity_complex<A, B>(
    case: &str,
    dims: &[usize],
    oracle: &[Complex<A>],
    port: &[Complex<B>],
    tol: Tolerance,
    out_dir: Option<&Path>,
) -> Result<ParityReport>
where
    A: Copy + Into<f64>,
    B: Copy + Into<f64>,
{
    check_shape(case, dims, oracle.len(), port.len())?;
    let f = judge(
        case,
        oracle.len(),
        |i| (widen(oracle[i]), widen(port[i])),
        tol,
        |i| locate(dims, i),
    );
    report(case, f, tol, out_dir, |dir| {
        let mut c_order: Vec<usize> = dims.iter().rev().copied().collect();
        c_order.push(2);
        let parts = |v: Vec<Complex<f64>>| v.iter().flat_map(|z| [z.re, z.im]).collect::<Vec<_>>();
        let o = parts(oracle.iter().map(|&z| widen(z)).collect());
        let p = parts(port.iter().map(|&z| widen(z)).collect());
        crate::io::npy::write_npy_f64(&dir.join("cpu.npy"), &c_order, &o)?;
        crate::io::npy::write_npy_f64(&dir.join("gpu.npy"), &c_order, &p)
    })
}

/// Both arrays hold `dims`'s element count.
fn check_shape(case: &str, dims: &[usize], oracle: usize, port: usize) -> Result<()> {
    let n: usize = dims.iter().product();
    if oracle != n || port != n {
        return Err(Error::invalid(
            "parity check",
            format!(
                "{case}: dims {dims:?} hold {n} elements; the oracle has {oracle}, \
                 the port {port}"
            ),
        ));
    }
    Ok(())
}

/// Element `i` of an array of `dims` (x fastest) as `[i, j, k]`.
fn locate(dims: &[usize], mut i: usize) -> (String, serde_json::Value) {
    let mut at = Vec::with_capacity(dims.len());
    for &d in dims {
        at.push(i % d.max(1));
        i /= d.max(1);
    }
    let words: Vec<String> = at.iter().map(|v| v.to_string()).collect();
    (format!("[{}]", words.join(", ")), serde_json::json!(at))
}

/// Writes `cpu.png`, `gpu.png` and `diff.png` into `dir` (which exists).
fn write_images(dir: &Path, oracle: &Frame, port: &Frame) -> Result<()> {
    // Scalar frames share one grey range so the two pictures are comparable.
    let range = if oracle.channels == 1 {
        let (a, b) = (oracle.finite_range(), port.finite_range());
        match (a, b) {
            (Some(a), Some(b)) => Some((a.0.min(b.0), a.1.max(b.1))),
            (a, b) => a.or(b),
        }
    } else {
        None
    };
    let png = PngOptions {
        sixteen_bit: false,
        range,
    };
    write_frame(&dir.join("cpu.png"), oracle, png)?;
    write_frame(&dir.join("gpu.png"), port, png)?;
    write_frame(
        &dir.join("diff.png"),
        &diff_heatmap(oracle, port, None),
        PngOptions::default(),
    )
}

fn write_json(path: &Path, json: &serde_json::Value) -> Result<()> {
    let text = serde_json::to_string_pretty(json).expect("serialisable");
    crate::io::write_atomic(path, |w| {
        w.write_all(text.as_bytes()).map_err(|e| Error::io(path, e))
    })
}

/// Writes `cpu.png`, `gpu.png`, `diff.png` and `stats.json` (the statistics and the
/// tolerance) into `dir`.
pub fn write_artifacts(
    dir: &Path,
    oracle: &Frame,
    port: &Frame,
    stats: &ErrorStats,
    tol: Tolerance,
) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    write_images(dir, oracle, port)?;
    write_json(
        &dir.join("stats.json"),
        &serde_json::json!({
            "stats": stats,
            "tolerance": tol,
        }),
    )
}

/// A colour map from 0 (black) through blue, magenta and orange to 1 (white).
fn heat(t: f64) -> [f64; 3] {
    let t = t.clamp(0.0, 1.0);
    let stops = [
        (0.0, [0.0, 0.0, 0.0]),
        (0.25, [0.1, 0.1, 0.7]),
        (0.5, [0.75, 0.1, 0.6]),
        (0.75, [1.0, 0.55, 0.0]),
        (1.0, [1.0, 1.0, 1.0]),
    ];
    for w in stops.windows(2) {
        let ((t0, c0), (t1, c1)) = (w[0], w[1]);
        if t <= t1 {
            let f = (t - t0) / (t1 - t0);
            return [0, 1, 2].map(|k| c0[k] + f * (c1[k] - c0[k]));
        }
    }
    [1.0; 3]
}

/// The per-pixel maximum |Δ| over channels as a heat map (RGBA), with a colour scale
/// along the bottom: a bar from 0 (left) to `scale` (right, default the largest |Δ|),
/// and the scale's value written as ticks every tenth. NaN/Inf mismatches show in green.
pub fn diff_heatmap(oracle: &Frame, port: &Frame, scale: Option<f64>) -> Frame {
    let (w, h, ch) = (oracle.width, oracle.height, oracle.channels);
    let diffs: Vec<f64> = (0..w * h)
        .map(|p| {
            (0..ch)
                .map(|c| {
                    let (a, b) = (oracle.data[p * ch + c], port.data[p * ch + c]);
                    if a.is_finite() && b.is_finite() {
                        (a - b).abs()
                    } else if (a.is_nan() && b.is_nan()) || a == b {
                        0.0
                    } else {
                        f64::NAN
                    }
                })
                .fold(0.0, |m: f64, d| {
                    if d.is_nan() || m.is_nan() {
                        f64::NAN
                    } else {
                        m.max(d)
                    }
                })
        })
        .collect();
    let max = scale.unwrap_or_else(|| {
        diffs
            .iter()
            .cloned()
            .filter(|d| d.is_finite())
            .fold(0.0, f64::max)
    });
    let bar = (h / 12).max(4);
    let mut out = Frame::new(w, h + bar, 4);
    for (p, d) in diffs.iter().enumerate() {
        let c = if d.is_nan() {
            [0.0, 1.0, 0.0]
        } else {
            heat(if max > 0.0 { d / max } else { 0.0 })
        };
        out.data[p * 4..p * 4 + 4].copy_from_slice(&[c[0], c[1], c[2], 1.0]);
    }
    for row in h..h + bar {
        for col in 0..w {
            let t = (col as f64 + 0.5) / w as f64;
            let tick = row < h + bar / 3 && (col * 10) % w < 10 && col > 0;
            let c = if tick { [1.0, 1.0, 1.0] } else { heat(t) };
            let i = (row * w + col) * 4;
            out.data[i..i + 4].copy_from_slice(&[c[0], c[1], c[2], 1.0]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(data: Vec<f64>) -> Frame {
        Frame {
            width: data.len(),
            height: 1,
            channels: 1,
            data,
        }
    }

    fn scratch(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("voxlab-parity-{name}-{}", std::process::id()))
    }

    #[test]
    fn stats_of_known_differences() {
        let s = error_stats(&[1.0, 2.0, 3.0, 4.0], &[1.0, 2.5, 3.0, 3.0], 0.6);
        assert_eq!(s.max_abs, 1.0);
        assert_eq!(s.worst_index, 3);
        assert_eq!(s.n_over, 1);
        assert!((s.rmse - (1.25f64 / 4.0).sqrt()).abs() < 1e-15);
        assert!((s.rel_l2 - (1.25f64 / 30.0).sqrt()).abs() < 1e-15);
        assert!((s.psnr_db - 20.0 * (4.0 / (1.25f64 / 4.0).sqrt()).log10()).abs() < 1e-12);
        assert_eq!((s.peak, s.max_abs_rel, s.mean_abs), (4.0, 0.25, 0.375));
    }

    /// ‖(3, 4) − (0, 0)‖ / ‖(3, 4)‖ = 1; (1, 1) against (1, 1 + 1e-3·…): rel L2 of a
    /// known pair; f32 ports compare on their exact f64 values.
    #[test]
    fn relative_l2_of_known_pairs() {
        assert_eq!(error_stats(&[3.0, 4.0], &[0.0, 0.0], 1.0).rel_l2, 1.0);
        // Δ = (0, 0.5): ‖Δ‖ = 0.5 against ‖(3, 4)‖ = 5.
        let s = error_stats(&[3.0, 4.0], &[3.0f32, 4.5], f64::INFINITY);
        assert_eq!(s.rel_l2, 0.1);
        assert_eq!(s.max_abs_rel, 0.125);
        // Zero against zero is exact; anything against zero is infinitely wrong.
        assert_eq!(error_stats(&[0.0; 3], &[0.0; 3], 0.0).rel_l2, 0.0);
        let s = error_stats(&[0.0; 2], &[0.0, 1e-9], 0.0);
        assert_eq!((s.rel_l2, s.max_abs_rel), (f64::INFINITY, f64::INFINITY));
    }

    /// Complex values compare by the modulus of the difference: (3 + 4i) against 0 is
    /// |Δ| = 5 (the largest part's difference would say 4), and the relative L2 over
    /// complex values is the one over their interleaved parts.
    #[test]
    fn complex_values_compare_by_modulus() {
        let o = [Complex::new(3.0, 4.0), Complex::new(1.0, 0.0)];
        let p = [Complex::new(0.0f32, 0.0), Complex::new(1.0, 0.0)];
        let s = error_stats_complex(&o, &p, 4.5);
        assert_eq!((s.max_abs, s.worst_index, s.n_over, s.n), (5.0, 0, 1, 2));
        assert_eq!(s.peak, 5.0);
        let flat = |v: &[Complex<f64>]| v.iter().flat_map(|z| [z.re, z.im]).collect::<Vec<_>>();
        let p64: Vec<Complex<f64>> = p.iter().map(|&z| widen(z)).collect();
        let parts = error_stats(&flat(&o), &flat(&p64), 4.5);
        assert_eq!(parts.max_abs, 4.0);
        assert_eq!(s.rel_l2, parts.rel_l2);
        assert_eq!(s.rel_l2, (25.0f64 / 26.0).sqrt());
        // rmse is per complex element: √(25 / 2).
        assert_eq!(s.rmse, 12.5f64.sqrt());
    }

    #[test]
    fn nan_mismatch_fails_and_matching_nan_does_not() {
        let s = error_stats(&[f64::NAN, 1.0], &[f64::NAN, f64::NAN], 1.0);
        assert_eq!(s.non_finite_mismatches, 1);
        assert_eq!(s.n_over, 1);
        let s = error_stats(&[f64::INFINITY, 1.0], &[f64::NEG_INFINITY, 1.0], 1.0);
        assert_eq!(s.non_finite_mismatches, 1);
        assert_eq!(s.max_abs, 0.0);
        let s = s.infinite_if_mismatched();
        assert_eq!([s.max_abs, s.rel_l2, s.rmse], [f64::INFINITY; 3]);
        let s = error_stats(&[1.0], &[1.5], 0.0).infinite_if_mismatched();
        assert_eq!(s.max_abs, 0.5);
        let tol = Tolerance {
            max_abs: 1.0,
            rmse: 1.0,
            ..Tolerance::NONE
        };
        let r = check_parity(
            "nan",
            &frame(vec![0.0, 1.0]),
            &frame(vec![0.0, f64::NAN]),
            tol,
            None,
        )
        .unwrap();
        assert!(!r.passed);
        assert!(r.message.contains("NaN"));
        // No bound at all still fails a NaN, in an array and in complex values.
        let r = check_parity_array(
            "nan",
            &[2],
            &[0.0, 1.0],
            &[0.0, f64::NAN],
            Tolerance::NONE,
            None,
        )
        .unwrap();
        assert!(
            !r.passed && r.message.contains("[1] 1.000000e0 vs NaN"),
            "{}",
            r.message
        );
        let c = [Complex::new(1.0, 0.0)];
        let r = check_parity_complex(
            "nan",
            &[1],
            &c,
            &[Complex::new(1.0, f64::NAN)],
            Tolerance::NONE,
            None,
        )
        .unwrap();
        assert!(!r.passed, "{}", r.message);
        assert!(
            check_parity_complex("same", &[1], &c, &c, Tolerance::max_abs(0.0), None)
                .unwrap()
                .passed
        );
    }

    #[test]
    fn failure_writes_images_and_names_the_worst_element() {
        let dir = scratch("frame");
        let tol = Tolerance::max_abs(0.1).with_rmse(1.0);
        let r = check_parity(
            "t",
            &frame(vec![0.0, 0.5, 1.0]),
            &frame(vec![0.0, 0.9, 1.0]),
            tol,
            Some(&dir),
        )
        .unwrap();
        assert!(!r.passed);
        assert!(r.message.contains("col 1, row 0"), "{}", r.message);
        for f in ["cpu.png", "gpu.png", "diff.png", "stats.json"] {
            assert!(dir.join(f).is_file(), "{f}");
        }
        let _ = std::fs::remove_dir_all(&dir);
        let ok = check_parity(
            "t",
            &frame(vec![0.0, 0.5]),
            &frame(vec![0.0, 0.55]),
            tol,
            None,
        )
        .unwrap();
        assert!(ok.passed);
    }

    /// A 3 × 2 array: element [2, 1] is flat index 5; the bounds each fail on their own
    /// quantity; a 2-D failure leaves pictures and arrays, stats.json the numbers.
    #[test]
    fn arrays_name_elements_by_index_and_each_bound_counts() {
        let o = [1.0, 2.0, 3.0, 4.0, 5.0, 10.0];
        let mut p = o;
        p[5] = 10.5;
        let check = |tol| check_parity_array("a", &[3, 2], &o, &p, tol, None).unwrap();
        // max |Δ| 0.5 / peak 10 = 0.05; rel L2 = 0.5 / √155.
        let l2 = 0.5 / 155f64.sqrt();
        assert!(check(Tolerance::max_abs_rel(0.05).with_rel_l2(l2)).passed);
        for tol in [
            Tolerance::max_abs(0.4),
            Tolerance::max_abs_rel(0.049),
            Tolerance::rel_l2(0.99 * l2),
            Tolerance::rmse(0.2),
        ] {
            let r = check(tol);
            assert!(!r.passed, "{tol:?}");
            assert!(r.message.contains("at [2, 1]"), "{}", r.message);
        }
        let r = check(Tolerance::rel_l2(0.01));
        assert!(r.message.contains("exceeded: rel L2"), "{}", r.message);
        assert!(
            r.message
                .contains("largest differences: [2, 1] 1.000000e1 vs 1.050000e1"),
            "{}",
            r.message
        );
        assert!(check(Tolerance::max_abs_rel(0.01))
            .message
            .contains("first mismatches: [2, 1]"));
        assert!(check_parity_array("a", &[4], &o, &p, Tolerance::NONE, None).is_err());

        let dir = scratch("array");
        let r =
            check_parity_array("a", &[3, 2], &o, &p, Tolerance::max_abs(0.1), Some(&dir)).unwrap();
        assert!(r.message.contains(&dir.display().to_string()));
        for f in [
            "cpu.png",
            "gpu.png",
            "diff.png",
            "cpu.npy",
            "gpu.npy",
            "stats.json",
        ] {
            assert!(dir.join(f).is_file(), "{f}");
        }
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("stats.json")).unwrap())
                .unwrap();
        assert_eq!(json["worst"]["index"], serde_json::json!([2, 1]));
        assert_eq!(json["max_abs_rel"], 0.05);
        assert_eq!(json["tolerance"]["max_abs"], 0.1);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn tolerance_builders_and_scaling() {
        let t = Tolerance::max_abs(1e-3).with_rmse(5e-5).with_rel_l2(1e-6);
        assert_eq!(
            t,
            Tolerance {
                max_abs: 1e-3,
                rmse: 5e-5,
                rel_l2: 1e-6,
                ..Tolerance::NONE
            }
        );
        let s = t.with_max_abs_rel(0.1).scaled(10.0);
        assert_eq!((s.max_abs, s.rmse), (1e-2, 5e-4));
        assert_eq!((s.max_abs_rel, s.rel_l2), (0.1, 1e-6));
        let stats = error_stats(&[1.0], &[f64::NAN], 0.0);
        assert!(Tolerance::NONE.exceeded(&stats).is_empty());
        assert!(!Tolerance::NONE.admits(&stats));
    }
}
