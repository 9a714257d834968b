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
//! `raycast::transmit_pow`), without fused multiply–adds, so the images are the same
//! to the last bit; the unit tests below check that on every view and setting.

use super::filter::{sample, Grid};
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
    /// Step `k`'s midpoint and length (`t` units).
    #[inline(always)]
    pub fn segment(&self, k: usize) -> (V3<R>, R) {
        let ta = if k == 0 {
            self.t_in
        } else {
            self.t_s + R::of(k as f64) * self.dt
        };
        let tb = if k + 1 == self.n {
            self.t_out
        } else {
            self.t_s + R::of((k + 1) as f64) * self.dt
        };
        (self.o + self.d * ((ta + tb) * R::of(0.5)), tb - ta)
    }
}

/// What the batched kernel reads: the grid the filter samples and the 1D table.
#[derive(Clone, Copy)]
pub struct Source<'a, R> {
    pub grid: &'a Grid<R>,
    pub filter: Filter,
    pub lut: &'a LutR<R>,
    /// The table as [`lut_pairs`] lays it out for the vector path.
    pub pairs: &'a [[R; 8]],
    /// Voxels per `t` unit along the ray (`|d|`).
    pub speed: R,
    /// The reference step `Δs₀` in voxels.
    pub ref_step: R,
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
            let c = src.lut.classify(sample(src.grid, src.filter, p));
            for (a, (&x, &v)) in p.0.iter().zip(&c).enumerate() {
                self.p[a][l] = x;
                self.rgb[a][l] = v;
            }
            self.alpha[l] = c[3];
            if c[3] > R::zero() {
                self.visible |= 1 << l;
            }
            self.alpha_step[l] = R::one()
                - super::raycast::transmit_pow(R::one() - c[3], len * src.speed / src.ref_step);
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

