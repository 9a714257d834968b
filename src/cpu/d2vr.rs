//! D²VR: direct volume rendering straight from (filtered) X-ray projections
//! (Xu & Mueller, "GPU-Accelerated D²VR", VG 2006, §4).
//!
//! No volume is ever stored. The ray caster ([`super::raycast::render_field`]) marches
//! through a *virtual* reconstruction grid (dims + an index → CT-world affine, e.g. an
//! RTK-centred `N³`), and each sample's value at world point `P` is reconstructed on
//! the fly from all `A` filtered projections `q_k`:
//!
//! ```text
//! s(P) = π/(2A) · Σ_k w_k(P) · bilinear_zero(q_k, col_k(P), row_k(P))
//! ```
//!
//! with `(col_k, row_k, w_k)` from [`crate::ct::ViewMatrix::project`] (`w = (SID/(SID −
//! w·e_w))²` for a cone beam, 1 for a parallel beam). This is the FBP/FDK
//! backprojection evaluated at one point: with projections filtered by
//! [`crate::cpu::ramp::filter_projections`] (whose ramp is `≈ 2|f|`, hence `π/(2A)`,
//! scikit-image's constant; cosine-weighted for a cone beam) it is the FBP/FDK
//! reconstruction; with raw projections it is an unnormalised backprojection. Classification, shading, compositing, early ray
//! termination and every render mode are the ray caster's, so a D²VR image equals the
//! ray-cast image of the field `s` by construction.
//!
//! # Gradients (paper §4.2)
//! - **GFS** (gradients from samples, eq. 4): central differences of reconstructed
//!   samples in index space, `h = 1` voxel — six extra reconstructions per shaded sample.
//! - **GFR** (gradients from the projections, the paper's GFP/eq. 5): the exact
//!   gradient of the piecewise-smooth function `s(P)` above. Per view, with
//!   `den = r2·P̃`, `col = (r0·P̃)/den`, `row = (r1·P̃)/den`, `w = (r3.x/den)²`:
//!   `∇col = (r0 − col·r2)/den`, `∇row = (r1 − row·r2)/den`, `∇w = −2w·r2/den` (the
//!   xyz parts of the rows), and `∇_P[w q] = q ∇w + w (q_x ∇col + q_y ∇row)` where
//!   `q_x`, `q_y` are the derivatives of the zero-padded bilinear interpolant within its
//!   cell ([`bilinear_zero_grad`]). The index-space gradient is `Jᵀ ∇_P s` (`J` the
//!   affine's linear part). One pass over the views gives value and gradient.
//!
//! # Accelerations (paper §4.4)
//! - **Bounding cylinder**: only points inside the effective reconstruction area are
//!   reconstructed — the cylinder about the rotation axis (CT `+y`) every view's
//!   detector covers ([`effective_cylinder`]). Outside it a sample is 0 at no cost.
//!   The sample positions are unchanged (so the CPU and GPU march the same points).
//! - **Occlusion culling**: the ray caster's early ray termination
//!   (`RenderSettings::ert_threshold`).
//! - **Occupancy** ([`OccupancyMask`]): a voxel of the virtual grid whose footprint lies
//!   in the zero shadow of some *raw* projection holds no object; its samples are 0
//!   without reconstruction.
//!
//! [`D2vrStats`] counts the reconstructions actually done against the samples a plain
//! march through the grid's box would take: the paper's "rasterized voxels" fraction.

use super::field::Field;
use super::raycast::{render_field, RenderOutput};
use crate::camera::Camera;
use crate::ct::{Beam, Geometry, Projections, ViewMatrix};
use crate::error::{Error, Result};
use crate::real::{Real, M3, V3};
use crate::settings::{Classification, Mode, RenderSettings};
use crate::transfer::TransferFunction;
use glam::{DMat3, DMat4, DVec3};
use std::sync::atomic::{AtomicU64, Ordering};

/// How shaded samples get their gradient.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum D2vrGradient {
    /// Central differences of six extra reconstructed samples (paper eq. 4).
    Gfs,
    /// The analytic gradient of the backprojection, from projection-space derivatives
    /// (paper eq. 5, "GFP").
    Gfr,
}

