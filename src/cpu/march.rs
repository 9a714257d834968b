//! The ray caster's step grid, and its batched DVR kernel.
//!
//! [`Steps`] is one ray's step grid: step `k` covers `[t_s + kΔt, t_s + (k+1)Δt]`
//! clipped to `[t_in, t_out]`, and is represented by its midpoint and its length.
//!
//! [`Batch`] evaluates up to [`BATCH`] consecutive steps of one ray at once: the sample
//! positions, the reconstructed values, the transfer function's colour and opacity and
//! the opacity correction `1 − (1 − α)^(ℓ/Δs₀)`. The samples of a batch do not depend
//! on each other, so they need not wait for one another as they would inside the
//! compositing loop; only the front-to-back compositing that follows stays sequential.
//! In f32 with the trilinear filter on an AVX-512 CPU the sixteen samples of a batch
//! are computed in the sixteen lanes of one register, each voxel and table entry
//! fetched with a gather.
//!
//! Every path does the same arithmetic in the same order as the per-sample loop of
//! [`super::raycast`] (`Steps::segment`, `filter::sample`, `LutR::classify`,
//! `shade::transmit_pow`), without fused multiply–adds, so the images are the same
//! to the last bit; the unit tests below check that on every view and setting.

use super::filter::sample;
use super::grid::Grid;
use crate::real::{Real, V3};
use crate::settings::Filter;
use crate::transfer::LutR;

/// Steps evaluated together.
pub const BATCH: usize = 16;

/// One ray's step grid in index space: `n` steps from `t_s` of `dt` along `o + d·t`,
/// the first starting at `t_in`, the last ending at `t_out`.
#[derive(Clone, Copy, Debug)]
pub struct Steps<R> {
    pub o: V3<R>,
    pub d: V3<R>,
    pub t_in: R,
    pub t_out: R,
    pub t_s: R,
    pub dt: R,
    pub n: usize,
}

impl<R: Real> Steps<R> {
    /// Step `k`'s midpoint and length (`t` units). A full step (neither the first nor
    /// the last) is `dt` long exactly, its midpoint `t_s + (k + ½)·dt`; the first starts
    /// at `t_in`, the last ends at `t_out`.
    #[inline(always)]
    pub fn segment(&self, k: usize) -> (V3<R>, R) {
        let (mid, len) = segment_t(k, self.n, self.t_in, self.t_s, self.t_out, self.dt);
        (self.o + self.d * mid, len)
    }

    /// Whether step `k` is a full step: neither the first nor the last.
    #[inline(always)]
    pub fn full(&self, k: usize) -> bool {
        k > 0 && k + 1 < self.n
    }

    /// The opacity-correction exponent `ℓ/Δs₀` of step `k` of length `len` (`t` units)
    /// on a ray of `speed` voxels per `t`: `e_full` (the step over `Δs₀`, exactly) for a
    /// full step, as `dt = step/speed` by construction and `dt·speed/Δs₀` would only
    /// round to it; `len·speed/Δs₀` for the clipped first and last steps.
    #[inline(always)]
    pub fn exponent(&self, k: usize, len: R, speed: R, ref_step: R, e_full: R) -> R {
        if self.full(k) {
            e_full
        } else {
            len * speed / ref_step
        }
    }
}

/// Step `k`'s bounds `(t_a, t_b)` in a grid of `n` steps from `t_s` by `dt`, cut to
/// `[t_in, t_out]`: `t_s + k·dt` and `t_s + (k+1)·dt`, except that the first starts at
/// `t_in` and the last ends at `t_out`.
/// mirrors shaders/shared/skip.wgsl: step_bounds
#[inline(always)]
pub fn step_bounds<R: Real>(k: usize, n: usize, t_in: R, t_s: R, t_out: R, dt: R) -> (R, R) {
    let ta = if k == 0 {
        t_in
    } else {
        t_s + R::of(k as f64) * dt
    };
    let tb = if k + 1 == n {
        t_out
    } else {
        t_s + R::of((k + 1) as f64) * dt
    };
    (ta, tb)
}

/// Step `k`'s midpoint parameter and length in the grid of [`step_bounds`]: a full
/// step (neither the first nor the last) is `dt` long exactly, its midpoint
/// `t_s + (k + ½)·dt`; the first and last are the middle and length of their bounds.
/// The rule of [`Steps::segment`], shared with the multi-volume caster.
#[inline(always)]
pub fn segment_t<R: Real>(k: usize, n: usize, t_in: R, t_s: R, t_out: R, dt: R) -> (R, R) {
    if k > 0 && k + 1 < n {
        return (t_s + (R::of(k as f64) + R::of(0.5)) * dt, dt);
    }
    let (ta, tb) = step_bounds(k, n, t_in, t_s, t_out, dt);
    ((ta + tb) * R::of(0.5), tb - ta)
}

