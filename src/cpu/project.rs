//! Forward projection: the line integrals a CT scanner measures, `p = ∫ μ(ℓ) dℓ` along
//! every detector pixel's ray (Xu & Mueller 2006, eq. 1), in the geometry of
//! [`crate::ct`].
//!
//! [`project_phantom`] is the oracle: the exact line integrals of an analytic phantom
//! (ellipsoids have closed-form chords), placed in the CT frame by
//! [`crate::ct::phantom_to_ct`]. Values are density × mm.
//!
//! [`project_volume`] projects a voxel grid with **Joseph's method** (P. M. Joseph, "An
//! improved algorithm for reprojecting rays through pixel images", IEEE TMI 1(3), 1982)
//! — the ray-driven projector behind RTK's `JosephForwardProjectionImageFilter` and
//! ASTRA's line kernel. In the grid's index frame a ray is `x(t) = o + t·d` with `t` in
//! world mm. Let `m` be the axis along which the ray moves fastest (`|d_m|` largest);
//! the ray crosses every index plane `x_m = s` once, at `t_s = (s − o_m)/d_m`, and
//!
//! ```text
//! p ≈ Σ_s  bilinear(slice s; x_a(t_s), x_b(t_s)) · Δt,     Δt = 1/|d_m|
//! ```
//!
//! where `a`, `b` are the other two axes, `bilinear` interpolates the four nearest
//! voxels of the slice (continued by zeros outside the grid, so the sum fades out over
//! the last voxel instead of stopping at a box face) and `Δt` is the world length of
//! the ray between two planes. Voxel centres sit at integer indices; the grid's affine
//! maps indices to CT world mm. Joseph is exact for a field that is linear in the
//! slice plane between the voxel centres, and for a constant field it returns value ×
//! chord length through the slab `−½ ≤ x_m ≤ n_m − ½` whenever the in-plane
//! coordinates stay between the first and last voxel centres (`tests/ct_project.rs`).
//!
//! The per-ray work is [`joseph_ray`], on the ray that [`pixel_ray`] builds from a
//! [`JosephView`]; both are mirrored by `shaders/project.wgsl`, which runs one
//! invocation per detector pixel (`crate::gpu::project`).

use crate::ct::{ct_to_phantom, phantom_to_ct, Beam, Geometry, Projections};
use crate::error::{Error, Result};
use crate::phantom::{index_to_phantom, Phantom};
use crate::real::{as_f32, as_f32_mut, Real};
use crate::volume::{check_dims, Volume, Voxel};
use glam::{DMat3, DMat4, DVec3};
use rayon::prelude::*;

mod gather;
pub use gather::{sart_voxel, SartUpdate};

/// Exact projections of `phantom` (f64): one line integral per detector pixel centre.
pub fn project_phantom(phantom: &Phantom, g: &Geometry) -> Result<Projections<f64>> {
    g.validate()?;
    let mut out = Projections::<f64>::zeros(g)?;
    let per_view = g.rows * g.cols;
    out.data
        .par_chunks_mut(g.cols)
        .enumerate()
        .for_each(|(line, dst)| {
            let (k, row) = (line / g.rows, line % g.rows);
            debug_assert!(line < g.n_angles() * per_view);
            for (col, v) in dst.iter_mut().enumerate() {
                let (o, d, t0) = g.ray(k, col as f64, row as f64);
                *v = phantom.line_integral_world(
                    ct_to_phantom(o),
                    ct_to_phantom(d),
                    t0,
                    f64::INFINITY,
                );
            }
        });
    Ok(out)
}

/// A voxel grid in working precision `R`, placed in the CT world: `affine` maps a
/// voxel index `(i, j, k)` (voxel centres at integers) to CT world mm. Samples are x
/// (`i`) fastest, as in [`Volume`].
#[derive(Clone, Debug, PartialEq)]
pub struct Grid<R> {
    pub dims: [usize; 3],
    pub affine: DMat4,
    pub data: Vec<R>,
}

/// The rotation of [`crate::ct::phantom_to_ct`] as a matrix: phantom/volume
/// `(x, y, z)` → CT `(x, z, −y)`.
pub fn phantom_to_ct_matrix() -> DMat4 {
    DMat4::from_mat3(DMat3::from_cols(
        phantom_to_ct(DVec3::X),
        phantom_to_ct(DVec3::Y),
        phantom_to_ct(DVec3::Z),
    ))
}

impl<R: Real> Grid<R> {
    /// Wraps samples, checking the sizes and the affine (finite, invertible, affine).
    pub fn new(dims: [usize; 3], affine: DMat4, data: Vec<R>) -> Result<Self> {
        let n = check_dims(dims)?;
        if data.len() != n {
            return Err(Error::invalid(
                "projection grid",
                format!("{} values for dimensions {dims:?}", data.len()),
            ));
        }
        let det = DMat3::from_mat4(affine).determinant();
        if !affine.is_finite()
            || !det.is_finite()
            || det.abs() < 1e-300
            || affine.row(3) != glam::DVec4::W
        {
            return Err(Error::invalid(
                "projection grid",
                "the index-to-world affine must be finite, invertible and affine",
            ));
        }
        if let Some(k) = data.iter().position(|v| !v.is_finite()) {
            return Err(Error::invalid(
                "projection grid",
                format!("voxel {k} is not finite"),
            ));
        }
        Ok(Grid { dims, affine, data })
    }

    /// A volume whose world frame **is** the CT frame (its affine is used as it is).
    pub fn from_volume_ct<T: Voxel>(v: &Volume<T>) -> Result<Self> {
        let data = v.data().iter().map(|x| R::of(x.to_f64())).collect();
        Grid::new(v.dims(), v.affine(), data)
    }

    /// A volume placed as a patient in the scanner: centred on the isocentre, then
    /// turned by [`crate::ct::phantom_to_ct`], so that its z axis (head–foot) is the
    /// rotation axis and its axial slices are scikit-image images (x right, y up).
    pub fn from_volume_patient<T: Voxel>(v: &Volume<T>) -> Result<Self> {
        let c = v.center_world();
        let affine = phantom_to_ct_matrix() * DMat4::from_translation(-c) * v.affine();
        let data = v.data().iter().map(|x| R::of(x.to_f64())).collect();
        Grid::new(v.dims(), affine, data)
    }

    /// `phantom` point-sampled (in f64, then rounded to `R`) at the voxel centres of
    /// the grid [`Phantom::sample`] uses, placed in the CT frame by
    /// [`crate::ct::phantom_to_ct`] — the same placement as [`project_phantom`], so the
    /// two projections differ only by discretisation.
    pub fn phantom(phantom: &Phantom, dims: [usize; 3]) -> Result<Self> {
        let n = check_dims(dims)?;
        let mut data = vec![R::zero(); n];
        data.par_chunks_mut(dims[0] * dims[1])
            .enumerate()
            .for_each(|(k, slice)| {
                for (idx, v) in slice.iter_mut().enumerate() {
                    let (i, j) = (idx % dims[0], idx / dims[0]);
                    let p = index_to_phantom([i as f64, j as f64, k as f64], dims);
                    *v = R::of(phantom.value_at(p));
                }
            });
        Grid::new(
            dims,
            phantom_to_ct_matrix() * phantom.grid_affine(dims),
            data,
        )
    }

    /// The samples rounded to f32 (what the GPU uploads).
    pub fn to_f32(&self) -> Vec<f32> {
        self.data.iter().map(|v| v.f64() as f32).collect()
    }
}

/// One view's rays in the grid's index frame, affine in the detector indices
/// `(c, r)`:
/// - start `o = a0 + c·a_u + r·a_v` (the pixel's point for a parallel beam, the
///   source for a cone beam),
/// - direction `e = d0 + c·d_u + r·d_v` (index units),
/// - the same direction in world mm, `w0 + c·w_u + r·w_v`, whose length turns `e` into
///   a direction of unit world length (so the ray parameter is world mm),
/// - `a0[3]` = the smallest ray parameter in the beam: 0 at a cone source, −10³⁰ for
///   a parallel line.
///
/// Nine rows of four numbers (the fourth unused but `a0[3]`): the same bytes as WGSL's
/// `JosephView` in `shaders/shared/project_params.wgsl` (144 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JosephView<R> {
    pub rows: [[R; 4]; 9],
}

// Only the f32 instance is uploaded.
unsafe impl bytemuck::Zeroable for JosephView<f32> {}
unsafe impl bytemuck::Pod for JosephView<f32> {}

/// The ray parameter that stands for −∞ (finite so that f32 and WGSL handle it).
pub const PARALLEL_T_MIN: f64 = -1e30;

