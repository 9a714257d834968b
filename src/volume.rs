//! `Volume<T>`: a regular grid of voxels with its geometry.
//!
//! Conventions (see `docs/conventions.md`):
//! - memory order is x fastest: voxel `(i, j, k)` is `data[i + nx * (j + ny * k)]`;
//! - voxel `(i, j, k)`'s centre is at *index coordinates* `(i, j, k)`; the volume's
//!   box in index space is `[-0.5, n - 0.5]` on every axis (each voxel owns a cell);
//! - `affine` maps index coordinates to world coordinates in millimetres; its linear
//!   part's columns are the world vectors of one step along x, y and z, so their
//!   lengths are the spacing.

use crate::error::{Error, Result};
use glam::{DMat3, DMat4, DVec3};

/// The default largest number of voxels a volume may have (2^31, 8 GiB of f32),
/// refused before allocating so that a lying header cannot exhaust memory. The limit
/// in force is [`max_voxels`]; change it with [`set_max_voxels`] (the command line
/// reads `VOXLAB_MAX_VOXELS` and `--max-voxels`).
pub const MAX_VOXELS: usize = 1 << 31;

static MAX_VOXELS_NOW: std::sync::atomic::AtomicUsize =
    std::sync::atomic::AtomicUsize::new(MAX_VOXELS);

/// The voxel limit in force: every reader refuses a header that promises more voxels
/// (or samples) than this before allocating anything. [`MAX_VOXELS`] unless changed.
pub fn max_voxels() -> usize {
    MAX_VOXELS_NOW.load(std::sync::atomic::Ordering::Relaxed)
}

/// Sets the voxel limit for the whole process (at least 1).
pub fn set_max_voxels(n: usize) {
    MAX_VOXELS_NOW.store(n.max(1), std::sync::atomic::Ordering::Relaxed);
}

/// The scalar types a volume can hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum VoxelKind {
    U8,
    U16,
    I16,
    F32,
}

impl VoxelKind {
    /// Bytes per voxel.
    pub fn size(self) -> usize {
        match self {
            VoxelKind::U8 => 1,
            VoxelKind::U16 | VoxelKind::I16 => 2,
            VoxelKind::F32 => 4,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            VoxelKind::U8 => "u8",
            VoxelKind::U16 => "u16",
            VoxelKind::I16 => "i16",
            VoxelKind::F32 => "f32",
        }
    }
}

/// A voxel type: u8, u16, i16 or f32.
pub trait Voxel: bytemuck::Pod + Default + PartialOrd + Send + Sync + std::fmt::Debug {
    const KIND: VoxelKind;
    /// The voxel's value as f64 (exact for every supported type).
    fn to_f64(self) -> f64;
    /// Rounds and saturates an f64 into this type (NaN becomes 0 for integers).
    fn from_f64(x: f64) -> Self;
}

macro_rules! int_voxel {
    ($t:ty, $kind:ident) => {
        impl Voxel for $t {
            const KIND: VoxelKind = VoxelKind::$kind;
            #[inline(always)]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline(always)]
            fn from_f64(x: f64) -> Self {
                // `as` saturates and maps NaN to 0.
                x.round() as $t
            }
        }
    };
}
int_voxel!(u8, U8);
int_voxel!(u16, U16);
int_voxel!(i16, I16);

impl Voxel for f32 {
    const KIND: VoxelKind = VoxelKind::F32;
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn from_f64(x: f64) -> Self {
        x as f32
    }
}

/// Checks dimensions: every axis at least 1 and the product at most [`max_voxels`].
pub fn check_dims(dims: [usize; 3]) -> Result<usize> {
    if dims.contains(&0) {
        return Err(Error::invalid(
            "volume dimensions",
            format!("{dims:?} has an empty axis"),
        ));
    }
    let n = dims
        .iter()
        .try_fold(1usize, |acc, &d| acc.checked_mul(d))
        .filter(|&n| n <= max_voxels())
        .ok_or_else(|| {
            Error::too_large(
                "volume",
                format!("{dims:?} exceeds the limit of {} voxels", max_voxels()),
            )
        })?;
    Ok(n)
}

/// Checks a spacing: finite and strictly positive on every axis.
pub fn check_spacing(spacing: [f64; 3]) -> Result<()> {
    if spacing
        .iter()
        .all(|s| (MIN_SPACING_MM..=MAX_SPACING_MM).contains(s))
    {
        Ok(())
    } else {
        Err(Error::invalid(
            "voxel spacing",
            format!(
                "{spacing:?} must lie in [{MIN_SPACING_MM:e}, {MAX_SPACING_MM:e}] mm on every axis"
            ),
        ))
    }
}

