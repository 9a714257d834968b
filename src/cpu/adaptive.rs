//! Spectral adaptive sampling (Suwelack, Heitz, Unterhinninghofen & Dillmann, MIAR 2010,
//! after Bergner et al., TVCG 2006), with regular and "direct" sampling beside it.
//!
//! Scope: direct volume rendering with post-classification through a pre-integrated
//! transfer function ([`super::preintegrate`]), front-to-back compositing with early ray
//! termination, trilinear reconstruction, no shading. All three samplings share that
//! compositing; they differ only in where the samples go.
//!
//! A ray marches from its box entry in index space (distance `s` in voxels). Each step
//! from `s` to `s + T` reads the value at its end and composites the pre-integrated
//! segment from the previous value with the step length `T`. What sets `T`:
//!
//! - **Regular**: `T = step` (the reference; the last step ends on the box).
//! - **Adaptive** (paper §3–4): the maximal frequency of `g ∘ Ψ ∘ f` along the step is
//!   estimated as `ν_g(I) · |a_Ψ| · max|f′|` (eq. 1 and 4), so
//!   `T = 1 / (2 · osf · ν_g(I) · |a_Ψ| · max|f′|)` (eq. 5 with an oversampling factor
//!   `osf`, 2 by default as in the paper), clamped to `[T_min, T_max]`. Here
//!   - `max|f′|` comes from the **importance volume**: per voxel and axis the largest
//!     one-sided difference `G_a`, max-filtered over a cube of half-width
//!     `r = ⌈T_max + 1.5⌉` voxels (the paper's width `2·T_max`, plus the trilinear cell
//!     and the rounding to the nearest voxel), so that for a unit index direction `d`
//!     `|df/ds| ≤ Σ_a |d_a| G_a` holds on the whole next step (trilinear derivatives are
//!     interpolated edge differences);
//!   - `I = [s_min, s_max]` from the first-order Taylor bound around the current sample
//!     (eqs. 6–8) `f(x₀) ∓ max|f′| · T_max`, mapped by `Ψ`;
//!   - `ν_g(I)` from the [`SpectralTable`] of the transfer function's **opacity**, so a
//!     window/level change (a new `Ψ`) acts through `a_Ψ` alone, without a new spectrum.
//! - **Direct** (the paper's upper bound): the spectrum of `g ∘ Ψ ∘ f` itself, computed
//!   per block of `B³` voxels (3D FFT of the block sampled at half-voxel spacing,
//!   mirrored), gives `ν_h` per block; `T = 1/(2·osf·ν_h)`, clamped, minimised over the
//!   neighbouring blocks a step can reach. It must be recomputed whenever the transfer
//!   function or the window changes.
//!
//! **Why opacity.** The samples that matter are those where light is absorbed: colour
//! changes where `α = 0` are invisible, and the opacity ramp is where a medical transfer
//! function is sharp. Extinction `−ln(1 − α)` would weigh the same places but is unbounded
//! near `α = 1`, which makes its spectrum depend on an arbitrary clamp.
//!
//! **Spectra.** A signal on an interval is sampled at cell midpoints and extended
//! evenly (mirrored) before the FFT, so that the interval's ends do not add the jump of a
//! periodic extension (a ramp stays a triangle wave, whose energy lies at low
//! frequencies). The cut-off is the smallest frequency below which the fraction `energy`
//! (0.99 by default) of the non-DC energy lies; a constant signal has cut-off 0.
//!
//! The GPU twins: `shaders/adaptive.wgsl` (the caster: `adaptive_step`, `direct_step`,
//! `cast_ray`) and `shaders/adaptive_importance.wgsl` (the importance volume).

use super::dft::{Direction, Normalization};
use super::field::box_hi;
use super::filter::sample;
use super::grid::Grid;
use super::preintegrate::{preintegrate, PreintTable, DEFAULT_PREINT_SIZE};
use super::raycast::RenderOutput;
use super::shade::over_background;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::real::{intersect_box, Real, V3};
use crate::settings::Filter;
use crate::transfer::{LutR, TransferFunction};
use crate::volume::AnyVolume;
use glam::DMat4;
use rayon::prelude::*;
use rustfft::num_complex::Complex;
use serde::{Deserialize, Serialize};

