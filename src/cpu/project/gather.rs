//! The transpose of the flat 2-D layout as a **gather** ([`JosephPair::transpose`]'s
//! fast path), and OS-SART's update in one pass over the image
//! ([`JosephPair::sart_update`]).
//!
//! In a parallel view every ray has the same slope `ka` and weight `w`, and the ray
//! positions `xa0` are evenly spaced: `xa0_c ≈ α + c·δ` for ray `c` (`|δ|` the ray
//! spacing along the in-plane axis, at least the detector pixel). Ray `c` adds into
//! voxel `(s, i)` (plane `s`, in-plane index `i`) only where its position on that
//! plane, `x_a = xa0_c + s·ka`, lies in `(i − 1, i + 1)`: so the rays of a voxel are
//! a run of consecutive ones, the first of them `⌈(i ∓ 1 − α − s·ka)/δ⌉` up to the
//! rounding that `ε` bounds, and there are at most `⌈2/|δ|⌉` of them (two or three
//! when the detector pixel is the voxel). A voxel can therefore sum its own terms:
//! for each candidate ray the same tap weight ([`super::joseph_weight`]'s `w · h_a`, from
//! the ray's own `xa0`, `ka` and `w`) as the transpose by planes, added in the same
//! order (views of a driving axis in slot order, rays in order; the driving axes in
//! order), so the sums are those of [`JosephPair::transpose`] bit for bit. Terms the
//! planes skip (a zero tap weight or a zero value) add a zero here, which changes no
//! sum: a sum that starts at `+0` is never `−0`.
//!
//! On a CPU with AVX-512 scatters are slow (each of the sixteen lanes a store of its
//! own, and on some CPUs worse), so in f32 there the gather is the transpose: the
//! transpose by planes adds every ray's two taps with a gather and a scatter, the
//! gather reads each voxel's two or three rays per view from registers
//! (`cargo bench --bench iterative`).
//!
//! The column sums `Aᵀ𝟙` of the same views are the same terms with `y = 1`. So one
//! pass over the image gives, voxel by voxel, OS-SART's `Aᵀ_S y` and `Aᵀ_S 𝟙` and
//! applies the update `x ← x + λ·(1/Aᵀ_S𝟙)·Aᵀ_S y` (masked, clamped) at once: no
//! stored column weights, no image of the backprojection. In f32 on a CPU with
//! AVX-512F the pixels of a grid line are the sixteen lanes; a pixel's candidate rays
//! are read from a window of 32 rays by permutes (the first candidate is affine in
//! the pixel index, as the ray coordinate of `cpu::fbp`'s interpolation is).
//!
//! The GPU transposes by the same gather (`shaders/joseph_pair_transpose.wgsl:
//! transpose`, one invocation per voxel over the footprint's pixels); its OS-SART
//! then updates from stored column weights (`shaders/iterative.wgsl: sart_update`).

use super::{FlatRays, JosephPair};
use crate::real::{as_f32, as_f32_mut, Real};
use rayon::prelude::*;

/// How far (in rays) the first candidate's estimate may be below the true first
/// ray: covers the rounding of `⌈g⌉`'s argument, which the vector kernel computes in
/// f32 from `|g| < `[`SIMD_G_MAX`] (four roundings of at most 2.4e-4 each).
const ESTIMATE_SLACK: f64 = 2e-3;

/// The vector kernel runs where `|g| <` this over the whole grid.
const SIMD_G_MAX: f64 = 4096.0;

/// The most candidate rays per voxel and view (a detector pixel of at least a
/// quarter of the voxel).
const MAX_CANDIDATES: usize = 8;

/// Rays of no weight on either side of a view's rays ([`FAR`] positions, zero
/// values), so that the vector kernel's windows of 32 rays stay inside the arrays.
const PAD: usize = 32;

/// The position given to a ray that misses the grid (and to the padding): so far
/// outside any grid of fewer than 2²¹ voxels a side that none of its taps is a
/// voxel, in f32 and f64.
const FAR: f64 = -4_194_304.0;

/// Voxels per task of [`JosephPair::sart_update`].
const VOXELS_PER_TASK: usize = 2048;

/// One view of the flat layout laid out for the gather (module docs): its rays are
/// parallel (one `ka`, one `w`), evenly spaced up to `ε`, and none of them takes a
/// sample on a plane past its own `s0..=s1` (checked ray by ray), so the candidate
/// rays and their tap weights alone decide every term.
pub(super) struct GatherView<R> {
    /// Per ray, its `xa0`; [`FAR`] for a ray that misses the grid (it takes no
    /// weight), and for [`PAD`] rays on either side.
    pos: Vec<R>,
    /// Rays per view.
    rays: usize,
    ka: R,
    w: R,
    /// The driving axis `m` and the in-plane axis `a`.
    m: usize,
    a: usize,
    /// The first candidate ray of voxel `(s, i)` is `⌈g[0] + g[1]·s + g[2]·i⌉`.
    g: [f64; 3],
    /// Candidate rays per voxel.
    k: usize,
    /// Whether the f32 vector kernel can run the view: the candidates of sixteen
    /// voxels of a line lie in a window of 32 rays (the first one moves by `|g1|` per
    /// voxel, `g1` the coefficient of the line's index: `15·|g1| + k + 3 ≤ 31`), and
    /// `|g| <` [`SIMD_G_MAX`] everywhere.
    simd: bool,
}