/// The diagonal of the box of `dims` voxels, in voxels: the longest chord a ray can
/// cross, so a ray of step `s` voxels takes at most `diagonal / s` samples.
pub fn diagonal(dims: [usize; 3]) -> f64 {
    dims.iter().map(|&n| (n as f64).powi(2)).sum::<f64>().sqrt()
}

/// The eight corners of the box of `dims` voxels (index −½ … n − ½ on each axis)
/// placed by `affine`, in world coordinates.
pub fn box_corners(dims: [usize; 3], affine: glam::DMat4) -> [glam::DVec3; 8] {
    std::array::from_fn(|c| {
        let at = |axis: usize| {
            if c >> axis & 1 == 0 {
                -0.5
            } else {
                dims[axis] as f64 - 0.5
            }
        };
        affine.transform_point3(glam::DVec3::new(at(0), at(1), at(2)))
    })
}

/// The finest voxel spacing accepted, in mm (a picometre: below it, and for denormal
/// numbers, the voxel-to-world affine cannot be inverted reliably).
pub const MIN_SPACING_MM: f64 = 1e-9;
/// The coarsest voxel spacing accepted, in mm (a thousand kilometres).
pub const MAX_SPACING_MM: f64 = 1e9;

/// Voxels a volume reads without owning them: a buffer another owner keeps alive (a
/// NumPy array the Python package borrows, a memory map). The slice must not change
/// while any volume holds it.
pub trait SharedVoxels<T>: Send + Sync {
    /// The voxels, x fastest.
    fn voxels(&self) -> &[T];
}

impl<T: Send + Sync> SharedVoxels<T> for Vec<T> {
    fn voxels(&self) -> &[T] {
        self
    }
}

/// Where a volume's voxels live: in its own `Vec`, or in a shared buffer (cloning the
/// volume then shares it too; writing through [`Volume::data_mut`] copies it first).
#[derive(Clone)]
enum Voxels<T> {
    Owned(Vec<T>),
    Shared(std::sync::Arc<dyn SharedVoxels<T>>),
}

impl<T> Voxels<T> {
    fn as_slice(&self) -> &[T] {
        match self {
            Voxels::Owned(v) => v,
            Voxels::Shared(s) => s.voxels(),
        }
    }
}

impl<T> Default for Voxels<T> {
    fn default() -> Self {
        Voxels::Owned(Vec::new())
    }
}

/// A regular grid of voxels, x fastest, with spacing and a voxel-to-world affine.
///
/// The voxels are the volume's own (`Vec`), or borrowed without a copy from a buffer
/// that outlives it ([`Volume::shared`]).
#[derive(Clone)]
pub struct Volume<T> {
    dims: [usize; 3],
    affine: DMat4,
    data: Voxels<T>,
}

impl<T: std::fmt::Debug> std::fmt::Debug for Volume<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Volume")
            .field("dims", &self.dims)
            .field("affine", &self.affine)
            .field(
                "data",
                &match &self.data {
                    Voxels::Owned(_) => "owned",
                    Voxels::Shared(_) => "shared",
                },
            )
            .finish()
    }
}

impl<T: PartialEq> PartialEq for Volume<T> {
    fn eq(&self, other: &Self) -> bool {
        self.dims == other.dims
            && self.affine == other.affine
            && self.data.as_slice() == other.data.as_slice()
    }
}

/// Checks a voxel-to-world affine: finite, invertible, last row `(0, 0, 0, 1)`.
fn check_affine(affine: DMat4) -> Result<()> {
    let lin = DMat3::from_mat4(affine);
    let det = lin.determinant();
    if !affine.is_finite() || det.abs() < 1e-300 || !det.is_finite() {
        return Err(Error::invalid(
            "voxel-to-world affine",
            "must be finite and invertible",
        ));
    }
    if affine.row(3) != glam::DVec4::new(0.0, 0.0, 0.0, 1.0) {
        return Err(Error::invalid(
            "voxel-to-world affine",
            "last row must be (0, 0, 0, 1)",
        ));
    }
    Ok(())
}

/// Checks that `len` values fill `dims`.
fn check_len(dims: [usize; 3], len: usize) -> Result<()> {
    let n = check_dims(dims)?;
    if len != n {
        return Err(Error::invalid(
            "volume data",
            format!("{len} values for dimensions {dims:?} (expected {n})"),
        ));
    }
    Ok(())
}

