//! `voxlab demo`: the gallery, through [`voxlab::jobs::demo::run`].

use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::jobs::render::{Backend, Renderer};
use voxlab::Result;

#[derive(Args)]
pub struct DemoArgs {
    /// Folder to write the pictures, index.html and README.md into.
    #[arg(long, default_value = "voxlab-demo")]
    pub out: PathBuf,
}

pub fn run(a: DemoArgs) -> Result<ExitCode> {
    voxlab::io::check_output_dir("--out", &a.out)?;
    let renderer = Renderer::new(Backend::Auto)?;
    eprintln!(
        "voxlab demo: rendering a gallery of embedded real scans and built-in phantoms on {}…",
        renderer.describe()
    );
    if let Some(why) = renderer.fallback_reason() {
        eprintln!("  (not using a GPU: {why})");
    }
    let t = std::time::Instant::now();
    let items = voxlab::jobs::demo::run(&a.out, &renderer, &|item, n, total| {
        eprintln!(
            "  [{n}/{total}] {} ({:.1} s)",
            item.file.display(),
            item.seconds
        );
    })?;
    println!(
        "wrote {} pictures to {} in {:.1} s; open {} to see them",
        items.len(),
        a.out.display(),
        t.elapsed().as_secs_f64(),
        a.out.join("index.html").display()
    );
    Ok(ExitCode::SUCCESS)
}