crate::choice_enum! {
    /// Where the samples of a ray go.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Sampling: "sampling" {
        /// Fixed steps of `step` voxels (the reference).
        Regular = "regular",
        /// Steps from the transfer function's spectrum and the importance volume (Suwelack
        /// et al. 2010).
        Adaptive = "adaptive",
        /// Steps from the local spectrum of the classified volume (the upper bound; must be
        /// recomputed for every transfer function).
        Direct = "direct",
    }
}

impl Sampling {
    pub const ALL: [Sampling; 3] = [Sampling::Regular, Sampling::Direct, Sampling::Adaptive];
}

/// Settings of the adaptive ray caster.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct AdaptiveSettings {
    pub sampling: Sampling,
    /// The regular step and the smallest adaptive or direct step `T_min` (voxels).
    pub step: f64,
    /// The largest step `T_max` (voxels).
    pub t_max: f64,
    /// Oversampling factor over the Nyquist rate of the estimated maximal frequency.
    pub oversampling: f64,
    /// Fraction of the non-DC energy below the cut-off frequency.
    pub energy: f64,
    /// Resolution of the spectral table `ν_g(I)` (bins over the domain per axis).
    pub spectrum_bins: usize,
    /// Entries per axis of the pre-integrated table.
    pub preint_size: usize,
    /// Edge of the blocks of direct sampling (voxels).
    pub block: usize,
    /// Rays stop once their opacity reaches this (1 disables it).
    pub ert_threshold: f64,
    /// RGBA behind the volume.
    pub background: [f64; 4],
    /// Also return the number of samples each ray took.
    pub sample_count: bool,
}

impl Default for AdaptiveSettings {
    fn default() -> Self {
        AdaptiveSettings {
            sampling: Sampling::Adaptive,
            step: 0.5,
            t_max: 8.0,
            oversampling: 2.0,
            energy: 0.99,
            spectrum_bins: 64,
            preint_size: DEFAULT_PREINT_SIZE,
            block: 8,
            ert_threshold: 0.99,
            background: [0.0, 0.0, 0.0, 1.0],
            sample_count: true,
        }
    }
}

impl AdaptiveSettings {
    /// Refuses meaningless settings before any work.
    pub fn validate(&self) -> Result<()> {
        let pos = |x: f64| x.is_finite() && x > 0.0;
        if !pos(self.step) || self.step < 1e-3 {
            return Err(Error::invalid("step", "must be at least 0.001 voxel"));
        }
        if !pos(self.t_max) || self.t_max < self.step || self.t_max > 64.0 {
            return Err(Error::invalid(
                "t-max",
                format!("must lie in [step = {}, 64] voxels", self.step),
            ));
        }
        if !pos(self.oversampling) {
            return Err(Error::invalid("oversampling", "must be positive"));
        }
        if !(self.energy > 0.0 && self.energy <= 1.0) {
            return Err(Error::invalid("energy", "must lie in (0, 1]"));
        }
        if !(2..=1024).contains(&self.spectrum_bins) {
            return Err(Error::invalid("spectrum bins", "must lie in 2..=1024"));
        }
        if !(2..=1024).contains(&self.preint_size) {
            return Err(Error::invalid(
                "pre-integration size",
                "must lie in 2..=1024",
            ));
        }
        if !(2..=64).contains(&self.block) {
            return Err(Error::invalid("block", "must lie in 2..=64 voxels"));
        }
        if !(self.ert_threshold > 0.0 && self.ert_threshold <= 1.0) {
            return Err(Error::invalid("ert threshold", "must lie in (0, 1]"));
        }
        if self.background.iter().any(|c| !(0.0..=1.0).contains(c)) {
            return Err(Error::invalid("background", "must lie in [0, 1]"));
        }
        Ok(())
    }
}

// ------------------------------------------------------------------------------ spectra

/// The smallest bin `k ≥ 1` such that bins `1..=k` hold the fraction `energy` of the
/// energy of bins `1..` (bin 0, DC, excluded); 0 when that energy vanishes.
pub fn cutoff_bin(bin_energy: &[f64], energy: f64) -> usize {
    let total: f64 = bin_energy.iter().skip(1).sum();
    if total <= 1e-24 * bin_energy.first().copied().unwrap_or(0.0).max(1e-300) || total <= 0.0 {
        return 0;
    }
    let target = energy * total;
    let mut acc = 0.0;
    for (k, e) in bin_energy.iter().enumerate().skip(1) {
        acc += e;
        if acc >= target * (1.0 - 1e-12) {
            return k;
        }
    }
    bin_energy.len() - 1
}