impl<T: Voxel> Volume<T> {
    /// A volume with the given spacing (mm) whose voxel (0,0,0) sits at the world origin
    /// and whose axes are the world axes.
    pub fn new(dims: [usize; 3], spacing: [f64; 3], data: Vec<T>) -> Result<Self> {
        check_spacing(spacing)?;
        let affine = DMat4::from_scale(DVec3::from_array(spacing));
        Self::with_affine(dims, affine, data)
    }

    /// A volume with an explicit voxel-to-world affine.
    pub fn with_affine(dims: [usize; 3], affine: DMat4, data: Vec<T>) -> Result<Self> {
        check_len(dims, data.len())?;
        check_affine(affine)?;
        Ok(Volume {
            dims,
            affine,
            data: Voxels::Owned(data),
        })
    }

    /// A volume that reads its voxels from `data` without copying them (the same
    /// checks as [`Volume::with_affine`]). Clones share the buffer; the first write
    /// through [`Volume::data_mut`] copies it into the volume's own `Vec`.
    pub fn shared(
        dims: [usize; 3],
        affine: DMat4,
        data: std::sync::Arc<dyn SharedVoxels<T>>,
    ) -> Result<Self> {
        check_len(dims, data.voxels().len())?;
        check_affine(affine)?;
        Ok(Volume {
            dims,
            affine,
            data: Voxels::Shared(data),
        })
    }

    /// A volume of `dims` filled with `value`.
    pub fn filled(dims: [usize; 3], spacing: [f64; 3], value: T) -> Result<Self> {
        let n = check_dims(dims)?;
        Self::new(dims, spacing, vec![value; n])
    }

    /// Samples `f(i, j, k)` at every voxel index (in parallel over z-slices).
    pub fn from_fn(
        dims: [usize; 3],
        spacing: [f64; 3],
        f: impl Fn(usize, usize, usize) -> T + Sync,
    ) -> Result<Self> {
        use rayon::prelude::*;
        let n = check_dims(dims)?;
        let mut data = vec![T::default(); n];
        let slice = dims[0] * dims[1];
        data.par_chunks_mut(slice).enumerate().for_each(|(k, s)| {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    s[i + dims[0] * j] = f(i, j, k);
                }
            }
        });
        Self::new(dims, spacing, data)
    }
}

impl<T> Volume<T> {
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }
    pub fn data(&self) -> &[T] {
        self.data.as_slice()
    }
    /// The voxels to write: a volume that shares its buffer copies it first.
    pub fn data_mut(&mut self) -> &mut [T]
    where
        T: Clone,
    {
        if let Voxels::Shared(s) = &self.data {
            self.data = Voxels::Owned(s.voxels().to_vec());
        }
        match &mut self.data {
            Voxels::Owned(v) => v,
            Voxels::Shared(_) => unreachable!("copied just above"),
        }
    }
    /// The voxels as a `Vec` (a copy when the volume shares its buffer).
    pub fn into_data(self) -> Vec<T>
    where
        T: Clone,
    {
        match self.data {
            Voxels::Owned(v) => v,
            Voxels::Shared(s) => s.voxels().to_vec(),
        }
    }
    /// Whether the voxels are borrowed from a shared buffer ([`Volume::shared`]).
    pub fn is_shared(&self) -> bool {
        matches!(self.data, Voxels::Shared(_))
    }
    /// The same voxels behind a shared buffer (no copy: the volume's own `Vec` becomes
    /// the buffer), so that clones share them: for a volume many renders read (the
    /// lab's).
    pub fn into_shared(self) -> Self
    where
        T: Send + Sync + 'static,
    {
        match self.data {
            Voxels::Owned(v) => Volume {
                dims: self.dims,
                affine: self.affine,
                data: Voxels::Shared(std::sync::Arc::new(v)),
            },
            Voxels::Shared(_) => self,
        }
    }
    /// The same volume holding its own voxels (a copy of a shared buffer): for what
    /// outlives the call that lent the buffer (a render session).
    pub fn into_owned(self) -> Self
    where
        T: Clone,
    {
        match self.data {
            Voxels::Owned(_) => self,
            Voxels::Shared(s) => Volume {
                dims: self.dims,
                affine: self.affine,
                data: Voxels::Owned(s.voxels().to_vec()),
            },
        }
    }
    pub fn len(&self) -> usize {
        self.data().len()
    }
    pub fn is_empty(&self) -> bool {
        self.data().is_empty()
    }
    /// The index-to-world affine.
    pub fn affine(&self) -> DMat4 {
        self.affine
    }
    /// Replaces the affine (it must be finite and invertible).
    pub fn set_affine(&mut self, affine: DMat4) -> Result<()> {
        check_affine(affine)?;
        self.affine = affine;
        Ok(())
    }
    /// Spacing in mm: the lengths of the affine's columns.
    pub fn spacing(&self) -> [f64; 3] {
        let m = DMat3::from_mat4(self.affine);
        [m.x_axis.length(), m.y_axis.length(), m.z_axis.length()]
    }
    /// World position of the volume's centre (index `(n - 1) / 2`).
    pub fn center_world(&self) -> DVec3 {
        let c = DVec3::new(
            (self.dims[0] as f64 - 1.0) * 0.5,
            (self.dims[1] as f64 - 1.0) * 0.5,
            (self.dims[2] as f64 - 1.0) * 0.5,
        );
        self.affine.transform_point3(c)
    }
    /// World-space extent of the volume's box (`n * spacing` per axis).
    pub fn extent_world(&self) -> [f64; 3] {
        let s = self.spacing();
        [
            s[0] * self.dims[0] as f64,
            s[1] * self.dims[1] as f64,
            s[2] * self.dims[2] as f64,
        ]
    }
    /// Moves the origin so that the volume's centre is at the world origin.
    pub fn centered(mut self) -> Self {
        let c = self.center_world();
        self.affine.w_axis -= c.extend(0.0);
        self
    }
    /// Linear index of voxel (i, j, k).
    #[inline(always)]
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }
    #[inline(always)]
    pub fn get(&self, i: usize, j: usize, k: usize) -> &T {
        &self.data()[self.index(i, j, k)]
    }
}

