//! Benchmark cases of the volume processing tools (family `process`,
//! docs/processing.md): resampling with the ray caster's reconstruction filters,
//! Gaussian smoothing, the 3-D median and the gradient-magnitude field.
//!
//! Input: the modified Shepp–Logan head on `n³` voxels. Resampling tiles the whole
//! volume with twice as many voxels per axis (`n³ → (2n)³`, every output voxel one
//! interpolation) with trilinear, Catmull–Rom, interpolating cubic B-spline (its
//! prefilter included in the run) and Lanczos-3; the Gaussian has σ = 2 voxels (radius
//! 8, three separable passes); the median a 3³ window; the gradient magnitude central
//! differences. One run is [`crate::cpu::process`]'s function in the working
//! precision, or [`crate::gpu::process`]'s `*_planned` function, which compiles its
//! pipeline, uploads, dispatches and reads back each call: its kernel column is the
//! dispatches on the device (timestamp queries; without them, the wall clock of the
//! whole call), its set-up the pipeline's compilation, and end to end the rest of the
//! call. Work: voxel updates (output voxels) and, for resampling, samples (output
//! voxels × taps).

use super::{Case, GpuRun, Prepared, Run, Suite, Unit, Work};
use crate::cpu::process::{self as cp, Field, Region, ResampleSpec};
use crate::error::Result;
use crate::metrics::Tolerance;
use crate::phantom::Phantom;
use crate::settings::Filter;
use crate::volume::Volume;
use std::rc::Rc;
use std::time::Instant;

/// The f32 CPU path and the GPU against the f64 oracle, relative to the output's
/// peak: `tests/gpu_process.rs` TOL_MAX_REL (measured there 1.7e-7 … 3.1e-6 over
/// resampling, Gaussian and gradient magnitude; f32 sample positions on the phantom's
/// unit steps are the worst). The median of f32 values is one of them, exact.
/// rel L2: a third of the max bound. Measured at 128³ (docs/bench/lavapipe.md), CPU
/// f32 and lavapipe alike: max ≤ 4.0e-7 (Lanczos-3 resampling), rel L2 ≤ 1.4e-7.
const PROCESS_TOL: Tolerance = Tolerance::max_abs_rel(2e-5).with_rel_l2(7e-6);

/// One processing operation.
#[derive(Clone, Copy, Debug)]
enum Op {
    Resample(Filter),
    Gaussian(f64),
    Median(usize),
    GradientMagnitude,
}

impl Op {
    fn name(self) -> String {
        match self {
            Op::Resample(f) => format!("resample-{}", f.name()),
            Op::Gaussian(s) => format!("gaussian-sigma{s}"),
            Op::Median(k) => format!("median-{k}"),
            Op::GradientMagnitude => "gradient-magnitude".into(),
        }
    }

    /// The output side for an input of side `n`.
    fn out_side(self, n: usize) -> usize {
        match self {
            Op::Resample(_) => 2 * n,
            _ => n,
        }
    }

    fn cpu<R: crate::real::Real>(self, v: &Volume<f32>) -> Result<Field<R>> {
        match self {
            Op::Resample(filter) => cp::resample(v, &spec(v, filter)),
            Op::Gaussian(s) => cp::gaussian(v, [s; 3]),
            Op::Median(k) => cp::median(v, k),
            Op::GradientMagnitude => cp::gradient_magnitude(v),
        }
    }

    fn gpu(
        self,
        ctx: &crate::gpu::GpuContext,
        v: &Volume<f32>,
    ) -> Result<(Field<f32>, crate::gpu::process::ProcessTimings)> {
        use crate::gpu::process::{self as gp, ProcessPlan, ResamplePlan};
        let (limits, dims) = (&ctx.limits, v.dims());
        match self {
            Op::Resample(filter) => {
                let spec = spec(v, filter);
                let plan = ResamplePlan::for_volume(limits, v, &spec)?;
                gp::resample_planned(ctx, v, &spec, &plan)
            }
            Op::Gaussian(s) => {
                let plan = ProcessPlan::gaussian(limits, dims, [s; 3])?;
                gp::gaussian_planned(ctx, v, [s; 3], &plan)
            }
            Op::Median(k) => gp::median_planned(ctx, v, k, &ProcessPlan::median(limits, dims, k)?),
            Op::GradientMagnitude => {
                let plan = ProcessPlan::gradient_magnitude(limits, dims)?;
                gp::gradient_magnitude_planned(ctx, v, &plan)
            }
        }
    }
}