impl<R: Real> JosephView<R> {
    /// View `k` of `g` seen from a grid whose index-to-world affine is `affine`.
    pub fn new(g: &Geometry, k: usize, affine: DMat4) -> Self {
        let inv = affine.inverse();
        let point = |p: DVec3| inv.transform_point3(p);
        let vector = |v: DVec3| inv.transform_vector3(v);
        let z = DVec3::ZERO;
        let (a0, a_u, a_v, d0, d_u, d_v, w0, w_u, w_v, t_min) = if let Some(views) = &g.views {
            // A view given by vectors: a cone's rays leave the source towards
            // pixel00 + c·u + r·v; a parallel ray runs along the unit direction `d`
            // through the pixel's point moved along `d` onto the plane through the
            // isocentre perpendicular to it (`x − (x·d)·d`, linear, so still affine
            // in `(c, r)`), as `Geometry::ray` does.
            let vv = &views[k];
            match g.beam {
                Beam::Parallel => {
                    let d = vv.source.normalize();
                    let flat = |x: DVec3| x - d * x.dot(d);
                    (
                        point(flat(vv.pixel00)),
                        vector(flat(vv.u)),
                        vector(flat(vv.v)),
                        vector(d),
                        z,
                        z,
                        d,
                        z,
                        z,
                        PARALLEL_T_MIN,
                    )
                }
                Beam::Cone { .. } => {
                    let r = vv.pixel00 - vv.source;
                    (
                        point(vv.source),
                        z,
                        z,
                        vector(r),
                        vector(vv.u),
                        vector(vv.v),
                        r,
                        vv.u,
                        vv.v,
                        0.0,
                    )
                }
            }
        } else {
            Self::circular(g, k, &point, &vector)
        };
        let row = |v: DVec3, w: f64| [R::of(v.x), R::of(v.y), R::of(v.z), R::of(w)];
        JosephView {
            rows: [
                row(a0, t_min),
                row(a_u, 0.0),
                row(a_v, 0.0),
                row(d0, 0.0),
                row(d_u, 0.0),
                row(d_v, 0.0),
                row(w0, 0.0),
                row(w_u, 0.0),
                row(w_v, 0.0),
            ],
        }
    }

    /// The ten rows of a circular orbit's view `k` (before rounding to `R`).
    #[allow(clippy::type_complexity)]
    fn circular(
        g: &Geometry,
        k: usize,
        point: &dyn Fn(DVec3) -> DVec3,
        vector: &dyn Fn(DVec3) -> DVec3,
    ) -> (
        DVec3,
        DVec3,
        DVec3,
        DVec3,
        DVec3,
        DVec3,
        DVec3,
        DVec3,
        DVec3,
        f64,
    ) {
        let (eu, ev, ew) = g.axes(k);
        let (su, sv) = (eu * g.du, ev * g.dv);
        let det00 = g.detector_point(k, 0.0, 0.0);
        let z = DVec3::ZERO;
        match g.beam {
            Beam::Parallel => (
                point(det00),
                vector(su),
                vector(sv),
                vector(-ew),
                z,
                z,
                -ew,
                z,
                z,
                PARALLEL_T_MIN,
            ),
            Beam::Cone { sid, .. } => {
                let src = ew * sid;
                (
                    point(src),
                    z,
                    z,
                    vector(det00 - src),
                    vector(su),
                    vector(sv),
                    det00 - src,
                    su,
                    sv,
                    0.0,
                )
            }
        }
    }
}

/// Every view of `g` for a grid with index-to-world `affine`.
pub fn joseph_views<R: Real>(g: &Geometry, affine: DMat4) -> Vec<JosephView<R>> {
    (0..g.n_angles())
        .map(|k| JosephView::new(g, k, affine))
        .collect()
}

/// The ray of detector pixel `(col, row)`: start `o` and direction `d` in index
/// coordinates with `|d|` = one world mm, and the smallest ray parameter `t_min`.
///
/// mirrors shaders/shared/joseph.wgsl: pixel_ray
#[inline(always)]
pub fn pixel_ray<R: Real>(v: &JosephView<R>, col: R, row: R) -> ([R; 3], [R; 3], R) {
    let r = &v.rows;
    let lin = |b: usize, i: usize| r[b][i] + col * r[b + 1][i] + row * r[b + 2][i];
    let o = [lin(0, 0), lin(0, 1), lin(0, 2)];
    let e = [lin(3, 0), lin(3, 1), lin(3, 2)];
    let w = [lin(6, 0), lin(6, 1), lin(6, 2)];
    let inv_len = R::one() / (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
    (o, [e[0] * inv_len, e[1] * inv_len, e[2] * inv_len], r[0][3])
}

/// Bilinear interpolation, continued by zeros, of one index plane of the grid: the
/// plane `x_m = s` with in-plane coordinates `x` (axis with stride `sa`, size `na`) and
/// `y` (stride `sb`, size `nb`). The same taps and zero rule as
/// [`crate::ct::bilinear_zero`].
///
/// mirrors shaders/shared/joseph_bilinear.wgsl: slice_bilinear
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn slice_bilinear<R: Real>(
    data: &[R],
    base: usize,
    sa: usize,
    na: usize,
    sb: usize,
    nb: usize,
    x: R,
    y: R,
) -> R {
    let ((fx, ix), (fy, iy)) = (x.floor_index(), y.floor_index());
    if !(fx >= -R::one() && fx < R::of(na as f64) && fy >= -R::one() && fy < R::of(nb as f64)) {
        return R::zero();
    }
    let (tx, ty) = (x - fx, y - fy);
    let (ix, iy) = (ix.unwrap_or(-2), iy.unwrap_or(-2));
    let at = |i: i64, j: i64| -> R {
        if i < 0 || j < 0 || i >= na as i64 || j >= nb as i64 {
            R::zero()
        } else {
            data[base + i as usize * sa + j as usize * sb]
        }
    };
    let top = at(ix, iy) * (R::one() - tx) + at(ix + 1, iy) * tx;
    let bottom = at(ix, iy + 1) * (R::one() - tx) + at(ix + 1, iy + 1) * tx;
    top * (R::one() - ty) + bottom * ty
}

/// Narrows the plane range `[lo, hi]` to where `x(s) = x0 + s·k` lies in `(−1, n)`,
/// outside which every bilinear tap is zero. Returns `false` when nothing is left.
///
/// mirrors shaders/shared/joseph.wgsl: clip_planes
#[inline(always)]
fn clip_planes<R: Real>(x0: R, k: R, n: usize, lo: &mut R, hi: &mut R) -> bool {
    let n = R::of(n as f64);
    if k.abs() > R::of(1e-20) {
        let s1 = (-R::one() - x0) / k;
        let s2 = (n - x0) / k;
        *lo = lo.max(s1.min(s2));
        *hi = hi.min(s1.max(s2));
    } else if !(x0 > -R::one() && x0 < n) {
        return false;
    }
    *lo <= *hi
}

/// Where one ray meets the grid in Joseph's scheme: the driving axis `m` (the ray
/// moves fastest along it; ties go to the lower axis), the in-plane axes `a`, `b`, the
/// in-plane coordinates on plane `s`, `x_a(s) = xa0 + s·ka` and `x_b(s) = xb0 + s·kb`,
/// the planes `s0..=s1` that can hold a non-zero tap, and the world length `w` of the
/// ray between two planes (`1/|d_m|`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JosephPlanes<R> {
    pub m: usize,
    pub a: usize,
    pub b: usize,
    pub xa0: R,
    pub ka: R,
    pub xb0: R,
    pub kb: R,
    pub s0: usize,
    pub s1: usize,
    pub w: R,
}

/// The planes of Joseph's sum (module docs) for the ray `x(t) = o + t·d`, `t ≥ t_min`,
/// in index coordinates with `|d|` = one world mm; `None` when the ray takes no
/// sample. The forward projector ([`joseph_ray`]) and its transpose
/// ([`joseph_weight`]) both start here, so they use the very same numbers.
///
/// mirrors shaders/shared/joseph.wgsl: joseph_planes
#[inline(always)]
pub fn joseph_planes<R: Real>(
    dims: [usize; 3],
    o: [R; 3],
    d: [R; 3],
    t_min: R,
) -> Option<JosephPlanes<R>> {
    let ad = [d[0].abs(), d[1].abs(), d[2].abs()];
    let (m, a, b) = if ad[0] >= ad[1] && ad[0] >= ad[2] {
        (0, 1, 2)
    } else if ad[1] >= ad[2] {
        (1, 0, 2)
    } else {
        (2, 0, 1)
    };
    if ad[m] == R::zero() {
        return None;
    }
    let inv = R::one() / d[m];
    // In-plane coordinates on plane s: x_a(s) = xa0 + s·ka (t = (s − o_m)/d_m).
    let (ka, kb) = (d[a] * inv, d[b] * inv);
    let (xa0, xb0) = (o[a] - o[m] * ka, o[b] - o[m] * kb);
    let mut lo = R::zero();
    let mut hi = R::of((dims[m] - 1) as f64);
    if !clip_planes(xa0, ka, dims[a], &mut lo, &mut hi)
        || !clip_planes(xb0, kb, dims[b], &mut lo, &mut hi)
    {
        return None;
    }
    // t ≥ t_min ⇔ s ≥ o_m + t_min·d_m (d_m > 0), s ≤ … (d_m < 0).
    let s_min = o[m] + t_min * d[m];
    if d[m] > R::zero() {
        lo = lo.max(s_min);
    } else {
        hi = hi.min(s_min);
    }
    if lo > hi {
        return None;
    }
    // 0 ≤ lo ≤ hi ≤ n_m − 1 here, so the casts are in range.
    let s0 = lo.ceil().to_usize().unwrap_or(0);
    let s1 = hi.floor().to_usize().unwrap_or(0);
    if s0 > s1 {
        return None;
    }
    Some(JosephPlanes {
        m,
        a,
        b,
        xa0,
        ka,
        xb0,
        kb,
        s0,
        s1,
        w: inv.abs(),
    })
}

/// Joseph's line integral (module docs) of the grid `data` (`dims`, x fastest) along
/// `x(t) = o + t·d`, `t ≥ t_min`, in index coordinates with `|d|` = one world mm.
///
/// mirrors shaders/project.wgsl: joseph_ray
pub fn joseph_ray<R: Real>(data: &[R], dims: [usize; 3], o: [R; 3], d: [R; 3], t_min: R) -> R {
    match joseph_planes(dims, o, d, t_min) {
        Some(p) => joseph_sum(data, dims, &p),
        None => R::zero(),
    }
}