/// What the batched kernel reads: the grid the filter samples and the 1D table.
#[derive(Clone, Copy)]
pub struct Source<'a, R> {
    pub grid: &'a Grid<R>,
    /// Where `grid`'s voxel 0 lies in the index space the rays are in: zero for a
    /// whole grid, a brick's origin ([`super::field::BrickField`]): a point `p` is
    /// sampled at `p − origin`, as the brick's field samples it (exactly).
    pub origin: [R; 3],
    pub filter: Filter,
    pub lut: &'a LutR<R>,
    /// The table as [`lut_pairs`] lays it out for the vector path.
    pub pairs: &'a [[R; 8]],
    /// Voxels per `t` unit along the ray (`|d|`).
    pub speed: R,
    /// The reference step `Δs₀` in voxels.
    pub ref_step: R,
    /// The opacity-correction exponent of a full step: the step over `Δs₀`.
    pub e_full: R,
}

impl<R: Real> Source<'_, R> {
    /// [`Self::origin`] as a point.
    #[inline(always)]
    pub fn local_origin(&self) -> V3<R> {
        V3::new(self.origin[0], self.origin[1], self.origin[2])
    }
}

/// The 1D table laid out for the vector path: entry `i` holds, per channel, the value
/// `e_i` and the difference `e_{i+1} − e_i` to the next entry (0 past the last), so one
/// 64-bit fetch gives both. `e_i + f·(e_{i+1} − e_i)` is then what `LutR::classify`
/// computes, to the bit.
pub fn lut_pairs<R: Real>(lut: &LutR<R>) -> Vec<[R; 8]> {
    let e = &lut.entries;
    (0..e.len())
        .map(|i| {
            let (a, b) = (e[i], e[(i + 1).min(e.len() - 1)]);
            let mut q = [R::zero(); 8];
            for c in 0..4 {
                q[2 * c] = a[c];
                q[2 * c + 1] = b[c] - a[c];
            }
            q
        })
        .collect()
}

/// Up to [`BATCH`] consecutive steps of a ray, classified.
#[derive(Clone, Debug)]
pub struct Batch<R> {
    /// How many steps the batch holds.
    pub len: usize,
    /// Sample positions (index space), per axis.
    pub p: [[R; BATCH]; 3],
    /// Colour from the transfer function, per channel.
    pub rgb: [[R; BATCH]; 3],
    /// Opacity per reference step, as the table gives it.
    pub alpha: [R; BATCH],
    /// Opacity over the step's own length: `1 − (1 − α)^(ℓ·|d|/Δs₀)`.
    pub alpha_step: [R; BATCH],
    /// Bit `l` set when step `l`'s table opacity is above zero.
    pub visible: u32,
}

impl<R: Real> Default for Batch<R> {
    fn default() -> Self {
        let z = [R::zero(); BATCH];
        Batch {
            len: 0,
            p: [z; 3],
            rgb: [z; 3],
            alpha: z,
            alpha_step: z,
            visible: 0,
        }
    }
}

impl<R: Real> Batch<R> {
    /// Fills the batch with steps `k0 .. k0 + m` (`1 ≤ m ≤ BATCH`, `k0 + m ≤ n`).
    pub fn fill(&mut self, src: &Source<R>, steps: &Steps<R>, k0: usize, m: usize) {
        debug_assert!((1..=BATCH).contains(&m) && k0 + m <= steps.n);
        self.len = m;
        self.visible = 0;
        #[cfg(target_arch = "x86_64")]
        {
            use std::any::TypeId;
            if TypeId::of::<R>() == TypeId::of::<f32>()
                && src.filter == Filter::Trilinear
                && simd::usable(
                    src.grid.data.len(),
                    src.grid.dims[0],
                    src.pairs.len(),
                    steps.n,
                )
            {
                // SAFETY: R is f32 (checked above), so these have f32's layout.
                let (b, s, st) = unsafe {
                    (
                        &mut *(self as *mut Batch<R> as *mut Batch<f32>),
                        &*(src as *const Source<R> as *const Source<f32>),
                        &*(steps as *const Steps<R> as *const Steps<f32>),
                    )
                };
                // SAFETY: `usable` checked the CPU's features and the index ranges.
                if unsafe { simd::fill_f32x16(b, s, st, k0, m) } {
                    return;
                }
            }
        }
        for l in 0..m {
            let (p, len) = steps.segment(k0 + l);
            let e = steps.exponent(k0 + l, len, src.speed, src.ref_step, src.e_full);
            let c = src
                .lut
                .classify(sample(src.grid, src.filter, p - src.local_origin()));
            for (a, (&x, &v)) in p.0.iter().zip(&c).enumerate() {
                self.p[a][l] = x;
                self.rgb[a][l] = v;
            }
            self.alpha[l] = c[3];
            if c[3] > R::zero() {
                self.visible |= 1 << l;
            }
            self.alpha_step[l] = R::one() - super::shade::transmit_pow(R::one() - c[3], e);
        }
    }

    /// Sample `l`'s position.
    #[inline(always)]
    pub fn position(&self, l: usize) -> V3<R> {
        V3::new(self.p[0][l], self.p[1][l], self.p[2][l])
    }

    /// Sample `l`'s colour.
    #[inline(always)]
    pub fn colour(&self, l: usize) -> [R; 3] {
        [self.rgb[0][l], self.rgb[1][l], self.rgb[2][l]]
    }
}

