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
}

pub fn run(a: PhantomArgs) -> Result<ExitCode> {
    voxlab::io::check_volume_output("--out", &a.out)?;
    let p = voxlab::jobs::phantom::run(&a.spec)?;
    voxlab::io::write_volume(&a.out, &p.volume)?;
    println!(
        "wrote {} ({} {}×{}×{}, spacing {:.4} mm)",
        a.out.display(),
        p.phantom.name,
        p.dims[0],
        p.dims[1],
        p.dims[2],
        p.volume.spacing()[0]
    );
    Ok(ExitCode::SUCCESS)
}
