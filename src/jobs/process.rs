//! `voxlab process`: resampling, Gaussian smoothing, median filtering and the
//! gradient-magnitude field of a volume, scipy.ndimage-compatible (see
//! docs/processing.md). The operations are [`crate::cpu::process`] and
//! [`crate::gpu::process`].

use super::input::VolumeInput;
use super::{stage, Backend, Engine, Progress};
use crate::cpu::process::{self as cp, Field, Region, ResampleSpec};
use crate::error::{Error, Result};
use crate::settings::Filter;
use crate::volume::Volume;
use serde::{Deserialize, Serialize};

crate::choice_enum! {
    /// The operation.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Op: "operation" {
        /// Resample a box of the volume to other dimensions or spacing (--dims or
        /// --spacing; --box or --world-box; --filter).
        Resample = "resample",
        /// Gaussian smoothing, σ in voxels per axis (--sigma), truncated at 4σ, mirrored
        /// borders: scipy.ndimage.gaussian_filter.
        Gaussian = "gaussian",
        /// Median of the k×k×k window (--size, odd), mirrored borders:
        /// scipy.ndimage.median_filter.
        Median = "median",
        /// |∇f| in value per mm from central differences.
        GradientMagnitude = "gradient-magnitude",
    }
}

/// The `voxlab process` job.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ProcessRequest {
    pub input: VolumeInput,
    pub op: Op,
    pub backend: Backend,
    /// resample: output dimensions.
    pub dims: Option<[usize; 3]>,
    /// resample: output spacing in mm (one value or three); the dimensions are the
    /// box's extent divided by it, rounded (at least 1).
    pub spacing: Option<Vec<f64>>,
    /// resample: index-space box `[x0, y0, z0, x1, y1, z1]` in voxel units, cell edges
    /// (`None` and no `world_box`: the whole volume).
    pub index_box: Option<[f64; 6]>,
    /// resample: an axis-aligned world box in mm; the output is aligned with the world
    /// axes.
    pub world_box: Option<[f64; 6]>,
    /// resample: reconstruction filter.
    pub filter: Filter,
    /// gaussian: σ in voxels (one value or three).
    pub sigma: Option<Vec<f64>>,
    /// median: window side k (odd; at most 5 on the GPU).
    pub size: usize,
}

impl Default for ProcessRequest {
    fn default() -> Self {
        ProcessRequest {
            input: VolumeInput::default(),
            op: Op::Gaussian,
            backend: Backend::Cpu,
            dims: None,
            spacing: None,
            index_box: None,
            world_box: None,
            filter: Filter::Trilinear,
            sigma: None,
            size: 3,
        }
    }
}

/// The processed volume (float32) and what was done.
#[derive(Clone, Debug)]
pub struct Processed {
    pub volume: Volume<f32>,
    /// `resampling to 16×16×16 (Trilinear)`, `Gaussian σ = [1.0, 1.0, 1.0] voxels`, …
    pub what: String,
    pub seconds: f64,
    pub engine: Engine,
}

fn three(v: &[f64], what: &str) -> Result<[f64; 3]> {
    match v.len() {
        1 => Ok([v[0]; 3]),
        3 => Ok([v[0], v[1], v[2]]),
        _ => Err(Error::invalid(what, "give one or three numbers")),
    }
}

/// The resampling spec of the request, for a volume of `vol`'s geometry.
fn resample_spec(a: &ProcessRequest, vol: &Volume<f32>) -> Result<ResampleSpec> {
    if a.index_box.is_some() && a.world_box.is_some() {
        return Err(Error::invalid(
            "--box",
            "give an index box or a world box, not both",
        ));
    }
    let region = match (&a.index_box, &a.world_box) {
        (Some(b), _) => Region::Index {
            lo: [b[0], b[1], b[2]],
            hi: [b[3], b[4], b[5]],
        },
        (None, Some(b)) => Region::World {
            lo: [b[0], b[1], b[2]],
            hi: [b[3], b[4], b[5]],
        },
        (None, None) => Region::Whole,
    };
    let dims = match (&a.dims, &a.spacing) {
        (Some(d), _) => *d,
        (None, Some(sp)) => {
            let sp = three(sp, "--spacing")?;
            if !sp.iter().all(|s| s.is_finite() && *s > 0.0) {
                return Err(Error::invalid("--spacing", "must be positive (mm)"));
            }
            // The box's extent in mm along each output axis.
            let extent = match region {
                Region::Whole => vol.extent_world(),
                Region::Index { lo, hi } => {
                    let s = vol.spacing();
                    [0, 1, 2].map(|i| (hi[i] - lo[i]) * s[i])
                }
                Region::World { lo, hi } => [0, 1, 2].map(|i| hi[i] - lo[i]),
            };
            let mut d = [0usize; 3];
            for i in 0..3 {
                let n = (extent[i] / sp[i]).round();
                if !n.is_finite() || n > 1e12 {
                    return Err(Error::too_large(
                        "volume",
                        format!("--spacing {sp:?} gives {n} voxels along axis {i}"),
                    ));
                }
                d[i] = (n as usize).max(1);
            }
            d
        }
        (None, None) => {
            return Err(Error::invalid(
                "--dims",
                "resample needs --dims NX,NY,NZ or --spacing",
            ))
        }
    };
    Ok(ResampleSpec {
        region,
        dims,
        filter: a.filter,
    })
}

