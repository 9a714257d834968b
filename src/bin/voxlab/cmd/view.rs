//! `voxlab view`: the interactive lab, a window over the render job
//! ([`voxlab::jobs::view::ViewState`], `crate::lab`).

use crate::cli::{choice, LoadArgs, Terminal};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::io::check_output;
use voxlab::jobs::view::ViewState;
use voxlab::jobs::Backend;
use voxlab::Result;

/// The scan `voxlab view` opens without INPUT.
pub const DEFAULT_INPUT: &str = "embedded:microct-bone";

#[derive(Args)]
pub struct ViewArgs {
    /// A volume (any file `voxlab render` reads, a DICOM directory, phantom:NAME[:N])
    /// or an embedded scan (embedded:microct-bone, embedded:mr-brain). Default: the
    /// embedded micro-CT of bone.
    pub input: Option<String>,
    #[command(flatten)]
    pub load: LoadArgs,
    /// Start from a view state written by --save-state or the lab's Save state
    /// (replaces INPUT and the image size).
    #[arg(long, conflicts_with = "input")]
    pub state: Option<PathBuf>,
    /// Who renders the interactive view: gpu (the WGSL port, sharing the window's
    /// device), cpu-f32 or cpu (the f64 oracle; slow, for small volumes).
    #[arg(long, value_parser = choice::<Backend>(), default_value = "gpu")]
    pub backend: Backend,
    /// Image size of the 3-D view in pixels.
    #[arg(long, default_value_t = 512)]
    pub width: usize,
    #[arg(long, default_value_t = 512)]
    pub height: usize,
    /// Where Save state (key S) writes, and the state written on exit when given.
    #[arg(long)]
    pub save_state: Option<PathBuf>,
    /// Where Screenshot (key P) writes the 3-D view, at the render's resolution (.png,
    /// or .npy for the float32 RGBA values); written on exit when given.
    #[arg(long)]
    pub screenshot: Option<PathBuf>,
    /// Exit after this many frames (for scripts and tests); the state and the
    /// screenshots are written first (with --compare, once the reference is done).
    #[arg(long)]
    pub frames: Option<u64>,
    /// Write a PNG of the whole window (panels and editors included) on exit.
    #[arg(long)]
    pub window_screenshot: Option<PathBuf>,
    /// Open on the difference view: side A (the interactive frame) against side B
    /// (the CPU oracle), or the sides --sides names.
    #[arg(long)]
    pub compare: bool,
    /// The difference view's two sides, A,B: any two of gpu, cpu-f32 and cpu (B is the
    /// reference; a side on the interactive backend takes the interactive frame).
    /// Default: the interactive backend,cpu.
    #[arg(long, value_name = "A,B", value_delimiter = ',', value_parser = choice::<Backend>())]
    pub sides: Vec<Backend>,
}

pub fn run(a: ViewArgs) -> Result<ExitCode> {
    let sides = match a.sides.as_slice() {
        [] => None,
        [x, y] => Some([*x, *y]),
        other => {
            return Err(voxlab::Error::invalid(
                "--sides",
                format!(
                    "takes two backends A,B (such as gpu,cpu), not {}",
                    other.len()
                ),
            ))
        }
    };
    if let Some(p) = &a.screenshot {
        check_output("--screenshot", p, &["png", "npy"])?;
    }
    if let Some(p) = &a.save_state {
        check_output("--save-state", p, &["json"])?;
    }
    if let Some(p) = &a.window_screenshot {
        check_output("--window-screenshot", p, &["png"])?;
    }
    let term = Terminal::bars();
    let (state, volume) = match &a.state {
        Some(path) => {
            let state = ViewState::load(path)?;
            let volume = state.input.load(&term)?;
            (state, volume)
        }
        None => {
            let input = a.load.input(a.input.as_deref().unwrap_or(DEFAULT_INPUT));
            let volume = input.load(&term)?;
            (ViewState::new(input, &volume, a.width, a.height)?, volume)
        }
    };
    drop(term);
    let options = crate::lab::Options {
        state,
        volume,
        backend: a.backend,
        save_state: a.save_state,
        screenshot: a.screenshot,
        frames: a.frames,
        window_screenshot: a.window_screenshot,
        compare: a.compare,
        sides,
    };
    crate::lab::run(options)?;
    Ok(ExitCode::SUCCESS)
}
