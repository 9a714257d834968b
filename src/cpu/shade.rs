//! One sample's colour, the primitives every CPU ray caster shares: classification
//! (1D or 2D transfer function, or pre-classified grids), Phong shading, the opacity
//! correction for the step length and front-to-back / back-to-front compositing.
//!
//! The casters (`cpu::raycast`, the modes of `cpu::modes`, the batched and packet
//! kernels of `cpu::march`, the multi-volume caster `cpu::multi`) import these; this
//! module imports none of them. The formulas are those of the ray caster's module docs
//! (`cpu::raycast`):
//!
//! - opacity correction `α' = 1 − (1 − α)^(Δs/Δs₀)` (`transmit_pow`);
//! - front to back `C += (1 − A) α' c`, `A += (1 − A) α'` (`under`, with early ray
//!   termination `under_until`); back to front `C = α' c + (1 − α') C`,
//!   `A = α' + (1 − α') A` (`over`); the result over the background at the end
//!   (`over_background`);
//! - Phong `c' = c (k_a + k_d |n·L|) + k_s |n·H|^s` with the world normal `n = −∇f/|∇f|`
//!   (two-sided), blended in from unshaded as `|∇f|` rises through the gradient
//!   threshold (`shade_gradient`).

use super::field::Field;
use super::filter::sample;
use super::grid::Grid;
use crate::real::{Real, M3, V3};
use crate::settings::Filter;
use crate::transfer::LutR;
use crate::transfer2d::Lut2R;
use glam::DMat4;

/// Shading constants in the working precision.
#[derive(Clone, Copy, Debug)]
pub struct ShadingR<R> {
    pub ambient: R,
    pub diffuse: R,
    pub specular: R,
    pub shininess: R,
}

/// What one ray's samples and steps need, prepared once per render: the index-space
/// box and steps, the classification tables, the shading constants and the
/// compositing's threshold and background. The ray caster's own set-up
/// (`cpu::raycast`) adds skipping, clipping and the modes' set-up around it.
pub(crate) struct SampleSetup<R> {
    /// World → index space.
    pub(crate) to_index: DMat4,
    /// Index-space gradient → world-space gradient (`J⁻ᵀ`).
    pub(crate) normal: M3<R>,
    /// The field's box `[lo, hi]` in index space.
    pub(crate) lo: V3<R>,
    pub(crate) hi: V3<R>,
    /// The step `Δs` and the reference step `Δs₀` the opacities are given for, in voxels.
    pub(crate) step: R,
    pub(crate) ref_step: R,
    pub(crate) lut: LutR<R>,
    /// The 2D transfer function's table (DVR, post-classification), if any.
    pub(crate) lut2: Option<Lut2R<R>>,
    /// Pre-classified opacity-weighted colour grids `(αr, αg, αb, α)`, if any, and the
    /// whole grid's voxel their voxel 0 is (a brick's origin, [`super::field::BrickField`];
    /// zero for a whole grid): `p` is sampled at `p − origin`, exactly.
    pub(crate) pre: Option<([Grid<R>; 4], V3<R>)>,
    pub(crate) filter: Filter,
    pub(crate) k: ShadingR<R>,
    pub(crate) shade: bool,
    /// The light's world direction; `None` for a headlight (back along the ray).
    pub(crate) light: Option<V3<R>>,
    /// The gradient magnitude at which shading is fully on.
    pub(crate) grad_thr: R,
    /// Early ray termination threshold.
    pub(crate) ert: R,
    pub(crate) bg: [R; 4],
}

/// Colour and opacity (per reference step) of the sample at `p`.
/// mirrors shaders/raycast.wgsl: classify_sample
#[inline]
pub(crate) fn classify_sample<R: Real, F: Field<R>>(
    field: &F,
    s: &SampleSetup<R>,
    p: V3<R>,
) -> ([R; 3], R) {
    match &s.pre {
        None => {
            let c = match &s.lut2 {
                // The world-space gradient magnitude, as the shading sees it.
                Some(l2) => {
                    l2.classify2d(field.value(p), s.normal.mul_vec(field.gradient(p)).length())
                }
                None => s.lut.classify(field.value(p)),
            };
            ([c[0], c[1], c[2]], c[3])
        }
        Some((g, origin)) => {
            let p = p - *origin;
            let a = sample(&g[3], s.filter, p).max(R::zero()).min(R::one());
            if a <= R::zero() {
                return ([R::zero(); 3], R::zero());
            }
            let un = |ch: usize| {
                (sample(&g[ch], s.filter, p) / a)
                    .max(R::zero())
                    .min(R::one())
            };
            ([un(0), un(1), un(2)], a)
        }
    }
}

/// Phong-shades a sample, blending in from unshaded where the gradient is tiny.
/// mirrors shaders/raycast.wgsl: shade_sample
#[inline]
pub(crate) fn shade_sample<R: Real, F: Field<R>>(
    field: &F,
    s: &SampleSetup<R>,
    p: V3<R>,
    rgb: [R; 3],
    light: V3<R>,
    half: V3<R>,
) -> [R; 3] {
    shade_gradient(
        field.gradient(p),
        s.grad_thr,
        &s.normal,
        &s.k,
        rgb,
        light,
        half,
    )
}

