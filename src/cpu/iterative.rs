//! Iterative reconstruction on Joseph's matched pair ([`JosephPair`]): SIRT, CGLS,
//! OS-SART and a total-variation method (Chambolle–Pock), generic over f32/f64.
//! See docs/iterative.md for the formulas, the weights and their sources.
//!
//! Notation: `A` the forward projector restricted to the support (`A M`, `M` the 0/1
//! mask of the voxels that may be non-zero), `b` the measured projections, `x` the
//! image, `r = b − A x` the residual.
//!
//! - **SIRT** (as ASTRA and TIGRE define it): `x ← x + λ C Aᵀ R (b − A x)` with
//!   `R = diag(1 / A𝟙)` (row sums: every ray's length in the support) and
//!   `C = diag(1 / Aᵀ𝟙)` (column sums); a zero sum gives a zero weight. Its fixed
//!   point minimises `‖A x − b‖²_R`.
//! - **OS-SART**: the same update over one ordered subset of the views at a time, with
//!   the subset's own column sums `C_S = diag(1 / A_Sᵀ𝟙)`; one iteration visits every
//!   subset once. Subset `s` of `K` holds the views `s, s + K, s + 2K, …`.
//! - **CGLS**: conjugate gradients on the normal equations `AᵀA x = Aᵀ b`; from zero it
//!   converges to the least-squares solution of least norm.
//! - **TV**: `min ½‖A x − b‖² + w·TV(x)` (isotropic TV of forward differences, zero
//!   past the last voxel), by Chambolle and Pock's primal–dual algorithm on
//!   `K = [A; μ∇]` with `μ = ‖A‖ / ‖∇‖` (so that both blocks have the same norm),
//!   steps `σ = τ = 0.99 / ‖K‖`, `‖A‖` from a power iteration.
//!
//! Non-negativity (SIRT, OS-SART, TV) projects `x` onto `x ≥ 0` after every update.
//! Every sum over voxels or rays is taken in fixed chunks in a fixed order, so the
//! results do not depend on the thread count; [`JosephPair`] is deterministic too.

use super::project::{masked, JosephPair, SartUpdate, SupportPlanes};
use crate::error::{Error, Result};
use crate::real::Real;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

crate::choice_enum! {
    /// The iterative method.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
    pub enum Method: "iterative method", default Sirt {
        /// Simultaneous iterative reconstruction (ASTRA's and TIGRE's weights).
        Sirt = "sirt",
        /// Conjugate gradients on the normal equations (least squares).
        Cgls = "cgls",
        /// Ordered-subset SART: SIRT's update over one subset of the views at a time.
        OsSart = "os-sart",
        /// Least squares plus total variation (Chambolle–Pock).
        Tv = "tv",
    }
}

impl Method {
    /// Every method, in the order the docs list them.
    pub const ALL: [Method; 4] = [Method::Sirt, Method::Cgls, Method::OsSart, Method::Tv];
}

crate::choice_enum! {
    /// The order in which OS-SART visits its subsets.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
    pub enum SubsetOrder: "subset order", default Sequential {
        /// 0, 1, 2, …, K − 1 in every iteration.
        Sequential = "sequential",
        /// A fresh permutation every iteration, from a fixed seed (a run repeats).
        Random = "random",
    }
}

/// The options of [`solve`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IterativeOptions {
    pub method: Method,
    /// Iterations (OS-SART: passes over every subset).
    pub iterations: usize,
    /// OS-SART: the number of subsets (at most the number of views).
    pub subsets: usize,
    pub order: SubsetOrder,
    /// SIRT and OS-SART: the relaxation λ, in (0, 2).
    pub relaxation: f64,
    /// TV: the weight `w` of the total variation (units of the image × mm).
    pub tv_weight: f64,
    /// SIRT, OS-SART, TV: keep `x ≥ 0`.
    pub nonnegative: bool,
    /// Stop once the objective falls by less than `tolerance` × its previous value in
    /// one iteration (0: run every iteration).
    pub tolerance: f64,
}

impl Default for IterativeOptions {
    fn default() -> Self {
        IterativeOptions {
            method: Method::Sirt,
            iterations: 100,
            subsets: 10,
            order: SubsetOrder::Sequential,
            relaxation: 1.0,
            tv_weight: DEFAULT_TV_WEIGHT,
            nonnegative: false,
            tolerance: 0.0,
        }
    }
}

/// The default TV weight (for images of densities near 1 per mm, as the phantoms).
pub const DEFAULT_TV_WEIGHT: f64 = 0.2;

/// The most iterations one run may take.
pub const MAX_ITERATIONS: usize = 1_000_000;

impl IterativeOptions {
    /// Checks the options against a problem of `n_views` views.
    ///
    /// # Errors
    /// [`Error::Invalid`] naming the option.
    pub fn check(&self, n_views: usize) -> Result<()> {
        if self.iterations == 0 || self.iterations > MAX_ITERATIONS {
            return Err(Error::invalid(
                "--iterations",
                format!("{}: give 1 to {MAX_ITERATIONS}", self.iterations),
            ));
        }
        if self.method == Method::OsSart && (self.subsets == 0 || self.subsets > n_views) {
            return Err(Error::invalid(
                "--subsets",
                format!(
                    "{}: give 1 to the number of views ({n_views})",
                    self.subsets
                ),
            ));
        }
        if matches!(self.method, Method::Sirt | Method::OsSart)
            && !(self.relaxation > 0.0 && self.relaxation < 2.0)
        {
            return Err(Error::invalid(
                "--relaxation",
                format!("{}: must lie in (0, 2)", self.relaxation),
            ));
        }
        if !(self.tv_weight.is_finite() && self.tv_weight >= 0.0) {
            return Err(Error::invalid(
                "--tv-weight",
                format!("{}: must be a finite number ≥ 0", self.tv_weight),
            ));
        }
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return Err(Error::invalid(
                "--tolerance",
                format!("{}: must be a finite number ≥ 0", self.tolerance),
            ));
        }
        if self.method == Method::Cgls && self.nonnegative {
            return Err(Error::invalid(
                "--nonnegative",
                "CGLS has no non-negativity constraint (use sirt, os-sart or tv)",
            ));
        }
        Ok(())
    }
}

