//! `voxlab info`: a volume or the GPU described, through [`voxlab::jobs::info`].

use crate::cli::LoadArgs;
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::io::write_frame;
use voxlab::{Error, Result};

#[derive(Args)]
pub struct InfoArgs {
    /// Volume file, DICOM directory or phantom:NAME[:SIZE]. Not needed with --gpu.
    pub input: Option<String>,
    #[command(flatten)]
    pub load: LoadArgs,
    /// Also draw the histogram (256 bins, log counts, minimum to maximum from left to
    /// right) into this PNG file.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Number of histogram bins to print.
    #[arg(long, default_value_t = 16)]
    pub bins: usize,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// List the GPU adapters, open the best one, print its limits and features, and
    /// run a small self-test on it.
    #[arg(long)]
    pub gpu: bool,
}

pub fn run(a: InfoArgs) -> Result<ExitCode> {
    if a.gpu {
        let g = voxlab::jobs::info::gpu()?;
        println!("adapters (best first):");
        for a in &g.adapters {
            println!(
                "  {} [{} {}] driver {} {}",
                a.name, a.backend, a.device_type, a.driver, a.driver_info
            );
        }
        println!("\nopened:\n{}", g.opened);
        println!(
            "self-test:    {} values computed on the device match the CPU",
            g.self_test_values
        );
        return Ok(ExitCode::SUCCESS);
    }
    let input = a.input.as_deref().ok_or_else(|| {
        Error::invalid("arguments", "give a volume file or phantom:NAME, or --gpu")
    })?;
    if let Some(p) = &a.plot {
        voxlab::io::check_output("--plot", p, &["png"])?;
    }
    let v = voxlab::jobs::info::run(&a.load.input(input), a.bins, a.plot.is_some())?;
    if let (Some(p), Some(h)) = (&a.plot, &v.plot_histogram) {
        write_frame(p, &h.plot(768, 320)?, Default::default())?;
    }
    if a.json {
        // Through a JSON value, so that the keys come out sorted.
        let j = serde_json::to_value(&v).expect("serialisable");
        println!(
            "{}",
            serde_json::to_string_pretty(&j).expect("serialisable")
        );
        return Ok(ExitCode::SUCCESS);
    }
    let (d, s) = (v.dims, v.spacing_mm);
    println!("{input}");
    println!("  format    {}", v.format);
    println!(
        "  dims      {} × {} × {} ({} voxels, {})",
        d[0],
        d[1],
        d[2],
        d[0] * d[1] * d[2],
        v.kind.name()
    );
    if let Some(f) = v.frames {
        println!(
            "  frames    {} 3-D volumes; this is frame {} (--frame K reads another)",
            f.count, f.described
        );
    }
    println!("  spacing   {:.6} × {:.6} × {:.6} mm", s[0], s[1], s[2]);
    println!("  orient    {}", v.orientation);
    for row in &v.affine_rows[..3] {
        println!(
            "  affine    [{:10.4} {:10.4} {:10.4} | {:10.4}]",
            row[0], row[1], row[2], row[3]
        );
    }
    let (r, nf, h) = (&v.range, &v.non_finite, &v.histogram);
    println!("  range     [{}, {}]", r.min, r.max);
    println!(
        "  NaN/inf   {} NaN, {} +inf, {} -inf",
        nf.nan, nf.pos_inf, nf.neg_inf
    );
    println!("  histogram ({} bins)", h.counts.len());
    let max = h.counts.iter().copied().max().unwrap_or(1).max(1);
    for (b, &c) in h.counts.iter().enumerate() {
        let bar = "#".repeat(((c as f64 / max as f64) * 40.0).round() as usize);
        println!("  {:>12.5} {:>10} {bar}", h.bin_center(b), c);
    }
    if let Some(p) = &a.plot {
        println!("  plot      {}", p.display());
    }
    Ok(ExitCode::SUCCESS)
}
