//! Filtered backprojection: FBP for parallel beams (2-D slices and 3-D stacks) and
//! FDK for circular cone beams (Feldkamp, Davis & Kress 1984; Kak & Slaney ch. 3,
//! eqs. 61 and 176; Xu & Mueller 2006, §3.1), on any grid of points.
//!
//! # The formula
//! After ramp filtering ([`crate::cpu::ramp`]: cosine pre-weighting for a cone beam,
//! the ramp, values per mm at the isocentre), every reconstructed point `p` is
//!
//! `f(p) = π/(2A) · Σ_k w_k(p) · q_k(col_k(p), row_k(p))`
//!
//! over the `A` views, where `(col_k, row_k, w_k)` = [`ViewMatrix::project`] — `w = 1`
//! for a parallel beam and `w = (SID/(SID − p·e_w))²` (FDK's `U⁻²`) for a cone beam —
//! and `q_k(·)` is [`bilinear_zero`] of the filtered projection: [`backproject_point`].
//! A geometry given view by view ([`Geometry::from_views`]) has its own projective map
//! per view and `w = (SID_k/depth)²` (RTK's), the rest unchanged.
//!
//! **Why `π/(2A)`.** The continuous inversion is `∫₀^π dθ ∫|ω|P_θ(ω)e^{2πiωs}dω` for a
//! parallel beam, and half of `∫₀^{2π}` for a full cone-beam circle (each ray is
//! measured twice). With `A` evenly spread views both become `π/A · Σ_k`, with the ramp
//! `|f|`. scikit-image's filter is `H ≈ 2|f|`, so the same reconstruction carries
//! `π/(2A)` — the constant scikit-image's `iradon` multiplies by, which is what makes
//! voxlab's FBP equal to `iradon` on the same sinogram. Other angular ranges (short
//! scans, 360° parallel scans) need their own weights; this module assumes the two
//! standard ones (180° parallel, 360° cone).
//!
//! # Grids
//! A reconstruction grid is `dims` plus a voxel-index → CT-world affine ([`Grid`]), the
//! output is a [`Volume`] with that affine:
//! - [`skimage_grid`]: scikit-image's `iradon` image, `n × n`, `x = col − n//2`,
//!   `y = n//2 − row`, world `X = x`, `Z = −y`, `Y = 0` (see `crate::ct`);
//! - [`parallel_stack_grid`]: one such image (spacing `du`) per detector row, slice `k`
//!   at the height of row `k`;
//! - [`rtk_grid`]: RTK's centred grid, voxel `i` at `(i − (N − 1)/2)·spacing` on each
//!   axis, axes = CT world `X, Y, Z`.
//!
//! # Implementation
//! [`backproject_point`] is the per-point definition (also used for arbitrary points,
//! [`reconstruct_points`]). [`backproject`] evaluates the same sum on a grid line by
//! line: along a line of voxels every view's projective numerators and denominator are
//! affine in the voxel index, so each is `a + i·b`; for a parallel beam the detector
//! row is constant along a grid line, and the inner loop becomes a 1-D linear
//! interpolation on a zero-bordered copy of that row. For a cone beam on a grid whose
//! `j` axis is the rotation axis (RTK's) the sum runs along voxel columns instead
//! (`backproject_columns`): there the detector column, the weight and the
//! denominator are constant and only the row moves, so each view costs one division
//! per column and a 1-D walk down two detector columns, read from a transposed copy of
//! the view. All of these agree with the per-point sum to rounding (tests).
//!
//! [`backproject_region`] evaluates the same sums on a box of the grid, bit for bit,
//! from the whole stack or from only the lines the box reads ([`region_rows`],
//! [`crate::ct::Lines`]: a distributed rank's). The views are then copied as one band
//! of rows, and each voxel's row, computed in the whole detector, is moved into the
//! band by an integer after its floor, which changes no rounding.

use crate::cpu::ramp::{filter_projections, FilterMethod, RampFilter};
use crate::ct::{bilinear_zero, Beam, DetectorLines, Geometry, Projections, ViewMatrix};
use crate::error::{Error, Result};
use crate::real::{as_f32, as_f32_mut, Real};
use crate::volume::{check_dims, Volume};
use glam::{DMat4, DVec3, DVec4};
use rayon::prelude::*;
use rustfft::FftNum;
use std::f64::consts::PI;
use std::sync::atomic::{AtomicUsize, Ordering};

/// A reconstruction grid: voxel counts and the voxel-index → CT-world (mm) affine.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    pub dims: [usize; 3],
    pub affine: DMat4,
}

impl Grid {
    /// The CT-world position of voxel `(i, j, k)`.
    pub fn point(&self, i: usize, j: usize, k: usize) -> DVec3 {
        self.affine
            .transform_point3(DVec3::new(i as f64, j as f64, k as f64))
    }

    /// The CT-world positions of the eight corners of the box of voxel centres
    /// `0..nx` × `j` × `k`: where a quantity affine in the point (a cone beam's depth)
    /// takes its extremes over the box.
    pub fn corners(&self, j: std::ops::Range<usize>, k: std::ops::Range<usize>) -> [[f64; 3]; 8] {
        let last = |r: &std::ops::Range<usize>| r.end.saturating_sub(1).max(r.start);
        let mut out = [[0.0; 3]; 8];
        for (n, c) in out.iter_mut().enumerate() {
            let i = if n & 1 == 0 {
                0
            } else {
                self.dims[0].saturating_sub(1)
            };
            let jj = if n & 2 == 0 { j.start } else { last(&j) };
            let kk = if n & 4 == 0 { k.start } else { last(&k) };
            *c = self.point(i, jj, kk).to_array();
        }
        out
    }
}

/// scikit-image's `iradon` output grid for an `n × n` image (1 mm = 1 detector bin):
/// index `i` = column, `j` = row, world `X = i − n//2`, `Z = j − n//2`, `Y = 0`.
pub fn skimage_grid(n: usize) -> Grid {
    let h = (n / 2) as f64;
    Grid {
        dims: [n, n, 1],
        affine: DMat4::from_cols(
            DVec4::new(1.0, 0.0, 0.0, 0.0),
            DVec4::new(0.0, 0.0, 1.0, 0.0),
            DVec4::new(0.0, 1.0, 0.0, 0.0),
            DVec4::new(-h, 0.0, -h, 1.0),
        ),
    }
}

/// The grid of a 3-D parallel stack: `n × n × rows`, each z-slice the scikit-image
/// image (pixel `du`) of detector row `k`, at height `Y = (k − cv)·dv`.
pub fn parallel_stack_grid(n: usize, g: &Geometry) -> Grid {
    let h = (n / 2) as f64;
    Grid {
        dims: [n, n, g.rows],
        affine: DMat4::from_cols(
            DVec4::new(g.du, 0.0, 0.0, 0.0),
            DVec4::new(0.0, 0.0, g.du, 0.0),
            DVec4::new(0.0, g.dv, 0.0, 0.0),
            DVec4::new(-h * g.du, -g.cv * g.dv, -h * g.du, 1.0),
        ),
    }
}

/// RTK's centred grid: voxel `i` at `(i − (N − 1)/2)·spacing` on each axis, the axes
/// being CT world `X, Y, Z` (`Y` the rotation axis).
pub fn rtk_grid(dims: [usize; 3], spacing: [f64; 3]) -> Grid {
    let o: [f64; 3] = std::array::from_fn(|a| -(dims[a] as f64 - 1.0) / 2.0 * spacing[a]);
    Grid {
        dims,
        affine: DMat4::from_cols(
            DVec4::new(spacing[0], 0.0, 0.0, 0.0),
            DVec4::new(0.0, spacing[1], 0.0, 0.0),
            DVec4::new(0.0, 0.0, spacing[2], 0.0),
            DVec4::new(o[0], o[1], o[2], 1.0),
        ),
    }
}

/// A reconstructed grid: values at every voxel of `grid`, x fastest (f64 is not a
/// storable voxel type, so the oracle's output lives here; [`Reconstruction::to_volume`]
/// gives an f32 [`Volume`] with the grid's affine).
#[derive(Clone, Debug, PartialEq)]
pub struct Reconstruction<R> {
    pub grid: Grid,
    pub data: Vec<R>,
}

impl<R: Real> Reconstruction<R> {
    /// The value at voxel `(i, j, k)`.
    pub fn get(&self, i: usize, j: usize, k: usize) -> R {
        let d = self.grid.dims;
        self.data[i + d[0] * (j + d[1] * k)]
    }

