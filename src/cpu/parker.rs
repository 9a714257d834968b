//! Parker weights: FDK from a short scan (half a turn plus the fan angle).
//!
//! A circular cone-beam scan over a full turn measures every ray of the central plane
//! twice, and FDK halves each (the `π/(2A)` backprojection constant of
//! [`crate::cpu::fbp`]). A *short scan* covers only `B = π + 2δ` with `δ` at least the
//! fan's half angle `δ_fan = atan(max |u| / SDD)`: enough for every ray of the central
//! plane once, but some twice and some once. Parker (Med. Phys. 9(2), 1982) weights
//! each projection pixel so that every ray's measurements add up to one:
//!
//! ```text
//! w(β, γ) = sin²(π/4 · β / (δ − γ))               0 ≤ β ≤ 2δ − 2γ
//!         = 1                                     2δ − 2γ ≤ β ≤ π − 2γ
//!         = sin²(π/4 · (π + 2δ − β) / (δ + γ))    π − 2γ ≤ β ≤ π + 2δ
//! ```
//!
//! with `β` the gantry angle from the scan's first view (radians) and `γ` the fan angle
//! of the detector column, `γ = −atan(u / SDD)` in voxlab's geometry (RTK's: the source
//! at `(SID sin a, 0, SID cos a)`, detector axis `e_u = (cos a, 0, −sin a)`; the sign
//! makes `(β, γ)` and its conjugate ray `(β + π + 2γ, −γ)` the same line, which
//! `tests/parker.rs` checks on the geometry itself). `δ = (B − π)/2` comes from the
//! scan's own span, so a scan longer than the minimum (an "over-scan") is weighted by
//! the same formula with the larger `δ`.
//!
//! The weight carried into the filter is `w · A·Δβ / π` (`A` views `Δβ` apart): each
//! ray now counts once over `A·Δβ` instead of twice over `2π`, and this factor turns
//! the full-scan constant `π/(2A)` into the short scan's, so the backprojection itself
//! is unchanged. Apply [`weigh`] to the raw projections before the ramp filter (RTK's
//! `ParkerShortScanImageFilter` has the same place in its FDK pipeline); the GPU port
//! is `gpu::parker::weigh` (`shaders/parker.wgsl`).

use crate::ct::{Beam, Geometry, Lines, Projections};
use crate::error::{Error, Result};
use crate::real::Real;
use rayon::prelude::*;
use std::f64::consts::PI;

/// What [`short_scan`] found out about a scan.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShortScan {
    /// Gantry angle of the first view, degrees.
    pub first_deg: f64,
    /// `δ = (B − π)/2`, radians, with `B` the span from the first to the last view.
    pub delta: f64,
    /// The fan's half angle `atan(max |u| / SDD)` to the detector's outer edge, radians
    /// (`δ` is at least this).
    pub fan_half_angle: f64,
    /// `A·Δβ/π`: the factor that turns the full-scan backprojection constant into the
    /// short scan's.
    pub scale: f64,
    /// SDD, mm.
    pub sdd: f64,
}

/// Checks that `g` is a cone-beam short scan and returns its parameters.
///
/// # Errors
/// [`Error::Invalid`] for a parallel beam, fewer than 2 views, angles that do not
/// increase, a span below `π + 2·δ_fan` (some rays of the central plane are never
/// measured) or of a full turn or more (no short scan: reconstruct without weights).
pub fn short_scan(g: &Geometry) -> Result<ShortScan> {
    g.validate()?;
    // Parker's weights are functions of the gantry angle and the fan angle of a
    // circular orbit.
    g.require_circular("short scan (--short-scan)")?;
    let bad = |m: String| Err(Error::invalid("short scan", m));
    let Beam::Cone { sdd, .. } = g.beam else {
        return bad(
            "Parker weights are for a cone beam; a parallel beam needs 180° and no weights".into(),
        );
    };
    let a = &g.angles_deg;
    if a.len() < 2 {
        return bad(format!("{} view(s); a short scan needs many", a.len()));
    }
    if let Some(k) = a.windows(2).position(|w| w[1] <= w[0]) {
        return bad(format!(
            "the angles must increase (view {} at {}° follows {}°)",
            k + 1,
            a[k + 1],
            a[k]
        ));
    }
    let span = (a[a.len() - 1] - a[0]).to_radians();
    let step = span / (a.len() - 1) as f64;
    // The fan reaches the detector's outer edges, half a pixel beyond the last centres:
    // every pixel centre then has |γ| < δ by a margin, which keeps the weights
    // well-conditioned where the ramps meet (see `parker_weight`).
    let umax = (g.cols as f64 - 0.5 - g.cu).abs().max((g.cu + 0.5).abs()) * g.du;
    let fan_half_angle = (umax / sdd).atan();
    let need = PI + 2.0 * fan_half_angle;
    // Half a step of slack: a scan sampled at even angles may end just short of B.
    if span + 0.5 * step < need {
        return bad(format!(
            "the views span {:.2}°; a short scan needs at least 180° + the fan angle \
             = {:.2}° (fan half angle {:.2}°)",
            span.to_degrees(),
            need.to_degrees(),
            fan_half_angle.to_degrees()
        ));
    }
    if span + step >= 2.0 * PI - 1e-9 {
        return bad(format!(
            "the views cover a full turn ({:.2}° + one step): reconstruct without short-scan \
             weights",
            span.to_degrees()
        ));
    }
    Ok(ShortScan {
        first_deg: a[0],
        delta: ((span - PI) / 2.0).max(fan_half_angle),
        fan_half_angle,
        scale: a.len() as f64 * step / PI,
        sdd,
    })
}

