//! Pre-integrated transfer functions (Engel, Kraus & Ertl 2001), for steps of any length.
//!
//! Between two samples a ray sees the data value go from `s_f` (front) to `s_b` (back);
//! pre-integration assumes it does so *linearly* and integrates the emission–absorption
//! equation along the step exactly, instead of classifying one sample:
//!
//! ```text
//! τ(u)   = −ln(1 − α(u))                       extinction per reference step Δs₀ = 1 voxel
//! α(f,b) = 1 − exp(−∫₀¹ τ(s(x)) dx)            s(x) = s_f + x (s_b − s_f)
//! C(f,b) = ∫₀¹ c(s(x)) τ(s(x)) exp(−∫₀ˣ τ) dx    (opacity-weighted colour)
//! ```
//!
//! The table holds `(C_r, C_g, C_b, α)` for a step of the reference length `Δs₀ = 1`
//! voxel, on an `n × n` grid of (front, back) values spanning the transfer function's
//! domain: entry `(i, j)` (front `i`, back `j`, stored at `j·n + i`) is the integral from
//! table coordinate `i` to `j`, where the table coordinate of raw value `t` is the lookup
//! table's `x = (Ψ(t) − d0)/(d1 − d0)·(n − 1)` ([`crate::transfer::LutR`]).
//!
//! **The definition we compute.** Entry `(i, j)` is the front-to-back composite of
//! `K = 8 (|j − i| + 1)` equal sub-steps, each represented by its midpoint value
//! classified through the piecewise-linear table, with the opacity corrected to the
//! sub-step's length `1/K`. The transfer function is linear inside each table cell and
//! every cell the step crosses gets at least 8 sub-steps, so this is the integral up to a
//! midpoint-rule error of order `1/K²` (the tests bound it).
//!
//! **Steps of other lengths.** Adaptive sampling takes steps of length `Δs ≠ Δs₀`. With
//! the end values fixed, the optical depth of a step is proportional to its length
//! (`∫₀^Δs τ(s(x/Δs)) dx = Δs ∫₀¹ τ`), so the opacity correction
//! `α' = 1 − (1 − α)^(Δs/Δs₀)` applied to the pre-integrated `α` is **exact**. The colour
//! is corrected likewise, `C' = C · α'/α` (it keeps the step's average colour): exact
//! when the colour is constant along the step, an approximation otherwise, because the
//! self-attenuation inside the step changes with its length. `tests/adaptive.rs`
//! measures that error against a finely sampled reference
//! (`preintegrated_steps_match_fine_reference`). We chose the correction over a third
//! table dimension over step length: it is exact for opacity, costs nothing, and its
//! measured colour error is far below the sampling error it replaces.
//!
//! The GPU twins: `shaders/preintegrate.wgsl` (the table) and `shaders/adaptive.wgsl`
//! (`preint_lookup`, `preint_step`).

use crate::real::Real;
use crate::transfer::{LutR, TransferFunction};
use rayon::prelude::*;

/// Default table resolution (entries per axis).
pub const DEFAULT_PREINT_SIZE: usize = 256;

/// Sub-steps per table cell crossed (and the floor for a step within one cell).
pub const SUBSTEPS_PER_CELL: usize = 8;

/// A pre-integrated transfer function: `n × n` entries `(C_r, C_g, C_b, α)` for a step
/// of one voxel, front value along the fast axis.
#[derive(Clone, Debug)]
pub struct PreintTable<R> {
    /// Entries per axis.
    pub n: usize,
    /// Raw value → table coordinate: `x = scale·t + offset` (window map folded in).
    pub scale: R,
    pub offset: R,
    /// `entries[j·n + i]`: from front coordinate `i` to back coordinate `j`.
    pub entries: Vec<[R; 4]>,
}

/// The lookup table's RGBA at table coordinate `x` (linear between entries, clamped).
/// Mirrors `shaders/preintegrate.wgsl: lut_at`.
#[inline]
pub fn lut_at<R: Real>(entries: &[[R; 4]], x: R) -> [R; 4] {
    let n = entries.len();
    let x = x.max(R::zero()).min(R::of((n - 1) as f64));
    let i0 = x.floor();
    let f = x - i0;
    let i0 = i0.to_usize().unwrap_or(0).min(n - 1);
    let i1 = (i0 + 1).min(n - 1);
    let (a, b) = (&entries[i0], &entries[i1]);
    std::array::from_fn(|c| a[c] + f * (b[c] - a[c]))
}

