//! `voxlab fft`: checks and times the Fourier transforms on random complex data.
//!
//! For each shape, one array of random complex values (uniform in `[−1, 1)` in both
//! parts, fixed seed) is transformed forward, unnormalised, by the CPU f64 FFT, the
//! CPU f32 FFT ([`crate::cpu::fft::fft_nd`]) and, when asked and an adapter exists,
//! the GPU ([`crate::gpu::fft`], Stockham and split-stream). Each result is compared
//! with a reference: the exact DFT ([`crate::cpu::dft::dft_nd`]) when its cost
//! `N·ΣN_axis` is at most [`EXACT_WORK_LIMIT`], else the CPU f64 FFT. The error is
//! the relative L2 norm `‖x − ref‖ / ‖ref‖`; it must stay within `1e-12` (f64) or
//! `1e-6·log2 N` (f32, `N` the total size, at least 1).
//!
//! Timings: one warm-up run (the one checked), then the median of `runs` runs. CPU
//! times cover the transform only (the copy of the input is outside). GPU times are
//! end to end without set-up (upload, passes, readback), and the pass time (from
//! timestamp queries when the adapter has them) is reported apart. GFLOP/s is the
//! conventional `5·N·log2 N / t`; GB/s counts one read and one write of the array,
//! `2·N·sizeof(complex) / t`. For the GPU the report adds the compute dispatches of
//! one transform and the roofline: the pass time's GB/s against the adapter's peak
//! memory bandwidth, where [`crate::gpu::peak`] knows the part.

use super::BackendSet;
use crate::cpu::dft::{dft_nd, Direction, Normalization};
use crate::error::{Error, Result};
use crate::gpu::fft::{fft_nd_timed, GpuFftVariant};
use crate::gpu::GpuContext;
use rustfft::num_complex::Complex;
use std::time::Instant;

/// Largest `N·ΣN_axis` for which the exact DFT is the reference.
pub const EXACT_WORK_LIMIT: f64 = 1e9;

/// Largest total size accepted (2²⁷ complex values, 2 GiB in f64).
pub const MAX_TOTAL: usize = 1 << 27;

/// Parses a shape such as `1024`, `256x256` or `64x64x64` (row-major, last axis
/// fastest).
///
/// # Errors
/// [`Error::Invalid`] when an axis is not a positive whole number;
/// [`Error::TooLarge`] above [`MAX_TOTAL`] values.
pub fn parse_shape(s: &str) -> Result<Vec<usize>> {
    let shape = s
        .split(['x', 'X', '×'])
        .map(|a| a.trim().parse::<usize>().ok().filter(|&n| n > 0))
        .collect::<Option<Vec<usize>>>()
        .ok_or_else(|| {
            Error::invalid(
                "FFT shape",
                format!("'{s}' is not like 1024, 256x256 or 64x64x64 (positive axes)"),
            )
        })?;
    let total = shape
        .iter()
        .try_fold(1usize, |a, &n| a.checked_mul(n))
        .filter(|&t| t <= MAX_TOTAL);
    if total.is_none() {
        return Err(Error::too_large(
            "FFT shape",
            format!("'{s}' has more than {MAX_TOTAL} values"),
        ));
    }
    Ok(shape)
}