/// Whether [`values`] samples in vector lanes for a ray of `n` steps from `src`: f32,
/// the trilinear filter, an AVX-512 CPU, indices that fit the lanes. Elsewhere it
/// takes the steps one at a time, which a caller does as well without the batch.
pub fn values_in_lanes<R: Real>(src: &Source<R>, n: usize) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::any::TypeId::of::<R>() == std::any::TypeId::of::<f32>()
            && src.filter == Filter::Trilinear
            && simd::usable(src.grid.data.len(), src.grid.dims[0], src.pairs.len(), n)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = (src, n);
        false
    }
}

/// The filtered values and lengths of steps `k0 .. k0 + m` of a ray (`1 ≤ m ≤
/// BATCH`, `k0 + m ≤ n`) into `value[..m]` and `len[..m]`: what MIP, MinIP and X-ray
/// take of each step — `sample(grid, filter, p − origin)` at the step's midpoint `p`,
/// and the step's length — to the bit as [`Steps::segment`] and `filter::sample` give
/// them. In f32 with the trilinear filter on an AVX-512 CPU the sixteen steps are
/// sampled in the lanes of one register.
pub fn values<R: Real>(
    src: &Source<R>,
    steps: &Steps<R>,
    k0: usize,
    m: usize,
    value: &mut [R; BATCH],
    len: &mut [R; BATCH],
) {
    debug_assert!((1..=BATCH).contains(&m) && k0 + m <= steps.n);
    #[cfg(target_arch = "x86_64")]
    {
        if values_in_lanes(src, steps.n) {
            // SAFETY: R is f32 (checked by `values_in_lanes`), so these have f32's layout.
            let (s, st, v, l) = unsafe {
                (
                    &*(src as *const Source<R> as *const Source<f32>),
                    &*(steps as *const Steps<R> as *const Steps<f32>),
                    &mut *(value as *mut [R; BATCH] as *mut [f32; BATCH]),
                    &mut *(len as *mut [R; BATCH] as *mut [f32; BATCH]),
                )
            };
            // SAFETY: `values_in_lanes` checked the CPU's features and the index ranges.
            if unsafe { simd::values_f32x16(s, st, k0, m, v, l) } {
                return;
            }
        }
    }
    for l in 0..m {
        let (p, length) = steps.segment(k0 + l);
        value[l] = sample(src.grid, src.filter, p - src.local_origin());
        len[l] = length;
    }
}

#[cfg(target_arch = "x86_64")]
mod simd {
    use super::{Batch, Packet, Source, Steps, BATCH, PACKET};
    use std::arch::x86_64::*;

    /// Whether the AVX-512 batch can run: the CPU has it, every voxel index, table
    /// index and step index fits the 32-bit lanes (steps below 2²⁴ are exact in f32),
    /// and the grid is at least two voxels wide (voxels are fetched in x pairs).
    pub fn usable(voxels: usize, nx: usize, entries: usize, steps: usize) -> bool {
        voxels < i32::MAX as usize
            && entries * 8 < i32::MAX as usize
            && steps < 1 << 24
            && nx >= 2
            && std::arch::is_x86_feature_detected!("avx512f")
    }

    /// Fetches the 64-bit pairs at the 16 float offsets `at` of `base`: returns the
    /// first and the second float of each pair.
    #[inline(always)]
    unsafe fn pairs(base: *const f32, at: __m512i) -> (__m512, __m512) {
        let lo = _mm512_i32gather_epi64::<4>(_mm512_castsi512_si256(at), base as *const i64);
        let hi =
            _mm512_i32gather_epi64::<4>(_mm512_extracti64x4_epi64::<1>(at), base as *const i64);
        let (lo, hi) = (_mm512_castsi512_ps(lo), _mm512_castsi512_ps(hi));
        let even = _mm512_set_epi32(30, 28, 26, 24, 22, 20, 18, 16, 14, 12, 10, 8, 6, 4, 2, 0);
        let odd = _mm512_set_epi32(31, 29, 27, 25, 23, 21, 19, 17, 15, 13, 11, 9, 7, 5, 3, 1);
        (
            _mm512_permutex2var_ps(lo, even, hi),
            _mm512_permutex2var_ps(lo, odd, hi),
        )
    }

    /// Sixteen step grids, one per lane (the same ray in every lane for a batch).
    struct Lanes {
        o: [__m512; 3],
        d: [__m512; 3],
        t_in: __m512,
        t_out: __m512,
        t_s: __m512,
        dt: __m512,
        n: __m512i,
        speed: __m512,
    }

    /// Sixteen classified steps.
    struct Classified {
        p: [__m512; 3],
        rgb: [__m512; 3],
        alpha: __m512,
        /// `1 − (1 − α)^e` (`shade::transmit_pow`: a square root for ½, the power
        /// of `real::pow01` for exponents other than ½ and 1).
        alpha_step: __m512,
        /// Lanes whose coordinates are all in (−1e9, 1e9), where the scalar path floors
        /// by truncation; the others are to be computed by the scalar path.
        moderate: u16,
    }