/// D²VR switches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct D2vrOptions {
    pub gradient: D2vrGradient,
    /// Reconstruct only inside the effective reconstruction cylinder.
    pub cylinder: bool,
    /// Value range of the reconstruction, `(lo, hi)`: scales the shading threshold
    /// exactly as a voxel grid's range does in the ray caster.
    pub value_range: (f64, f64),
}

impl Default for D2vrOptions {
    fn default() -> Self {
        D2vrOptions {
            gradient: D2vrGradient::Gfr,
            cylinder: true,
            value_range: (0.0, 1.0),
        }
    }
}

/// The virtual reconstruction grid: its dimensions and the affine from index space to
/// the CT world (mm). The ray caster's box is `[-0.5, n − 0.5]³` in index space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct D2vrGrid {
    pub dims: [usize; 3],
    pub affine: DMat4,
}

impl D2vrGrid {
    /// RTK's centred grid: `world = spacing · (i − (n − 1)/2)` per axis.
    pub fn centred(dims: [usize; 3], spacing_mm: f64) -> Result<Self> {
        if dims.iter().any(|&n| n == 0 || n > crate::ct::MAX_DETECTOR) {
            return Err(Error::invalid(
                "D²VR grid",
                format!("dims {dims:?} must be in 1..={}", crate::ct::MAX_DETECTOR),
            ));
        }
        if !(spacing_mm.is_finite() && spacing_mm > 0.0) {
            return Err(Error::invalid(
                "D²VR grid",
                format!("spacing {spacing_mm} must be finite and > 0"),
            ));
        }
        let c = DVec3::new(
            (dims[0] as f64 - 1.0) * 0.5,
            (dims[1] as f64 - 1.0) * 0.5,
            (dims[2] as f64 - 1.0) * 0.5,
        );
        Ok(D2vrGrid {
            dims,
            affine: DMat4::from_scale(DVec3::splat(spacing_mm)) * DMat4::from_translation(-c),
        })
    }
}

/// The effective reconstruction area: a cylinder about the rotation axis (CT `+y`)
/// with radius `radius` (mm) and `y ∈ [y_lo, y_hi]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cylinder {
    pub radius: f64,
    pub y_lo: f64,
    pub y_hi: f64,
}

/// The cylinder every view's detector covers.
///
/// Parallel beam: radius `min(cu, cols − 1 − cu)·du`, heights the rows' extent
/// `[−cv·dv, (rows − 1 − cv)·dv]`. Cone beam: the circle inscribed in the fan,
/// `SID · sin γ` with `tan γ = r_det / SDD` (`r_det` the parallel radius on the
/// detector) — slightly smaller than the isocentre demagnification `r_det·SID/SDD`,
/// because off-centre points are magnified more — and the heights demagnified at the
/// cylinder's nearest depth to the source, `v·(SID − radius)/SDD`, so that every point
/// inside projects onto the detector in every view.
pub fn effective_cylinder(g: &Geometry) -> Cylinder {
    let r_det = g.cu.min(g.cols as f64 - 1.0 - g.cu).max(0.0) * g.du;
    let (v_lo, v_hi) = (-g.cv * g.dv, (g.rows as f64 - 1.0 - g.cv) * g.dv);
    match g.beam {
        Beam::Parallel => Cylinder {
            radius: r_det,
            y_lo: v_lo.min(0.0),
            y_hi: v_hi.max(0.0),
        },
        Beam::Cone { sid, sdd } => {
            let radius = sid * r_det / (r_det * r_det + sdd * sdd).sqrt();
            let k = (sid - radius) / sdd;
            Cylinder {
                radius,
                y_lo: (v_lo * k).min(0.0),
                y_hi: (v_hi * k).max(0.0),
            }
        }
    }
}