    /// An f32 volume with the grid's affine.
    pub fn to_volume(&self) -> Result<Volume<f32>> {
        Volume::with_affine(
            self.grid.dims,
            self.grid.affine,
            self.data.iter().map(|v| v.f64() as f32).collect(),
        )
    }
}

/// The backprojection constant `π/(2A)` for `A` views (see the module docs).
pub fn backprojection_scale(n_angles: usize) -> f64 {
    PI / (2.0 * n_angles as f64)
}

/// One reconstructed point: `π/(2A)·Σ_k w_k(p)·bilinear_zero(filtered_k, col_k, row_k)`
/// with `A = views.len()` (the projections' count). `p` is in CT world mm.
///
/// mirrors shaders/fbp_backproject.wgsl: backproject_point
pub fn backproject_point<R: Real>(
    filtered: &Projections<R>,
    views: &[ViewMatrix<R>],
    p: [R; 3],
) -> R {
    let mut acc = R::zero();
    for (k, m) in views.iter().enumerate() {
        if let Some((c, r, w)) = m.project(p) {
            acc = acc + w * bilinear_zero(filtered.view(k), filtered.cols, filtered.rows, c, r);
        }
    }
    acc * R::of(backprojection_scale(views.len()))
}

fn check_inputs<R: Copy + Default>(filtered: &Projections<R>, g: &Geometry) -> Result<()> {
    g.validate()?;
    filtered.check_against(g)
}

/// The detector rows the voxels of `region` read in each view of `g`: the rows between
/// those of the region box's corners (a projection maps the box into the hull of its
/// corners' images, so the extreme rows are corners'), one more on each side for the
/// bilinear taps and rounding; the whole view when a corner lies at or behind the
/// source.
pub fn region_rows(g: &Geometry, grid: &Grid, region: &Region) -> Vec<std::ops::Range<usize>> {
    let corners = grid.corners(region.j.clone(), region.k.clone());
    g.view_matrices::<f64>()
        .iter()
        .map(|m| {
            let rows: Option<Vec<f64>> = corners
                .iter()
                .map(|&p| m.project(p).map(|(_, r, _)| r))
                .collect();
            match rows {
                None => 0..g.rows,
                Some(r) => {
                    let lo = r.iter().fold(f64::INFINITY, |m, &v| m.min(v));
                    let hi = r.iter().fold(f64::NEG_INFINITY, |m, &v| m.max(v));
                    let first = (lo.floor() - 1.0).max(0.0);
                    let last = (hi.floor() + 2.0).min(g.rows as f64 - 1.0);
                    if last < first {
                        0..0
                    } else {
                        first as usize..last as usize + 1
                    }
                }
            }
        })
        .collect()
}

/// The detector rows of every view a backprojection copies and reads, `first` to
/// `first + len − 1`. Rows are addressed by their index `iy = row + 1` in a
/// zero-bordered view, so the window's bordered copy holds rows `first − 1` to
/// `first + len`.
#[derive(Clone, Copy, Debug)]
struct Window {
    first: usize,
    len: usize,
}

impl Window {
    /// The bordered row `iy ∈ [0, rows]` of the whole view in the window's bordered
    /// copy (clamped into it: a voxel of the region never reads outside it, and one
    /// outside the detector reads with weight zero).
    #[inline(always)]
    fn local(self, iy: usize) -> usize {
        iy.saturating_sub(self.first).min(self.len)
    }

    /// The rows of `filtered` a backprojection of `region` copies: every row of a
    /// whole stack, else the rows [`region_rows`] names in any view, each of which
    /// `filtered` must hold.
    fn of<R, L: DetectorLines<R> + ?Sized>(
        filtered: &L,
        g: &Geometry,
        grid: &Grid,
        region: &Region,
    ) -> Result<Window> {
        if filtered.whole() {
            return Ok(Window {
                first: 0,
                len: g.rows,
            });
        }
        let bands = region_rows(g, grid, region);
        for (v, band) in bands.iter().enumerate() {
            if let Some(r) = band.clone().find(|&r| filtered.line(v, r).is_none()) {
                return Err(Error::invalid(
                    "backprojection lines",
                    format!("the region reads row {r} of view {v}, which the lines do not hold"),
                ));
            }
        }
        let first = bands
            .iter()
            .filter(|b| !b.is_empty())
            .map(|b| b.start)
            .min();
        let end = bands.iter().map(|b| b.end).max().unwrap_or(0);
        Ok(match first {
            Some(first) => Window {
                first,
                len: end - first,
            },
            None => Window { first: 0, len: 0 },
        })
    }
}

/// [`backproject_point`] at every point of `points` (CT world mm), in parallel.
pub fn reconstruct_points<R: Real>(
    filtered: &Projections<R>,
    g: &Geometry,
    points: &[[R; 3]],
) -> Result<Vec<R>> {
    check_inputs(filtered, g)?;
    let views = g.view_matrices::<R>();
    Ok(points
        .par_iter()
        .map(|&p| backproject_point(filtered, &views, p))
        .collect())
}

/// Backprojects filtered projections onto `grid` (the sum of [`backproject_point`] at
/// every voxel centre, evaluated line by line). `progress(done_lines, total_lines)`.
pub fn backproject<R: Real>(
    filtered: &Projections<R>,
    g: &Geometry,
    grid: &Grid,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Reconstruction<R>> {
    let data = backproject_region(filtered, g, grid, &Region::all(grid.dims), progress)?;
    Ok(Reconstruction { grid: *grid, data })
}

/// A box of a grid's voxels: every `i`, the slices `j` and `k` of two index ranges.
/// Its voxels are stored `i` fastest, then `j`, then `k`, as in the whole grid.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Region {
    pub j: std::ops::Range<usize>,
    pub k: std::ops::Range<usize>,
}

impl Region {
    /// The whole grid.
    pub fn all(dims: [usize; 3]) -> Region {
        Region {
            j: 0..dims[1],
            k: 0..dims[2],
        }
    }

    /// How many voxels the region holds on a grid `nx` voxels wide.
    pub fn voxels(&self, nx: usize) -> usize {
        nx * self.j.len() * self.k.len()
    }
}