/// `n` random complex values, uniform in `[−1, 1)` in both parts (xorshift64*,
/// deterministic for a given `seed`).
pub fn random_complex(n: usize, seed: u64) -> Vec<Complex<f64>> {
    let mut s = seed.max(1);
    let mut next = || {
        s ^= s >> 12;
        s ^= s << 25;
        s ^= s >> 27;
        let u = (s.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64;
        2.0 * u - 1.0
    };
    (0..n).map(|_| Complex::new(next(), next())).collect()
}

/// Relative L2 error `‖port − reference‖ / ‖reference‖` in f64
/// ([`crate::metrics::error_stats_complex`]; ∞ when `port` has a NaN or infinity).
pub fn rel_l2<T: Into<f64> + Copy>(port: &[Complex<T>], reference: &[Complex<f64>]) -> f64 {
    crate::metrics::error_stats_complex(reference, port, f64::INFINITY)
        .infinite_if_mismatched()
        .rel_l2
}

/// The error allowed for a transform of `total` values in f32 (`single`) or f64.
pub fn tolerance(total: usize, single: bool) -> f64 {
    if single {
        1e-6 * (total as f64).log2().max(1.0)
    } else {
        1e-12
    }
}

/// The GPU for `backends`, and a line saying which it is (or why there is none).
/// `all` without an adapter runs the CPU only; `gpu` without one fails.
///
/// # Errors
/// [`Error::NoAdapter`] or [`Error::Gpu`] for `gpu` without a usable device.
pub fn open(backends: BackendSet) -> Result<(Option<&'static GpuContext>, Option<String>)> {
    if !backends.gpu() {
        return Ok((None, None));
    }
    match GpuContext::shared() {
        Ok(c) => Ok((Some(c), Some(format!("GPU: {}", c.describe())))),
        Err(e) if backends.cpu() => Ok((
            None,
            Some(format!("GPU: none available ({e}); running the CPU only")),
        )),
        Err(e) => Err(e),
    }
}

/// One implementation on one shape.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CaseResult {
    pub shape: Vec<usize>,
    /// `cpu-f64`, `cpu-f32`, `gpu-stockham` or `gpu-split-stream`.
    pub backend: String,
    /// `exact-dft` or `cpu-f64-fft`.
    pub reference: String,
    pub rel_l2: f64,
    pub tolerance: f64,
    pub passed: bool,
    /// Median seconds (GPU: end to end without set-up).
    pub median_s: f64,
    /// GPU only: median seconds of the passes.
    pub kernel_median_s: Option<f64>,
    /// GPU only: whether the pass time comes from timestamp queries.
    pub kernel_from_timestamps: Option<bool>,
    /// `5·N·log2 N / median_s`, in 1e9 per second.
    pub gflops: f64,
    /// `2·N·sizeof(complex) / median_s`, in 1e9 bytes per second.
    pub gbps: f64,
    /// Why the case was not run (then the numbers are meaningless and it passes).
    pub skipped: Option<String>,
    /// GPU only: how the transform was split past one storage binding ("FFT in 4
    /// slabs along axis 1 …"); `None` when it ran in one piece.
    pub split: Option<String>,
    /// GPU only: the compute dispatches of one transform.
    pub dispatches: Option<usize>,
    /// GPU only: `2·N·sizeof(complex)` over the median pass time, 1e9 bytes per second.
    pub kernel_gbps: Option<f64>,
    /// GPU only: `kernel_gbps` as a fraction of the adapter's peak memory bandwidth
    /// (`None` when the part is not in [`crate::gpu::peak`]'s table).
    pub of_peak_bandwidth: Option<f64>,
}

/// Everything `voxlab fft` measured.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Report {
    pub runs: usize,
    pub threads: usize,
    /// The GPU adapter, when one was used.
    pub adapter: Option<String>,
    /// Its data-sheet peaks, when the part is known ([`crate::gpu::peak`]).
    pub adapter_peak: Option<crate::gpu::peak::Peak>,
    pub cases: Vec<CaseResult>,
    pub passed: bool,
}

/// The median, NaN when there is nothing to take it of.
fn median(mut t: Vec<f64>) -> f64 {
    t.sort_by(|a, b| a.total_cmp(b));
    t.get(t.len() / 2).copied().unwrap_or(f64::NAN)
}

fn flops(total: usize) -> f64 {
    5.0 * total as f64 * (total as f64).log2().max(0.0)
}