/// Occupancy of the virtual grid: voxel `i` is empty when, in some view, the raw
/// projection is zero over the whole detector footprint of its cell
/// `[i − 0.5, i + 0.5]³` (the bounding box of its eight corners' projections — exact for
/// the projective maps, which keep convex sets convex — widened by the one pixel the
/// bilinear interpolant reaches). A point there lies in the shadow of no object.
#[derive(Clone, Debug, PartialEq)]
pub struct OccupancyMask {
    pub dims: [usize; 3],
    /// 1 = occupied, x fastest.
    pub occupied: Vec<u32>,
}

impl OccupancyMask {
    /// Builds the mask from the *unfiltered* projections (`|p| ≤ zero` counts as zero).
    pub fn from_projections<T: Real>(
        raw: &Projections<T>,
        g: &Geometry,
        grid: &D2vrGrid,
        zero: f64,
    ) -> Result<Self> {
        use rayon::prelude::*;
        g.validate()?;
        raw.check_against(g)?;
        let [nx, ny, nz] = grid.dims;
        let views: Vec<ViewMatrix<f64>> = g.view_matrices();
        let (cols, rows) = (g.cols as i64, g.rows as i64);
        let occupied = (0..nx * ny * nz)
            .into_par_iter()
            .map(|idx| {
                let (i, j, k) = (idx % nx, (idx / nx) % ny, idx / (nx * ny));
                let corners: Vec<[f64; 3]> = (0..8)
                    .map(|c| {
                        let q = DVec3::new(
                            i as f64 + if c & 1 == 0 { -0.5 } else { 0.5 },
                            j as f64 + if c & 2 == 0 { -0.5 } else { 0.5 },
                            k as f64 + if c & 4 == 0 { -0.5 } else { 0.5 },
                        );
                        grid.affine.transform_point3(q).to_array()
                    })
                    .collect();
                for (v, m) in views.iter().enumerate() {
                    let (mut c0, mut c1, mut r0, mut r1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
                    let mut behind = false;
                    for p in &corners {
                        match m.project(*p) {
                            Some((c, r, _)) => {
                                c0 = c0.min(c);
                                c1 = c1.max(c);
                                r0 = r0.min(r);
                                r1 = r1.max(r);
                            }
                            None => behind = true,
                        }
                    }
                    if behind {
                        continue; // cannot decide from this view
                    }
                    let (a0, a1) = ((c0.floor() as i64).max(0), (c1.ceil() as i64).min(cols - 1));
                    let (b0, b1) = ((r0.floor() as i64).max(0), (r1.ceil() as i64).min(rows - 1));
                    let img = raw.view(v);
                    let mut any = false;
                    'scan: for r in b0..=b1 {
                        for c in a0..=a1 {
                            if img[(r * cols + c) as usize].f64().abs() > zero {
                                any = true;
                                break 'scan;
                            }
                        }
                    }
                    if !any {
                        return 0;
                    }
                }
                1
            })
            .collect();
        Ok(OccupancyMask {
            dims: grid.dims,
            occupied,
        })
    }

    /// Fraction of occupied voxels.
    pub fn fraction(&self) -> f64 {
        self.occupied.iter().filter(|&&o| o != 0).count() as f64 / self.occupied.len() as f64
    }

    /// Whether the voxel nearest index point `p` is occupied (outside the grid: no).
    #[inline]
    pub fn at<R: Real>(&self, p: V3<R>) -> bool {
        let mut idx = 0usize;
        let mut stride = 1usize;
        for a in 0..3 {
            let i = (p.0[a] + R::of(0.5)).floor();
            if !(i >= R::zero() && i < R::of(self.dims[a] as f64)) {
                return false;
            }
            idx += i.to_usize().unwrap_or(0) * stride;
            stride *= self.dims[a];
        }
        self.occupied[idx] != 0
    }
}

/// The backprojection constant `π/(2A)`: FBP's, shared (see [`crate::cpu::fbp`]).
pub use crate::cpu::fbp::backprojection_scale;

