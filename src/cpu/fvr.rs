//! Fourier volume rendering (FVR): X-ray projections from one 2-D slice of the volume's
//! 3-D spectrum, after Jansen et al. 2004, "Fourier volume rendering on the GPU using a
//! split-stream-FFT" (§2, eq. 8).
//!
//! **The projection-slice theorem.** The 2-D Fourier transform of the projection
//! `P(x, y) = ∫ f(x·r + y·u + t·v) dt` along a unit direction `v` equals the 3-D Fourier
//! transform of `f` on the central plane spanned by `r` and `u`:
//! `P̂(k_r, k_u) = F(k_r·r + k_u·u)`. A volume is transformed once (`O(M³ log M)`); every
//! view then costs one slice (`O(M²)` samples of the spectrum) and one 2-D inverse FFT
//! (`O(M² log M)`).
//!
//! **Pipeline and normalisation.** With `M = padding · max(dims)` rounded up to an even
//! number (the only rounding; every FFT size is fine):
//! 1. the volume (isotropic voxels only) is zero-padded into an `M³` cube whose origin is
//!    the array centre `M/2`: voxel `n` sits at position `r = n + o − M/2` with the
//!    integer offset `o_i = ⌊(M − n_i)/2⌋`, so the volume centre is within half a voxel
//!    of the origin. The array is `ifftshift`ed (origin to index 0) — done here by
//!    writing each voxel at `r mod M` directly;
//! 2. the unnormalised forward 3-D DFT `F(κ) = Σ_r f(r) e^{−2πi κ·r/M}` (f64,
//!    [`fft_nd`]), then `fftshift` (in place), so frequency `κ` sits at index `M/2 + κ`;
//! 3. for a view with in-plane unit axes `r`, `u` (index space), the slice
//!    `S(k_r, k_u) = F(k_r·r + k_u·u)`, `k ∈ [−M/2, M/2)`, is interpolated from the
//!    spectrum's grid with a [`Kernel`] (indices wrap: the DFT is periodic in `κ`);
//!    a phase ramp `e^{2πi(k_r δ_r + k_u δ_u)/M}` shifts the result by the sub-pixel
//!    offset `δ` of the image's pixel centres (zero for axis views);
//! 4. `ifftshift`, the unnormalised-convention inverse 2-D DFT (`1/M²`), `fftshift`
//!    (steps done by index arithmetic), real part. With the forward transform unscaled
//!    and the inverse `1/M²`, the result is `Σ_t f` along the ray in voxel units — for a
//!    nearest-neighbour slice of an axis view exactly `vol.sum(axis)`. Multiplying by
//!    the voxel size gives the line integral in value × mm, the unit of the ray
//!    caster's X-ray mode. (With the unitary convention, as in the paper, the factor
//!    would be `s·√M³/M` = `s·√M`.)
//!
//! **Precision.** [`FvrSpectrum::new`] always transforms in f64 (the oracle). The
//! spectrum is generic over its element precision `R`: [`FvrSpectrum::to_f32`] rounds
//! it to complex f32 once, and [`fvr_project`] then slices, phase-shifts and inverse
//! transforms in f32 (weights and phases computed in f64 and rounded, as the GPU
//! port receives them) — the CPU f32 baseline the GPU is timed against.
//!
//! Only isotropic voxels are handled (the slice would otherwise have to be taken in a
//! sheared frequency frame); anisotropic or sheared volumes are refused with a clear
//! error. The image of an axis view has the layout of [`Camera::axis_view`] (and of
//! NumPy's `vol.sum(axis=…)`); other views are `max(dims)²` images centred on the
//! volume, one voxel per pixel.

use crate::camera::{AxisView, Camera, Orbit, Projection};
use crate::cpu::dft::{Direction, Normalization};
use crate::cpu::fft::fft_nd;
use crate::cpu::filter::{sin_pi, sinc, weight_lanczos, weight_tent};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::real::Real;
use crate::volume::{check_dims, Volume};
use glam::{DMat3, DMat4, DVec3};
use rayon::prelude::*;
use rustfft::num_complex::Complex;
use std::f64::consts::PI;

crate::choice_enum! {
    /// How the spectrum is sampled between its grid points.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Kernel: "FVR kernel" {
        /// The nearest grid frequency (box, 1 tap per axis).
        Nearest = "nearest",
        /// Tent kernel, 2 taps per axis.
        Trilinear = "trilinear",
        /// Lanczos-2 windowed sinc `sinc(x)·sinc(x/2)` (eq. 8, `a = 2`), 4 taps per axis.
        /// The weights of every Lanczos kernel are normalised to sum to 1 per axis (eq. 8's
        /// raw weights sum to 1 only at grid points: half-way between them to 1.019 for
        /// `a = 2`, 0.994 for `a = 3`, 1.002 for `a = 4`, a bias `docs/fvr.md` measures).
        Lanczos2 = "lanczos2",
        /// Lanczos-3, 6 taps per axis.
        Lanczos3 = "lanczos3",
        /// Lanczos-4, 8 taps per axis.
        Lanczos4 = "lanczos4",
        /// The exact trigonometric interpolation of the DFT: the spectrum of the padded
        /// grid evaluated directly at the wanted frequency, `Σ_r f(r) e^{−2πi κ·r/M}`.
        /// `O(N³)` per sample: only for small volumes.
        Dirichlet = "dirichlet",
    }
}