impl<R: Real> GatherView<R> {
    /// View `view` of `flat` laid out for the gather, or `None` when its rays are not
    /// parallel and evenly spaced, or a ray's planes were cut short of where its taps
    /// fall outside the grid.
    pub(super) fn new(dims: [usize; 3], flat: &FlatRays<R>, view: usize) -> Option<Self> {
        let pv = flat.per_view;
        let (m, a) = flat.axes[view];
        let first = view * pv;
        let valid: Vec<usize> = (0..pv)
            .filter(|&c| flat.s0[first + c] <= flat.s1[first + c])
            .collect();
        let (&c0, &c1) = (valid.first()?, valid.last()?);
        if c0 == c1 {
            return None;
        }
        let (ka, w) = (flat.ka[first + c0], flat.w[first + c0]);
        let xa0 = |c: usize| flat.xa0[first + c];
        if !(ka.is_finite() && w.is_finite())
            || valid
                .iter()
                .any(|&c| flat.ka[first + c] != ka || flat.w[first + c] != w || !xa0(c).is_finite())
        {
            return None;
        }
        // xa0_c ≈ α + c·δ, within `dev`.
        let delta = (xa0(c1).f64() - xa0(c0).f64()) / (c1 - c0) as f64;
        let alpha = xa0(c0).f64() - c0 as f64 * delta;
        if delta.is_nan() || delta.abs() <= 1e-6 {
            return None;
        }
        let dev = valid
            .iter()
            .map(|&c| (xa0(c).f64() - (alpha + c as f64 * delta)).abs())
            .fold(0.0, f64::max);
        // A ray adds on plane s only when x_a(s) = xa0 + s·ka lies in (−1, n_a). x_a
        // is monotone in s (so is every rounding step), so it is enough that the
        // planes just outside s0..=s1 put it outside on the side it moves away to.
        let (na, nm) = (dims[a], dims[m]);
        let outside = |c: usize, s: usize, below: bool| {
            let x = xa0(c) + R::of(s as f64) * ka;
            // Moving towards lower planes x_a falls when ka > 0, rises when ka < 0.
            let falls = (ka > R::zero()) == below;
            if ka == R::zero() {
                !(x > -R::one() && x < R::of(na as f64))
            } else if falls {
                x <= -R::one()
            } else {
                x >= R::of(na as f64)
            }
        };
        for &c in &valid {
            let (s0, s1) = (flat.s0[first + c] as usize, flat.s1[first + c] as usize);
            if (s0 > 0 && !outside(c, s0 - 1, true)) || (s1 + 1 < nm && !outside(c, s1 + 1, false))
            {
                return None;
            }
        }
        // |computed x_a − (α + c·δ + s·ka)| ≤ ε: the fit, then the rounding of s·ka
        // and of the sum (|x_a| < n_a + 1 where it matters), each ≤ half an ulp.
        let eps = dev + R::epsilon().f64() * (nm as f64 * ka.f64().abs() + na as f64 + 2.0);
        // The rays of voxel (s, i): α + c·δ + s·ka ∈ (i − 1 − ε, i + 1 + ε).
        let sign = delta.signum();
        let mu = eps / delta.abs() + ESTIMATE_SLACK;
        let g = [(-sign - alpha) / delta - mu, -ka.f64() / delta, 1.0 / delta];
        // The run spans (2 + 2ε)/|δ| rays; its first is at most 2·slack below ⌈g⌉.
        let k = ((2.0 + 2.0 * eps) / delta.abs() + 2.0 * ESTIMATE_SLACK).ceil() as usize;
        if k > MAX_CANDIDATES {
            return None;
        }
        // Lines run along the lower of the two axes.
        let g1 = if m < a { g[1] } else { g[2] };
        let corners = [0.0, (nm - 1) as f64]
            .iter()
            .flat_map(|&s| [0.0, (na - 1) as f64].map(|i| g[0] + g[1] * s + g[2] * i))
            .fold(0.0f64, |acc, v| acc.max(v.abs()));
        let simd = 15.0 * g1.abs() + k as f64 + 3.0 <= 31.0 && corners < SIMD_G_MAX;
        if dims[a].max(dims[m]) >= 1 << 21 {
            return None;
        }
        let mut pos = vec![R::of(FAR); pv + 2 * PAD];
        for &c in &valid {
            pos[PAD + c] = xa0(c);
        }
        Some(GatherView {
            pos,
            rays: pv,
            ka,
            w,
            m,
            a,
            g,
            k,
            simd,
        })
    }

