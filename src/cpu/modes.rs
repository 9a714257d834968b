//! Rendering modes beyond DVR/MIP/X-ray: MIDA, windowed MIP/MinIP and iso-surfaces.
//! The per-ray loops of the CPU oracle; `shaders/shared/modes.wgsl` holds their twins.
//!
//! Conventions are the ray caster's (`cpu::raycast`): a ray is cut into `n` steps, step
//! `k` is represented by its midpoint `t_k`, opacities are corrected for the step
//! length, `Δs/Δs₀`, and compositing is front to back, `C += (1 − A) α c`,
//! `A += (1 − A) α`, over the background at the end.
//!
//! **MIDA** (Bruckner & Gröller 2009, "Instant volume visualization using maximum
//! intensity difference accumulation"). With `s_i ∈ [0, 1]` the sample value normalised
//! by the volume's value range and `m_{i−1} = max_{j<i} s_j`, the growth of the running
//! maximum is `δ_i = s_i − m_{i−1}` where positive, else 0 (and 0 for the first sample).
//! For `γ ∈ [−1, 0]` the accumulated colour and opacity are attenuated by
//! `β_i = 1 − δ_i (1 + γ)`:
//!
//! ```text
//! C_i = β_i C_{i−1} + (1 − β_i A_{i−1}) α_i c_i
//! A_i = β_i A_{i−1} + (1 − β_i A_{i−1}) α_i
//! ```
//!
//! so at `γ = −1` (β ≡ 1) it is DVR exactly, and at `γ = 0` it is plain MIDA: what lies
//! in front of a new maximum fades in proportion to the rise. For `γ ∈ (0, 1]` the
//! result is blended with MIP, `C = (1 − γ) C_MIDA(0) + γ C_MIP`, where `C_MIP = α c` of
//! the first sample holding the ray's maximum (its transfer-function colour and
//! opacity, unshaded: which of a plateau's samples holds the maximum is decided by
//! rounding, while its value is not). At `γ = 1` it is that MIP colour. Because `A` may fall
//! (β < 1), MIDA never terminates rays early.
//!
//! **Window/level** (MIP, MinIP): `g = clamp((v − centre) / width + ½, 0, 1)`, the grey
//! level the window maps the projected value to. The map is non-decreasing, so it
//! commutes with max and min: the windowed MIP is the window applied to the MIP.
//! Presets: [`WINDOW_PRESETS`] (CT, in Hounsfield units).
//!
//! **Iso-surfaces.** Up to four iso-values `τ_j`, each with a colour and an opacity. A
//! ray crosses `τ` between consecutive samples `k − 1` and `k` when `(v_{k−1} ≥ τ) ≠
//! (v_k ≥ τ)`. The hit is refined by linear interpolation of the two samples,
//! `t = t_{k−1} + (τ − v_{k−1}) / (v_k − v_{k−1}) (t_k − t_{k−1})` (Fluør 2006 §2.4,
//! hit-point refinement), or without refinement taken at `t_k`. The hit is shaded at
//! its point with the DVR's Phong model (normal `−∇f/|∇f|`) and composited with its
//! opacity, hits of one interval in depth order, before sample `k` itself; with DVR on,
//! sample `k`'s DVR contribution follows, so surfaces and volume composite in depth
//! order. Opaque iso-surfaces end the ray at the first hit. Binary shadows (opaque
//! only): from the hit, samples `q_m = p + (m + 1) Δ L` toward the light `L` (step `Δ`
//! of the primary ray, in voxels) until the box is left; when any `q_m` lies on another
//! side of some `τ_j` than `q_0`, the hit is in shadow and keeps only the ambient term,
//! `c k_a`.

use super::field::Field;
use super::shade::{
    classify_sample, light_half, over_background, shade_sample, transmit_pow, under, SampleSetup,
};
use crate::error::{Error, Result};
use crate::real::{intersect_box, Real, V3};
use crate::settings::{Mode, RenderSettings, MAX_ISO_SURFACES};

/// CT window presets: (name, width, centre) in Hounsfield units, with a description.
pub const WINDOW_PRESETS: [(&str, f64, f64, &str); 6] = [
    ("brain", 80.0, 40.0, "brain parenchyma"),
    ("subdural", 250.0, 75.0, "blood next to bone"),
    ("abdomen", 400.0, 40.0, "abdominal soft tissue"),
    ("liver", 150.0, 30.0, "liver lesions"),
    ("lung", 1500.0, -600.0, "lung parenchyma"),
    ("bone", 1800.0, 400.0, "cortical and trabecular bone"),
];