/// Minimum and maximum of a set of values, with a count of the non-finite ones.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ValueRange {
    pub min: f64,
    pub max: f64,
    /// How many values were NaN or infinite (left out of min and max).
    pub non_finite: usize,
}

/// How many voxels are NaN, +∞ or −∞, and the first of them (x-fastest index).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct NonFiniteCount {
    pub nan: usize,
    pub pos_inf: usize,
    pub neg_inf: usize,
    pub first: Option<usize>,
}

impl NonFiniteCount {
    /// All non-finite voxels.
    pub fn total(&self) -> usize {
        self.nan + self.pos_inf + self.neg_inf
    }
}

/// A histogram of voxel values over `[min, max]` with equal-width bins; the maximum
/// falls in the last bin.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Histogram {
    pub min: f64,
    pub max: f64,
    pub counts: Vec<u64>,
}

/// Bar heights in [0, 1] for drawing `counts` on a logarithmic axis, `ln(1 + c)` over
/// the largest (all 0 for an empty histogram): what `voxlab info --plot` and the lab's
/// editors draw, so that long tails stay visible beside the background's peak.
pub fn log_heights(counts: &[u64]) -> Vec<f64> {
    let top = counts
        .iter()
        .map(|&c| (1.0 + c as f64).ln())
        .fold(0.0, f64::max);
    counts
        .iter()
        .map(|&c| {
            if top > 0.0 {
                (1.0 + c as f64).ln() / top
            } else {
                0.0
            }
        })
        .collect()
}

impl Histogram {
    /// Draws a histogram as an RGBA frame of `width` × `height` pixels: one bar per bin,
    /// heights on a logarithmic count axis (log(1 + count), so that the long tails of CT
    /// and MR histograms stay visible beside the background's peak), light bars on a dark
    /// background, with a baseline. The value axis runs from the histogram's minimum at
    /// the left to its maximum at the right; `voxlab info` prints the numbers beside it.
    pub fn plot(&self, width: usize, height: usize) -> Result<crate::frame::Frame> {
        let h = self;
        if width < 16 || height < 16 || width > 8192 || height > 8192 {
            return Err(Error::invalid(
                "histogram plot size",
                format!("{width}×{height} must be between 16 and 8192 pixels per side"),
            ));
        }
        let mut f = crate::frame::Frame::new(width, height, 4);
        let set = |f: &mut crate::frame::Frame, col: usize, row: usize, rgb: [f64; 3]| {
            let i = (row * width + col) * 4;
            f.data[i..i + 4].copy_from_slice(&[rgb[0], rgb[1], rgb[2], 1.0]);
        };
        for row in 0..height {
            for col in 0..width {
                set(&mut f, col, row, [0.08, 0.08, 0.1]);
            }
        }
        let (margin, base) = (8, height - 8);
        let plot_w = width - 2 * margin;
        let plot_h = base - margin;
        let heights = log_heights(&h.counts);
        let bins = h.counts.len().max(1);
        for col in 0..plot_w {
            let b = (col * bins / plot_w).min(bins - 1);
            let frac = heights.get(b).copied().unwrap_or(0.0);
            let bar = (frac * plot_h as f64).round() as usize;
            for r in 0..bar.min(plot_h) {
                set(&mut f, margin + col, base - 1 - r, [0.55, 0.75, 0.95]);
            }
        }
        for col in margin..width - margin {
            set(&mut f, col, base, [0.9, 0.9, 0.9]);
        }
        Ok(f)
    }