/// A projector `A` and its exact transpose `Aᵀ` over any subset of the views: what
/// the methods need of Joseph's pair, on the CPU ([`JosephPair`]) or the GPU
/// (`crate::gpu::joseph_pair::GpuJosephPair`). `forward(x, views)` gives
/// `views.len() × per_view` values in the order of `views`; `transpose(y, views)` one
/// value per voxel.
pub trait MatchedPair<R>: Sync {
    /// The grid's size in voxels (x fastest).
    fn dims(&self) -> [usize; 3];
    /// The number of views.
    fn n_views(&self) -> usize;
    /// Detector pixels per view.
    fn per_view(&self) -> usize;
    /// The number of voxels.
    fn n_voxels(&self) -> usize {
        self.dims().iter().product()
    }
    /// `A x` over `views`.
    ///
    /// # Errors
    /// Device failures (a GPU pair).
    fn forward(&self, x: &[R], views: &[usize]) -> Result<Vec<R>>;
    /// `Aᵀ y` over `views`.
    ///
    /// # Errors
    /// Device failures (a GPU pair).
    fn transpose(&self, y: &[R], views: &[usize]) -> Result<Vec<R>>;
    /// `M·Aᵀ y` over `views`: [`Self::transpose`] with the voxels off `support` set
    /// to `+0` (all kept when `None`); a pair may skip them
    /// ([`JosephPair::transpose_on`]).
    ///
    /// # Errors
    /// Device failures (a GPU pair).
    fn transpose_on(&self, y: &[R], views: &[usize], support: Option<&[bool]>) -> Result<Vec<R>>
    where
        R: Real,
    {
        Ok(masked(self.transpose(y, views)?, support))
    }
    /// What [`Self::forward_within`] needs to skip the planes where every tap of a ray
    /// lies off `support` ([`JosephPair::support_planes`]); `None` when the pair has
    /// no such narrowing.
    fn support_planes(&self, _support: &[bool]) -> Option<SupportPlanes> {
        None
    }
    /// [`Self::forward`] of an image that is `+0` off the support `planes` were made
    /// for, the same numbers ([`JosephPair::forward_within`]).
    ///
    /// # Errors
    /// Device failures (a GPU pair).
    fn forward_within(
        &self,
        x: &[R],
        views: &[usize],
        _planes: Option<&SupportPlanes>,
    ) -> Result<Vec<R>> {
        self.forward(x, views)
    }
    /// Whether [`Self::sart_update`] runs for `views` (`cpu::iterative`'s OS-SART then
    /// keeps no column weights for them).
    fn has_sart_update(&self, _views: &[usize]) -> bool {
        false
    }
    /// OS-SART's update over `views` in one pass over the image, when the pair has
    /// one ([`JosephPair::sart_update`]): `x ← x + λ·C·M·Aᵀ y` with
    /// `C = diag(1 / M·Aᵀ𝟙)`, the same numbers as [`Self::transpose`], the column
    /// weights and the update one after the other. `Ok(false)`, and `x` untouched,
    /// when it has none.
    ///
    /// # Errors
    /// Device failures (a GPU pair).
    fn sart_update(
        &self,
        _x: &mut [R],
        _y: &[R],
        _views: &[usize],
        _step: &SartUpdate<R>,
    ) -> Result<bool> {
        Ok(false)
    }
}

impl<R: Real> MatchedPair<R> for JosephPair<R> {
    fn dims(&self) -> [usize; 3] {
        self.dims
    }
    fn n_views(&self) -> usize {
        JosephPair::n_views(self)
    }
    fn per_view(&self) -> usize {
        JosephPair::per_view(self)
    }
    fn forward(&self, x: &[R], views: &[usize]) -> Result<Vec<R>> {
        Ok(JosephPair::forward(self, x, views))
    }
    fn transpose(&self, y: &[R], views: &[usize]) -> Result<Vec<R>> {
        Ok(JosephPair::transpose(self, y, views))
    }
    fn transpose_on(&self, y: &[R], views: &[usize], support: Option<&[bool]>) -> Result<Vec<R>> {
        Ok(JosephPair::transpose_on(self, y, views, support))
    }
    fn support_planes(&self, support: &[bool]) -> Option<SupportPlanes> {
        JosephPair::support_planes(self, support)
    }
    fn forward_within(
        &self,
        x: &[R],
        views: &[usize],
        planes: Option<&SupportPlanes>,
    ) -> Result<Vec<R>> {
        Ok(JosephPair::forward_within(self, x, views, planes))
    }
    fn has_sart_update(&self, views: &[usize]) -> bool {
        // One pass is faster than the transpose by planes with stored column weights
        // only on the vector kernel (the scalar gather would slow the f64 oracle).
        JosephPair::has_fast_sart_update(self, views)
    }
    fn sart_update(
        &self,
        x: &mut [R],
        y: &[R],
        views: &[usize],
        step: &SartUpdate<R>,
    ) -> Result<bool> {
        Ok(JosephPair::has_fast_sart_update(self, views)
            && JosephPair::sart_update(self, x, y, views, step))
    }
}

