//! # voxlab
//!
//! Volume rendering and tomography, implemented twice: an exact, rayon-parallel CPU
//! implementation generic over `f32`/`f64` (the f64 instance is the *oracle*), and a
//! mirrored GPU implementation on wgpu + WGSL compute shaders that must match it within
//! a stated tolerance.
//!
//! ## Conventions
//! - Volumes are stored x fastest; voxel `(i, j, k)` has its centre at index
//!   coordinates `(i, j, k)` and owns the cell `[i - 0.5, i + 0.5]` (and so on), so a
//!   volume's box in index space is `[-0.5, n - 0.5]³`.
//! - `Volume::affine` maps index coordinates to world coordinates in millimetres.
//! - Transfer functions are defined over a domain of *mapped* values `Ψ(t) = a·t + b`
//!   of the raw data value `t` (the window/level map).
//! - Images have row 0 at the top; pixel `(col, row)` has its centre at
//!   `(col + 0.5, row + 0.5)` in image coordinates.
//! - Step sizes are in voxels (index-space length); opacity is defined per reference
//!   step `Δs₀ = 1` voxel and corrected as `α' = 1 − (1 − α)^(Δs/Δs₀)`.
//!
//! `docs/conventions.md` states all of them in one place.
//!
//! ## The shape of the crate
//!
//! Dependencies point one way: the leaves ([`error`], [`real`], [`choice`], [`source`], [`json`]) → the model
//! ([`volume`], [`camera`], [`transfer`], [`transfer2d`], [`editor`], [`settings`], [`phantom`],
//! [`ct`], [`frame`], [`multi`]) → [`io`] → [`cpu`] (the oracle) → [`gpu`] (the port)
//! → [`jobs`] (one function per user task: what `voxlab render`, `reconstruct`, `fvr`
//! … do) → [`bench`](mod@bench) → the `voxlab` binary, a thin shell over the jobs.
//!
//! ## Examples
//!
//! What `voxlab render` does, from a typed request:
//!
//! ```
//! use voxlab::jobs::{input::VolumeInput, render, Backend};
//!
//! let mut req = render::RenderRequest::default();
//! req.scene.input = VolumeInput::new("phantom:shepp-logan-modified:32");
//! (req.scene.width, req.scene.height) = (Some(48), Some(40));
//! req.backend = Backend::CpuF32;
//! let out = render::run(&req, &())?; // `&()`: no progress display, never cancelled
//! assert_eq!((out.output.image.width, out.output.image.height), (48, 40));
//! assert!(out.output.total_samples > 0);
//! # Ok::<(), voxlab::Error>(())
//! ```
//!
//! One level down, a scene rendered with the f64 oracle:
//!
//! ```
//! use voxlab::{camera::*, phantom::Phantom, settings::*, transfer::TransferFunction};
//! use voxlab::jobs::render::{render, Backend, Scene};
//!
//! let volume = Phantom::shepp_logan_modified().sample([32; 3])?.into();
//! let camera = Camera::orbit(
//!     glam::DVec3::ZERO,
//!     [256.0; 3],
//!     Orbit::default(),
//!     Projection::Perspective { fov_y_deg: 30.0 },
//!     48,
//!     48,
//! )?;
//! let scene = Scene { volume, transfer: TransferFunction::preset("phantom")?, camera };
//! let out = render(&scene, &RenderSettings::default(), Backend::Cpu)?;
//! assert_eq!((out.image.width, out.image.height, out.image.channels), (48, 48, 4));
//! let path = std::env::temp_dir().join("voxlab-doc-head.png");
//! voxlab::io::write_frame(&path, &out.image, Default::default())?;
//! # Ok::<(), voxlab::Error>(())
//! ```

pub mod bench;
pub mod camera;
pub mod choice;
pub mod cpu;
pub mod ct;
pub mod editor;
pub mod error;
pub mod frame;
pub mod gpu;
pub mod io;
pub mod jobs;
pub mod json;
pub mod metrics;
pub mod multi;
pub mod phantom;
pub mod real;
pub mod settings;
pub mod source;
pub mod transfer;
pub mod transfer2d;
pub mod volume;

pub use error::{Error, Result};
pub use volume::{AnyVolume, Volume, Voxel, VoxelKind};