/// The whole volume onto twice as many voxels per axis.
fn spec(v: &Volume<f32>, filter: Filter) -> ResampleSpec {
    ResampleSpec {
        region: Region::Whole,
        dims: v.dims().map(|n| 2 * n),
        filter,
    }
}

/// (operation, input side) of every case of a suite.
fn grid(suite: Suite) -> Vec<(Op, usize)> {
    let ops = [
        Op::Resample(Filter::Trilinear),
        Op::Resample(Filter::CatmullRom),
        Op::Resample(Filter::BsplineInterp),
        Op::Resample(Filter::Lanczos3),
        Op::Gaussian(2.0),
        Op::Median(3),
        Op::GradientMagnitude,
    ];
    let n = match suite {
        Suite::Quick => 12,
        Suite::Full => 128,
    };
    ops.into_iter().map(|op| (op, n)).collect()
}

/// Every processing case of a suite.
pub fn cases(suite: Suite) -> Vec<Case> {
    grid(suite)
        .into_iter()
        .map(|(op, n)| {
            let m = op.out_side(n);
            Case::new(
                "process",
                op.name(),
                format!("{n}³ → {m}³"),
                move || prepare(op, n),
            )
        })
        .collect()
}

fn flat_field<R: crate::real::Real>(f: &Field<R>) -> Vec<f64> {
    f.grid.data.iter().map(|v| v.f64()).collect()
}

fn prepare(op: Op, n: usize) -> Result<Prepared> {
    let v = Rc::new(Phantom::shepp_logan_modified().sample([n; 3])?);
    fn cpu<R: crate::real::Real>(op: Op, v: &Volume<f32>) -> Result<Run> {
        let t = Instant::now();
        let f = op.cpu::<R>(v)?;
        let seconds = t.elapsed().as_secs_f64();
        Ok(Run {
            seconds,
            output: flat_field(&f),
        })
    }
    let (v64, v32, vg) = (Rc::clone(&v), Rc::clone(&v), Rc::clone(&v));
    let gpu = Box::new(move |ctx: &crate::gpu::GpuContext| {
        let t = Instant::now();
        let (f, times) = op.gpu(ctx, &vg)?;
        let end_to_end = t.elapsed().as_secs_f64() - times.setup;
        Ok(GpuRun {
            output: flat_field(&f),
            kernel: times.kernel.unwrap_or(end_to_end),
            kernel_from_timestamps: times.kernel.is_some(),
            end_to_end,
            setup: times.setup,
        })
    }) as super::GpuFn;
    let m = op.out_side(n);
    let voxels = (m * m * m) as f64;
    let mut work = vec![Work {
        amount: voxels,
        unit: Unit::VoxelUpdates,
    }];
    if let Op::Resample(filter) = op {
        let taps = ((2 * filter.radius()) as f64).powi(3);
        work.push(Work {
            amount: voxels * taps,
            unit: Unit::Samples,
        });
    }
    Ok(Prepared {
        cpu_f64: Box::new(move || cpu::<f64>(op, &v64)),
        cpu_f32: Some(Box::new(move || cpu::<f32>(op, &v32))),
        gpu: Some(gpu),
        tol_f32: PROCESS_TOL,
        tol_gpu: PROCESS_TOL,
        work,
        note: format!(
            "{} of the {n}³ modified Shepp–Logan head (output {m}³). GPU: kernel = the \
             dispatches on the device (timestamp queries; without them, the wall clock \
             of the call), each submitted and waited for; set-up = the pipeline's \
             compilation; end to end = upload, dispatches and readback. Samples \
             (resampling): output voxels × filter taps.",
            op.name()
        ),
    })
}
