//! Volume processing: resampling, Gaussian smoothing, median filtering and the
//! gradient-magnitude field — the CPU oracle, generic over `R: Real`.
//!
//! Every operation maps a volume to a [`Field<R>`]: a grid of values in precision `R`
//! and the voxel-to-world affine of that grid. The f64 instance is the oracle; each
//! output voxel is computed independently (rayon over z-slices), so the result never
//! depends on the thread count. The GPU port is `crate::gpu::process`, with the
//! per-voxel helpers mirrored in `shaders/process_*.wgsl`. See `docs/processing.md`.
//!
//! **Resampling** ([`resample`]). A box of the input — in index space (cell edges:
//! the whole volume is `[−½, n − ½]` per axis) or in world space (axis-aligned mm) —
//! is tiled by `dims` output cells, and output voxel `i` samples the cell centre
//! `lo + (i + ½)(hi − lo)/dims` with any [`Filter`] of `cpu::filter` (the ray caster's
//! reconstruction filters, clamp-to-edge beyond the volume). The output affine puts
//! each output voxel centre at the world position it sampled, so the resampled volume
//! occupies the same world box. An index box keeps the input's axes (the output affine
//! is the input affine times the index map); a world box gives an output aligned with
//! the world axes (`world = lo + (i + ½)·(hi − lo)/dims`), sampled at
//! `affine⁻¹ · world`.
//!
//! **Gaussian** ([`gaussian`]). Separable: `g[n] = Σ_{t=−r}^{r} w[t] f[n + t]` along x,
//! then y, then z, with `w[t] = exp(−t²/2σ²) / Σ_s exp(−s²/2σ²)` and the radius
//! `r = ⌊4σ + ½⌋` — `scipy.ndimage.gaussian_filter(f, σ, mode='reflect', truncate=4.0)`,
//! σ per axis in voxels. Boundary rule `reflect` (scipy's default): the line is
//! mirrored about its end edges, `d c b a | a b c d | d c b a` ([`reflect_index`]).
//!
//! **Median** ([`median`]). The median of the `k³` values in the cubic window centred on
//! each voxel (`k` odd), the same `reflect` rule:
//! `scipy.ndimage.median_filter(f, size=k, mode='reflect')`.
//!
//! **Gradient magnitude** ([`gradient_magnitude`]). Central differences at the voxel
//! centres, `∂f/∂i ≈ (f[i+1] − f[i−1])/2` per index axis — `cpu::gradient`'s
//! precomputed central gradient, reused — turned into world units (per mm) by the
//! inverse transpose of the affine's linear part `L`: `∇_w f = L⁻ᵀ ∇_i f`, and
//! `|∇_w f|` stored. Border rule: `cpu::gradient` clamps the neighbour index, which for a
//! one-voxel stencil is the same as `reflect` (index −1 reads voxel 0), so the border
//! voxels hold half the one-sided difference. For an axis-aligned volume this is
//! `sqrt(Σ_a (correlate1d(f, [−½, 0, ½], axis=a, mode='reflect') / s_a)²)` in scipy.
//!
//! ```
//! use voxlab::cpu::process::{gaussian, median, resample, Region, ResampleSpec};
//! use voxlab::settings::Filter;
//! let vol = voxlab::phantom::Phantom::shepp_logan().sample([16, 16, 16])?;
//! let smooth = gaussian::<f64, f32>(&vol, [1.0, 1.0, 2.0])?; // σ in voxels
//! let denoised = median::<f64, f32>(&vol, 3)?;
//! let fine = resample::<f64, f32>(
//!     &vol,
//!     &ResampleSpec { region: Region::Whole, dims: [32, 32, 32], filter: Filter::CatmullRom },
//! )?;
//! assert_eq!(fine.grid.dims, [32, 32, 32]);
//! let written: voxlab::Volume<f32> = smooth.to_volume()?; // with the same affine
//! # let _ = (denoised, written);
//! # Ok::<(), voxlab::Error>(())
//! ```

use super::filter::{prepare, sample};
use super::gradient::precompute_gradients;
use super::grid::Grid;
use crate::error::{Error, Result};
use crate::real::{Real, V3};
use crate::settings::{Filter, GradientMethod};
use crate::volume::{check_dims, Volume, Voxel};
use glam::{DMat3, DMat4, DVec3};
use rayon::prelude::*;