/// The cut-off frequency (cycles per unit) of a 1D signal sampled at the midpoints of
/// `n` cells of width `spacing`: mirrored to `2n` samples, FFT (rustfft), energy per
/// frequency `k/(2n·spacing)`, [`cutoff_bin`].
pub fn cutoff_1d(samples: &[f64], spacing: f64, energy: f64) -> f64 {
    let n = samples.len();
    if n == 0 {
        return 0.0;
    }
    let m = 2 * n;
    let mut z: Vec<Complex<f64>> = (0..m)
        .map(|i| Complex::new(samples[if i < n { i } else { m - 1 - i }], 0.0))
        .collect();
    super::fft::fft_nd(&mut z, &[m], Direction::Forward, Normalization::None);
    let mut bins = vec![0.0; n + 1];
    for (k, v) in z.iter().enumerate() {
        bins[k.min(m - k)] += v.norm_sqr();
    }
    cutoff_bin(&bins, energy) as f64 / (m as f64 * spacing)
}

/// Samples per table bin when the transfer function is analysed.
pub const SPECTRUM_OVERSAMPLING: usize = 16;

/// `ν_g(I)`: the cut-off frequency (cycles per mapped value) of the transfer function's
/// opacity on every interval `I = [d0 + i·Δ, d0 + j·Δ]`, `0 ≤ i < j ≤ bins`,
/// `Δ = (d1 − d0)/bins`. Independent of the window map.
#[derive(Clone, Debug, PartialEq)]
pub struct SpectralTable {
    pub bins: usize,
    pub domain: [f64; 2],
    /// `nu[i·(bins + 1) + j]` for `i < j` (other entries 0).
    pub nu: Vec<f64>,
}

/// The opacity's cut-off frequency on `[lo, hi]` (mapped values), from
/// `SPECTRUM_OVERSAMPLING` exact samples per table bin of width `bin`.
pub fn interval_cutoff(tf: &TransferFunction, lo: f64, hi: f64, bin: f64, energy: f64) -> f64 {
    let n = (((hi - lo) / bin).round() as usize).max(1) * SPECTRUM_OVERSAMPLING;
    let h = (hi - lo) / n as f64;
    let s: Vec<f64> = (0..n)
        .map(|m| tf.eval(lo + (m as f64 + 0.5) * h)[3])
        .collect();
    cutoff_1d(&s, h, energy)
}

/// Builds `ν_g(I)` for every interval of `bins` bins over the domain.
pub fn spectral_table(tf: &TransferFunction, bins: usize, energy: f64) -> SpectralTable {
    let [d0, d1] = tf.domain;
    let bin = (d1 - d0) / bins as f64;
    let w = bins + 1;
    let nu: Vec<f64> = (0..w * w)
        .into_par_iter()
        .map(|idx| {
            let (i, j) = (idx / w, idx % w);
            if i < j {
                interval_cutoff(tf, d0 + i as f64 * bin, d0 + j as f64 * bin, bin, energy)
            } else {
                0.0
            }
        })
        .collect();
    SpectralTable {
        bins,
        domain: tf.domain,
        nu,
    }
}

impl SpectralTable {
    /// The bins `(i, j)`, `i < j`, of the smallest table interval covering the mapped
    /// interval `[lo, hi]` (clamped to the domain, where the transfer function is
    /// constant beyond). Mirrors `shaders/adaptive.wgsl: spectrum_lookup`.
    #[inline]
    pub fn bins_of<R: Real>(&self, lo: R, hi: R) -> (usize, usize) {
        let m = self.bins as f64;
        let d0 = R::of(self.domain[0]);
        let inv = R::of(m / (self.domain[1] - self.domain[0]));
        let top = R::of(m);
        let i = ((lo - d0) * inv).floor().max(R::zero()).min(top);
        let j = ((hi - d0) * inv).ceil().max(R::zero()).min(top);
        let (mut i, mut j) = (i.to_usize().unwrap_or(0), j.to_usize().unwrap_or(0));
        if j <= i {
            if i >= self.bins {
                i = self.bins - 1;
            }
            j = i + 1;
        }
        (i, j)
    }
    /// `ν_g` of the table interval covering `[lo, hi]`.
    #[inline]
    pub fn lookup<R: Real>(&self, lo: R, hi: R) -> f64 {
        let (i, j) = self.bins_of(lo, hi);
        self.nu[i * (self.bins + 1) + j]
    }
}