/// The `[width, centre]` of a window preset, by name.
pub fn window_preset(name: &str) -> Result<[f64; 2]> {
    WINDOW_PRESETS
        .iter()
        .find(|p| p.0 == name)
        .map(|p| [p.1, p.2])
        .ok_or_else(|| {
            let names: Vec<&str> = WINDOW_PRESETS.iter().map(|p| p.0).collect();
            Error::invalid(
                "window preset",
                format!("unknown preset {name:?}; known: {}", names.join(", ")),
            )
        })
}

/// One iso-surface in the working precision.
#[derive(Clone, Copy, Debug)]
pub struct IsoR<R> {
    pub value: R,
    pub color: [R; 3],
    pub opacity: R,
}

/// What the modes of this module need, prepared once per render.
#[derive(Clone, Debug)]
pub struct ModeSetup<R> {
    pub gamma: R,
    /// The field's lowest value and the reciprocal of its range (MIDA normalisation).
    pub lo: R,
    pub inv_range: R,
    /// `[width, centre]` of the MIP/MinIP grey window.
    pub window: Option<[R; 2]>,
    /// The iso-surfaces this render draws (empty unless mode iso, or DVR with some).
    pub iso: Vec<IsoR<R>>,
    pub opaque: bool,
    pub shadows: bool,
    pub refine: bool,
}

impl<R: Real> ModeSetup<R> {
    pub fn new(s: &RenderSettings, value_range: (f64, f64)) -> Self {
        let (lo, hi) = value_range;
        let draws_iso = s.mode == Mode::Iso || s.mode == Mode::Dvr;
        ModeSetup {
            gamma: R::of(s.mida_gamma),
            lo: R::of(lo),
            inv_range: R::of(1.0 / (hi - lo).max(f64::MIN_POSITIVE)),
            window: s.window.map(|w| w.map(R::of)),
            iso: if draws_iso {
                s.iso_surfaces
                    .iter()
                    .map(|i| IsoR {
                        value: R::of(i.value),
                        color: i.color.map(R::of),
                        opacity: R::of(i.opacity),
                    })
                    .collect()
            } else {
                Vec::new()
            },
            opaque: s.iso_opaque,
            shadows: s.iso_shadows,
            refine: s.iso_refine,
        }
    }
}

/// A clipped ray in index space, cut into `n` steps of `dt` (the last one ends at
/// `t_out`), exactly as `cpu::raycast::cast_ray` cuts it.
#[derive(Clone, Copy, Debug)]
pub struct Span<R> {
    pub o: V3<R>,
    pub d: V3<R>,
    pub t_in: R,
    pub t_out: R,
    pub dt: R,
    pub n: usize,
    /// Voxels per unit t.
    pub speed: R,
}

impl<R: Real> Span<R> {
    /// Step k's bounds `(t_a, t_b)`. Mirrors `shaders/shared/rays.wgsl: segment_bounds`.
    #[inline]
    pub fn bounds(&self, k: usize) -> (R, R) {
        let ta = self.t_in + R::of(k as f64) * self.dt;
        let tb = if k + 1 == self.n {
            self.t_out
        } else {
            self.t_in + R::of((k + 1) as f64) * self.dt
        };
        (ta, tb)
    }
    /// Whether step k is a full step (neither the first nor the last), as
    /// `march::Steps::full`.
    #[inline]
    pub fn full(&self, k: usize) -> bool {
        k > 0 && k + 1 < self.n
    }
    /// Step k's midpoint parameter: `t_in + (k + ½)·dt` for a full step, the middle of
    /// its bounds otherwise (the rule of `march::Steps::segment`, so that a MIDA or
    /// iso-surface ray that reduces to DVR gives DVR's image to the bit).
    #[inline]
    pub fn t_mid(&self, k: usize) -> R {
        if self.full(k) {
            return self.t_in + (R::of(k as f64) + R::of(0.5)) * self.dt;
        }
        let (a, b) = self.bounds(k);
        (a + b) * R::of(0.5)
    }
    /// Step k's midpoint and length (`dt` exactly for a full step).
    #[inline]
    pub fn segment(&self, k: usize) -> (V3<R>, R) {
        let len = if self.full(k) {
            self.dt
        } else {
            let (a, b) = self.bounds(k);
            b - a
        };
        (self.o + self.d * self.t_mid(k), len)
    }
    /// Step k's opacity-correction exponent, as `march::Steps::exponent`.
    #[inline]
    pub fn exponent(&self, k: usize, len: R, ref_step: R, e_full: R) -> R {
        if self.full(k) {
            e_full
        } else {
            len * self.speed / ref_step
        }
    }
}