/// Parker's weight of the ray at gantry angle `beta` (from the first view) and fan
/// angle `gamma`, for the half over-scan `delta` (all radians). 0 outside `[0, π + 2δ]`.
///
/// The ramps have slope up to `(π/4)/(δ − |γ|)` in `β`: an error `ε` in `β` (f32 on
/// the GPU) moves the weight by up to `ε·(π/4)/(δ − |γ|)`, which is why the fan angle
/// is taken to the detector's edge (`δ − |γ| ≥` half a pixel's angle).
///
/// mirrors shaders/parker.wgsl: parker_weight
#[inline]
pub fn parker_weight(beta: f64, gamma: f64, delta: f64) -> f64 {
    let quarter = PI / 4.0;
    if beta < 0.0 || beta > PI + 2.0 * delta {
        0.0
    } else if beta < 2.0 * delta - 2.0 * gamma {
        (quarter * beta / (delta - gamma)).sin().powi(2)
    } else if beta <= PI - 2.0 * gamma {
        1.0
    } else {
        (quarter * (PI + 2.0 * delta - beta) / (delta + gamma))
            .sin()
            .powi(2)
    }
}

/// The fan angle `γ = −atan(u / SDD)` of detector column `col` (see the module docs for
/// the sign). `gpu::parker` uploads these per column, computed here in f64.
///
#[inline]
pub fn fan_angle(g: &Geometry, sdd: f64, col: f64) -> f64 {
    -(((col - g.cu) * g.du) / sdd).atan()
}

/// The weights of every view and column (`A × cols`, the same for every detector row),
/// `scale` included: what [`weigh`] multiplies by.
///
/// # Errors
/// As [`short_scan`].
pub fn weights(g: &Geometry) -> Result<Vec<f64>> {
    let s = short_scan(g)?;
    let mut w = Vec::with_capacity(g.n_angles() * g.cols);
    for &a in &g.angles_deg {
        let beta = (a - s.first_deg).to_radians();
        for c in 0..g.cols {
            let gamma = fan_angle(g, s.sdd, c as f64);
            w.push(s.scale * parker_weight(beta, gamma, s.delta));
        }
    }
    Ok(w)
}

/// The projections multiplied by Parker's weights (and the short-scan scale), ready
/// for `cpu::ramp::filter_projections` and the unchanged backprojection.
///
/// # Errors
/// As [`short_scan`]; [`Error::Invalid`] when the stack does not fit `g` or holds NaN or
/// infinite values.
pub fn weigh<R: Real>(p: &Projections<R>, g: &Geometry) -> Result<Projections<R>> {
    p.check_against(g)?;
    let data = weigh_data(&p.data, &|n| n, g)?;
    Projections::new(p.angles, g.rows, g.cols, data)
}

/// [`weigh`] on some lines of a stack (a distributed rank's).
///
/// # Errors
/// As [`weigh`].
pub fn weigh_lines<R: Real>(p: &Lines<R>, g: &Geometry) -> Result<Lines<R>> {
    p.check_against(g)?;
    Ok(p.with_data(weigh_data(&p.data, &|n| p.ids[n], g)?))
}

/// Lines of `g.cols` values times Parker's weights, line `n` of `data` being line
/// `id(n)` (`view·rows + row`) of the stack.
fn weigh_data<R: Real>(
    data: &[R],
    id: &(dyn Fn(usize) -> usize + Sync),
    g: &Geometry,
) -> Result<Vec<R>> {
    if data.iter().any(|v| !v.is_finite()) {
        return Err(Error::invalid(
            "projections",
            "contain NaN or infinite values",
        ));
    }
    let w = weights(g)?;
    let (rows, cols) = (g.rows, g.cols);
    let mut data = data.to_vec();
    if cols > 0 && rows > 0 {
        data.par_chunks_mut(cols).enumerate().for_each(|(n, line)| {
            let view = id(n) / rows;
            for (x, &wc) in line.iter_mut().zip(&w[view * cols..(view + 1) * cols]) {
                *x = R::of(x.f64() * wc);
            }
        });
    }
    Ok(data)
}