    /// The positions of the rays `rays` (`xa0`, or [`FAR`] for a ray that misses
    /// the grid): the flat forward pass reads them for a parallel view.
    pub(super) fn positions(&self, rays: std::ops::Range<usize>) -> &[R] {
        &self.pos[PAD + rays.start..PAD + rays.end]
    }

    /// Adds the terms of this view's rays at voxel `(s, i)` to `u` (`w·h_a·y`) and
    /// `c` (`w·h_a`), rays in order.
    ///
    /// mirrors shaders/shared/joseph.wgsl: joseph_weight
    #[inline(always)]
    fn add_voxel(&self, y: &[R], (s, i): (usize, usize), u: &mut R, c: &mut R) {
        let first = (self.g[0] + self.g[1] * s as f64 + self.g[2] * i as f64).ceil();
        let (lo, hi) = (
            first.max(0.0) as usize,
            (first + self.k as f64).min(self.rays as f64).max(0.0) as usize,
        );
        let (sr, ir) = (R::of(s as f64), R::of(i as f64));
        let one = R::one();
        for ray in lo..hi {
            // The transpose by planes' numbers: x_a = xa0 + s·ka, the tap at ⌊x_a⌋
            // weighs 1 − t, the next t.
            let xa = self.pos[PAD + ray] + sr * self.ka;
            let (fa, _) = xa.floor_index();
            let ta = xa - fa;
            let wa = if fa == ir {
                one - ta
            } else if fa == ir - one {
                ta
            } else {
                continue;
            };
            let ha = self.w * wa;
            *u = *u + ha * y[PAD + ray];
            *c = *c + ha;
        }
    }
}

/// One view of an update: its gather layout, its values and how its planes lie
/// along the grid's lines.
struct Call<'a, R> {
    view: &'a GatherView<R>,
    /// The view's values, with [`PAD`] zeros on either side.
    y: &'a [R],
    /// The view's planes cross the lines (`m` is the lines' axis): a line's voxels
    /// lie on successive planes. Else a line is one plane.
    across: bool,
    /// The last view of its driving axis: the axis's sums go into the totals.
    ends_axis: bool,
}

/// The parameters of [`JosephPair::sart_update`].
#[derive(Clone, Copy, Debug)]
pub struct SartUpdate<'a, R> {
    /// The relaxation `λ`.
    pub relaxation: R,
    /// Clamp the image to `x ≥ 0` after the update.
    pub nonnegative: bool,
    /// The voxels that may be non-zero (all when `None`).
    pub support: Option<&'a [bool]>,
}

/// One voxel of [`JosephPair::sart_update`]: `Aᵀ_S y` and `Aᵀ_S 𝟙` at voxel `(p, q)`
/// (line index `p`, line `q`) summed over the calls as the transpose by planes sums
/// them (each driving axis's views in order into a partial sum, the partials in
/// axis order).
///
/// Mirrors shaders/joseph_pair_transpose.wgsl: transpose (the same gather over the footprint's pixels).
#[inline(always)]
fn gather_voxel<R: Real>(calls: &[Call<R>], (p, q): (usize, usize)) -> (R, R) {
    let zero = R::zero();
    let (mut u, mut c, mut pu, mut pc) = (zero, zero, zero, zero);
    for call in calls {
        let si = if call.across { (p, q) } else { (q, p) };
        call.view.add_voxel(call.y, si, &mut pu, &mut pc);
        if call.ends_axis {
            (u, c) = (u + pu, c + pc);
            (pu, pc) = (zero, zero);
        }
    }
    (u, c)
}

/// OS-SART's update of one voxel from its sums: `x + λ·(1/sum)·u` on the support
/// (`1/sum` taken as 0 where `sum ≤ 1e-6`), `x + 0` off it, then `max(x, 0)` when
/// asked — the numbers of `cpu::iterative`'s transpose, column weights and update.
///
/// Mirrors shaders/iterative.wgsl: mask, reciprocal, sart_update (the update from stored weights).
#[inline(always)]
pub fn sart_voxel<R: Real>(x: R, u: R, sum: R, keep: bool, lambda: R, nonnegative: bool) -> R {
    let zero = R::zero();
    let (u, sum) = if keep { (u, sum) } else { (zero, zero) };
    let c = if sum > R::of(1e-6) {
        R::one() / sum
    } else {
        zero
    };
    let v = x + lambda * c * u;
    if nonnegative && (v.is_nan() || v <= zero) {
        zero
    } else {
        v
    }
}

