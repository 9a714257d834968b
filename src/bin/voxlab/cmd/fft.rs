//! `voxlab fft`: the FFTs checked against the exact DFT and timed, through
//! [`voxlab::jobs::fft`].

use crate::cli::choice;
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::jobs::fft;
use voxlab::jobs::BackendSet;
use voxlab::{Error, Result};

/// Arguments of `voxlab fft`.
#[derive(Args)]
pub struct FftArgs {
    /// Shapes, row-major with the last axis fastest: 1024, 256x256, 64x64x64, …
    #[arg(required = true)]
    pub shapes: Vec<String>,
    /// cpu, gpu or all. Without a GPU adapter, `all` says so and runs the CPU.
    #[arg(long, value_parser = choice::<BackendSet>(), default_value = "all")]
    pub backend: BackendSet,
    /// Timed runs per case (after one warm-up run, which is the one checked).
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// Also write every number to this JSON file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Print each shape's memory plan (host bytes, device bytes against the adapter's
    /// limits, and the slabs a GPU transform past one binding would use) and transform
    /// nothing.
    #[arg(long)]
    pub dry_run: bool,
}

pub fn run(a: FftArgs) -> Result<ExitCode> {
    if a.runs == 0 {
        return Err(Error::invalid("--runs", "must be at least 1"));
    }
    if let Some(j) = &a.json {
        voxlab::io::check_output("--json", j, &["json"])?;
    }
    let shapes = a
        .shapes
        .iter()
        .map(|s| fft::parse_shape(s))
        .collect::<Result<Vec<_>>>()?;
    let (ctx, line) = fft::open(a.backend)?;
    if let Some(line) = line {
        println!("{line}");
    }
    if a.dry_run {
        for mut plan in fft::plan(&shapes, a.backend, ctx)? {
            plan.writes
                .extend(a.json.iter().map(|j| j.display().to_string()));
            print!("{}", plan.describe());
        }
        return Ok(ExitCode::SUCCESS);
    }
    println!(
        "forward, unnormalised; {} timed run(s) after 1 warm-up; {} CPU threads",
        a.runs,
        rayon::current_num_threads()
    );
    println!("{}", fft::TABLE_HEADER);
    let report = fft::run(&shapes, a.backend, a.runs, ctx, &mut |c| {
        println!("{}", fft::format_case(c))
    })?;
    if let Some(path) = &a.json {
        let text = serde_json::to_string_pretty(&report)
            .map_err(|e| Error::invalid("FFT report", e.to_string()))?;
        voxlab::io::write_text(path, &text)?;
    }
    if report.passed {
        println!("all within tolerance");
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!("voxlab: an FFT error exceeds its tolerance");
        Ok(ExitCode::from(3))
    }
}
