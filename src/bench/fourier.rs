//! Benchmark cases of the Fourier family: the complex N-D FFT (`fft`) and Fourier
//! volume rendering (`fvr`).
//!
//! **fft.** The forward, unnormalised complex FFT of random values (uniform in
//! `[−1, 1)` in both parts, [`crate::jobs::fft::random_complex`] with a fixed seed) in
//! 2-D (`256²`, `512²`, `1024²`) and 3-D (`64³`, `128³`, `256³`). The oracle is the f64
//! FFT ([`crate::cpu::fft::fft_nd`], rustfft along every axis, all rayon threads): the
//! exact DFT costs `N·ΣN_axis` multiply-adds (`1.8·10¹¹` at `256³`) and is far too slow
//! to time; the f64 FFT is itself held to `1e-13` of the exact DFT in `tests/fft.rs`.
//! The CPU f32 baseline is the same code in f32. The GPU runs the Stockham
//! transform with a plan made once ([`GpuFftPlan`], reported as set-up): each run
//! uploads the array into a buffer made once, runs every pass (timed by timestamp
//! queries where the adapter has them) and reads the result back. Work: the
//! conventional `5·N·log₂N` flops, and `16·N` bytes — one read and one write of the
//! complex f32 array, the least any transform moves (the GPU's passes each read and
//! write the whole array, so they move several times that: the GB/s figure is a
//! lower bound on the memory traffic).
//!
//! **fvr.** One X-ray view (azimuth 30°, elevation 20°, de-apodised) of the modified
//! Shepp–Logan phantom sampled on `n³` voxels, padded by 2 (`M = 2n`), from its
//! precomputed spectrum ([`FvrSpectrum::new`], f64, timed once in `prepare` and shown
//! in the note), trilinear and Lanczos-3 slicing. The oracle is
//! [`crate::cpu::fvr::fvr_project`] (f64 slice, f64 inverse `M²` FFT); the CPU f32
//! baseline is the same function on the spectrum rounded to complex f32
//! ([`FvrSpectrum::to_f32`], once, not timed — the GPU receives the same rounding).
//! The GPU makes its own spectrum once per device: the padded cube uploaded as complex
//! f32 and transformed by its 3-D FFT on the device, with the pipelines and the
//! inverse-FFT plan ([`GpuFvrSpectrum::compute`], reported as set-up beside the CPU's
//! f64 pre-processing in the note), then per view: slice dispatch, inverse FFT,
//! readback, crop. Work: rays (the `n²` output pixels).
//!
//! The same inputs feed `cargo bench --bench fft` and `--bench fvr`
//! ([`fft_input`], [`fvr_volume`], [`FVR_VIEW`]).

use super::case::flat;
use super::{Case, GpuRun, Prepared, Run, Suite, Unit, Work};
use crate::cpu::dft::{Direction, Normalization};
use crate::cpu::fft::fft_nd;
use crate::cpu::fvr::{fvr_project, FvrSpectrum, FvrView, Kernel};
use crate::error::Result;
use crate::gpu::fft::{GpuFftPlan, GpuFftVariant};
use crate::gpu::fvr::{fvr_project_timed, GpuFvrSpectrum};
use crate::gpu::GpuContext;
use crate::jobs::fft::random_complex;
use crate::metrics::Tolerance;
use crate::phantom::Phantom;
use crate::volume::Volume;
use rustfft::num_complex::Complex;
use std::sync::Arc;
use std::time::Instant;

/// The seed of every FFT input.
pub const FFT_SEED: u64 = 0x5eed;

/// The view of every FVR case: oblique, so the slice is interpolated everywhere.
pub const FVR_VIEW: FvrView = FvrView::Orbit {
    azimuth_deg: 30.0,
    elevation_deg: 20.0,
};

/// The oversampling of the FVR spectrum (`M = 2n`).
pub const FVR_PADDING: usize = 2;

/// The input of an FFT case of `shape`: random complex values, fixed seed.
pub fn fft_input(shape: &[usize]) -> Vec<Complex<f64>> {
    random_complex(shape.iter().product(), FFT_SEED)
}