impl Kernel {
    /// The windowed-sinc order `a` of a Lanczos kernel.
    pub(crate) fn lanczos_order(self) -> Option<usize> {
        match self {
            Kernel::Lanczos2 => Some(2),
            Kernel::Lanczos3 => Some(3),
            Kernel::Lanczos4 => Some(4),
            _ => None,
        }
    }

    /// The kernel's weight at offset `x` (frequency bins) along one axis.
    pub fn weight(self, x: f64) -> f64 {
        match self {
            Kernel::Nearest => {
                if x.abs() < 0.5 {
                    1.0
                } else {
                    0.0
                }
            }
            Kernel::Trilinear => weight_tent(x),
            Kernel::Lanczos2 | Kernel::Lanczos3 | Kernel::Lanczos4 => {
                weight_lanczos(x, self.lanczos_order().expect("a Lanczos kernel"))
            }
            Kernel::Dirichlet => panic!("the Dirichlet kernel is evaluated in closed form"),
        }
    }

    /// The kernel's spatial transfer at position `x` (voxels from the origin) of an
    /// `M`-periodic grid: `ŵ(x/M) = ∫ w(κ) e^{2πi κ x/M} dκ`. Interpolating the spectrum
    /// with `w` multiplies the volume by `ŵ` (separably); de-apodisation divides by it.
    pub fn transfer(self, x: f64, m: usize) -> f64 {
        let xi = x / m as f64;
        match self {
            Kernel::Nearest => sinc(xi),
            Kernel::Trilinear => sinc(xi) * sinc(xi),
            Kernel::Dirichlet => 1.0,
            _ => {
                // Simpson's rule over [−a, a] (the kernel is smooth inside), divided by
                // the kernel's integral: the slice's weights are normalised to sum to 1.
                let a = self.lanczos_order().expect("a Lanczos kernel") as f64;
                let n = 256 * a as usize;
                let h = 2.0 * a / n as f64;
                let (mut s, mut s0) = (0.0, 0.0);
                for i in 0..=n {
                    let k = -a + i as f64 * h;
                    let c = if i == 0 || i == n {
                        1.0
                    } else if i % 2 == 1 {
                        4.0
                    } else {
                        2.0
                    };
                    s += c * self.weight(k) * (2.0 * PI * k * xi).cos();
                    s0 += c * self.weight(k);
                }
                s / s0
            }
        }
    }
}

/// A view of an [`FvrSpectrum`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FvrView {
    /// Along an index axis, laid out like [`Camera::axis_view`].
    Axis(AxisView),
    /// The orthographic orbit camera of [`Camera::orbit`] (world frame, +z up).
    Orbit {
        azimuth_deg: f64,
        elevation_deg: f64,
    },
    /// Explicit unit vectors in the volume's index frame: rays go along `forward`,
    /// pixel x along `right`, pixel y along `−up`. Orthonormalised on use.
    Basis {
        forward: DVec3,
        right: DVec3,
        up: DVec3,
    },
}

/// A view resolved against a volume: the orthonormal image frame in index space and
/// the image size. Pixel `(col, row)` is the ray through index point
/// `center + right·(col + ½ − W/2) − up·(row + ½ − H/2)` along `forward`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FvrGeometry {
    pub center: DVec3,
    pub forward: DVec3,
    pub right: DVec3,
    pub up: DVec3,
    pub width: usize,
    pub height: usize,
    /// The volume's voxel-to-world affine.
    pub affine: DMat4,
}

impl FvrGeometry {
    /// The index-space point on pixel `(col, row)`'s ray through the volume centre's plane.
    pub fn pixel_point(&self, col: usize, row: usize) -> DVec3 {
        self.center + self.right * (col as f64 + 0.5 - self.width as f64 * 0.5)
            - self.up * (row as f64 + 0.5 - self.height as f64 * 0.5)
    }

    /// Pixel `(col, row)`'s ray in world coordinates: an origin and a unit direction.
    pub fn pixel_ray_world(&self, col: usize, row: usize) -> (DVec3, DVec3) {
        let o = self.affine.transform_point3(self.pixel_point(col, row));
        let d = self.affine.transform_vector3(self.forward).normalize();
        (o, d)
    }

    /// The orthographic camera whose pixel rays are these (for the ray caster).
    pub fn camera(&self) -> Result<Camera> {
        let lin = DMat3::from_mat4(self.affine);
        let s = lin.col(0).length();
        let c = self.affine.transform_point3(self.center);
        let forward = (lin * self.forward).normalize();
        let extent = (self.width.max(self.height) as f64) * s * 2.0;
        Ok(Camera {
            eye: c - forward * extent,
            forward,
            right: (lin * self.right).normalize(),
            up: (lin * self.up).normalize(),
            projection: Projection::Orthographic {
                width_mm: self.width as f64 * s,
                height_mm: self.height as f64 * s,
            },
            width: self.width,
            height: self.height,
        })
    }
}