/// The grey level of `v` under the window `[width, centre]`:
/// `clamp((v − centre) / width + ½, 0, 1)`.
/// Mirrors `shaders/shared/modes.wgsl: window_map`.
#[inline]
pub fn window_map<R: Real>(v: R, window: [R; 2]) -> R {
    ((v - window[1]) / window[0] + R::of(0.5))
        .max(R::zero())
        .min(R::one())
}

/// The MIDA attenuation `β = 1 − δ (1 + min(γ, 0))` for a rise `δ ≥ 0` of the running
/// maximum. Mirrors `shaders/shared/modes.wgsl: mida_beta`.
#[inline]
pub fn mida_beta<R: Real>(delta: R, gamma: R) -> R {
    R::one() - delta * (R::one() + gamma.min(R::zero()))
}

/// The refined (or not) parameter of a crossing of `tau` between samples `(t0, v0)`
/// and `(t1, v1)`. Mirrors `shaders/shared/modes.wgsl: iso_hit_t`.
#[inline]
pub fn iso_hit_t<R: Real>(t0: R, v0: R, t1: R, v1: R, tau: R, refine: bool) -> R {
    if refine {
        t0 + (tau - v0) / (v1 - v0) * (t1 - t0)
    } else {
        t1
    }
}

/// Whether the field crosses `tau` between two values.
/// Mirrors `shaders/shared/modes.wgsl: crosses`.
#[inline]
pub fn crosses<R: Real>(v0: R, v1: R, tau: R) -> bool {
    (v0 >= tau) != (v1 >= tau)
}

/// The first crossing of `tau` along a span: the ray parameter of the hit, refined or
/// not, as the iso-surface renderer computes it; `None` when the ray never crosses.
pub fn first_iso_hit<R: Real, F: Field<R>>(
    field: &F,
    span: &Span<R>,
    tau: R,
    refine: bool,
) -> Option<R> {
    let mut t0 = span.t_mid(0);
    let mut v0 = field.value(span.o + span.d * t0);
    for k in 1..span.n {
        let t1 = span.t_mid(k);
        let v1 = field.value(span.o + span.d * t1);
        if crosses(v0, v1, tau) {
            return Some(iso_hit_t(t0, v0, t1, v1, tau, refine));
        }
        (t0, v0) = (t1, v1);
    }
    None
}

/// A MIDA ray's state after its first samples, front to back: everything a later
/// sample needs, so that a ray cut into runs (the bricks of a split render, one after
/// another in the ray's order) ends with the unsplit ray's state.
/// Mirrors `shaders/shared/modes_cast.wgsl: MidaState`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MidaState<R> {
    /// The accumulated premultiplied colour and opacity.
    pub c: [R; 3],
    pub a: R,
    /// The running maximum `m` of the normalised values (meaningful once `started`).
    pub running: R,
    /// The largest raw value so far and its sample's unshaded colour and opacity: the
    /// MIP colour of the blend for γ > 0.
    pub best: R,
    pub best_rgba: [R; 4],
    /// Whether the ray has taken a sample.
    pub started: bool,
}

impl<R: Real> Default for MidaState<R> {
    fn default() -> Self {
        MidaState {
            c: [R::zero(); 3],
            a: R::zero(),
            running: R::zero(),
            best: R::neg_infinity(),
            best_rgba: [R::zero(); 4],
            started: false,
        }
    }
}