    /// Value at the centre of bin `b`.
    pub fn bin_center(&self, b: usize) -> f64 {
        let w = (self.max - self.min) / self.counts.len() as f64;
        self.min + (b as f64 + 0.5) * w
    }
}

impl<T: Voxel> Volume<T> {
    /// Minimum and maximum over the finite values.
    pub fn value_range(&self) -> ValueRange {
        use rayon::prelude::*;
        let (min, max, bad) = self
            .data()
            .par_chunks(1 << 16)
            .map(|c| {
                let mut r = (f64::INFINITY, f64::NEG_INFINITY, 0usize);
                for v in c {
                    let x = v.to_f64();
                    if x.is_finite() {
                        r.0 = r.0.min(x);
                        r.1 = r.1.max(x);
                    } else {
                        r.2 += 1;
                    }
                }
                r
            })
            .reduce(
                || (f64::INFINITY, f64::NEG_INFINITY, 0),
                |a, b| (a.0.min(b.0), a.1.max(b.1), a.2 + b.2),
            );
        ValueRange {
            min,
            max,
            non_finite: bad,
        }
    }

    /// Fails with [`Error::NonFinite`] if any voxel is NaN or infinite.
    pub fn check_finite(&self, what: &str) -> Result<()> {
        if T::KIND != VoxelKind::F32 || self.all_finite() {
            return Ok(());
        }
        let mut first = None;
        let mut count = 0;
        for (i, v) in self.data().iter().enumerate() {
            if !v.to_f64().is_finite() {
                count += 1;
                first.get_or_insert(i);
            }
        }
        match first {
            None => Ok(()),
            Some(first) => Err(Error::NonFinite {
                what: what.to_string(),
                count,
                first,
            }),
        }
    }

    /// Whether every voxel is finite: a parallel pass that only answers yes or no (the
    /// counting passes run only when it says no).
    fn all_finite(&self) -> bool {
        use rayon::prelude::*;
        self.data()
            .par_chunks(1 << 16)
            .all(|c| c.iter().fold(true, |ok, v| ok & v.to_f64().is_finite()))
    }

    /// Counts the NaN, +∞ and −∞ voxels (always zero for integer volumes).
    pub fn non_finite(&self) -> NonFiniteCount {
        let mut c = NonFiniteCount::default();
        if T::KIND != VoxelKind::F32 || self.all_finite() {
            return c;
        }
        for (i, v) in self.data().iter().enumerate() {
            let x = v.to_f64();
            if x.is_finite() {
                continue;
            }
            if x.is_nan() {
                c.nan += 1;
            } else if x > 0.0 {
                c.pos_inf += 1;
            } else {
                c.neg_inf += 1;
            }
            c.first.get_or_insert(i);
        }
        c
    }

    /// Applies voxlab's rule for non-finite data before rendering (`docs/io.md`):
    /// NaN and −∞ become the smallest finite value, +∞ the largest (0 when no value is
    /// finite). NaN marks missing data in most tools, and the minimum is what empty
    /// space holds in CT and MR, so missing voxels render as background: transparent
    /// under a transfer function that starts at the minimum, never the maximum of a
    /// MIP, and no contribution beyond the background's in an X-ray. Returns what was
    /// replaced.
    pub fn replace_non_finite(&mut self) -> NonFiniteCount {
        let count = self.non_finite();
        if count.total() == 0 {
            return count;
        }
        let r = self.value_range();
        let (lo, hi) = if r.min <= r.max {
            (r.min, r.max)
        } else {
            (0.0, 0.0)
        };
        for v in self.data_mut() {
            let x = v.to_f64();
            if !x.is_finite() {
                *v = T::from_f64(if x == f64::INFINITY { hi } else { lo });
            }
        }
        count
    }