#[allow(clippy::too_many_arguments)]
fn case(
    shape: &[usize],
    backend: &str,
    reference: &str,
    err: f64,
    single: bool,
    median_s: f64,
    kernel: Option<(f64, bool)>,
    bytes_per_value: usize,
) -> CaseResult {
    let total: usize = shape.iter().product();
    let tol = tolerance(total, single);
    CaseResult {
        shape: shape.to_vec(),
        backend: backend.into(),
        reference: reference.into(),
        rel_l2: err,
        tolerance: tol,
        passed: err <= tol,
        median_s,
        kernel_median_s: kernel.map(|k| k.0),
        kernel_from_timestamps: kernel.map(|k| k.1),
        gflops: flops(total) / median_s / 1e9,
        gbps: (2 * total * bytes_per_value) as f64 / median_s / 1e9,
        skipped: None,
        split: None,
        dispatches: None,
        kernel_gbps: kernel.map(|k| (2 * total * bytes_per_value) as f64 / k.0 / 1e9),
        of_peak_bandwidth: None,
    }
}

/// Times the forward FFT on a fresh copy of `x`: one warm-up (its result returned),
/// then the median of `runs` runs (NaN when `runs` is 0).
fn time_cpu<T: rustfft::FftNum>(
    x: &[Complex<T>],
    shape: &[usize],
    runs: usize,
) -> (Vec<Complex<T>>, f64) {
    let go = |d: &mut [Complex<T>]| {
        crate::cpu::fft::fft_nd(d, shape, Direction::Forward, Normalization::Unnormalized)
    };
    let mut first = x.to_vec();
    go(&mut first);
    let mut t = Vec::with_capacity(runs);
    for _ in 0..runs {
        let mut d = x.to_vec();
        let start = Instant::now();
        go(&mut d);
        t.push(start.elapsed().as_secs_f64());
    }
    (first, median(t))
}

/// Checks and times every shape on the chosen backends. `gpu` is the opened adapter
/// (`None` runs the CPU only). `log` receives one line per finished case.
///
/// # Errors
/// [`Error::Invalid`] when `runs` is 0.
pub fn run(
    shapes: &[Vec<usize>],
    backends: BackendSet,
    runs: usize,
    gpu: Option<&GpuContext>,
    log: &mut dyn FnMut(&CaseResult),
) -> Result<Report> {
    if runs == 0 {
        return Err(Error::invalid("--runs", "must be at least 1"));
    }
    let mut cases = Vec::new();
    let mut push = |c: CaseResult, cases: &mut Vec<CaseResult>| {
        log(&c);
        cases.push(c);
    };
    for (i, shape) in shapes.iter().enumerate() {
        let total: usize = shape.iter().product();
        let x = random_complex(total, 0x5eed_0000 + i as u64);
        let x32: Vec<Complex<f32>> = x
            .iter()
            .map(|v| Complex::new(v.re as f32, v.im as f32))
            .collect();
        let work = total as f64 * shape.iter().sum::<usize>() as f64;
        let exact = work <= EXACT_WORK_LIMIT;
        // The f64 FFT is always run (it may be the reference), timed only for the CPU.
        let (f64_out, f64_t) = time_cpu(&x, shape, if backends.cpu() { runs } else { 0 });
        let (reference, ref_name) = if exact {
            (
                dft_nd(&x, shape, Direction::Forward, Normalization::Unnormalized),
                "exact-dft",
            )
        } else {
            (f64_out.clone(), "cpu-f64-fft")
        };
        if backends.cpu() {
            let err = rel_l2(&f64_out, &reference);
            let c = case(shape, "cpu-f64", ref_name, err, false, f64_t, None, 16);
            push(c, &mut cases);
            let (out, t) = time_cpu(&x32, shape, runs);
            let err = rel_l2(&out, &reference);
            push(
                case(shape, "cpu-f32", ref_name, err, true, t, None, 8),
                &mut cases,
            );
        }
        let Some(ctx) = gpu.filter(|_| backends.gpu()) else {
            continue;
        };
        for (variant, name) in [
            (GpuFftVariant::Stockham, "gpu-stockham"),
            (GpuFftVariant::SplitStream, "gpu-split-stream"),
        ] {
            let go = || {
                fft_nd_timed(
                    ctx,
                    &x32,
                    shape,
                    Direction::Forward,
                    Normalization::Unnormalized,
                    variant,
                )
            };
            let first = match go() {
                Ok(o) => o,
                Err(e @ (Error::Invalid { .. } | Error::TooLarge { .. })) => {
                    let mut c = case(shape, name, ref_name, 0.0, true, f64::NAN, None, 8);
                    c.skipped = Some(e.to_string());
                    push(c, &mut cases);
                    continue;
                }
                Err(e) => return Err(e),
            };
            let err = rel_l2(&first.data, &reference);
            let (mut e2e, mut kern) = (Vec::new(), Vec::new());
            for _ in 0..runs {
                let o = go()?;
                e2e.push(o.timings.total - o.timings.setup);
                kern.push(o.timings.kernel);
            }
            let stamps = first.timings.kernel_from_timestamps;
            let mut c = case(
                shape,
                name,
                ref_name,
                err,
                true,
                median(e2e),
                Some((median(kern), stamps)),
                8,
            );
            c.split = crate::gpu::fft::split_plan(ctx, shape)?.map(|p| p.describe());
            c.dispatches = Some(first.timings.dispatches);
            let peak = crate::gpu::peak::peak_of(&ctx.summary.name).map(|p| p.memory_gbps);
            c.of_peak_bandwidth = c
                .kernel_gbps
                .and_then(|g| crate::gpu::peak::fraction(g, peak));
            push(c, &mut cases);
        }
    }
    let passed = cases.iter().all(|c| c.passed);
    Ok(Report {
        runs,
        threads: rayon::current_num_threads(),
        adapter: gpu.filter(|_| backends.gpu()).map(|g| {
            let s = &g.summary;
            format!("{} ({}, {})", s.name, s.backend, s.driver_info)
        }),
        adapter_peak: gpu
            .filter(|_| backends.gpu())
            .and_then(|g| crate::gpu::peak::peak_of(&g.summary.name)),
        cases,
        passed,
    })
}