/// Takes the MIDA sample at `p` (opacity-correction exponent `e`) into `st`.
/// Mirrors `shaders/shared/modes_cast.wgsl: mida_sample`.
#[allow(clippy::too_many_arguments)]
#[inline]
pub(crate) fn mida_sample<R: Real, F: Field<R>>(
    st: &mut MidaState<R>,
    field: &F,
    s: &SampleSetup<R>,
    m: &ModeSetup<R>,
    p: V3<R>,
    e: R,
    (light, half): (V3<R>, V3<R>),
) {
    let v = field.value(p);
    let sn = (v - m.lo) * m.inv_range;
    let delta = if st.started && sn > st.running {
        sn - st.running
    } else {
        R::zero()
    };
    st.running = if st.started { st.running.max(sn) } else { sn };
    st.started = true;
    let beta = mida_beta(delta, m.gamma);
    let (rgb, alpha) = classify_sample(field, s, p);
    if v > st.best {
        st.best = v;
        st.best_rgba = [rgb[0], rgb[1], rgb[2], alpha];
    }
    if alpha <= R::zero() {
        for ch in st.c.iter_mut() {
            *ch = beta * *ch;
        }
        st.a = beta * st.a;
        return;
    }
    let alpha = R::one() - transmit_pow(R::one() - alpha, e);
    let rgb = if s.shade {
        shade_sample(field, s, p, rgb, light, half)
    } else {
        rgb
    };
    let w = (R::one() - beta * st.a) * alpha;
    for (ch, x) in st.c.iter_mut().zip(rgb) {
        *ch = beta * *ch + w * x;
    }
    st.a = beta * st.a + w;
}

/// A MIDA ray's pixel from its state after its last sample: for γ > 0 blended with the
/// MIP colour (unshaded: on a plateau of the maximum, rounding picks which sample holds
/// it, and the gradient there is ill-defined; the value, and so its colour, is not),
/// then over the background `bg`. Mirrors `shaders/shared/modes_cast.wgsl: mida_finish`.
pub fn mida_finish<R: Real>(st: &MidaState<R>, gamma: R, bg: [R; 4]) -> [R; 4] {
    let (mut c, mut a) = (st.c, st.a);
    if gamma > R::zero() {
        let [r, g, b, alpha] = st.best_rgba;
        for (ch, x) in c.iter_mut().zip([r, g, b]) {
            *ch = (R::one() - gamma) * *ch + gamma * alpha * x;
        }
        a = (R::one() - gamma) * a + gamma * alpha;
    }
    over_background(c, a, bg)
}

/// MIDA along one ray; returns the RGBA pixel and the samples taken.
/// Mirrors `shaders/shared/modes_cast.wgsl: cast_mida`.
pub(crate) fn cast_mida<R: Real, F: Field<R>>(
    field: &F,
    s: &SampleSetup<R>,
    m: &ModeSetup<R>,
    span: &Span<R>,
    dir: glam::DVec3,
) -> ([R; 4], u32) {
    let lh = light_half(s.light, dir);
    let mut st = MidaState::default();
    for k in 0..span.n {
        let (p, len) = span.segment(k);
        let e = span.exponent(k, len, s.ref_step, s.step / s.ref_step);
        mida_sample(&mut st, field, s, m, p, e, lh);
    }
    (mida_finish(&st, m.gamma, s.bg), span.n as u32)
}

/// How a shadow ray's march ended ([`shadow_steps`]).
/// Mirrors `shaders/shared/modes_cast.wgsl: SHADOW_LIT`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ShadowEnd {
    /// It left the box: the hit is lit.
    Lit,
    /// A sample lay on another side of an iso-value than the first: in shadow.
    Dark,
    /// Its next sample lies outside the points it may take (another brick's).
    Paused,
}

/// A shadow ray's march from an opaque hit: the next sample `k` (from 1) and, once
/// `k > 1`, the first sample's value. A march paused in one brick resumes in the next
/// with the same state ([`shadow_steps`]).
/// Mirrors `shaders/shared/modes_cast.wgsl: ShadowMarch`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ShadowMarch<R> {
    pub k: usize,
    pub first: R,
}

impl<R: Real> ShadowMarch<R> {
    /// A march about to take its first sample.
    pub(crate) fn start() -> Self {
        ShadowMarch {
            k: 1,
            first: R::zero(),
        }
    }
}