/// The shading of [`shade_sample`] from an index-space gradient `g`: Phong with the
/// world normal `−normal·g`, blended in from the unshaded colour as `|g|` rises from
/// ½ to 1 × `grad_thr`. Shared with the multi-volume caster (`cpu::multi`).
#[inline]
pub(crate) fn shade_gradient<R: Real>(
    g: V3<R>,
    grad_thr: R,
    normal: &M3<R>,
    k: &ShadingR<R>,
    rgb: [R; 3],
    light: V3<R>,
    half: V3<R>,
) -> [R; 3] {
    let mag = g.length();
    let two = R::of(2.0);
    let w = ((mag / grad_thr - R::of(0.5)) * two)
        .max(R::zero())
        .min(R::one());
    if w <= R::zero() {
        return rgb;
    }
    let n = -(normal.mul_vec(g)).normalize_or_zero();
    let lit = phong(rgb, n, light, half, k);
    [
        rgb[0] + w * (lit[0] - rgb[0]),
        rgb[1] + w * (lit[1] - rgb[1]),
        rgb[2] + w * (lit[2] - rgb[2]),
    ]
}

/// Phong shading of colour `c` with normal `n`, light `l` and half vector `h` (all
/// unit, world space; two-sided).
/// mirrors shaders/shared/shading.wgsl: phong
#[inline]
pub fn phong<R: Real>(c: [R; 3], n: V3<R>, l: V3<R>, h: V3<R>, k: &ShadingR<R>) -> [R; 3] {
    let ndl = n.dot(l).abs();
    let ndh = n.dot(h).abs();
    let diffuse = k.ambient + k.diffuse * ndl;
    let spec = k.specular * ndh.powf(k.shininess);
    [
        c[0] * diffuse + spec,
        c[1] * diffuse + spec,
        c[2] * diffuse + spec,
    ]
}

/// The light and half vectors of a ray with world direction `dir`: the light `light`
/// (a headlight, back along the ray, when `None`) and the unit bisector of it and the
/// view direction `−dir`. Mirrors `shaders/shared/shading.wgsl: light_half`
#[inline]
pub(crate) fn light_half<R: Real>(light: Option<V3<R>>, dir: glam::DVec3) -> (V3<R>, V3<R>) {
    let view = -V3::<R>::from_dvec(dir);
    let light = light.unwrap_or(view);
    (light, (light + view).normalize_or_zero())
}

/// `x^e` for the opacity correction `1 − (1 − α)^e`. The default step is half the
/// reference step, so `e = ½` is by far the commonest exponent: there the correctly
/// rounded square root stands in for the general power (the same value to within an
/// ulp, and several times cheaper); `e = 1` is `x` itself.
#[inline]
pub(crate) fn transmit_pow<R: Real>(x: R, e: R) -> R {
    if e == R::of(0.5) {
        x.sqrt()
    } else if e == R::one() {
        x
    } else {
        x.pow01(e)
    }
}

/// Front to back: one step's colour `rgb` and opacity `alpha` under the pixel so far
/// (`c`, `a`): `C += (1 − A) α c`, `A += (1 − A) α`.
#[inline(always)]
pub(crate) fn under<R: Real>(c: &mut [R; 3], a: &mut R, rgb: [R; 3], alpha: R) {
    let w = (R::one() - *a) * alpha;
    for ch in 0..3 {
        c[ch] = c[ch] + w * rgb[ch];
    }
    *a = *a + w;
}

/// [`under`], then true once `a` reaches the early-termination threshold `ert`.
#[inline(always)]
pub(crate) fn under_until<R: Real>(
    c: &mut [R; 3],
    a: &mut R,
    rgb: [R; 3],
    alpha: R,
    ert: R,
) -> bool {
    under(c, a, rgb, alpha);
    *a >= ert
}

/// Back to front: one step's colour `rgb` and opacity `alpha` over the pixel so far
/// (`c`, `a`): `C = α c + (1 − α) C`, `A = α + (1 − α) A`.
#[inline(always)]
pub(crate) fn over<R: Real>(c: &mut [R; 3], a: &mut R, rgb: [R; 3], alpha: R) {
    for ch in 0..3 {
        c[ch] = alpha * rgb[ch] + (R::one() - alpha) * c[ch];
    }
    *a = alpha + (R::one() - alpha) * *a;
}

/// The composited colour `c` and opacity `a` over the background `bg` (straight RGBA):
/// `C + (1 − A) bg_rgb bg_α`, `A + (1 − A) bg_α`.
/// mirrors shaders/shared/modes.wgsl: over_background
#[inline(always)]
pub(crate) fn over_background<R: Real>(c: [R; 3], a: R, bg: [R; 4]) -> [R; 4] {
    let t = R::one() - a;
    [
        c[0] + t * bg[0] * bg[3],
        c[1] + t * bg[1] * bg[3],
        c[2] + t * bg[2] * bg[3],
        a + t * bg[3],
    ]
}