/// One table entry: the step from table coordinate `xf` to `xb` by the sub-step
/// definition above. Mirrors `shaders/preintegrate.wgsl: preint_entry`.
pub fn preint_entry<R: Real>(entries: &[[R; 4]], xf: R, xb: R) -> [R; 4] {
    let cells = (xb - xf).abs().ceil().to_usize().unwrap_or(0);
    let k = SUBSTEPS_PER_CELL * (cells + 1);
    let inv_k = R::one() / R::of(k as f64);
    let mut c = [R::zero(); 3];
    let mut a = R::zero();
    for m in 0..k {
        let x = xf + (xb - xf) * ((R::of(m as f64) + R::of(0.5)) * inv_k);
        let s = lut_at(entries, x);
        if s[3] <= R::zero() {
            continue;
        }
        let alpha = R::one() - (R::one() - s[3]).powf(inv_k);
        let w = (R::one() - a) * alpha;
        for ch in 0..3 {
            c[ch] = c[ch] + w * s[ch];
        }
        a = a + w;
    }
    [c[0], c[1], c[2], a]
}

/// Builds the pre-integrated table of `n ≥ 2` entries per axis over the transfer
/// function's domain.
pub fn preintegrate<R: Real>(tf: &TransferFunction, n: usize) -> PreintTable<R> {
    let lut: LutR<R> = tf.lut(n.max(2)).to_real();
    let n = lut.entries.len();
    let entries: Vec<[R; 4]> = (0..n * n)
        .into_par_iter()
        .map(|idx| {
            let (i, j) = (idx % n, idx / n);
            preint_entry(&lut.entries, R::of(i as f64), R::of(j as f64))
        })
        .collect();
    PreintTable {
        n,
        scale: lut.scale,
        offset: lut.offset,
        entries,
    }
}

impl<R: Real> PreintTable<R> {
    /// The table coordinate of raw value `t`, clamped to the table.
    #[inline]
    pub fn coord(&self, t: R) -> R {
        (self.scale * t + self.offset)
            .max(R::zero())
            .min(R::of((self.n - 1) as f64))
    }

    /// Bilinear lookup of the reference-step entry for raw front and back values.
    /// Mirrors `shaders/adaptive.wgsl: preint_lookup`.
    #[inline]
    pub fn lookup(&self, front: R, back: R) -> [R; 4] {
        let n = self.n;
        let (x, y) = (self.coord(front), self.coord(back));
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let x0 = x0.to_usize().unwrap_or(0).min(n - 1);
        let y0 = y0.to_usize().unwrap_or(0).min(n - 1);
        let (x1, y1) = ((x0 + 1).min(n - 1), (y0 + 1).min(n - 1));
        let e = |i: usize, j: usize| &self.entries[j * n + i];
        let (a, b, c, d) = (e(x0, y0), e(x1, y0), e(x0, y1), e(x1, y1));
        std::array::from_fn(|ch| {
            let lo = a[ch] + fx * (b[ch] - a[ch]);
            let hi = c[ch] + fx * (d[ch] - c[ch]);
            lo + fy * (hi - lo)
        })
    }

    /// Colour and opacity of a step of `len` voxels (reference step 1) from raw value
    /// `front` to `back`: `α' = 1 − (1 − α)^len` (exact), `C' = C·α'/α`.
    /// Mirrors `shaders/adaptive.wgsl: preint_step`.
    #[inline]
    pub fn step(&self, front: R, back: R, len: R) -> [R; 4] {
        let e = self.lookup(front, back);
        preint_step(e, len)
    }
}

/// Corrects a reference-step entry to a step of `len` reference steps.
/// Mirrors `shaders/adaptive.wgsl: preint_step`.
#[inline]
pub fn preint_step<R: Real>(e: [R; 4], len: R) -> [R; 4] {
    let a = e[3].max(R::zero()).min(R::one());
    if a <= R::zero() {
        return [R::zero(); 4];
    }
    let a2 = R::one() - (R::one() - a).powf(len);
    let k = a2 / a;
    [e[0] * k, e[1] * k, e[2] * k, a2]
}