impl<R: Real> JosephPair<R> {
    /// Whether [`Self::sart_update`] runs for `views`: a 2-D problem on the flat
    /// layout, every view of `views` parallel and evenly spaced (module docs).
    pub fn has_sart_update(&self, views: &[usize]) -> bool {
        self.calls(&[], views).is_some()
    }

    /// Whether the gather runs for `views` on its vector kernel (f32 on a CPU with
    /// AVX-512F, every view's candidates within the kernel's window): only then is
    /// one pass faster than the transpose by planes with stored column weights, and
    /// only then does `cpu::iterative`'s OS-SART take it, and [`Self::transpose`]
    /// gather.
    pub fn has_fast_sart_update(&self, views: &[usize]) -> bool {
        #[cfg(target_arch = "x86_64")]
        if let (Some(flat), Some((_, n0))) = (&self.flat, self.calls(&[], views)) {
            return std::arch::is_x86_feature_detected!("avx512f")
                && n0 < 1 << 24
                && views.iter().all(|&k| {
                    flat.gather[k]
                        .as_ref()
                        .is_some_and(|v| v.simd && v.rays < 1 << 24 && as_f32(&v.pos).is_some())
                });
        }
        false
    }

    /// The pair without the gather ([`Self::sart_update`] then declines).
    pub fn without_gather(mut self) -> Self {
        if let Some(flat) = &mut self.flat {
            flat.gather.iter_mut().for_each(|g| *g = None);
        }
        self
    }

    /// The calls of an update over `views` with values `y` (each view's with [`PAD`]
    /// zeros on either side; empty: only whether it runs), and the lines' length.
    fn calls<'a>(&'a self, y: &'a [R], views: &[usize]) -> Option<(Vec<Call<'a, R>>, usize)> {
        let flat = self.flat.as_ref()?;
        if views.is_empty() {
            return None;
        }
        let gv: Vec<&GatherView<R>> = views
            .iter()
            .map(|&k| flat.gather.get(k)?.as_ref())
            .collect::<Option<_>>()?;
        // Every view's planes and in-plane axis are the grid's two axes: the grid is
        // n0 × n1 voxels, lines along the lower axis.
        let (m0, a0) = (gv[0].m, gv[0].a);
        let (lo, hi) = (m0.min(a0), m0.max(a0));
        if gv.iter().any(|v| v.m.min(v.a) != lo || v.m.max(v.a) != hi) {
            return None;
        }
        let n0 = self.dims[lo];
        if y.is_empty() {
            return Some((Vec::new(), n0));
        }
        let stride = self.per_view() + 2 * PAD;
        // The transpose by planes' order: driving axes in order, views in slot order.
        let mut calls: Vec<Call<R>> = Vec::with_capacity(views.len());
        for m in [lo, hi] {
            for (slot, v) in gv.iter().enumerate() {
                if v.m == m {
                    calls.push(Call {
                        view: v,
                        y: &y[slot * stride..(slot + 1) * stride],
                        across: m == lo,
                        ends_axis: false,
                    });
                }
            }
            if let Some(last) = calls.last_mut() {
                last.ends_axis = true;
            }
        }
        Some((calls, n0))
    }

    /// OS-SART's update over the views `views` in one pass over the image:
    ///
    /// ```text
    /// x ← x + λ·C·M·Aᵀ y,   C = diag(1 / M·Aᵀ𝟙)  (0 where the sum is ≤ 1e-6)
    /// ```
    ///
    /// with `A` the pair over `views`, `y` their values (`views.len() × rows × cols`,
    /// in that order), `M` the support's mask, then `max(x, 0)` when asked: the numbers
    /// of [`Self::transpose`] of `y` and of `𝟙`, masked, the second's reciprocal, and
    /// the update, bit for bit, voxel by voxel (module docs). Returns `false` and
    /// leaves `x` alone when the pair has no gather for `views`
    /// ([`Self::has_sart_update`]).
    pub fn sart_update(&self, x: &mut [R], y: &[R], views: &[usize], step: &SartUpdate<R>) -> bool {
        assert_eq!(
            x.len(),
            self.n_voxels(),
            "JosephPair::sart_update: grid size"
        );
        assert_eq!(
            y.len(),
            views.len() * self.per_view(),
            "JosephPair::sart_update: projection size"
        );
        if let Some(m) = step.support {
            assert_eq!(m.len(), x.len(), "JosephPair::sart_update: support size");
        }
        if !self.has_sart_update(views) {
            return false;
        }
        let padded = self.padded(y, views.len());
        let Some((calls, n0)) = self.calls(&padded, views) else {
            return false;
        };
        let calls = &calls;
        x.par_chunks_mut(VOXELS_PER_TASK)
            .enumerate()
            .for_each(|(t, xs)| {
                let first = t * VOXELS_PER_TASK;
                let ms = step.support.map(|m| &m[first..first + xs.len()]);
                #[cfg(target_arch = "x86_64")]
                if gather_range_f32(calls, n0, first, xs, ms, Some(step)) {
                    return;
                }
                for (j, xv) in xs.iter_mut().enumerate() {
                    let idx = first + j;
                    let keep = ms.is_none_or(|m| m[j]);
                    let (u, c) = if keep {
                        gather_voxel(calls, (idx % n0, idx / n0))
                    } else {
                        (R::zero(), R::zero())
                    };
                    *xv = sart_voxel(*xv, u, c, keep, step.relaxation, step.nonnegative);
                }
            });
        true
    }

    /// `y` (`views` views of values) with [`PAD`] zeros on either side of each view.
    fn padded(&self, y: &[R], views: usize) -> Vec<R> {
        let pv = self.per_view();
        let mut padded = vec![R::zero(); views * (pv + 2 * PAD)];
        for (dst, src) in padded.chunks_mut(pv + 2 * PAD).zip(y.chunks(pv)) {
            dst[PAD..PAD + pv].copy_from_slice(src);
        }
        padded
    }

    /// [`Self::transpose`] of `y` over `views` as a gather on the vector kernel,
    /// with the voxels off `support` set to `+0` (`M·Aᵀ y`): the numbers of the
    /// transpose by planes bit for bit (module docs); `None` where the kernel does
    /// not run ([`Self::has_fast_sart_update`]).
    pub(super) fn transpose_gather(
        &self,
        y: &[R],
        views: &[usize],
        support: Option<&[bool]>,
    ) -> Option<Vec<R>> {
        if !self.has_fast_sart_update(views) {
            return None;
        }
        let padded = self.padded(y, views.len());
        let (calls, n0) = self.calls(&padded, views)?;
        let calls = &calls;
        let mut out = vec![R::zero(); self.n_voxels()];
        let ran = out
            .par_chunks_mut(VOXELS_PER_TASK)
            .enumerate()
            .map(|(t, us)| {
                let first = t * VOXELS_PER_TASK;
                let ms = support.map(|m| &m[first..first + us.len()]);
                #[cfg(target_arch = "x86_64")]
                return gather_range_f32(calls, n0, first, us, ms, None);
                #[cfg(not(target_arch = "x86_64"))]
                false
            })
            .all(|ran| ran);
        ran.then_some(out)
    }
}

