//! scikit-image's Radon transform and its inverse on images in memory:
//! [`radon`] as `skimage.transform.radon` and [`iradon`] as
//! `skimage.transform.iradon` (the Python package's `voxlab.transform.radon` and
//! `iradon`). The algorithms are [`crate::cpu::radon`] (the oracle) and
//! [`crate::gpu::radon`] (the port); the ramp filters are [`crate::cpu::ramp`]'s.

use super::{cancellable, Backend, Engine, Progress};
use crate::cpu::radon::{
    iradon_backproject, outside_circle, radon_square, spline_curvatures, square, Interpolation,
    Square, CUBIC_MIN_BINS,
};
use crate::cpu::ramp::{filter_projections, FilterMethod, RampFilter};
use crate::ct::{Geometry, Projections};
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
/// (the caller picks `R`), or in f32 on the GPU (`gpu`, and `auto` with a hardware
/// GPU; the sinogram is then rounded f32 values in `R`).
///
/// # Errors
/// An empty image or a data length that is not `rows × cols`; no GPU for `gpu`;
/// [`Error::Cancelled`].
pub fn radon<R: Real>(
    image: &[R],
    rows: usize,
    cols: usize,
    maps: &[[f64; 6]],
    circle: bool,
    backend: Backend,
    progress: &dyn Progress,
) -> Result<Sinogram<R>> {
    backend.require(
        "the Radon transform",
        &[Backend::Cpu, Backend::CpuF32, Backend::Gpu],
    )?;
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
    let engine = Engine::open(backend)?;
    let data = match engine.gpu() {
        Some(ctx) => {
            let img: Vec<f32> = img.iter().map(|v| v.f64() as f32).collect();
            crate::gpu::radon::radon_square(ctx, &img, sq.side, maps)?
                .into_iter()
                .map(|v| R::of(v as f64))
                .collect()
        }
        None => radon_square(&img, sq.side, maps),
    };
    progress.end(0.0);
    Ok(Sinogram {
        bins: sq.side,
        angles: maps.len(),
        data,
    })
}

/// scikit-image's `iradon` options beside the sinogram and its angles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IradonOptions {
    /// The output image's side (`output_size`).
    pub output_size: usize,
    /// The ramp filter (`filter_name`; [`RampFilter::None`] for `None`).
    pub filter: RampFilter,
    /// How filtered projections are read between bins (`interpolation`).
    pub interpolation: Interpolation,
    /// `circle`: the sinogram covers the inscribed circle only (it is padded to the
    /// circle's diagonal first) and the image is zeroed outside that circle.
    pub circle: bool,
}

/// An image of [`iradon`]: `size × size`, row-major, row 0 at the top.
#[derive(Clone, Debug)]
pub struct IradonImage<A> {
    pub size: usize,
    pub data: Vec<A>,
    /// The backend that computed it (`auto` resolved).
    pub backend: Backend,
}