/// Work counters of one D²VR render.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct D2vrStats {
    /// Samples a plain march through the grid's box takes (no culling, no ERT).
    pub box_samples: u64,
    /// Samples the ray caster visited (after early ray termination).
    pub visited_samples: u64,
    /// Sample values actually reconstructed (inside the cylinder and occupied).
    pub value_reconstructions: u64,
    /// Extra reconstructions for gradients (GFS: 6 per shaded sample; GFR: the
    /// gradient pass, counted once per shaded sample).
    pub gradient_reconstructions: u64,
}

impl D2vrStats {
    /// `value_reconstructions / box_samples`: the paper's fraction of rasterised voxels.
    pub fn fraction(&self) -> f64 {
        self.value_reconstructions as f64 / (self.box_samples.max(1)) as f64
    }
}

/// A D²VR image and its work counters.
#[derive(Clone, Debug)]
pub struct D2vrOutput {
    pub render: RenderOutput,
    pub stats: D2vrStats,
}

/// Derivatives of [`bilinear_zero`](crate::ct::bilinear_zero) with respect to `x` and `y`, with its value:
/// `(q, ∂q/∂x, ∂q/∂y)` of the bilinear patch of the cell `(floor x, floor y)` (taps
/// outside the image are zero, as in the value).
///
/// mirrors shaders/shared/ct_bilinear.wgsl: bilinear_zero_grad
#[inline(always)]
pub fn bilinear_zero_grad<R: Real>(img: &[R], cols: usize, rows: usize, x: R, y: R) -> [R; 3] {
    let Some(([a, b, c, d], tx, ty)) = crate::ct::bilinear_taps(img, cols, rows, x, y) else {
        return [R::zero(); 3];
    };
    let top = a * (R::one() - tx) + b * tx;
    let bottom = c * (R::one() - tx) + d * tx;
    [
        top * (R::one() - ty) + bottom * ty,
        (b - a) * (R::one() - ty) + (d - c) * ty,
        bottom - top,
    ]
}

/// The field the ray caster samples: filtered projections seen through a virtual grid.
pub struct ProjectionField<'a, R> {
    q: &'a Projections<R>,
    views: Vec<ViewMatrix<R>>,
    dims: [usize; 3],
    /// Index → world, linear part (rows) and translation.
    lin: M3<R>,
    shift: V3<R>,
    /// `Jᵀ`: world gradient → index gradient.
    lin_t: M3<R>,
    scale: R,
    cylinder: Option<(R, R, R)>,
    occupancy: Option<&'a OccupancyMask>,
    gradient: D2vrGradient,
    range: (f64, f64),
    values: AtomicU64,
    gradients: AtomicU64,
}

impl<'a, R: Real> ProjectionField<'a, R> {
    /// Wraps filtered projections `q` acquired with geometry `g`.
    pub fn new(
        q: &'a Projections<R>,
        g: &Geometry,
        grid: &D2vrGrid,
        options: &D2vrOptions,
        occupancy: Option<&'a OccupancyMask>,
    ) -> Result<Self> {
        g.validate()?;
        // The bounding cylinder (`effective_cylinder`) is that of a circular orbit.
        g.require_circular("D²VR")?;
        q.check_against(g)?;
        if let Some(m) = occupancy {
            if m.dims != grid.dims {
                return Err(Error::invalid(
                    "occupancy mask",
                    format!("mask is {:?} but the grid is {:?}", m.dims, grid.dims),
                ));
            }
        }
        let lin = DMat3::from_mat4(grid.affine);
        if !(lin.determinant().is_finite() && lin.determinant() != 0.0) {
            return Err(Error::invalid("D²VR grid", "the affine is singular"));
        }
        let t = grid.affine.w_axis.truncate();
        let cyl = effective_cylinder(g);
        Ok(ProjectionField {
            q,
            views: g.view_matrices(),
            dims: grid.dims,
            lin: M3::from_dmat3(lin),
            shift: V3::from_dvec(t),
            lin_t: M3::from_dmat3(lin.transpose()),
            scale: R::of(backprojection_scale(g.n_angles())),
            cylinder: options.cylinder.then(|| {
                (
                    R::of(cyl.radius * cyl.radius),
                    R::of(cyl.y_lo),
                    R::of(cyl.y_hi),
                )
            }),
            occupancy,
            gradient: options.gradient,
            range: options.value_range,
            values: AtomicU64::new(0),
            gradients: AtomicU64::new(0),
        })
    }

