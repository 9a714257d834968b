//! The scalar fields the ray casters sample, in index coordinates: a voxel grid
//! reconstructed with a filter ([`GridField`]), an analytic phantom sampled exactly
//! ([`PhantomField`]), or any other [`Field`] (D²VR's projections, `cpu::d2vr`).
//!
//! A field has a box `[-0.5, n − 0.5]` on each axis, a value and an index-space
//! gradient at every point, and a value range (which scales the shading's gradient
//! threshold and normalises MIDA).

use super::filter::{prepare, sample};
use super::gradient::{gradient_at, gradient_stencil, precompute_gradients};
use super::grid::{value_range, Grid};
use crate::phantom::{index_to_phantom, Phantom};
use crate::real::{Real, V3};
use crate::settings::{Filter, GradientMethod};

/// A scalar field the ray caster samples, in index coordinates.
pub trait Field<R: Real>: Sync {
    /// Grid dimensions; the field's box is `[-0.5, n − 0.5]` on each axis.
    fn dims(&self) -> [usize; 3];
    /// The value at index-space point `p`.
    fn value(&self, p: V3<R>) -> R;
    /// The index-space gradient at `p`.
    fn gradient(&self, p: V3<R>) -> V3<R>;
    /// Minimum and maximum value (scales the shading threshold).
    fn value_range(&self) -> (f64, f64);
    /// The voxel values behind the field, if any (pre-classification needs them).
    fn voxel_values(&self) -> Option<&Grid<R>> {
        None
    }
    /// What the filter samples (B-spline coefficients for `bspline-interp`), if a grid.
    fn sampled_grid(&self) -> Option<&Grid<R>> {
        None
    }
    /// A brick's own grid and the whole grid's voxel its voxel 0 is ([`BrickField`]):
    /// what its empty-space skipping bounds.
    fn brick(&self) -> Option<(&Grid<R>, [usize; 3])> {
        None
    }
}

/// The upper corner `n − ½` of the index-space box `[−½, n − ½]` of a grid of `dims`
/// voxels (the lower corner is `−½` on every axis).
#[inline]
pub fn box_hi<R: Real>(dims: [usize; 3]) -> V3<R> {
    V3::new(
        R::of(dims[0] as f64 - 0.5),
        R::of(dims[1] as f64 - 0.5),
        R::of(dims[2] as f64 - 0.5),
    )
}

/// A voxel grid reconstructed with a filter; gradients on the fly or precomputed.
pub struct GridField<R> {
    /// What the filter samples (see `filter::prepare`): the voxel values, or for
    /// `BsplineInterp` their B-spline coefficients.
    pub grid: Grid<R>,
    /// The voxel values, kept apart only when `grid` holds coefficients.
    values: Option<Grid<R>>,
    pub filter: Filter,
    pub method: GradientMethod,
    /// Precomputed gradient components (prepared for the filter like the data).
    pub gradients: Option<[Grid<R>; 3]>,
    range: (f64, f64),
}

impl<R: Real> GridField<R> {
    pub fn new(values: Grid<R>, filter: Filter, method: GradientMethod, precompute: bool) -> Self {
        let gradients =
            precompute.then(|| precompute_gradients(&values, method).map(|g| prepare(&g, filter)));
        let (lo, hi) = value_range(&values.data);
        let (grid, values) = if filter.prefiltered() {
            (prepare(&values, filter), Some(values))
        } else {
            (values, None)
        };
        GridField {
            grid,
            values,
            filter,
            method,
            gradients,
            range: (lo, hi),
        }
    }

    /// The voxel values.
    pub fn values(&self) -> &Grid<R> {
        self.values.as_ref().unwrap_or(&self.grid)
    }
}

impl<R: Real> Field<R> for GridField<R> {
    fn dims(&self) -> [usize; 3] {
        self.grid.dims
    }
    #[inline]
    fn value(&self, p: V3<R>) -> R {
        sample(&self.grid, self.filter, p)
    }
    #[inline]
    fn gradient(&self, p: V3<R>) -> V3<R> {
        match &self.gradients {
            Some([gx, gy, gz]) => V3::new(
                sample(gx, self.filter, p),
                sample(gy, self.filter, p),
                sample(gz, self.filter, p),
            ),
            None => gradient_at(&self.grid, self.filter, p, self.method),
        }
    }
    fn value_range(&self) -> (f64, f64) {
        self.range
    }
    fn voxel_values(&self) -> Option<&Grid<R>> {
        Some(self.values())
    }
    fn sampled_grid(&self) -> Option<&Grid<R>> {
        Some(&self.grid)
    }
}