/// The samples `q_k = p + k Δ L` of the shadow ray from the hit `p` (index space)
/// toward the light `l`, from `m.k` on: `q_1` is the first, and from `k = 2` on, until
/// `k Δ` reaches the box's far side `t_exit`, each is compared with it (`step`: the
/// primary ray's `Δ` in voxels). Takes only the samples `owns` (a brick's,
/// `cpu::raycast::Owned::contains`; every point for a whole volume).
/// Mirrors `shaders/shared/modes_cast.wgsl: shadow_steps`.
pub(crate) fn shadow_steps<R: Real, F: Field<R>>(
    m: &mut ShadowMarch<R>,
    field: &F,
    step: R,
    iso: &[IsoR<R>],
    (p, l, t_exit): (V3<R>, V3<R>, R),
    owns: impl Fn(V3<R>) -> bool,
) -> ShadowEnd {
    let dt = step / l.length();
    loop {
        let k = m.k;
        let t = R::of(k as f64) * dt;
        if k >= 2 && t >= t_exit {
            return ShadowEnd::Lit;
        }
        let q = p + l * t;
        if !owns(q) {
            return ShadowEnd::Paused;
        }
        let v = field.value(q);
        m.k = k + 1;
        if k == 1 {
            m.first = v;
            continue;
        }
        if iso.iter().any(|iso| crosses(m.first, v, iso.value)) {
            return ShadowEnd::Dark;
        }
    }
}

/// Whether the point `p` (index space) on an opaque iso-surface is in shadow: samples
/// `p + (m + 1) Δ L` toward the light until the box is left; in shadow when one lies on
/// another side of an iso-value than the first ([`shadow_steps`] over the whole box).
/// Mirrors `shaders/shared/modes_cast.wgsl: in_shadow`.
pub(crate) fn in_shadow<R: Real, F: Field<R>>(
    field: &F,
    s: &SampleSetup<R>,
    iso: &[IsoR<R>],
    p: V3<R>,
    l: V3<R>,
) -> bool {
    let Some((_, t_exit)) = intersect_box(p, l, s.lo, s.hi) else {
        return false;
    };
    let mut m = ShadowMarch::start();
    shadow_steps(&mut m, field, s.step, iso, (p, l, t_exit), |_| true) == ShadowEnd::Dark
}

/// An iso-surface ray's state after its first steps, front to back: everything a
/// later step needs, so that a ray cut into runs (the bricks of a split render, one
/// after another in the ray's order) ends with the unsplit ray's state.
/// Mirrors `shaders/shared/modes_cast.wgsl: IsoState`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IsoState<R> {
    /// The accumulated premultiplied colour and opacity.
    pub c: [R; 3],
    pub a: R,
    /// The last sample's parameter and value (meaningful once `started`).
    pub t0: R,
    pub v0: R,
    /// Whether the ray has taken its first sample.
    pub started: bool,
    /// Whether an opaque surface ended the ray.
    pub done: bool,
}

impl<R: Real> Default for IsoState<R> {
    fn default() -> Self {
        IsoState {
            c: [R::zero(); 3],
            a: R::zero(),
            t0: R::zero(),
            v0: R::zero(),
            started: false,
            done: false,
        }
    }
}

/// What an iso-surface ray's steps share: the light and half vectors, the light in
/// index space (for shadow rays), whether DVR samples lie between the surfaces.
#[derive(Clone, Copy, Debug)]
pub(crate) struct IsoRay<R> {
    pub lh: (V3<R>, V3<R>),
    pub l_index: V3<R>,
    pub dvr: bool,
}

impl<R: Real> IsoRay<R> {
    pub(crate) fn new(s: &SampleSetup<R>, dir: glam::DVec3, dvr: bool) -> Self {
        let lh = light_half(s.light, dir);
        // The light in index space, for shadow rays: J⁻¹ L (headlight: back along the ray).
        let l_index = V3::<R>::from_dvec(s.to_index.transform_vector3(lh.0.to_dvec()));
        IsoRay { lh, l_index, dvr }
    }
}

