//! `x^e` for a transmittance `x ∈ [0, 1]` and an exponent `e > 0`, in f32, written so
//! that sixteen vector lanes compute it with the same operations in the same order:
//! the opacity correction `1 − (1 − α)^e` of the CPU's f32 ray caster for steps that
//! are neither half nor the whole reference step. The scalar function ([`pow01`]) and
//! its AVX-512 twin (`pow01_x16`) give the same bits, so the batched and per-sample
//! kernels stay equal to the last bit; the library `powf` has no vector twin.
//!
//! `ln x = k ln 2 + ln m` with `x = m·2^k`, `m ∈ [√½, √2)`, and
//! `ln m = 2s(1 + s²/3 + s⁴/5 + s⁶/7 + s⁸/9)`, `s = (m − 1)/(m + 1)`; then
//! `exp(e ln x) = 2^n exp(r)` with `n` the nearest integer to `e ln x / ln 2` and `r`
//! reduced by a two-part `ln 2` (Cody–Waite), `exp(r)` by its Taylor series to `r⁷`.
//! Relative error within 1.2·10⁻⁷·(1 + |ln x^e|) of f64 (measured in `tests` below,
//! which hold it to 2.5·10⁻⁷·(1 + |ln x^e|)): about 2 ulps for the transmittances
//! near 1 that matter.

/// ln 2 in two parts: the high part has 9 significant bits, so `k·LN2_HI` is exact.
const LN2_HI: f32 = 0.693_359_4;
const LN2_LO: f32 = -2.121_944_4e-4;
const LOG2E: f32 = std::f32::consts::LOG2_E;
/// 1.5·2²³: `(v + MAGIC) − MAGIC` rounds `|v| < 2²²` to the nearest integer (ties to
/// even) in scalar and vector code alike.
const MAGIC: f32 = 12_582_912.0;
/// √2's bits: mantissas above it are halved (and the exponent raised).
const SQRT2_BITS: u32 = 0x3fb5_04f3;
/// Below this `e ln x` the power is under the smallest subnormal: 0.
const Y_MIN: f32 = -104.0;
const C3: f32 = 1.0 / 3.0;
const C5: f32 = 0.2;
const C7: f32 = 1.0 / 7.0;
const C9: f32 = 1.0 / 9.0;
const F2: f32 = 0.5;
const F3: f32 = 1.0 / 6.0;
const F4: f32 = 1.0 / 24.0;
const F5: f32 = 1.0 / 120.0;
const F6: f32 = 1.0 / 720.0;
const F7: f32 = 1.0 / 5040.0;

/// `x^e` for `x ∈ [0, 1]`, `e > 0`: 0 below the smallest normal number (a
/// transmittance `1 − α` is 0 or at least 2⁻²⁴) and for NaN.
#[inline]
pub fn pow01(x: f32, e: f32) -> f32 {
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    if !(x >= f32::MIN_POSITIVE) {
        return 0.0;
    }
    let bits = x.to_bits();
    let mut k = (bits >> 23) as i32 - 127;
    let mut mb = (bits & 0x007f_ffff) | 0x3f80_0000;
    if mb > SQRT2_BITS {
        mb -= 0x0080_0000;
        k += 1;
    }
    let m = f32::from_bits(mb);
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    let p = 1.0 + s2 * (C3 + s2 * (C5 + s2 * (C7 + s2 * C9)));
    let kf = k as f32;
    let ln_x = kf * LN2_HI + (kf * LN2_LO + 2.0 * s * p);
    let y = e * ln_x;
    if y < Y_MIN {
        return 0.0;
    }
    let n = (y * LOG2E + MAGIC) - MAGIC;
    let r = (y - n * LN2_HI) - n * LN2_LO;
    let q = 1.0 + r * (1.0 + r * (F2 + r * (F3 + r * (F4 + r * (F5 + r * (F6 + r * F7))))));
    // 2^n in two normal factors (n reaches −150).
    let ni = n as i32;
    let a = ni >> 1;
    let b = ni - a;
    let two = |j: i32| f32::from_bits(((j + 127) as u32) << 23);
    (q * two(a)) * two(b)
}