/// One line of the text table (see [`TABLE_HEADER`]).
pub fn format_case(c: &CaseResult) -> String {
    let shape = c
        .shape
        .iter()
        .map(|n| n.to_string())
        .collect::<Vec<_>>()
        .join("x");
    if let Some(why) = &c.skipped {
        return format!("{shape:<14} {:<17} skipped: {why}", c.backend);
    }
    let kernel = c
        .kernel_median_s
        .map_or("-".to_string(), |k| format!("{:.3}", k * 1e3));
    let split = c
        .split
        .as_ref()
        .map_or(String::new(), |s| format!("  ({s})"));
    let dispatches = c.dispatches.map_or("-".to_string(), |d| d.to_string());
    let of_peak = c
        .of_peak_bandwidth
        .map_or("-".to_string(), |f| format!("{:.1} %", 100.0 * f));
    format!(
        "{shape:<14} {:<17} {:<12} {:>10.2e} {:>9.1e} {:<4} {:>10.3} {:>10} {:>8.3} {:>7.3} {dispatches:>5} {of_peak:>7}{split}",
        c.backend,
        c.reference,
        c.rel_l2,
        c.tolerance,
        if c.passed { "ok" } else { "FAIL" },
        c.median_s * 1e3,
        kernel,
        c.gflops,
        c.gbps
    )
}

/// The header of the text table.
pub const TABLE_HEADER: &str = "shape          backend           reference        rel L2       tol ok    median ms  kernel ms  GFLOP/s    GB/s  disp  % peak";