/// The volume of an FVR case: the modified Shepp–Logan phantom on `n³` voxels.
///
/// # Errors
/// When the phantom cannot be sampled (never for `n ≥ 1`).
pub fn fvr_volume(n: usize) -> Result<Volume<f32>> {
    Phantom::shepp_logan_modified().sample([n; 3])
}

/// The bound on the relative L2 error of an f32 FFT of `total` values:
/// `1e-6·log₂N` (`tests/fft.rs`, `tests/gpu_fft.rs`). Measured on lavapipe:
/// CPU f32 ≤ 2.4e-7, GPU Stockham ≤ 1.6e-7 over every size in those tests.
pub fn fft_rel_l2_bound(total: usize) -> f64 {
    1e-6 * (total as f64).log2().max(1.0)
}

/// Complex values as `[re, im]` pairs in f64, for the parity check.
fn flat_complex<T: Copy + Into<f64>>(data: &[Complex<T>]) -> Vec<f64> {
    data.iter()
        .flat_map(|v| [v.re.into(), v.im.into()])
        .collect()
}

/// The FFT and FVR cases of `suite`.
pub fn cases(suite: Suite) -> Vec<Case> {
    let (sizes2, sizes3, fvr_sizes): (&[usize], &[usize], &[usize]) = match suite {
        Suite::Quick => (&[32], &[16], &[16]),
        // 1000² and 100³: lengths that are not powers of two (Bluestein's algorithm
        // on the GPU, mixed radix in rustfft).
        Suite::Full => (
            &[256, 512, 1024, 1000],
            &[64, 128, 256, 100],
            &[64, 128, 256],
        ),
    };
    let mut out = Vec::new();
    for &n in sizes2 {
        out.push(fft_case(vec![n, n]));
    }
    for &n in sizes3 {
        out.push(fft_case(vec![n, n, n]));
    }
    for &n in fvr_sizes {
        for kernel in [Kernel::Trilinear, Kernel::Lanczos3] {
            out.push(fvr_case(n, kernel));
        }
    }
    out
}

fn fft_case(shape: Vec<usize>) -> Case {
    let n = shape[0];
    let (name, size) = match shape.len() {
        2 => ("2d", format!("{n}²")),
        _ => ("3d", format!("{n}³")),
    };
    Case::new("fft", name, size, move || prepare_fft(&shape))
}

/// The forward unnormalised CPU FFT of a copy of `x`, timed without the copy.
fn cpu_fft<T: rustfft::FftNum + Into<f64>>(x: &[Complex<T>], shape: &[usize]) -> Run {
    let mut d = x.to_vec();
    let t = Instant::now();
    fft_nd(
        &mut d,
        shape,
        Direction::Forward,
        Normalization::Unnormalized,
    );
    let seconds = t.elapsed().as_secs_f64();
    Run {
        seconds,
        output: flat_complex(&d),
    }
}

/// A GPU FFT plan and the data buffer it runs on, made once per device.
struct FftState {
    device: wgpu::Device,
    plan: GpuFftPlan,
    buffer: wgpu::Buffer,
    setup: f64,
}

