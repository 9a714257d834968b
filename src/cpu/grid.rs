//! The voxel grid the CPU algorithms sample, and the running minimum and maximum of
//! its values (the field's value range, and the cells of empty-space skipping's
//! min/max grid, `cpu::skip`).
//!
//! A grid holds its values x fastest, in the working precision `R`; voxel `(i, j, k)`
//! is `data[i + nx·(j + ny·k)]` and has its centre at index coordinates `(i, j, k)`.
//! The reconstruction filters (`cpu::filter`, `cpu::tricubic`) sample it between
//! voxel centres.

use crate::real::Real;
use crate::volume::{AnyVolume, Volume, Voxel};
use rayon::prelude::*;

/// A voxel grid in the working precision: the data the CPU algorithms sample.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid<R> {
    pub dims: [usize; 3],
    pub data: Vec<R>,
}

impl<R: Real> Grid<R> {
    /// Copies a volume's values into precision `R` (exact for f64).
    pub fn from_volume<T: Voxel>(v: &Volume<T>) -> Self {
        Grid {
            dims: v.dims(),
            data: v.data().par_iter().map(|x| R::of(x.to_f64())).collect(),
        }
    }
    /// The voxel values of a volume of any voxel type.
    pub fn from_any(v: &AnyVolume) -> Self {
        match v {
            AnyVolume::U8(v) => Grid::from_volume(v),
            AnyVolume::U16(v) => Grid::from_volume(v),
            AnyVolume::I16(v) => Grid::from_volume(v),
            AnyVolume::F32(v) => Grid::from_volume(v),
        }
    }
    /// A grid of `f(i, j, k)`.
    pub fn from_fn(dims: [usize; 3], f: impl Fn(usize, usize, usize) -> R) -> Self {
        let mut data = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    data.push(f(i, j, k));
                }
            }
        }
        Grid { dims, data }
    }
    /// The voxels `lo .. hi` (per axis, within the grid) as a grid of their own.
    pub fn crop(&self, lo: [usize; 3], hi: [usize; 3]) -> Grid<R> {
        let [nx, ny, _] = self.dims;
        Grid::from_fn(std::array::from_fn(|a| hi[a] - lo[a]), |i, j, k| {
            self.data[(lo[0] + i) + nx * ((lo[1] + j) + ny * (lo[2] + k))]
        })
    }
    /// The value at voxel `(i, j, k)` with indices clamped to the grid.
    #[inline(always)]
    pub fn at_clamped(&self, i: isize, j: isize, k: isize) -> R {
        let c = |x: isize, n: usize| x.clamp(0, n as isize - 1) as usize;
        let (i, j, k) = (c(i, self.dims[0]), c(j, self.dims[1]), c(k, self.dims[2]));
        self.data[i + self.dims[0] * (j + self.dims[1] * k)]
    }
}

/// The smallest and largest value (±∞ for no values), in parallel chunks.
pub(crate) fn value_range<R: Real>(data: &[R]) -> (f64, f64) {
    let (lo, hi) = data.par_chunks(1 << 16).map(min_max).reduce(
        || (R::infinity(), R::neg_infinity()),
        |a, b| (a.0.min(b.0), a.1.max(b.1)),
    );
    (lo.f64(), hi.f64())
}

/// The smallest and largest of `values` (±∞ for none; NaNs are passed over).
pub(crate) fn min_max<R: Real>(values: &[R]) -> (R, R) {
    let mut m = MinMax::new();
    m.add(values);
    m.get()
}

/// A running minimum and maximum kept in sixteen lanes, so that the loop vectorises.
pub(crate) struct MinMax<R> {
    lo: [R; 16],
    hi: [R; 16],
}

impl<R: Real> MinMax<R> {
    pub(crate) fn new() -> Self {
        MinMax {
            lo: [R::infinity(); 16],
            hi: [R::neg_infinity(); 16],
        }
    }

    #[inline]
    #[allow(clippy::needless_range_loop)] // indexed lanes vectorise; zipped ones did not
    pub(crate) fn add(&mut self, values: &[R]) {
        let chunks = values.chunks_exact(16);
        let rest = chunks.remainder();
        for c in chunks {
            for i in 0..16 {
                self.lo[i] = if c[i] < self.lo[i] { c[i] } else { self.lo[i] };
                self.hi[i] = if c[i] > self.hi[i] { c[i] } else { self.hi[i] };
            }
        }
        for (i, &v) in rest.iter().enumerate() {
            self.lo[i] = if v < self.lo[i] { v } else { self.lo[i] };
            self.hi[i] = if v > self.hi[i] { v } else { self.hi[i] };
        }
    }

    pub(crate) fn get(&self) -> (R, R) {
        let lo = self.lo.iter().fold(R::infinity(), |m, &v| m.min(v));
        let hi = self.hi.iter().fold(R::neg_infinity(), |m, &v| m.max(v));
        (lo, hi)
    }
}