/// [`backproject`] restricted to the voxels of `region`: each voxel is computed from
/// its index in the whole grid by the same arithmetic, so the values equal those of
/// the whole grid bit for bit (the slabs of a distributed reconstruction). Returns the
/// region's voxels in its own order ([`Region`]).
///
/// `filtered` is the whole filtered stack, or only some of its lines
/// ([`crate::ct::Lines`]): then it must hold the rows [`region_rows`] names, and only
/// the band of rows they span is copied, so a slab's memory follows the slab, not the
/// detector. A voxel's row is computed in the whole detector and moved into the band
/// by an integer, so the sums are those of the whole stack bit for bit.
///
/// # Errors
/// As [`backproject`]; a region outside the grid or empty; lines that miss a row the
/// region reads.
pub fn backproject_region<R: Real, L: DetectorLines<R> + ?Sized>(
    filtered: &L,
    g: &Geometry,
    grid: &Grid,
    region: &Region,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Vec<R>> {
    g.validate()?;
    g.check_stack(filtered.shape())?;
    check_dims(grid.dims)?;
    if region.j.is_empty()
        || region.k.is_empty()
        || region.j.end > grid.dims[1]
        || region.k.end > grid.dims[2]
    {
        return Err(Error::invalid(
            "backprojection region",
            format!(
                "j {:?}, k {:?} is empty or leaves the {}×{}×{} grid",
                region.j, region.k, grid.dims[0], grid.dims[1], grid.dims[2]
            ),
        ));
    }
    let n = region.voxels(grid.dims[0]);
    let views = g.view_matrices::<R>();
    let (cols, rows) = (g.cols, g.rows);
    let window = Window::of(filtered, g, grid, region)?;
    let parallel = matches!(g.beam, Beam::Parallel);
    // A cone beam on a grid with its j axis along the rotation axis: column by column.
    let along_axis = |r: &[R; 4]| {
        let sj = to_r::<R>(grid.affine.y_axis.truncate());
        r[0] * sj[0] + r[1] * sj[1] + r[2] * sj[2] == R::zero()
    };
    if !parallel
        && views
            .iter()
            .all(|m| along_axis(&m.rows[0]) && along_axis(&m.rows[2]))
    {
        let scale = R::of(backprojection_scale(g.n_angles()));
        let mut data = vec![R::zero(); n];
        backproject_columns(
            filtered, window, g, grid, region, &views, scale, &mut data, progress,
        );
        return Ok(data);
    }
    let Window { first, len } = window;
    // Zero-bordered copies of the window's detector rows: [0, row…, 0].
    let pc = cols + 2;
    let mut padded = if parallel {
        vec![R::zero(); g.n_angles() * len * pc]
    } else {
        Vec::new()
    };
    padded.par_chunks_mut(pc).enumerate().for_each(|(n, d)| {
        if let Some(s) = filtered.line(n / len, first + n % len) {
            d[1..=cols].copy_from_slice(s);
        }
    });
    // Cone beam: zero-bordered copies of every view's window, (len + 2) × (cols + 2),
    // so the four bilinear taps need no per-tap bounds test.
    let (pcol, prow) = (cols + 2, len + 2);
    let padded2 = if parallel {
        Vec::new()
    } else {
        let mut p2 = vec![R::zero(); g.n_angles() * prow * pcol];
        p2.par_chunks_mut(prow * pcol)
            .enumerate()
            .for_each(|(v, d)| {
                for r in 0..len {
                    if let Some(src) = filtered.line(v, first + r) {
                        d[(r + 1) * pcol + 1..(r + 1) * pcol + 1 + cols].copy_from_slice(src);
                    }
                }
            });
        p2
    };
    let a = grid.affine;
    let step = a.x_axis.truncate();
    let nx = grid.dims[0];
    let nj = region.j.len();
    let total = nj * region.k.len();
    let done = AtomicUsize::new(0);
    let scale = R::of(backprojection_scale(g.n_angles()));
    let mut data = vec![R::zero(); n];
    // Voxel lines at the same height j (along the rotation axis, y) project onto the
    // same few detector rows in every view. Visiting them one after another (z inside
    // j, not the memory order) keeps those rows of all views in cache (256³ cone beam,
    // CPU f32 on 2 cores: 4.4 s → 3.9 s).
    let mut lines: Vec<(usize, &mut [R])> = data.chunks_mut(nx).enumerate().collect();
    lines.sort_by_key(|(line, _)| (line % nj, line / nj));
    lines.into_par_iter().panic_fuse().for_each_init(
        || vec![R::zero(); pc],
        |blend, (line, out)| {
            let (j, k) = (region.j.start + line % nj, region.k.start + line / nj);
            let o = grid.point(0, j, k);
            let (o, st) = (to_r::<R>(o), to_r::<R>(step));
            for (v, m) in views.iter().enumerate() {
                let dot = |r: &[R; 4], p: [R; 3], h: R| r[0] * p[0] + r[1] * p[1] + r[2] * p[2] + h;
                let ab = |r: &[R; 4]| (dot(r, o, r[3]), dot(r, st, R::zero()));
                let (a0, b0) = ab(&m.rows[0]);
                let (a1, b1) = ab(&m.rows[1]);
                let (a2, b2) = ab(&m.rows[2]);
                if parallel && b1 == R::zero() {
                    // Row constant along the line (den = 1): 1-D interpolation.
                    let y = a1;
                    let fy = y.floor();
                    if !(fy >= -R::one() && fy < R::of(rows as f64)) {
                        continue;
                    }
                    let ty = y - fy;
                    let iy = fy.to_i64().unwrap_or(-2);
                    let base = v * len * pc;
                    // Rows outside the window are zero taps, as rows off the detector:
                    // the region reads none of them (`Window::of`).
                    let row_of = |r: i64| -> Option<&[R]> {
                        let l = r - first as i64;
                        (r >= 0 && r < rows as i64 && l >= 0 && l < len as i64)
                            .then(|| &padded[base + l as usize * pc..base + (l as usize + 1) * pc])
                    };
                    let line_ref: &[R] = if ty == R::zero() {
                        match row_of(iy) {
                            Some(l) => l,
                            None => continue,
                        }
                    } else {
                        // The two rows are looked up once per view, not per column; a
                        // missing row is a zero tap (the same sums as bilinear_zero).
                        let (u, w) = (R::one() - ty, ty);
                        match (row_of(iy), row_of(iy + 1)) {
                            (Some(l0), Some(l1)) => {
                                for ((b, &t0), &t1) in blend.iter_mut().zip(l0).zip(l1) {
                                    *b = t0 * u + t1 * w;
                                }
                            }
                            (Some(l0), None) => {
                                for (b, &t0) in blend.iter_mut().zip(l0) {
                                    *b = t0 * u + R::zero() * w;
                                }
                            }
                            (None, Some(l1)) => {
                                for (b, &t1) in blend.iter_mut().zip(l1) {
                                    *b = R::zero() * u + t1 * w;
                                }
                            }
                            (None, None) => continue,
                        }
                        blend
                    };
                    interp_line(out, line_ref, cols, a0, b0);
                } else {
                    let img = &padded2[v * prow * pcol..(v + 1) * prow * pcol];
                    cone_line(
                        out,
                        img,
                        pcol,
                        [cols, rows],
                        window,
                        [a0, a1, a2],
                        [b0, b1, b2],
                        m.rows[3][0],
                    );
                }
            }
            for acc in out.iter_mut() {
                *acc = *acc * scale;
            }
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, total);
        },
    );
    Ok(data)
}

/// The cone-beam sum on a grid whose `j` axis is parallel to the rotation axis (RTK's
/// grid, and every grid [`rtk_grid`] makes): along such a voxel column the column
/// numerator and the denominator are constant — so are the detector column, the
/// distance weight and the horizontal interpolation weight — and only the row moves,
/// `row_j = (n₁ + j·c₁)/den`. Per view and column the two detector columns it falls
/// between are blended once into `L[r] = w²·((1 − t_x)·q[r, c] + t_x·q[r, c + 1])`
/// (a transposed, zero-bordered copy of the view makes both contiguous), and each
/// voxel is a 1-D linear interpolation of `L`: one division per column instead of per
/// voxel, two taps instead of four. The same sum as [`backproject_point`] to rounding
/// (tests). Blocks of whole `z`-slices run in parallel, each accumulating `[k][i][j]`
/// (j fastest) in a buffer sized to stay in cache, visited view after view.
#[allow(clippy::too_many_arguments)]
fn backproject_columns<R: Real, L: DetectorLines<R> + ?Sized>(
    filtered: &L,
    window: Window,
    g: &Geometry,
    grid: &Grid,
    region: &Region,
    views: &[ViewMatrix<R>],
    scale: R,
    data: &mut [R],
    progress: &(dyn Fn(usize, usize) + Sync),
) {
    let (cols, rows) = (g.cols, g.rows);
    let (nx, ny, nz, j0) = (grid.dims[0], region.j.len(), region.k.len(), region.j.start);
    let (pcol, prow) = (cols + 2, window.len + 2);
    // Transposed, zero-bordered views of the window's rows: imgt[v][c + 1][r + 1] =
    // q_v(first + r, c), then 32 zeros so that a 32-value window from any column stays
    // inside.
    let mut imgt = vec![R::zero(); views.len() * pcol * prow + 32];
    imgt.par_chunks_mut(pcol * prow)
        .take(views.len())
        .enumerate()
        .for_each(|(v, d)| {
            for r in 0..window.len {
                if let Some(src) = filtered.line(v, window.first + r) {
                    for (c, &x) in src.iter().enumerate() {
                        d[(c + 1) * prow + r + 1] = x;
                    }
                }
            }
        });
    let a = grid.affine;
    let (si, sj) = (
        to_r::<R>(a.x_axis.truncate()),
        to_r::<R>(a.y_axis.truncate()),
    );
    let slice = nx * ny;
    // Slices per block: the accumulator within ~1.5 MiB, and enough blocks for the
    // threads to share.
    let fit = ((3 << 19) / (slice * std::mem::size_of::<R>())).max(1);
    let share = nz.div_ceil(4 * rayon::current_num_threads()).max(1);
    let kb = fit.min(share);
    let total = ny * nz;
    let done = AtomicUsize::new(0);
    let dot = |r: &[R; 4], p: [R; 3], h: R| r[0] * p[0] + r[1] * p[1] + r[2] * p[2] + h;
    data.par_chunks_mut(kb * slice)
        .enumerate()
        .panic_fuse()
        .for_each(|(block, out)| {
            let k0 = region.k.start + block * kb;
            let nk = out.len() / slice;
            let mut acc = vec![R::zero(); out.len()];
            let (limc, one) = (R::of(cols as f64 + 1.0), R::one());
            for (v, m) in views.iter().enumerate() {
                let img = &imgt[v * pcol * prow..(v + 1) * pcol * prow + 32];
                let c1 = dot(&m.rows[1], sj, R::zero());
                for kk in 0..nk {
                    let o = to_r::<R>(grid.point(0, 0, k0 + kk));
                    let ab = |r: &[R; 4]| (dot(r, o, r[3]), dot(r, si, R::zero()));
                    let ((a0, b0), (a1, b1), (a2, b2)) =
                        (ab(&m.rows[0]), ab(&m.rows[1]), ab(&m.rows[2]));
                    for i in 0..nx {
                        let fi = R::of(i as i32 as f64);
                        let den = a2 + fi * b2;
                        let inv = one / den;
                        let s = (a0 + fi * b0) * inv + one;
                        if !(den > R::zero() && s >= R::zero() && s < limc) {
                            continue;
                        }
                        // s ≥ 0: truncation is the floor; ix ≤ cols.
                        let ix = (s.f64() as usize).min(cols);
                        let tx = s - R::of(ix as i32 as f64);
                        let w = m.rows[3][0] * inv;
                        let pair = ColumnPair {
                            c0: &img[ix * prow..(ix + 1) * prow + 32],
                            c1: &img[(ix + 1) * prow..(ix + 2) * prow + 32],
                            tx,
                            w2: w * w,
                        };
                        let line = &mut acc[(kk * nx + i) * ny..(kk * nx + i + 1) * ny];
                        column_line(line, j0, pair, rows, window, a1 + fi * b1, c1, inv);
                    }
                }
            }
            for kk in 0..nk {
                for i in 0..nx {
                    let line = &acc[(kk * nx + i) * ny..(kk * nx + i + 1) * ny];
                    for (j, &x) in line.iter().enumerate() {
                        out[kk * slice + j * nx + i] = x * scale;
                    }
                }
            }
            progress(done.fetch_add(nk * ny, Ordering::Relaxed) + nk * ny, total);
        });
}

