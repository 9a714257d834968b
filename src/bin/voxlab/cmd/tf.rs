//! `voxlab tf`: the transfer-function presets, through [`voxlab::jobs::tf`].

use clap::Args;
use std::process::ExitCode;
use voxlab::Result;

#[derive(Args)]
pub struct TfArgs {
    /// Preset to print as JSON (omit to list them).
    pub name: Option<String>,
}

pub fn run(a: TfArgs) -> Result<ExitCode> {
    match &a.name {
        None => {
            for (n, tf) in voxlab::jobs::tf::list()? {
                println!(
                    "{n:16} domain [{}, {}], {} points",
                    tf.domain[0],
                    tf.domain[1],
                    tf.points.len()
                );
            }
        }
        Some(n) => println!("{}", voxlab::jobs::tf::get(n)?.to_json()),
    }
    Ok(ExitCode::SUCCESS)
}