/// Joseph's sum over the planes `p` of one ray: [`slice_bilinear`] on every plane
/// `s0..=s1`, times the length `w` between two planes. For a one-voxel-thick grid with
/// the ray in its plane (2-D) the taps at `y = 1` are outside and `ty = 0`, so each
/// sample is its top row plus zero: the same value without the empty taps.
#[inline(always)]
pub fn joseph_sum<R: Real>(data: &[R], dims: [usize; 3], p: &JosephPlanes<R>) -> R {
    let stride = [1, dims[0], dims[0] * dims[1]];
    let mut sum = R::zero();
    if dims[p.b] == 1 && p.kb == R::zero() && p.xb0 == R::zero() {
        let (sa, na) = (stride[p.a], dims[p.a] as i64);
        for s in p.s0..=p.s1 {
            let xa = p.xa0 + R::of(s as f64) * p.ka;
            let (fx, ix) = xa.floor_index();
            let tx = xa - fx;
            let ix = ix.unwrap_or(-2);
            let base = s * stride[p.m];
            let at = |i: i64| {
                if i < 0 || i >= na {
                    R::zero()
                } else {
                    data[base + i as usize * sa]
                }
            };
            let top = at(ix) * (R::one() - tx) + at(ix + 1) * tx;
            sum = sum + (top * R::one() + R::zero());
        }
    } else {
        for s in p.s0..=p.s1 {
            let sr = R::of(s as f64);
            sum = sum
                + slice_bilinear(
                    data,
                    s * stride[p.m],
                    stride[p.a],
                    dims[p.a],
                    stride[p.b],
                    dims[p.b],
                    p.xa0 + sr * p.ka,
                    p.xb0 + sr * p.kb,
                );
        }
    }
    sum * p.w
}

/// The weight of voxel `voxel` in Joseph's sum along a ray that meets the grid as
/// `p` says: `w · h_a · h_b` on the voxel's plane `s = voxel[m]`, where `h_a` is the
/// bilinear tap weight of [`slice_bilinear`] (`1 − t` for the tap at `floor(x_a)`,
/// `t` for the one after it) — the very number the forward sum multiplies the voxel
/// by, so the transpose built from it is exact.
///
/// mirrors shaders/shared/joseph.wgsl: joseph_weight
#[inline(always)]
pub fn joseph_weight<R: Real>(p: &JosephPlanes<R>, voxel: [usize; 3]) -> R {
    let s = voxel[p.m];
    if s < p.s0 || s > p.s1 {
        return R::zero();
    }
    let sr = R::of(s as f64);
    let tap = |x: R, i: usize| -> R {
        let f = x.floor_index().0;
        let t = x - f;
        let fi = R::of(i as f64);
        if f == fi {
            R::one() - t
        } else if f == fi - R::one() {
            t
        } else {
            R::zero()
        }
    };
    let ha = tap(p.xa0 + sr * p.ka, voxel[p.a]);
    if ha == R::zero() {
        return R::zero();
    }
    p.w * ha * tap(p.xb0 + sr * p.kb, voxel[p.b])
}

/// Options of [`project_volume`].
#[derive(Default)]
pub struct ProjectOptions<'a> {
    /// Called once per finished view (from worker threads), e.g. for a progress bar.
    pub on_view: Option<&'a (dyn Fn() + Sync)>,
}

/// Joseph projections (module docs) of `grid` in geometry `g`, in precision `R`: one
/// ray per detector pixel centre, parallel over detector lines. Values are grid
/// value × mm.
///
/// # Errors
/// [`Error::Invalid`] for an invalid geometry.
pub fn project_volume<R: Real>(
    grid: &Grid<R>,
    g: &Geometry,
    options: &ProjectOptions,
) -> Result<Projections<R>> {
    g.validate()?;
    let views: Vec<JosephView<R>> = joseph_views(g, grid.affine);
    let mut out = Projections::<R>::zeros(g)?;
    let per_view = g.rows * g.cols;
    out.data
        .par_chunks_mut(per_view)
        .enumerate()
        .panic_fuse()
        .for_each(|(k, img)| {
            img.par_chunks_mut(g.cols)
                .enumerate()
                .for_each(|(row, dst)| {
                    for (col, v) in dst.iter_mut().enumerate() {
                        let (o, d, t_min) =
                            pixel_ray(&views[k], R::of(col as f64), R::of(row as f64));
                        *v = joseph_ray(&grid.data, grid.dims, o, d, t_min);
                    }
                });
            if let Some(f) = options.on_view {
                f();
            }
        });
    Ok(out)
}

/// Where a voxel's rays land on the detector, per view: three rows `(α, α₀)`, `(β, β₀)`,
/// `(γ, γ₀)` such that the ray of detector pixel `(c, r)` passes through the point `X`
/// of the index frame exactly when `c = (α·X + α₀)/(γ·X + γ₀)` and
/// `r = (β·X + β₀)/(γ·X + γ₀)` (a parallel beam has `γ = 0`, `γ₀ = 1`; for a cone
/// beam the denominator is the ray parameter along `d0 + c·d_u + r·d_v`). Built in
/// f64 from [`JosephView`]'s own rows. The transpose uses it only to bound the
/// pixels it visits; their weights come from the rays themselves.
///
/// Three rows of four numbers (48 bytes in f32, ready for upload).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JosephFootprint<R> {
    pub rows: [[R; 4]; 3],
}

// Only the f32 instance is uploaded.
unsafe impl bytemuck::Zeroable for JosephFootprint<f32> {}
unsafe impl bytemuck::Pod for JosephFootprint<f32> {}

impl JosephFootprint<f64> {
    /// The footprint map of one view (from the f64 rays of [`JosephView::new`]).
    pub fn new(v: &JosephView<f64>) -> Self {
        let row = |i: usize| DVec3::new(v.rows[i][0], v.rows[i][1], v.rows[i][2]);
        let a0 = row(0);
        let parallel = v.rows[0][3] < 0.0;
        // Columns of M: the unknowns' coefficients in X − a0.
        let m = if parallel {
            DMat3::from_cols(row(1), row(2), row(3))
        } else {
            DMat3::from_cols(row(3), row(4), row(5))
        };
        let inv = m.inverse();
        // Rows of M⁻¹ applied to X − a0: (row·X, −row·a0).
        let r = |i: usize| {
            let q = inv.row(i);
            [q.x, q.y, q.z, -q.dot(a0)]
        };
        let rows = if parallel {
            // (c, r, t) = M⁻¹ (X − a0).
            [r(0), r(1), [0.0, 0.0, 0.0, 1.0]]
        } else {
            // (t, t·c, t·r) = M⁻¹ (X − a0).
            [r(1), r(2), r(0)]
        };
        JosephFootprint { rows }
    }

    /// The detector pixels `(c0..=c1, r0..=r1)` whose rays can pass through the cube
    /// of half-size `h` (index units) around the voxel centre `x`, clamped to
    /// `cols × rows`; `None` when no pixel can. Interval arithmetic on the rows:
    /// exact for a parallel beam, conservative for a cone beam, and the whole detector
    /// when the cube reaches the plane of the source.
    pub fn pixels(
        &self,
        x: [f64; 3],
        h: f64,
        cols: usize,
        rows: usize,
    ) -> Option<(usize, usize, usize, usize)> {
        self.pixels_box(x, [h; 3], cols, rows)
    }

    /// [`Self::pixels`] for the box of half-sizes `h` (per index axis) about `x`.
    ///
    /// mirrors shaders/joseph_pair_transpose.wgsl: footprint_box
    #[inline]
    pub fn pixels_box(
        &self,
        x: [f64; 3],
        h: [f64; 3],
        cols: usize,
        rows: usize,
    ) -> Option<(usize, usize, usize, usize)> {
        let lin = |i: usize| {
            let q = &self.rows[i];
            let centre = q[0] * x[0] + q[1] * x[1] + q[2] * x[2] + q[3];
            let half = h[0] * q[0].abs() + h[1] * q[1].abs() + h[2] * q[2].abs();
            (centre - half, centre + half)
        };
        let parallel = self.rows[2] == [0.0, 0.0, 0.0, 1.0];
        let (dlo, dhi) = lin(2);
        let (full_c, full_r) = ((0.0, (cols - 1) as f64), (0.0, (rows - 1) as f64));
        let ((clo, chi), (rlo, rhi)) = if parallel {
            (lin(0), lin(1))
        } else if dlo <= 1e-12 * dhi.abs().max(1.0) {
            (full_c, full_r)
        } else {
            let ratio = |(nlo, nhi): (f64, f64)| {
                let q = [nlo / dlo, nlo / dhi, nhi / dlo, nhi / dhi];
                (
                    q.iter().copied().fold(f64::INFINITY, f64::min),
                    q.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                )
            };
            (ratio(lin(0)), ratio(lin(1)))
        };
        let span = |lo: f64, hi: f64, n: usize| -> Option<(usize, usize)> {
            let lo = lo.ceil().max(0.0);
            let hi = hi.floor().min((n - 1) as f64);
            // Also false for NaN.
            if lo <= hi {
                Some((lo as usize, hi as usize))
            } else {
                None
            }
        };
        let (c0, c1) = span(clo, chi, cols)?;
        let (r0, r1) = span(rlo, rhi, rows)?;
        Some((c0, c1, r0, r1))
    }
}

/// The half-size of the cube whose pixels the transpose visits: a hair under one
/// voxel, so that a ray that grazes the cube's face (tap weight 0 up to rounding,
/// as when detector rows line up with voxel planes) is not visited.
pub const FOOTPRINT_HALF: f64 = 1.0 - 1e-9;