/// What [`solve`] solves: `b ≈ A x` on the voxels of `support` (all when `None`).
pub struct Problem<'a, R> {
    pub pair: &'a dyn MatchedPair<R>,
    /// Projections, `n_views × rows × cols`, in view order.
    pub b: &'a [R],
    pub support: Option<&'a [bool]>,
}

/// The result of [`solve`].
#[derive(Clone, Debug)]
pub struct Solution<R> {
    pub x: Vec<R>,
    /// `‖b − A x_k‖` for `k = 0` (the initial image) to the last iteration (CGLS: the
    /// residual its recurrence carries).
    pub residual: Vec<f64>,
    /// The objective the method decreases, for the same iterates: SIRT and OS-SART
    /// `½‖b − A x‖²_R`, CGLS `½‖b − A x‖²`, TV `½‖b − A x‖² + w·TV(x)`.
    pub objective: Vec<f64>,
    /// Iterations run.
    pub iterations: usize,
    /// Stopped by the tolerance (or CGLS reached a zero gradient).
    pub converged: bool,
    /// TV: the estimate of `‖A‖` the steps were set from.
    pub norm_estimate: Option<f64>,
}

/// Called after every iteration with its number (1-based), the image and its
/// residual; an error (e.g. [`Error::Cancelled`]) stops the run.
pub type OnIteration<'a, R> = dyn FnMut(usize, &[R], f64) -> Result<()> + Send + 'a;

/// The views of a problem cut into shares, one per process (the ranks of
/// `voxlab reconstruct --distributed`): each share holds some views' projections and
/// its own [`MatchedPair`] over them, and every share holds the whole image. What the
/// methods sum over the views — `Aᵀ y`, and over rays `‖r‖²`, `⟨q, q⟩` — each share
/// sums over its own views, and [`Shares::sum`] completes the sums. One share
/// ([`Alone`]) is the problem as [`solve`] sees it: nothing is added.
pub trait Shares {
    /// How many shares the views are cut into (1: this process holds them all).
    fn count(&self) -> usize;
    /// Replaces `values` (this share's partial sums) by the sums over every share,
    /// elementwise, the same bits on every share. A collective: every share calls it,
    /// in the same order.
    fn sum(&self, values: &mut [f64]);
    /// Where this share's `local` views lie among the problem's: `(first, total)`, its
    /// views being `first .. first + local` of `total` (OS-SART's subsets are cut from
    /// the whole problem's views). One share: `(0, local)`.
    fn views(&self, local: usize) -> (usize, usize) {
        (0, local)
    }
}

/// The whole problem in one process.
pub struct Alone;

impl Shares for Alone {
    fn count(&self) -> usize {
        1
    }
    fn sum(&self, _values: &mut [f64]) {}
}

/// This share's per-voxel partial sums (its views' `Aᵀ y`) summed over every share:
/// `v` itself when there is one share; else in f64, rounded back to `R`.
fn summed<R: Real>(shares: &dyn Shares, v: Vec<R>) -> Vec<R> {
    if shares.count() == 1 {
        return v;
    }
    let mut w: Vec<f64> = v.par_iter().map(|x| x.f64()).collect();
    shares.sum(&mut w);
    w.into_par_iter().map(R::of).collect()
}

/// This share's sums over its rays summed over every share (`s` itself when there is
/// one).
fn summed_scalars<const N: usize>(shares: &dyn Shares, mut s: [f64; N]) -> [f64; N] {
    if shares.count() > 1 {
        shares.sum(&mut s);
    }
    s
}

/// [`solve`] for one share of a problem cut by views ([`Shares`]): `prob` holds this
/// share's views (its pair over them, their projections), `x0` the whole image; every
/// share calls it with the same options and initial image, and every share returns
/// the same image, residuals and objectives. Every method: OS-SART's subsets are cut
/// from the whole problem's views ([`Shares::views`]): each share updates with its
/// views of a subset, and the update and column weights are summed over the shares,
/// subset by subset; TV's `Aᵀp` and its power iteration's `AᵀA v` are summed over the
/// shares, its dual field and gradients are image-sized and computed alike on every
/// share, its dual `p` per ray on the ray's share. With one share it is [`solve`],
/// bit for bit; with more, the sums over the views are regrouped by share (`Aᵀ y` as
/// `Σ_shares Σ_views in share`, summed in f64), and so are the residual's (its chunks
/// of 4096 values start at each share's first ray).
///
/// Runs on the calling thread (not inside the thread pool, as [`solve`] does), so
/// that a share waiting in [`Shares::sum`] never holds a worker the others need.
///
/// # Errors
/// As [`solve`].
pub fn solve_shared<R: Real>(
    prob: &Problem<R>,
    x0: Vec<R>,
    opts: &IterativeOptions,
    shares: &dyn Shares,
    on_iteration: &mut Hook<R>,
) -> Result<Solution<R>> {
    check_problem_of(prob, x0.len(), opts, shares.views(prob.pair.n_views()).1)?;
    let x0 = masked(x0, prob.support);
    match opts.method {
        Method::Sirt => sart(prob, x0, opts, false, shares, on_iteration),
        Method::OsSart => sart(prob, x0, opts, true, shares, on_iteration),
        Method::Cgls => cgls(prob, x0, opts, shares, on_iteration),
        Method::Tv => tv(prob, x0, opts, shares, on_iteration),
    }
}

