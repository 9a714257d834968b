//! The floating-point abstraction the CPU oracle is generic over, and the one ray–box
//! slab test every ray in the crate is clipped with.
//!
//! Every CPU algorithm is written once for `R: Real` and instantiated at `f64` (the
//! oracle) and `f32` (the fair speed baseline, and the precision the GPU works in).
//! This module is a leaf: the model, the CPU oracle and the GPU port all import it,
//! and it imports none of them (its f32 power is its own, [`pow01`]).

pub mod pow01;

use std::fmt::{Debug, Display};
use std::iter::Sum;
use std::ops::{Add, Div, Mul, Neg, Sub};

/// A floating-point type the CPU algorithms can run in: `f32` or `f64`.
pub trait Real:
    num_traits::Float + num_traits::FloatConst + Default + Debug + Display + Sum + Send + Sync + 'static
{
    /// Name used in reports ("f32" / "f64").
    const NAME: &'static str;
    /// Converts from `f64` (rounding to nearest for `f32`).
    fn of(x: f64) -> Self;
    /// Converts to `f64` (exact).
    fn f64(self) -> f64;
    /// `self^e` for a transmittance `self ∈ [0, 1]` and `e > 0`: the library power in
    /// f64, [`pow01::pow01`] in f32 (which vector lanes reproduce bit for
    /// bit).
    fn pow01(self, e: Self) -> Self;
    /// `⌊self⌋` and, when it fits, the same as an integer: exact, and without a
    /// libm call where the value fits the hardware's truncating conversion (baseline
    /// x86-64 has no rounding instruction, so `floor` is a function call there, and
    /// the projectors take one per sample).
    fn floor_index(self) -> (Self, Option<i64>);
}

impl Real for f32 {
    const NAME: &'static str = "f32";
    #[inline(always)]
    fn of(x: f64) -> Self {
        x as f32
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self as f64
    }
    #[inline]
    fn pow01(self, e: Self) -> Self {
        pow01::pow01(self, e)
    }
    #[inline(always)]
    fn floor_index(self) -> (Self, Option<i64>) {
        if self.abs() < 2_147_483_648.0 {
            // Truncation towards zero, one down where that rounded up.
            // SAFETY: |self| < 2^31 and not NaN (the comparison fails for NaN), so
            // the truncated value fits an i32.
            let t: i32 = unsafe { self.to_int_unchecked() };
            let tf = t as f32;
            if tf > self {
                (tf - 1.0, Some(i64::from(t) - 1))
            } else {
                (tf, Some(i64::from(t)))
            }
        } else {
            let f = self.floor();
            (f, num_traits::ToPrimitive::to_i64(&f))
        }
    }
}

impl Real for f64 {
    const NAME: &'static str = "f64";
    #[inline(always)]
    fn of(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self
    }
    #[inline]
    fn pow01(self, e: Self) -> Self {
        self.powf(e)
    }
    #[inline(always)]
    fn floor_index(self) -> (Self, Option<i64>) {
        if self.abs() < 4_611_686_018_427_387_904.0 {
            // SAFETY: |self| < 2^62 and not NaN, so the truncated value fits an i64.
            let t: i64 = unsafe { self.to_int_unchecked() };
            let tf = t as f64;
            if tf > self {
                (tf - 1.0, Some(t - 1))
            } else {
                (tf, Some(t))
            }
        } else {
            let f = self.floor();
            (f, num_traits::ToPrimitive::to_i64(&f))
        }
    }
}

/// `v` as `f32` values when `R` is `f32` (for the f32 vector kernels of generic
/// code), else `None`.
pub fn as_f32<R: Real>(v: &[R]) -> Option<&[f32]> {
    // SAFETY: R is f32 (checked), so the slice has its layout.
    (std::any::TypeId::of::<R>() == std::any::TypeId::of::<f32>())
        .then(|| unsafe { &*(v as *const [R] as *const [f32]) })
}

/// [`as_f32`] for a mutable slice.
pub fn as_f32_mut<R: Real>(v: &mut [R]) -> Option<&mut [f32]> {
    if std::any::TypeId::of::<R>() == std::any::TypeId::of::<f32>() {
        // SAFETY: R is f32 (checked), so the slice has its layout.
        Some(unsafe { &mut *(v as *mut [R] as *mut [f32]) })
    } else {
        None
    }
}

/// A 3-vector in the working precision `R` (glam only offers concrete `f32`/`f64`
/// types, and the oracle must be generic).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct V3<R>(pub [R; 3]);

impl<R: Real> V3<R> {
    #[inline(always)]
    pub fn new(x: R, y: R, z: R) -> Self {
        V3([x, y, z])
    }
    #[inline(always)]
    pub fn splat(v: R) -> Self {
        V3([v; 3])
    }
    #[inline(always)]
    pub fn zero() -> Self {
        V3([R::zero(); 3])
    }
    /// Converts from a glam `DVec3` (world-space quantities are set up in f64).
    #[inline(always)]
    pub fn from_dvec(v: glam::DVec3) -> Self {
        V3([R::of(v.x), R::of(v.y), R::of(v.z)])
    }
    #[inline(always)]
    pub fn to_dvec(self) -> glam::DVec3 {
        glam::DVec3::new(self.0[0].f64(), self.0[1].f64(), self.0[2].f64())
    }
    #[inline(always)]
    pub fn x(self) -> R {
        self.0[0]
    }
    #[inline(always)]
    pub fn y(self) -> R {
        self.0[1]
    }
    #[inline(always)]
    pub fn z(self) -> R {
        self.0[2]
    }
    #[inline(always)]
    pub fn dot(self, o: Self) -> R {
        self.0[0] * o.0[0] + self.0[1] * o.0[1] + self.0[2] * o.0[2]
    }
    #[inline(always)]
    pub fn length(self) -> R {
        self.dot(self).sqrt()
    }
    /// Unit vector, or zero when the length is zero.
    #[inline(always)]
    pub fn normalize_or_zero(self) -> Self {
        let l = self.length();
        if l > R::zero() {
            self * (R::one() / l)
        } else {
            Self::zero()
        }
    }
}