/// Where a volume sits in its zero-padded `M³` cube, and the voxel geometry: all a
/// view needs besides the spectrum (the slice's frame, its crop and scale). Shared by
/// [`FvrSpectrum`] (the CPU's f64 spectrum) and `gpu::fvr::GpuFvrSpectrum` (the
/// spectrum transformed on the GPU).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FvrLayout {
    /// The cube side `M`.
    m: usize,
    dims: [usize; 3],
    /// The integer placement offset of the volume in the cube.
    offset: [usize; 3],
    spacing: f64,
    affine: DMat4,
}

impl FvrLayout {
    /// The cube of side [`padded_side`]`(dims, padding)` for `volume`, which must have
    /// isotropic, unsheared voxels; the volume is centred in it.
    ///
    /// # Errors
    /// [`Error::Invalid`] for anisotropic or sheared voxels or a bad padding;
    /// [`Error::TooLarge`] for a cube past the volume limit.
    pub fn new(volume: &Volume<f32>, padding: usize) -> Result<Self> {
        Self::of(volume.dims(), volume.affine(), padding)
    }

    /// [`FvrLayout::new`] for a volume of `dims` voxels placed by `affine` (index to
    /// world), from its header alone.
    ///
    /// # Errors
    /// As [`FvrLayout::new`].
    pub fn of(dims: [usize; 3], affine: DMat4, padding: usize) -> Result<Self> {
        let spacing = isotropic_spacing(affine)?;
        let m = padded_side(dims, padding)?;
        Ok(FvrLayout {
            m,
            dims,
            offset: dims.map(|n| (m - n) / 2),
            spacing,
            affine,
        })
    }

    /// The cube side `M`.
    pub fn side(&self) -> usize {
        self.m
    }

    /// The volume's voxel size (mm).
    pub fn spacing(&self) -> f64 {
        self.spacing
    }

    /// The volume's size in voxels, x fastest.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Where the volume's voxel `(0, 0, 0)` sits in the cube, `⌊(M − n)/2⌋` per axis.
    pub fn offset(&self) -> [usize; 3] {
        self.offset
    }

    /// Refuses a Dirichlet slice past [`MAX_DIRICHLET_WORK`] multiply-adds
    /// (`N³` voxels for each of the `M²` samples).
    ///
    /// # Errors
    /// [`Error::TooLarge`] saying how much work it would be.
    pub fn check_dirichlet_work(&self) -> Result<()> {
        let n: usize = self.dims.iter().product();
        let m = self.m;
        let work = n as f64 * (m * m) as f64;
        if work > MAX_DIRICHLET_WORK {
            return Err(Error::too_large(
                "Dirichlet slice",
                format!(
                    "{n} voxels × {m}² samples = {work:.1e} operations (limit \
                     {MAX_DIRICHLET_WORK:.0e}); the exact kernel is for small volumes"
                ),
            ));
        }
        Ok(())
    }

    /// Where voxel `(i, j, k)` of the volume goes in the cube before the forward FFT:
    /// its position `r = n + offset − M/2` about the cube's centre, wrapped modulo `M`
    /// (the `ifftshift` of the padded cube, so that the centre is at index 0).
    pub fn cube_index(&self, voxel: [usize; 3]) -> [usize; 3] {
        let (m, half) = (self.m, self.m / 2);
        std::array::from_fn(|a| (voxel[a] + self.offset[a] + m - half) % m)
    }

    /// Resolves a view: its orthonormal image frame in index space and image size.
    pub fn geometry(&self, view: FvrView) -> Result<FvrGeometry> {
        let dims = self.dims;
        let center = DVec3::from_array(dims.map(|n| (n as f64 - 1.0) * 0.5));
        let n = *dims.iter().max().expect("three axes");
        let unit = |a: usize| DVec3::from_array(std::array::from_fn(|i| (i == a) as u8 as f64));
        let (forward, right, up, width, height) = match view {
            FvrView::Axis(v) => {
                let (a, sign) = v.axis();
                let (ca, ra) = v.image_axes();
                (unit(a) * sign, unit(ca), -unit(ra), dims[ca], dims[ra])
            }
            FvrView::Orbit {
                azimuth_deg,
                elevation_deg,
            } => {
                let s = self.spacing;
                let extent = dims.map(|d| d as f64 * s);
                let cam = Camera::orbit(
                    self.affine.transform_point3(center),
                    extent,
                    Orbit {
                        azimuth_deg,
                        elevation_deg,
                        distance_mm: None,
                    },
                    Projection::Orthographic {
                        width_mm: 0.0,
                        height_mm: 0.0,
                    },
                    1,
                    1,
                )?;
                let inv = DMat3::from_mat4(self.affine).inverse();
                let to_index = |v: DVec3| (inv * v).normalize();
                (
                    to_index(cam.forward),
                    to_index(cam.right),
                    to_index(cam.up),
                    n,
                    n,
                )
            }
            FvrView::Basis { forward, right, up } => {
                let f = forward.normalize();
                let r = (right - f * right.dot(f)).normalize();
                let u = f.cross(r);
                let u = if u.dot(up) < 0.0 { -u } else { u };
                if !(f.is_finite() && r.is_finite() && u.is_finite()) {
                    return Err(Error::invalid(
                        "view basis",
                        "forward and right must be finite, non-zero and not parallel",
                    ));
                }
                (f, r, u, n, n)
            }
        };
        Ok(FvrGeometry {
            center,
            forward,
            right,
            up,
            width,
            height,
            affine: self.affine,
        })
    }

