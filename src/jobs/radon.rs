//! The Radon transform of a 2-D image in memory, as scikit-image's
//! `skimage.transform.radon` (the Python package's `voxlab.transform.radon`). The
//! algorithm is [`crate::cpu::radon`].

use super::{Backend, Progress};
use crate::cpu::radon::{outside_circle, radon_square, square, Square};

use crate::error::{Error, Result};
use crate::real::Real;

/// The message scikit-image warns with when `circle` is set and the image is not zero
/// outside its inscribed circle.
pub const OUTSIDE_CIRCLE: &str =
    "Radon transform: image must be zero outside the reconstruction circle";

/// A sinogram: `(bins, angles)` row-major (bin, then angle), the image's precision.
#[derive(Clone, Debug)]
pub struct Sinogram<R> {
    pub bins: usize,
    pub angles: usize,
    pub data: Vec<R>,
}

/// The sinogram of the row-major `rows × cols` image, one angle per inverse map
/// ([`crate::cpu::radon::rotation`]; pass the caller's own matrices to reproduce its
/// rounding),
/// with scikit-image's `circle` rule (crop to the inscribed square, warning through
/// `progress` when the image is not zero outside the circle; otherwise pad to the
/// circumscribed square). Runs in the image's precision `R` on `cpu` or `cpu-f32`
/// (the caller picks `R`).
///
/// # Errors
/// An empty image or a data length that is not `rows × cols`; a backend other than
/// `cpu`/`cpu-f32` ([`Error::Unsupported`]); [`Error::Cancelled`].
pub fn radon<R: Real>(
    image: &[R],
    rows: usize,
    cols: usize,
    maps: &[[f64; 6]],
    circle: bool,
    backend: Backend,
    progress: &dyn Progress,
) -> Result<Sinogram<R>> {
    backend.require("the Radon transform", &[Backend::Cpu, Backend::CpuF32])?;
    if rows == 0 || cols == 0 {
        return Err(Error::invalid("image", "the image is empty"));
    }
    if image.len() != rows * cols {
        return Err(Error::invalid(
            "image",
            format!("{} values for a {rows} × {cols} image", image.len()),
        ));
    }
    if circle && outside_circle(image, rows, cols) {
        progress.warn(OUTSIDE_CIRCLE);
    }
    let sq = Square::of(rows, cols, circle);
    let img = square(image, rows, cols, sq);
    progress.begin("Radon transform", "angle", maps.len() as u64);
    if progress.cancelled() {
        return Err(Error::Cancelled);
    }
    let data = radon_square(&img, sq.side, maps);
    progress.end(0.0);
    Ok(Sinogram {
        bins: sq.side,
        angles: maps.len(),
        data,
    })
}