/// The gather on voxels `first ..` with the f32 kernel, when the pair is f32, the
/// CPU has AVX-512F and every view's candidates fit the kernel's window (`simd`):
/// with a `step`, [`JosephPair::sart_update`] of `xs`; without, `xs` (zeros) takes
/// `M·Aᵀ y` ([`JosephPair::transpose_gather`]). `false` (and nothing done) otherwise.
#[cfg(target_arch = "x86_64")]
fn gather_range_f32<R: Real>(
    calls: &[Call<R>],
    n0: usize,
    first: usize,
    xs: &mut [R],
    ms: Option<&[bool]>,
    step: Option<&SartUpdate<R>>,
) -> bool {
    let Some(xs) = as_f32_mut(xs) else {
        return false;
    };
    if !std::arch::is_x86_feature_detected!("avx512f") || n0 >= 1 << 24 {
        return false;
    }
    let mut c32 = Vec::with_capacity(calls.len());
    for c in calls {
        let v = c.view;
        let (Some(pos), Some(y)) = (as_f32(&v.pos), as_f32(c.y)) else {
            return false;
        };
        if !v.simd || v.rays >= 1 << 24 {
            return false;
        }
        c32.push(Call32 {
            pos,
            y,
            rays: v.rays as i32,
            ka: v.ka.f64() as f32,
            w: v.w.f64() as f32,
            g: v.g,
            k: v.k,
            across: c.across,
            ends_axis: c.ends_axis,
        });
    }
    let Some(step) = step else {
        // SAFETY: the CPU has AVX-512F; every call is `simd`.
        unsafe { gather_range_f32x16::<false>(&c32, n0, first, xs, ms, 0.0, false) };
        return true;
    };
    let (lambda, nonneg) = (step.relaxation.f64() as f32, step.nonnegative);
    // SAFETY: the CPU has AVX-512F; every call is `simd`.
    unsafe {
        match c32.as_slice() {
            [one] if one.across => sart_view_f32x16::<true>(one, n0, first, xs, ms, lambda, nonneg),
            [one] => sart_view_f32x16::<false>(one, n0, first, xs, ms, lambda, nonneg),
            _ => gather_range_f32x16::<true>(&c32, n0, first, xs, ms, lambda, nonneg),
        }
    };
    true
}