    /// The in-plane coordinates (voxels, relative to the cube origin) of pixel
    /// `(0, 0)`'s ray: pixel `(col, row)` sits at `(c_r + col, c_u − row)`.
    pub(crate) fn pixel_origin(&self, g: &FvrGeometry) -> (f64, f64) {
        let half = (self.m / 2) as f64;
        let rel = g.center + DVec3::from_array(self.offset.map(|o| o as f64)) - DVec3::splat(half);
        let cr = rel.dot(g.right) + 0.5 - g.width as f64 * 0.5;
        let cu = rel.dot(g.up) - 0.5 + g.height as f64 * 0.5;
        (cr, cu)
    }
}

/// The centred 3-D spectrum of a zero-padded volume, ready for many views, with its
/// elements in precision `R` (f64, the oracle, unless rounded by
/// [`FvrSpectrum::to_f32`]).
#[derive(Clone, Debug)]
pub struct FvrSpectrum<R = f64> {
    /// The cube, the volume's place in it, its voxel geometry.
    layout: FvrLayout,
    /// `[z][y][x]`, frequency `κ` at index `M/2 + κ`.
    spectrum: Vec<Complex<R>>,
    /// The original volume in f64 (for the Dirichlet kernel), `[z][y][x]`.
    values: Vec<f64>,
}

/// The most multiply-adds a Dirichlet slice may take (`N³·M²`).
pub const MAX_DIRICHLET_WORK: f64 = 4e9;

/// The cube side for `dims` and `padding`: `padding · max(dims)` rounded up to even.
pub fn padded_side(dims: [usize; 3], padding: usize) -> Result<usize> {
    if padding == 0 || padding > 16 {
        return Err(Error::invalid(
            "padding",
            format!("{padding}: the oversampling factor must lie in 1 … 16"),
        ));
    }
    let n = *dims.iter().max().expect("three axes");
    let m = n
        .checked_mul(padding)
        .and_then(|m| m.checked_add(m % 2))
        .ok_or_else(|| Error::too_large("padded FVR cube", format!("{n}·{padding}")))?;
    check_dims([m, m, m]).map_err(|_| {
        Error::too_large(
            "padded FVR cube",
            format!(
                "{m}³ voxels exceed the limit of {} (use a smaller --padding or volume)",
                crate::volume::max_voxels()
            ),
        )
    })?;
    Ok(m)
}

/// `fftshift` of an `M³` cube of even side `M`, in place: the shift by `M/2` on every
/// axis pairs element `(z, y, x)` with `(z + M/2, y + M/2, x + M/2) mod M`, so it is a
/// set of swaps (and its own inverse). Saves the copy
/// [`crate::cpu::dft::fftshift`] would make.
pub fn fftshift_cube_in_place<T: Send>(data: &mut [T], m: usize) {
    assert!(
        m.is_multiple_of(2) && data.len() == m * m * m,
        "an M³ cube of even side"
    );
    let h = m / 2;
    let (lower, upper) = data.split_at_mut(h * m * m);
    lower
        .par_chunks_mut(m * m)
        .zip(upper.par_chunks_mut(m * m))
        .for_each(|(a, b)| {
            for y in 0..m {
                for x in 0..m {
                    std::mem::swap(&mut a[y * m + x], &mut b[((y + h) % m) * m + (x + h) % m]);
                }
            }
        });
}

/// The voxel size of an isotropic, unsheared affine, or an error.
fn isotropic_spacing(affine: DMat4) -> Result<f64> {
    let lin = DMat3::from_mat4(affine);
    let c = [lin.col(0), lin.col(1), lin.col(2)];
    let s = c[0].length();
    let tol = 1e-6 * s;
    let iso = c.iter().all(|v| (v.length() - s).abs() <= tol);
    let ortho = c[0].dot(c[1]).abs() <= tol * s
        && c[0].dot(c[2]).abs() <= tol * s
        && c[1].dot(c[2]).abs() <= tol * s;
    if !(iso && ortho && s > 0.0 && s.is_finite()) {
        return Err(Error::invalid(
            "volume for Fourier volume rendering",
            format!(
                "voxel sizes {:.6}, {:.6}, {:.6} mm: only isotropic, unsheared voxels are \
                 supported (resample the volume first)",
                c[0].length(),
                c[1].length(),
                c[2].length()
            ),
        ));
    }
    Ok(s)
}

/// The element types an [`FvrSpectrum`] may hold: f64 (the oracle) and f32.
pub trait SpectrumReal: Real + rustfft::FftNum + num_traits::NumAssign {}
impl SpectrumReal for f32 {}
impl SpectrumReal for f64 {}