/// The 1-D transform of every line of `data` (row-major, `shape`, last axis fastest)
/// along each axis of `axes` in turn (an axis listed twice is transformed twice), then
/// every value multiplied by `scale`: numpy's `fftn(a, axes=…)` with the scale of its
/// `norm` given explicitly. `exact` uses the exact DFT ([`crate::cpu::dft::dft_1d`],
/// `O(N²)` per line) instead of the FFT (RustFFT, the CPU FFTs' engine). Parallel over
/// lines; the result does not depend on the thread count.
///
/// This is the primitive under the Python package's `voxlab.fft`.
///
/// # Errors
/// [`Error::Invalid`] when `shape` does not describe `data` or an axis is out of range.
pub fn transform_axes(
    data: &mut [Complex<f64>],
    shape: &[usize],
    axes: &[usize],
    dir: Direction,
    scale: f64,
    exact: bool,
) -> Result<()> {
    use rayon::prelude::*;
    let total = shape.iter().try_fold(1usize, |a, &n| a.checked_mul(n));
    if total != Some(data.len()) {
        return Err(Error::invalid(
            "FFT shape",
            format!("{shape:?} does not hold {} values", data.len()),
        ));
    }
    if let Some(&a) = axes.iter().find(|&&a| a >= shape.len()) {
        return Err(Error::invalid(
            "FFT axis",
            format!("{a} is out of range for {} dimensions", shape.len()),
        ));
    }
    if data.is_empty() {
        return Ok(());
    }
    let mut planner = rustfft::FftPlanner::<f64>::new();
    let fft_dir = match dir {
        Direction::Forward => rustfft::FftDirection::Forward,
        Direction::Inverse => rustfft::FftDirection::Inverse,
    };
    for &axis in axes {
        let n = shape[axis];
        let inner: usize = shape[axis + 1..].iter().product();
        if n <= 1 {
            continue;
        }
        let plan = planner.plan_fft(n, fft_dir);
        // One line: in place (contiguous) by RustFFT or the exact DFT.
        let line = |buf: &mut [Complex<f64>], scratch: &mut Vec<Complex<f64>>| {
            if exact {
                let out = dft_1d(buf, dir);
                buf.copy_from_slice(&out);
            } else {
                scratch.resize(plan.get_inplace_scratch_len(), Complex::new(0.0, 0.0));
                plan.process_with_scratch(buf, scratch);
            }
        };
        if inner == 1 {
            data.par_chunks_mut(n)
                .for_each_init(Vec::new, |scratch, l| line(l, scratch));
        } else {
            // Each block `[n][inner]` is transposed to `[inner][n]`, transformed line
            // by line, and transposed back.
            data.par_chunks_mut(n * inner).for_each_init(
                || (Vec::new(), vec![Complex::new(0.0, 0.0); n * inner]),
                |(scratch, t), block| {
                    for j in 0..n {
                        for i in 0..inner {
                            t[i * n + j] = block[j * inner + i];
                        }
                    }
                    for l in t.chunks_mut(n) {
                        line(l, scratch);
                    }
                    for j in 0..n {
                        for i in 0..inner {
                            block[j * inner + i] = t[i * n + j];
                        }
                    }
                },
            );
        }
    }
    if scale != 1.0 {
        data.par_iter_mut().for_each(|v| *v *= scale);
    }
    Ok(())
}

/// The exact, unscaled DFT of one line.
fn dft_1d(line: &[Complex<f64>], dir: Direction) -> Vec<Complex<f64>> {
    crate::cpu::dft::dft_1d(line, dir, Normalization::None)
}

