//! `voxlab process`: resampling, Gaussian smoothing, median filtering and the
//! gradient-magnitude field of a volume (see docs/processing.md).

use clap::{Args, ValueEnum};
use std::path::PathBuf;
use voxlab::cpu::process::{self as cp, Field, Region, ResampleSpec};
use voxlab::settings::Filter;
use voxlab::{Error, Result, Volume};

/// The operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Op {
    /// Resample a box of the volume to other dimensions or spacing (--dims or
    /// --spacing; --box or --world-box; --filter).
    Resample,
    /// Gaussian smoothing, σ in voxels per axis (--sigma), truncated at 4σ, mirrored
    /// borders: scipy.ndimage.gaussian_filter.
    Gaussian,
    /// Median of the k×k×k window (--size, odd), mirrored borders:
    /// scipy.ndimage.median_filter.
    Median,
    /// |∇f| in value per mm from central differences.
    GradientMagnitude,
}

/// Where to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ProcessBackend {
    /// The f64 CPU oracle.
    Cpu,
    /// The same CPU code in f32.
    CpuF32,
    /// The GPU port (f32).
    Gpu,
}

/// Arguments of `voxlab process`.
#[derive(Args)]
pub struct ProcessArgs {
    /// Input volume (any format `info` reads, or phantom:NAME[:SIZE]).
    input: String,
    #[command(flatten)]
    load: crate::LoadArgs,
    /// The operation.
    #[arg(long, value_enum)]
    op: Op,
    /// Output volume (float32): .nrrd, .nhdr, .npy, .nii or .nii.gz; written atomically.
    #[arg(long)]
    out: PathBuf,
    /// cpu (f64 oracle), cpu-f32 or gpu.
    #[arg(long, value_enum, default_value = "cpu")]
    backend: ProcessBackend,
    /// resample: output dimensions NX,NY,NZ.
    #[arg(long, value_parser = crate::list::<usize, 3>, conflicts_with = "spacing")]
    dims: Option<[usize; 3]>,
    /// resample: output spacing in mm (one value or SX,SY,SZ); the dimensions are the
    /// box's extent divided by it, rounded (at least 1).
    #[arg(long, value_delimiter = ',')]
    spacing: Option<Vec<f64>>,
    /// resample: index-space box X0,Y0,Z0,X1,Y1,Z1 in voxel units, cell edges (the whole
    /// volume is -0.5,-0.5,-0.5,NX-0.5,NY-0.5,NZ-0.5; the default).
    #[arg(long = "box", value_parser = crate::list::<f64, 6>, allow_negative_numbers = true, conflicts_with = "world_box")]
    index_box: Option<[f64; 6]>,
    /// resample: axis-aligned world box X0,Y0,Z0,X1,Y1,Z1 in mm; the output is aligned
    /// with the world axes.
    #[arg(long, value_parser = crate::list::<f64, 6>, allow_negative_numbers = true)]
    world_box: Option<[f64; 6]>,
    /// resample: reconstruction filter.
    #[arg(long, value_enum, default_value = "trilinear")]
    filter: Filter,
    /// gaussian: σ in voxels (one value or SX,SY,SZ).
    #[arg(long, value_delimiter = ',')]
    sigma: Option<Vec<f64>>,
    /// median: window side k (odd; at most 5 on the GPU).
    #[arg(long, default_value_t = 3)]
    size: usize,
}

fn three(v: &[f64], what: &str) -> Result<[f64; 3]> {
    match v.len() {
        1 => Ok([v[0]; 3]),
        3 => Ok([v[0], v[1], v[2]]),
        _ => Err(Error::invalid(what, "give one or three numbers")),
    }
}

/// The resampling spec from the options, for a volume of `vol`'s geometry.
fn resample_spec(a: &ProcessArgs, vol: &Volume<f32>) -> Result<ResampleSpec> {
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
        grid: voxlab::cpu::filter::Grid {
            dims: f.grid.dims,
            data: f.grid.data.iter().map(|&x| x as f32).collect(),
        },
        affine: f.affine,
    }
}

pub fn run(a: ProcessArgs) -> Result<()> {
    crate::check_output_as("--out", &a.out, &["nrrd", "nhdr", "npy", "nii", "gz"])?;
    let vol = crate::load_input(&a.input, &a.load)?.to_f32();
    let sigma = match (&a.sigma, a.op) {
        (Some(s), _) => Some(three(s, "--sigma")?),
        (None, Op::Gaussian) => {
            return Err(Error::invalid("--sigma", "gaussian needs --sigma (voxels)"))
        }
        (None, _) => None,
    };
    let spec = match a.op {
        Op::Resample => Some(resample_spec(&a, &vol)?),
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
    let pb = crate::progress_bar(1, &what, "step");
    pb.enable_steady_tick(std::time::Duration::from_millis(200));
    let t = std::time::Instant::now();
    let result: Result<Field<f32>> = match a.backend {
        ProcessBackend::Gpu => {
            use voxlab::gpu::process as gp;
            let ctx = voxlab::gpu::GpuContext::new()?;
            match a.op {
                Op::Resample => gp::resample(&ctx, &vol, &spec.expect("spec")),
                Op::Gaussian => gp::gaussian(&ctx, &vol, sigma.expect("sigma")),
                Op::Median => gp::median(&ctx, &vol, a.size),
                Op::GradientMagnitude => gp::gradient_magnitude(&ctx, &vol),
            }
        }
        ProcessBackend::CpuF32 => match a.op {
            Op::Resample => cp::resample::<f32, f32>(&vol, &spec.expect("spec")),
            Op::Gaussian => cp::gaussian::<f32, f32>(&vol, sigma.expect("sigma")),
            Op::Median => cp::median::<f32, f32>(&vol, a.size),
            Op::GradientMagnitude => cp::gradient_magnitude::<f32, f32>(&vol),
        },
        ProcessBackend::Cpu => match a.op {
            Op::Resample => cp::resample::<f64, f32>(&vol, &spec.expect("spec")),
            Op::Gaussian => cp::gaussian::<f64, f32>(&vol, sigma.expect("sigma")),
            Op::Median => cp::median::<f64, f32>(&vol, a.size),
            Op::GradientMagnitude => cp::gradient_magnitude::<f64, f32>(&vol),
        }
        .map(to_f32),
    };
    pb.finish_and_clear();
    let out = result?.to_volume()?;
    eprintln!("{what}: {:.2} s", t.elapsed().as_secs_f64());
    let (d, s) = (out.dims(), out.spacing());
    voxlab::io::write_volume(&a.out, &out.into())?;
    println!(
        "wrote {} ({}×{}×{} f32, spacing {:.4} × {:.4} × {:.4} mm)",
        a.out.display(),
        d[0],
        d[1],
        d[2],
        s[0],
        s[1],
        s[2]
    );
    Ok(())
}