impl FvrSpectrum<f64> {
    /// Zero-pads `volume` into an `M³` cube (see [`padded_side`]), centres it, and keeps
    /// its centred 3-D spectrum (f64). `padding` is the oversampling factor (2 is the
    /// usual choice; 1 pads only to an even cube).
    pub fn new(volume: &Volume<f32>, padding: usize) -> Result<Self> {
        let layout = FvrLayout::new(volume, padding)?;
        volume.check_finite("volume for Fourier volume rendering")?;
        let (m, dims) = (layout.m, layout.dims);
        let values: Vec<f64> = volume.data().iter().map(|&v| v as f64).collect();
        let mut cube = vec![Complex::new(0.0, 0.0); m * m * m];
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let v = values[(k * dims[1] + j) * dims[0] + i];
                    let [x, y, z] = layout.cube_index([i, j, k]);
                    cube[(z * m + y) * m + x] = Complex::new(v, 0.0);
                }
            }
        }
        fft_nd(
            &mut cube,
            &[m, m, m],
            Direction::Forward,
            Normalization::Unnormalized,
        );
        fftshift_cube_in_place(&mut cube, m);
        Ok(FvrSpectrum {
            layout,
            spectrum: cube,
            values,
        })
    }

    /// The same spectrum rounded to complex f32 (the CPU f32 path; the GPU port
    /// uploads the same rounding). The volume's values stay in f64 for the Dirichlet
    /// kernel.
    pub fn to_f32(&self) -> FvrSpectrum<f32> {
        FvrSpectrum {
            layout: self.layout,
            spectrum: self
                .spectrum
                .par_iter()
                .map(|c| Complex::new(c.re as f32, c.im as f32))
                .collect(),
            values: self.values.clone(),
        }
    }
}

impl<R: SpectrumReal> FvrSpectrum<R> {
    /// The cube side `M`.
    pub fn side(&self) -> usize {
        self.layout.m
    }

    /// The volume's voxel size (mm).
    pub fn spacing(&self) -> f64 {
        self.layout.spacing
    }

    /// The cube and the volume's place in it.
    pub fn layout(&self) -> &FvrLayout {
        &self.layout
    }

    /// The volume's values in f64, `[z][y][x]` (the Dirichlet kernel's input).
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// The centred spectrum, `[z][y][x]`, frequency `κ` at index `M/2 + κ`.
    pub fn spectrum(&self) -> &[Complex<R>] {
        &self.spectrum
    }

    /// Resolves a view: its orthonormal image frame in index space and image size
    /// ([`FvrLayout::geometry`]).
    pub fn geometry(&self, view: FvrView) -> Result<FvrGeometry> {
        self.layout.geometry(view)
    }

    /// Interpolates the centred spectrum at frequency `kappa` (bins, `[x, y, z]`).
    /// Mirrored by `shaders/fvr_slice.wgsl: sample` (same taps, weights normalised to
    /// sum to 1 per axis, `round` half away from zero for the nearest kernel).
    /// The weights are computed in f64 and rounded to `R`; the sum runs in `R`.
    pub fn sample(&self, kernel: Kernel, kappa: DVec3) -> Complex<R> {
        let m = self.layout.m as i64;
        let half = (self.layout.m / 2) as f64;
        let g = [kappa.x + half, kappa.y + half, kappa.z + half];
        // Periodic index; taps lie within one period of the cube, so mostly no division.
        let wrap = |i: i64| {
            if (0..m).contains(&i) {
                i as usize
            } else if (-m..0).contains(&i) {
                (i + m) as usize
            } else {
                i.rem_euclid(m) as usize
            }
        };
        if kernel == Kernel::Nearest {
            let i = g.map(|v| wrap(v.round() as i64));
            return self.spectrum[(i[2] * self.layout.m + i[1]) * self.layout.m + i[0]];
        }
        let r: i64 = match kernel {
            Kernel::Trilinear => 1,
            k => k.lanczos_order().expect("a truncated kernel") as i64,
        };
        let mut idx = [[0usize; 8]; 3];
        let mut w = [[R::zero(); 8]; 3];
        let taps = (2 * r) as usize;
        for a in 0..3 {
            let first = g[a].floor() as i64 - r + 1;
            let mut w64 = [0.0f64; 8];
            for (t, i) in idx[a][..taps].iter_mut().enumerate() {
                *i = wrap(first + t as i64);
            }
            if r == 1 {
                for (t, wt) in w64[..taps].iter_mut().enumerate() {
                    *wt = kernel.weight(g[a] - (first + t as i64) as f64);
                }
            } else {
                lanczos_weights(g[a] - g[a].floor(), r as usize, &mut w64[..taps]);
            }
            let sum: f64 = w64[..taps].iter().sum();
            for (x, v) in w[a][..taps].iter_mut().zip(&w64) {
                *x = R::of(v / sum);
            }
        }
        // The tap count as a constant, so that the sums unroll (the same sums).
        match taps {
            2 => self.sum_taps::<2>(&idx, &w),
            4 => self.sum_taps::<4>(&idx, &w),
            6 => self.sum_taps::<6>(&idx, &w),
            _ => self.sum_taps::<8>(&idx, &w),
        }
    }