/// `voxlab fft --dry-run`: the memory plan of [`run`] for each shape, computing
/// nothing: the host's arrays (the input in f64 and f32, the reference, every
/// backend's output), and on the GPU the device's two ping-pong buffers (and, for a
/// length that is not a power of two, Bluestein's two work buffers) of the whole array
/// or of its largest slab against the planner's limits, with the split
/// ([`crate::gpu::fft::split_plan`], [`crate::gpu::fft::device_bytes`]).
///
/// # Errors
/// [`Error::TooLarge`] for a GPU transform that cannot be split to fit (a prime 1-D length
/// past one binding).
pub fn plan(
    shapes: &[Vec<usize>],
    backends: BackendSet,
    gpu: Option<&GpuContext>,
) -> Result<Vec<super::plan::MemoryPlan>> {
    shapes
        .iter()
        .map(|shape| {
            let n: u64 = shape.iter().map(|&a| a as u64).product();
            let exact = n as f64 * shape.iter().sum::<usize>() as f64 <= EXACT_WORK_LIMIT;
            let ctx = gpu.filter(|_| backends.gpu());
            // The input (f64, f32), the f64 FFT, the reference DFT, the f32 output and
            // the GPU's.
            let host = 16 * n + 8 * n + 16 * n + if exact { 16 * n } else { 0 } + 16 * n;
            let name = shape
                .iter()
                .map(|a| a.to_string())
                .collect::<Vec<_>>()
                .join("x");
            let axes: Vec<usize> = (0..shape.len()).collect();
            let (device, split) = match ctx {
                Some(ctx) => {
                    use crate::gpu::fft::device_bytes;
                    let ((peak, largest), split) = match crate::gpu::fft::split_plan(ctx, shape)? {
                        None => (device_bytes(shape, &axes), Vec::new()),
                        Some(p) => {
                            // The larger of the two phases' pieces: a band of axis 1
                            // (axis 0's lines), a slab of axis 0 (the other axes).
                            // (A 1-D transform is cut as its four-step view.)
                            let view = p.view(shape);
                            let mut band = view.clone();
                            band[1] = p.axis0_lines.per_piece;
                            let mut slab = view.clone();
                            slab[0] = p.other_axes.per_piece;
                            let others: Vec<usize> = (1..view.len()).collect();
                            let (a, b) = (device_bytes(&band, &[0]), device_bytes(&slab, &others));
                            ((a.0.max(b.0), a.1.max(b.1)), vec![p.describe()])
                        }
                    };
                    (Some(super::plan::DevicePlan::on(ctx, peak, largest)), split)
                }
                None => (None, Vec::new()),
            };
            Ok(super::plan::MemoryPlan {
                job: format!("fft {name}"),
                backend: match ctx {
                    Some(c) if backends.cpu() => format!("cpu and gpu ({})", c.summary.name),
                    Some(c) => format!("gpu ({})", c.summary.name),
                    None => "cpu".to_string(),
                },
                host_bytes: host,
                device,
                split,
                writes: Vec::new(),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `transform_axes` over every axis is the exact N-D DFT; over some axes it is the
    /// exact 1-D DFT of every line along them; the exact path is the same sums.
    #[test]
    fn transform_axes_is_the_dft_along_the_axes_given() {
        let shape = [3usize, 5, 4];
        let x = random_complex(60, 11);
        let want = dft_nd(&x, &shape, Direction::Forward, Normalization::Unnormalized);
        for exact in [false, true] {
            let mut y = x.clone();
            transform_axes(&mut y, &shape, &[0, 1, 2], Direction::Forward, 1.0, exact).unwrap();
            assert!(
                rel_l2(&y, &want) < 1e-14,
                "exact={exact}: {}",
                rel_l2(&y, &want)
            );
        }
        // Along axis 1 only: each (i, ·, k) line.
        let mut y = x.clone();
        transform_axes(&mut y, &shape, &[1], Direction::Inverse, 0.2, false).unwrap();
        for i in 0..3 {
            for k in 0..4 {
                let line: Vec<_> = (0..5).map(|j| x[(i * 5 + j) * 4 + k]).collect();
                let d = crate::cpu::dft::dft_1d(&line, Direction::Inverse, Normalization::None);
                for (j, v) in d.iter().enumerate() {
                    assert!((y[(i * 5 + j) * 4 + k] - v * 0.2).norm() < 1e-14);
                }
            }
        }
        let e = transform_axes(&mut y, &shape, &[3], Direction::Forward, 1.0, false);
        assert!(matches!(e, Err(Error::Invalid { .. })));
    }
}