/// Joseph's projector as a matched pair: the forward projection `A` of
/// [`project_volume`] and its exact transpose `Aᵀ`, which sums into every voxel the
/// very weights ([`joseph_weight`]) the forward pass multiplied it by. Both run
/// over any subset of the views, both are deterministic (every output value is a
/// sum in a fixed order, whatever the thread count), and
/// `⟨A x, y⟩ = ⟨x, Aᵀ y⟩` holds to rounding (`tests/iterative.rs`).
///
/// The rays' [`JosephPlanes`] are kept in a table when it fits in
/// [`RAY_TABLE_BYTES`]; the transpose then runs ray by ray over index planes, as the
/// forward pass does (`transpose_by_planes`). Without the table it is voxel-driven (a
/// gather, [`Self::transpose_voxel`]): for every voxel and view, the
/// detector pixels whose rays can touch the voxel ([`JosephFootprint::pixels`]), each
/// weighted as the forward pass weighs it. On a 2-D problem (a one-voxel-thick grid
/// seen in its plane, as scikit-image's geometry) the table is also laid out view by
/// view (`FlatRays`; [`Self::is_flat`]), and both passes run over that layout plane by plane: the
/// same numbers in the same order, with a view's rays contiguous and a block of
/// planes per task.
pub struct JosephPair<R> {
    pub dims: [usize; 3],
    pub affine: DMat4,
    pub cols: usize,
    pub rows: usize,
    pub views: Vec<JosephView<R>>,
    pub footprints: Vec<JosephFootprint<f64>>,
    /// Per view, the driving axis when every ray of the view that meets the grid has
    /// the same one (then a voxel's rays cross its own plane on that axis, and the
    /// transpose bounds them by a square instead of a cube).
    pub view_axis: Vec<Option<usize>>,
    table: Option<Vec<Option<JosephPlanes<R>>>>,
    flat: Option<FlatRays<R>>,
}

/// The ray table of a 2-D problem laid out per view: when every ray that meets the
/// grid takes [`joseph_sum`]'s 2-D path (a one-voxel-thick grid, the ray in its
/// plane) and every view drives along one axis, the forward pass and the transpose
/// run view by view and plane by plane over these arrays ([`JosephPair::forward`],
/// `transpose_flat`) — the very numbers of the table, summed in the very same order,
/// so the results are bit for bit those of the ray-by-ray loops, with a view's rays
/// contiguous in memory.
struct FlatRays<R> {
    /// Per view: the driving axis `m` and the in-plane axis `a`.
    axes: Vec<(usize, usize)>,
    /// Rays per view.
    per_view: usize,
    /// Per ray (view-major): `xa0`, `ka`, `w` of its [`JosephPlanes`], and its planes
    /// `s0..=s1` (`1..=0` for a ray that misses the grid, with `w = 0`).
    xa0: Vec<R>,
    ka: Vec<R>,
    w: Vec<R>,
    s0: Vec<u32>,
    s1: Vec<u32>,
    /// Per view, its layout for the gather when it has one ([`gather`]).
    gather: Vec<Option<gather::GatherView<R>>>,
}

impl<R: Real> FlatRays<R> {
    /// The layout of `table` (rays of `per_view` pixels per view), or `None` when a
    /// ray does not take the 2-D path or a view has no single driving axis.
    fn new(
        dims: [usize; 3],
        table: &[Option<JosephPlanes<R>>],
        view_axis: &[Option<usize>],
        per_view: usize,
    ) -> Option<Self> {
        let n = table.len();
        let mut flat = FlatRays {
            axes: Vec::with_capacity(view_axis.len()),
            per_view,
            xa0: vec![R::zero(); n],
            ka: vec![R::zero(); n],
            w: vec![R::zero(); n],
            s0: vec![1; n],
            s1: vec![0; n],
            gather: Vec::new(),
        };
        for (k, axis) in view_axis.iter().enumerate() {
            let m = (*axis)?;
            let mut a = None;
            let first = k * per_view;
            for (i, ray) in table[first..first + per_view].iter().enumerate() {
                let i = first + i;
                let Some(p) = *ray else { continue };
                let two_d = dims[p.b] == 1 && p.kb == R::zero() && p.xb0 == R::zero();
                if !two_d || p.m != m || a.is_some_and(|a| a != p.a) || p.s1 > u32::MAX as usize {
                    return None;
                }
                a = Some(p.a);
                (flat.xa0[i], flat.ka[i], flat.w[i]) = (p.xa0, p.ka, p.w);
                (flat.s0[i], flat.s1[i]) = (p.s0 as u32, p.s1 as u32);
            }
            flat.axes.push((m, a.unwrap_or((m + 1) % 3)));
        }
        flat.gather = (0..view_axis.len())
            .into_par_iter()
            .map(|k| gather::GatherView::new(dims, &flat, k))
            .collect();
        Some(flat)
    }
}

/// Per view, the driving axis ([`JosephPlanes::m`]) when every ray of the view that
/// meets a grid of `dims` has the same one, else `None` (a `cols × rows` detector).
pub fn view_axes<R: Real>(
    dims: [usize; 3],
    views: &[JosephView<R>],
    cols: usize,
    rows: usize,
) -> Vec<Option<usize>> {
    views
        .par_iter()
        .map(|v| {
            let mut axes = (0..rows * cols).filter_map(|i| {
                let (col, row) = (R::of((i % cols) as f64), R::of((i / cols) as f64));
                let (o, d, t_min) = pixel_ray(v, col, row);
                joseph_planes(dims, o, d, t_min).map(|p| p.m)
            });
            let first = axes.next()?;
            axes.all(|m| m == first).then_some(first)
        })
        .collect()
}

/// Every ray's planes (`s0..=s1`, `1..=0` for none) narrowed to a support
/// ([`JosephPair::support_planes`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SupportPlanes {
    s0: Vec<u32>,
    s1: Vec<u32>,
}

/// One view's line integrals over the flat layout: plane by plane, every ray of the
/// view that crosses the plane adds its sample — for each ray the terms of
/// [`joseph_sum`]'s 2-D path in the same order, so the same sum bit for bit.
fn forward_flat<R: Real>(
    flat: &FlatRays<R>,
    planes: Option<&SupportPlanes>,
    (x, lines): (&[R], Option<&[R]>),
    dims: [usize; 3],
    (k, first): (usize, usize),
    dst: &mut [R],
) {
    let pv = flat.per_view;
    let rays = k * pv + first..k * pv + first + dst.len();
    let (s0, s1) = match planes {
        Some(p) => (&p.s0[rays.clone()], &p.s1[rays.clone()]),
        None => (&flat.s0[rays.clone()], &flat.s1[rays.clone()]),
    };
    let (xa0, ka) = (&flat.xa0[rays.clone()], &flat.ka[rays.clone()]);
    let (m, a) = flat.axes[k];
    let stride = [1, dims[0], dims[0] * dims[1]];
    let (mut sm, mut sa, na) = (stride[m], stride[a], dims[a] as i64);
    let mut x = x;
    if let Some(lines) = lines.filter(|_| sm == 1 && sa == dims[m]) {
        // The view's planes are the grid's columns: read them from the copy.
        (x, sm, sa) = (lines, dims[a], 1);
    }
    let view = FlatView { s0, s1, xa0, ka };
    let lo = s0
        .iter()
        .zip(s1)
        .filter(|(a, b)| a <= b)
        .map(|(a, _)| *a)
        .min();
    let hi = s1
        .iter()
        .zip(s0)
        .filter(|(b, a)| a <= b)
        .map(|(b, _)| *b)
        .max();
    let (Some(lo), Some(hi)) = (lo, hi) else {
        return;
    };
    #[cfg(target_arch = "x86_64")]
    if let (Some(view), Some(x), Some(out)) = (view.as_f32(), as_f32(x), as_f32_mut(dst)) {
        if avx512_fits(x.len(), [dims[a], hi as usize + 1]) {
            // A parallel view: the positions of its gather layout, and no planes' mask.
            let parallel = flat.gather[k]
                .as_ref()
                .and_then(|g| as_f32(g.positions(first..first + out.len())));
            // SAFETY: the CPU has AVX-512F (avx512_fits), indices fit an i32.
            unsafe {
                match parallel {
                    Some(xa0) => forward_flat_f32x16::<true>(
                        FlatView { xa0, ..view },
                        x,
                        (sm, sa, dims[a]),
                        out,
                    ),
                    None => forward_flat_f32x16::<false>(view, x, (sm, sa, dims[a]), out),
                }
            };
            for (v, &w) in dst.iter_mut().zip(&flat.w[rays]) {
                *v = *v * w;
            }
            return;
        }
    }
    let _ = view;
    for s in lo..=hi {
        let sr = R::of(s as f64);
        let base = s as usize * sm;
        for c in 0..dst.len() {
            if s < s0[c] || s > s1[c] {
                continue;
            }
            let xa = xa0[c] + sr * ka[c];
            let (fx, ix) = xa.floor_index();
            let tx = xa - fx;
            let ix = ix.unwrap_or(-2);
            let at = |i: i64| {
                if i < 0 || i >= na {
                    R::zero()
                } else {
                    x[base + i as usize * sa]
                }
            };
            let top = at(ix) * (R::one() - tx) + at(ix + 1) * tx;
            dst[c] = dst[c] + (top * R::one() + R::zero());
        }
    }
    for (v, &w) in dst.iter_mut().zip(&flat.w[rays]) {
        *v = *v * w;
    }
}