    /// `Σ_z w_z Σ_y w_y Σ_x w_x S[z][y][x]` over `T` taps per axis at indices `idx`.
    #[inline(always)]
    fn sum_taps<const T: usize>(&self, idx: &[[usize; 8]; 3], w: &[[R; 8]; 3]) -> Complex<R> {
        let zero = Complex::new(R::zero(), R::zero());
        // Away from the cube's edge the x taps are one contiguous run (same sum).
        let x_run = (idx[0][0] + T <= self.layout.m && idx[0][T - 1] == idx[0][0] + T - 1)
            .then_some(idx[0][0]);
        let mut acc = zero;
        for tz in 0..T {
            let mut az = zero;
            for ty in 0..T {
                let row = (idx[2][tz] * self.layout.m + idx[1][ty]) * self.layout.m;
                let mut ax = zero;
                if let Some(x0) = x_run {
                    let line: &[Complex<R>; T] = self.spectrum[row + x0..row + x0 + T]
                        .try_into()
                        .expect("T taps");
                    for (v, &wt) in line.iter().zip(&w[0][..T]) {
                        ax += *v * wt;
                    }
                } else {
                    for tx in 0..T {
                        ax += self.spectrum[row + idx[0][tx]] * w[0][tx];
                    }
                }
                az += ax * w[1][ty];
            }
            acc += az * w[2][tz];
        }
        acc
    }

    /// The spectrum of the padded grid evaluated exactly at `kappa` (the Dirichlet
    /// kernel): `Σ_r f(r) e^{−2πi κ·r/M}`, `r = n + o − M/2`.
    pub fn sample_exact(&self, kappa: DVec3) -> Complex<f64> {
        let m = self.layout.m as f64;
        let half = (self.layout.m / 2) as f64;
        let phases = |a: usize, k: f64| -> Vec<Complex<f64>> {
            (0..self.layout.dims[a])
                .map(|n| {
                    let r = (n + self.layout.offset[a]) as f64 - half;
                    Complex::from_polar(1.0, -2.0 * PI * k * r / m)
                })
                .collect()
        };
        let (px, py, pz) = (phases(0, kappa.x), phases(1, kappa.y), phases(2, kappa.z));
        let [nx, ny, _] = self.layout.dims;
        let mut acc = Complex::new(0.0, 0.0);
        for (k, ez) in pz.iter().enumerate() {
            let mut az = Complex::new(0.0, 0.0);
            for (j, ey) in py.iter().enumerate() {
                let row = &self.values[(k * ny + j) * nx..(k * ny + j + 1) * nx];
                let mut ax = Complex::new(0.0, 0.0);
                for (v, ex) in row.iter().zip(&px) {
                    ax += ex * *v;
                }
                az += ax * ey;
            }
            acc += az * ez;
        }
        acc
    }
}

/// The Lanczos-`a` weights of the `2a` taps `x_t = f + a − 1 − t` (`f` ∈ [0, 1), the
/// fractional part of the sample's coordinate), equal to `Kernel::weight` up to
/// rounding, with three trigonometric calls per axis instead of two per tap:
/// `sin π(f + k) = (−1)^k sin πf`, and `sin (π(f + k)/a)` by angle addition from
/// `sin πf/a`, `cos πf/a` and a table of `sin kπ/a`, `cos kπ/a`, except for the two
/// taps beside the sample (`k` = 0, −1), which take their own arguments.
fn lanczos_weights(f: f64, a: usize, w: &mut [f64]) {
    use std::sync::OnceLock;
    // [a][k + 4] = (sin kπ/a, cos kπ/a), k = −4 … 3.
    static TABLE: OnceLock<[[(f64, f64); 8]; 5]> = OnceLock::new();
    let table = TABLE.get_or_init(|| {
        let mut t = [[(0.0, 1.0); 8]; 5];
        for (a, row) in t.iter_mut().enumerate().skip(2) {
            for (i, e) in row.iter_mut().enumerate() {
                *e = ((i as f64 - 4.0) * PI / a as f64).sin_cos();
            }
        }
        t
    });
    let af = a as f64;
    let s = sin_pi(f);
    let (sa, ca) = (PI * f / af).sin_cos();
    // The inner taps' sin(πx/a) straight from their own (exact) arguments: there the
    // weight is near 1 and the angle addition would lose relative accuracy.
    let s_left = (PI * (f - 1.0) / af).sin();
    for (t, wt) in w.iter_mut().enumerate() {
        let k = a as i64 - 1 - t as i64;
        let x = f + k as f64;
        *wt = if x == 0.0 {
            1.0
        } else if x.abs() >= af {
            0.0
        } else {
            let s1 = if k.rem_euclid(2) == 0 { s } else { -s };
            let s2 = match k {
                0 => sa,
                -1 => s_left,
                _ => {
                    let (sk, ck) = table[a][(k + 4) as usize];
                    sa * ck + ca * sk
                }
            };
            // sinc(x)·sinc(x/a) = a·sin πx·sin(πx/a) / (π x)².
            af * s1 * s2 / (PI * PI * x * x)
        };
    }
}

/// Rounds `c` to an integer when it is within `1e-9` of one (axis views), else returns
/// its nearest integer and the remainder.
fn split(c: f64) -> (i64, f64) {
    let n = c.round();
    let d = c - n;
    (n as i64, if d.abs() < 1e-9 { 0.0 } else { d })
}

