//! `voxlab convert`: a volume to another format (cropped, resampled, retyped on the
//! way), through [`voxlab::jobs::convert::run`].

use crate::cli::{choice, list, LoadArgs, Terminal};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::jobs::convert::ConvertRequest;
use voxlab::settings::Filter;
use voxlab::Result;

#[derive(Args)]
pub struct ConvertArgs {
    /// Input volume (any format `info` reads, or a phantom).
    pub input: String,
    /// Output volume: .nrrd, .nhdr, .npy, .nii, .nii.gz, .mha or .mhd.
    pub output: PathBuf,
    #[command(flatten)]
    pub load: LoadArgs,
    /// Keep only the voxels X0..X1, Y0..Y1, Z0..Z1 (index ranges, end exclusive),
    /// given as X0,Y0,Z0,X1,Y1,Z1. The world position of every kept voxel is unchanged.
    #[arg(long, value_parser = list::<usize, 6>)]
    pub crop: Option<[usize; 6]>,
    /// Resample (after cropping) to NX,NY,NZ voxels over the same box, with --filter.
    #[arg(long, value_parser = list::<usize, 3>, conflicts_with = "spacing")]
    pub resize: Option<[usize; 3]>,
    /// Resample (after cropping) to this voxel spacing in mm (one value, or SX,SY,SZ),
    /// over the same box, with --filter.
    #[arg(long, value_delimiter = ',')]
    pub spacing: Option<Vec<f64>>,
    /// Reconstruction filter for resampling (in f64, through the CPU oracle's filters).
    #[arg(long, value_parser = choice::<Filter>(), default_value = "trilinear")]
    pub filter: Filter,
    /// Voxel type of the output: u8, u16, i16 or f32 (values rounded and clamped into
    /// integer types). Default: the input's type, or f32 after resampling.
    #[arg(long = "type")]
    pub voxel_type: Option<String>,
    /// Multiply every value by S (finite, positive) before the type conversion:
    /// round(v·S), saturated, for an integer --type (a [0, 1] volume to u16 with
    /// --scale 65535); the input's type when --type is not given.
    #[arg(long, value_name = "S")]
    pub scale: Option<f64>,
    /// Replace NaN and infinite voxels as rendering does (NaN and -inf by the smallest
    /// finite value, +inf by the largest). Without it, convert keeps every value: a
    /// float output keeps them, and an integer --type or resampling is refused.
    #[arg(long)]
    pub replace_non_finite: bool,
}

pub fn run(c: ConvertArgs) -> Result<ExitCode> {
    voxlab::io::check_volume_output("output file", &c.output)?;
    let req = ConvertRequest {
        input: c.load.input(&c.input),
        crop: c.crop,
        resize: c.resize,
        spacing: c.spacing.clone(),
        filter: c.filter,
        voxel_type: c.voxel_type.clone(),
        replace_non_finite: c.replace_non_finite,
        scale: c.scale,
    };
    let term = Terminal::bars();
    let vol = voxlab::jobs::convert::run(&req, &term)?;
    drop(term);
    voxlab::io::write_volume(&c.output, &vol)?;
    let (d, s) = (vol.dims(), vol.spacing());
    println!(
        "wrote {} ({}×{}×{} {}, spacing {:.4} × {:.4} × {:.4} mm)",
        c.output.display(),
        d[0],
        d[1],
        d[2],
        vol.kind().name(),
        s[0],
        s[1],
        s[2]
    );
    Ok(ExitCode::SUCCESS)
}
