//! The parity vocabulary: how far a port's output is from the oracle's, and whether
//! that is within tolerance. Used by every CPU–GPU test and by `voxlab compare`.
//!
//! On failure, [`check_parity`] writes `cpu.png`, `gpu.png`, `diff.png` (a heat map of
//! |Δ| with its colour scale) and `stats.json` into a folder (the tests use
//! `target/parity/<case>/`), and its message names the worst element and the first
//! mismatches.

use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::io::{write_frame, PngOptions};
use serde::Serialize;
use std::path::Path;

/// How two arrays differ.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ErrorStats {
    /// Elements compared.
    pub n: usize,
    /// Largest |oracle − port|.
    pub max_abs: f64,
    /// Index of the largest difference (`(row · width + col) · channels + channel`).
    pub worst_index: usize,
    /// Root mean square of the differences.
    pub rmse: f64,
    /// ‖oracle − port‖₂ / ‖oracle‖₂ (0 when both are zero).
    pub rel_l2: f64,
    /// 20 log10(peak / rmse), with peak the largest |oracle| (∞ when identical).
    pub psnr_db: f64,
    /// Elements whose difference exceeds the tolerance's `max_abs`.
    pub n_over: usize,
    /// Elements where exactly one side is NaN or infinite, or both are but differ.
    pub non_finite_mismatches: usize,
}

/// What counts as agreement.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Tolerance {
    /// No element may differ by more than this.
    pub max_abs: f64,
    /// The root-mean-square difference may not exceed this.
    pub rmse: f64,
}

impl Tolerance {
    /// The same bounds scaled by `scale` (for outputs in data units).
    pub fn scaled(self, scale: f64) -> Self {
        Tolerance {
            max_abs: self.max_abs * scale,
            rmse: self.rmse * scale,
        }
    }
}

/// Computes the statistics of `port` against `oracle`; `max_abs` decides `n_over`.
pub fn error_stats(oracle: &[f64], port: &[f64], max_abs: f64) -> ErrorStats {
    assert_eq!(
        oracle.len(),
        port.len(),
        "compared arrays must have one length"
    );
    let mut s = ErrorStats {
        n: oracle.len(),
        ..Default::default()
    };
    let (mut sum_sq, mut ref_sq, mut peak) = (0.0, 0.0, 0.0f64);
    for (i, (&a, &b)) in oracle.iter().zip(port).enumerate() {
        if !(a.is_finite() && b.is_finite()) {
            let same = (a.is_nan() && b.is_nan()) || a == b;
            if !same {
                s.non_finite_mismatches += 1;
                s.n_over += 1;
            }
            continue;
        }
        let d = (a - b).abs();
        if d > s.max_abs {
            s.max_abs = d;
            s.worst_index = i;
        }
        if d > max_abs {
            s.n_over += 1;
        }
        sum_sq += d * d;
        ref_sq += a * a;
        peak = peak.max(a.abs());
    }
    let n = s.n.max(1) as f64;
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
    s
}

/// The outcome of a parity check.
#[derive(Clone, Debug)]
pub struct ParityReport {
    pub case: String,
    pub stats: ErrorStats,
    pub tolerance: Tolerance,
    pub passed: bool,
    /// A human-readable summary; on failure it names the worst element and the first
    /// mismatches.
    pub message: String,
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
    let stats = error_stats(&oracle.data, &port.data, tol.max_abs);
    let passed = stats.n_over == 0 && stats.rmse <= tol.rmse;
    let ch = oracle.channels;
    let locate = |i: usize| {
        let px = i / ch;
        (px % oracle.width, px / oracle.width, i % ch)
    };
    let (wc, wr, wch) = locate(stats.worst_index);
    let mut message = format!(
        "{case}: {}/{} elements over {:.1e} (max |Δ| = {:.3e} at col {wc}, row {wr}, channel {wch}: \
         oracle {:.6e}, port {:.6e}); rmse {:.3e} (bound {:.1e}), rel L2 {:.3e}, PSNR {:.1} dB",
        stats.n_over,
        stats.n,
        tol.max_abs,
        stats.max_abs,
        oracle.data[stats.worst_index.min(stats.n.saturating_sub(1))],
        port.data[stats.worst_index.min(stats.n.saturating_sub(1))],
        stats.rmse,
        tol.rmse,
        stats.rel_l2,
        stats.psnr_db,
    );
    if stats.non_finite_mismatches > 0 {
        message += &format!("; {} NaN/Inf mismatches", stats.non_finite_mismatches);
    }
    if !passed {
        let first: Vec<String> = oracle
            .data
            .iter()
            .zip(&port.data)
            .enumerate()
            .filter(|(_, (a, b))| {
                // Over the bound, or a NaN/Inf on one side only.
                let d = (*a - *b).abs();
                d > tol.max_abs || (d.is_nan() && !(a.is_nan() && b.is_nan()))
            })
            .take(5)
            .map(|(i, (a, b))| {
                let (c, r, k) = locate(i);
                format!("({c},{r})[{k}] {a:.6e} vs {b:.6e}")
            })
            .collect();
        if !first.is_empty() {
            message += &format!("; first mismatches: {}", first.join(", "));
        }
        if let Some(dir) = out_dir {
            write_artifacts(dir, oracle, port, &stats, tol)?;
            message += &format!("; images in {}", dir.display());
        }
    }
    Ok(ParityReport {
        case: case.to_string(),
        stats,
        tolerance: tol,
        passed,
        message,
    })
}

/// Writes `cpu.png`, `gpu.png`, `diff.png` and `stats.json` into `dir`.
pub fn write_artifacts(
    dir: &Path,
    oracle: &Frame,
    port: &Frame,
    stats: &ErrorStats,
    tol: Tolerance,
) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
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
    )?;
    let json = serde_json::to_string_pretty(&serde_json::json!({
        "stats": stats,
        "tolerance": tol,
    }))
    .expect("serialisable");
    let path = dir.join("stats.json");
    crate::io::write_atomic(&path, |w| {
        w.write_all(json.as_bytes())
            .map_err(|e| Error::io(&path, e))
    })
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

    #[test]
    fn stats_of_known_differences() {
        let s = error_stats(&[1.0, 2.0, 3.0, 4.0], &[1.0, 2.5, 3.0, 3.0], 0.6);
        assert_eq!(s.max_abs, 1.0);
        assert_eq!(s.worst_index, 3);
        assert_eq!(s.n_over, 1);
        assert!((s.rmse - (1.25f64 / 4.0).sqrt()).abs() < 1e-15);
        assert!((s.rel_l2 - (1.25f64 / 30.0).sqrt()).abs() < 1e-15);
        assert!((s.psnr_db - 20.0 * (4.0 / (1.25f64 / 4.0).sqrt()).log10()).abs() < 1e-12);
    }

    #[test]
    fn nan_mismatch_fails_and_matching_nan_does_not() {
        let s = error_stats(&[f64::NAN, 1.0], &[f64::NAN, f64::NAN], 1.0);
        assert_eq!(s.non_finite_mismatches, 1);
        assert_eq!(s.n_over, 1);
        let tol = Tolerance {
            max_abs: 1.0,
            rmse: 1.0,
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
    }

    #[test]
    fn failure_writes_images_and_names_the_worst_element() {
        let dir = std::env::temp_dir().join(format!("voxlab-parity-test-{}", std::process::id()));
        let tol = Tolerance {
            max_abs: 0.1,
            rmse: 1.0,
        };
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
}