/// [`OnIteration`] without `Send`: what the methods call after every iteration
/// ([`solve_shared`] runs on the calling thread, so its hook may hold what cannot move).
pub type Hook<'a, R> = dyn FnMut(usize, &[R], f64) -> Result<()> + 'a;

/// Values per chunk of every deterministic sum.
const CHUNK: usize = 4096;

/// `Σ f(i)` over `0..n` in fixed chunks, the chunk sums added in order (f64).
/// Mirrors shaders/iterative.wgsl: partials, finish (the device-resident port, src/gpu/iterative.rs).
fn sum_by<F: Fn(usize) -> f64 + Sync>(n: usize, f: F) -> f64 {
    let parts: Vec<f64> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut s = 0.0;
            for i in c * CHUNK..((c + 1) * CHUNK).min(n) {
                s += f(i);
            }
            s
        })
        .collect();
    parts.iter().sum()
}

/// `⟨a, b⟩` (deterministic, f64).
pub fn dot<R: Real>(a: &[R], b: &[R]) -> f64 {
    debug_assert_eq!(a.len(), b.len());
    sum_by(a.len(), |i| a[i].f64() * b[i].f64())
}

/// `‖a‖₂` (deterministic).
pub fn norm<R: Real>(a: &[R]) -> f64 {
    dot(a, a).sqrt()
}

/// `1/v` where `v > ε`, else 0 (the weights of SIRT and OS-SART).
/// Mirrors shaders/iterative.wgsl: reciprocal (the device-resident port, src/gpu/iterative.rs).
fn reciprocal<R: Real>(v: Vec<R>) -> Vec<R> {
    v.into_par_iter()
        .map(|s| {
            if s > R::of(1e-6) {
                R::one() / s
            } else {
                R::zero()
            }
        })
        .collect()
}

/// The views of subset `s` of `k`: `s, s + k, s + 2k, …`.
pub fn subset_views(n_views: usize, k: usize, s: usize) -> Vec<usize> {
    (s..n_views).step_by(k).collect()
}

/// The order of the subsets in iteration `it` (0-based).
pub fn subset_order(order: SubsetOrder, k: usize, it: usize) -> Vec<usize> {
    let mut v: Vec<usize> = (0..k).collect();
    if order == SubsetOrder::Random {
        // Fisher–Yates with a SplitMix64 stream seeded by the iteration.
        let mut state = 0x9E37_79B9_7F4A_7C15u64 ^ (it as u64).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        let mut next = || {
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        };
        for i in (1..k).rev() {
            let j = (next() % (i as u64 + 1)) as usize;
            v.swap(i, j);
        }
    }
    v
}

/// Solves the problem from `x0` (masked to the support) with `opts`.
///
/// # Errors
/// Bad options or sizes ([`Error::Invalid`]); what `on_iteration` returns.
pub fn solve<R: Real>(
    prob: &Problem<R>,
    x0: Vec<R>,
    opts: &IterativeOptions,
    on_iteration: &mut OnIteration<R>,
) -> Result<Solution<R>> {
    check_problem(prob, x0.len(), opts)?;
    // The whole run on a worker of the thread pool: the many short parallel loops of
    // an OS-SART pass then start from inside the pool instead of each being handed
    // over (and waited for) by an outside thread.
    rayon::scope(|_| {
        let x0 = masked(x0, prob.support);
        match opts.method {
            Method::Sirt => sart(prob, x0, opts, false, &Alone, on_iteration),
            Method::OsSart => sart(prob, x0, opts, true, &Alone, on_iteration),
            Method::Cgls => cgls(prob, x0, opts, &Alone, on_iteration),
            Method::Tv => tv(prob, x0, opts, &Alone, on_iteration),
        }
    })
}

/// Checks the options and the sizes of a problem and its initial image (`n_x0`
/// values), for every port of [`solve`].
///
/// # Errors
/// [`Error::Invalid`] naming the option or the array.
pub fn check_problem<R>(prob: &Problem<R>, n_x0: usize, opts: &IterativeOptions) -> Result<()> {
    check_problem_of(prob, n_x0, opts, prob.pair.n_views())
}

/// [`check_problem`] for a problem of `views` views in all, of which `prob` may hold a
/// share (the options, OS-SART's subsets among them, are checked against all).
fn check_problem_of<R>(
    prob: &Problem<R>,
    n_x0: usize,
    opts: &IterativeOptions,
    views: usize,
) -> Result<()> {
    let pair = prob.pair;
    opts.check(views)?;
    let n = pair.n_voxels();
    let rays = pair.n_views() * pair.per_view();
    if n_x0 != n {
        return Err(Error::invalid(
            "initial image",
            format!("{n_x0} values for a grid of {n} voxels"),
        ));
    }
    if prob.b.len() != rays {
        return Err(Error::invalid(
            "projections",
            format!("{} values for {rays} rays", prob.b.len()),
        ));
    }
    if prob.support.is_some_and(|m| m.len() != n) {
        return Err(Error::invalid("support", "one flag per voxel"));
    }
    Ok(())
}

/// OS-SART keeps the column weights of its `k` subsets (`n` voxels of `bytes` each)
/// while they take at most 1 GiB, else recomputes them per subset.
pub fn keeps_column_weights(k: usize, n: usize, bytes: usize) -> bool {
    k == 1 || k.saturating_mul(n).saturating_mul(bytes) <= 1 << 30
}

/// All the views.
fn all_views<R>(pair: &dyn MatchedPair<R>) -> Vec<usize> {
    (0..pair.n_views()).collect()
}