/// The largest median window side on the CPU (`k³ = 29 791` values per voxel).
pub const MAX_MEDIAN_SIZE_CPU: usize = 31;

/// The largest σ in voxels (a radius of 4 000 voxels).
pub const MAX_SIGMA: f64 = 1000.0;

/// A processed volume: values in precision `R` and the voxel-to-world affine.
#[derive(Clone, Debug, PartialEq)]
pub struct Field<R> {
    pub grid: Grid<R>,
    pub affine: DMat4,
}

impl<R: Real> Field<R> {
    /// The field as an f32 volume (values rounded to f32).
    pub fn to_volume(&self) -> Result<Volume<f32>> {
        Volume::with_affine(
            self.grid.dims,
            self.affine,
            self.grid.data.iter().map(|x| x.f64() as f32).collect(),
        )
    }
}

/// The part of the input a resampling covers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Region {
    /// The whole volume: index box `[−½, n − ½]` on every axis.
    Whole,
    /// An index-space box `[lo, hi]` (cell edges; fractional values allowed).
    Index { lo: [f64; 3], hi: [f64; 3] },
    /// An axis-aligned world box in mm; the output is aligned with the world axes.
    World { lo: [f64; 3], hi: [f64; 3] },
}

/// What [`resample`] produces: `dims` voxels tiling `region`, sampled with `filter`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResampleSpec {
    pub region: Region,
    pub dims: [usize; 3],
    pub filter: Filter,
}

/// The output-index → input-index map and the output affine of a resampling of a
/// volume of `in_dims` with affine `in_affine`, after checking the box and the output
/// size.
///
/// # Errors
/// As [`resample`].
pub fn resample_plan(
    in_dims: [usize; 3],
    in_affine: DMat4,
    spec: &ResampleSpec,
) -> Result<(DMat4, DMat4)> {
    check_dims(spec.dims)?;
    let (lo, hi) = match spec.region {
        Region::Whole => ([-0.5; 3], in_dims.map(|n| n as f64 - 0.5)),
        Region::Index { lo, hi } | Region::World { lo, hi } => (lo, hi),
    };
    if !(0..3).all(|a| lo[a].is_finite() && hi[a].is_finite() && hi[a] > lo[a]) {
        return Err(Error::invalid(
            "resampling box",
            format!("lo {lo:?}, hi {hi:?}: every axis needs finite lo < hi (an empty box)"),
        ));
    }
    // Output index i ↦ box coordinate lo + (i + ½)(hi − lo)/dims.
    let step = DVec3::from_array([0, 1, 2].map(|a| (hi[a] - lo[a]) / spec.dims[a] as f64));
    let tile =
        DMat4::from_translation(DVec3::from_array(lo) + 0.5 * step) * DMat4::from_scale(step);
    Ok(match spec.region {
        Region::World { .. } => (in_affine.inverse() * tile, tile),
        _ => (tile, in_affine * tile),
    })
}

/// Resamples `region` of `vol` onto `spec.dims` voxels with `spec.filter` (see the
/// module docs for the convention). Identity when the region is the whole volume and
/// the dims are unchanged (for interpolating filters).
///
/// # Errors
/// [`Error::Invalid`] for an empty or non-finite box, [`Error::TooLarge`] for an output
/// over the voxel limit ([`crate::volume::max_voxels`]).
pub fn resample<R: Real, T: Voxel>(vol: &Volume<T>, spec: &ResampleSpec) -> Result<Field<R>> {
    let (to_in, affine) = resample_plan(vol.dims(), vol.affine(), spec)?;
    let grid = prepare(&Grid::<R>::from_volume(vol), spec.filter);
    let dims = spec.dims;
    let mut data = vec![R::zero(); dims[0] * dims[1] * dims[2]];
    data.par_chunks_mut(dims[0] * dims[1])
        .enumerate()
        .for_each(|(k, slice)| {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let p = to_in.transform_point3(DVec3::new(i as f64, j as f64, k as f64));
                    slice[i + dims[0] * j] = sample(&grid, spec.filter, V3::from_dvec(p));
                }
            }
        });
    Ok(Field {
        grid: Grid { dims, data },
        affine,
    })
}

/// scipy's `reflect` rule: index `i` of a line of `n` mirrored about the end edges
/// (`d c b a | a b c d | d c b a`, period `2n`).
/// Mirrors `shaders/shared/process_params.wgsl: reflect_index`.
#[inline(always)]
pub fn reflect_index(i: isize, n: usize) -> usize {
    let p = 2 * n as isize;
    let m = i.rem_euclid(p);
    if m >= n as isize {
        (p - 1 - m) as usize
    } else {
        m as usize
    }
}

