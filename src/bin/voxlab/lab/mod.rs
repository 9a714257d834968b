//! The lab (`voxlab view`): what the window starts with, and the window itself when
//! the binary is built with the `lab` feature. The window is a thin shell: the view it
//! shows is a [`voxlab::jobs::view::ViewState`], every frame is the render job's, the
//! editors call [`voxlab::editor`], the difference view [`voxlab::metrics`].

#[cfg(feature = "lab")]
mod editors;
#[cfg(feature = "lab")]
mod window;
#[cfg(feature = "lab")]
mod worker;

use std::path::PathBuf;
use voxlab::jobs::view::ViewState;
use voxlab::jobs::Backend;
use voxlab::Result;

/// What the window starts with.
#[cfg_attr(not(feature = "lab"), allow(dead_code))]
pub struct Options {
    pub state: ViewState,
    pub volume: voxlab::AnyVolume,
    pub backend: Backend,
    pub save_state: Option<PathBuf>,
    pub screenshot: Option<PathBuf>,
    pub frames: Option<u64>,
    pub window_screenshot: Option<PathBuf>,
    pub compare: bool,
    /// The difference view's sides A and B (default: the interactive backend against
    /// the CPU f64 oracle).
    pub sides: Option<[Backend; 2]>,
}

/// Opens the window and runs until it closes (or `--frames` frames were drawn).
#[cfg(feature = "lab")]
pub fn run(options: Options) -> Result<()> {
    window::run(options)
}

#[cfg(not(feature = "lab"))]
pub fn run(_: Options) -> Result<()> {
    Err(voxlab::Error::unsupported(
        "view",
        "this build",
        "voxlab was built without the lab (feature `lab`); build it with \
         `cargo build --release --features lab`",
    ))
}