/// One detector column pair and where a voxel column falls on it: `c0`, `c1` are
/// columns `ix` and `ix + 1` of a transposed, zero-bordered view (rows `0..rows + 2`,
/// then at least 32 readable values of overhang), `tx` the horizontal weight and `w2`
/// the FDK weight `w²`.
#[derive(Clone, Copy)]
struct ColumnPair<'a, R> {
    c0: &'a [R],
    c1: &'a [R],
    tx: R,
    w2: R,
}

/// `out[j] += w²·bilinear(t_j)` along one voxel column whose first voxel is `j0` of
/// the grid, `t_j = (n1 + (j0 + j)·c1)·inv + 1`
/// (the bordered row), zero where `t_j ∉ [0, rows + 1)` (the border rule of
/// [`bilinear_zero`]); the columns hold the `window`'s rows. The same arithmetic as
/// [`cone_line_from`] once the row is known.
#[inline]
#[allow(clippy::too_many_arguments)]
fn column_line<R: Real>(
    out: &mut [R],
    j0: usize,
    p: ColumnPair<R>,
    rows: usize,
    window: Window,
    n1: R,
    c1: R,
    inv: R,
) {
    let len = window.len;
    assert!(p.c0.len() >= len + 2 + 32 && p.c1.len() >= len + 2 + 32);
    #[cfg(target_arch = "x86_64")]
    {
        if let (Some(o32), Some(c0), Some(c1v)) = (as_f32_mut(out), as_f32(p.c0), as_f32(p.c1)) {
            if std::arch::is_x86_feature_detected!("avx2")
                && p.c0.len().max(p.c1.len()) < i32::MAX as usize
            {
                let f = |x: R| x.f64() as f32;
                let q = ColumnPair {
                    c0,
                    c1: c1v,
                    tx: f(p.tx),
                    w2: f(p.w2),
                };
                let (n1, c1, inv) = (f(n1), f(c1), f(inv));
                // SAFETY: the CPU has the features each function is compiled for.
                let band = window.first != 0 || window.len != rows;
                let done = unsafe {
                    match (std::arch::is_x86_feature_detected!("avx512f"), band) {
                        (true, true) => {
                            column_line_f32x16::<true>(o32, j0, q, rows, window, n1, c1, inv)
                        }
                        (true, false) => {
                            column_line_f32x16::<false>(o32, j0, q, rows, window, n1, c1, inv)
                        }
                        (false, true) => {
                            column_line_f32x8::<true>(o32, j0, q, rows, window, n1, c1, inv)
                        }
                        (false, false) => {
                            column_line_f32x8::<false>(o32, j0, q, rows, window, n1, c1, inv)
                        }
                    }
                };
                column_line_from(o32, j0, done, q, rows, window, n1, c1, inv);
                return;
            }
        }
    }
    column_line_from(out, j0, 0, p, rows, window, n1, c1, inv);
}

/// The loop of [`column_line`] from voxel `start` on, branch-free: outside voxels add
/// a zero and read clamped taps.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn column_line_from<R: Real>(
    out: &mut [R],
    j0: usize,
    start: usize,
    p: ColumnPair<R>,
    rows: usize,
    window: Window,
    n1: R,
    c1: R,
    inv: R,
) {
    let (zero, one, lim) = (R::zero(), R::one(), R::of(rows as f64 + 1.0));
    let len = window.len;
    let (c0, c1v, tx, w2) = (&p.c0[..len + 2], &p.c1[..len + 2], p.tx, p.w2);
    let ux = one - tx;
    for (j, acc) in out.iter_mut().enumerate().skip(start) {
        // Integers below 2^24 are exact in f32.
        let t = (n1 + R::of((j0 + j) as i32 as f64) * c1) * inv + one;
        let inside = t >= zero && t < lim;
        let t = if inside { t } else { zero };
        let iy = ((t.f64() as i32).max(0) as usize).min(rows);
        let ty = t - R::of(iy as i32 as f64);
        let ly = window.local(iy);
        let top = c0[ly] * ux + c1v[ly] * tx;
        let bottom = c0[ly + 1] * ux + c1v[ly + 1] * tx;
        let v = w2 * (top * (one - ty) + bottom * ty);
        *acc = *acc + if inside { v } else { zero };
    }
}

