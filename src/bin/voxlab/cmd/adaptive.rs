//! `voxlab adaptive`: regular, direct and spectral adaptive sampling side by side,
//! through [`voxlab::jobs::adaptive::run`].

use crate::cli::{choice, LoadArgs, Terminal};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::jobs::adaptive::AdaptiveRequest;
use voxlab::jobs::Backend;
use voxlab::Result;

/// Arguments of `voxlab adaptive`.
#[derive(Args)]
pub struct AdaptiveArgs {
    /// Volume file (any format `info` reads) or phantom:NAME[:SIZE]; default: the
    /// modified Shepp–Logan phantom.
    pub input: Option<String>,
    #[command(flatten)]
    pub load: LoadArgs,
    /// Transfer function: a preset name or a JSON file. Default: a medical-style
    /// function with a sharp opacity ramp (at 0.25 for phantoms, at 60 % of the value
    /// range for files).
    #[arg(long)]
    pub tf: Option<String>,
    /// Move the transfer function along the raw value axis by this much (through the
    /// window map, as a user browsing structures would; the spectrum is not recomputed).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub shift: f64,
    /// Folder for the images, table.md and table.json.
    #[arg(long)]
    pub out: PathBuf,
    /// cpu (f64 oracle), cpu-f32, gpu or auto.
    #[arg(long, value_parser = choice::<Backend>(), default_value = "cpu-f32")]
    pub backend: Backend,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 256)]
    pub size: usize,
    /// Orbit camera azimuth and elevation in degrees.
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true)]
    pub azimuth: f64,
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    pub elevation: f64,
    /// Regular step and smallest adaptive step T_min (voxels).
    #[arg(long, default_value_t = 0.5)]
    pub step: f64,
    /// Largest step T_max (voxels).
    #[arg(long, default_value_t = 8.0)]
    pub t_max: f64,
    /// Oversampling factor over the estimated Nyquist rate.
    #[arg(long, default_value_t = 2.0)]
    pub oversampling: f64,
    /// Fraction of the spectrum's energy below the cut-off frequency.
    #[arg(long, default_value_t = 0.99)]
    pub energy: f64,
    /// Block edge of direct sampling (voxels).
    #[arg(long, default_value_t = 8)]
    pub block: usize,
    /// Timed renders per sampling (the median is reported).
    #[arg(long, default_value_t = 3)]
    pub runs: usize,
    /// Print the memory plan (host bytes, and on the GPU device bytes against the
    /// adapter's limits) after loading the input and checking the request, and render
    /// and write nothing.
    #[arg(long)]
    pub dry_run: bool,
}

/// Runs the comparison and writes the report into `a.out`.
pub fn run(a: AdaptiveArgs) -> Result<ExitCode> {
    voxlab::io::check_output_dir("--out", &a.out)?;
    let input = a
        .input
        .clone()
        .unwrap_or_else(|| "phantom:shepp-logan-modified".to_string());
    let req = AdaptiveRequest {
        input: a.load.input(&input),
        tf: a.tf.clone(),
        shift: a.shift,
        backend: a.backend,
        size: a.size,
        azimuth: a.azimuth,
        elevation: a.elevation,
        step: a.step,
        t_max: a.t_max,
        oversampling: a.oversampling,
        energy: a.energy,
        block: a.block,
        runs: a.runs,
    };
    if a.dry_run {
        let mut plan = voxlab::jobs::adaptive::plan(&req, &Terminal::bars())?;
        let dir = a.out.display();
        plan.writes.push(format!(
            "{dir}/{{regular,direct,adaptive}}.png, {dir}/samples-*.png, table.md and table.json"
        ));
        print!("{}", plan.describe());
        return Ok(ExitCode::SUCCESS);
    }
    let term = Terminal::bars();
    let c = voxlab::jobs::adaptive::run(&req, &term)?;
    drop(term);
    for row in &c.report.rows {
        eprintln!(
            "{:>8}: {:.3} s per frame, {} samples",
            row.sampling.name(),
            row.seconds_per_frame,
            row.total_samples
        );
    }
    c.write_images(&a.out)?;
    let md = c.write_tables(&a.out)?;
    print!("{md}");
    Ok(ExitCode::SUCCESS)
}