/// Filtered backprojection of a `(bins, angles)` sinogram (row-major: bin, then angle,
/// as scikit-image holds it) taken at `theta` (degrees), step for step as scikit-image's
/// `iradon`: padded to `⌈√2·bins⌉` bins when `circle` (`_sinogram_circle_to_square`),
/// filtered by [`crate::cpu::ramp`] (its padding and windows), then backprojected
/// pixel by pixel with `t = y·cos θ − x·sin θ` read by the interpolation
/// ([`crate::cpu::radon::iradon_backproject`]), masked and scaled by `π/(2A)`.
///
/// `trig` gives each angle's `(cos θ, sin θ)` as the caller computed them (numpy's,
/// to reproduce scikit-image's `t` and so its nearest-bin choices bit for bit); `None`
/// computes them in f64 from `theta`. On `cpu` the filter, `t` and the interpolation
/// run in f64 and the sum in `A` (scikit-image: the sinogram's float type, so f32 for
/// a float32 sinogram); `cpu-f32` and `gpu` run in f32 throughout and return f32
/// values in `A`.
///
/// # Errors
/// An empty sinogram, a length that is not `bins × angles`, a `trig` of another
/// length, an `output_size` of 0 or past the voxel limit, non-finite values, cubic
/// interpolation of fewer than 4 (padded) bins; no GPU for `gpu`;
/// [`Error::Cancelled`].
#[allow(clippy::too_many_arguments)]
pub fn iradon<A: Real>(
    sinogram: &[f64],
    bins: usize,
    theta: &[f64],
    trig: Option<&[(f64, f64)]>,
    options: &IradonOptions,
    backend: Backend,
    progress: &dyn Progress,
) -> Result<IradonImage<A>> {
    let angles = theta.len();
    if bins == 0 || angles == 0 {
        return Err(Error::invalid(
            "sinogram",
            format!("{bins} bins × {angles} angles is empty"),
        ));
    }
    if sinogram.len() != bins * angles {
        return Err(Error::invalid(
            "sinogram",
            format!(
                "{} values for {bins} bins × {angles} angles",
                sinogram.len()
            ),
        ));
    }
    let size = options.output_size;
    if size == 0 {
        return Err(Error::invalid("output_size", "must be at least 1"));
    }
    crate::volume::check_dims([size, size, 1])?;
    let trig: Vec<(f64, f64)> = match trig {
        Some(t) if t.len() != angles => {
            return Err(Error::invalid(
                "angles",
                format!("{} cosines and sines for {angles} angles", t.len()),
            ))
        }
        Some(t) => t.to_vec(),
        None => theta
            .iter()
            .map(|d| {
                let a = d.to_radians();
                (a.cos(), a.sin())
            })
            .collect(),
    };
    // (bins, angles) → one filtered line per angle.
    let mut lines = vec![0.0; bins * angles];
    for (b, row) in sinogram.chunks(angles).enumerate() {
        for (k, &v) in row.iter().enumerate() {
            lines[k * bins + b] = v;
        }
    }
    let mut proj = Projections::new(angles, 1, bins, lines)?;
    if options.circle {
        proj = proj.padded_centred(crate::ct::circle_diagonal(bins));
    }
    let n = proj.cols;
    if options.interpolation == Interpolation::Cubic && n < CUBIC_MIN_BINS {
        return Err(Error::invalid(
            "interpolation",
            format!("cubic interpolation needs at least {CUBIC_MIN_BINS} detector bins, not {n}"),
        ));
    }
    let g = Geometry::parallel_skimage(n, theta.to_vec())?;
    let engine = Engine::open(backend)?;
    let kind = options.interpolation;
    let curvatures = |lines: &[f64]| -> Vec<f64> {
        match kind {
            Interpolation::Cubic => lines.chunks(n).flat_map(spline_curvatures).collect(),
            _ => Vec::new(),
        }
    };
    progress.begin("iradon backprojection", "row", size as u64);
    let data: Vec<A> = match (engine.backend(), engine.gpu()) {
        (Backend::Gpu, Some(ctx)) => {
            let p32 =
                Projections::new(angles, 1, n, proj.data.iter().map(|&v| v as f32).collect())?;
            let q = crate::gpu::ramp::filter_projections(ctx, &p32, &g, options.filter)?;
            let q64: Vec<f64> = q.data.iter().map(|&v| v as f64).collect();
            let m: Vec<f32> = curvatures(&q64).iter().map(|&v| v as f32).collect();
            super::check_cancel(progress)?;
            crate::gpu::radon::iradon_backproject(
                ctx,
                &q.data,
                &m,
                n,
                &trig,
                size,
                kind,
                options.circle,
            )?
            .into_iter()
            .map(|v| A::of(v as f64))
            .collect()
        }
        (Backend::CpuF32, _) => {
            let p32 =
                Projections::new(angles, 1, n, proj.data.iter().map(|&v| v as f32).collect())?;
            let q = filter_projections(&p32, &g, options.filter, FilterMethod::Fft)?;
            let q64: Vec<f64> = q.data.iter().map(|&v| v as f64).collect();
            let m: Vec<f32> = curvatures(&q64).iter().map(|&v| v as f32).collect();
            cancellable(progress, |cp| {
                Ok(iradon_backproject::<f32, f32>(
                    &q.data,
                    &m,
                    n,
                    &trig,
                    size,
                    kind,
                    options.circle,
                    &|d, t| cp.advance(d, t),
                ))
            })?
            .into_iter()
            .map(|v| A::of(v as f64))
            .collect()
        }
        _ => {
            let q = filter_projections(&proj, &g, options.filter, FilterMethod::Fft)?;
            let m = curvatures(&q.data);
            cancellable(progress, |cp| {
                Ok(iradon_backproject::<f64, A>(
                    &q.data,
                    &m,
                    n,
                    &trig,
                    size,
                    kind,
                    options.circle,
                    &|d, t| cp.advance(d, t),
                ))
            })?
        }
    };
    progress.end(0.0);
    Ok(IradonImage {
        size,
        data,
        backend: engine.backend(),
    })
}