    /// Steps `k` (one per lane) of the step grids `g`, classified: the arithmetic of
    /// `Steps::segment`, `filter::sample` (trilinear), `LutR::classify` and
    /// `shade::transmit_pow`, in the same order.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn classify(src: &Source<f32>, g: &Lanes, k: __m512i) -> Classified {
        let at = place::<true>(src, g, k);
        let v = reconstruct(src, &at);
        look_up(src, g, &at, v)
    }

    /// Where steps `k` fall: their midpoints and lengths, and the trilinear filter's
    /// taps and weights there.
    struct Taps {
        p: [__m512; 3],
        len: __m512,
        /// Lanes at a first or last step (clipped; the others are full steps).
        ends: __mmask16,
        moderate: u16,
        /// The 64-bit fetch offsets of the four x pairs: (y0, z0), (y1, z0), (y0, z1), (y1, z1).
        at: [__m512i; 4],
        f: [__m512; 3],
        lo_edge: __mmask16,
        hi_edge: __mmask16,
    }

    /// The first stage of [`classify`]: positions and taps, no memory read. With
    /// `CHECK` false every lane is taken as moderate (packets check each ray once, in
    /// [`Packet::start`]).
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn place<const CHECK: bool>(src: &Source<f32>, g: &Lanes, k: __m512i) -> Taps {
        let one_i = _mm512_set1_epi32(1);
        let zero_i = _mm512_setzero_si512();
        let k1 = _mm512_add_epi32(k, one_i);
        let (first, last) = (
            _mm512_cmpeq_epi32_mask(k, zero_i),
            _mm512_cmpeq_epi32_mask(k1, g.n),
        );
        // A full step: midpoint t_s + (k + ½)·dt, length dt.
        let kf = _mm512_cvtepi32_ps(k);
        let half = _mm512_set1_ps(0.5);
        let mut mid = _mm512_add_ps(g.t_s, _mm512_mul_ps(_mm512_add_ps(kf, half), g.dt));
        let mut len = g.dt;
        let ends = first | last;
        if ends != 0 {
            // ta = t_in for k = 0, else t_s + k·dt; tb = t_out for k + 1 = n, else
            // t_s + (k+1)·dt.
            let ta =
                _mm512_mask_blend_ps(first, _mm512_add_ps(g.t_s, _mm512_mul_ps(kf, g.dt)), g.t_in);
            let tb = _mm512_mask_blend_ps(
                last,
                _mm512_add_ps(g.t_s, _mm512_mul_ps(_mm512_cvtepi32_ps(k1), g.dt)),
                g.t_out,
            );
            mid = _mm512_mask_blend_ps(ends, mid, _mm512_mul_ps(_mm512_add_ps(ta, tb), half));
            len = _mm512_mask_blend_ps(ends, len, _mm512_sub_ps(tb, ta));
        }
        let p = [0, 1, 2].map(|a| _mm512_add_ps(g.o[a], _mm512_mul_ps(g.d[a], mid)));
        // In the grid's own index space (a brick's: the exact subtraction of its field).
        let q = [0, 1, 2].map(|a| _mm512_sub_ps(p[a], _mm512_set1_ps(src.origin[a])));
        let (lim, neg_lim) = (_mm512_set1_ps(1e9), _mm512_set1_ps(-1e9));
        let mut moderate = 0xffffu16;
        if CHECK {
            for x in p {
                moderate &= _mm512_cmp_ps_mask::<_CMP_GT_OQ>(x, neg_lim)
                    & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(x, lim);
            }
        }
        let dims = src.grid.dims;
        // ⌊x⌋ (exact: rounded toward −∞) and f = x − ⌊x⌋.
        let floor = |x: __m512| {
            let fl = _mm512_roundscale_ps::<{ _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC }>(x);
            (_mm512_cvttps_epi32(fl), _mm512_sub_ps(x, fl))
        };
        let clamp = |i: __m512i, n: usize| {
            _mm512_min_epi32(_mm512_max_epi32(i, zero_i), _mm512_set1_epi32(n as i32 - 1))
        };
        let (ix, fx) = floor(q[0]);
        let (iy, fy) = floor(q[1]);
        let (iz, fz) = floor(q[2]);
        // Row offsets of the clamped taps, each one product (no chained multiplies).
        let nx = _mm512_set1_epi32(dims[0] as i32);
        let nxy = _mm512_set1_epi32((dims[0] * dims[1]) as i32);
        let (y0, y1) = (
            _mm512_mullo_epi32(nx, clamp(iy, dims[1])),
            _mm512_mullo_epi32(nx, clamp(_mm512_add_epi32(iy, one_i), dims[1])),
        );
        let (z0, z1) = (
            _mm512_mullo_epi32(nxy, clamp(iz, dims[2])),
            _mm512_mullo_epi32(nxy, clamp(_mm512_add_epi32(iz, one_i), dims[2])),
        );
        // Along x the taps ⌊x⌋ and ⌊x⌋ + 1 (clamped) come from one 64-bit fetch at
        // c = clamp(⌊x⌋, 0, nx − 2): below the grid both taps are voxel c, at or past
        // its last voxel both are c + 1.
        let cx = clamp(ix, dims[0] - 1);
        let (z0, z1) = (_mm512_add_epi32(z0, cx), _mm512_add_epi32(z1, cx));
        Taps {
            p,
            len,
            ends,
            moderate,
            at: [
                _mm512_add_epi32(y0, z0),
                _mm512_add_epi32(y1, z0),
                _mm512_add_epi32(y0, z1),
                _mm512_add_epi32(y1, z1),
            ],
            f: [fx, fy, fz],
            lo_edge: _mm512_cmplt_epi32_mask(ix, zero_i),
            hi_edge: _mm512_cmpge_epi32_mask(ix, _mm512_set1_epi32(dims[0] as i32 - 1)),
        }
    }

    /// The second stage of [`classify`]: the trilinear value at the taps.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn reconstruct(src: &Source<f32>, t: &Taps) -> __m512 {
        let one = _mm512_set1_ps(1.0);
        let [fx, fy, fz] = t.f;
        let (wx0, wy0, wz0) = (
            _mm512_sub_ps(one, fx),
            _mm512_sub_ps(one, fy),
            _mm512_sub_ps(one, fz),
        );
        let data = src.grid.data.as_ptr();
        // The scalar sums start from zero; here the first product stands in for
        // 0 + product, which differs only in the sign of a zero (and a zero's sign
        // changes nothing downstream: the table index is clamped at 0).
        let edges = (t.lo_edge | t.hi_edge) != 0;
        let line = |at: __m512i| {
            let (p0, p1) = pairs(data, at);
            let (a, c) = if edges {
                (
                    _mm512_mask_blend_ps(t.hi_edge, p0, p1),
                    _mm512_mask_blend_ps(t.lo_edge, p1, p0),
                )
            } else {
                (p0, p1)
            };
            _mm512_add_ps(_mm512_mul_ps(wx0, a), _mm512_mul_ps(fx, c))
        };
        let plane = |a0: __m512i, a1: __m512i| {
            _mm512_add_ps(_mm512_mul_ps(wy0, line(a0)), _mm512_mul_ps(fy, line(a1)))
        };
        _mm512_add_ps(
            _mm512_mul_ps(wz0, plane(t.at[0], t.at[1])),
            _mm512_mul_ps(fz, plane(t.at[2], t.at[3])),
        )
    }

    /// The last stage of [`classify`]: the table's colour and opacity at value `v`,
    /// and the opacity correction for each step's length.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn look_up(src: &Source<f32>, g: &Lanes, t: &Taps, v: __m512) -> Classified {
        let one = _mm512_set1_ps(1.0);
        let zero = _mm512_setzero_ps();
        // LutR::classify: x = clamp(scale·v + offset, 0, n − 1), linear between entries.
        let lut = src.lut;
        let n_e = src.pairs.len();
        let xl = _mm512_min_ps(
            _mm512_max_ps(
                _mm512_add_ps(
                    _mm512_mul_ps(_mm512_set1_ps(lut.scale), v),
                    _mm512_set1_ps(lut.offset),
                ),
                zero,
            ),
            _mm512_set1_ps((n_e - 1) as f32),
        );
        let i0 = _mm512_min_epi32(_mm512_cvttps_epi32(xl), _mm512_set1_epi32(n_e as i32 - 1));
        let f = _mm512_sub_ps(xl, _mm512_cvtepi32_ps(i0));
        let e0 = _mm512_slli_epi32::<3>(i0);
        let table = src.pairs.as_ptr() as *const f32;
        let channel = |c: i32| {
            let (a, d) = pairs(table, _mm512_add_epi32(e0, _mm512_set1_epi32(2 * c)));
            _mm512_add_ps(a, _mm512_mul_ps(f, d))
        };
        let alpha = channel(3);
        // Steps::exponent: e_full for full steps, len·speed/Δs₀ for the others.
        let mut e = _mm512_set1_ps(src.e_full);
        if t.ends != 0 {
            let clipped =
                _mm512_div_ps(_mm512_mul_ps(t.len, g.speed), _mm512_set1_ps(src.ref_step));
            e = _mm512_mask_blend_ps(t.ends, e, clipped);
        }
        let keep = _mm512_sub_ps(one, alpha);
        let half = _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(e, _mm512_set1_ps(0.5));
        let unit = _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(e, one);
        let mut tr = _mm512_mask_blend_ps(half, keep, _mm512_sqrt_ps(keep));
        let general = !(half | unit);
        if general != 0 {
            tr = _mm512_mask_blend_ps(general, tr, crate::real::pow01::pow01_x16(keep, e));
        }
        Classified {
            p: t.p,
            rgb: [channel(0), channel(1), channel(2)],
            alpha,
            alpha_step: _mm512_sub_ps(one, tr),
            moderate: t.moderate,
        }
    }

    /// Steps `k0 .. k0 + m` of one ray in the sixteen lanes: the ray's step grid in
    /// every lane, the step indices, and the lanes that hold a step (lanes past the
    /// batch repeat step `k0`: valid indices, their results unused).
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn batch_lanes(
        src: &Source<f32>,
        st: &Steps<f32>,
        k0: usize,
        m: usize,
    ) -> (Lanes, __m512i, __mmask16) {
        let lanes = _mm512_set_epi32(15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0);
        let live: __mmask16 = if m >= BATCH { 0xffff } else { (1u16 << m) - 1 };
        let k = _mm512_mask_add_epi32(
            _mm512_set1_epi32(k0 as i32),
            live,
            _mm512_set1_epi32(k0 as i32),
            lanes,
        );
        let g = Lanes {
            o: st.o.0.map(|x| _mm512_set1_ps(x)),
            d: st.d.0.map(|x| _mm512_set1_ps(x)),
            t_in: _mm512_set1_ps(st.t_in),
            t_out: _mm512_set1_ps(st.t_out),
            t_s: _mm512_set1_ps(st.t_s),
            dt: _mm512_set1_ps(st.dt),
            n: _mm512_set1_epi32(st.n as i32),
            speed: _mm512_set1_ps(src.speed),
        };
        (g, k, live)
    }

    /// [`Batch::fill`] in sixteen f32 lanes with the trilinear filter. Returns `false`
    /// (and fills nothing) when a coordinate is out of the range where the scalar path
    /// floors by truncation; the caller then takes the scalar path.
    ///
    /// # Safety
    /// The CPU must support AVX-512F and [`usable`] must hold.
    #[target_feature(enable = "avx512f")]
    pub unsafe fn fill_f32x16(
        b: &mut Batch<f32>,
        src: &Source<f32>,
        st: &Steps<f32>,
        k0: usize,
        m: usize,
    ) -> bool {
        let (g, k, live) = batch_lanes(src, st, k0, m);
        let c = classify(src, &g, k);
        if c.moderate & live != live {
            return false;
        }
        for a in 0..3 {
            _mm512_storeu_ps(b.p[a].as_mut_ptr(), c.p[a]);
            _mm512_storeu_ps(b.rgb[a].as_mut_ptr(), c.rgb[a]);
        }
        _mm512_storeu_ps(b.alpha.as_mut_ptr(), c.alpha);
        _mm512_storeu_ps(b.alpha_step.as_mut_ptr(), c.alpha_step);
        b.visible = (_mm512_cmp_ps_mask::<_CMP_GT_OQ>(c.alpha, _mm512_setzero_ps()) & live) as u32;
        true
    }

    /// [`super::values`] in sixteen f32 lanes with the trilinear filter. Returns `false`
    /// (and fills nothing) when a coordinate is out of the range where the scalar path
    /// floors by truncation; the caller then takes the scalar path.
    ///
    /// # Safety
    /// The CPU must support AVX-512F and [`usable`] must hold.
    #[target_feature(enable = "avx512f")]
    pub unsafe fn values_f32x16(
        src: &Source<f32>,
        st: &Steps<f32>,
        k0: usize,
        m: usize,
        value: &mut [f32; BATCH],
        len: &mut [f32; BATCH],
    ) -> bool {
        let (g, k, live) = batch_lanes(src, st, k0, m);
        let taps = place::<true>(src, &g, k);
        if taps.moderate & live != live {
            return false;
        }
        // `reconstruct` leaves out the scalar sums' leading `0 +`, which only changes
        // the sign of a zero result: adding +0 restores it (a max or min of the values
        // could otherwise keep a −0 the scalar path never gives).
        let v = _mm512_add_ps(reconstruct(src, &taps), _mm512_setzero_ps());
        _mm512_storeu_ps(value.as_mut_ptr(), v);
        _mm512_storeu_ps(len.as_mut_ptr(), taps.len);
        true
    }

    /// One step of every live ray of a packet, composited front to back. Returns the
    /// lanes whose current range ended or that reached the early-termination threshold
    /// `ert`, and the latter apart.
    ///
    /// # Safety
    /// The CPU must support AVX-512F and [`usable`] must hold for every live lane.
    #[target_feature(enable = "avx512f")]
    pub unsafe fn packet_step(pk: &mut Packet, src: &Source<f32>, ert: f32) -> (u16, u16) {
        let (g, k) = lanes(pk);
        let mut c = classify(src, &g, k);
        finish_odd(pk, src, &mut c);
        composite(pk, &c, k, ert)
    }

    /// [`packet_step`] for `N` packets at once, their stages interleaved so that the
    /// fetches of one overlap the arithmetic of the others: the images are the same.
    /// Packets with no live lane are stepped too (their results are masked off).
    ///
    /// # Safety
    /// As [`packet_step`], for every packet.
    #[target_feature(enable = "avx512f")]
    pub unsafe fn packet_steps<const N: usize>(
        pks: &mut [Packet; N],
        src: &Source<f32>,
        ert: f32,
    ) -> [(u16, u16); N] {
        // Plain loops over zeroed arrays (all-zero bits are valid for these vector
        // types): they unroll and stay in registers, where `array::from_fn` does not.
        let mut g: [Lanes; N] = std::mem::zeroed();
        let mut k: [__m512i; N] = std::mem::zeroed();
        for i in 0..N {
            (g[i], k[i]) = lanes(&pks[i]);
        }
        let mut taps: [Taps; N] = std::mem::zeroed();
        for i in 0..N {
            taps[i] = place::<false>(src, &g[i], k[i]);
        }
        let mut v: [__m512; N] = std::mem::zeroed();
        for i in 0..N {
            v[i] = reconstruct(src, &taps[i]);
        }
        let mut c: [Classified; N] = std::mem::zeroed();
        for i in 0..N {
            c[i] = look_up(src, &g[i], &taps[i], v[i]);
            c[i].moderate = !pks[i].far;
        }
        let mut out = [(0u16, 0u16); N];
        for i in 0..N {
            finish_odd(&pks[i], src, &mut c[i]);
            out[i] = composite(&mut pks[i], &c[i], k[i], ert);
        }
        out
    }

    /// A packet's step grids and current steps.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn lanes(pk: &Packet) -> (Lanes, __m512i) {
        let ld = |x: &[f32; PACKET]| _mm512_loadu_ps(x.as_ptr());
        let g = Lanes {
            o: [ld(&pk.o[0]), ld(&pk.o[1]), ld(&pk.o[2])],
            d: [ld(&pk.d[0]), ld(&pk.d[1]), ld(&pk.d[2])],
            t_in: ld(&pk.t_in),
            t_out: ld(&pk.t_out),
            t_s: ld(&pk.t_s),
            dt: ld(&pk.dt),
            n: _mm512_loadu_si512(pk.n.as_ptr() as *const _),
            speed: ld(&pk.speed),
        };
        (g, _mm512_loadu_si512(pk.k.as_ptr() as *const _))
    }

    /// Classifies lane by lane the live lanes where the vector path does not apply.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn finish_odd(pk: &Packet, src: &Source<f32>, c: &mut Classified) {
        let odd = !c.moderate & pk.live;
        if odd == 0 {
            return;
        }
        let ld = |x: &[f32; PACKET]| _mm512_loadu_ps(x.as_ptr());
        let mut rgb = [[0f32; PACKET]; 3];
        let (mut alpha, mut alpha_step) = ([0f32; PACKET], [0f32; PACKET]);
        for (a, v) in rgb.iter_mut().enumerate() {
            _mm512_storeu_ps(v.as_mut_ptr(), c.rgb[a]);
        }
        _mm512_storeu_ps(alpha.as_mut_ptr(), c.alpha);
        _mm512_storeu_ps(alpha_step.as_mut_ptr(), c.alpha_step);
        for l in 0..PACKET {
            if odd & (1 << l) != 0 {
                let st = pk.steps(l);
                let k = pk.k[l] as usize;
                let (p, len) = st.segment(k);
                let v = super::sample(src.grid, src.filter, p - src.local_origin());
                let q = src.lut.classify(v);
                for a in 0..3 {
                    rgb[a][l] = q[a];
                }
                alpha[l] = q[3];
                let e = st.exponent(k, len, pk.speed[l], src.ref_step, src.e_full);
                alpha_step[l] = 1.0 - crate::cpu::shade::transmit_pow(1.0 - q[3], e);
            }
        }
        c.rgb = [ld(&rgb[0]), ld(&rgb[1]), ld(&rgb[2])];
        c.alpha = ld(&alpha);
        c.alpha_step = ld(&alpha_step);
    }

    /// `shade::under_until` lane by lane where the step is visible, and the next step.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn composite(pk: &mut Packet, c: &Classified, k: __m512i, ert: f32) -> (u16, u16) {
        let live = pk.live;
        let ld = |x: &[f32; PACKET]| _mm512_loadu_ps(x.as_ptr());
        let visible = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(c.alpha, _mm512_setzero_ps()) & live;
        let mut a = ld(&pk.a);
        let w = _mm512_mul_ps(_mm512_sub_ps(_mm512_set1_ps(1.0), a), c.alpha_step);
        for (ch, rgb) in c.rgb.iter().enumerate() {
            let acc = ld(&pk.c[ch]);
            let acc = _mm512_mask_add_ps(acc, visible, acc, _mm512_mul_ps(w, *rgb));
            _mm512_storeu_ps(pk.c[ch].as_mut_ptr(), acc);
        }
        a = _mm512_mask_add_ps(a, visible, a, w);
        _mm512_storeu_ps(pk.a.as_mut_ptr(), a);
        let hit = _mm512_mask_cmp_ps_mask::<_CMP_GE_OQ>(visible, a, _mm512_set1_ps(ert));
        let one_i = _mm512_set1_epi32(1);
        let taken = _mm512_loadu_si512(pk.taken.as_ptr() as *const _);
        _mm512_storeu_si512(
            pk.taken.as_mut_ptr() as *mut _,
            _mm512_mask_add_epi32(taken, live, taken, one_i),
        );
        let k = _mm512_mask_add_epi32(k, live, k, one_i);
        _mm512_storeu_si512(pk.k.as_mut_ptr() as *mut _, k);
        let k_hi = _mm512_loadu_si512(pk.k_hi.as_ptr() as *const _);
        let past = _mm512_mask_cmpgt_epi32_mask(live, k, k_hi);
        (past | hit, hit)
    }
}