/// `b − A x` over `views` (`b` holds every view).
/// Mirrors shaders/iterative.wgsl: residual (the device-resident port, src/gpu/iterative.rs).
fn residual_of<R: Real>(prob: &Problem<R>, x: &[R], views: &[usize]) -> Result<Vec<R>> {
    residual_within(prob, x, views, None, None)
}

/// [`residual_of`] for an image that is `+0` off the support `planes` were made for
/// (`MatchedPair::forward_within`: the same numbers), times the row weights `rows`
/// (every view's) when given: `R_S (b − A x)` in the same pass.
fn residual_within<R: Real>(
    prob: &Problem<R>,
    x: &[R],
    views: &[usize],
    planes: Option<&SupportPlanes>,
    rows: Option<&[R]>,
) -> Result<Vec<R>> {
    let pv = prob.pair.per_view();
    let mut r = prob.pair.forward_within(x, views, planes)?;
    let per_view = |slot: usize, img: &mut [R]| {
        let at = views[slot] * pv..(views[slot] + 1) * pv;
        let src = &prob.b[at.clone()];
        match rows {
            Some(w) => {
                for ((v, &bv), &wv) in img.iter_mut().zip(src).zip(&w[at]) {
                    *v = (bv - *v) * wv;
                }
            }
            None => {
                for (v, &bv) in img.iter_mut().zip(src) {
                    *v = bv - *v;
                }
            }
        }
    };
    if views.len() == 1 {
        // One view (an OS-SART subset of one): too little work to share out.
        per_view(0, &mut r);
    } else {
        r.par_chunks_mut(pv)
            .enumerate()
            .for_each(|(slot, img)| per_view(slot, img));
    }
    Ok(r)
}

/// `Aᵀ y` on the support.
fn transpose_masked<R: Real>(prob: &Problem<R>, y: &[R], views: &[usize]) -> Result<Vec<R>> {
    prob.pair.transpose_on(y, views, prob.support)
}

/// Has the objective stopped falling (by the tolerance)?
/// Mirrors shaders/iterative.wgsl: log_entry (the device-resident port, src/gpu/iterative.rs).
fn stalled(opts: &IterativeOptions, objective: &[f64]) -> bool {
    let k = objective.len();
    opts.tolerance > 0.0
        && k >= 2
        && (objective[k - 2] - objective[k - 1]).abs() <= opts.tolerance * objective[k - 2].abs()
}

/// SIRT (`subsets = false`) and OS-SART, on one share of the views (SIRT only) or
/// all of them ([`Alone`]): the row weights are per ray, so per share; the column
/// weights and the backprojection are summed over the shares.
/// Mirrors shaders/iterative.wgsl: weight_rows (the device-resident port, src/gpu/iterative.rs).
fn sart<R: Real>(
    prob: &Problem<R>,
    mut x: Vec<R>,
    opts: &IterativeOptions,
    subsets: bool,
    shares: &dyn Shares,
    on_iteration: &mut Hook<R>,
) -> Result<Solution<R>> {
    let pair = prob.pair;
    let all = all_views(pair);
    // Every image projected here is 0 off the support (x is masked, and so are the
    // updates): the pair may skip the planes where a ray's taps all lie off it.
    let planes = prob.support.and_then(|m| pair.support_planes(m));
    let planes = planes.as_ref();
    let ones_x = masked(vec![R::one(); pair.n_voxels()], prob.support);
    let row_w = reciprocal(pair.forward_within(&ones_x, &all, planes)?);
    let k = if subsets { opts.subsets } else { 1 };
    // The subsets of the whole problem's views; a share takes its own views of each
    // (as indices among them), and sums each subset's update over the shares.
    let (first, total) = shares.views(pair.n_views());
    let mine = first..first + pair.n_views();
    let groups: Vec<Vec<usize>> = (0..k)
        .map(|s| {
            subset_views(total, k, s)
                .into_iter()
                .filter(|v| mine.contains(v))
                .map(|v| v - first)
                .collect()
        })
        .collect();
    // The subsets whose update the pair makes in one pass (computing their column
    // weights as it goes: one share only, since the update must be summed first); the
    // others keep their column weights while they fit, else recompute them.
    let one_pass: Vec<bool> = groups
        .iter()
        .map(|v| subsets && shares.count() == 1 && pair.has_sart_update(v))
        .collect();
    let keep = keeps_column_weights(k, pair.n_voxels(), std::mem::size_of::<R>());
    let col_w_of = |views: &[usize]| {
        let ones_y = vec![R::one(); views.len() * pair.per_view()];
        transpose_masked(prob, &ones_y, views).map(|c| reciprocal(summed(shares, c)))
    };
    let kept: Vec<Option<Vec<R>>> = if keep {
        groups
            .iter()
            .zip(&one_pass)
            .map(|(v, &one)| if one { Ok(None) } else { col_w_of(v).map(Some) })
            .collect::<Result<_>>()?
    } else {
        Vec::new()
    };
    let lambda = R::of(opts.relaxation);
    let step = SartUpdate {
        relaxation: lambda,
        nonnegative: opts.nonnegative,
        support: prob.support,
    };
    let weighted = |r: &[R]| -> f64 {
        sum_by(r.len(), |i| {
            let v = r[i].f64();
            row_w[i].f64() * v * v
        })
    };
    let mut residual = Vec::new();
    let mut objective = Vec::new();
    let mut converged = false;
    let mut iterations = 0;
    for it in 0..=opts.iterations {
        // The residual of the current iterate (the last pass only logs it).
        let r = residual_within(prob, &x, &all, planes, None)?;
        let [rr, wrr] = summed_scalars(shares, [dot(&r, &r), weighted(&r)]);
        residual.push(rr.sqrt());
        objective.push(0.5 * wrr);
        if it > 0 {
            on_iteration(it, &x, *residual.last().unwrap_or(&0.0))?;
            if stalled(opts, &objective) {
                converged = true;
                break;
            }
        }
        if it == opts.iterations {
            break;
        }
        iterations = it + 1;
        if !subsets {
            let mut wr = r;
            wr.par_iter_mut()
                .zip(&row_w)
                .for_each(|(v, &w)| *v = *v * w);
            let upd = summed(shares, transpose_masked(prob, &wr, &all)?);
            let Some(cw) = &kept[0] else {
                unreachable!("SIRT keeps its column weights")
            };
            update(&mut x, &upd, cw, lambda, opts.nonnegative, prob.support);
            continue;
        }
        for s in subset_order(opts.order, k, it) {
            let views = &groups[s];
            let wr = residual_within(prob, &x, views, planes, Some(&row_w))?;
            if one_pass[s] && pair.sart_update(&mut x, &wr, views, &step)? {
                continue;
            }
            let upd = summed(shares, transpose_masked(prob, &wr, views)?);
            let fresh;
            let cw = if let Some(Some(cw)) = kept.get(s) {
                cw
            } else {
                fresh = col_w_of(views)?;
                &fresh
            };
            update(&mut x, &upd, cw, lambda, opts.nonnegative, prob.support);
        }
    }
    Ok(Solution {
        x,
        residual,
        objective,
        iterations,
        converged,
        norm_estimate: None,
    })
}