fn to_f32(f: Field<f64>) -> Field<f32> {
    Field {
        grid: crate::cpu::grid::Grid {
            dims: f.grid.dims,
            data: f.grid.data.iter().map(|&x| x as f32).collect(),
        },
        affine: f.affine,
    }
}

/// The input volume and the operation's parameters: σ for the Gaussian, the
/// resampling spec, and the stage's name.
#[allow(clippy::type_complexity)]
fn prepare(
    a: &ProcessRequest,
    progress: &dyn Progress,
) -> Result<(Volume<f32>, Option<[f64; 3]>, Option<ResampleSpec>, String)> {
    // The options first, so that `--dry-run` refuses them too, before any reading (the
    // GPU's smaller median window: `gpu::process::ProcessPlan::median`).
    let sigma = match (&a.sigma, a.op) {
        (Some(s), _) => Some(three(s, "--sigma")?),
        (None, Op::Gaussian) => {
            return Err(Error::invalid("--sigma", "gaussian needs --sigma (voxels)"))
        }
        (None, _) => None,
    };
    if let (Some(s), Op::Gaussian) = (sigma, a.op) {
        cp::check_sigma(s)?;
    }
    if a.op == Op::Median {
        cp::check_median_size(a.size, cp::MAX_MEDIAN_SIZE_CPU)?;
    }
    let vol = a.input.load(progress)?.to_f32();
    let spec = match a.op {
        Op::Resample => Some(resample_spec(a, &vol)?),
        _ => None,
    };
    let what = match a.op {
        Op::Resample => {
            let s = spec.expect("resample spec");
            format!(
                "resampling to {}×{}×{} ({:?})",
                s.dims[0], s.dims[1], s.dims[2], s.filter
            )
        }
        Op::Gaussian => format!("Gaussian σ = {:?} voxels", sigma.unwrap_or_default()),
        Op::Median => format!("median {}³", a.size),
        Op::GradientMagnitude => "gradient magnitude".to_string(),
    };
    Ok((vol, sigma, spec, what))
}

/// `voxlab process --dry-run`: the memory plan of [`run`] (host bytes, device bytes
/// against the planner's limits, the slabs the GPU would use) after reading the input
/// and checking the options, without computing or writing anything.
///
/// # Errors
/// As [`run`] up to the work; [`Error::TooLarge`] for a job that cannot fit even
/// split.
pub fn plan(a: &ProcessRequest, progress: &dyn Progress) -> Result<super::plan::MemoryPlan> {
    use crate::gpu::process::{ProcessPlan, ResamplePlan};
    let (vol, sigma, spec, what) = prepare(a, progress)?;
    let voxels = vol.len() as u64;
    let out_voxels = spec.map_or(voxels, |s| s.dims.iter().product::<usize>() as u64);
    let engine = Engine::open(a.backend)?;
    // The request writes nothing itself: the caller adds its output.
    let writes = Vec::new();
    let (backend, device, split) = match (engine.backend(), engine.gpu()) {
        (Backend::Gpu, Some(ctx)) => {
            let plan = match a.op {
                Op::Resample => None,
                // (Resampling plans its own slabs below.)
                Op::Gaussian => Some(ProcessPlan::gaussian(
                    &ctx.limits,
                    vol.dims(),
                    sigma.expect("sigma"),
                )?),
                Op::Median => Some(ProcessPlan::median(&ctx.limits, vol.dims(), a.size)?),
                Op::GradientMagnitude => {
                    Some(ProcessPlan::gradient_magnitude(&ctx.limits, vol.dims())?)
                }
            };
            let slice = (vol.dims()[0] * vol.dims()[1]) as u64 * 4;
            let (peak, largest, split) = match plan {
                // Resampling: each output slab and the input slices it reads.
                None => {
                    let spec = spec.as_ref().expect("spec");
                    let r = ResamplePlan::for_volume(&ctx.limits, &vol, spec)?;
                    let input = r.largest_input() as u64 * slice;
                    let out = (r.slabs.per_piece * spec.dims[0] * spec.dims[1]) as u64 * 4;
                    let split = if r.is_split() {
                        vec![r.describe()]
                    } else {
                        Vec::new()
                    };
                    (input + out, input.max(out), split)
                }
                Some(p) => {
                    let input = (p.slabs.per_piece + 2 * p.ghost).min(p.slabs.total) as u64 * slice;
                    let split = if p.is_split() {
                        vec![p.describe()]
                    } else {
                        Vec::new()
                    };
                    (2 * input, input, split)
                }
            };
            (
                format!("gpu ({})", ctx.summary.name),
                Some(super::plan::DevicePlan::on(ctx, peak, largest)),
                split,
            )
        }
        (Backend::CpuF32, _) => ("cpu f32".to_string(), None, Vec::new()),
        _ => ("cpu f64".to_string(), None, Vec::new()),
    };
    // The f32 input, the result, and (f64 backend) its f64 field.
    let wide = if backend == "cpu f64" { 8 } else { 0 };
    Ok(super::plan::MemoryPlan {
        job: format!("process: {what}"),
        backend,
        host_bytes: voxels * 4 + out_voxels * (4 + wide),
        device,
        split,
        writes,
    })
}