// ----------------------------------------------------------------- importance volume

/// Half-width of the importance volume's max filter for a largest step `t_max`.
pub fn importance_radius(t_max: f64) -> usize {
    (t_max + 1.5).ceil() as usize
}

/// The largest one-sided difference of `grid` at voxel `(i, j, k)` along `axis`
/// (clamped at the border, where the trilinear field is constant).
/// Mirrors `shaders/adaptive_importance.wgsl: axis_difference`.
#[inline]
pub fn axis_difference<R: Real>(grid: &Grid<R>, i: usize, j: usize, k: usize, axis: usize) -> R {
    let (i, j, k) = (i as isize, j as isize, k as isize);
    let mut e = [0isize; 3];
    e[axis] = 1;
    let c = grid.at_clamped(i, j, k);
    let fwd = grid.at_clamped(i + e[0], j + e[1], k + e[2]) - c;
    let bwd = c - grid.at_clamped(i - e[0], j - e[1], k - e[2]);
    fwd.abs().max(bwd.abs())
}

/// The maximum of `g` over a window of half-width `r` along `axis` (clamped).
pub fn max_filter_axis<R: Real>(g: &Grid<R>, axis: usize, r: usize) -> Grid<R> {
    let [nx, ny, _] = g.dims;
    let n = g.dims[axis];
    let data = (0..g.data.len())
        .into_par_iter()
        .map(|idx| {
            let p = [idx % nx, (idx / nx) % ny, idx / (nx * ny)];
            let lo = p[axis].saturating_sub(r);
            let hi = (p[axis] + r).min(n - 1);
            let mut q = p;
            let mut m = R::zero();
            for x in lo..=hi {
                q[axis] = x;
                m = m.max(g.data[q[0] + nx * (q[1] + ny * q[2])]);
            }
            m
        })
        .collect();
    Grid { dims: g.dims, data }
}

/// The importance volume: per axis, [`axis_difference`] max-filtered over the cube of
/// half-width [`importance_radius`]`(t_max)` (separably, x then y then z).
pub fn importance_volume<R: Real>(grid: &Grid<R>, t_max: f64) -> [Grid<R>; 3] {
    let [nx, ny, _] = grid.dims;
    let r = importance_radius(t_max);
    std::array::from_fn(|axis| {
        let d = Grid {
            dims: grid.dims,
            data: (0..grid.data.len())
                .into_par_iter()
                .map(|idx| axis_difference(grid, idx % nx, (idx / nx) % ny, idx / (nx * ny), axis))
                .collect(),
        };
        let d = max_filter_axis(&d, 0, r);
        let d = max_filter_axis(&d, 1, r);
        max_filter_axis(&d, 2, r)
    })
}

// ----------------------------------------------------------------------- direct sampling

/// Mirrors a cube of `n³` samples (x fastest) into `(2n)³` complex values.
pub fn mirror_3d(samples: &[f64], n: usize) -> Vec<Complex<f64>> {
    let m = 2 * n;
    let f = |i: usize| if i < n { i } else { m - 1 - i };
    let mut out = Vec::with_capacity(m * m * m);
    for k in 0..m {
        for j in 0..m {
            for i in 0..m {
                out.push(Complex::new(samples[f(i) + n * (f(j) + n * f(k))], 0.0));
            }
        }
    }
    out
}

/// The radial cut-off frequency (cycles per unit) of the spectrum of a mirrored cube of
/// side `m` samples `spacing` apart: energy binned by `⌈|k|⌉` (k folded to `min(k, m−k)`
/// per axis), then [`cutoff_bin`].
pub fn radial_cutoff(spectrum: &[Complex<f64>], m: usize, spacing: f64, energy: f64) -> f64 {
    let fold = |k: usize| k.min(m - k) as f64;
    let nb = (3.0f64.sqrt() * (m / 2) as f64).ceil() as usize + 2;
    let mut bins = vec![0.0; nb];
    for (idx, v) in spectrum.iter().enumerate() {
        let (i, j, k) = (idx % m, (idx / m) % m, idx / (m * m));
        let r = (fold(i).powi(2) + fold(j).powi(2) + fold(k).powi(2)).sqrt();
        bins[(r - 1e-9).ceil().max(0.0) as usize] += v.norm_sqr();
    }
    cutoff_bin(&bins, energy) as f64 / (m as f64 * spacing)
}