/// scikit-image's `iradon_sart` options beside the sinogram and its angles.
#[derive(Clone, Debug, PartialEq)]
pub struct SartOptions<R> {
    /// The start image, `n × n` row-major (`image`; `None`: zeros).
    pub image: Option<Vec<R>>,
    /// Each view's shift of its bins (`projection_shifts`; `None`: zeros).
    pub shifts: Option<Vec<R>>,
    /// The range the image is clipped to after every view (`clip`).
    pub clip: Option<[R; 2]>,
    /// `relaxation`: the step `image += λ·update` (λ rounded to `R`).
    pub relaxation: f64,
}

/// One iteration of scikit-image's `iradon_sart` on an `(n, angles)` sinogram
/// (row-major: bin, then angle) taken at `theta` degrees, in the sinogram's precision
/// `R` (scikit-image's `dtype`): every view once in the golden-ratio order, each view's
/// update from bilinear samples half a pixel apart along its rays inside the circle of
/// radius `n//2 − 1` ([`crate::cpu::radon::iradon_sart`]). Returns the `n × n` image.
/// Runs on `cpu` or `cpu-f32` in `R` (the caller picks `R`), or in f32 on the GPU
/// (`gpu::radon::iradon_sart`, values returned in `R`).
///
/// # Errors
/// An empty sinogram or lengths that do not match (theta, image, shifts), non-finite
/// values, a relaxation that is not finite; no GPU for `gpu`; [`Error::Cancelled`].
pub fn iradon_sart<R: Real>(
    sinogram: &[R],
    bins: usize,
    theta: &[R],
    options: &SartOptions<R>,
    backend: Backend,
    progress: &dyn Progress,
) -> Result<Vec<R>> {
    let angles = theta.len();
    if bins == 0 || angles == 0 {
        return Err(Error::invalid(
            "sinogram",
            format!("{bins} bins × {angles} angles is empty"),
        ));
    }
    if sinogram.len() != bins * angles {
        return Err(Error::invalid(
            "sinogram",
            format!(
                "{} values for {bins} bins × {angles} angles",
                sinogram.len()
            ),
        ));
    }
    let length = |what: &str, got: usize, want: usize| -> Result<()> {
        if got == want {
            Ok(())
        } else {
            Err(Error::invalid(
                what,
                format!("{got} values where the sinogram needs {want}"),
            ))
        }
    };
    if let Some(im) = &options.image {
        length("image", im.len(), bins * bins)?;
    }
    if let Some(sh) = &options.shifts {
        length("projection_shifts", sh.len(), angles)?;
    }
    if !options.relaxation.is_finite() {
        return Err(Error::invalid("relaxation", "must be finite"));
    }
    let finite = |what: &str, v: &[R]| -> Result<()> {
        match v.iter().position(|x| !x.is_finite()) {
            None => Ok(()),
            Some(i) => Err(Error::invalid(
                what,
                format!("value {i} is {} (NaN or infinite)", v[i]),
            )),
        }
    };
    finite("sinogram", sinogram)?;
    finite("theta", theta)?;
    crate::volume::check_dims([bins, bins, 1])?;
    let mut image = options
        .image
        .clone()
        .unwrap_or_else(|| vec![R::zero(); bins * bins]);
    let shifts = options
        .shifts
        .clone()
        .unwrap_or_else(|| vec![R::zero(); angles]);
    let engine = Engine::open(backend)?;
    progress.begin("SART", "view", angles as u64);
    match engine.gpu() {
        Some(ctx) => {
            let f = |v: &[R]| v.iter().map(|x| x.f64() as f32).collect::<Vec<f32>>();
            let order = crate::cpu::radon::golden_order(theta);
            let clip = options.clip.map(|c| c.map(|x| x.f64() as f32));
            super::check_cancel(progress)?;
            let out = crate::gpu::radon::iradon_sart(
                ctx,
                &f(sinogram),
                bins,
                &f(theta),
                &order,
                &f(&image),
                &f(&shifts),
                clip,
                options.relaxation,
            )?;
            image = out.iter().map(|&v| R::of(v as f64)).collect();
        }
        None => {
            cancellable(progress, |cp| {
                crate::cpu::radon::iradon_sart(
                    sinogram,
                    bins,
                    theta,
                    &mut image,
                    &shifts,
                    options.clip,
                    options.relaxation,
                    &|d, t| cp.advance(d, t),
                );
                Ok(())
            })?;
        }
    }
    progress.end(0.0);
    Ok(image)
}