/// `x ← x + λ·c·u` with `u` set to 0 off the support (one pass for [`masked`]
/// and the update), then `max(x, 0)` when asked.
/// Mirrors shaders/iterative.wgsl: mask, sart_update (the device-resident port, src/gpu/iterative.rs).
fn update<R: Real>(
    x: &mut [R],
    u: &[R],
    c: &[R],
    lambda: R,
    nonneg: bool,
    support: Option<&[bool]>,
) {
    // Chunks with straight loops (one per case), which the compiler vectorises.
    x.par_chunks_mut(CHUNK).enumerate().for_each(|(k, xs)| {
        let r = k * CHUNK..k * CHUNK + xs.len();
        let (us, cs) = (&u[r.clone()], &c[r.clone()]);
        let ms = support.map(|m| &m[r]);
        match (ms, nonneg) {
            (Some(ms), true) => update_chunk::<R, true, true>(xs, us, cs, ms, lambda),
            (Some(ms), false) => update_chunk::<R, true, false>(xs, us, cs, ms, lambda),
            (None, true) => update_chunk::<R, false, true>(xs, us, cs, &[], lambda),
            (None, false) => update_chunk::<R, false, false>(xs, us, cs, &[], lambda),
        }
    });
}

/// [`update`] on one chunk (`ms` the support's flags there when `MASK`).
#[inline(always)]
fn update_chunk<R: Real, const MASK: bool, const NONNEG: bool>(
    xs: &mut [R],
    us: &[R],
    cs: &[R],
    ms: &[bool],
    lambda: R,
) {
    let n = xs.len();
    assert!(us.len() == n && cs.len() == n && (!MASK || ms.len() == n));
    let zero = R::zero();
    for (j, xv) in xs.iter_mut().enumerate() {
        // Both loads first, then a select: a branch-free loop.
        let uv = us[j];
        let uv = if MASK && !ms[j] { zero } else { uv };
        let v = *xv + lambda * cs[j] * uv;
        // max(v, 0), with v = −0 and NaN giving 0 (as JosephPair::sart_update does).
        *xv = if NONNEG && (v.is_nan() || v <= zero) {
            zero
        } else {
            v
        };
    }
}

/// `y ← y + α·x` (in place).
/// Mirrors shaders/iterative.wgsl: axpy (the device-resident port, src/gpu/iterative.rs).
fn axpy<R: Real>(y: &mut [R], alpha: R, x: &[R]) {
    y.par_iter_mut()
        .zip(x)
        .for_each(|(yv, &xv)| *yv = *yv + alpha * xv);
}

/// CGLS (Hestenes–Stiefel on the normal equations), on one share of the views or all
/// of them ([`Alone`]): `r` and `q = A p` are per ray, so per share; `Aᵀ r` and the
/// sums over rays are summed over the shares, and every share then takes the same
/// steps on the whole image.
/// Mirrors shaders/iterative.wgsl: cgls_alpha, cgls_beta, direction (the device-resident port, src/gpu/iterative.rs).
fn cgls<R: Real>(
    prob: &Problem<R>,
    mut x: Vec<R>,
    opts: &IterativeOptions,
    shares: &dyn Shares,
    on_iteration: &mut Hook<R>,
) -> Result<Solution<R>> {
    let all = all_views(prob.pair);
    let mut r = residual_of(prob, &x, &all)?;
    let mut s = summed(shares, transpose_masked(prob, &r, &all)?);
    let mut p = s.clone();
    let mut gamma = dot(&s, &s);
    let [rr] = summed_scalars(shares, [dot(&r, &r)]);
    let mut residual = vec![rr.sqrt()];
    let mut objective = vec![0.5 * rr];
    let mut converged = false;
    let mut iterations = 0;
    for it in 1..=opts.iterations {
        if gamma == 0.0 {
            converged = true;
            break;
        }
        let q = prob.pair.forward(&p, &all)?;
        let [qq] = summed_scalars(shares, [dot(&q, &q)]);
        if qq == 0.0 {
            converged = true;
            break;
        }
        let alpha = gamma / qq;
        axpy(&mut x, R::of(alpha), &p);
        axpy(&mut r, R::of(-alpha), &q);
        s = summed(shares, transpose_masked(prob, &r, &all)?);
        let gamma_new = dot(&s, &s);
        let beta = R::of(gamma_new / gamma);
        gamma = gamma_new;
        p.par_iter_mut()
            .zip(&s)
            .for_each(|(pv, &sv)| *pv = sv + beta * *pv);
        iterations = it;
        let [rr] = summed_scalars(shares, [dot(&r, &r)]);
        let rn = rr.sqrt();
        residual.push(rn);
        objective.push(0.5 * rn * rn);
        on_iteration(it, &x, rn)?;
        if stalled(opts, &objective) {
            converged = true;
            break;
        }
    }
    Ok(Solution {
        x,
        residual,
        objective,
        iterations,
        converged,
        norm_estimate: None,
    })
}

