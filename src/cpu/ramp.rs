//! Ramp filtering of CT projections: the "filtered" in filtered backprojection
//! (Kak & Slaney, *Principles of Computerized Tomographic Imaging*, ch. 3, eq. 61;
//! Xu & Mueller 2006, §3.1), constructed exactly as scikit-image's `iradon`
//! (`skimage/transform/radon_transform.py: _get_fourier_filter`).
//!
//! # The filter
//! Each detector row of `cols` samples is zero-padded to
//! `P = max(64, next power of two ≥ 2·cols)` ([`padded_length`]), which makes the
//! circular convolution below equal to the linear one on the `cols` kept samples.
//! The band-limited ramp's spatial kernel (Kak & Slaney eq. 61 with `τ = 1`),
//! laid out periodically ([`spatial_ramp`]):
//!
//! `h[0] = 1/4`, `h[n] = −1/(π·n)²` for odd `n`, `h[n] = 0` for even `n ≠ 0`, with
//! `n` read as `min(i, P − i)` at index `i` (scikit-image's `1, 3, 5, …, 5, 3, 1`).
//!
//! Its frequency response is `H = 2·Re(DFT(h))` ([`frequency_response`]), which is
//! `≈ 2|f|` in cycles per sample (within `≈ 0.41/P`, the largest gap at DC where
//! `H[0] ≈ 0.41/P > 0`).
//! Windows multiply `H` (`f = fftfreq(P)`, `ω = π f`):
//!
//! | filter        | window                                              |
//! |---------------|-----------------------------------------------------|
//! | `ramp`        | 1                                                   |
//! | `shepp-logan` | `sin ω / ω` (`k ≥ 1`)                               |
//! | `cosine`      | `fftshift(sin(linspace(0, π, P, endpoint=False)))`  |
//! | `hamming`     | `fftshift(np.hamming(P))`                           |
//! | `hann`        | `fftshift(np.hanning(P))`                           |
//! | `none`        | no ramp: `H = 1` (scikit-image's `filter_name=None`) |
//!
//! scikit-image keeps `Re(ifft(fft(row)·H))`. For a real row that is the circular
//! convolution with the real kernel `g = Re(IDFT(H))` ([`ramp_kernel`]), i.e. the
//! filter whose response is the even part `(H[k] + H[P−k])/2` (the Hamming and Hann
//! windows are not exactly even after `fftshift`; ramp, Shepp–Logan and cosine are).
//! For the pure ramp `g = 2h` exactly.
//!
//! # Units and the factor 2
//! Filtered values are divided by the detector spacing at the isocentre, so they are
//! "per mm": `du` for a parallel beam; `du·SID/SDD` for a cone beam (the detector
//! magnification folded into the ramp: the ramp is homogeneous of degree −2, so
//! filtering in detector millimetres and rescaling by `SDD/SID` is Kak & Slaney's
//! eq. 176 on the virtual detector through the isocentre). With `du = 1` a parallel
//! row comes out exactly as scikit-image's filtered sinogram. Because `H ≈ 2|f|`
//! (not `|f|`), the backprojection that follows uses `π/(2A)` for `A` views —
//! scikit-image's constant; `crate::cpu::fbp` explains it.
//!
//! # FDK pre-weighting
//! For a cone beam each projection is first multiplied by the cosine weight
//! [`cosine_weight`]`(u, v) = SDD/√(SDD² + u² + v²)` with `(u, v)` the detector
//! position in mm (RTK's `FDKWeightProjectionFilter` with no source or detector
//! offsets: the cosine of the angle between the ray and the central ray). RTK also
//! multiplies by the angular gap and `SDD/(2·SID)` there; voxlab puts `SDD/SID` into
//! the filter's spacing (above) and the angular factor into the backprojection.
//!
//! A geometry given view by view ([`crate::ct::Geometry::from_views`]) is weighted
//! per view instead, spacing included ([`RampView`]): the cosine of each ray with the
//! view's detector normal and the view's own isocentre spacing (RTK's weights with its
//! source and detector offsets).
//!
//! # Oracle and fast path
//! [`FilterMethod::Direct`] is the oracle: the direct circular convolution with `g`,
//! accumulated in f64 whatever `R` is, `O(cols·P)` per row, no FFT anywhere (the
//! windowed kernels come from the exact DFT of `crate::cpu::dft`).
//! [`FilterMethod::Fft`] multiplies in frequency with rustfft (`crate::cpu::fft`) in
//! precision `R`, rayon over rows.