/// [`column_line_from`] for f32, sixteen voxels at a time with AVX-512, the same
/// operations in the same order (bit for bit the same sums). Where the sixteen rows
/// fall in a window of 32 (always, unless a voxel is more than two detector rows tall)
/// the taps come from two loads and a permute per column instead of gathers. Returns
/// how many leading voxels it did.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments)]
unsafe fn column_line_f32x16<const BAND: bool>(
    out: &mut [f32],
    j0: usize,
    p: ColumnPair<f32>,
    rows: usize,
    window: Window,
    n1: f32,
    c1: f32,
    inv: f32,
) -> usize {
    use std::arch::x86_64::*;
    let len = window.len;
    assert!(p.c0.len() >= len + 2 + 32 && p.c1.len() >= len + 2 + 32);
    let (wfirst, wlen) = (
        _mm512_set1_epi32(window.first as i32),
        _mm512_set1_epi32(len as i32),
    );
    let n = out.len() / 16 * 16;
    let set = _mm512_set1_ps;
    let (one, zero) = (set(1.0), _mm512_setzero_ps());
    let lim = set((rows as f64 + 1.0) as f32);
    let (zi, mr) = (_mm512_setzero_si512(), _mm512_set1_epi32(rows as i32));
    let lane = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    let (vn1, vc1, vinv) = (set(n1), set(c1), set(inv));
    let (tx, ux, w2) = (set(p.tx), set(1.0 - p.tx), set(p.w2));
    let (b0, b1) = (p.c0.as_ptr(), p.c1.as_ptr());
    let mut k = 0;
    while k < n {
        let fj = _mm512_cvtepi32_ps(_mm512_add_epi32(_mm512_set1_epi32((j0 + k) as i32), lane));
        let t = _mm512_add_ps(
            _mm512_mul_ps(_mm512_add_ps(vn1, _mm512_mul_ps(fj, vc1)), vinv),
            one,
        );
        let inside =
            _mm512_cmp_ps_mask::<_CMP_GE_OQ>(t, zero) & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(t, lim);
        let t = _mm512_maskz_mov_ps(inside, t);
        let iy = _mm512_min_epi32(_mm512_max_epi32(_mm512_cvttps_epi32(t), zi), mr);
        let ty = _mm512_sub_ps(t, _mm512_cvtepi32_ps(iy));
        // Window::local, lane by lane: the taps' place in the columns (the identity on
        // whole columns: iy ≤ rows).
        let iy = if BAND {
            _mm512_min_epi32(_mm512_max_epi32(_mm512_sub_epi32(iy, wfirst), zi), wlen)
        } else {
            iy
        };
        // All lanes inside: rows are monotone in j, so the ends bound them.
        let first = _mm512_cvtsi512_si32(iy);
        let last = _mm_extract_epi32::<3>(_mm512_extracti32x4_epi32::<3>(iy));
        let (lo, hi) = (first.min(last), first.max(last));
        // SAFETY: 0 ≤ iy ≤ len, so every tap lies in the columns' first len + 2
        // values; a window [lo, lo + 32) with lo ≤ len lies in the asserted length;
        // all below 2³¹ (checked by the caller); k + 16 ≤ out.len().
        unsafe {
            let (g00, g01, g10, g11) = if inside == 0xffff && hi - lo < 31 {
                let idx = _mm512_sub_epi32(iy, _mm512_set1_epi32(lo));
                let idx1 = _mm512_add_epi32(idx, _mm512_set1_epi32(1));
                let pick = |b: *const f32, i: __m512i| {
                    let w0 = _mm512_loadu_ps(b.add(lo as usize));
                    let w1 = _mm512_loadu_ps(b.add(lo as usize + 16));
                    _mm512_permutex2var_ps(w0, i, w1)
                };
                (pick(b0, idx), pick(b1, idx), pick(b0, idx1), pick(b1, idx1))
            } else {
                let iy1 = _mm512_add_epi32(iy, _mm512_set1_epi32(1));
                (
                    _mm512_i32gather_ps::<4>(iy, b0),
                    _mm512_i32gather_ps::<4>(iy, b1),
                    _mm512_i32gather_ps::<4>(iy1, b0),
                    _mm512_i32gather_ps::<4>(iy1, b1),
                )
            };
            let top = _mm512_add_ps(_mm512_mul_ps(g00, ux), _mm512_mul_ps(g01, tx));
            let bottom = _mm512_add_ps(_mm512_mul_ps(g10, ux), _mm512_mul_ps(g11, tx));
            let v = _mm512_mul_ps(
                w2,
                _mm512_add_ps(
                    _mm512_mul_ps(top, _mm512_sub_ps(one, ty)),
                    _mm512_mul_ps(bottom, ty),
                ),
            );
            let q = out.as_mut_ptr().add(k);
            let sum = _mm512_add_ps(_mm512_loadu_ps(q), _mm512_maskz_mov_ps(inside, v));
            _mm512_storeu_ps(q, sum);
        }
        k += 16;
    }
    n
}

/// [`column_line_from`] for f32, eight voxels at a time with AVX2 gathers (bit for bit
/// the same sums).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn column_line_f32x8<const BAND: bool>(
    out: &mut [f32],
    j0: usize,
    p: ColumnPair<f32>,
    rows: usize,
    window: Window,
    n1: f32,
    c1: f32,
    inv: f32,
) -> usize {
    use std::arch::x86_64::*;
    let len = window.len;
    assert!(p.c0.len() >= len + 2 && p.c1.len() >= len + 2);
    let (wfirst, wlen) = (
        _mm256_set1_epi32(window.first as i32),
        _mm256_set1_epi32(len as i32),
    );
    let n = out.len() / 8 * 8;
    let set = _mm256_set1_ps;
    let (one, zero) = (set(1.0), _mm256_setzero_ps());
    let lim = set((rows as f64 + 1.0) as f32);
    let (zi, mr) = (_mm256_setzero_si256(), _mm256_set1_epi32(rows as i32));
    let lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    let (vn1, vc1, vinv) = (set(n1), set(c1), set(inv));
    let (tx, ux, w2) = (set(p.tx), set(1.0 - p.tx), set(p.w2));
    let (b0, b1) = (p.c0.as_ptr(), p.c1.as_ptr());
    let mut k = 0;
    while k < n {
        let fj = _mm256_cvtepi32_ps(_mm256_add_epi32(_mm256_set1_epi32((j0 + k) as i32), lane));
        let t = _mm256_add_ps(
            _mm256_mul_ps(_mm256_add_ps(vn1, _mm256_mul_ps(fj, vc1)), vinv),
            one,
        );
        let inside = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GE_OQ>(t, zero),
            _mm256_cmp_ps::<_CMP_LT_OQ>(t, lim),
        );
        let t = _mm256_and_ps(inside, t);
        let iy = _mm256_min_epi32(_mm256_max_epi32(_mm256_cvttps_epi32(t), zi), mr);
        let ty = _mm256_sub_ps(t, _mm256_cvtepi32_ps(iy));
        // Window::local, lane by lane (the identity on whole columns).
        let iy = if BAND {
            _mm256_min_epi32(_mm256_max_epi32(_mm256_sub_epi32(iy, wfirst), zi), wlen)
        } else {
            iy
        };
        // SAFETY: as in column_line_f32x16.
        unsafe {
            let iy1 = _mm256_add_epi32(iy, _mm256_set1_epi32(1));
            let g = |b: *const f32, i: __m256i| _mm256_i32gather_ps::<4>(b, i);
            let (g00, g01, g10, g11) = (g(b0, iy), g(b1, iy), g(b0, iy1), g(b1, iy1));
            let top = _mm256_add_ps(_mm256_mul_ps(g00, ux), _mm256_mul_ps(g01, tx));
            let bottom = _mm256_add_ps(_mm256_mul_ps(g10, ux), _mm256_mul_ps(g11, tx));
            let v = _mm256_mul_ps(
                w2,
                _mm256_add_ps(
                    _mm256_mul_ps(top, _mm256_sub_ps(one, ty)),
                    _mm256_mul_ps(bottom, ty),
                ),
            );
            let q = out.as_mut_ptr().add(k);
            let sum = _mm256_add_ps(_mm256_loadu_ps(q), _mm256_and_ps(inside, v));
            _mm256_storeu_ps(q, sum);
        }
        k += 8;
    }
    n
}

fn to_r<R: Real>(v: DVec3) -> [R; 3] {
    [R::of(v.x), R::of(v.y), R::of(v.z)]
}

/// `out[i] += linear interpolation of the zero-bordered line (`line[c + 1]` = detector
/// column `c`) at `c = a + i·b``, zero outside `[−1, cols)` as [`bilinear_zero`].
///
/// `s_i = (a + 1) + i·b` is monotone in `i` (each rounding is monotone), so the voxels
/// with `s_i ∈ [0, cols + 1)` form one run: its ends are found analytically and then
/// corrected by testing, and the inner loop has no branch.
#[inline(always)]
fn interp_line<R: Real>(out: &mut [R], line: &[R], cols: usize, a: R, b: R) {
    let lim = R::of(cols as f64 + 1.0);
    let a1 = a + R::one();
    let n = out.len();
    let s_at = |i: usize| a1 + R::of(i as f64) * b;
    let inside = |i: usize| {
        let s = s_at(i);
        s >= R::zero() && s < lim
    };
    // Analytic estimate of the run, in f64.
    let (af, bf, lf) = (a1.f64(), b.f64(), lim.f64());
    let (lo_f, hi_f) = if bf > 0.0 {
        ((0.0 - af) / bf, (lf - af) / bf)
    } else if bf < 0.0 {
        ((lf - af) / bf, (0.0 - af) / bf)
    } else if inside(0) {
        (0.0, n as f64)
    } else {
        return;
    };
    let clampi = |x: f64| {
        if x.is_nan() {
            0
        } else {
            x.clamp(0.0, n as f64) as usize
        }
    };
    let mut lo = clampi(lo_f.ceil());
    let mut hi = clampi(hi_f.ceil());
    if lo >= hi {
        // Maybe an empty run, maybe rounding: test the neighbourhood.
        lo = lo.min(hi).saturating_sub(1);
        hi = (lo + 3).min(n);
        while lo < hi && !inside(lo) {
            lo += 1;
        }
        hi = lo;
        while hi < n && inside(hi) {
            hi += 1;
        }
    } else {
        while lo > 0 && inside(lo - 1) {
            lo -= 1;
        }
        while lo < hi && !inside(lo) {
            lo += 1;
        }
        while hi < n && inside(hi) {
            hi += 1;
        }
        while hi > lo && !inside(hi - 1) {
            hi -= 1;
        }
    }
    if lo >= hi {
        return;
    }
    // s ∈ [0, cols + 1) on lo..hi: truncation is the floor, ix ∈ [0, cols], and both
    // taps lie in the bordered line (length cols + 2).
    accumulate_run(&mut out[lo..hi], &line[..cols + 2], lo, a1, b);
}