/// Planes `first ..` of the flat transpose (`planes` holds whole planes of `na`
/// values): every ray of `class` (slot, view) crossing one of them adds `w·h_a·y` into
/// its two taps, as [`JosephPair::transpose_by_planes`] does; a block of planes
/// shares one pass over the rays (each voxel still sums its rays in their order).
fn transpose_flat_planes<R: Real>(
    flat: &FlatRays<R>,
    y: &[R],
    class: &[(usize, usize)],
    pv: usize,
    (first, na): (usize, usize),
    layout: BlockLayout,
    planes: &mut [R],
) {
    let last = (first + planes.len() / na) as u32 - 1;
    let (ls, is) = layout.strides(na, planes.len() / na);
    #[cfg(target_arch = "x86_64")]
    if let (Some(y), Some(out)) = (as_f32(y), as_f32_mut(planes)) {
        let n = out.len() / na;
        if n <= 16 && avx512_fits(out.len(), [na, last as usize + 1]) {
            for &(slot, k) in class {
                let rays = k * pv..(k + 1) * pv;
                let view = FlatView {
                    s0: &flat.s0[rays.clone()],
                    s1: &flat.s1[rays.clone()],
                    xa0: &flat.xa0[rays.clone()],
                    ka: &flat.ka[rays.clone()],
                };
                let (Some(view), Some(w)) = (view.as_f32(), as_f32(&flat.w[rays])) else {
                    unreachable!("f32 planes with another ray table")
                };
                let ys = &y[slot * pv..(slot + 1) * pv];
                // SAFETY: the CPU has AVX-512F, at most 16 planes, indices fit an i32.
                unsafe { transpose_flat_planes_f32x16(view, w, ys, (first, na), (ls, is), out) };
            }
            return;
        }
    }
    let first = first as u32;
    let one = R::one();
    for &(slot, k) in class {
        let ys = &y[slot * pv..(slot + 1) * pv];
        let rays = k * pv..(k + 1) * pv;
        let (s0, s1) = (&flat.s0[rays.clone()], &flat.s1[rays.clone()]);
        let (xa0, ka, w) = (
            &flat.xa0[rays.clone()],
            &flat.ka[rays.clone()],
            &flat.w[rays],
        );
        for c in 0..pv {
            let yv = ys[c];
            if yv == R::zero() {
                continue;
            }
            for s in s0[c].max(first)..=s1[c].min(last) {
                let at = (s - first) as usize * ls;
                let xa = xa0[c] + R::of(s as f64) * ka[c];
                let (fa, ia) = xa.floor_index();
                let ta = xa - fa;
                let ia = ia.unwrap_or(i64::MIN / 2);
                for (da, wa) in [(0, one - ta), (1, ta)] {
                    let ca = ia + da;
                    if ca < 0 || ca >= na as i64 || wa == R::zero() {
                        continue;
                    }
                    // `ha · wb · y` with the 2-D path's wb = 1.
                    let ha = w[c] * wa;
                    let i = at + ca as usize * is;
                    planes[i] = planes[i] + ha * one * yv;
                }
            }
        }
    }
}

/// How a block of the flat transpose holds its `n` planes of `na` values: plane
/// after plane (`Planes`), or in-plane index after in-plane index, the `n` planes'
/// values side by side (`Lines`: a block of the grid's columns, laid out as its
/// lines).
#[derive(Clone, Copy, PartialEq)]
enum BlockLayout {
    Planes,
    Lines,
}

impl BlockLayout {
    /// The strides of (plane, in-plane index).
    fn strides(self, na: usize, n: usize) -> (usize, usize) {
        match self {
            BlockLayout::Planes => (na, 1),
            BlockLayout::Lines => (1, n),
        }
    }
}

/// Index planes per task of the flat transpose (a block of planes shares one pass
/// over the rays; sixteen, one per lane of [`transpose_flat_planes_f32x16`]).
const PLANES_PER_TASK: usize = 16;

/// One view's rays in the flat layout ([`FlatRays`]).
#[derive(Clone, Copy)]
struct FlatView<'a, R> {
    s0: &'a [u32],
    s1: &'a [u32],
    xa0: &'a [R],
    ka: &'a [R],
}

impl<'a, R: Real> FlatView<'a, R> {
    fn as_f32(&self) -> Option<FlatView<'a, f32>> {
        Some(FlatView {
            s0: self.s0,
            s1: self.s1,
            xa0: as_f32(self.xa0)?,
            ka: as_f32(self.ka)?,
        })
    }
}

/// Whether the AVX-512 kernels of the flat layout run: the CPU has AVX-512F, the
/// array of `len` values is indexed by an i32, and the counts `small` (the in-plane
/// size and the planes) are exact in f32 (below 2²⁴).
#[cfg(target_arch = "x86_64")]
fn avx512_fits(len: usize, small: [usize; 2]) -> bool {
    len < i32::MAX as usize
        && small.iter().all(|&n| n < 1 << 24)
        && std::arch::is_x86_feature_detected!("avx512f")
}

/// [`forward_flat`]'s plane loop for f32, sixteen rays at a time with AVX-512
/// (before the weights): sixteen rays keep their sums in one register while they
/// walk their planes, with the same operations in the same order for every ray, so
/// the same sums bit for bit. A tap outside the in-plane range reads 0 (masked), a
/// ray outside its planes `s0..=s1` keeps its sum (a masked add).
///
/// `PARALLEL`: a view with a gather layout (`gather::GatherView`, whose positions
/// `view.xa0` put a ray that misses the grid far outside it, and whose rays take no
/// tap inside the grid past their planes): a ray outside its planes then adds
/// `+0`, which leaves its sum as it is (a sum that starts at `+0` is never `−0`),
/// so the kernel adds without the planes' mask, and tests the taps on integers.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn forward_flat_f32x16<const PARALLEL: bool>(
    view: FlatView<f32>,
    x: &[f32],
    (sm, sa, na): (usize, usize, usize),
    dst: &mut [f32],
) {
    use std::arch::x86_64::*;
    let pv = dst.len();
    assert!(view.s0.len() == pv && view.s1.len() == pv);
    assert!(view.xa0.len() == pv && view.ka.len() == pv);
    let set = _mm512_set1_ps;
    let (one, zero) = (set(1.0), _mm512_setzero_ps());
    let (max0, min1, max1) = (set(na as f32 - 1.0), set(-1.0), set(na as f32 - 2.0));
    let vsa = _mm512_set1_epi32(sa as i32);
    let vna = _mm512_set1_epi32(na as i32);
    let mut c = 0;
    while c < pv {
        let n = (pv - c).min(16);
        let m: __mmask16 = ((1u32 << n) - 1) as u16;
        // The planes any of the sixteen rays crosses.
        let (s0s, s1s) = (&view.s0[c..c + n], &view.s1[c..c + n]);
        let crossing = s0s.iter().zip(s1s).filter(|(a, b)| a <= b);
        let lo = crossing.clone().map(|(a, _)| *a).min();
        let hi = crossing.map(|(_, b)| *b).max();
        let (Some(lo), Some(hi)) = (lo, hi) else {
            c += 16;
            continue;
        };
        // SAFETY: lanes at or past pv are masked off every load and store; every
        // value read lies in x (the masks keep 0 ≤ in-plane index < na, s·sm + i·sa
        // indexes the grid, and a window is read only where it lies in x).
        unsafe {
            let s0 = _mm512_maskz_loadu_epi32(m, view.s0.as_ptr().add(c) as *const i32);
            let s1 = _mm512_maskz_loadu_epi32(m, view.s1.as_ptr().add(c) as *const i32);
            let xa0 = _mm512_maskz_loadu_ps(m, view.xa0.as_ptr().add(c));
            let ka = _mm512_maskz_loadu_ps(m, view.ka.as_ptr().add(c));
            let q = dst.as_mut_ptr().add(c);
            let mut d = _mm512_maskz_loadu_ps(m, q);
            // The last ray's lane.
            let last = _mm512_set1_epi32(n as i32 - 1);
            for s in lo..=hi {
                let xa = _mm512_add_ps(xa0, _mm512_mul_ps(set(s as f32), ka));
                let fx = _mm512_roundscale_ps::<{ _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC }>(xa);
                let tx = _mm512_sub_ps(xa, fx);
                let ix = _mm512_cvttps_epi32(fx);
                let (active, ok0, ok1) = if PARALLEL {
                    // 0 ≤ ⌊x⌋ < n_a and 0 ≤ ⌊x⌋ + 1 < n_a, as unsigned integers.
                    let ok0 = m & _mm512_cmplt_epu32_mask(ix, vna);
                    let ix1 = _mm512_add_epi32(ix, _mm512_set1_epi32(1));
                    (m, ok0, m & _mm512_cmplt_epu32_mask(ix1, vna))
                } else {
                    let vs = _mm512_set1_epi32(s as i32);
                    let active =
                        m & _mm512_cmple_epu32_mask(s0, vs) & _mm512_cmple_epu32_mask(vs, s1);
                    let ok0 = active
                        & _mm512_cmp_ps_mask::<_CMP_GE_OQ>(fx, zero)
                        & _mm512_cmp_ps_mask::<_CMP_LE_OQ>(fx, max0);
                    let ok1 = active
                        & _mm512_cmp_ps_mask::<_CMP_GE_OQ>(fx, min1)
                        & _mm512_cmp_ps_mask::<_CMP_LE_OQ>(fx, max1);
                    (active, ok0, ok1)
                };
                let any = ok0 | ok1;
                let base = s as usize * sm;
                // Contiguous planes and taps within a window of 32 values: two loads
                // and two permutes instead of two gathers. The window starts one
                // below the tap of the first or the last ray (where the rays'
                // positions are monotone, every tap lies between them); the lanes'
                // own indices decide whether it holds them all.
                let ends = (
                    _mm_cvtsi128_si32(_mm512_castsi512_si128(ix)),
                    _mm_cvtsi128_si32(_mm512_castsi512_si128(_mm512_permutexvar_epi32(last, ix))),
                );
                let wlo = ends.0.min(ends.1).wrapping_sub(1);
                let at = base as i64 + i64::from(wlo);
                let i0 = _mm512_sub_epi32(ix, _mm512_set1_epi32(wlo));
                let inside = _mm512_mask_cmple_epu32_mask(any, i0, _mm512_set1_epi32(30));
                let (v0, v1) = if sa == 1 && inside == any && at >= 0 && at as usize + 32 <= x.len()
                {
                    let p = x.as_ptr().add(at as usize);
                    let (w0, w1) = (_mm512_loadu_ps(p), _mm512_loadu_ps(p.add(16)));
                    let i1 = _mm512_add_epi32(i0, _mm512_set1_epi32(1));
                    (
                        _mm512_maskz_permutex2var_ps(ok0, w0, i0, w1),
                        _mm512_maskz_permutex2var_ps(ok1, w0, i1, w1),
                    )
                } else {
                    let vb = _mm512_set1_epi32(base as i32);
                    let i0 = _mm512_add_epi32(vb, _mm512_mullo_epi32(ix, vsa));
                    let i1 = _mm512_add_epi32(i0, vsa);
                    (
                        _mm512_mask_i32gather_ps::<4>(zero, ok0, i0, x.as_ptr()),
                        _mm512_mask_i32gather_ps::<4>(zero, ok1, i1, x.as_ptr()),
                    )
                };
                let top = _mm512_add_ps(
                    _mm512_mul_ps(v0, _mm512_sub_ps(one, tx)),
                    _mm512_mul_ps(v1, tx),
                );
                // `top · 1 + 0` in joseph_sum: the same sum, as d is never −0.
                d = _mm512_mask_add_ps(d, active, d, top);
            }
            _mm512_mask_storeu_ps(q, m, d);
        }
        c += 16;
    }
}