/// Per-block steps of direct sampling.
#[derive(Clone, Debug, PartialEq)]
pub struct DirectSteps {
    /// Block edge in voxels.
    pub block: usize,
    /// Blocks per axis.
    pub blocks: [usize; 3],
    /// The cut-off frequency of `g ∘ Ψ ∘ f` per block (cycles per voxel).
    pub nu: Vec<f64>,
    /// The step per block (voxels): clamped, minimised over reachable blocks.
    pub step: Vec<f64>,
}

/// The classified opacity `α(Ψ(f))` of block `b` sampled at half-voxel spacing:
/// `(2B)³` points `x = b·B − ½ + (q + ½)/2`.
pub fn block_samples<R: Real>(
    grid: &Grid<R>,
    lut: &LutR<R>,
    block: usize,
    b: [usize; 3],
) -> Vec<f64> {
    let n = 2 * block;
    let mut out = Vec::with_capacity(n * n * n);
    let c = |bb: usize, q: usize| R::of((bb * block) as f64 - 0.5 + (q as f64 + 0.5) * 0.5);
    for qz in 0..n {
        for qy in 0..n {
            for qx in 0..n {
                let p = V3::new(c(b[0], qx), c(b[1], qy), c(b[2], qz));
                out.push(lut.classify(sample(grid, Filter::Trilinear, p))[3].f64());
            }
        }
    }
    out
}

/// Direct sampling's steps: the spectrum of every block of the classified volume.
pub fn direct_steps<R: Real>(
    grid: &Grid<R>,
    tf: &TransferFunction,
    settings: &AdaptiveSettings,
) -> DirectSteps {
    let lut: LutR<R> = tf.lut(crate::transfer::DEFAULT_LUT_SIZE).to_real();
    let bsz = settings.block;
    let blocks = grid.dims.map(|n| n.div_ceil(bsz));
    let count = blocks[0] * blocks[1] * blocks[2];
    let nu: Vec<f64> = (0..count)
        .into_par_iter()
        .map(|idx| {
            let b = [
                idx % blocks[0],
                (idx / blocks[0]) % blocks[1],
                idx / (blocks[0] * blocks[1]),
            ];
            let s = block_samples(grid, &lut, bsz, b);
            let (lo, hi) = s
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                    (l.min(v), h.max(v))
                });
            if hi - lo <= 1e-12 {
                return 0.0;
            }
            let mut z = mirror_3d(&s, 2 * bsz);
            let m = 4 * bsz;
            super::fft::fft_nd(&mut z, &[m, m, m], Direction::Forward, Normalization::None);
            radial_cutoff(&z, m, 0.5, settings.energy)
        })
        .collect();
    let own: Vec<f64> = nu
        .iter()
        .map(|&v| clamp_step(step_for_frequency(v, settings.oversampling), settings))
        .collect();
    // A step starts at a point whose nearest voxel is in block b, i.e. within
    // [bB − ½, (b+1)B − ½), and goes at most T_max: blocks b ± ⌈T_max/B⌉ cover it (block
    // k's samples span [kB − ½, (k+1)B − ½]).
    let reach = (settings.t_max / bsz as f64).ceil() as isize;
    let step = (0..count)
        .map(|idx| {
            let b = [
                (idx % blocks[0]) as isize,
                ((idx / blocks[0]) % blocks[1]) as isize,
                (idx / (blocks[0] * blocks[1])) as isize,
            ];
            let mut m = f64::INFINITY;
            for dz in -reach..=reach {
                for dy in -reach..=reach {
                    for dx in -reach..=reach {
                        let q = [b[0] + dx, b[1] + dy, b[2] + dz];
                        if (0..3).all(|a| q[a] >= 0 && q[a] < blocks[a] as isize) {
                            let qi = q[0] as usize
                                + blocks[0] * (q[1] as usize + blocks[1] * q[2] as usize);
                            m = m.min(own[qi]);
                        }
                    }
                }
            }
            m
        })
        .collect();
    DirectSteps {
        block: bsz,
        blocks,
        nu,
        step,
    }
}