/// The branch-free inner loop of [`interp_line`]: `out[k] += lerp(line, s)` with
/// `s = a1 + (lo + k)·b`, computed exactly as `s_at` there (so `s ∈ [0, len − 1)`).
/// On x86-64 CPUs with AVX2 and FMA the same code is also compiled for them and chosen
/// at run time: the loop then runs 8 (f32) or 4 (f64) voxels per instruction with
/// gathered taps. The arithmetic is the same either way (no contraction into FMAs), so
/// the result does not depend on the CPU.
#[inline]
fn accumulate_run<R: Real>(out: &mut [R], line: &[R], lo: usize, a1: R, b: R) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU has the features the function is compiled for.
            unsafe { accumulate_run_avx2(out, line, lo, a1, b) };
            return;
        }
    }
    accumulate_run_body(out, line, lo, a1, b);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn accumulate_run_avx2<R: Real>(out: &mut [R], line: &[R], lo: usize, a1: R, b: R) {
    if let (Some(out), Some(line)) = (as_f32_mut(out), as_f32(line)) {
        let (a1, b) = (a1.f64() as f32, b.f64() as f32);
        let done = unsafe { accumulate_run_f32x8(out, line, lo, a1, b) };
        let (out, line) = (&mut out[done..], line);
        // The tail, with the same arithmetic.
        accumulate_run_body(out, line, lo + done, a1, b);
        return;
    }
    accumulate_run_body(out, line, lo, a1, b);
}

/// [`accumulate_run_body`] for f32, eight voxels at a time with AVX2 gathers; the same
/// operations in the same order, so bit for bit the same sums. Returns how many leading
/// voxels it did (a multiple of 8); the caller does the rest.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn accumulate_run_f32x8(out: &mut [f32], line: &[f32], lo: usize, a1: f32, b: f32) -> usize {
    use std::arch::x86_64::*;
    let n = out.len() / 8 * 8;
    let last = _mm256_set1_epi32((line.len() - 2) as i32);
    let zero = _mm256_setzero_si256();
    let (va1, vb, one) = (_mm256_set1_ps(a1), _mm256_set1_ps(b), _mm256_set1_ps(1.0));
    let lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    let base = line.as_ptr();
    let mut k = 0;
    while k < n {
        let i = _mm256_add_epi32(_mm256_set1_epi32((lo + k) as i32), lane);
        // s = a1 + i·b (no FMA: the scalar loop rounds the product, then the sum).
        let s = _mm256_add_ps(va1, _mm256_mul_ps(_mm256_cvtepi32_ps(i), vb));
        let ix = _mm256_min_epi32(_mm256_max_epi32(_mm256_cvttps_epi32(s), zero), last);
        let t = _mm256_sub_ps(s, _mm256_cvtepi32_ps(ix));
        // SAFETY: 0 ≤ ix ≤ len − 2, so both taps lie in `line`; k + 8 ≤ out.len().
        unsafe {
            let l0 = _mm256_i32gather_ps::<4>(base, ix);
            let l1 = _mm256_i32gather_ps::<4>(base.add(1), ix);
            let p = out.as_mut_ptr().add(k);
            let acc = _mm256_loadu_ps(p);
            let sum = _mm256_add_ps(
                _mm256_add_ps(acc, _mm256_mul_ps(l0, _mm256_sub_ps(one, t))),
                _mm256_mul_ps(l1, t),
            );
            _mm256_storeu_ps(p, sum);
        }
        k += 8;
    }
    n
}

#[inline(always)]
fn accumulate_run_body<R: Real>(out: &mut [R], line: &[R], lo: usize, a1: R, b: R) {
    let last = line.len() - 2;
    let (lo, one) = (lo as i32, R::one());
    for (k, acc) in out.iter_mut().enumerate() {
        // Integers below 2^24 are exact in f32: the same s as `s_at(lo + k)`.
        let s = a1 + R::of((lo + k as i32) as f64) * b;
        // s ≥ 0, so truncation is the floor; the clamp changes nothing but lets the
        // compiler see both taps in bounds (no check, so the loop vectorises).
        let ix = ((s.f64() as i32).max(0) as usize).min(last);
        let t = s - R::of(ix as i32 as f64);
        *acc = *acc + line[ix] * (one - t) + line[ix + 1] * t;
    }
}

/// `out[i] += w_i² · bilinear_zero(view, c_i, r_i)` along one voxel line of a cone
/// beam, with `(c, r, den) = (a + i·b) / den` and `w = r30 / den`; `img` is the view's
/// `window` of rows zero-bordered to `(window.len + 2) × pcol` (the whole view when the
/// window is). Same arithmetic as [`backproject_point`].
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn cone_line<R: Real>(
    out: &mut [R],
    img: &[R],
    pcol: usize,
    [cols, rows]: [usize; 2],
    window: Window,
    a: [R; 3],
    b: [R; 3],
    r30: R,
) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU has the features the function is compiled for.
            unsafe { cone_line_avx2(out, img, pcol, [cols, rows], window, a, b, r30) };
            return;
        }
    }
    cone_line_from(out, 0, img, pcol, [cols, rows], window, a, b, r30);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn cone_line_avx2<R: Real>(
    out: &mut [R],
    img: &[R],
    pcol: usize,
    size: [usize; 2],
    window: Window,
    a: [R; 3],
    b: [R; 3],
    r30: R,
) {
    let short = img.len() < i32::MAX as usize;
    if let (true, Some(out), Some(img)) = (short, as_f32_mut(out), as_f32(img)) {
        let f = |v: [R; 3]| v.map(|x| x.f64() as f32);
        let (a, b, r30) = (f(a), f(b), r30.f64() as f32);
        let band = window.first != 0 || window.len != size[1];
        let done = match (std::arch::is_x86_feature_detected!("avx512f"), band) {
            (true, true) => unsafe {
                cone_line_f32x16::<true>(out, img, pcol, size, window, a, b, r30)
            },
            (true, false) => unsafe {
                cone_line_f32x16::<false>(out, img, pcol, size, window, a, b, r30)
            },
            (false, true) => unsafe {
                cone_line_f32x8::<true>(out, img, pcol, size, window, a, b, r30)
            },
            (false, false) => unsafe {
                cone_line_f32x8::<false>(out, img, pcol, size, window, a, b, r30)
            },
        };
        // The tail, with the same arithmetic (voxel indices continue at `done`).
        cone_line_from(out, done, img, pcol, size, window, a, b, r30);
        return;
    }
    cone_line_from(out, 0, img, pcol, size, window, a, b, r30);
}