    /// Histogram of the finite values in `bins` equal bins over the value range.
    pub fn histogram(&self, bins: usize) -> Histogram {
        let bins = bins.max(1);
        let r = self.value_range();
        let (min, max) = if r.min <= r.max {
            (r.min, r.max)
        } else {
            (0.0, 0.0)
        };
        let mut counts = vec![0u64; bins];
        let width = max - min;
        for v in self.data() {
            let x = v.to_f64();
            if !x.is_finite() {
                continue;
            }
            let b = if width > 0.0 {
                (((x - min) / width) * bins as f64) as usize
            } else {
                0
            };
            counts[b.min(bins - 1)] += 1;
        }
        Histogram { min, max, counts }
    }

    /// Keeps the voxels `lo..hi` (end exclusive) on each axis. Every kept voxel stays
    /// where it was in the world: the affine is moved by `lo` index steps.
    pub fn crop(&self, lo: [usize; 3], hi: [usize; 3]) -> Result<Volume<T>> {
        for a in 0..3 {
            if lo[a] >= hi[a] || hi[a] > self.dims[a] {
                return Err(Error::invalid(
                    "crop box",
                    format!(
                        "{lo:?}..{hi:?} must satisfy lo < hi ≤ dims {:?} on every axis",
                        self.dims
                    ),
                ));
            }
        }
        let dims = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        let mut data = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
        for k in lo[2]..hi[2] {
            for j in lo[1]..hi[1] {
                let row = self.index(lo[0], j, k);
                data.extend_from_slice(&self.data()[row..row + dims[0]]);
            }
        }
        let shift = DVec3::new(lo[0] as f64, lo[1] as f64, lo[2] as f64);
        Volume::with_affine(dims, self.affine * DMat4::from_translation(shift), data)
    }

    /// Converts every voxel to another type (rounding and saturating into integers).
    pub fn convert<U: Voxel>(&self) -> Volume<U> {
        Volume {
            dims: self.dims,
            affine: self.affine,
            data: Voxels::Owned(
                self.data()
                    .iter()
                    .map(|v| U::from_f64(v.to_f64()))
                    .collect(),
            ),
        }
    }
}

/// A volume of any supported voxel type, as read from a file.
#[derive(Clone, Debug, PartialEq)]
pub enum AnyVolume {
    U8(Volume<u8>),
    U16(Volume<u16>),
    I16(Volume<i16>),
    F32(Volume<f32>),
}

/// Applies an expression to the typed volume inside an [`AnyVolume`].
#[macro_export]
macro_rules! with_volume {
    ($any:expr, $v:ident => $body:expr) => {
        match $any {
            $crate::volume::AnyVolume::U8($v) => $body,
            $crate::volume::AnyVolume::U16($v) => $body,
            $crate::volume::AnyVolume::I16($v) => $body,
            $crate::volume::AnyVolume::F32($v) => $body,
        }
    };
}