impl<R: Real> Add for V3<R> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        V3([self.0[0] + o.0[0], self.0[1] + o.0[1], self.0[2] + o.0[2]])
    }
}
impl<R: Real> Sub for V3<R> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        V3([self.0[0] - o.0[0], self.0[1] - o.0[1], self.0[2] - o.0[2]])
    }
}
impl<R: Real> Mul<R> for V3<R> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, s: R) -> Self {
        V3([self.0[0] * s, self.0[1] * s, self.0[2] * s])
    }
}
impl<R: Real> Div<R> for V3<R> {
    type Output = Self;
    #[inline(always)]
    fn div(self, s: R) -> Self {
        V3([self.0[0] / s, self.0[1] / s, self.0[2] / s])
    }
}
impl<R: Real> Neg for V3<R> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        V3([-self.0[0], -self.0[1], -self.0[2]])
    }
}

/// A 3×3 matrix in the working precision, rows first.
#[derive(Clone, Copy, Debug)]
pub struct M3<R>(pub [[R; 3]; 3]);

impl<R: Real> M3<R> {
    /// Converts from a glam `DMat3` (column-major) to rows in `R`.
    pub fn from_dmat3(m: glam::DMat3) -> Self {
        let r = |i: usize| {
            let row = m.row(i);
            [R::of(row.x), R::of(row.y), R::of(row.z)]
        };
        M3([r(0), r(1), r(2)])
    }
    #[inline(always)]
    pub fn mul_vec(&self, v: V3<R>) -> V3<R> {
        let m = &self.0;
        V3([
            m[0][0] * v.0[0] + m[0][1] * v.0[1] + m[0][2] * v.0[2],
            m[1][0] * v.0[0] + m[1][1] * v.0[1] + m[1][2] * v.0[2],
            m[2][0] * v.0[0] + m[2][1] * v.0[1] + m[2][2] * v.0[2],
        ])
    }
}

/// The ray–box slab test (Kay & Kajiya 1986): the parameter interval `(t0, t1)` of the
/// ray `o + t·d` inside the axis-aligned box `[lo, hi]`, or `None` when the ray misses
/// it or only grazes it (`t1 ≤ t0`). Each axis with `d ≠ 0` gives the interval between
/// its two planes, `(lo − o)/d` and `(hi − o)/d`, and the intervals intersect; an axis
/// with `d = 0` (either sign of zero) keeps every `t` when `lo ≤ o ≤ hi` (bounds
/// inclusive) and none otherwise. A NaN component of `o` or `d` drops its axis out of
/// the test (its comparisons are false, and `min`/`max` return the other operand of a
/// NaN), so `t0` and `t1` are never NaN.
///
/// The distance to a plane becomes a ray parameter by multiplying with `1/d`, as the
/// GPU does; [`slab_interval`] is the same test dividing by `d` instead (one rounding
/// instead of two: the analytic phantom's chords and the world-space callers keep it).
/// mirrors shaders/shared/rays.wgsl: intersect_box
#[inline]
pub fn intersect_box<R: Real>(o: V3<R>, d: V3<R>, lo: V3<R>, hi: V3<R>) -> Option<(R, R)> {
    slab(o.0, d.0, lo.0, hi.0, Quotient::Reciprocal)
}

/// [`intersect_box`] in f64 on glam vectors, each plane distance divided by `d`
/// (correctly rounded) rather than multiplied by `1/d`: the ray parameters of the
/// analytic phantom's chords and line integrals, and of world-space rays against a
/// box in millimetres.
#[inline]
pub fn slab_interval(
    o: glam::DVec3,
    d: glam::DVec3,
    lo: glam::DVec3,
    hi: glam::DVec3,
) -> Option<(f64, f64)> {
    slab(
        o.to_array(),
        d.to_array(),
        lo.to_array(),
        hi.to_array(),
        Quotient::Divide,
    )
}

/// How [`slab`] turns a distance along an axis into a ray parameter.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Quotient {
    /// `Δ · (1/d)`, the GPU's form.
    Reciprocal,
    /// `Δ / d`.
    Divide,
}

/// The slab test behind [`intersect_box`] and [`slab_interval`].
#[inline(always)]
fn slab<R: Real>(o: [R; 3], d: [R; 3], lo: [R; 3], hi: [R; 3], q: Quotient) -> Option<(R, R)> {
    let mut t0 = R::neg_infinity();
    let mut t1 = R::infinity();
    for a in 0..3 {
        if d[a] == R::zero() {
            if o[a] < lo[a] || o[a] > hi[a] {
                return None;
            }
        } else {
            let (ta, tb) = match q {
                Quotient::Reciprocal => {
                    let inv = R::one() / d[a];
                    ((lo[a] - o[a]) * inv, (hi[a] - o[a]) * inv)
                }
                Quotient::Divide => ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]),
            };
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
    }
    (t1 > t0).then_some((t0, t1))
}