/// One brick of a larger grid, sampled at the larger grid's index coordinates: what a
/// rank of a distributed render holds (`jobs::distributed_render`). `inner` holds the
/// voxels of the box that starts at voxel `origin` of the whole grid (the brick and its
/// ghost voxels, [`brick_ghost`]); a point `p` is sampled as `inner` at `p − origin`.
///
/// That subtraction is exact for every point the filter and the gradient stencil reach
/// from the brick's own samples (`p ≥ origin` on each axis and `p < 2²³`: both are
/// multiples of `p`'s unit in the last place, and so is the difference, which is no
/// larger than `p`), so the taps, their weights and the sample are those of the whole
/// grid, bit for bit. Its dimensions and value range are the whole grid's; it offers
/// no voxel grid (no pre-classification or per-ray batches, which index a grid
/// directly), but its own grid and origin ([`Field::brick`]): empty-space skipping
/// walks its cells from there, and the packet kernel samples it at `p − origin` as it
/// does (`cpu::march::Source::origin`).
pub struct BrickField<R> {
    pub inner: GridField<R>,
    pub origin: [usize; 3],
    /// The whole grid's dimensions and value range.
    pub whole: [usize; 3],
    pub range: (f64, f64),
}

/// The ghost voxels a brick needs on each side for `filter`: its radius, one for the
/// gradient stencil's reach, and one so that every point it samples lies at or above
/// the box's first voxel (see [`BrickField`]; precomputed gradients, clamped at the
/// box's faces, are then right wherever the filter reads them).
pub fn brick_ghost(filter: crate::settings::Filter) -> usize {
    filter.radius().saturating_add(2)
}

impl<R: Real> BrickField<R> {
    #[inline(always)]
    fn local(&self, p: V3<R>) -> V3<R> {
        let o = self.origin;
        p - V3::new(R::of(o[0] as f64), R::of(o[1] as f64), R::of(o[2] as f64))
    }
}

impl<R: Real> Field<R> for BrickField<R> {
    fn dims(&self) -> [usize; 3] {
        self.whole
    }
    #[inline]
    fn value(&self, p: V3<R>) -> R {
        self.inner.value(self.local(p))
    }
    #[inline]
    fn gradient(&self, p: V3<R>) -> V3<R> {
        match &self.inner.gradients {
            Some(_) => self.inner.gradient(self.local(p)),
            // The stencil's points are taken in whole-grid coordinates, as the whole
            // grid's field takes them (`gradient_at`).
            None => gradient_stencil(|q| self.value(q), p, self.inner.method),
        }
    }
    fn value_range(&self) -> (f64, f64) {
        self.range
    }
    fn brick(&self) -> Option<(&Grid<R>, [usize; 3])> {
        Some((&self.inner.grid, self.origin))
    }
}

/// An analytic phantom seen through a virtual grid of `dims` (the grid
/// `Phantom::sample(dims)` would produce), sampled exactly at every point: no
/// reconstruction filter stands between the ray caster and the truth.
pub struct PhantomField<'a> {
    pub phantom: &'a Phantom,
    pub dims: [usize; 3],
    pub method: GradientMethod,
}

impl<R: Real> Field<R> for PhantomField<'_> {
    fn dims(&self) -> [usize; 3] {
        self.dims
    }
    fn value(&self, p: V3<R>) -> R {
        let q = [p.x().f64(), p.y().f64(), p.z().f64()];
        R::of(self.phantom.value_at(index_to_phantom(q, self.dims)))
    }
    fn gradient(&self, p: V3<R>) -> V3<R> {
        gradient_stencil(|q| <Self as Field<R>>::value(self, q), p, self.method)
    }
    fn value_range(&self) -> (f64, f64) {
        (0.0, 1.0)
    }
}
