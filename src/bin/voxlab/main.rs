//! The `voxlab` command line: a thin shell over the library's jobs
//! (`voxlab::jobs`). `cmd/<name>.rs` holds `voxlab <name>`: its arguments and a
//! `run` that calls the job and writes its result; `cli.rs` what they share.

mod cli;
mod cmd;
mod lab;

use clap::{Parser, Subcommand};
use std::process::ExitCode;
use voxlab::{Error, Result};

#[derive(Parser)]
#[command(
    name = "voxlab",
    version,
    about = "Volume rendering and tomography: an exact CPU oracle and a GPU port that must agree with it",
    long_about = "voxlab renders volumes (CT, MRI, analytic phantoms) by ray casting: direct volume \
rendering with transfer functions and shading, maximum/minimum intensity projection, and X-ray \
line integrals. Every algorithm has an exact f64 CPU implementation (the oracle) and an f32 twin.\n\n\
It reads NRRD, NIfTI-1, DICOM (files and series), PVM, VolPack .den, TIFF stacks, MetaImage, .npy and \
raw volumes, and refuses broken files with an error naming the file and the field.\n\n\
Start with `voxlab demo`, which renders a gallery from two embedded real scans and the \
built-in phantoms."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Refuse volumes with more voxels than this before allocating anything (default
    /// 2147483648, or the VOXLAB_MAX_VOXELS environment variable).
    #[arg(long, global = true)]
    max_voxels: Option<usize>,
}

#[derive(Subcommand)]
enum Command {
    /// Render a gallery into a folder (no input needed): two real scans embedded in the
    /// binary (micro-CT of bone, MR head) and the built-in phantoms.
    Demo(cmd::demo::DemoArgs),
    /// Render a volume or a phantom to an image (.png or .npy).
    Render(Box<cmd::render::RenderArgs>),
    /// Render on the CPU f64 oracle and on the GPU and compare: images, a diff heat map,
    /// error statistics and timings. Takes the options of `render`.
    Compare(Box<cmd::compare::CompareArgs>),
    /// Write an analytic phantom sampled on a grid to a volume file (.nrrd, .nhdr, .npy,
    /// .nii, .nii.gz, .mha or .mhd).
    Phantom(cmd::phantom::PhantomArgs),
    /// Describe a volume (format, dimensions, spacing, orientation, type, value range,
    /// NaN/inf counts, histogram; --plot draws it), or the GPU.
    Info(Box<cmd::info::InfoArgs>),
    /// Convert a volume between formats, optionally cropping, resampling and changing
    /// its voxel type on the way (e.g. a DICOM series to NRRD).
    Convert(Box<cmd::convert::ConvertArgs>),
    /// Write one axis-aligned slice of a volume as an image: 8- or 16-bit gray PNG, or
    /// float32 .npy; laid out like the NumPy slice of the (nz, ny, nx) array.
    Slice(Box<cmd::slice::SliceArgs>),
    /// Fourier volume rendering: an X-ray projection (value × mm) from one slice of the
    /// volume's 3-D spectrum (projection-slice theorem), written as .png or .npy.
    Fvr(Box<cmd::fvr::FvrArgs>),
    /// D²VR: render straight from X-ray projections (a stack + geometry JSON, or an
    /// exactly projected phantom) without reconstructing a volume: each sample is
    /// backprojected from the ramp-filtered projections on the fly.
    D2vr(Box<cmd::d2vr::D2vrArgs>),
    /// Check and time the FFTs on random complex data: CPU f64, CPU f32 and the GPU
    /// (Stockham and split-stream), each validated against the exact DFT (when
    /// N·ΣN_axis ≤ 1e9, else the CPU f64 FFT). Prints the relative L2 error, the median
    /// time after a warm-up, GFLOP/s (5·N·log2 N / t) and GB/s (one read and one write
    /// of the array). Exit status 3 when an error exceeds 1e-12 (f64) or 1e-6·log2 N
    /// (f32).
    Fft(cmd::fft::FftArgs),
    /// CT forward projection: exact line integrals of a phantom, or Joseph's method on
    /// a volume (CPU f64/f32 or GPU), in a parallel or cone-beam geometry; writes a
    /// projection stack (.npy, .nrrd) and its geometry JSON.
    Project(Box<cmd::project::ProjectArgs>),
    /// CT reconstruction by filtered backprojection: FBP of a scikit-image sinogram or a
    /// parallel stack (as iradon), FDK of a cone-beam stack (on RTK's grid); CPU f64/f32
    /// or GPU; writes .npy (float32), .nrrd or .png.
    Reconstruct(Box<cmd::reconstruct::ReconstructArgs>),
    /// Benchmark every algorithm on the CPU f64 oracle, CPU f32 and the GPU: warm-up,
    /// timed runs (median, min, max), each result checked against the oracle first;
    /// writes a JSON, Markdown and SVG report (see docs/benchmarking.md). Exit status 3
    /// when a result fails its parity check or a case errors.
    Bench(Box<cmd::bench::BenchArgs>),
    /// Volume processing: resample a box to other dimensions or spacing (any
    /// reconstruction filter), Gaussian smoothing, 3-D median filter, or the
    /// gradient-magnitude field (value per mm); CPU f64/f32 or GPU; writes a float32
    /// volume (.nrrd, .nhdr, .npy, .nii, .nii.gz, .mha, .mhd).
    Process(Box<cmd::process::ProcessArgs>),
    /// Regular, direct and spectral adaptive sampling of one scene side by side: samples
    /// per pixel, time per frame and image error against regular sampling (Markdown and
    /// JSON), the images and the samples-per-ray images.
    Adaptive(Box<cmd::adaptive::AdaptiveArgs>),
    /// List the built-in transfer-function presets, or print one as JSON.
    Tf(cmd::tf::TfArgs),
    /// The interactive lab: a window that renders INPUT (default: an embedded micro-CT
    /// of bone) on the GPU while you orbit, edit the transfer functions (1-D and 2-D,
    /// over the volume's histograms) and change every render setting, with the CPU
    /// oracle and the difference beside it. Keys: H.
    View(Box<cmd::view::ViewArgs>),
}