/// Rays in a packet.
pub const PACKET: usize = 16;

/// Sixteen rays marched together (DVR, front to back, f32): per lane its step grid,
/// its current range of steps `k ..= k_hi` and what it has composited so far.
#[derive(Clone, Debug, Default)]
pub struct Packet {
    pub o: [[f32; PACKET]; 3],
    pub d: [[f32; PACKET]; 3],
    pub t_in: [f32; PACKET],
    pub t_out: [f32; PACKET],
    pub t_s: [f32; PACKET],
    pub dt: [f32; PACKET],
    pub n: [i32; PACKET],
    pub speed: [f32; PACKET],
    pub k: [i32; PACKET],
    pub k_hi: [i32; PACKET],
    pub c: [[f32; PACKET]; 3],
    pub a: [f32; PACKET],
    pub taken: [u32; PACKET],
    /// Bit `l` set while lane `l` holds a ray.
    pub live: u16,
    /// Bit `l` set when lane `l`'s ray reaches coordinates of 5·10⁸ or more, where
    /// the scalar path floors differently: its steps are classified lane by lane.
    pub far: u16,
}

impl Packet {
    /// Puts a ray in lane `l`, at the start of its range `k_lo ..= k_hi`.
    pub fn start(&mut self, l: usize, st: &Steps<f32>, speed: f32, (k_lo, k_hi): (usize, usize)) {
        for a in 0..3 {
            self.o[a][l] = st.o.0[a];
            self.d[a][l] = st.d.0[a];
            self.c[a][l] = 0.0;
        }
        self.t_in[l] = st.t_in;
        self.t_out[l] = st.t_out;
        self.t_s[l] = st.t_s;
        self.dt[l] = st.dt;
        self.n[l] = st.n as i32;
        self.speed[l] = speed;
        self.k[l] = k_lo as i32;
        self.k_hi[l] = k_hi as i32;
        self.a[l] = 0.0;
        self.taken[l] = 0;
        self.live |= 1 << l;
        // Every sample lies between the ray's ends (and within rounding of them).
        let moderate = |t: f32| (0..3).all(|a| (st.o.0[a] + st.d.0[a] * t).abs() < 5e8);
        if moderate(st.t_in) && moderate(st.t_out) && moderate(st.t_s) {
            self.far &= !(1 << l);
        } else {
            self.far |= 1 << l;
        }
    }