/// `1 / (2·osf·ν)`, infinite for `ν = 0`.
#[inline]
pub fn step_for_frequency(nu: f64, osf: f64) -> f64 {
    if nu > 0.0 {
        1.0 / (2.0 * osf * nu)
    } else {
        f64::INFINITY
    }
}

fn clamp_step(t: f64, s: &AdaptiveSettings) -> f64 {
    t.max(s.step).min(s.t_max)
}

// ------------------------------------------------------------------------- the caster

/// Everything the rays of one render read.
#[derive(Clone, Debug)]
pub struct AdaptiveScene<R> {
    pub grid: Grid<R>,
    pub affine: DMat4,
    pub preint: PreintTable<R>,
    /// The window map `Ψ(t) = a·t + b` of the transfer function.
    pub window: (f64, f64),
    pub spectrum: Option<SpectralTable>,
    pub importance: Option<[Grid<R>; 3]>,
    pub direct: Option<DirectSteps>,
}

/// Builds what `settings.sampling` needs: the pre-integrated table always, the spectral
/// table and importance volume for adaptive, the block spectra for direct.
pub fn prepare<R: Real>(
    volume: &AnyVolume,
    tf: &TransferFunction,
    settings: &AdaptiveSettings,
) -> Result<AdaptiveScene<R>> {
    settings.validate()?;
    tf.validate()?;
    volume.check_finite("volume")?;
    let grid = Grid::<R>::from_any(volume);
    let adaptive = settings.sampling == Sampling::Adaptive;
    let direct = settings.sampling == Sampling::Direct;
    Ok(AdaptiveScene {
        preint: preintegrate(tf, settings.preint_size),
        window: (tf.window.a, tf.window.b),
        spectrum: adaptive.then(|| spectral_table(tf, settings.spectrum_bins, settings.energy)),
        importance: adaptive.then(|| importance_volume(&grid, settings.t_max)),
        direct: direct.then(|| direct_steps(&grid, tf, settings)),
        affine: volume.affine(),
        grid,
    })
}

/// Renders with precision `R` (prepares, then casts).
pub fn render<R: Real>(
    volume: &AnyVolume,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &AdaptiveSettings,
) -> Result<RenderOutput> {
    check_cost(volume.dims(), camera, settings)?;
    let scene = prepare::<R>(volume, tf, settings)?;
    render_prepared(&scene, camera, settings)
}

/// The nearest voxel of `p`, clamped to the grid.
/// Mirrors `shaders/adaptive.wgsl: nearest_voxel`.
#[inline]
fn nearest_voxel<R: Real>(p: V3<R>, dims: [usize; 3]) -> [usize; 3] {
    std::array::from_fn(|a| {
        let v = (p.0[a] + R::of(0.5)).floor().to_isize().unwrap_or(0);
        v.clamp(0, dims[a] as isize - 1) as usize
    })
}

/// The adaptive step at `p` with value `f0` for unit index direction `d` (eqs. 5–8).
/// Mirrors `shaders/adaptive.wgsl: adaptive_step`.
#[inline]
pub fn adaptive_step<R: Real>(
    scene: &AdaptiveScene<R>,
    settings: &AdaptiveSettings,
    p: V3<R>,
    f0: R,
    d: V3<R>,
) -> R {
    let (Some(imp), Some(spec)) = (&scene.importance, &scene.spectrum) else {
        return R::of(settings.step);
    };
    let t_max = R::of(settings.t_max);
    let v = nearest_voxel(p, scene.grid.dims);
    let vi = v[0] + scene.grid.dims[0] * (v[1] + scene.grid.dims[1] * v[2]);
    let gd = d.x().abs() * imp[0].data[vi]
        + d.y().abs() * imp[1].data[vi]
        + d.z().abs() * imp[2].data[vi];
    if gd <= R::zero() {
        return t_max;
    }
    let (a, b) = (R::of(scene.window.0), R::of(scene.window.1));
    let (s_min, s_max) = (f0 - gd * t_max, f0 + gd * t_max);
    let (u0, u1) = (a * s_min + b, a * s_max + b);
    let nu = R::of(spec.lookup(u0.min(u1), u0.max(u1)));
    let denom = R::of(2.0 * settings.oversampling) * nu * a.abs() * gd;
    let t = if denom > R::zero() {
        R::one() / denom
    } else {
        t_max
    };
    t.max(R::of(settings.step)).min(t_max)
}

