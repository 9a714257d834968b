//! `voxlab compare`: the oracle and the GPU side by side, through
//! [`voxlab::jobs::compare::run`].

use super::render::{AccelArgs, SceneArgs};
use crate::cli::Terminal;
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::jobs::compare::CompareRequest;
use voxlab::Result;

#[derive(Args)]
pub struct CompareArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Folder for cpu.png, gpu.png, diff.png (|Δ| heat map with its scale) and stats.json.
    #[arg(long, default_value = "voxlab-compare")]
    pub out_dir: PathBuf,
    /// Fail (exit status 3) when any element differs by more than this.
    #[arg(long)]
    pub max_abs: Option<f64>,
    /// Fail (exit status 3) when the RMS difference exceeds this.
    #[arg(long)]
    pub rmse: Option<f64>,
    #[command(flatten)]
    pub accel: AccelArgs,
    /// Print the memory plans of the oracle's render and the GPU's (host and device
    /// bytes against the adapter's limits, and the bricks a volume past the 3-D texture
    /// limit is cut into) after loading the input, and render and write nothing.
    #[arg(long)]
    pub dry_run: bool,
}

/// Renders on the oracle and the GPU, writes the evidence, prints the numbers; exit
/// status 3 when a given tolerance is exceeded.
pub fn run(c: CompareArgs) -> Result<ExitCode> {
    voxlab::io::check_output_dir("--out-dir", &c.out_dir)?;
    let req = CompareRequest {
        scene: c.scene.request(&c.accel)?,
        max_abs: c.max_abs,
        rmse: c.rmse,
    };
    if c.dry_run {
        for mut plan in voxlab::jobs::compare::plan(&req, &Terminal::bars())? {
            plan.writes.push(format!(
                "{}/{{cpu,gpu,diff}}.png and stats.json",
                c.out_dir.display()
            ));
            print!("{}", plan.describe());
        }
        return Ok(ExitCode::SUCCESS);
    }
    let term = Terminal::bars();
    let cmp = voxlab::jobs::compare::run(&req, &term)?;
    drop(term);
    let input = match (&c.scene.input, &c.scene.state) {
        (Some(i), _) => i.clone(),
        (None, Some(state)) => format!("the input of {}", state.display()),
        (None, None) => String::new(),
    };
    cmp.write_evidence(&c.out_dir, &input, c.max_abs, c.rmse)?;
    let (s, t) = (&cmp.report.stats, &cmp.gpu_timings);
    println!("oracle  cpu f64, {:.3} s", cmp.cpu_seconds);
    println!(
        "port    {}, {:.3} s end to end (set-up {:.3}, upload {:.3}, prepare {:.3}, kernel {:.3}{}, readback {:.3})",
        cmp.adapter,
        t.total,
        t.setup,
        t.upload,
        t.prepare,
        t.kernel,
        if t.kernel_from_timestamps { " by timestamps" } else { " wall" },
        t.readback
    );
    println!(
        "error   max |Δ| {:.3e}, rmse {:.3e}, rel L2 {:.3e}, PSNR {:.1} dB, over tolerance {}/{}",
        s.max_abs, s.rmse, s.rel_l2, s.psnr_db, s.n_over, s.n
    );
    println!(
        "wrote   {}/{{cpu,gpu,diff}}.png and stats.json",
        c.out_dir.display()
    );
    if cmp.report.passed {
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!("voxlab: tolerance exceeded: {}", cmp.report.message);
        Ok(ExitCode::from(3))
    }
}
