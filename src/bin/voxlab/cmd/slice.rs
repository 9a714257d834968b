//! `voxlab slice`: one axis-aligned slice as an image, through
//! [`voxlab::jobs::slice::run`].

use crate::cli::{LoadArgs, Terminal};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::io::{write_frame, PngOptions};
use voxlab::jobs::slice::SliceRequest;
use voxlab::Result;

#[derive(Args)]
pub struct SliceArgs {
    /// Input volume (any format `info` reads, or a phantom).
    pub input: String,
    #[command(flatten)]
    pub load: LoadArgs,
    /// The axis across which to cut: z gives a[k, :, :], y a[:, j, :], x a[:, :, i].
    #[arg(long, default_value = "z")]
    pub axis: String,
    /// Slice index along the axis (default: the middle slice).
    #[arg(long)]
    pub index: Option<usize>,
    /// Output image: .png (gray) or .npy (float32, raw values).
    #[arg(long)]
    pub out: PathBuf,
    /// Write 16-bit PNG.
    #[arg(long)]
    pub sixteen_bit: bool,
    /// Gray-scale window width in data units (with --level); default: the volume's
    /// whole value range, the same for every slice.
    #[arg(long, requires = "level", allow_negative_numbers = true)]
    pub window: Option<f64>,
    /// Gray-scale window centre in data units (with --window).
    #[arg(long, requires = "window", allow_negative_numbers = true)]
    pub level: Option<f64>,
}

pub fn run(a: SliceArgs) -> Result<ExitCode> {
    voxlab::io::check_output("--out", &a.out, &["png", "npy"])?;
    let req = SliceRequest {
        input: a.load.input(&a.input),
        axis: a.axis.clone(),
        index: a.index,
        window: a.window.zip(a.level).map(|(w, l)| [w, l]),
    };
    let s = voxlab::jobs::slice::run(&req, &Terminal::bars())?;
    write_frame(
        &a.out,
        &s.frame,
        PngOptions {
            sixteen_bit: a.sixteen_bit,
            range: Some(s.range),
        },
    )?;
    println!(
        "wrote {} ({}×{}, axis {} index {}, gray {} → black, {} → white)",
        a.out.display(),
        s.frame.width,
        s.frame.height,
        a.axis,
        s.index,
        s.range.0,
        s.range.1
    );
    Ok(ExitCode::SUCCESS)
}