fn prepare_fft(shape: &[usize]) -> Result<Prepared> {
    let total: usize = shape.iter().product();
    let x = Arc::new(fft_input(shape));
    let x32: Arc<Vec<Complex<f32>>> = Arc::new(
        x.iter()
            .map(|v| Complex::new(v.re as f32, v.im as f32))
            .collect(),
    );
    let host: Vec<[f32; 2]> = x32.iter().map(|v| [v.re, v.im]).collect();
    let (s64, s32, sg) = (shape.to_vec(), shape.to_vec(), shape.to_vec());
    let x64 = Arc::clone(&x);
    let x32c = Arc::clone(&x32);
    let mut state: Option<FftState> = None;
    let gpu = move |ctx: &GpuContext| -> Result<GpuRun> {
        if state.as_ref().is_none_or(|s| s.device != ctx.device) {
            let t = Instant::now();
            let plan = GpuFftPlan::new(
                ctx,
                &sg,
                Direction::Forward,
                Normalization::Unnormalized,
                GpuFftVariant::Stockham,
            )?;
            let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("bench fft data"),
                size: (total * 8) as u64,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            ctx.wait()?;
            state = Some(FftState {
                device: ctx.device.clone(),
                plan,
                buffer,
                setup: t.elapsed().as_secs_f64(),
            });
        }
        let s = state.as_ref().expect("the plan was just made");
        let t = Instant::now();
        ctx.queue
            .write_buffer(&s.buffer, 0, bytemuck::cast_slice(&host));
        ctx.queue.submit([]);
        ctx.wait()?;
        let upload = t.elapsed().as_secs_f64();
        let out = s.plan.execute_buffer(ctx, &s.buffer)?;
        Ok(GpuRun {
            output: flat_complex(&out.data),
            kernel: out.timings.kernel,
            kernel_from_timestamps: out.timings.kernel_from_timestamps,
            end_to_end: upload + out.timings.total,
            setup: s.setup,
        })
    };
    let l2 = fft_rel_l2_bound(total);
    let log2n = (total as f64).log2();
    Ok(Prepared {
        cpu_f64: Box::new(move || Ok(cpu_fft(&x64, &s64))),
        cpu_f32: Some(Box::new(move || Ok(cpu_fft(&x32c, &s32)))),
        gpu: Some(Box::new(gpu)),
        // rel L2: the tests' bound 1e-6·log₂N. max |Δ| / max |X|: the same bound (the
        // largest |X| of random data is a few times its RMS, the largest error a few
        // times the RMS error). Measured on lavapipe, CPU f32 and GPU alike: max
        // 1.3e-7 … 2.2e-7, rel L2 1.1e-7 … 1.8e-7 from 32² to 256³.
        tol_f32: Tolerance::max_abs_rel(l2).with_rel_l2(l2),
        tol_gpu: Tolerance::max_abs_rel(l2).with_rel_l2(l2),
        work: vec![
            Work {
                amount: 5.0 * total as f64 * log2n,
                unit: Unit::Flops,
            },
            Work {
                amount: 16.0 * total as f64,
                unit: Unit::Bytes,
            },
        ],
        note: format!(
            "Forward unnormalised complex FFT of {total} random values. Oracle: the f64 FFT \
             (rustfft per axis; the exact DFT, N·ΣN multiply-adds, is too slow to time here \
             and holds the f64 FFT to 1e-13 in tests/fft.rs). GPU: Stockham, plan made once \
             (set-up); end to end = upload + passes + readback. Flops = 5·N·log₂N; Bytes = \
             16·N (one read and one write of the complex f32 array)."
        ),
    })
}

/// The GPU's tolerance for an FVR view from an `M³` spectrum. `tests/gpu_fvr.rs`
/// holds `M` ≤ 64 to 5e-6 (max and rel L2); the error grows about linearly with `M`
/// (the f32 spectrum's rounding scales with its largest values, near the DC term, and
/// the inverse FFT spreads it over the image), so the bounds grow beyond: max
/// `max(5e-6, 4e-8·M)`, rel L2 `max(5e-6, 2.5e-8·M)`. Measured on lavapipe (max / rel
/// L2, trilinear and Lanczos-3): M = 32 2.6e-7 / 2.4e-7; M = 128 1.1e-6 / 6.6e-7;
/// M = 256 2.3e-6 / 1.2e-6; M = 512 (1 GiB, 8 slabs on lavapipe; Lanczos-3, not
/// de-apodised, `tests/gpu_fvr.rs: a_1_gib_spectrum_renders_from_slabs`) 6.2e-6 / 4.3e-6.
pub fn fvr_gpu_tol(m: usize) -> Tolerance {
    Tolerance::max_abs_rel((4e-8 * m as f64).max(5e-6)).with_rel_l2((2.5e-8 * m as f64).max(5e-6))
}