use crate::cpu::dft::{dft_1d, Direction, Normalization};
use crate::ct::{Beam, Geometry, Lines, Projections};
use crate::error::{Error, Result};
use crate::real::Real;
use glam::DVec3;
use rayon::prelude::*;
use rustfft::num_complex::Complex;
use rustfft::{FftNum, FftPlanner};
use std::f64::consts::PI;

crate::choice_enum! {
    /// The frequency windows of scikit-image's `iradon` (same names on the command line).
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
    pub enum RampFilter: "ramp filter", default RamLak {
        /// The plain band-limited ramp (Ram–Lak).
        RamLak = "ramp",
        /// Ramp × `sin ω / ω`.
        SheppLogan = "shepp-logan",
        /// Ramp × a half sine.
        Cosine = "cosine",
        /// Ramp × a Hamming window.
        Hamming = "hamming",
        /// Ramp × a Hann window.
        Hann = "hann",
        /// No filter: the plain backprojection (scikit-image's `filter_name=None`), the
        /// object blurred by the backprojection's `1/r` point spread.
        None = "none",
    }
}

impl RampFilter {
    /// Every ramp filter, for tests and tables ([`RampFilter::None`], which is no
    /// ramp, is left out).
    pub const ALL: [RampFilter; 5] = [
        RampFilter::RamLak,
        RampFilter::SheppLogan,
        RampFilter::Cosine,
        RampFilter::Hamming,
        RampFilter::Hann,
    ];
}

/// How the rows are filtered: the exact spatial convolution (the oracle) or rustfft.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FilterMethod {
    /// Direct circular convolution with [`ramp_kernel`], accumulated in f64.
    Direct,
    /// Multiplication by the (even part of the) response with rustfft, in `R`.
    Fft,
}

/// scikit-image's padded length: `max(64, next power of two ≥ 2·cols)`.
pub fn padded_length(cols: usize) -> usize {
    (2 * cols.max(1)).next_power_of_two().max(64)
}

/// The periodic spatial ramp `h` of length `p` (see the module docs).
pub fn spatial_ramp(p: usize) -> Vec<f64> {
    (0..p)
        .map(|i| {
            let n = i.min(p - i);
            if i == 0 {
                0.25
            } else if n % 2 == 1 {
                -1.0 / (PI * n as f64).powi(2)
            } else {
                0.0
            }
        })
        .collect()
}

/// The window of `filter` at the `p` FFT bins (NumPy order), exactly as scikit-image.
fn window(p: usize, filter: RampFilter) -> Vec<f64> {
    let shift = |v: Vec<f64>| (0..p).map(|k| v[(k + p / 2) % p]).collect::<Vec<_>>();
    let m = (p as f64 - 1.0).max(1.0);
    match filter {
        RampFilter::RamLak | RampFilter::None => vec![1.0; p],
        RampFilter::SheppLogan => (0..p)
            .map(|k| {
                if k == 0 {
                    return 1.0;
                }
                let f = if k < p.div_ceil(2) {
                    k as f64 / p as f64
                } else {
                    (k as f64 - p as f64) / p as f64
                };
                let w = PI * f;
                w.sin() / w
            })
            .collect(),
        RampFilter::Cosine => shift((0..p).map(|n| (PI * n as f64 / p as f64).sin()).collect()),
        RampFilter::Hamming => shift(
            (0..p)
                .map(|n| 0.54 - 0.46 * (2.0 * PI * n as f64 / m).cos())
                .collect(),
        ),
        RampFilter::Hann => shift(
            (0..p)
                .map(|n| 0.5 - 0.5 * (2.0 * PI * n as f64 / m).cos())
                .collect(),
        ),
    }
}

/// scikit-image's frequency response `H[k]` (`k` in NumPy's FFT order) of `filter` at
/// padded length `p`: `2·Re(DFT(h))` times the window, with the DFT exact
/// (`crate::cpu::dft`); 1 at every bin for [`RampFilter::None`].
pub fn frequency_response(p: usize, filter: RampFilter) -> Vec<f64> {
    if filter == RampFilter::None {
        // scikit-image's `fourier_filter[:] = 1`.
        return vec![1.0; p];
    }
    let h: Vec<Complex<f64>> = spatial_ramp(p)
        .into_iter()
        .map(|v| Complex::new(v, 0.0))
        .collect();
    let hh = dft_1d(&h, Direction::Forward, Normalization::None);
    hh.iter()
        .zip(window(p, filter))
        .map(|(c, w)| 2.0 * c.re * w)
        .collect()
}