    /// Lane `l`'s step grid.
    pub fn steps(&self, l: usize) -> Steps<f32> {
        Steps {
            o: V3::new(self.o[0][l], self.o[1][l], self.o[2][l]),
            d: V3::new(self.d[0][l], self.d[1][l], self.d[2][l]),
            t_in: self.t_in[l],
            t_out: self.t_out[l],
            t_s: self.t_s[l],
            dt: self.dt[l],
            n: self.n[l] as usize,
        }
    }

    /// One step of every live lane; see `simd::packet_step`. `None` when the CPU has
    /// no AVX-512 (then packets are not used).
    pub fn step(&mut self, src: &Source<f32>, ert: f32) -> Option<(u16, u16)> {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the feature is present; `packets_usable` held when the packet
            // path was chosen.
            return Some(unsafe { simd::packet_step(self, src, ert) });
        }
        None
    }

    /// [`Packet::step`] for `N` packets at once (the same results, faster); a packet
    /// with no live lane gives `(0, 0)`.
    pub fn step_all<const N: usize>(
        pks: &mut [Packet; N],
        src: &Source<f32>,
        ert: f32,
    ) -> Option<[(u16, u16); N]> {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: as in `step`.
            return Some(unsafe { simd::packet_steps(pks, src, ert) });
        }
        None
    }
}

/// Whether rays can be marched in packets for this grid and table, with at most
/// `max_steps` steps per ray: f32 on an AVX-512 CPU with the trilinear filter.
pub fn packets_usable(src: &Source<f32>, max_steps: usize) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        src.filter == Filter::Trilinear
            && simd::usable(
                src.grid.data.len(),
                src.grid.dims[0],
                src.pairs.len(),
                max_steps,
            )
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The steps a ray walks are the midpoint rule's: lengths sum to `t_out − t_in`.
    #[test]
    fn steps_cover_the_ray() {
        let st = Steps {
            o: V3::new(0.0f64, 0.0, 0.0),
            d: V3::new(0.0, 0.0, 1.0),
            t_in: 0.3,
            t_out: 5.0,
            t_s: 0.05,
            dt: 0.5,
            n: 10,
        };
        let total: f64 = (0..st.n).map(|k| st.segment(k).1).sum();
        assert!((total - 4.7).abs() < 1e-12, "{total}");
        assert_eq!(st.segment(0).0.z(), 0.3 * 0.5 + 0.55 * 0.5);
    }
}