/// Runs the operation.
///
/// # Errors
/// Bad options or input; GPU errors; [`Error::Cancelled`].
pub fn run(a: &ProcessRequest, progress: &dyn Progress) -> Result<Processed> {
    let (vol, sigma, spec, what) = prepare(a, progress)?;
    let engine = Engine::open(a.backend)?;
    let t = std::time::Instant::now();
    let field = stage(progress, &what, "step", 0, || {
        match (engine.backend(), engine.gpu()) {
            (Backend::Gpu, Some(ctx)) => {
                use crate::gpu::process as gp;
                match a.op {
                    Op::Resample => {
                        let spec = spec.expect("spec");
                        let plan = gp::ResamplePlan::for_volume(&ctx.limits, &vol, &spec)?;
                        if plan.is_split() {
                            progress.note(&plan.describe());
                        }
                        gp::resample_planned(ctx, &vol, &spec, &plan).map(|(f, _)| f)
                    }
                    Op::Gaussian => {
                        let sigma = sigma.expect("sigma");
                        let plan = gp::ProcessPlan::gaussian(&ctx.limits, vol.dims(), sigma)?;
                        note_split(progress, &plan);
                        gp::gaussian_planned(ctx, &vol, sigma, &plan).map(|(f, _)| f)
                    }
                    Op::Median => {
                        let plan = gp::ProcessPlan::median(&ctx.limits, vol.dims(), a.size)?;
                        note_split(progress, &plan);
                        gp::median_planned(ctx, &vol, a.size, &plan).map(|(f, _)| f)
                    }
                    Op::GradientMagnitude => {
                        let plan = gp::ProcessPlan::gradient_magnitude(&ctx.limits, vol.dims())?;
                        note_split(progress, &plan);
                        gp::gradient_magnitude_planned(ctx, &vol, &plan).map(|(f, _)| f)
                    }
                }
            }
            (Backend::CpuF32, _) => match a.op {
                Op::Resample => cp::resample::<f32, f32>(&vol, &spec.expect("spec")),
                Op::Gaussian => cp::gaussian::<f32, f32>(&vol, sigma.expect("sigma")),
                Op::Median => cp::median::<f32, f32>(&vol, a.size),
                Op::GradientMagnitude => cp::gradient_magnitude::<f32, f32>(&vol),
            },
            _ => match a.op {
                Op::Resample => cp::resample::<f64, f32>(&vol, &spec.expect("spec")),
                Op::Gaussian => cp::gaussian::<f64, f32>(&vol, sigma.expect("sigma")),
                Op::Median => cp::median::<f64, f32>(&vol, a.size),
                Op::GradientMagnitude => cp::gradient_magnitude::<f64, f32>(&vol),
            }
            .map(to_f32),
        }
    })?;
    let volume = field.to_volume()?;
    Ok(Processed {
        volume,
        what,
        seconds: t.elapsed().as_secs_f64(),
        engine,
    })
}

/// Tells the user how a split GPU operation is cut.
fn note_split(progress: &dyn Progress, plan: &crate::gpu::process::ProcessPlan) {
    if plan.is_split() {
        progress.note(&plan.describe());
    }
}