/// The even part `(H[k] + H[P−k])/2` of the response: what `Re(ifft(fft(x)·H))`
/// applies to a real row.
pub fn effective_response(p: usize, filter: RampFilter) -> Vec<f64> {
    let h = frequency_response(p, filter);
    (0..p).map(|k| 0.5 * (h[k] + h[(p - k) % p])).collect()
}

/// The real spatial kernel `g = Re(IDFT(H))` of `filter` at padded length `p` (periodic,
/// index 0 = lag 0): the filter is `y[n] = Σ_m x[m]·g[(n − m) mod p]`. For
/// [`RampFilter::RamLak`] it is exactly `2·`[`spatial_ramp`]; the windowed kernels come
/// from the exact inverse DFT.
pub fn ramp_kernel(p: usize, filter: RampFilter) -> Vec<f64> {
    if filter == RampFilter::RamLak {
        return spatial_ramp(p).into_iter().map(|v| 2.0 * v).collect();
    }
    if filter == RampFilter::None {
        let mut delta = vec![0.0; p];
        delta[0] = 1.0;
        return delta;
    }
    let hh: Vec<Complex<f64>> = frequency_response(p, filter)
        .into_iter()
        .map(|v| Complex::new(v, 0.0))
        .collect();
    dft_1d(&hh, Direction::Inverse, Normalization::Unnormalized)
        .iter()
        .map(|c| c.re)
        .collect()
}

/// The FDK cosine weight `SDD/√(SDD² + u² + v²)` at detector position `(u, v)` mm.
///
/// mirrors shaders/ramp_filter.wgsl: cosine_weight
#[inline(always)]
pub fn cosine_weight(sdd: f64, u: f64, v: f64) -> f64 {
    sdd / (sdd * sdd + u * u + v * v).sqrt()
}

/// The spacing (mm at the isocentre) the filtered values are divided by: `du` for a
/// parallel beam, `du·SID/SDD` for a cone beam.
pub fn isocentre_spacing(g: &Geometry) -> f64 {
    match g.beam {
        Beam::Parallel => g.du,
        Beam::Cone { sid, sdd } => g.du * sid / sdd,
    }
}

/// One view's pre-weighting for a geometry given view by view: the FDK cosine weight
/// and the view's own isocentre spacing folded into one factor per pixel,
/// [`RampView::weight`]. With `S` the source, `X` the pixel's centre and the view's
/// distances along the detector normal ([`crate::ct::ViewFrame`]):
///
/// - cone beam: `weight = SDD_k / |X − S|` (the cosine of the ray's angle with the
///   detector normal; RTK's `SDD/√(SDD² + u² + v²)` with `(u, v)` measured from the
///   foot of the source's perpendicular, so source and detector offsets are in it)
///   divided by the spacing `|u|·SID_k²/(SDD_k·|S|)` — the pixel's width at the
///   isocentre, `|u|·SID_k/SDD_k`, with the factor `|S|/SID_k` of RTK's
///   `FDKWeightProjectionFilter` (Rit & Clackdoyle 2014) for a source off the normal
///   through the isocentre;
/// - parallel beam: `1/|u_⊥|`, the column step's component perpendicular to the rays.
///
/// For a circular orbit written as views these are the circular weights and spacing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RampView {
    /// From the source to the centre of pixel `(0, 0)` (mm; unused for a parallel beam).
    pub r: DVec3,
    /// The column and row steps (mm).
    pub u: DVec3,
    pub v: DVec3,
    /// `SDD_k` (mm) for a cone beam, 0 for a parallel beam.
    pub sdd: f64,
    /// `1/spacing` (per mm).
    pub scale: f64,
}

impl RampView {
    /// The factor pixel `(col, row)` is multiplied by before the ramp.
    ///
    /// mirrors shaders/ramp_filter.wgsl: view_weight
    #[inline(always)]
    pub fn weight(&self, col: f64, row: f64) -> f64 {
        if self.sdd == 0.0 {
            return self.scale;
        }
        let x = self.r + self.u * col + self.v * row;
        self.scale * self.sdd / x.length()
    }
}

