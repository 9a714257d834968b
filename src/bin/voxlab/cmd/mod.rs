//! One file per subcommand: its arguments and a `run` that maps them to a library job
//! (`voxlab::jobs`), then the job's result to files and messages.

pub mod adaptive;
pub mod bench;
pub mod compare;
pub mod convert;
pub mod d2vr;
pub mod demo;
pub mod fft;
pub mod fvr;
pub mod info;
pub mod phantom;
pub mod process;
pub mod project;
pub mod reconstruct;
pub mod render;
pub mod slice;
pub mod tf;
pub mod view;