/// The X-ray projection (value × mm) of the spectrum's volume for `view`: one slice
/// of the spectrum sampled with `kernel`, one inverse 2-D FFT. With `deapodize`, the
/// image is divided by the kernel's spatial transfer in both image axes.
pub fn fvr_project<R: SpectrumReal>(
    spectrum: &FvrSpectrum<R>,
    view: FvrView,
    kernel: Kernel,
    deapodize: bool,
) -> Result<Frame> {
    let plan = SlicePlan::new(&spectrum.layout, view)?;
    let g = &plan.geometry;
    let m = spectrum.layout.m;
    if kernel == Kernel::Dirichlet {
        spectrum.layout.check_dirichlet_work()?;
    }
    let (dr, du) = (plan.dr, plan.du);
    let half = (m / 2) as i64;
    // The slice in DC-at-0 order ([k_u][k_r], each k at k mod M): the ifftshift of
    // the centred slice. Mirrored per sample by `shaders/fvr_slice.wgsl: extract_slice`
    // (src/gpu/fvr.rs).
    // The sub-voxel shift's phase ramp e^{2πi(k_r δ_r + k_u δ_u)/M}, separable: one
    // factor per column and one per row.
    let k_of = |i: usize| (i as i64 + half).rem_euclid(m as i64) - half;
    let ramp = |d: f64| -> Vec<Complex<f64>> {
        (0..m)
            .map(|i| Complex::from_polar(1.0, 2.0 * PI * k_of(i) as f64 * d / m as f64))
            .collect()
    };
    let (ramp_r, ramp_u) = (ramp(dr), ramp(du));
    let sample_at = |ir: usize, ju: usize| -> Complex<R> {
        let kappa = g.right * k_of(ir) as f64 + g.up * k_of(ju) as f64;
        let mut s = match kernel {
            Kernel::Dirichlet => {
                let e = spectrum.sample_exact(kappa);
                Complex::new(R::of(e.re), R::of(e.im))
            }
            k => spectrum.sample(k, kappa),
        };
        if dr != 0.0 || du != 0.0 {
            let e = ramp_r[ir] * ramp_u[ju];
            s *= Complex::new(R::of(e.re), R::of(e.im));
        }
        s
    };
    // The volume is real, so its spectrum is Hermitian, `S(−κ) = S(κ)*`, and so is any
    // interpolant of it with an even kernel over the periodic grid, and so is the phase
    // ramp: the slice at `(−k_r, −k_u)` is the conjugate of the slice at `(k_r, k_u)`.
    // Rows `k_u ≤ 0` are sampled; rows `0 < k_u < M/2` are the conjugates of rows
    // `−k_u`, except at `k_r = −M/2`, whose partner `+M/2` is not on the slice.
    // (The nearest kernel breaks ties one way for `κ` and the other for `−κ`, so it is
    // sampled everywhere; it is cheap.)
    let hermitian = kernel != Kernel::Nearest;
    let mirrored = |ju: usize| hermitian && (1..m / 2).contains(&ju);
    let mut slice = vec![Complex::new(R::zero(), R::zero()); m * m];
    slice.par_chunks_mut(m).enumerate().for_each(|(ju, line)| {
        if !mirrored(ju) {
            for (ir, out) in line.iter_mut().enumerate() {
                *out = sample_at(ir, ju);
            }
        }
    });
    if hermitian {
        let (low, high) = slice.split_at_mut(m / 2 * m);
        let high = &*high;
        low.par_chunks_mut(m)
            .enumerate()
            .skip(1)
            .for_each(|(ju, line)| {
                // Row `M − ju` holds `k_u = −k_of(ju)`; it lies in `high` at `M/2 − ju`.
                let partner = &high[(m / 2 - ju) * m..(m / 2 - ju + 1) * m];
                for (ir, out) in line.iter_mut().enumerate() {
                    *out = if ir == m / 2 {
                        sample_at(ir, ju)
                    } else {
                        partner[(m - ir) % m].conj()
                    };
                }
            });
    }
    fft_nd(
        &mut slice,
        &[m, m],
        Direction::Inverse,
        Normalization::Unnormalized,
    );
    Ok(plan.crop(&spectrum.layout, kernel, deapodize, |i| slice[i].re.f64()))
}

/// A view resolved for slicing: its geometry, the in-plane position `(c_r, c_u)` of
/// pixel `(0, 0)`, and that position split into whole voxels `n` and the sub-voxel
/// offsets `δ` the phase ramp applies. Shared by [`fvr_project`] and
/// `gpu::fvr::fvr_project` so that both crop and scale alike.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SlicePlan {
    pub geometry: FvrGeometry,
    pub cr: f64,
    pub cu: f64,
    pub nr: i64,
    pub nu: i64,
    pub dr: f64,
    pub du: f64,
}

impl SlicePlan {
    /// Resolves `view`; refuses an image wider than the padded cube.
    pub fn new(layout: &FvrLayout, view: FvrView) -> Result<Self> {
        let g = layout.geometry(view)?;
        let m = layout.m;
        if g.width > m || g.height > m {
            return Err(Error::invalid(
                "FVR image size",
                format!("{}×{} exceeds the padded cube side {m}", g.width, g.height),
            ));
        }
        let (cr, cu) = layout.pixel_origin(&g);
        let ((nr, dr), (nu, du)) = (split(cr), split(cu));
        Ok(SlicePlan {
            geometry: g,
            cr,
            cu,
            nr,
            nu,
            dr,
            du,
        })
    }