/// The forward difference of `x` along `axis` at voxel `i` (0 at the last voxel).
/// Mirrors shaders/iterative.wgsl: forward_difference (the device-resident port, src/gpu/iterative.rs).
#[inline(always)]
fn forward_difference<R: Real>(x: &[R], dims: [usize; 3], axis: usize, i: usize) -> R {
    let stride = [1, dims[0], dims[0] * dims[1]][axis];
    let c = (i / stride) % dims[axis];
    if c + 1 < dims[axis] {
        x[i + stride] - x[i]
    } else {
        R::zero()
    }
}

/// `Σ_v |∇x(v)|₂` (isotropic TV, deterministic).
pub fn total_variation<R: Real>(x: &[R], dims: [usize; 3]) -> f64 {
    let axes = live_axes(dims);
    sum_by(x.len(), |i| {
        axes.iter()
            .map(|&a| forward_difference(x, dims, a, i).f64().powi(2))
            .sum::<f64>()
            .sqrt()
    })
}

/// `−div q = ∇ᵀ q` at voxel `i`, `q` holding one field per axis in `axes` order.
/// Mirrors shaders/iterative.wgsl: gradient_transpose (the device-resident port, src/gpu/iterative.rs).
#[inline(always)]
fn gradient_transpose<R: Real>(q: &[Vec<R>], axes: &[usize], dims: [usize; 3], i: usize) -> R {
    let strides = [1, dims[0], dims[0] * dims[1]];
    let mut acc = R::zero();
    for (f, &a) in q.iter().zip(axes) {
        let c = (i / strides[a]) % dims[a];
        // (∇ᵀq)_i = q_{i−1} − q_i, with q = 0 at the last voxel and before the first.
        if c + 1 < dims[a] {
            acc = acc - f[i];
        }
        if c > 0 {
            acc = acc + f[i - strides[a]];
        }
    }
    acc
}

/// `‖A‖` by 20 power iterations on `AᵀA` (from the support's ones), raised by 1 %.
/// Mirrors shaders/iterative.wgsl: normalise (the device-resident port, src/gpu/iterative.rs).
fn operator_norm<R: Real>(prob: &Problem<R>, shares: &dyn Shares) -> Result<f64> {
    let all = all_views(prob.pair);
    let mut v = masked(vec![R::one(); prob.pair.n_voxels()], prob.support);
    let mut est = 0.0;
    for _ in 0..20 {
        let nv = norm(&v);
        if nv == 0.0 {
            return Ok(0.0);
        }
        let inv = R::of(1.0 / nv);
        v.par_iter_mut().for_each(|x| *x = *x * inv);
        let w = summed(
            shares,
            transpose_masked(prob, &prob.pair.forward(&v, &all)?, &all)?,
        );
        est = norm(&w).sqrt();
        v = w;
    }
    Ok(est * 1.01)
}

/// The constants of Chambolle–Pock's TV iteration (module docs), from `‖A‖`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TvSteps {
    /// `μ = ‖A‖ / ‖∇‖` (1 when `‖A‖` is 0).
    pub mu: f64,
    /// `σ = τ = 0.99 / ‖K‖`.
    pub step: f64,
    /// The dual ball's radius `w / μ`.
    pub radius: f64,
}

impl TvSteps {
    /// The constants for `‖A‖ = norm_a`, `n_axes` live axes and TV weight `w`.
    pub fn new(norm_a: f64, n_axes: usize, w: f64) -> Self {
        // ‖∇‖² ≤ 4 per axis (forward differences).
        let norm_grad = (4.0 * n_axes.max(1) as f64).sqrt();
        let mu = if norm_a > 0.0 {
            norm_a / norm_grad
        } else {
            1.0
        };
        let k_norm = (norm_a * norm_a + mu * mu * norm_grad * norm_grad)
            .sqrt()
            .max(1e-30);
        TvSteps {
            mu,
            step: 0.99 / k_norm,
            radius: w / mu,
        }
    }
}

/// The axes of `dims` longer than one voxel.
pub fn live_axes(dims: [usize; 3]) -> Vec<usize> {
    (0..3).filter(|&a| dims[a] > 1).collect()
}