/// The truncation radius `⌊4σ + ½⌋` (scipy's `truncate=4.0`).
pub fn gaussian_radius(sigma: f64) -> usize {
    (4.0 * sigma + 0.5) as usize
}

/// The normalised 1-D Gaussian weights `w[t + r]`, `t = −r … r` (in f64).
pub fn gaussian_weights(sigma: f64) -> Vec<f64> {
    let r = gaussian_radius(sigma) as isize;
    let w: Vec<f64> = (-r..=r)
        .map(|t| (-0.5 * (t * t) as f64 / (sigma * sigma)).exp())
        .collect();
    let s: f64 = w.iter().sum();
    w.iter().map(|x| x / s).collect()
}

/// Checks σ per axis: finite, positive, at most [`MAX_SIGMA`].
pub fn check_sigma(sigma: [f64; 3]) -> Result<()> {
    if sigma
        .iter()
        .all(|s| s.is_finite() && *s > 0.0 && *s <= MAX_SIGMA)
    {
        Ok(())
    } else {
        Err(Error::invalid(
            "Gaussian sigma",
            format!("{sigma:?}: σ must be finite, > 0 and ≤ {MAX_SIGMA} voxels on every axis"),
        ))
    }
}

/// The weighted sum along `axis` at voxel `(i, j, k)`: `Σ_t w[t + r] f[reflect(n + t)]`,
/// taps in order. Mirrors `shaders/process_gaussian.wgsl: convolve_axis_at`.
#[inline]
pub fn convolve_axis_at<R: Real>(g: &Grid<R>, w: &[R], axis: usize, ijk: [usize; 3]) -> R {
    let [nx, ny, _] = g.dims;
    let n = g.dims[axis];
    let r = (w.len() / 2) as isize;
    let mut p = ijk;
    let mut acc = R::zero();
    for (t, &wt) in w.iter().enumerate() {
        p[axis] = reflect_index(ijk[axis] as isize + t as isize - r, n);
        acc = acc + wt * g.data[p[0] + nx * (p[1] + ny * p[2])];
    }
    acc
}

/// One separable pass: `out[v] = convolve_axis_at(g, w, axis, v)` for every voxel.
pub fn convolve_axis<R: Real>(g: &Grid<R>, w: &[R], axis: usize) -> Grid<R> {
    map_voxels(g.dims, |ijk| convolve_axis_at(g, w, axis, ijk))
}

/// A grid of `f(voxel)` over `dims`, in parallel over z-slices.
fn map_voxels<R: Real>(dims: [usize; 3], f: impl Fn([usize; 3]) -> R + Sync) -> Grid<R> {
    let mut data = vec![R::zero(); dims[0] * dims[1] * dims[2]];
    data.par_chunks_mut(dims[0] * dims[1])
        .enumerate()
        .for_each(|(k, s)| {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    s[i + dims[0] * j] = f([i, j, k]);
                }
            }
        });
    Grid { dims, data }
}

/// Gaussian smoothing with σ per axis (voxels), separable x → y → z, truncated at
/// `⌊4σ + ½⌋`, boundary `reflect`: scipy's `gaussian_filter` with its defaults.
///
/// # Errors
/// [`Error::Invalid`] for σ ≤ 0, NaN, infinite or above [`MAX_SIGMA`].
pub fn gaussian<R: Real, T: Voxel>(vol: &Volume<T>, sigma: [f64; 3]) -> Result<Field<R>> {
    check_sigma(sigma)?;
    let mut g = Grid::<R>::from_volume(vol);
    for (axis, &s) in sigma.iter().enumerate() {
        let w: Vec<R> = gaussian_weights(s).into_iter().map(R::of).collect();
        g = convolve_axis(&g, &w, axis);
    }
    Ok(Field {
        grid: g,
        affine: vol.affine(),
    })
}

/// Checks a median window side: odd, at least 1, at most `max`.
pub fn check_median_size(k: usize, max: usize) -> Result<()> {
    if k % 2 == 1 && k <= max {
        Ok(())
    } else {
        Err(Error::invalid(
            "median window size",
            format!("{k}: the cubic window side must be odd, from 1 to {max}"),
        ))
    }
}