/// Step `k`'s DVR sample composited under `st`.
fn iso_dvr_sample<R: Real, F: Field<R>>(
    st: &mut IsoState<R>,
    field: &F,
    s: &SampleSetup<R>,
    span: &Span<R>,
    k: usize,
    (light, half): (V3<R>, V3<R>),
) {
    let (p, len) = span.segment(k);
    let (rgb, alpha) = classify_sample(field, s, p);
    if alpha <= R::zero() {
        return;
    }
    let e = span.exponent(k, len, s.ref_step, s.step / s.ref_step);
    let alpha = R::one() - transmit_pow(R::one() - alpha, e);
    let rgb = if s.shade {
        shade_sample(field, s, p, rgb, light, half)
    } else {
        rgb
    };
    under(&mut st.c, &mut st.a, rgb, alpha);
}

/// Takes step `k` of an iso-surface ray into `st`: the first sample (`k = 0`), or the
/// crossings between the last sample and sample `k` (in depth order, before sample
/// `k`'s DVR contribution). Returns whether the step was taken: not once the ray has
/// ended (opacity past the threshold, an opaque surface).
/// Mirrors `shaders/shared/modes_cast.wgsl: iso_step`.
pub(crate) fn iso_step<R: Real, F: Field<R>>(
    st: &mut IsoState<R>,
    field: &F,
    s: &SampleSetup<R>,
    m: &ModeSetup<R>,
    span: &Span<R>,
    k: usize,
    ray: &IsoRay<R>,
) -> bool {
    let (light, half) = ray.lh;
    if k == 0 {
        st.t0 = span.t_mid(0);
        st.v0 = field.value(span.o + span.d * st.t0);
        st.started = true;
        if ray.dvr {
            iso_dvr_sample(st, field, s, span, 0, ray.lh);
        }
        return true;
    }
    if st.a >= s.ert || st.done {
        return false;
    }
    let (t0, v0) = (st.t0, st.v0);
    let t1 = span.t_mid(k);
    let v1 = field.value(span.o + span.d * t1);
    // The crossings of this interval, in depth order (ties: in list order).
    let mut hits: [(R, usize); MAX_ISO_SURFACES] = [(R::zero(), 0); MAX_ISO_SURFACES];
    let mut nh = 0;
    for (j, iso) in m.iso.iter().enumerate() {
        if crosses(v0, v1, iso.value) {
            let t = iso_hit_t(t0, v0, t1, v1, iso.value, m.refine);
            let mut q = nh;
            while q > 0 && hits[q - 1].0 > t {
                hits[q] = hits[q - 1];
                q -= 1;
            }
            hits[q] = (t, j);
            nh += 1;
        }
    }
    for &(t, j) in &hits[..nh] {
        let iso = &m.iso[j];
        let p = span.o + span.d * t;
        let mut rgb = if s.shade {
            shade_sample(field, s, p, iso.color, light, half)
        } else {
            iso.color
        };
        if m.opaque {
            if m.shadows && in_shadow(field, s, &m.iso, p, ray.l_index) {
                rgb = iso.color.map(|x| x * s.k.ambient);
            }
            under(&mut st.c, &mut st.a, rgb, R::one());
            st.done = true;
            return true;
        }
        under(&mut st.c, &mut st.a, rgb, iso.opacity);
    }
    if ray.dvr {
        iso_dvr_sample(st, field, s, span, k, ray.lh);
    }
    (st.t0, st.v0) = (t1, v1);
    true
}