/// [`cone_line_f32x8`] with AVX-512: sixteen voxels at a time, the same operations.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments)]
unsafe fn cone_line_f32x16<const BAND: bool>(
    out: &mut [f32],
    img: &[f32],
    pcol: usize,
    [cols, rows]: [usize; 2],
    window: Window,
    a: [f32; 3],
    b: [f32; 3],
    r30: f32,
) -> usize {
    use std::arch::x86_64::*;
    assert!(img.len() >= (window.len + 2) * pcol && pcol >= cols + 2);
    let (wfirst, wlen) = (
        _mm512_set1_epi32(window.first as i32),
        _mm512_set1_epi32(window.len as i32),
    );
    let n = out.len() / 16 * 16;
    let set = _mm512_set1_ps;
    let (one, zero) = (set(1.0), _mm512_setzero_ps());
    let (limc, limr) = (
        set((cols as f64 + 1.0) as f32),
        set((rows as f64 + 1.0) as f32),
    );
    let (mc, mr) = (
        _mm512_set1_epi32(cols as i32),
        _mm512_set1_epi32(rows as i32),
    );
    let (zi, vp) = (_mm512_setzero_si512(), _mm512_set1_epi32(pcol as i32));
    let lane = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    let line = |i: usize, fi: __m512| _mm512_add_ps(set(a[i]), _mm512_mul_ps(fi, set(b[i])));
    let base = img.as_ptr();
    let mut k = 0;
    while k < n {
        let fi = _mm512_cvtepi32_ps(_mm512_add_epi32(_mm512_set1_epi32(k as i32), lane));
        let (den, num0, num1) = (line(2, fi), line(0, fi), line(1, fi));
        let inv = _mm512_div_ps(one, den);
        let s = _mm512_add_ps(_mm512_mul_ps(num0, inv), one);
        let t = _mm512_add_ps(_mm512_mul_ps(num1, inv), one);
        let inside = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(den, zero)
            & _mm512_cmp_ps_mask::<_CMP_GE_OQ>(s, zero)
            & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(s, limc)
            & _mm512_cmp_ps_mask::<_CMP_GE_OQ>(t, zero)
            & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(t, limr);
        let s = _mm512_maskz_mov_ps(inside, s);
        let t = _mm512_maskz_mov_ps(inside, t);
        let w = _mm512_maskz_mov_ps(inside, _mm512_mul_ps(set(r30), inv));
        let ix = _mm512_min_epi32(_mm512_max_epi32(_mm512_cvttps_epi32(s), zi), mc);
        let iy = _mm512_min_epi32(_mm512_max_epi32(_mm512_cvttps_epi32(t), zi), mr);
        let tx = _mm512_sub_ps(s, _mm512_cvtepi32_ps(ix));
        let ty = _mm512_sub_ps(t, _mm512_cvtepi32_ps(iy));
        // Window::local, lane by lane (the identity on a whole view: iy ≤ rows).
        let ly = if BAND {
            _mm512_min_epi32(_mm512_max_epi32(_mm512_sub_epi32(iy, wfirst), zi), wlen)
        } else {
            iy
        };
        let p = _mm512_add_epi32(_mm512_mullo_epi32(ly, vp), ix);
        // SAFETY: as in cone_line_f32x8.
        unsafe {
            let g = |off: usize| _mm512_i32gather_ps::<4>(p, base.add(off));
            let (g00, g01, g10, g11) = (g(0), g(1), g(pcol), g(pcol + 1));
            let ux = _mm512_sub_ps(one, tx);
            let top = _mm512_add_ps(_mm512_mul_ps(g00, ux), _mm512_mul_ps(g01, tx));
            let bottom = _mm512_add_ps(_mm512_mul_ps(g10, ux), _mm512_mul_ps(g11, tx));
            let v = _mm512_add_ps(
                _mm512_mul_ps(top, _mm512_sub_ps(one, ty)),
                _mm512_mul_ps(bottom, ty),
            );
            let q = out.as_mut_ptr().add(k);
            let sum = _mm512_add_ps(_mm512_loadu_ps(q), _mm512_mul_ps(_mm512_mul_ps(w, w), v));
            _mm512_storeu_ps(q, sum);
        }
        k += 16;
    }
    n
}

/// [`cone_line_from`] for f32, eight voxels at a time with AVX2 gathers; the same
/// operations in the same order (outside voxels masked to weight 0 and clamped taps),
/// so bit for bit the same sums. Returns how many leading voxels it did (a multiple of
/// 8); the caller does the rest. Needs `img.len() < 2³¹`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn cone_line_f32x8<const BAND: bool>(
    out: &mut [f32],
    img: &[f32],
    pcol: usize,
    [cols, rows]: [usize; 2],
    window: Window,
    a: [f32; 3],
    b: [f32; 3],
    r30: f32,
) -> usize {
    use std::arch::x86_64::*;
    assert!(img.len() >= (window.len + 2) * pcol && pcol >= cols + 2);
    let (wfirst, wlen) = (
        _mm256_set1_epi32(window.first as i32),
        _mm256_set1_epi32(window.len as i32),
    );
    let n = out.len() / 8 * 8;
    let set = _mm256_set1_ps;
    let (one, zero) = (set(1.0), _mm256_setzero_ps());
    let (limc, limr) = (
        set((cols as f64 + 1.0) as f32),
        set((rows as f64 + 1.0) as f32),
    );
    let (mc, mr) = (
        _mm256_set1_epi32(cols as i32),
        _mm256_set1_epi32(rows as i32),
    );
    let (zi, vp) = (_mm256_setzero_si256(), _mm256_set1_epi32(pcol as i32));
    let lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    let line = |i: usize, fi: __m256| _mm256_add_ps(set(a[i]), _mm256_mul_ps(fi, set(b[i])));
    let base = img.as_ptr();
    let mut k = 0;
    while k < n {
        let fi = _mm256_cvtepi32_ps(_mm256_add_epi32(_mm256_set1_epi32(k as i32), lane));
        let (den, num0, num1) = (line(2, fi), line(0, fi), line(1, fi));
        let inv = _mm256_div_ps(one, den);
        let s = _mm256_add_ps(_mm256_mul_ps(num0, inv), one);
        let t = _mm256_add_ps(_mm256_mul_ps(num1, inv), one);
        // Ordered comparisons: NaN lanes are outside, as in the scalar test.
        let inside = _mm256_and_ps(
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GT_OQ>(den, zero),
                _mm256_and_ps(
                    _mm256_cmp_ps::<_CMP_GE_OQ>(s, zero),
                    _mm256_cmp_ps::<_CMP_LT_OQ>(s, limc),
                ),
            ),
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(t, zero),
                _mm256_cmp_ps::<_CMP_LT_OQ>(t, limr),
            ),
        );
        let s = _mm256_and_ps(inside, s);
        let t = _mm256_and_ps(inside, t);
        let w = _mm256_and_ps(inside, _mm256_mul_ps(set(r30), inv));
        let ix = _mm256_min_epi32(_mm256_max_epi32(_mm256_cvttps_epi32(s), zi), mc);
        let iy = _mm256_min_epi32(_mm256_max_epi32(_mm256_cvttps_epi32(t), zi), mr);
        let tx = _mm256_sub_ps(s, _mm256_cvtepi32_ps(ix));
        let ty = _mm256_sub_ps(t, _mm256_cvtepi32_ps(iy));
        // Window::local, lane by lane (the identity on a whole view: iy ≤ rows).
        let ly = if BAND {
            _mm256_min_epi32(_mm256_max_epi32(_mm256_sub_epi32(iy, wfirst), zi), wlen)
        } else {
            iy
        };
        let p = _mm256_add_epi32(_mm256_mullo_epi32(ly, vp), ix);
        // SAFETY: as in cone_line_from, p + pcol + 1 < (len + 2)·pcol ≤ img.len()
        // (asserted above, and below 2³¹ so the i32 offsets hold); k + 8 ≤ out.len().
        unsafe {
            let g = |off: usize| _mm256_i32gather_ps::<4>(base.add(off), p);
            let (g00, g01, g10, g11) = (g(0), g(1), g(pcol), g(pcol + 1));
            let ux = _mm256_sub_ps(one, tx);
            let top = _mm256_add_ps(_mm256_mul_ps(g00, ux), _mm256_mul_ps(g01, tx));
            let bottom = _mm256_add_ps(_mm256_mul_ps(g10, ux), _mm256_mul_ps(g11, tx));
            let v = _mm256_add_ps(
                _mm256_mul_ps(top, _mm256_sub_ps(one, ty)),
                _mm256_mul_ps(bottom, ty),
            );
            let q = out.as_mut_ptr().add(k);
            let sum = _mm256_add_ps(_mm256_loadu_ps(q), _mm256_mul_ps(_mm256_mul_ps(w, w), v));
            _mm256_storeu_ps(q, sum);
        }
        k += 8;
    }
    n
}