/// A [`Call`] in f32.
#[cfg(target_arch = "x86_64")]
struct Call32<'a> {
    /// Positions and values, each with [`PAD`] rays on either side.
    pos: &'a [f32],
    y: &'a [f32],
    rays: i32,
    ka: f32,
    w: f32,
    g: [f64; 3],
    k: usize,
    across: bool,
    ends_axis: bool,
}

/// [`JosephPair::sart_update`] (`UPDATE`) or the masked transpose (not `UPDATE`: `xs`
/// holds zeros and takes `M·Aᵀ y`; `lambda` and `nonneg` are unused) on voxels
/// `first ..` in f32 with AVX-512: sixteen voxels of a line at a time,
/// [`gather_voxel`] (without the column sums for the transpose) and [`sart_voxel`]
/// in every lane with the same operations in the same order, so the same numbers bit
/// for bit. A lane's candidate rays come from a window of 32 rays (two loads and a
/// permute per array instead of gathers); vectors off the support skip the rays.
///
/// # Safety
/// The CPU has AVX-512F, and every call is `simd` ([`GatherView`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn gather_range_f32x16<const UPDATE: bool>(
    calls: &[Call32],
    n0: usize,
    first: usize,
    xs: &mut [f32],
    ms: Option<&[bool]>,
    lambda: f32,
    nonneg: bool,
) {
    use std::arch::x86_64::*;
    const FLOOR: i32 = _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC;
    const CEIL: i32 = _MM_FROUND_TO_POS_INF | _MM_FROUND_NO_EXC;
    let set = _mm512_set1_ps;
    let lane = _mm512_setr_ps(
        0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0, 15.0,
    );
    let (zero, one) = (_mm512_setzero_ps(), set(1.0));
    let (floor_w, lam) = (set(1e-6f64 as f32), set(lambda));
    // Per call, its constants on the current line: g0 + g_q·q (f32), g1 and s·ka.
    let mut line = vec![(0.0f32, 0.0f32, 0.0f32); calls.len()];
    let mut line_start = 0;
    while line_start < xs.len() {
        // One line (or the part of it in xs): voxels p_start.. of line q.
        let (p_start, q) = ((first + line_start) % n0, (first + line_start) / n0);
        let line_len = (n0 - p_start).min(xs.len() - line_start);
        let qf = set(q as f32);
        for (lc, call) in line.iter_mut().zip(calls) {
            let (gq, g1) = if call.across {
                (call.g[2], call.g[1])
            } else {
                (call.g[1], call.g[2])
            };
            *lc = (
                (call.g[0] + gq * q as f64) as f32,
                g1 as f32,
                q as f32 * call.ka,
            );
        }
        for v in (0..line_len).step_by(16) {
            let (j, p0) = (line_start + v, p_start + v);
            let n = (line_len - v).min(16);
            let tail: __mmask16 = ((1u32 << n) - 1) as u16;
            let keep = match ms {
                // Sixteen flags (bytes 0 or 1) widened to lanes, or a short run's few.
                Some(m) if n == 16 => unsafe {
                    let bytes = _mm_loadu_si128(m.as_ptr().add(j) as *const __m128i);
                    _mm512_test_epi32_mask(_mm512_cvtepu8_epi32(bytes), _mm512_set1_epi32(1))
                },
                Some(m) => tail & bool_mask(&m[j..j + n]),
                None => tail,
            };
            // SAFETY (every load and store below): lanes past `n` are masked off, and
            // a window of 32 rays starts at ray −31 or later and ends before ray
            // rays + 32, inside the padded arrays.
            let px = unsafe { xs.as_mut_ptr().add(j) };
            if keep == 0 {
                if UPDATE && nonneg {
                    unsafe {
                        let x = _mm512_maskz_loadu_ps(tail, px);
                        _mm512_mask_storeu_ps(px, tail, _mm512_max_ps(x, zero));
                    }
                }
                continue;
            }
            let pf = _mm512_add_ps(set(p0 as f32), lane);
            let (mut u, mut c, mut pu, mut pc) = (zero, zero, zero, zero);
            for (call, &(g0, g1, sq)) in calls.iter().zip(&line) {
                // The first candidate of each lane, ⌈g0 + g1·p⌉ (monotone in p), and
                // the window of 32 rays from one below the lowest lane's.
                let g = _mm512_add_ps(set(g0), _mm512_mul_ps(set(g1), pf));
                let first_c = _mm512_cvttps_epi32(_mm512_roundscale_ps::<CEIL>(g));
                let ends = (
                    _mm_cvtsi128_si32(_mm512_castsi512_si128(first_c)),
                    _mm_extract_epi32::<3>(_mm512_extracti32x4_epi32::<3>(first_c)),
                );
                let w0 = ends.0.min(ends.1) - 1;
                if w0 >= -31 && w0 < call.rays {
                    let idx0 = _mm512_sub_epi32(first_c, _mm512_set1_epi32(w0));
                    let at = (PAD as i32 + w0) as usize;
                    let (pos0, pos1, y0, y1) = unsafe {
                        let (pp, py) = (call.pos.as_ptr().add(at), call.y.as_ptr().add(at));
                        (
                            _mm512_loadu_ps(pp),
                            _mm512_loadu_ps(pp.add(16)),
                            _mm512_loadu_ps(py),
                            _mm512_loadu_ps(py.add(16)),
                        )
                    };
                    // s·ka and the target index i: per lane when the planes cross the
                    // line, else the line's.
                    let (sk, target) = if call.across {
                        (_mm512_mul_ps(pf, set(call.ka)), qf)
                    } else {
                        (set(sq), pf)
                    };
                    let target1 = _mm512_sub_ps(target, one);
                    let w = set(call.w);
                    let mut ix = idx0;
                    for _ in 0..call.k {
                        let pos = _mm512_permutex2var_ps(pos0, ix, pos1);
                        let yc = _mm512_permutex2var_ps(y0, ix, y1);
                        ix = _mm512_add_epi32(ix, _mm512_set1_epi32(1));
                        let xa = _mm512_add_ps(pos, sk);
                        let fa = _mm512_roundscale_ps::<FLOOR>(xa);
                        let ta = _mm512_sub_ps(xa, fa);
                        let e0 = _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(fa, target);
                        let e1 = _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(fa, target1);
                        let wa = _mm512_mask_blend_ps(e1, _mm512_sub_ps(one, ta), ta);
                        let on = e0 | e1;
                        let ha = _mm512_mul_ps(w, wa);
                        pu = _mm512_mask_add_ps(pu, on, pu, _mm512_mul_ps(ha, yc));
                        if UPDATE {
                            pc = _mm512_mask_add_ps(pc, on, pc, ha);
                        }
                    }
                }
                // (Else no lane's candidates are rays.)
                if call.ends_axis {
                    u = _mm512_add_ps(u, pu);
                    c = _mm512_add_ps(c, pc);
                    (pu, pc) = (zero, zero);
                }
            }
            if !UPDATE {
                // The masked transpose: `u` on the support, the zeros of xs off it.
                unsafe { _mm512_mask_storeu_ps(px, keep, u) };
                continue;
            }
            // sart_voxel.
            let (u, c) = (_mm512_maskz_mov_ps(keep, u), _mm512_maskz_mov_ps(keep, c));
            let weight = _mm512_maskz_div_ps(_mm512_cmp_ps_mask::<_CMP_GT_OQ>(c, floor_w), one, c);
            unsafe {
                let x = _mm512_maskz_loadu_ps(tail, px);
                let mut v = _mm512_add_ps(x, _mm512_mul_ps(_mm512_mul_ps(lam, weight), u));
                if nonneg {
                    // max(v, 0) is v where v > 0, else 0 (NaN too): sart_voxel's choice.
                    v = _mm512_max_ps(v, zero);
                }
                _mm512_mask_storeu_ps(px, tail, v);
            }
        }
        line_start += line_len;
    }
}