/// Total variation by Chambolle–Pock (module docs).
/// Mirrors shaders/iterative.wgsl: midpoint, dual_data, primal (the device-resident port, src/gpu/iterative.rs).
fn tv<R: Real>(
    prob: &Problem<R>,
    mut x: Vec<R>,
    opts: &IterativeOptions,
    shares: &dyn Shares,
    on_iteration: &mut Hook<R>,
) -> Result<Solution<R>> {
    let pair = prob.pair;
    let dims = pair.dims();
    let all = all_views(pair);
    let axes = live_axes(dims);
    let norm_a = operator_norm(prob, shares)?;
    let steps = TvSteps::new(norm_a, axes.len(), opts.tv_weight);
    let (sigma, tau) = (R::of(steps.step), R::of(steps.step));
    let radius = R::of(steps.radius);
    let mu_r = R::of(steps.mu);
    let n = pair.n_voxels();
    let mut p = vec![R::zero(); prob.b.len()];
    let mut q: Vec<Vec<R>> = axes.iter().map(|_| vec![R::zero(); n]).collect();
    let mut xbar = x.clone();
    let mut ax_prev = pair.forward(&x, &all)?;
    // ‖A x − b‖² over every share's rays, and with it the residual and the objective
    // `½‖A x − b‖² + w·TV(x)` (TV(x) of the whole image, the same on every share).
    let logged = |x: &[R], ax: &[R]| {
        let [rr] = summed_scalars(
            shares,
            [sum_by(ax.len(), |i| {
                let d = ax[i].f64() - prob.b[i].f64();
                d * d
            })],
        );
        (
            rr.sqrt(),
            0.5 * rr + opts.tv_weight * total_variation(x, dims),
        )
    };
    let (r0, o0) = logged(&x, &ax_prev);
    let mut residual = vec![r0];
    let mut objective = vec![o0];
    let mut converged = false;
    let mut iterations = 0;
    let one = R::one();
    let two = R::of(2.0);
    let support = prob.support;
    for it in 1..=opts.iterations {
        // A x̄ = 2 A x_k − A x_{k−1}: one forward per iteration gives both.
        let axbar = pair.forward(&xbar, &all)?;
        if it > 1 {
            // A x_{k} = (A x̄_k + A x_{k−1}) / 2: the objective of the last iterate.
            let ax: Vec<R> = axbar
                .par_iter()
                .zip(&ax_prev)
                .map(|(&a, &b)| (a + b) / two)
                .collect();
            let (rn, obj) = logged(&x, &ax);
            residual.push(rn);
            objective.push(obj);
            on_iteration(it - 1, &x, rn)?;
            ax_prev = ax;
            if stalled(opts, &objective) {
                converged = true;
                break;
            }
        }
        // Dual of the data term: p ← (p + σ(A x̄ − b)) / (1 + σ).
        p.par_iter_mut()
            .zip(axbar.par_iter().zip(prob.b))
            .for_each(|(pv, (&a, &b))| *pv = (*pv + sigma * (a - b)) / (one + sigma));
        // Dual of TV: q ← proj_{|q| ≤ w/μ}(q + σ μ ∇x̄).
        tv_dual_step(&mut q, &xbar, &axes, dims, sigma * mu_r, radius);
        // Primal: x ← proj(x − τ(Aᵀp + μ ∇ᵀq)); x̄ ← 2x_new − x.
        let atp = summed(shares, transpose_masked(prob, &p, &all)?);
        let q_ref = &q;
        let axes_ref = &axes;
        let new: Vec<R> = (0..n)
            .into_par_iter()
            .map(|i| {
                let g = atp[i] + mu_r * gradient_transpose(q_ref, axes_ref, dims, i);
                let mut v = x[i] - tau * g;
                if opts.nonnegative {
                    v = v.max(R::zero());
                }
                if support.is_some_and(|m| !m[i]) {
                    v = R::zero();
                }
                v
            })
            .collect();
        xbar.par_iter_mut()
            .zip(new.par_iter().zip(&x))
            .for_each(|(b, (&nv, &ov))| *b = two * nv - ov);
        x = new;
        iterations = it;
    }
    if !converged && iterations == opts.iterations {
        let ax = pair.forward(&x, &all)?;
        let (rn, obj) = logged(&x, &ax);
        residual.push(rn);
        objective.push(obj);
        on_iteration(iterations, &x, rn)?;
        if stalled(opts, &objective) {
            converged = true;
        }
    }
    Ok(Solution {
        x,
        residual,
        objective,
        iterations,
        converged,
        norm_estimate: Some(norm_a),
    })
}

/// `q ← proj_{|q(v)|₂ ≤ radius}(q + s·∇x)`, voxel by voxel.
/// Mirrors shaders/iterative.wgsl: dual_gradient (the device-resident port, src/gpu/iterative.rs).
fn tv_dual_step<R: Real>(
    q: &mut [Vec<R>],
    x: &[R],
    axes: &[usize],
    dims: [usize; 3],
    s: R,
    radius: R,
) {
    let n = x.len();
    let new: Vec<[R; 3]> = (0..n)
        .into_par_iter()
        .map(|i| {
            let mut v = [R::zero(); 3];
            let mut len2 = R::zero();
            for (f, &a) in axes.iter().enumerate() {
                v[f] = q[f][i] + s * forward_difference(x, dims, a, i);
                len2 = len2 + v[f] * v[f];
            }
            let len = len2.sqrt();
            if len > radius {
                let scale = if len > R::zero() {
                    radius / len
                } else {
                    R::zero()
                };
                for c in v.iter_mut() {
                    *c = *c * scale;
                }
            }
            v
        })
        .collect();
    for (f, field) in q.iter_mut().enumerate() {
        field.par_iter_mut().zip(&new).for_each(|(d, v)| *d = v[f]);
    }
}