fn main() -> ExitCode {
    // Die quietly when stdout is a closed pipe (`voxlab info … | head`), as command-line
    // tools do, instead of failing on the write.
    #[cfg(unix)]
    // SAFETY: restores the default disposition of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // Ctrl-C, kill and a closed terminal remove the temporary files of unfinished
    // writes (docs/io.md).
    voxlab::io::remove_temp_files_on_signals();
    let cli = Cli::parse();
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            report_error(&e);
            ExitCode::FAILURE
        }
    }
}

/// How the command line says an error.
pub fn report_error(e: &Error) {
    // Messages quote file contents: no byte of them reaches the terminal raw.
    eprintln!(
        "voxlab: error: {}",
        voxlab::error::escape_controls(&e.to_string())
    );
}

/// The voxel limit from `--max-voxels` or `VOXLAB_MAX_VOXELS`.
fn set_max_voxels(flag: Option<usize>) -> Result<()> {
    let limit = match flag {
        Some(n) => Some(n),
        None => match std::env::var("VOXLAB_MAX_VOXELS") {
            Ok(s) => Some(s.trim().parse::<usize>().map_err(|_| {
                Error::invalid("VOXLAB_MAX_VOXELS", format!("'{s}' is not a whole number"))
            })?),
            Err(_) => None,
        },
    };
    if let Some(n) = limit {
        if n == 0 {
            return Err(Error::invalid("--max-voxels", "must be at least 1"));
        }
        voxlab::volume::set_max_voxels(n);
    }
    Ok(())
}

fn run(cli: Cli) -> Result<ExitCode> {
    set_max_voxels(cli.max_voxels)?;
    match cli.command {
        Command::Demo(a) => cmd::demo::run(a),
        Command::Render(a) => cmd::render::run(*a),
        Command::Compare(a) => cmd::compare::run(*a),
        Command::Phantom(a) => cmd::phantom::run(a),
        Command::Info(a) => cmd::info::run(*a),
        Command::Convert(a) => cmd::convert::run(*a),
        Command::Slice(a) => cmd::slice::run(*a),
        Command::Fvr(a) => cmd::fvr::run(*a),
        Command::D2vr(a) => cmd::d2vr::run(*a),
        Command::Fft(a) => cmd::fft::run(a),
        Command::Project(a) => cmd::project::run(*a),
        Command::Reconstruct(a) => cmd::reconstruct::run(*a),
        Command::Bench(a) => cmd::bench::run(*a),
        Command::Process(a) => cmd::process::run(*a),
        Command::Adaptive(a) => cmd::adaptive::run(*a),
        Command::Tf(a) => cmd::tf::run(a),
        Command::View(a) => cmd::view::run(*a),
    }
}