    /// World point (CT frame, mm) of index point `p`.
    #[inline]
    pub fn world(&self, p: V3<R>) -> V3<R> {
        self.lin.mul_vec(p) + self.shift
    }

    /// Whether `p` (index space) is culled: outside the cylinder or unoccupied.
    #[inline]
    fn culled(&self, p: V3<R>, w: V3<R>) -> bool {
        if let Some((r2, lo, hi)) = self.cylinder {
            if w.x() * w.x() + w.z() * w.z() > r2 || w.y() < lo || w.y() > hi {
                return true;
            }
        }
        if let Some(m) = self.occupancy {
            if !m.at(p) {
                return true;
            }
        }
        false
    }

    /// `s(P)` at world point `w`: the backprojection, no culling, no counting.
    ///
    /// mirrors shaders/d2vr.wgsl: reconstruct_sample
    #[inline]
    pub fn reconstruct_sample(&self, w: V3<R>) -> R {
        // FBP's own per-point backprojection (same views, same constant π/(2A)).
        crate::cpu::fbp::backproject_point(self.q, &self.views, w.0)
    }

    /// `∇_P s(P)` at world point `w` (GFR), world units.
    ///
    /// mirrors shaders/d2vr.wgsl: reconstruct_gradient
    #[inline]
    pub fn reconstruct_gradient(&self, w: V3<R>) -> V3<R> {
        let (cols, rows) = (self.q.cols, self.q.rows);
        let mut g = V3::zero();
        for (k, m) in self.views.iter().enumerate() {
            let r = &m.rows;
            let den = r[2][0] * w.0[0] + r[2][1] * w.0[1] + r[2][2] * w.0[2] + r[2][3];
            if den <= R::zero() {
                continue;
            }
            let inv = R::one() / den;
            let col = (r[0][0] * w.0[0] + r[0][1] * w.0[1] + r[0][2] * w.0[2] + r[0][3]) * inv;
            let row = (r[1][0] * w.0[0] + r[1][1] * w.0[1] + r[1][2] * w.0[2] + r[1][3]) * inv;
            let s = r[3][0] * inv;
            let wt = s * s;
            let [q, qx, qy] = bilinear_zero_grad(self.q.view(k), cols, rows, col, row);
            let two = R::of(2.0);
            #[allow(clippy::needless_range_loop)] // three rows indexed by one axis
            for a in 0..3 {
                let dcol = (r[0][a] - col * r[2][a]) * inv;
                let drow = (r[1][a] - row * r[2][a]) * inv;
                let dw = -two * wt * r[2][a] * inv;
                g.0[a] = g.0[a] + q * dw + wt * (qx * dcol + qy * drow);
            }
        }
        g * self.scale
    }

    /// The counters so far: (value reconstructions, gradient reconstructions).
    pub fn counts(&self) -> (u64, u64) {
        (
            self.values.load(Ordering::Relaxed),
            self.gradients.load(Ordering::Relaxed),
        )
    }

    #[inline]
    fn value_uncounted(&self, p: V3<R>) -> (R, bool) {
        let w = self.world(p);
        if self.culled(p, w) {
            return (R::zero(), false);
        }
        (self.reconstruct_sample(w), true)
    }
}