/// [`transpose_flat_planes`] for f32 and one view, with AVX-512: the block's planes
/// (at most sixteen) are the lanes, so every ray adds into sixteen distinct voxels
/// at once (a gather, an add, a scatter per tap) — for every voxel the same terms in
/// the same order, so the same sums bit for bit.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn transpose_flat_planes_f32x16(
    view: FlatView<f32>,
    w: &[f32],
    ys: &[f32],
    (first, na): (usize, usize),
    (ls, is): (usize, usize),
    planes: &mut [f32],
) {
    use std::arch::x86_64::*;
    let pv = ys.len();
    assert!(view.s0.len() == pv && view.s1.len() == pv && w.len() == pv);
    assert!(view.xa0.len() == pv && view.ka.len() == pv);
    let n = planes.len() / na;
    assert!((1..=16).contains(&n) && planes.len() == n * na);
    let last = (first + n - 1) as u32;
    let lanes: __mmask16 = ((1u32 << n) - 1) as u16;
    let lane = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    let vs = _mm512_add_epi32(_mm512_set1_epi32(first as i32), lane);
    let sf = _mm512_cvtepi32_ps(vs);
    let row = _mm512_mullo_epi32(lane, _mm512_set1_epi32(ls as i32));
    let vis = _mm512_set1_epi32(is as i32);
    let set = _mm512_set1_ps;
    let (one, zero) = (set(1.0), _mm512_setzero_ps());
    let (max0, min1, max1) = (set(na as f32 - 1.0), set(-1.0), set(na as f32 - 2.0));
    let out = planes.as_mut_ptr();
    for c in 0..pv {
        let yv = ys[c];
        let (s0, s1) = (view.s0[c], view.s1[c]);
        if yv == 0.0 || s0.max(first as u32) > s1.min(last) {
            continue;
        }
        let active = lanes
            & _mm512_cmple_epu32_mask(_mm512_set1_epi32(s0 as i32), vs)
            & _mm512_cmple_epu32_mask(vs, _mm512_set1_epi32(s1 as i32));
        let xa = _mm512_add_ps(set(view.xa0[c]), _mm512_mul_ps(sf, set(view.ka[c])));
        let fa = _mm512_roundscale_ps::<{ _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC }>(xa);
        let ta = _mm512_sub_ps(xa, fa);
        let ia = _mm512_cvttps_epi32(fa);
        let (wc, yc) = (set(w[c]), set(yv));
        let i0 = _mm512_add_epi32(row, _mm512_mullo_epi32(ia, vis));
        for (i, wa, ok) in [
            (
                i0,
                _mm512_sub_ps(one, ta),
                _mm512_cmp_ps_mask::<_CMP_GE_OQ>(fa, zero)
                    & _mm512_cmp_ps_mask::<_CMP_LE_OQ>(fa, max0),
            ),
            (
                _mm512_add_epi32(i0, vis),
                ta,
                _mm512_cmp_ps_mask::<_CMP_GE_OQ>(fa, min1)
                    & _mm512_cmp_ps_mask::<_CMP_LE_OQ>(fa, max1),
            ),
        ] {
            let ok = active & ok & _mm512_cmp_ps_mask::<_CMP_NEQ_UQ>(wa, zero);
            // `ha · wb · y` with the 2-D path's wb = 1 (`ha · 1` is `ha`).
            let add = _mm512_mul_ps(_mm512_mul_ps(wc, wa), yc);
            // SAFETY: the masked lanes index plane (s − first) < n at 0 ≤ i < na.
            unsafe {
                let p = _mm512_mask_i32gather_ps::<4>(zero, ok, i, out);
                _mm512_mask_i32scatter_ps::<4>(out, ok, i, _mm512_add_ps(p, add));
            }
        }
    }
}

/// From this many views on, the flat forward pass reads a grid whose planes are
/// its columns from a copy laid out as lines ([`columns_as_lines`]).
const LINES_COPY_VIEWS: usize = 16;

/// A 2-D grid (one axis of size 1) with its two other axes swapped, so that column
/// `s` of the grid is line `s` of the copy: `copy[s·n + i] = x[s + i·m]` for the
/// `m × n` grid; `None` for a 3-D grid.
fn columns_as_lines<R: Real>(x: &[R], dims: [usize; 3]) -> Option<Vec<R>> {
    let live: Vec<usize> = dims.iter().copied().filter(|&n| n > 1).collect();
    let &[m, n] = live.as_slice() else {
        return None;
    };
    let mut copy = vec![R::zero(); x.len()];
    copy.par_chunks_mut(n * 16)
        .enumerate()
        .for_each(|(b, lines)| {
            for (l, line) in lines.chunks_mut(n).enumerate() {
                let s = b * 16 + l;
                for (i, v) in line.iter_mut().enumerate() {
                    *v = x[s + i * m];
                }
            }
        });
    Some(copy)
}

/// Below this many views the flat forward pass splits each view into this many
/// pieces of rays (one task each).
const FORWARD_PIECES: usize = 4;

/// The largest ray table a [`JosephPair`] keeps (bytes).
pub const RAY_TABLE_BYTES: usize = 512 << 20;

/// `x` with the voxels outside `support` set to `+0` (`x` itself when `None`).
/// Mirrors shaders/iterative.wgsl: mask (the device-resident port, src/gpu/iterative.rs).
pub fn masked<R: Real>(mut x: Vec<R>, support: Option<&[bool]>) -> Vec<R> {
    if let Some(m) = support {
        x.par_iter_mut().zip(m).for_each(|(v, &keep)| {
            if !keep {
                *v = R::zero();
            }
        });
    }
    x
}

impl<R: Real> JosephPair<R> {
    /// The pair for a grid of `dims` voxels with index-to-world `affine`, seen in
    /// geometry `g`.
    ///
    /// # Errors
    /// [`Error::Invalid`] for an invalid geometry, grid or affine.
    pub fn new(dims: [usize; 3], affine: DMat4, g: &Geometry) -> Result<Self> {
        g.validate()?;
        check_dims(dims)?;
        let det = DMat3::from_mat4(affine).determinant();
        if !affine.is_finite() || !det.is_finite() || det.abs() < 1e-300 {
            return Err(Error::invalid(
                "reconstruction grid",
                "the index-to-world affine must be finite and invertible",
            ));
        }
        let views64: Vec<JosephView<f64>> = joseph_views(g, affine);
        let footprints = views64.iter().map(JosephFootprint::new).collect();
        let views = joseph_views(g, affine);
        let mut pair = JosephPair {
            dims,
            affine,
            cols: g.cols,
            rows: g.rows,
            views,
            footprints,
            view_axis: Vec::new(),
            table: None,
            flat: None,
        };
        let rays = g.n_angles() * g.rows * g.cols;
        if rays.saturating_mul(std::mem::size_of::<Option<JosephPlanes<R>>>()) <= RAY_TABLE_BYTES {
            let per_view = g.rows * g.cols;
            let table = (0..rays)
                .into_par_iter()
                .map(|i| pair.planes_of(i / per_view, i % per_view))
                .collect();
            pair.table = Some(table);
        }
        pair.view_axis = view_axes(dims, &pair.views, g.cols, g.rows);
        if let Some(table) = &pair.table {
            pair.flat = FlatRays::new(dims, table, &pair.view_axis, g.rows * g.cols);
        }
        Ok(pair)
    }

    /// The number of views.
    pub fn n_views(&self) -> usize {
        self.views.len()
    }

    /// The number of voxels.
    pub fn n_voxels(&self) -> usize {
        self.dims.iter().product()
    }

    /// The number of detector pixels per view.
    pub fn per_view(&self) -> usize {
        self.rows * self.cols
    }

    fn planes_of(&self, view: usize, pixel: usize) -> Option<JosephPlanes<R>> {
        let (col, row) = (pixel % self.cols, pixel / self.cols);
        let (o, d, t_min) = pixel_ray(&self.views[view], R::of(col as f64), R::of(row as f64));
        joseph_planes(self.dims, o, d, t_min)
    }