impl AnyVolume {
    pub fn kind(&self) -> VoxelKind {
        with_volume!(self, v => voxel_kind_of(v))
    }
    pub fn dims(&self) -> [usize; 3] {
        with_volume!(self, v => v.dims())
    }
    pub fn spacing(&self) -> [f64; 3] {
        with_volume!(self, v => v.spacing())
    }
    pub fn affine(&self) -> DMat4 {
        with_volume!(self, v => v.affine())
    }
    pub fn value_range(&self) -> ValueRange {
        with_volume!(self, v => v.value_range())
    }
    pub fn histogram(&self, bins: usize) -> Histogram {
        with_volume!(self, v => v.histogram(bins))
    }
    pub fn check_finite(&self, what: &str) -> Result<()> {
        with_volume!(self, v => v.check_finite(what))
    }
    /// Counts the NaN and infinite voxels.
    pub fn non_finite(&self) -> NonFiniteCount {
        with_volume!(self, v => v.non_finite())
    }
    /// Replaces non-finite voxels by voxlab's rule ([`Volume::replace_non_finite`]).
    pub fn replace_non_finite(&mut self) -> NonFiniteCount {
        with_volume!(self, v => v.replace_non_finite())
    }
    /// Keeps the voxels `lo..hi` (end exclusive) on each axis; see [`Volume::crop`].
    pub fn crop(&self, lo: [usize; 3], hi: [usize; 3]) -> Result<AnyVolume> {
        Ok(with_volume!(self, v => v.crop(lo, hi)?.into()))
    }
    /// An axis-aligned slice as a scalar frame, laid out as NumPy lays out the slice of
    /// the `(nz, ny, nx)` array: `axis` 2 (z) at `index` k is `a[k, :, :]` (rows y,
    /// columns x), axis 1 (y) is `a[:, j, :]` (rows z, columns x), axis 0 (x) is
    /// `a[:, :, i]` (rows z, columns y). Row 0 is the top of the image.
    pub fn slice(&self, axis: usize, index: usize) -> Result<crate::frame::Frame> {
        let d = self.dims();
        if axis > 2 || index >= d[axis] {
            return Err(Error::invalid(
                "slice",
                format!(
                    "index {index} on axis {} is outside the volume's {} voxels",
                    ["x", "y", "z"][axis.min(2)],
                    d[axis.min(2)]
                ),
            ));
        }
        let vals = self.values_f64();
        let at = |i: usize, j: usize, k: usize| vals[i + d[0] * (j + d[1] * k)];
        let (w, h) = match axis {
            2 => (d[0], d[1]),
            1 => (d[0], d[2]),
            _ => (d[1], d[2]),
        };
        let mut f = crate::frame::Frame::new(w, h, 1);
        for row in 0..h {
            for col in 0..w {
                f.data[row * w + col] = match axis {
                    2 => at(col, row, index),
                    1 => at(col, index, row),
                    _ => at(index, col, row),
                };
            }
        }
        Ok(f)
    }
    /// Converts to another voxel type (rounding and saturating into integer types).
    pub fn convert_to(&self, kind: VoxelKind) -> AnyVolume {
        with_volume!(self, v => match kind {
            VoxelKind::U8 => v.convert::<u8>().into(),
            VoxelKind::U16 => v.convert::<u16>().into(),
            VoxelKind::I16 => v.convert::<i16>().into(),
            VoxelKind::F32 => v.convert::<f32>().into(),
        })
    }
    /// The voxel values as f64, x fastest.
    pub fn values_f64(&self) -> Vec<f64> {
        with_volume!(self, v => v.data().iter().map(|x| x.to_f64()).collect())
    }
    /// The same voxels behind a shared buffer ([`Volume::into_shared`]): clones share
    /// them.
    pub fn into_shared(self) -> AnyVolume {
        with_volume!(self, v => v.into_shared().into())
    }
    /// The same volume holding its own voxels ([`Volume::into_owned`]).
    pub fn into_owned(self) -> AnyVolume {
        with_volume!(self, v => v.into_owned().into())
    }
    /// Converts to an f32 volume (exact for u8, u16 and i16).
    pub fn to_f32(&self) -> Volume<f32> {
        match self {
            // The same voxels: a clone, which shares a shared buffer instead of copying.
            AnyVolume::F32(v) => v.clone(),
            other => with_volume!(other, v => v.convert::<f32>()),
        }
    }
}

fn voxel_kind_of<T: Voxel>(_: &Volume<T>) -> VoxelKind {
    T::KIND
}

macro_rules! any_from {
    ($t:ty, $kind:ident) => {
        impl From<Volume<$t>> for AnyVolume {
            fn from(v: Volume<$t>) -> Self {
                AnyVolume::$kind(v)
            }
        }
    };
}
any_from!(u8, U8);
any_from!(u16, U16);
any_from!(i16, I16);
any_from!(f32, F32);

#[cfg(test)]
mod tests {

    #[test]
    fn crop_keeps_world_positions() {
        let v = Volume::from_fn([4, 3, 2], [0.5, 1.0, 2.0], |i, j, k| {
            (i + 10 * j + 100 * k) as f32
        })
        .unwrap();
        let c = v.crop([1, 1, 1], [3, 3, 2]).unwrap();
        assert_eq!(c.dims(), [2, 2, 1]);
        assert_eq!(c.data(), &[111.0, 112.0, 121.0, 122.0]);
        let w_old = v.affine().transform_point3(DVec3::new(1.0, 1.0, 1.0));
        let w_new = c.affine().transform_point3(DVec3::ZERO);
        assert_eq!(w_old, w_new);
        assert!(v.crop([0, 0, 0], [5, 1, 1]).is_err());
        assert!(v.crop([2, 0, 0], [2, 1, 1]).is_err());
    }