impl<R: Real> Field<R> for ProjectionField<'_, R> {
    fn dims(&self) -> [usize; 3] {
        self.dims
    }
    fn value(&self, p: V3<R>) -> R {
        let (v, done) = self.value_uncounted(p);
        if done {
            self.values.fetch_add(1, Ordering::Relaxed);
        }
        v
    }
    fn gradient(&self, p: V3<R>) -> V3<R> {
        match self.gradient {
            D2vrGradient::Gfs => {
                let mut g = V3::zero();
                let mut n = 0;
                for a in 0..3 {
                    let mut e = V3::zero();
                    e.0[a] = R::one();
                    let (hi, d1) = self.value_uncounted(p + e);
                    let (lo, d0) = self.value_uncounted(p - e);
                    n += d1 as u64 + d0 as u64;
                    g.0[a] = (hi - lo) * R::of(0.5);
                }
                self.gradients.fetch_add(n, Ordering::Relaxed);
                g
            }
            D2vrGradient::Gfr => {
                let w = self.world(p);
                if self.culled(p, w) {
                    return V3::zero();
                }
                self.gradients.fetch_add(1, Ordering::Relaxed);
                self.lin_t.mul_vec(self.reconstruct_gradient(w))
            }
        }
    }
    fn value_range(&self) -> (f64, f64) {
        self.range
    }
}

/// Samples a plain march through the `dims` box takes for `camera` at `step` voxels:
/// the ray caster's step rule, in f64.
pub fn box_samples(dims: [usize; 3], affine: DMat4, camera: &Camera, step: f64) -> u64 {
    use rayon::prelude::*;
    let to_index = affine.inverse();
    let hi = DVec3::new(
        dims[0] as f64 - 0.5,
        dims[1] as f64 - 0.5,
        dims[2] as f64 - 0.5,
    );
    (0..camera.height)
        .into_par_iter()
        .map(|row| {
            let mut n_row = 0u64;
            for col in 0..camera.width {
                let ray = camera.ray(col, row);
                let o = to_index.transform_point3(ray.origin);
                let d = to_index.transform_vector3(ray.dir);
                let Some((t0, t1)) = crate::real::slab_interval(o, d, DVec3::splat(-0.5), hi)
                else {
                    continue;
                };
                let t0 = t0.max(ray.t_min);
                if t1 <= t0 {
                    continue;
                }
                let dt = step / d.length();
                n_row += ((t1 - t0) / dt - 1e-3).ceil().max(1.0) as u64;
            }
            n_row
        })
        .sum()
}

/// Checks the inputs D²VR shares between backends (and its dry run), the samples per
/// ray and per frame of `camera`'s image included.
pub(crate) fn check_inputs(
    settings: &RenderSettings,
    options: &D2vrOptions,
    grid: &D2vrGrid,
    camera: &Camera,
) -> Result<()> {
    settings.validate()?;
    let per_ray = crate::volume::diagonal(grid.dims) / settings.step;
    crate::settings::check_ray_work("D²VR", settings.step, per_ray, camera)?;
    if settings.mode == Mode::Dvr && settings.classification == Classification::Pre {
        return Err(Error::invalid(
            "classification",
            "D²VR has no voxel grid to pre-classify: use post-classification",
        ));
    }
    let (lo, hi) = options.value_range;
    if !(lo.is_finite() && hi.is_finite() && hi >= lo) {
        return Err(Error::invalid(
            "D²VR value range",
            format!("({lo}, {hi}) must be finite with lo ≤ hi"),
        ));
    }
    Ok(())
}

/// Renders the volume that the filtered projections `filtered` (acquired with
/// `geometry`) reconstruct, without reconstructing it: every sample is backprojected on
/// the fly (module docs). `occupancy`, if given, culls voxels outside the objects'
/// shadow. `progress(done_rows, total_rows)` as in the ray caster.
#[allow(clippy::too_many_arguments)]
pub fn render_d2vr<R: Real>(
    filtered: &Projections<R>,
    geometry: &Geometry,
    grid: &D2vrGrid,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &RenderSettings,
    options: &D2vrOptions,
    occupancy: Option<&OccupancyMask>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<D2vrOutput> {
    check_inputs(settings, options, grid, camera)?;
    let field = ProjectionField::new(filtered, geometry, grid, options, occupancy)?;
    let render = render_field(&field, grid.affine, tf, camera, settings, progress)?;
    let (values, gradients) = field.counts();
    Ok(D2vrOutput {
        stats: D2vrStats {
            box_samples: box_samples(grid.dims, grid.affine, camera, settings.step),
            visited_samples: render.total_samples,
            value_reconstructions: values,
            gradient_reconstructions: gradients,
        },
        render,
    })
}
