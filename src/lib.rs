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
//! ## Example
//!
//! Render the modified Shepp–Logan phantom with the f64 oracle:
//!
//! ```
//! use voxlab::{camera::*, phantom::Phantom, render::*, settings::*, transfer::TransferFunction};
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
//! out.image.save(&std::env::temp_dir().join("voxlab-doc-head.png"), Default::default())?;
//! # Ok::<(), voxlab::Error>(())
//! ```

pub mod accumulate;
pub mod bench;
pub mod camera;
pub mod cpu;
pub mod ct;
pub mod demo;
pub mod error;
pub mod fft_check;
pub mod frame;
pub mod gpu;
pub mod io;
pub mod metrics;
pub mod multi;
pub mod phantom;
pub mod real;
pub mod render;
pub mod settings;
pub mod stereo;
pub mod transfer;
pub mod transfer2d;
pub mod volume;

pub use error::{Error, Result};
pub use volume::{AnyVolume, Volume, Voxel, VoxelKind};