/// Every view's [`RampView`] of a geometry given view by view (`None` for a circular
/// orbit, whose weights are [`cosine_weight`] and [`isocentre_spacing`]).
///
/// # Errors
/// [`Error::Invalid`] for a cone-beam view whose isocentre does not lie in front of
/// the source (`SID_k ≤ 0`): FDK's weights need the object between source and
/// detector.
pub fn ramp_views(g: &Geometry) -> Result<Option<Vec<RampView>>> {
    let Some(views) = &g.views else {
        return Ok(None);
    };
    views
        .iter()
        .enumerate()
        .map(|(k, vv)| {
            let f = g.view_frame(k);
            if g.beam == Beam::Parallel {
                let d = vv.source.normalize();
                let perp = vv.u - d * vv.u.dot(d);
                return Ok(RampView {
                    r: DVec3::ZERO,
                    u: vv.u,
                    v: vv.v,
                    sdd: 0.0,
                    scale: 1.0 / perp.length(),
                });
            }
            if !(f.sid >= crate::ct::MIN_LENGTH_MM && f.sid < f.sdd) {
                return Err(Error::invalid(
                    "FDK",
                    format!(
                        "view {k}: the isocentre lies at depth {:.6e} mm along the detector \
                         normal from the source, which is not between the source and the \
                         detector (SDD {:.6e} mm)",
                        f.sid, f.sdd
                    ),
                ));
            }
            let spacing = vv.u.length() * f.sid * f.sid / (f.sdd * f.source_distance);
            Ok(RampView {
                r: vv.pixel00 - vv.source,
                u: vv.u,
                v: vv.v,
                sdd: f.sdd,
                scale: 1.0 / spacing,
            })
        })
        .collect::<Result<Vec<_>>>()
        .map(Some)
}

/// The projections a filter sees: for a cone beam the cosine-weighted copy (in f64),
/// otherwise the input converted to f64. For a geometry given view by view every
/// pixel is multiplied by its [`RampView::weight`] (which holds the view's
/// `1/spacing` too).
///
/// # Errors
/// As [`ramp_views`].
pub fn preweight<R: Real>(p: &Projections<R>, g: &Geometry) -> Result<Vec<f64>> {
    preweight_lines(&p.data, &|n| n, g)
}

/// [`preweight`] of lines of `g.cols` values: line `n` of `data` is line `id(n)`
/// (`view·rows + row`) of the stack.
fn preweight_lines<R: Real>(data: &[R], id: &LineId, g: &Geometry) -> Result<Vec<f64>> {
    let mut out: Vec<f64> = data.iter().map(|v| v.f64()).collect();
    if let Some(rv) = ramp_views(g)? {
        out.par_chunks_mut(g.cols)
            .enumerate()
            .for_each(|(n, row_data)| {
                let line = id(n);
                let (k, r) = (line / g.rows, line % g.rows);
                for (c, x) in row_data.iter_mut().enumerate() {
                    *x *= rv[k].weight(c as f64, r as f64);
                }
            });
        return Ok(out);
    }
    if let Beam::Cone { sdd, .. } = g.beam {
        out.par_chunks_mut(g.cols)
            .enumerate()
            .for_each(|(n, row_data)| {
                let v = (((id(n) % g.rows) as f64) - g.cv) * g.dv;
                for (c, x) in row_data.iter_mut().enumerate() {
                    let u = (c as f64 - g.cu) * g.du;
                    *x *= cosine_weight(sdd, u, v);
                }
            });
    }
    Ok(out)
}

/// Filters every detector row of `p` (shaped for `g`) with `filter`: cosine
/// pre-weighting for a cone beam, zero-padding to [`padded_length`], the ramp, cut back
/// to `cols`, divided by [`isocentre_spacing`].
pub fn filter_projections<R: Real + FftNum>(
    p: &Projections<R>,
    g: &Geometry,
    filter: RampFilter,
    method: FilterMethod,
) -> Result<Projections<R>> {
    g.validate()?;
    p.check_against(g)?;
    let out = filter_data(&p.data, &|n| n, g, filter, method)?;
    Projections::new(p.angles, p.rows, p.cols, out)
}

/// [`filter_projections`] of some lines of a stack. Each line is filtered as in the
/// whole stack; with [`FilterMethod::Fft`] the lines `2m` and `2m + 1` share one
/// complex transform, so when `p` holds both lines of every pair it holds either of
/// (as a distributed rank's lines do), its lines are those of the whole stack's
/// filtered bit for bit.
///
/// # Errors
/// As [`filter_projections`].
pub fn filter_lines<R: Real + FftNum>(
    p: &Lines<R>,
    g: &Geometry,
    filter: RampFilter,
    method: FilterMethod,
) -> Result<Lines<R>> {
    g.validate()?;
    p.check_against(g)?;
    let out = filter_data(&p.data, &|n| p.ids[n], g, filter, method)?;
    Ok(p.with_data(out))
}

/// Which line of the stack (`view·rows + row`) line `n` of some data is.
type LineId<'a> = dyn Fn(usize) -> usize + Sync + 'a;

