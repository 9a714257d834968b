//! `voxlab fvr`: Fourier volume rendering to an image, through
//! [`voxlab::jobs::fvr::run`].

use crate::cli::{choice, LoadArgs, Terminal, ViewArgs};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::cpu::fvr::Kernel;
use voxlab::io::{check_output, write_frame, PngOptions};
use voxlab::jobs::fvr::FvrRequest;
use voxlab::jobs::Backend;
use voxlab::Result;

#[derive(Args)]
pub struct FvrArgs {
    /// A volume file or phantom:NAME[:N | :NX,NY,NZ] (isotropic voxels only).
    pub input: String,
    #[command(flatten)]
    pub load: LoadArgs,
    /// Output image: .png (gray) or .npy (float32, value × mm).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub view: ViewArgs,
    /// How the spectrum is sampled on the slice (dirichlet: exact, small volumes only).
    #[arg(long, value_parser = choice::<Kernel>(), default_value = "lanczos3")]
    pub kernel: Kernel,
    /// Oversampling factor: the volume is zero-padded to a cube of side
    /// padding × max(dims), rounded up to even.
    #[arg(long, default_value_t = 2)]
    pub padding: usize,
    /// Divide the image by the kernel's spatial transfer (undo its apodisation).
    #[arg(long)]
    pub deapodize: bool,
    /// Who computes: cpu (f64 throughout), cpu-f32 (the f64 spectrum rounded to
    /// complex f32, then slice and inverse 2-D FFT in f32), gpu: the padded volume
    /// is uploaded as f32 and its 3-D spectrum made on the GPU, then the slice
    /// (every kernel, dirichlet included) and the inverse 2-D FFT run there too (any
    /// padded side: Bluestein's algorithm where it is not a power of two). auto: the GPU
    /// when a hardware adapter exists, else cpu.
    #[arg(long, value_parser = choice::<Backend>(), default_value = "cpu")]
    pub backend: Backend,
    /// Write 16-bit PNG.
    #[arg(long)]
    pub sixteen_bit: bool,
    /// Print the memory plan (host bytes, device bytes against the adapter's limits,
    /// and the slabs the GPU would bind the spectrum in) after reading the volume, and
    /// transform and write nothing.
    #[arg(long)]
    pub dry_run: bool,
}

pub fn run(a: FvrArgs) -> Result<ExitCode> {
    check_output("output file", &a.out, &["png", "npy"])?;
    let req = FvrRequest {
        input: a.load.input(&a.input),
        view: a.view.request(),
        kernel: a.kernel,
        padding: a.padding,
        deapodize: a.deapodize,
        backend: a.backend,
    };
    if a.dry_run {
        let mut plan = voxlab::jobs::fvr::plan(&req, &Terminal::lines())?;
        plan.writes.push(a.out.display().to_string());
        print!("{}", plan.describe());
        return Ok(ExitCode::SUCCESS);
    }
    let image = voxlab::jobs::fvr::run(&req, &Terminal::lines())?;
    let frame = &image.frame;
    write_frame(
        &a.out,
        frame,
        PngOptions {
            sixteen_bit: a.sixteen_bit,
            range: None,
        },
    )?;
    println!(
        "wrote {} ({}×{}, FVR X-ray, {} kernel, padding {}{})",
        a.out.display(),
        frame.width,
        frame.height,
        a.kernel.name(),
        a.padding,
        if a.deapodize { ", de-apodized" } else { "" }
    );
    Ok(ExitCode::SUCCESS)
}
