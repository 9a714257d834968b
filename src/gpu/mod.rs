//! The GPU side: wgpu on Vulkan, Metal or DX12 (never the GL backend), with WGSL
//! compute shaders under `shaders/`.
//!
//! `context` finds an adapter, opens a device with the adapter's own limits, and turns
//! every failure into a typed [`crate::Error`]. `probe` is the smallest end-to-end
//! check that a device really computes: upload, dispatch, read back, compare. `fft`
//! is the power-of-two FFT (split-stream and Stockham variants); `fvr` the Fourier
//! volume rendering slice and its inverse FFT; `project` Joseph's CT forward projector.

pub mod adaptive;
pub mod clipmesh;
pub mod context;
pub mod d2vr;
pub mod fbp;
pub mod fft;
pub mod fvr;
pub mod gradient;
pub mod multi;
pub mod parker;
pub mod preintegrate;
pub mod probe;
pub mod process;
pub mod project;
pub mod ramp;
pub mod raycast;
pub mod skip;
pub mod tricubic;

pub use context::{AdapterSummary, GpuContext};