#[cfg(target_arch = "x86_64")]
mod simd {
    use super::{Batch, Source, Steps, BATCH};
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
        let lanes = _mm512_set_epi32(15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0);
        let live: __mmask16 = if m >= BATCH { 0xffff } else { (1u16 << m) - 1 };
        // Lanes past the batch repeat step k0 (valid indices; their results are unused).
        let k = _mm512_mask_add_epi32(
            _mm512_set1_epi32(k0 as i32),
            live,
            _mm512_set1_epi32(k0 as i32),
            lanes,
        );
        let one_i = _mm512_set1_epi32(1);
        let zero_i = _mm512_setzero_si512();
        let k1 = _mm512_add_epi32(k, one_i);
        let (ts, dt) = (_mm512_set1_ps(st.t_s), _mm512_set1_ps(st.dt));
        // ta = t_in for k = 0, else t_s + k·dt; tb = t_out for k + 1 = n, else t_s + (k+1)·dt.
        let ta = _mm512_mask_blend_ps(
            _mm512_cmpeq_epi32_mask(k, zero_i),
            _mm512_add_ps(ts, _mm512_mul_ps(_mm512_cvtepi32_ps(k), dt)),
            _mm512_set1_ps(st.t_in),
        );
        let tb = _mm512_mask_blend_ps(
            _mm512_cmpeq_epi32_mask(k1, _mm512_set1_epi32(st.n as i32)),
            _mm512_add_ps(ts, _mm512_mul_ps(_mm512_cvtepi32_ps(k1), dt)),
            _mm512_set1_ps(st.t_out),
        );
        let mid = _mm512_mul_ps(_mm512_add_ps(ta, tb), _mm512_set1_ps(0.5));
        let len = _mm512_sub_ps(tb, ta);
        let pos = |a: usize| {
            _mm512_add_ps(
                _mm512_set1_ps(st.o.0[a]),
                _mm512_mul_ps(_mm512_set1_ps(st.d.0[a]), mid),
            )
        };
        let p = [pos(0), pos(1), pos(2)];
        // The scalar path floors by truncation only for |x| < 1e9.
        let lim = _mm512_set1_ps(1e9);
        let neg_lim = _mm512_set1_ps(-1e9);
        let mut moderate = 0xffffu16;
        for x in p {
            moderate &= _mm512_cmp_ps_mask::<_CMP_GT_OQ>(x, neg_lim)
                & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(x, lim);
        }
        if moderate & live != live {
            return false;
        }
        let dims = src.grid.dims;
        // ⌊x⌋ by truncation, one down for negative non-integers, and f = x − ⌊x⌋.
        let floor = |x: __m512| {
            let t = _mm512_cvttps_epi32(x);
            let down = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(_mm512_cvtepi32_ps(t), x);
            let i0 = _mm512_mask_sub_epi32(t, down, t, one_i);
            (i0, _mm512_sub_ps(x, _mm512_cvtepi32_ps(i0)))
        };
        let clamp = |i: __m512i, n: usize| {
            _mm512_min_epi32(_mm512_max_epi32(i, zero_i), _mm512_set1_epi32(n as i32 - 1))
        };
        let one = _mm512_set1_ps(1.0);
        let (ix, fx) = floor(p[0]);
        let (iy, fy) = floor(p[1]);
        let (iz, fz) = floor(p[2]);
        let (wx0, wy0, wz0) = (
            _mm512_sub_ps(one, fx),
            _mm512_sub_ps(one, fy),
            _mm512_sub_ps(one, fz),
        );
        let (y0, y1) = (
            clamp(iy, dims[1]),
            clamp(_mm512_add_epi32(iy, one_i), dims[1]),
        );
        let (z0, z1) = (
            clamp(iz, dims[2]),
            clamp(_mm512_add_epi32(iz, one_i), dims[2]),
        );
        // Along x the taps ⌊x⌋ and ⌊x⌋ + 1 (clamped) come from one 64-bit fetch at
        // c = clamp(⌊x⌋, 0, nx − 2): below the grid both taps are voxel c, at or past
        // its last voxel both are c + 1.
        let cx = clamp(ix, dims[0] - 1);
        let lo_edge = _mm512_cmplt_epi32_mask(ix, zero_i);
        let hi_edge = _mm512_cmpge_epi32_mask(ix, _mm512_set1_epi32(dims[0] as i32 - 1));
        let data = src.grid.data.as_ptr();
        let (nx, ny) = (
            _mm512_set1_epi32(dims[0] as i32),
            _mm512_set1_epi32(dims[1] as i32),
        );
        let zero = _mm512_setzero_ps();
        let line = |j: __m512i, kk: __m512i| {
            let row = _mm512_mullo_epi32(nx, _mm512_add_epi32(j, _mm512_mullo_epi32(ny, kk)));
            let (p0, p1) = pairs(data, _mm512_add_epi32(row, cx));
            let a = _mm512_mask_blend_ps(hi_edge, p0, p1);
            let c = _mm512_mask_blend_ps(lo_edge, p1, p0);
            _mm512_add_ps(
                _mm512_add_ps(zero, _mm512_mul_ps(wx0, a)),
                _mm512_mul_ps(fx, c),
            )
        };
        let plane = |kk: __m512i| {
            _mm512_add_ps(
                _mm512_add_ps(zero, _mm512_mul_ps(wy0, line(y0, kk))),
                _mm512_mul_ps(fy, line(y1, kk)),
            )
        };
        let v = _mm512_add_ps(
            _mm512_add_ps(zero, _mm512_mul_ps(wz0, plane(z0))),
            _mm512_mul_ps(fz, plane(z1)),
        );
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
        // The opacity correction; exponents other than ½ and 1 (shortened end steps)
        // are raised lane by lane below.
        let e = _mm512_div_ps(
            _mm512_mul_ps(len, _mm512_set1_ps(src.speed)),
            _mm512_set1_ps(src.ref_step),
        );
        let keep = _mm512_sub_ps(one, alpha);
        let half = _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(e, _mm512_set1_ps(0.5));
        let unit = _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(e, one);
        let tr = _mm512_mask_blend_ps(half, keep, _mm512_sqrt_ps(keep));
        for (a, x) in p.iter().enumerate() {
            _mm512_storeu_ps(b.p[a].as_mut_ptr(), *x);
        }
        for c in 0..3 {
            _mm512_storeu_ps(b.rgb[c].as_mut_ptr(), channel(c as i32));
        }
        _mm512_storeu_ps(b.alpha.as_mut_ptr(), alpha);
        _mm512_storeu_ps(b.alpha_step.as_mut_ptr(), _mm512_sub_ps(one, tr));
        b.visible = (_mm512_cmp_ps_mask::<_CMP_GT_OQ>(alpha, zero) & live) as u32;
        let general = !(half | unit) & live;
        if general != 0 {
            let mut ev = [0f32; BATCH];
            _mm512_storeu_ps(ev.as_mut_ptr(), e);
            for (l, &e) in ev.iter().enumerate() {
                if general & (1 << l) != 0 {
                    b.alpha_step[l] = 1.0 - (1.0 - b.alpha[l]).powf(e);
                }
            }
        }
        true
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