/// The filter of [`filter_projections`] on lines of `g.cols` values, line `n` of
/// `data` being line `id(n)` of the stack (its weights depend on the view and row).
fn filter_data<R: Real + FftNum>(
    data: &[R],
    id: &LineId,
    g: &Geometry,
    filter: RampFilter,
    method: FilterMethod,
) -> Result<Vec<R>> {
    let cols = g.cols;
    let pl = padded_length(cols);
    if data.iter().any(|v| !v.is_finite()) {
        return Err(Error::invalid(
            "projections",
            "contain NaN or infinite values",
        ));
    }
    let views = ramp_views(g)?;
    // Views given by vectors carry their own 1/spacing in their weights.
    let inv_du = if views.is_some() {
        1.0
    } else {
        1.0 / isocentre_spacing(g)
    };
    if filter == RampFilter::None {
        // No ramp: the (pre-weighted) values per mm, exactly, with no transform's
        // round trip (the GPU's FFT path rounds them in f32).
        return Ok(preweight_lines(data, id, g)?
            .iter()
            .map(|&v| R::of(v * inv_du))
            .collect());
    }
    let mut out = vec![R::zero(); data.len()];
    match method {
        FilterMethod::Direct => {
            let w = preweight_lines(data, id, g)?;
            let k: Vec<f64> = ramp_kernel(pl, filter);
            out.par_chunks_mut(cols)
                .zip(w.par_chunks(cols))
                .for_each(|(o, x)| {
                    for (n, y) in o.iter_mut().enumerate() {
                        let mut acc = 0.0f64;
                        for (m, &xm) in x.iter().enumerate() {
                            acc += xm * k[(n + pl - m) % pl];
                        }
                        *y = R::of(acc * inv_du);
                    }
                });
        }
        FilterMethod::Fft => {
            // The even real response, scaled once; two real rows share one complex FFT
            // (`z = a + i·b`: a real even filter acts on both parts separately).
            let resp: Vec<R> = effective_response(pl, filter)
                .iter()
                .map(|&v| R::of(v * inv_du / pl as f64))
                .collect();
            let weights: Option<Vec<R>> = match g.beam {
                _ if views.is_some() => None,
                Beam::Parallel => None,
                Beam::Cone { sdd, .. } => Some(
                    (0..g.rows * cols)
                        .map(|i| {
                            let (r, c) = (i / cols, i % cols);
                            R::of(cosine_weight(
                                sdd,
                                (c as f64 - g.cu) * g.du,
                                (r as f64 - g.cv) * g.dv,
                            ))
                        })
                        .collect(),
                ),
            };
            let mut planner = FftPlanner::<R>::new();
            let fwd = planner.plan_fft_forward(pl);
            let inv = planner.plan_fft_inverse(pl);
            let scratch_len = fwd
                .get_inplace_scratch_len()
                .max(inv.get_inplace_scratch_len());
            // The weight of column `c` of line `line` of the stack.
            let weight = |line: usize, c: usize| -> R {
                match (&weights, &views) {
                    (_, Some(v)) => {
                        R::of(v[line / g.rows].weight(c as f64, (line % g.rows) as f64))
                    }
                    (None, None) => R::one(),
                    (Some(w), None) => w[(line % g.rows) * cols + c],
                }
            };
            out.par_chunks_mut(2 * cols)
                .zip(data.par_chunks(2 * cols))
                .enumerate()
                .for_each_init(
                    || {
                        (
                            vec![Complex::new(R::zero(), R::zero()); pl],
                            vec![Complex::new(R::zero(), R::zero()); scratch_len],
                        )
                    },
                    |(z, scratch), (pair, (o, x))| {
                        // Zero lines filter to zeros (`o` already is).
                        if x.iter().all(|&v| v == R::zero()) {
                            return;
                        }
                        let two = x.len() > cols;
                        for v in z.iter_mut() {
                            *v = Complex::new(R::zero(), R::zero());
                        }
                        let (l0, l1) = (id(2 * pair), if two { id(2 * pair + 1) } else { 0 });
                        for c in 0..cols {
                            let a = x[c] * weight(l0, c);
                            let b = if two {
                                x[cols + c] * weight(l1, c)
                            } else {
                                R::zero()
                            };
                            z[c] = Complex::new(a, b);
                        }
                        fwd.process_with_scratch(z, scratch);
                        for (v, &h) in z.iter_mut().zip(&resp) {
                            *v = *v * h;
                        }
                        inv.process_with_scratch(z, scratch);
                        for c in 0..cols {
                            o[c] = z[c].re;
                            if two {
                                o[cols + c] = z[c].im;
                            }
                        }
                    },
                );
        }
    }
    Ok(out)
}