/// The median of the `k³` window around voxel `ijk` (reflect rule), using `buf` as
/// scratch. Mirrors `shaders/process_median.wgsl: median_at`.
pub fn median_at<R: Real>(g: &Grid<R>, k: usize, ijk: [usize; 3], buf: &mut Vec<R>) -> R {
    let [nx, ny, nz] = g.dims;
    let r = (k / 2) as isize;
    buf.clear();
    for dz in -r..=r {
        let z = reflect_index(ijk[2] as isize + dz, nz);
        for dy in -r..=r {
            let y = reflect_index(ijk[1] as isize + dy, ny);
            for dx in -r..=r {
                let x = reflect_index(ijk[0] as isize + dx, nx);
                buf.push(g.data[x + nx * (y + ny * z)]);
            }
        }
    }
    let mid = buf.len() / 2;
    let (_, m, _) = buf.select_nth_unstable_by(mid, |a, b| {
        a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal)
    });
    *m
}

/// 3-D median filter with a cubic window of odd side `k`, boundary `reflect`:
/// scipy's `median_filter(f, size=k, mode='reflect')`.
///
/// # Errors
/// [`Error::Invalid`] for an even `k` or `k` > [`MAX_MEDIAN_SIZE_CPU`].
pub fn median<R: Real, T: Voxel>(vol: &Volume<T>, k: usize) -> Result<Field<R>> {
    check_median_size(k, MAX_MEDIAN_SIZE_CPU)?;
    let g = Grid::<R>::from_volume(vol);
    let dims = g.dims;
    let mut data = vec![R::zero(); g.data.len()];
    data.par_chunks_mut(dims[0] * dims[1])
        .enumerate()
        .for_each(|(z, s)| {
            let mut buf = Vec::with_capacity(k * k * k);
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    s[x + dims[0] * y] = median_at(&g, k, [x, y, z], &mut buf);
                }
            }
        });
    Ok(Field {
        grid: Grid { dims, data },
        affine: vol.affine(),
    })
}

/// `L⁻ᵀ`, the map from index-space to world-space gradients of an affine.
pub fn world_gradient_matrix(affine: DMat4) -> DMat3 {
    DMat3::from_mat4(affine).inverse().transpose()
}

/// `|M g|` for an index-space gradient `g` and `M = L⁻ᵀ`.
/// Mirrors `shaders/process_gradient.wgsl: world_gradient_length`.
#[inline(always)]
pub fn world_gradient_length<R: Real>(m: &[[R; 3]; 3], g: V3<R>) -> R {
    let row = |r: &[R; 3]| r[0] * g.x() + r[1] * g.y() + r[2] * g.z();
    V3::new(row(&m[0]), row(&m[1]), row(&m[2])).length()
}

/// `|∇f|` in value per mm at every voxel: central differences (`cpu::gradient`, clamped
/// = reflected neighbours) mapped to world units by `L⁻ᵀ`.
pub fn gradient_magnitude<R: Real, T: Voxel>(vol: &Volume<T>) -> Result<Field<R>> {
    let g = Grid::<R>::from_volume(vol);
    let [gx, gy, gz] = precompute_gradients(&g, GradientMethod::Central);
    let m = world_gradient_matrix(vol.affine());
    let rows: [[R; 3]; 3] = [0, 1, 2].map(|r| m.row(r).to_array().map(R::of));
    let data = (0..g.data.len())
        .into_par_iter()
        .map(|n| world_gradient_length(&rows, V3::new(gx.data[n], gy.data[n], gz.data[n])))
        .collect();
    Ok(Field {
        grid: Grid { dims: g.dims, data },
        affine: vol.affine(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reflect_matches_scipy_pattern() {
        // d c b a | a b c d | d c b a for n = 4.
        let got: Vec<usize> = (-4..8).map(|i| reflect_index(i, 4)).collect();
        assert_eq!(got, vec![3, 2, 1, 0, 0, 1, 2, 3, 3, 2, 1, 0]);
        assert_eq!(reflect_index(-3, 1), 0);
    }

    #[test]
    fn gaussian_radius_is_scipy_truncate_4() {
        assert_eq!(gaussian_radius(1.0), 4);
        assert_eq!(gaussian_radius(0.5), 2);
        assert_eq!(gaussian_radius(0.3), 1);
        assert_eq!(gaussian_weights(1.5).len(), 13);
    }
}