/// Direct sampling's step at `p`. Mirrors `shaders/adaptive.wgsl: direct_step`.
#[inline]
pub fn direct_step<R: Real>(scene: &AdaptiveScene<R>, settings: &AdaptiveSettings, p: V3<R>) -> R {
    let Some(ds) = &scene.direct else {
        return R::of(settings.step);
    };
    let v = nearest_voxel(p, scene.grid.dims);
    let b = v.map(|x| x / ds.block);
    R::of(ds.step[b[0] + ds.blocks[0] * (b[1] + ds.blocks[1] * b[2])])
}

/// Refuses an adaptive render of the `dims` volume with invalid settings or too many
/// samples per ray or per frame at its smallest step
/// ([`crate::settings::check_ray_work`]), before anything is prepared. The CPU and GPU
/// casters and `voxlab render --sampling … --dry-run` call it.
pub(crate) fn check_cost(
    dims: [usize; 3],
    camera: &Camera,
    settings: &AdaptiveSettings,
) -> Result<()> {
    settings.validate()?;
    crate::settings::check_ray_work(
        "adaptive render",
        settings.step,
        crate::volume::diagonal(dims) / settings.step,
        camera,
    )
}

/// Renders a prepared scene.
pub fn render_prepared<R: Real>(
    scene: &AdaptiveScene<R>,
    camera: &Camera,
    settings: &AdaptiveSettings,
) -> Result<RenderOutput> {
    let dims = scene.grid.dims;
    check_cost(dims, camera, settings)?;
    let to_index = scene.affine.inverse();
    let (w, h) = (camera.width, camera.height);
    let mut image = Frame::new(w, h, 4);
    let mut counts = vec![0u32; w * h];
    image
        .data
        .par_chunks_mut(w * 4)
        .zip(counts.par_chunks_mut(w))
        .enumerate()
        .for_each(|(row, (pixels, row_counts))| {
            for col in 0..w {
                let ray = camera.ray(col, row);
                let o = V3::<R>::from_dvec(to_index.transform_point3(ray.origin));
                let d = V3::<R>::from_dvec(to_index.transform_vector3(ray.dir));
                let (px, n) = cast_ray(scene, settings, o, d, R::of(ray.t_min));
                for c in 0..4 {
                    pixels[col * 4 + c] = px[c].f64();
                }
                row_counts[col] = n;
            }
        });
    Ok(RenderOutput::from_counts(
        image,
        &counts,
        settings.sample_count,
    ))
}

/// An adaptive ray through the volume's box, in index space: it enters at `p0` and
/// runs `len` voxels along the unit direction `dir`.
/// Mirrors `shaders/adaptive.wgsl: AdaptiveRay`.
#[derive(Clone, Copy, Debug)]
pub struct AdaptiveRay<R> {
    pub p0: V3<R>,
    pub dir: V3<R>,
    pub len: R,
}

/// What an adaptive ray carries from one step to the next (and, on the GPU, from one
/// brick to the next): the colour and opacity composited so far, where the next step
/// starts (`s` voxels along the ray, step `k`) and the value there (`f0`), the samples
/// read, whether the first sample was read (`started`) and whether the ray ended by
/// early termination (`done`). Mirrors `shaders/adaptive.wgsl: AdaptiveState`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AdaptiveState<R> {
    pub c: [R; 3],
    pub a: R,
    pub s: R,
    pub f0: R,
    pub k: u32,
    pub taken: u32,
    pub started: bool,
    pub done: bool,
}

/// The ray from index-space origin `o` along `d` (per unit of `t`, from `t_min`)
/// through the box of a `dims` volume; `None` when it misses.
/// Mirrors `shaders/adaptive.wgsl: adaptive_ray`.
#[inline]
pub fn adaptive_ray<R: Real>(
    dims: [usize; 3],
    o: V3<R>,
    d: V3<R>,
    t_min: R,
) -> Option<AdaptiveRay<R>> {
    let (t_in, t_out) = intersect_box(o, d, V3::splat(R::of(-0.5)), box_hi(dims))?;
    let t_in = t_in.max(t_min);
    if t_out <= t_in {
        return None;
    }
    let speed = d.length();
    Some(AdaptiveRay {
        p0: o + d * t_in,
        dir: d * (R::one() / speed),
        len: (t_out - t_in) * speed,
    })
}