/// The loop of [`cone_line`] from voxel `start` on, branch-free so that it vectorises: a voxel outside the
/// detector (or behind the source) gets weight 0 and clamped, in-bounds taps instead
/// of a skipped iteration — the same sums, since adding `0·tap` leaves a finite sum
/// unchanged.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn cone_line_from<R: Real>(
    out: &mut [R],
    start: usize,
    img: &[R],
    pcol: usize,
    [cols, rows]: [usize; 2],
    window: Window,
    a: [R; 3],
    b: [R; 3],
    r30: R,
) {
    let (limc, limr) = (R::of(cols as f64 + 1.0), R::of(rows as f64 + 1.0));
    let (zero, one) = (R::zero(), R::one());
    assert!(img.len() >= (window.len + 2) * pcol && pcol >= cols + 2);
    for (k, acc) in out.iter_mut().enumerate().skip(start) {
        // Integers below 2^24 are exact in f32.
        let fi = R::of(k as i32 as f64);
        let den = a[2] + fi * b[2];
        let (num0, num1) = (a[0] + fi * b[0], a[1] + fi * b[1]);
        let inv = one / den;
        // bilinear_zero's ⌊c⌋ ∈ [−1, cols) and ⌊r⌋ ∈ [−1, rows), shifted by one into
        // the bordered image, where truncation is the floor.
        let (s, t) = (num0 * inv + one, num1 * inv + one);
        let inside = den > zero && s >= zero && s < limc && t >= zero && t < limr;
        let (s, t, w) = if inside {
            (s, t, r30 * inv)
        } else {
            (zero, zero, zero)
        };
        let ix = ((s.f64() as i32).max(0) as usize).min(cols);
        let iy = ((t.f64() as i32).max(0) as usize).min(rows);
        let (tx, ty) = (s - R::of(ix as i32 as f64), t - R::of(iy as i32 as f64));
        let p = window.local(iy) * pcol + ix;
        // SAFETY: ix ≤ cols and local(iy) ≤ len, so p + pcol + 1 ≤ (len + 1)·pcol + cols
        // + 1 < (len + 2)·pcol ≤ img.len() (asserted above).
        let tap = |q: usize| unsafe { *img.get_unchecked(q) };
        let top = tap(p) * (one - tx) + tap(p + 1) * tx;
        let bottom = tap(p + pcol) * (one - tx) + tap(p + pcol + 1) * tx;
        *acc = *acc + w * w * (top * (one - ty) + bottom * ty);
    }
}

/// Zeroes every voxel outside the disc of radius `n//2` about `(n//2, n//2)` in each
/// z-slice (scikit-image's `circle=True` output), `n = dims[0] = dims[1]`.
pub fn apply_circle_mask<R: Real>(vol: &mut Reconstruction<R>) -> Result<()> {
    let d = vol.grid.dims;
    circle_mask_region(d, &Region::all(d), &mut vol.data)
}

/// [`apply_circle_mask`] on the voxels of `region` of a grid of `dims` (in the
/// region's order, as [`backproject_region`] returns them): the disc is the whole
/// grid's, so the regions of a grid masked one by one equal the grid masked at once.
///
/// # Errors
/// Slices that are not square; `data` not the region's size.
pub fn circle_mask_region<R: Real>(
    dims: [usize; 3],
    region: &Region,
    data: &mut [R],
) -> Result<()> {
    if dims[0] != dims[1] {
        return Err(Error::invalid(
            "circle mask",
            format!("needs square slices, got {}×{}", dims[0], dims[1]),
        ));
    }
    if data.len() != region.voxels(dims[0]) {
        return Err(Error::invalid(
            "circle mask",
            format!(
                "{} values for a region of {} voxels",
                data.len(),
                region.voxels(dims[0])
            ),
        ));
    }
    let (nx, nj) = (dims[0], region.j.len());
    let r = (dims[0] / 2) as i64;
    for (idx, v) in data.iter_mut().enumerate() {
        let i = (idx % nx) as i64 - r;
        let j = (region.j.start + (idx / nx) % nj) as i64 - r;
        if i * i + j * j > r * r {
            *v = R::zero();
        }
    }
    Ok(())
}

/// FBP/FDK: [`filter_projections`] (FFT path) with `filter`, then [`backproject`] onto
/// `grid`.
pub fn fbp<R: Real + FftNum>(
    projections: &Projections<R>,
    g: &Geometry,
    filter: RampFilter,
    grid: &Grid,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Reconstruction<R>> {
    let q = filter_projections(projections, g, filter, FilterMethod::Fft)?;
    backproject(&q, g, grid, progress)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic pseudo-random value in [−1, 1).
    fn noise(i: usize) -> f32 {
        let x = (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 40;
        (x as f32 / (1u64 << 23) as f32) - 1.0
    }

    /// The vectorised f32 loops give the scalar loops' sums bit for bit, over lines
    /// that start and end inside, outside and across the detector, with tails.
    #[test]
    fn simd_loops_equal_the_scalar_loops_bit_for_bit() {
        let cols = 37;
        let line: Vec<f32> = (0..cols + 2)
            .map(|i| {
                if i == 0 || i == cols + 1 {
                    0.0
                } else {
                    noise(i)
                }
            })
            .collect();
        for (n, a, b) in [
            (61, -3.7f32, 0.71f32),
            (29, 40.2, -1.3),
            (8, 0.5, 0.0),
            (100, -9.1, 0.43),
        ] {
            let mut fast: Vec<f32> = (0..n).map(|i| noise(i + 1000)).collect();
            let mut slow = fast.clone();
            interp_line(&mut fast, &line, cols, a, b);
            // The scalar body over the run interp_line chose: recompute it the same way.
            let mut reference = slow.clone();
            let s_at = |i: usize| a + 1.0 + i as f32 * b;
            let inside: Vec<usize> = (0..n)
                .filter(|&i| s_at(i) >= 0.0 && s_at(i) < cols as f32 + 1.0)
                .collect();
            if let (Some(&lo), Some(&hi)) = (inside.first(), inside.last()) {
                accumulate_run_body(&mut reference[lo..=hi], &line, lo, a + 1.0, b);
            }
            slow.copy_from_slice(&reference);
            assert_eq!(fast, slow, "n {n}, a {a}, b {b}");
        }
        // Cone beam: a 23 × 17 view, bordered; the whole view and a band of its
        // rows (whose taps are clamped into the band).
        let (cols, rows) = (23, 17);
        let pcol = cols + 2;
        for window in [
            Window {
                first: 0,
                len: rows,
            },
            Window { first: 5, len: 6 },
        ] {
            let len = window.len;
            let img: Vec<f32> = (0..(len + 2) * pcol)
                .map(|q| {
                    let (r, c) = (q / pcol, q % pcol);
                    if r == 0 || r == len + 1 || c == 0 || c == cols + 1 {
                        0.0
                    } else {
                        noise(q)
                    }
                })
                .collect();
            for (n, a, b) in [
                (53, [-5.0f32, 3.0, 1.2], [0.61, 0.2, 0.013]),
                (19, [30.0, -2.0, 0.9], [-1.7, 0.9, -0.02]),
                (40, [2.0, 8.0, -0.5], [0.3, 0.1, 0.05]),
            ] {
                let mut fast: Vec<f32> = (0..n).map(|i| noise(i + 7)).collect();
                let mut slow = fast.clone();
                cone_line(&mut fast, &img, pcol, [cols, rows], window, a, b, 0.8);
                cone_line_from(&mut slow, 0, &img, pcol, [cols, rows], window, a, b, 0.8);
                assert_eq!(fast, slow, "n {n}, {window:?}");
            }
        }
        // Cone beam along the rotation axis: two bordered columns of 40 rows plus the
        // 32-value overhang; rows spread less and more than a 32-wide window, voxels
        // entering and leaving the detector, ascending and descending.
        let rows = 40;
        let col = |seed: usize| -> Vec<f32> {
            (0..rows + 2 + 32)
                .map(|r| {
                    if r == 0 || r > rows {
                        0.0
                    } else {
                        noise(r + seed)
                    }
                })
                .collect()
        };
        let (c0, c1) = (col(11), col(500));
        // The whole columns, and a band of rows 6..26 read from the same values (the
        // band's copies need only be long enough).
        for window in [
            Window {
                first: 0,
                len: rows,
            },
            Window { first: 6, len: 20 },
        ] {
            for (n, n1, c1s, inv) in [
                (64, 3.0f32, 0.7f32, 0.9f32),
                (37, -10.0, 1.1, 0.8),
                (50, 45.0, -0.6, 1.05),
                (48, 1.0, 3.5, 0.7),
                (16, 2.0, 0.0, 1.0),
            ] {
                let pair = ColumnPair {
                    c0: &c0,
                    c1: &c1,
                    tx: 0.37,
                    w2: 1.3,
                };
                let mut fast: Vec<f32> = (0..n).map(|i| noise(i + 3)).collect();
                let mut slow = fast.clone();
                column_line(&mut fast, 0, pair, rows, window, n1, c1s, inv);
                column_line_from(&mut slow, 0, 0, pair, rows, window, n1, c1s, inv);
                assert_eq!(fast, slow, "n {n}, n1 {n1}, c1 {c1s}, {window:?}");
                assert!(slow.iter().any(|&x| x != 0.0));
            }
        }
    }
}