    /// The image from the inverse-transformed slice (`re(i)`: the real part of its
    /// element `i`, `[y][x]`, DC at 0): crop with wrap-around, scale by the voxel size,
    /// optionally de-apodise.
    pub fn crop(
        &self,
        layout: &FvrLayout,
        kernel: Kernel,
        deapodize: bool,
        re: impl Fn(usize) -> f64 + Sync,
    ) -> Frame {
        let g = &self.geometry;
        let m = layout.m;
        let mut frame = Frame::new(g.width, g.height, 1);
        let s = layout.spacing;
        // The transfer is separable: one factor per column and one per row, computed
        // once (for Lanczos kernels each is a numerical integral).
        let (tx, ty): (Vec<f64>, Vec<f64>) = if deapodize {
            (
                (0..g.width)
                    .into_par_iter()
                    .map(|col| kernel.transfer(self.cr + col as f64, m))
                    .collect(),
                (0..g.height)
                    .into_par_iter()
                    .map(|row| kernel.transfer(self.cu - row as f64, m))
                    .collect(),
            )
        } else {
            (Vec::new(), Vec::new())
        };
        frame
            .data
            .par_chunks_mut(g.width)
            .enumerate()
            .for_each(|(row, line)| {
                let yu = (self.nu - row as i64).rem_euclid(m as i64) as usize;
                for (col, px) in line.iter_mut().enumerate() {
                    let xr = (self.nr + col as i64).rem_euclid(m as i64) as usize;
                    let mut v = re(yu * m + xr) * s;
                    if deapodize {
                        let t = tx[col] * ty[row];
                        v /= t.max(1e-3);
                    }
                    *px = v;
                }
            });
        frame
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu::dft::fftshift;

    #[test]
    fn padded_side_rounds_to_even_and_refuses_absurd_sizes() {
        assert_eq!(padded_side([5, 3, 4], 1).unwrap(), 6);
        assert_eq!(padded_side([5, 3, 4], 2).unwrap(), 10);
        assert_eq!(padded_side([7, 7, 7], 3).unwrap(), 22);
        assert!(padded_side([4, 4, 4], 0).is_err());
        let e = padded_side([100_000, 1, 1], 2).unwrap_err();
        assert!(e.to_string().contains("too large"), "{e}");
    }

    #[test]
    fn lanczos_weights_by_angle_addition_equal_the_kernel() {
        for (a, kernel) in [
            (2, Kernel::Lanczos2),
            (3, Kernel::Lanczos3),
            (4, Kernel::Lanczos4),
        ] {
            for i in 0..1000 {
                let f = i as f64 / 1000.0 + if i % 7 == 3 { 1e-12 } else { 0.0 };
                let mut w = [0.0; 8];
                lanczos_weights(f, a, &mut w[..2 * a]);
                for (t, &wt) in w[..2 * a].iter().enumerate() {
                    let x = f + (a as f64 - 1.0 - t as f64);
                    let want = kernel.weight(x);
                    // Different roundings of the same formula: a few ulps of 1. A
                    // wrong sign or tap is off by order 0.1.
                    assert!((wt - want).abs() <= 1e-15, "a {a} x {x}: {wt} vs {want}");
                }
            }
        }
    }

    #[test]
    fn kernel_transfer_is_one_at_the_origin_and_matches_closed_forms() {
        for k in [
            Kernel::Nearest,
            Kernel::Trilinear,
            Kernel::Lanczos2,
            Kernel::Lanczos3,
            Kernel::Lanczos4,
        ] {
            assert!((k.transfer(0.0, 64) - 1.0).abs() < 1e-12, "{k:?}");
        }
        // The closed form of the tent's transfer, sinc², against the quadrature's
        // accuracy on a smooth kernel: the Lanczos transfer at the cube's edge.
        assert!((Kernel::Trilinear.transfer(16.0, 64) - 0.8105694691387022).abs() < 1e-12);
        // The Lanczos transfer is flat in the middle and falls off near ±M/2.
        let t = Kernel::Lanczos3.transfer(16.0, 64);
        assert!(t > 0.95 && t < 1.05, "{t}");
        assert!(Kernel::Trilinear.transfer(32.0, 64) < 0.41);
    }

    #[test]
    fn the_in_place_cube_shift_is_fftshift() {
        for m in [2, 4, 6] {
            let data: Vec<u32> = (0..(m * m * m) as u32).collect();
            let want = fftshift(&data, &[m, m, m]);
            let mut got = data.clone();
            fftshift_cube_in_place(&mut got, m);
            assert_eq!(got, want, "M = {m}");
        }
    }

    #[test]
    fn anisotropic_volumes_are_refused() {
        let v = Volume::new([4, 4, 4], [1.0, 1.0, 2.0], vec![0.0f32; 64]).unwrap();
        let e = FvrSpectrum::new(&v, 2).unwrap_err();
        assert!(e.to_string().contains("isotropic"), "{e}");
    }
}