    #[inline(always)]
    fn planes(&self, view: usize, pixel: usize) -> Option<JosephPlanes<R>> {
        match &self.table {
            Some(t) => t[view * self.per_view() + pixel],
            None => self.planes_of(view, pixel),
        }
    }

    /// `A x` over the views `views` (in that order): `views.len() × rows × cols`
    /// line integrals, the numbers [`project_volume`] gives for them.
    pub fn forward(&self, x: &[R], views: &[usize]) -> Vec<R> {
        self.forward_within(x, views, None)
    }

    /// Every ray's planes narrowed to those where one of its taps can fall on a
    /// voxel of `support` (one flag per voxel), for [`Self::forward_within`]; `None`
    /// without the flat 2-D layout. The support is bounded by the disc about the
    /// centre of its bounding box through its farthest voxel; a ray's planes whose
    /// crossing lies farther than one voxel outside that disc are dropped (with a
    /// plane to spare at either end): every tap there lies off the support.
    pub fn support_planes(&self, support: &[bool]) -> Option<SupportPlanes> {
        let flat = self.flat.as_ref()?;
        assert_eq!(
            support.len(),
            self.n_voxels(),
            "JosephPair::support_planes: support size"
        );
        let dims = self.dims;
        let coords = |i: usize| {
            [
                i % dims[0],
                (i / dims[0]) % dims[1],
                i / (dims[0] * dims[1]),
            ]
        };
        let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
        for (i, _) in support.iter().enumerate().filter(|(_, &k)| k) {
            let c = coords(i);
            for a in 0..3 {
                (lo[a], hi[a]) = (lo[a].min(c[a]), hi[a].max(c[a]));
            }
        }
        let n = flat.xa0.len();
        let empty = SupportPlanes {
            s0: vec![1; n],
            s1: vec![0; n],
        };
        if lo[0] == usize::MAX {
            return Some(empty);
        }
        let centre: [f64; 3] = std::array::from_fn(|a| (lo[a] + hi[a]) as f64 / 2.0);
        let rho = support
            .iter()
            .enumerate()
            .filter(|(_, &k)| k)
            .map(|(i, _)| {
                let c = coords(i);
                (0..3)
                    .map(|a| (c[a] as f64 - centre[a]).powi(2))
                    .sum::<f64>()
            })
            .fold(0.0f64, f64::max)
            .sqrt();
        // A tap lies within one voxel (along a) of the ray's crossing, whose computed
        // position is within 1e-3 of the exact line's.
        let reach = rho + 1.01;
        let pv = flat.per_view;
        let mut out = empty;
        out.s0
            .par_chunks_mut(pv)
            .zip(out.s1.par_chunks_mut(pv))
            .enumerate()
            .for_each(|(k, (s0, s1))| {
                let (m, a) = flat.axes[k];
                let (cm, ca) = (centre[m], centre[a]);
                for c in 0..pv {
                    let r = k * pv + c;
                    let (f0, f1) = (flat.s0[r], flat.s1[r]);
                    if f0 > f1 {
                        continue;
                    }
                    // (s − cm)² + (xa0 + s·ka − ca)² ≤ reach²: a quadratic in s.
                    let (x0, ka) = (flat.xa0[r].f64() - ca, flat.ka[r].f64());
                    let qa = 1.0 + ka * ka;
                    let qb = 2.0 * (ka * x0 - cm);
                    let qc = cm * cm + x0 * x0 - reach * reach;
                    let disc = qb * qb - 4.0 * qa * qc;
                    if disc.is_nan() || disc < 0.0 {
                        continue;
                    }
                    let root = disc.sqrt();
                    let (r0, r1) = ((-qb - root) / (2.0 * qa), (-qb + root) / (2.0 * qa));
                    let n0 = (r0.floor() - 1.0).max(f64::from(f0));
                    let n1 = (r1.ceil() + 1.0).min(f64::from(f1));
                    if n0 <= n1 {
                        (s0[c], s1[c]) = (n0 as u32, n1 as u32);
                    }
                }
            });
        Some(out)
    }

    /// [`Self::forward`] of an image that is `+0` off the support `planes` were
    /// made for ([`Self::support_planes`]), skipping the planes where every tap of a
    /// ray lies off it: their samples are `+0`, which leaves a ray's sum as it is
    /// (a sum that starts at `+0` is never `−0`), so the numbers are
    /// [`Self::forward`]'s bit for bit. `None`: every plane.
    pub fn forward_within(
        &self,
        x: &[R],
        views: &[usize],
        planes: Option<&SupportPlanes>,
    ) -> Vec<R> {
        assert_eq!(x.len(), self.n_voxels(), "JosephPair::forward: grid size");
        let dims = self.dims;
        let mut out = vec![R::zero(); views.len() * self.per_view()];
        if let Some(flat) = &self.flat {
            let pv = self.per_view();
            // A few views (an OS-SART subset) split into pieces of rays too.
            let piece = if views.len() >= FORWARD_PIECES {
                pv
            } else {
                pv.div_ceil(FORWARD_PIECES).max(64)
            };
            // Many views: the grid also as lines along the other axis, so that every
            // view's planes are contiguous (the same values, read in another layout).
            let lines = (views.len() >= LINES_COPY_VIEWS)
                .then(|| columns_as_lines(x, dims))
                .flatten();
            let lines = lines.as_deref();
            out.par_chunks_mut(pv).zip(views).for_each(|(dst, &k)| {
                dst.par_chunks_mut(piece).enumerate().for_each(|(j, d)| {
                    forward_flat(flat, planes, (x, lines), dims, (k, j * piece), d)
                });
            });
            return out;
        }
        out.par_chunks_mut(self.cols)
            .enumerate()
            .for_each(|(line, dst)| {
                let (k, row) = (views[line / self.rows], line % self.rows);
                for (col, v) in dst.iter_mut().enumerate() {
                    let Some(p) = self.planes(k, row * self.cols + col) else {
                        *v = R::zero();
                        continue;
                    };
                    *v = joseph_sum(x, dims, &p);
                }
            });
        out
    }

    /// `Aᵀ y` over the views `views`: `y` holds `views.len() × rows × cols` values in
    /// that order; the result is one value per voxel, each the sum over the views (in
    /// order), rows and columns of `weight · y`.
    pub fn transpose(&self, y: &[R], views: &[usize]) -> Vec<R> {
        self.transpose_on(y, views, None)
    }

    /// [`Self::transpose`] with the voxels off `support` set to `+0` (all kept when
    /// `None`): `M·Aᵀ y`. Where the gather's vector kernel runs
    /// ([`Self::has_fast_sart_update`]: f32 parallel 2-D views on a CPU with
    /// AVX-512F) every voxel gathers its own terms and the voxels off the support
    /// cost nothing; elsewhere the transpose runs by planes and is masked after. The
    /// same numbers either way, bit for bit (module `gather`).
    pub fn transpose_on(&self, y: &[R], views: &[usize], support: Option<&[bool]>) -> Vec<R> {
        assert_eq!(
            y.len(),
            views.len() * self.per_view(),
            "JosephPair::transpose: projection size"
        );
        if let Some(m) = support {
            assert_eq!(
                m.len(),
                self.n_voxels(),
                "JosephPair::transpose: support size"
            );
        }
        match self.transpose_gather(y, views, support) {
            Some(u) => u,
            None => masked(self.transpose_unmasked(y, views), support),
        }
    }

    /// [`Self::transpose`] without the gather.
    fn transpose_unmasked(&self, y: &[R], views: &[usize]) -> Vec<R> {
        match &self.table {
            Some(_) if self.flat.is_some() => self.transpose_flat(y, views),
            Some(table) => self.transpose_by_planes(table, y, views),
            None => self.transpose_by_voxels(y, views),
        }
    }

    /// The pair without the flat 2-D layout: the forward pass ray by ray and the
    /// transpose by planes over the ray table (the same numbers, bit for bit; kept
    /// for the tests that say so).
    pub fn without_flat(mut self) -> Self {
        self.flat = None;
        self
    }

    /// Whether the forward pass and the transpose run over the flat 2-D layout
    /// (every ray on [`joseph_sum`]'s 2-D path, one driving axis per view).
    pub fn is_flat(&self) -> bool {
        self.flat.is_some()
    }

    /// The pair without its ray table: every ray is rebuilt where it is needed, and
    /// [`Self::transpose`] gathers voxel by voxel (what it does when the table would
    /// not fit; both ways give the same weights).
    pub fn without_table(mut self) -> Self {
        self.table = None;
        self.flat = None;
        self
    }

    /// [`Self::transpose`] as a gather: every voxel sums, view by view in order, the
    /// rays of [`Self::transpose_voxel`].
    fn transpose_by_voxels(&self, y: &[R], views: &[usize]) -> Vec<R> {
        let dims = self.dims;
        let mut out = vec![R::zero(); self.n_voxels()];
        out.par_chunks_mut(dims[0])
            .enumerate()
            .for_each(|(line, dst)| {
                let (j, k) = (line % dims[1], line / dims[1]);
                // Views outside, voxels inside: every voxel still sums its views in
                // order (the same sum as transpose_voxel), and one view's rays stay in
                // cache along the line.
                for (slot, &view) in views.iter().enumerate() {
                    for (i, v) in dst.iter_mut().enumerate() {
                        *v = *v + self.transpose_view(y, slot, view, [i, j, k]);
                    }
                }
            });
        out
    }