/// [`pow01`] in sixteen lanes, operation for operation.
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
pub unsafe fn pow01_x16(
    x: std::arch::x86_64::__m512,
    e: std::arch::x86_64::__m512,
) -> std::arch::x86_64::__m512 {
    use std::arch::x86_64::*;
    let c = |v: f32| _mm512_set1_ps(v);
    let ci = |v: i32| _mm512_set1_epi32(v);
    let one = c(1.0);
    let positive = _mm512_cmp_ps_mask::<_CMP_GE_OQ>(x, c(f32::MIN_POSITIVE));
    let bits = _mm512_castps_si512(x);
    let mut k = _mm512_sub_epi32(_mm512_srli_epi32::<23>(bits), ci(127));
    let mut mb = _mm512_or_si512(_mm512_and_si512(bits, ci(0x007f_ffff)), ci(0x3f80_0000));
    let big = _mm512_cmpgt_epi32_mask(mb, ci(SQRT2_BITS as i32));
    mb = _mm512_mask_sub_epi32(mb, big, mb, ci(0x0080_0000));
    k = _mm512_mask_add_epi32(k, big, k, ci(1));
    let m = _mm512_castsi512_ps(mb);
    let s = _mm512_div_ps(_mm512_sub_ps(m, one), _mm512_add_ps(m, one));
    let s2 = _mm512_mul_ps(s, s);
    let p = _mm512_add_ps(
        one,
        _mm512_mul_ps(
            s2,
            _mm512_add_ps(
                c(C3),
                _mm512_mul_ps(
                    s2,
                    _mm512_add_ps(
                        c(C5),
                        _mm512_mul_ps(s2, _mm512_add_ps(c(C7), _mm512_mul_ps(s2, c(C9)))),
                    ),
                ),
            ),
        ),
    );
    let kf = _mm512_cvtepi32_ps(k);
    let ln_x = _mm512_add_ps(
        _mm512_mul_ps(kf, c(LN2_HI)),
        _mm512_add_ps(
            _mm512_mul_ps(kf, c(LN2_LO)),
            _mm512_mul_ps(_mm512_mul_ps(c(2.0), s), p),
        ),
    );
    let y = _mm512_mul_ps(e, ln_x);
    let tiny = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(y, c(Y_MIN));
    let n = _mm512_sub_ps(
        _mm512_add_ps(_mm512_mul_ps(y, c(LOG2E)), c(MAGIC)),
        c(MAGIC),
    );
    let r = _mm512_sub_ps(
        _mm512_sub_ps(y, _mm512_mul_ps(n, c(LN2_HI))),
        _mm512_mul_ps(n, c(LN2_LO)),
    );
    let mut q = _mm512_add_ps(c(F6), _mm512_mul_ps(r, c(F7)));
    for f in [F5, F4, F3, F2, 1.0, 1.0] {
        q = _mm512_add_ps(c(f), _mm512_mul_ps(r, q));
    }
    let ni = _mm512_cvttps_epi32(n);
    let a = _mm512_srai_epi32::<1>(ni);
    let b = _mm512_sub_epi32(ni, a);
    let two =
        |j: __m512i| _mm512_castsi512_ps(_mm512_slli_epi32::<23>(_mm512_add_epi32(j, ci(127))));
    let v = _mm512_mul_ps(_mm512_mul_ps(q, two(a)), two(b));
    _mm512_maskz_mov_ps(positive & !tiny, v)
}

#[cfg(test)]
mod tests {
    use super::*;

    const BOUND: f64 = 2.5e-7;

    /// Against f64's `powf`: relative error within `BOUND·(1 + |ln x^e|)` where the
    /// power is above 10⁻³⁰ (below, within 10⁻³⁵ absolute), over transmittances from 0
    /// to 1 (near 1 in particular) and exponents from 0.05 to 8.
    #[test]
    fn pow01_is_within_a_few_ulps_of_f64() {
        let mut xs: Vec<f32> = (0..=2000).map(|i| i as f32 / 2000.0).collect();
        xs.extend((1..60).map(|j| 1.0 - 2f32.powi(-j / 2 - 1)));
        xs.extend((1..120).map(|j| 2f32.powi(-j)));
        xs.extend([f32::MIN_POSITIVE, 0.999_999_94]);
        let es = [
            0.05f32,
            0.1,
            0.25,
            0.3,
            1.0 / 3.0,
            0.5,
            0.7,
            1.0,
            1.25,
            2.0,
            3.7,
            8.0,
        ];
        let mut worst = 0f64;
        for &e in &es {
            for &x in &xs {
                let got = pow01(x, e) as f64;
                let want = (x as f64).powf(e as f64);
                if want > 1e-30 {
                    // The rounding of ln x carries over to x^e as |e ln x| times it.
                    let rel = (got - want).abs() / want / (1.0 + want.ln().abs());
                    worst = worst.max(rel);
                    assert!(rel <= BOUND, "{x}^{e}: {got} vs {want} ({rel:.2e})");
                } else {
                    assert!((got - want).abs() <= 1e-35, "{x}^{e}: {got} vs {want}");
                }
            }
        }
        eprintln!("pow01: worst relative error {worst:.2e}");
        assert_eq!(pow01(0.0, 0.3), 0.0);
        assert_eq!(pow01(-0.5, 0.3), 0.0);
        assert_eq!(pow01(f32::NAN, 0.3), 0.0);
        assert_eq!(pow01(1.0, 0.3), 1.0);
    }

    /// The vector twin gives the scalar function's bits, lane for lane.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn pow01_x16_equals_the_scalar_function() {
        if !std::arch::is_x86_feature_detected!("avx512f") {
            eprintln!("no AVX-512: the vector twin is not used on this CPU");
            return;
        }
        use std::arch::x86_64::*;
        let mut state = 7u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for round in 0..4000 {
            let mut x = [0f32; 16];
            let mut e = [0f32; 16];
            for l in 0..16 {
                x[l] = match (round + l) % 5 {
                    0 => 1.0 - next() * 1e-5,
                    1 => next().powi(8),
                    2 => -next(),
                    _ => next(),
                };
                e[l] = 0.05 + 6.0 * next();
            }
            let mut got = [0f32; 16];
            // SAFETY: AVX-512F checked above.
            unsafe {
                let v = pow01_x16(_mm512_loadu_ps(x.as_ptr()), _mm512_loadu_ps(e.as_ptr()));
                _mm512_storeu_ps(got.as_mut_ptr(), v);
            }
            for l in 0..16 {
                assert_eq!(
                    got[l].to_bits(),
                    pow01(x[l], e[l]).to_bits(),
                    "{}^{}",
                    x[l],
                    e[l]
                );
            }
        }
    }
}
