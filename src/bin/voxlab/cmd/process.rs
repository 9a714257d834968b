//! `voxlab process`: resampling, smoothing, median filtering and gradient magnitude
//! of a volume, through [`voxlab::jobs::process::run`].

use crate::cli::{choice, list, LoadArgs, Terminal};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::jobs::process::{Op, ProcessRequest};
use voxlab::jobs::Backend;
use voxlab::settings::Filter;
use voxlab::Result;

/// Arguments of `voxlab process`.
#[derive(Args)]
pub struct ProcessArgs {
    /// Input volume (any format `info` reads, or phantom:NAME[:SIZE]).
    pub input: String,
    #[command(flatten)]
    pub load: LoadArgs,
    /// The operation.
    #[arg(long, value_parser = choice::<Op>())]
    pub op: Op,
    /// Output volume (float32): .nrrd, .nhdr, .npy, .nii, .nii.gz, .mha or .mhd; written atomically.
    #[arg(long)]
    pub out: PathBuf,
    /// cpu (f64 oracle), cpu-f32, gpu or auto.
    #[arg(long, value_parser = choice::<Backend>(), default_value = "cpu")]
    pub backend: Backend,
    /// resample: output dimensions NX,NY,NZ.
    #[arg(long, value_parser = list::<usize, 3>, conflicts_with = "spacing")]
    pub dims: Option<[usize; 3]>,
    /// resample: output spacing in mm (one value or SX,SY,SZ); the dimensions are the
    /// box's extent divided by it, rounded (at least 1).
    #[arg(long, value_delimiter = ',')]
    pub spacing: Option<Vec<f64>>,
    /// resample: index-space box X0,Y0,Z0,X1,Y1,Z1 in voxel units, cell edges (the whole
    /// volume is -0.5,-0.5,-0.5,NX-0.5,NY-0.5,NZ-0.5; the default).
    #[arg(long = "box", value_parser = list::<f64, 6>, allow_negative_numbers = true, conflicts_with = "world_box")]
    pub index_box: Option<[f64; 6]>,
    /// resample: axis-aligned world box X0,Y0,Z0,X1,Y1,Z1 in mm; the output is aligned
    /// with the world axes.
    #[arg(long, value_parser = list::<f64, 6>, allow_negative_numbers = true)]
    pub world_box: Option<[f64; 6]>,
    /// resample: reconstruction filter.
    #[arg(long, value_parser = choice::<Filter>(), default_value = "trilinear")]
    pub filter: Filter,
    /// gaussian: σ in voxels (one value or SX,SY,SZ).
    #[arg(long, value_delimiter = ',')]
    pub sigma: Option<Vec<f64>>,
    /// median: window side k (odd; at most 5 on the GPU).
    #[arg(long, default_value_t = 3)]
    pub size: usize,
    /// Print the memory plan (host bytes, device bytes against the adapter's limits,
    /// and the slabs the GPU would use) after reading the input, and write nothing.
    #[arg(long)]
    pub dry_run: bool,
}

pub fn run(a: ProcessArgs) -> Result<ExitCode> {
    voxlab::io::check_volume_output("--out", &a.out)?;
    let req = ProcessRequest {
        input: a.load.input(&a.input),
        op: a.op,
        backend: a.backend,
        dims: a.dims,
        spacing: a.spacing.clone(),
        index_box: a.index_box,
        world_box: a.world_box,
        filter: a.filter,
        sigma: a.sigma.clone(),
        size: a.size,
    };
    let term = Terminal::bars();
    if a.dry_run {
        let mut plan = voxlab::jobs::process::plan(&req, &term)?;
        drop(term);
        plan.writes.push(a.out.display().to_string());
        print!("{}", plan.describe());
        return Ok(ExitCode::SUCCESS);
    }
    let p = voxlab::jobs::process::run(&req, &term)?;
    drop(term);
    eprintln!("{}: {:.2} s", p.what, p.seconds);
    let (d, s) = (p.volume.dims(), p.volume.spacing());
    voxlab::io::write_volume(&a.out, &p.volume.into())?;
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
    Ok(ExitCode::SUCCESS)
}