    /// [`Self::transpose_by_planes`] over the flat layout ([`FlatRays`]): the same
    /// tasks (one per index plane), rays (views in order, then pixels) and sums.
    fn transpose_flat(&self, y: &[R], views: &[usize]) -> Vec<R> {
        let Some(flat) = &self.flat else {
            unreachable!("transpose_flat without the flat layout")
        };
        let dims = self.dims;
        let pv = self.per_view();
        let mut out = vec![R::zero(); self.n_voxels()];
        for m in 0..3 {
            let class: Vec<(usize, usize)> = views
                .iter()
                .enumerate()
                .filter(|&(_, &k)| flat.axes[k].0 == m)
                .map(|(slot, &k)| (slot, k))
                .collect();
            let Some(&(_, k0)) = class.first() else {
                continue;
            };
            let a = flat.axes[k0].1;
            let (na, sa) = (dims[a], [1, dims[0], dims[0] * dims[1]][a]);
            let sm = [1, dims[0], dims[0] * dims[1]][m];
            let (nm, block) = (dims[m], na * PLANES_PER_TASK);
            let planes_of = |b: usize, len: usize, layout: BlockLayout| {
                let mut planes = vec![R::zero(); len];
                let first = b * PLANES_PER_TASK;
                transpose_flat_planes(flat, y, &class, pv, (first, na), layout, &mut planes);
                planes
            };
            // Back into the grid's layout (voxel (plane s, in-plane i) at s·sm + i·sa
            // of a 2-D grid), each voxel once: `out + plane value`.
            if sa == 1 && sm == na {
                // The planes are the grid's lines: blocks of them are chunks of it.
                out.par_chunks_mut(block).enumerate().for_each(|(b, dst)| {
                    let planes = planes_of(b, dst.len(), BlockLayout::Planes);
                    for (o, v) in dst.iter_mut().zip(planes) {
                        *o = *o + v;
                    }
                });
            } else if sm == 1 && sa == nm {
                // The planes are the grid's columns: lines of the grid gather them.
                // Each block is held as lines (BlockLayout::Lines), so a line of the
                // grid copies a run of values from every block.
                let blocks: Vec<Vec<R>> = (0..nm.div_ceil(PLANES_PER_TASK))
                    .into_par_iter()
                    .map(|b| {
                        let n = PLANES_PER_TASK.min(nm - b * PLANES_PER_TASK);
                        planes_of(b, na * n, BlockLayout::Lines)
                    })
                    .collect();
                out.par_chunks_mut(sa).enumerate().for_each(|(i, line)| {
                    for (dst, block) in line.chunks_mut(PLANES_PER_TASK).zip(&blocks) {
                        let n = dst.len();
                        for (o, &v) in dst.iter_mut().zip(&block[i * n..(i + 1) * n]) {
                            *o = *o + v;
                        }
                    }
                });
            } else {
                let planes: Vec<R> = (0..nm.div_ceil(PLANES_PER_TASK))
                    .into_par_iter()
                    .flat_map_iter(|b| {
                        let n = PLANES_PER_TASK.min(nm - b * PLANES_PER_TASK);
                        planes_of(b, na * n, BlockLayout::Planes)
                    })
                    .collect();
                for (s, plane) in planes.chunks(na).enumerate() {
                    for (i, &v) in plane.iter().enumerate() {
                        let idx = s * sm + i * sa;
                        out[idx] = out[idx] + v;
                    }
                }
            }
        }
        out
    }

    /// [`Self::transpose`] ray by ray, plane by plane: for each driving axis `m` in
    /// turn, every index plane `x_m = s` is one task that adds, for every ray (views in
    /// order, then pixels in order) driven along `m` that crosses it, the ray's value
    /// times each of its bilinear tap weights ([`joseph_weight`]'s numbers) into the
    /// plane's voxels. A plane belongs to one task, so every voxel's sum runs in a
    /// fixed order whatever the thread count; the work is the forward projection's.
    fn transpose_by_planes(
        &self,
        table: &[Option<JosephPlanes<R>>],
        y: &[R],
        views: &[usize],
    ) -> Vec<R> {
        let dims = self.dims;
        let pv = self.per_view();
        let mut out = vec![R::zero(); self.n_voxels()];
        let mut plane_buf = vec![R::zero(); self.n_voxels()];
        for m in 0..3 {
            // The rays driven along m with a non-zero value: (index into y, planes).
            let rays: Vec<(usize, JosephPlanes<R>)> = views
                .iter()
                .enumerate()
                .flat_map(|(slot, &k)| {
                    (0..pv).filter_map(move |pixel| {
                        let yi = slot * pv + pixel;
                        match table[k * pv + pixel] {
                            Some(p) if p.m == m && y[yi] != R::zero() => Some((yi, p)),
                            _ => None,
                        }
                    })
                })
                .collect();
            if rays.is_empty() {
                continue;
            }
            let (a, b) = match m {
                0 => (1, 2),
                1 => (0, 2),
                _ => (0, 1),
            };
            let (na, nb) = (dims[a], dims[b]);
            plane_buf
                .par_chunks_mut(na * nb)
                .enumerate()
                .for_each(|(s, plane)| {
                    plane.iter_mut().for_each(|v| *v = R::zero());
                    let sr = R::of(s as f64);
                    for (yi, p) in &rays {
                        if s < p.s0 || s > p.s1 {
                            continue;
                        }
                        let (xa, xb) = (p.xa0 + sr * p.ka, p.xb0 + sr * p.kb);
                        let ((fa, ia), (fb, ib)) = (xa.floor_index(), xb.floor_index());
                        let (ta, tb) = (xa - fa, xb - fb);
                        let (ia, ib) = (ia.unwrap_or(i64::MIN / 2), ib.unwrap_or(i64::MIN / 2));
                        let yv = y[*yi];
                        let one = R::one();
                        for (da, wa) in [(0, one - ta), (1, ta)] {
                            let ca = ia + da;
                            if ca < 0 || ca >= na as i64 || wa == R::zero() {
                                continue;
                            }
                            let ha = p.w * wa;
                            for (db, wb) in [(0, one - tb), (1, tb)] {
                                let cb = ib + db;
                                if cb < 0 || cb >= nb as i64 {
                                    continue;
                                }
                                let idx = ca as usize + na * cb as usize;
                                plane[idx] = plane[idx] + ha * wb * yv;
                            }
                        }
                    }
                });
            // Back into the grid's layout (x fastest).
            out.par_chunks_mut(dims[0])
                .enumerate()
                .for_each(|(line, dst)| {
                    let (j, k) = (line % dims[1], line / dims[1]);
                    for (i, v) in dst.iter_mut().enumerate() {
                        let c = [i, j, k];
                        let idx = c[m] * na * nb + c[a] + na * c[b];
                        *v = *v + plane_buf[idx];
                    }
                });
        }
        out
    }

    /// The part of one voxel's [`Self::transpose`] sum from one view (`slot` = its
    /// place in `y`).
    #[inline(always)]
    fn transpose_view(&self, y: &[R], slot: usize, k: usize, voxel: [usize; 3]) -> R {
        let x = voxel.map(|v| v as f64);
        let mut h = [FOOTPRINT_HALF; 3];
        if let Some(m) = self.view_axis[k] {
            h[m] = 0.0;
        }
        let Some((c0, c1, r0, r1)) = self.footprints[k].pixels_box(x, h, self.cols, self.rows)
        else {
            return R::zero();
        };
        let base = slot * self.per_view();
        let mut acc = R::zero();
        for row in r0..=r1 {
            for col in c0..=c1 {
                let pixel = row * self.cols + col;
                let yv = y[base + pixel];
                if yv == R::zero() {
                    continue;
                }
                if let Some(p) = self.planes(k, pixel) {
                    acc = acc + joseph_weight(&p, voxel) * yv;
                }
            }
        }
        acc
    }

    /// One voxel of [`Self::transpose`].
    ///
    /// mirrors shaders/joseph_pair_transpose.wgsl: transpose
    #[inline]
    pub fn transpose_voxel(&self, y: &[R], views: &[usize], voxel: [usize; 3]) -> R {
        let mut acc = R::zero();
        for (slot, &k) in views.iter().enumerate() {
            acc = acc + self.transpose_view(y, slot, k, voxel);
        }
        acc
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::phantom::Primitive;
    use glam::DVec3;

    #[test]
    fn a_centred_sphere_projects_to_its_chords() {
        // Radius 0.5 in phantom units = 64 mm; density 2.
        let ph = Phantom::from_primitives("ball", vec![Primitive::sphere(2.0, DVec3::ZERO, 0.5)]);
        for g in [
            Geometry::parallel_skimage(201, vec![0.0, 45.0, 123.0]).unwrap(),
            Geometry::cone_rtk(1000.0, 1500.0, 201, 5, 1.0, 1.0, vec![0.0, 200.0]).unwrap(),
        ] {
            let p = project_phantom(&ph, &g).unwrap();
            for k in 0..g.n_angles() {
                for row in 0..g.rows {
                    for col in 0..g.cols {
                        let (o, d, _) = g.ray(k, col as f64, row as f64);
                        // Distance of the ray from the centre, then the chord length.
                        let dist = (o - d * o.dot(d)).length();
                        let chord = 2.0 * (64.0f64 * 64.0 - dist * dist).max(0.0).sqrt();
                        let got = p.view(k)[row * g.cols + col];
                        // Compare squares: near a tangent the chord is the square root of
                        // a difference, and its rounding error grows without bound there.
                        let (got2, want2) = (got * got, 4.0 * chord * chord);
                        assert!(
                            (got2 - want2).abs() < 1e-9 * 256.0 * 256.0,
                            "{k} {row} {col}: {got}"
                        );
                    }
                }
            }
        }
    }
}