/// Iso-surfaces along one ray, with DVR samples in between when `dvr`; returns the
/// RGBA pixel and the samples taken. Mirrors `shaders/shared/modes_cast.wgsl: cast_iso`.
pub(crate) fn cast_iso<R: Real, F: Field<R>>(
    field: &F,
    s: &SampleSetup<R>,
    m: &ModeSetup<R>,
    span: &Span<R>,
    dir: glam::DVec3,
    dvr: bool,
) -> ([R; 4], u32) {
    let ray = IsoRay::new(s, dir, dvr);
    let mut st = IsoState::default();
    let mut taken = 0u32;
    for k in 0..span.n {
        if !iso_step(&mut st, field, s, m, span, k, &ray) {
            break;
        }
        taken += 1;
    }
    (over_background(st.c, st.a, s.bg), taken)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu::field::GridField;
    use crate::cpu::grid::Grid;
    use crate::cpu::raycast::Owned;
    use crate::settings::{Filter, GradientMethod};

    /// A shadow ray cut among the bricks of a tiling, each taking the samples it owns
    /// from where the last left it (the split GPU render's shadow pass), ends as the
    /// whole ray does, for rays that end lit and in shadow, along axes and obliquely.
    #[test]
    fn a_shadow_march_cut_among_bricks_ends_as_the_whole_march() {
        let dims = [12, 10, 9];
        // A ball of value 1 in 0, off centre: rays through it cross 0.5 twice.
        let data = (0..dims[2])
            .flat_map(|z| (0..dims[1]).flat_map(move |y| (0..dims[0]).map(move |x| (x, y, z))))
            .map(|(x, y, z)| {
                let d = [x as f64 - 7.0, y as f64 - 4.0, z as f64 - 5.0];
                if d.iter().map(|v| v * v).sum::<f64>() < 9.0 {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        let field = GridField::new(
            Grid { dims, data },
            Filter::Trilinear,
            GradientMethod::Central,
            false,
        );
        let iso = [IsoR {
            value: 0.5,
            color: [1.0; 3],
            opacity: 1.0,
        }];
        let (lo, hi) = (V3::splat(-0.5), V3::new(11.5, 9.5, 8.5));
        // Bricks of a k-d tiling, uneven.
        let cuts = |a: usize| match a {
            0 => vec![0, 5, 8, 12],
            1 => vec![0, 3, 10],
            _ => vec![0, 6, 9],
        };
        let mut bricks = Vec::new();
        for (x0, x1) in cuts(0).windows(2).map(|w| (w[0], w[1])) {
            for (y0, y1) in cuts(1).windows(2).map(|w| (w[0], w[1])) {
                for (z0, z1) in cuts(2).windows(2).map(|w| (w[0], w[1])) {
                    bricks.push(Owned::<f64>::new([x0, y0, z0], [x1, y1, z1], dims));
                }
            }
        }
        let (mut lit, mut dark) = (0, 0);
        for (p, l, step) in [
            (V3::new(2.0, 4.0, 5.0), V3::new(1.0, 0.0, 0.0), 1.0),
            (V3::new(11.0, 4.2, 5.1), V3::new(-1.0, 0.0, 0.0), 0.5),
            (V3::new(1.3, 1.1, 0.7), V3::new(0.8, 0.4, 0.6), 0.7),
            (V3::new(1.3, 8.1, 0.7), V3::new(0.8, -0.9, 0.6), 1.3),
            (V3::new(6.9, 4.0, 5.0), V3::new(0.0, 0.0, 1.0), 0.3),
            (V3::new(3.0, 8.0, 7.0), V3::new(-0.3, 0.2, -0.1), 2.0),
            (V3::new(1.0, 9.0, 1.0), V3::new(0.5, 0.2, 0.8), 0.4),
            (V3::new(11.0, 0.5, 0.5), V3::new(0.0, 0.3, 1.0), 0.9),
        ] {
            let whole = in_shadow_of(&field, step, &iso, p, l, (lo, hi));
            let (_, t_exit) = intersect_box(p, l, lo, hi).unwrap();
            let mut m = ShadowMarch::start();
            let mut end = ShadowEnd::Paused;
            let mut passes = 0;
            while end == ShadowEnd::Paused {
                // Every brick in turn, in any order: the one holding the next sample
                // takes its run of them.
                for b in &bricks {
                    let e = shadow_steps(&mut m, &field, step, &iso, (p, l, t_exit), |q| {
                        b.contains(q)
                    });
                    if e != ShadowEnd::Paused {
                        end = e;
                        break;
                    }
                }
                passes += 1;
                assert!(passes <= bricks.len(), "the march makes no progress");
            }
            assert_eq!(end == ShadowEnd::Dark, whole, "{p:?} {l:?}");
            if whole {
                dark += 1;
            } else {
                lit += 1;
            }
        }
        assert!(lit >= 2 && dark >= 2, "{lit} lit, {dark} in shadow");
    }

    fn in_shadow_of(
        field: &GridField<f64>,
        step: f64,
        iso: &[IsoR<f64>],
        p: V3<f64>,
        l: V3<f64>,
        (lo, hi): (V3<f64>, V3<f64>),
    ) -> bool {
        let (_, t_exit) = intersect_box(p, l, lo, hi).unwrap();
        let mut m = ShadowMarch::start();
        shadow_steps(&mut m, field, step, iso, (p, l, t_exit), |_| true) == ShadowEnd::Dark
    }
}