/// [`sart_range_f32x16`] for a subset of one view (`ACROSS`: its planes cross the
/// lines), the case of SART: the same operations on every lane, with the view's
/// constants in registers and its one partial sum taken as the total (`0 + u` is
/// `u`: a sum that starts at `+0` is never `−0`).
///
/// # Safety
/// The CPU has AVX-512F, and the call is `simd` ([`GatherView`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn sart_view_f32x16<const ACROSS: bool>(
    call: &Call32,
    n0: usize,
    first: usize,
    xs: &mut [f32],
    ms: Option<&[bool]>,
    lambda: f32,
    nonneg: bool,
) {
    use std::arch::x86_64::*;
    const FLOOR: i32 = _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC;
    const CEIL: i32 = _MM_FROUND_TO_POS_INF | _MM_FROUND_NO_EXC;
    let set = _mm512_set1_ps;
    let lane = _mm512_setr_ps(
        0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0, 15.0,
    );
    let (zero, one, sixteen) = (_mm512_setzero_ps(), set(1.0), set(16.0));
    let (floor_w, lam) = (set(1e-6f64 as f32), set(lambda));
    let (w, ka, ones) = (set(call.w), set(call.ka), _mm512_set1_epi32(1));
    // The coefficient of the line index in the first candidate's estimate, and of
    // the line.
    let (g1, gq) = if ACROSS {
        (call.g[1], call.g[2])
    } else {
        (call.g[2], call.g[1])
    };
    let g1v = set(g1 as f32);
    let mut line_start = 0;
    while line_start < xs.len() {
        let (p_start, q) = ((first + line_start) % n0, (first + line_start) / n0);
        let line_len = (n0 - p_start).min(xs.len() - line_start);
        let qf = set(q as f32);
        let g0 = set((call.g[0] + gq * q as f64) as f32);
        // s·ka of the line's plane (when the line is a plane).
        let sq = set(q as f32 * call.ka);
        let mut pf = _mm512_add_ps(set(p_start as f32), lane);
        for v in (0..line_len).step_by(16) {
            let j = line_start + v;
            let n = (line_len - v).min(16);
            let tail: __mmask16 = ((1u32 << n) - 1) as u16;
            let keep = match ms {
                Some(m) if n == 16 => unsafe {
                    let bytes = _mm_loadu_si128(m.as_ptr().add(j) as *const __m128i);
                    _mm512_test_epi32_mask(_mm512_cvtepu8_epi32(bytes), ones)
                },
                Some(m) => tail & bool_mask(&m[j..j + n]),
                None => tail,
            };
            // SAFETY: as in sart_range_f32x16.
            let px = unsafe { xs.as_mut_ptr().add(j) };
            let here = pf;
            pf = _mm512_add_ps(pf, sixteen);
            if keep == 0 {
                if nonneg {
                    unsafe {
                        let x = _mm512_maskz_loadu_ps(tail, px);
                        _mm512_mask_storeu_ps(px, tail, _mm512_max_ps(x, zero));
                    }
                }
                continue;
            }
            let g = _mm512_add_ps(g0, _mm512_mul_ps(g1v, here));
            let first_c = _mm512_cvttps_epi32(_mm512_roundscale_ps::<CEIL>(g));
            let ends = (
                _mm_cvtsi128_si32(_mm512_castsi512_si128(first_c)),
                _mm_extract_epi32::<3>(_mm512_extracti32x4_epi32::<3>(first_c)),
            );
            let w0 = ends.0.min(ends.1) - 1;
            let (mut u, mut c) = (zero, zero);
            if w0 >= -31 && w0 < call.rays {
                let at = (PAD as i32 + w0) as usize;
                let (pos0, pos1, y0, y1) = unsafe {
                    let (pp, py) = (call.pos.as_ptr().add(at), call.y.as_ptr().add(at));
                    (
                        _mm512_loadu_ps(pp),
                        _mm512_loadu_ps(pp.add(16)),
                        _mm512_loadu_ps(py),
                        _mm512_loadu_ps(py.add(16)),
                    )
                };
                let (sk, target) = if ACROSS {
                    (_mm512_mul_ps(here, ka), qf)
                } else {
                    (sq, here)
                };
                let target1 = _mm512_sub_ps(target, one);
                let mut ix = _mm512_sub_epi32(first_c, _mm512_set1_epi32(w0));
                for _ in 0..call.k {
                    let pos = _mm512_permutex2var_ps(pos0, ix, pos1);
                    let yc = _mm512_permutex2var_ps(y0, ix, y1);
                    ix = _mm512_add_epi32(ix, ones);
                    let xa = _mm512_add_ps(pos, sk);
                    let fa = _mm512_roundscale_ps::<FLOOR>(xa);
                    let ta = _mm512_sub_ps(xa, fa);
                    let e0 = _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(fa, target);
                    let e1 = _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(fa, target1);
                    let wa = _mm512_mask_blend_ps(e1, _mm512_sub_ps(one, ta), ta);
                    let on = e0 | e1;
                    let ha = _mm512_mul_ps(w, wa);
                    u = _mm512_mask_add_ps(u, on, u, _mm512_mul_ps(ha, yc));
                    c = _mm512_mask_add_ps(c, on, c, ha);
                }
            }
            // sart_voxel.
            let (u, c) = (_mm512_maskz_mov_ps(keep, u), _mm512_maskz_mov_ps(keep, c));
            let weight = _mm512_maskz_div_ps(_mm512_cmp_ps_mask::<_CMP_GT_OQ>(c, floor_w), one, c);
            unsafe {
                let x = _mm512_maskz_loadu_ps(tail, px);
                let mut v = _mm512_add_ps(x, _mm512_mul_ps(_mm512_mul_ps(lam, weight), u));
                if nonneg {
                    v = _mm512_max_ps(v, zero);
                }
                _mm512_mask_storeu_ps(px, tail, v);
            }
        }
        line_start += line_len;
    }
}

/// The flags of up to sixteen voxels as a lane mask.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn bool_mask(m: &[bool]) -> u16 {
    m.iter()
        .take(16)
        .enumerate()
        .fold(0, |mask, (l, &k)| mask | (u16::from(k) << l))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bool_mask_sets_one_bit_per_flag() {
        let m = [true, false, true, true, false, false, false, true, true];
        assert_eq!(bool_mask(&m), 0b1_1000_1101);
        assert_eq!(bool_mask(&[true; 16]), u16::MAX);
        assert_eq!(bool_mask(&[]), 0);
    }
}