    #[test]
    fn non_finite_rule_replaces_by_the_finite_range() {
        let data = vec![f32::NAN, 2.0, f32::INFINITY, -3.0, f32::NEG_INFINITY, 5.0];
        let mut v = Volume::new([6, 1, 1], [1.0; 3], data).unwrap();
        let c = v.non_finite();
        assert_eq!((c.nan, c.pos_inf, c.neg_inf, c.first), (1, 1, 1, Some(0)));
        let replaced = v.replace_non_finite();
        assert_eq!(replaced, c);
        assert_eq!(v.data(), &[-3.0, 2.0, 5.0, -3.0, -3.0, 5.0]);
        assert_eq!(v.non_finite().total(), 0);
        let mut all_nan = Volume::new([2, 1, 1], [1.0; 3], vec![f32::NAN; 2]).unwrap();
        all_nan.replace_non_finite();
        assert_eq!(all_nan.data(), &[0.0, 0.0]);
    }

    use super::*;

    #[test]
    fn layout_is_x_fastest() {
        let v =
            Volume::from_fn([3, 4, 5], [1.0; 3], |i, j, k| (i + 10 * j + 100 * k) as f32).unwrap();
        assert_eq!(v.data()[1], 1.0);
        assert_eq!(v.data()[3], 10.0);
        assert_eq!(v.data()[12], 100.0);
        assert_eq!(*v.get(2, 3, 4), 432.0);
    }

    #[test]
    fn a_shared_volume_reads_its_buffer_and_copies_only_on_write() {
        let buffer: std::sync::Arc<Vec<u16>> = std::sync::Arc::new((0..24).collect());
        let shared: std::sync::Arc<dyn SharedVoxels<u16>> = buffer.clone();
        let v = Volume::shared([2, 3, 4], DMat4::IDENTITY, shared).unwrap();
        assert!(v.is_shared());
        assert_eq!(v.data().as_ptr(), buffer.as_ptr(), "no copy");
        assert_eq!(*v.get(1, 2, 3), 23);
        let c = v.clone();
        assert!(c.is_shared() && c.data().as_ptr() == buffer.as_ptr());
        let owned = Volume::with_affine([2, 3, 4], DMat4::IDENTITY, (0..24).collect()).unwrap();
        assert_eq!(v, owned);
        // A write copies first: the buffer is never changed.
        let mut w = v.clone();
        w.data_mut()[0] = 99;
        assert!(!w.is_shared());
        assert_eq!(buffer[0], 0);
        assert_eq!(v.data()[0], 0);
        assert_eq!(v.clone().into_data(), *buffer);
        let own = v.clone().into_owned();
        assert!(!own.is_shared() && own.data().as_ptr() != buffer.as_ptr() && own == v);
        // An owned volume turned shared keeps its voxels where they are.
        let at = own.data().as_ptr();
        let s = own.into_shared();
        assert!(s.is_shared() && s.data().as_ptr() == at && s.clone().data().as_ptr() == at);
        // The same checks as an owned volume.
        let short: std::sync::Arc<dyn SharedVoxels<u16>> = std::sync::Arc::new(vec![0u16; 5]);
        assert!(Volume::shared([2, 3, 4], DMat4::IDENTITY, short).is_err());
    }

    #[test]
    fn refuses_absurd_sizes_before_allocating() {
        let e = check_dims([1 << 20, 1 << 20, 1 << 20]).unwrap_err();
        assert!(matches!(e, Error::TooLarge { .. }));
        assert!(check_dims([usize::MAX, 2, 2]).is_err());
        assert!(check_dims([0, 2, 2]).is_err());
    }

    #[test]
    fn range_and_histogram() {
        let v = Volume::new([4, 1, 1], [1.0; 3], vec![0u8, 1, 2, 3]).unwrap();
        let r = v.value_range();
        assert_eq!((r.min, r.max), (0.0, 3.0));
        let h = v.histogram(2);
        assert_eq!(h.counts, vec![2, 2]);
        let f = Volume::new([3, 1, 1], [1.0; 3], vec![1.0f32, f32::NAN, -2.0]).unwrap();
        let r = f.value_range();
        assert_eq!((r.min, r.max, r.non_finite), (-2.0, 1.0, 1));
        assert!(f.check_finite("test").is_err());
    }

    #[test]
    fn centre_and_spacing() {
        let v = Volume::filled([5, 3, 2], [2.0, 1.0, 0.5], 0u8)
            .unwrap()
            .centered();
        assert_eq!(v.spacing(), [2.0, 1.0, 0.5]);
        assert!(v.center_world().length() < 1e-12);
        assert_eq!(v.extent_world(), [10.0, 3.0, 1.0]);
    }
}