fn fvr_case(n: usize, kernel: Kernel) -> Case {
    let name = kernel.name();
    let m = FVR_PADDING * n;
    Case::new(
        "fvr",
        name,
        format!("{n}³ (M = {m}) → {n}²"),
        move || prepare_fvr(n, kernel),
    )
}

fn prepare_fvr(n: usize, kernel: Kernel) -> Result<Prepared> {
    let vol = fvr_volume(n)?;
    let t = Instant::now();
    let spectrum = Arc::new(FvrSpectrum::new(&vol, FVR_PADDING)?);
    let pre = t.elapsed().as_secs_f64();
    let m = spectrum.side();
    let g = spectrum.geometry(FVR_VIEW)?;
    let rays = (g.width * g.height) as f64;
    let cpu_spec = Arc::clone(&spectrum);
    let cpu = move || -> Result<Run> {
        let t = Instant::now();
        let img = fvr_project(&cpu_spec, FVR_VIEW, kernel, true)?;
        let seconds = t.elapsed().as_secs_f64();
        Ok(Run {
            seconds,
            output: img.data,
        })
    };
    let spec32 = spectrum.to_f32();
    let cpu32 = move || -> Result<Run> {
        let t = Instant::now();
        let img = fvr_project(&spec32, FVR_VIEW, kernel, true)?;
        let seconds = t.elapsed().as_secs_f64();
        Ok(Run {
            seconds,
            output: img.data,
        })
    };
    drop(spectrum);
    // The GPU's spectrum, transformed on the device once per device (set-up).
    let mut state: Option<(wgpu::Device, GpuFvrSpectrum, f64)> = None;
    let gpu = move |ctx: &GpuContext| -> Result<GpuRun> {
        if state.as_ref().is_none_or(|s| s.0 != ctx.device) {
            let t = Instant::now();
            let on_gpu = GpuFvrSpectrum::compute(ctx, &vol, FVR_PADDING)?;
            state = Some((ctx.device.clone(), on_gpu, t.elapsed().as_secs_f64()));
        }
        let (_, on_gpu, setup) = state.as_ref().expect("the spectrum was just made");
        let (img, times) = fvr_project_timed(ctx, on_gpu, FVR_VIEW, kernel, true)?;
        Ok(GpuRun {
            output: flat(&img.data),
            kernel: times.kernel.unwrap_or(times.slice + times.fft),
            kernel_from_timestamps: times.kernel.is_some(),
            end_to_end: times.total,
            setup: *setup,
        })
    };
    Ok(Prepared {
        cpu_f64: Box::new(cpu),
        cpu_f32: Some(Box::new(cpu32)),
        gpu: Some(Box::new(gpu)),
        // The CPU f32 path rounds the same spectrum and sums in f32 like the GPU: the
        // GPU's bound holds it (tests/fvr.rs measures it).
        tol_f32: fvr_gpu_tol(m),
        tol_gpu: fvr_gpu_tol(m),
        work: vec![Work {
            amount: rays,
            unit: Unit::Rays,
        }],
        note: format!(
            "One oblique X-ray view (azimuth 30°, elevation 20°, de-apodised) from the \
             precomputed spectrum of the {n}³ modified Shepp–Logan phantom padded to {m}³. \
             Pre-processing (pad, centre, f64 3-D FFT; once per volume, not timed per \
             view): {:.1} ms. CPU f32: the spectrum rounded to complex f32 once (not \
             timed), slice and inverse FFT in f32. GPU set-up = the spectrum made on the \
             GPU (the padded cube uploaded as complex f32, its 3-D FFT on the device) with \
             the pipelines and the inverse-FFT plan; kernel = the slice dispatch and \
             the inverse FFT's passes on the device (timestamp queries; without them, \
             both steps with the readback, wall clock); end to end adds the host crop. The \
             spectrum is {} MiB, split into z-slabs where it exceeds the adapter's \
             storage-binding limit (lavapipe: 128 MiB per binding).",
            pre * 1e3,
            (m * m * m * 8) >> 20
        ),
    })
}