/// The state of `ray` before its first step: the value where it enters, one sample.
/// Mirrors `shaders/adaptive.wgsl: adaptive_start`.
#[inline]
pub fn adaptive_start<R: Real>(scene: &AdaptiveScene<R>, ray: &AdaptiveRay<R>) -> AdaptiveState<R> {
    AdaptiveState {
        f0: sample(&scene.grid, Filter::Trilinear, ray.p0),
        taken: 1,
        started: true,
        ..Default::default()
    }
}

/// Whether `st` has a step left on `ray`.
#[inline]
pub fn adaptive_going<R: Real>(st: &AdaptiveState<R>, ray: &AdaptiveRay<R>) -> bool {
    !st.done && st.s < ray.len
}

/// One step of `ray` from `st` (which has one left: [`adaptive_going`]): its length by
/// the sampling, the value at its end, the pre-integrated segment composited front to
/// back; `done` once the opacity reaches the early-termination threshold.
/// Mirrors `shaders/adaptive.wgsl: adaptive_advance`.
#[inline]
pub fn adaptive_advance<R: Real>(
    scene: &AdaptiveScene<R>,
    settings: &AdaptiveSettings,
    ray: &AdaptiveRay<R>,
    st: &mut AdaptiveState<R>,
) {
    let AdaptiveRay { p0, dir, len } = *ray;
    let s = st.s;
    let p = p0 + dir * s;
    let s1 = match settings.sampling {
        Sampling::Regular => R::of((st.k + 1) as f64) * R::of(settings.step),
        Sampling::Adaptive => s + adaptive_step(scene, settings, p, st.f0, dir),
        Sampling::Direct => s + direct_step(scene, settings, p),
    };
    let s1 = s1.min(len);
    let f1 = sample(&scene.grid, Filter::Trilinear, p0 + dir * s1);
    st.taken += 1;
    let e = scene.preint.step(st.f0, f1, s1 - s);
    let wgt = R::one() - st.a;
    for (c, e) in st.c.iter_mut().zip(e) {
        *c = *c + wgt * e;
    }
    st.a = st.a + wgt * e[3];
    if st.a >= R::of(settings.ert_threshold) {
        st.done = true;
        return;
    }
    st.s = s1;
    st.f0 = f1;
    st.k += 1;
}

/// One ray from index-space origin `o` along `d` (per unit of `t`): the pixel and the
/// number of samples read: the march of `shaders/adaptive.wgsl`'s entry point, finished
/// over the background as it finishes it.
/// Mirrors `shaders/adaptive.wgsl: adaptive_run`.
pub fn cast_ray<R: Real>(
    scene: &AdaptiveScene<R>,
    settings: &AdaptiveSettings,
    o: V3<R>,
    d: V3<R>,
    t_min: R,
) -> ([R; 4], u32) {
    let bg = settings.background.map(R::of);
    let Some(ray) = adaptive_ray(scene.grid.dims, o, d, t_min) else {
        return ([bg[0] * bg[3], bg[1] * bg[3], bg[2] * bg[3], bg[3]], 0);
    };
    let mut st = adaptive_start(scene, &ray);
    while adaptive_going(&st, &ray) {
        adaptive_advance(scene, settings, &ray, &mut st);
    }
    (over_background(st.c, st.a, bg), st.taken)
}

/// A medical-style transfer function over `[lo, hi]`: transparent up to `threshold`,
/// then a sharp opacity ramp of `width` (to 0.3 per voxel), rising slowly to 0.5 at
/// `hi`; warm colours turning white. What `voxlab adaptive` uses by default.
pub fn medical_tf(lo: f64, hi: f64, threshold: f64, width: f64) -> TransferFunction {
    use crate::transfer::{ControlPoint, WindowMap};
    let p = |value: f64, rgba: [f64; 4]| ControlPoint { value, rgba };
    TransferFunction {
        name: "medical".into(),
        domain: [lo, hi],
        points: vec![
            p(lo, [0.3, 0.15, 0.1, 0.0]),
            p(threshold, [0.8, 0.4, 0.3, 0.0]),
            p(threshold + width, [0.95, 0.8, 0.65, 0.3]),
            p(hi, [1.0, 1.0, 0.95, 0.5]),
        ],
        window: WindowMap::default(),
        interpolation: Default::default(),
        faux_shading: None,
    }
}
