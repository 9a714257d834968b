//! The CPU oracle: exact, rayon-parallel implementations generic over `f32`/`f64`.
//!
//! One file per algorithm family; the GPU port in `crate::gpu` mirrors the per-element
//! functions by name. The f64 instance is the oracle (its output never depends on the
//! thread count); the f32 instance is the fair baseline for speed comparisons.

pub mod adaptive;
pub mod clipmesh;
pub mod composite;
pub mod d2vr;
pub mod dft;
pub mod fbp;
pub mod fft;
pub mod field;
pub mod filter;
pub mod fvr;
pub mod gradient;
pub mod grid;
pub mod iterative;
pub mod jitter;
pub mod march;
pub mod modes;
pub mod multi;
pub mod parker;
pub mod preintegrate;
pub mod process;
pub mod project;
pub mod radon;
pub mod ramp;
pub mod raycast;
pub mod shade;
pub mod skip;
pub mod tricubic;
