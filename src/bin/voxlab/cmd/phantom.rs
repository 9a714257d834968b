//! `voxlab phantom`: an analytic phantom to a volume file, through
//! [`voxlab::jobs::phantom::run`].

use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::Result;

#[derive(Args)]
pub struct PhantomArgs {
    /// Phantom and size: NAME, NAME:N or NAME:NX,NY,NZ. Names: shepp-logan,
    /// shepp-logan-modified, marschner-lobb, sphere, spheres, ellipsoid, slab.
    pub spec: String,
    /// Output volume file (.nrrd, .nhdr, .npy, .nii, .nii.gz, .mha or .mhd).
    #[arg(long)]
    pub out: PathBuf,
    /// Voxel type of the file: f32 (the phantom's values), or u8, u16, i16 (each value
    /// times --scale, rounded and saturated), as a scanner would store it.
    #[arg(long = "type", value_name = "TYPE", default_value = "f32")]
    pub voxel_type: String,
    /// Multiplies every value before the conversion to --type (default 1; e.g. 60000
    /// spreads the Shepp–Logan head's [0, 1] over most of u16).
    #[arg(long, default_value_t = 1.0)]
    pub scale: f64,
}

pub fn run(a: PhantomArgs) -> Result<ExitCode> {
    voxlab::io::check_volume_output("--out", &a.out)?;
    let kind = voxlab::jobs::convert::voxel_kind(&a.voxel_type)?;
    let p = voxlab::jobs::phantom::run(&a.spec)?;
    let volume = voxlab::jobs::phantom::quantised(&p, kind, a.scale)?;
    voxlab::io::write_volume(&a.out, &volume)?;
    println!(
        "wrote {} ({} {}×{}×{} {}, spacing {:.4} mm)",
        a.out.display(),
        p.phantom.name,
        p.dims[0],
        p.dims[1],
        p.dims[2],
        a.voxel_type,
        volume.spacing()[0]
    );
    Ok(ExitCode::SUCCESS)
}
