//! Empty-space skipping and the clipping box: which parts of a ray can hold a visible
//! sample, decided without sampling.
//!
//! **The min/max grid** (Gavrilov & Turlapov, "acceleration structures"): the volume is
//! cut into cells of `B³` voxels (`B` = `RenderSettings::block_size`, 32 by default).
//! Cell `c` covers the index-space region `[cB − ½, (c+1)B − ½)` per axis, and it stores
//! the minimum and maximum of every voxel the reconstruction filter can read for a
//! sample in that region: the voxels `cB − r − 1 ..= (c+1)B + r` (filter radius `r`, one
//! more voxel each side for rounding of the sample position). With post-classification
//! the voxels are what the filter samples (the B-spline coefficients for
//! `bspline-interp`); with pre-classification the voxel values themselves.
//!
//! **Emptiness in O(1)**: a filter with non-negative weights that sum to one
//! (nearest, trilinear, both B-splines) interpolates inside `[min, max]`. Filters with
//! negative lobes (Catmull–Rom, Lanczos) overshoot by at most `e·(max − min)` on each
//! side, `e = (L³ − 1)/2`, where `L = max_f Σ|w_i(f)|` is the 1D Lebesgue constant (the
//! positive weights of the 3D product sum to `(L³ + 1)/2`). The LUT classifies value
//! `t` at table coordinate `x = scale·t + offset` by linear interpolation between
//! entries `⌊x⌋` and `⌊x⌋ + 1`, so every sample of the cell is transparent when all
//! entries `⌊x(min)⌋ − 1 ..= ⌊x(max)⌋ + 2` have zero opacity. A prefix count of
//! non-zero opacities, `P[i] = #{j < i : α_j > 0}`, answers that with one subtraction
//! and is rebuilt in O(LUT) when the transfer function changes; the grid itself does
//! not depend on the transfer function.
//!
//! **The walk** (Amanatides & Woo 1987): a ray steps from cell to cell through the
//! grid, always crossing the nearest cell boundary next, and returns the parameter
//! spans of maximal runs of non-empty cells. The ray caster keeps the sample positions
//! of the unskipped ray, `t_k` = midpoint of step `k`: a span `[t_a, t_b]` becomes the
//! sample indices `⌊(t_a − t_s)/Δt − ½⌋ − 1 ..= ⌈(t_b − t_s)/Δt − ½⌉ + 1`, so a skip only
//! jumps `k` forward. Every skipped sample is transparent and would have been
//! discarded (`α ≤ 0`) anyway: the image is bit-identical with skipping on or off.
//! Back-to-front rays walk the reversed ray, `o − d·s` with `s = −t`.
//!
//! Skipping is off for MIP, MinIP and X-ray (they never look at the transfer function:
//! every sample counts), for the full sinc (its footprint is the whole grid), and for
//! pre-classified `bspline-interp` (the prefiltered opacity volume is non-zero
//! everywhere).
//!
//! **Clipping box**: the ray's parameter interval is intersected with the box, given
//! in voxel indices (voxels `lo ..= hi`, index space `[lo − ½, hi + ½]`) or in world
//! millimetres (intersected with the world-space ray directly).
//!
//! WGSL twins of the per-ray helpers: `shaders/shared/skip.wgsl`; the grid is built on
//! the GPU by `shaders/skip_minmax.wgsl` (`gpu::skip`).

use super::filter::axis_taps;
use super::grid::{Grid, MinMax};
use crate::real::{intersect_box, Real, V3};
use crate::settings::{Classification, ClipBox, ClipSpace, Filter, Mode, RenderSettings};
use crate::transfer::LutR;
use rayon::prelude::*;

/// "No boundary" along an axis the ray does not move on.
const BIG: f64 = 3.0e38;

/// The filter radius the min/max grid must cover, or `None` when skipping does not
/// apply to these settings (off, not DVR, full sinc, pre-classified `bspline-interp`,
/// a 2D transfer function, whose opacity depends on the gradient too: the 1D table's
/// emptiness says nothing about it, or iso-surfaces, which can lie where the table is
/// transparent).
pub fn skip_radius(settings: &RenderSettings) -> Option<usize> {
    if !settings.skip_empty
        || settings.mode != Mode::Dvr
        || settings.transfer_2d.is_some()
        || !settings.iso_surfaces.is_empty()
    {
        return None;
    }
    match (settings.filter, settings.classification) {
        (Filter::Sinc, _) => None,
        (f, Classification::Pre) if f.prefiltered() => None,
        (f, _) => Some(f.radius()),
    }
}

/// The 1D Lebesgue constant `L = max_f Σ|w_i(f)|` of a truncated filter, from 4096
/// fractional positions and raised by 0.1 % (the maximum lies between samples).
pub fn lebesgue_1d(filter: Filter) -> f64 {
    match filter {
        Filter::Nearest
        | Filter::Trilinear
        | Filter::Bspline
        | Filter::BsplineInterp
        | Filter::BsplineFast
        | Filter::BsplineFastInterp => 1.0,
        Filter::Sinc => f64::INFINITY,
        _ => {
            let mut l = 1.0f64;
            for i in 0..=4096 {
                let t = axis_taps::<f64>(filter, i as f64 / 4096.0);
                let s: f64 = t.w[..t.count].iter().map(|w| w.abs()).sum();
                l = l.max(s);
            }
            l * 1.001
        }
    }
}

/// The overshoot factor `e = (L³ − 1)/2` of a sample beyond its footprint's
/// `[min, max]` (zero for pre-classification: voxels are classified exactly, and a
/// footprint of zero opacities interpolates to zero).
pub fn overshoot(filter: Filter, classification: Classification) -> f64 {
    if classification == Classification::Pre {
        return 0.0;
    }
    let l = lebesgue_1d(filter);
    (l * l * l - 1.0) / 2.0
}

/// Cells per axis for `dims` voxels and blocks of `block`.
pub fn cell_count(dims: [usize; 3], block: usize) -> [usize; 3] {
    dims.map(|n| n.div_ceil(block))
}

/// The voxels (inclusive, clamped to `0 ..= n − 1`) a sample in cell `c` can read.
/// Mirrors `shaders/skip_minmax.wgsl: footprint`.
pub fn footprint(c: usize, n: usize, block: usize, radius: usize) -> (usize, usize) {
    let lo = (c * block).saturating_sub(radius + 1);
    let hi = ((c + 1) * block + radius).min(n - 1);
    (lo, hi)
}

/// One `[min, max]` per cell, x fastest.
#[derive(Clone, Debug, PartialEq)]
pub struct MinMaxGrid<R> {
    pub block: usize,
    pub radius: usize,
    pub cells: [usize; 3],
    pub minmax: Vec<[R; 2]>,
}

/// Builds the min/max grid of `grid` for cells of `block` voxels and a filter of
/// `radius` (see the module docs for the footprint).
pub fn min_max_grid<R: Real>(grid: &Grid<R>, block: usize, radius: usize) -> MinMaxGrid<R> {
    let dims = grid.dims;
    let cells = cell_count(dims, block);
    let minmax = (0..cells[0] * cells[1] * cells[2])
        .into_par_iter()
        .map(|c| {
            let (cx, cy, cz) = (
                c % cells[0],
                (c / cells[0]) % cells[1],
                c / (cells[0] * cells[1]),
            );
            let (x0, x1) = footprint(cx, dims[0], block, radius);
            let (y0, y1) = footprint(cy, dims[1], block, radius);
            let (z0, z1) = footprint(cz, dims[2], block, radius);
            let mut m = MinMax::new();
            for z in z0..=z1 {
                for y in y0..=y1 {
                    let row = dims[0] * (y + dims[1] * z);
                    m.add(&grid.data[row + x0..=row + x1]);
                }
            }
            let (lo, hi) = m.get();
            [lo, hi]
        })
        .collect();
    MinMaxGrid {
        block,
        radius,
        cells,
        minmax,
    }
}

/// The transfer function's opacity as a prefix count, with the LUT's table map.
#[derive(Clone, Debug, PartialEq)]
pub struct OpacityPrefix<R> {
    /// `prefix[i]` = number of entries `j < i` with `α_j > 0` (`entries + 1` values).
    pub prefix: Vec<u32>,
    pub scale: R,
    pub offset: R,
    /// Overshoot factor `e` (see [`overshoot`]).
    pub expand: R,
    /// Relative widening of `[min, max]` for the rounding of the interpolation
    /// (1024 ε of the working precision).
    pub margin: R,
}

/// The prefix count of `lut`'s opacities; `expand` from [`overshoot`].
pub fn opacity_prefix<R: Real>(lut: &LutR<R>, expand: f64) -> OpacityPrefix<R> {
    let mut prefix = Vec::with_capacity(lut.entries.len() + 1);
    let mut count = 0u32;
    prefix.push(0);
    for e in &lut.entries {
        count += (e[3] > R::zero()) as u32;
        prefix.push(count);
    }
    OpacityPrefix {
        prefix,
        scale: lut.scale,
        offset: lut.offset,
        expand: R::of(expand),
        margin: R::epsilon() * R::of(1024.0),
    }
}

impl<R: Real> OpacityPrefix<R> {
    /// Whether every value a sample with footprint range `[lo, hi]` can take is fully
    /// transparent. Mirrors `shaders/shared/skip.wgsl: range_empty`.
    pub fn range_empty(&self, lo: R, hi: R) -> bool {
        let n = self.prefix.len() - 1;
        let last = R::of((n - 1) as f64);
        let w = hi - lo;
        let m = self.margin * lo.abs().max(hi.abs()) + self.margin;
        let a = lo - self.expand * w - m;
        let b = hi + self.expand * w + m;
        let xa = self.scale * a + self.offset;
        let xb = self.scale * b + self.offset;
        let x0 = xa.min(xb).max(R::zero()).min(last);
        let x1 = xa.max(xb).max(R::zero()).min(last);
        let i0 = x0.floor().to_usize().unwrap_or(0).saturating_sub(1);
        let i1 = (x1.floor().to_usize().unwrap_or(n - 1) + 2).min(n - 1);
        self.prefix[i1 + 1] == self.prefix[i0]
    }
}

/// Min/max grids already built for one prepared volume, by the address of the voxels
/// they bound (see [`Skipper::cached`]).
pub type MinMaxCache<R> = std::sync::Mutex<Vec<(usize, std::sync::Arc<MinMaxGrid<R>>)>>;

/// What a ray needs to skip: the grid and the transfer function's prefix count.
#[derive(Clone, Debug)]
pub struct Skipper<R> {
    pub grid: std::sync::Arc<MinMaxGrid<R>>,
    pub tf: OpacityPrefix<R>,
    /// `tf.range_empty` of every cell, worked out once.
    empty: Vec<bool>,
    /// Per class of ray directions (see [`direction_runs`]), made when a ray first
    /// needs it: the side of the box of cells of one kind (empty or not) ahead of each
    /// cell, so that a walk may leap across it (see [`CellWalk::next_span_leaping`]).
    runs: [std::sync::OnceLock<Vec<u8>>; 27],
}

impl<R: Real> Skipper<R> {
    /// Builds the grid over `voxels` (see the module docs for which voxels) and the
    /// prefix count of `lut` for `settings`; `None` when skipping does not apply.
    pub fn new(voxels: &Grid<R>, lut: &LutR<R>, settings: &RenderSettings) -> Option<Self> {
        Self::cached(voxels, lut, settings, None)
    }

    /// [`Skipper::new`], taking the min/max grid from `cache` when it holds one for
    /// these voxels, block size and filter reach, and adding the one it builds
    /// otherwise.
    pub fn cached(
        voxels: &Grid<R>,
        lut: &LutR<R>,
        settings: &RenderSettings,
        cache: Option<&MinMaxCache<R>>,
    ) -> Option<Self> {
        use std::sync::Arc;
        let radius = skip_radius(settings)?;
        let block = settings.block_size;
        // The grid's voxels are named by their address: a cache belongs to one
        // prepared volume, whose grids live as long as it does.
        let voxels_at = voxels.data.as_ptr() as usize;
        let found = cache.and_then(|c| {
            let c = c.lock().unwrap_or_else(|e| e.into_inner());
            c.iter()
                .find(|(at, g)| *at == voxels_at && g.block == block && g.radius == radius)
                .map(|(_, g)| g.clone())
        });
        let grid = found.unwrap_or_else(|| {
            let g = Arc::new(min_max_grid(voxels, block, radius));
            if let Some(c) = cache {
                c.lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .push((voxels_at, g.clone()));
            }
            g
        });
        let tf = opacity_prefix(lut, overshoot(settings.filter, settings.classification));
        let empty = grid
            .minmax
            .iter()
            .map(|&[lo, hi]| tf.range_empty(lo, hi))
            .collect::<Vec<bool>>();
        Some(Skipper {
            grid,
            tf,
            empty,
            runs: Default::default(),
        })
    }

    /// The side of the box of cells of `c`'s kind ahead of cell `c` for rays of
    /// direction class `class` (see [`direction_runs`]).
    #[inline]
    pub fn cell_run(&self, c: [i32; 3], class: usize) -> u8 {
        let n = self.grid.cells;
        let run = self.runs[class].get_or_init(|| direction_runs(&self.empty, n, class));
        run[c[0] as usize + n[0] * (c[1] as usize + n[1] * c[2] as usize)]
    }

    /// Whether cell `c` is transparent. Mirrors `shaders/shared/skip.wgsl: cell_empty`.
    #[inline]
    pub fn cell_empty(&self, c: [i32; 3]) -> bool {
        let n = self.grid.cells;
        self.empty[c[0] as usize + n[0] * (c[1] as usize + n[1] * c[2] as usize)]
    }

    /// Whether every cell is transparent (nothing to render at all).
    pub fn all_empty(&self) -> bool {
        self.empty.iter().all(|&e| e)
    }
}

/// The class of a direction whose steps along the axes are `step` (each −1, 0 or
/// 1): `Σ_a code_a·3^a`, code 0 for +1, 1 for −1, 2 for 0.
pub fn direction_class(step: [i32; 3]) -> usize {
    (0..3)
        .map(|a| {
            let code = match step[a] {
                1 => 0,
                -1 => 1,
                _ => 2,
            };
            code * 3usize.pow(a as u32)
        })
        .sum()
}

/// The steps `s` (each −1, 0 or 1) of direction class `class` ([`direction_class`]).
fn class_steps(class: usize) -> [i64; 3] {
    [0, 1, 2].map(|a| [1, -1, 0][class / 3usize.pow(a) % 3])
}

/// Per cell of a grid of `cells` whose kinds are `kind`, for the rays of direction
/// class `class` (steps `s` along the axes, [`direction_class`]), the side `m` of the
/// largest box of cells with the cell at its corner, extending from it the way those
/// rays travel, all of whose cells inside the grid are of the cell's kind: cells
/// `c + i∘s`, `i_a ∈ [0, m − 1]` (`i_a = 0` along an axis the rays do not move along).
/// Capped at 255 (also where the box reaches the grid's far faces). Dynamic
/// programming over the cells ahead of each cell: `m(c) = 1 + min m(c + e∘s)` over
/// `e ∈ {0, 1}³ \ {0}` with `e_a = 0` where `s_a = 0`, 1 when one of them is of the
/// other kind, and a cell ahead outside the grid bounds nothing. Rays along an axis
/// (the orthographic axis views) thus leap along columns of cells, whatever lies beside
/// them.
pub fn direction_runs(kind: &[bool], cells: [usize; 3], class: usize) -> Vec<u8> {
    let [nx, ny, nz] = cells.map(|n| n as i64);
    let at = |x: i64, y: i64, z: i64| (x + nx * (y + ny * z)) as usize;
    let s = class_steps(class);
    // Visit the cells ahead first: against the direction along every axis.
    let order = |n: i64, s: i64| -> Box<dyn Iterator<Item = i64>> {
        if s > 0 {
            Box::new((0..n).rev())
        } else {
            Box::new(0..n)
        }
    };
    let ahead: Vec<[i64; 3]> = (1..8)
        .map(|e: i64| [e & 1, e >> 1 & 1, e >> 2 & 1])
        .filter(|e| (0..3).all(|a| e[a] == 0 || s[a] != 0))
        .map(|e| [e[0] * s[0], e[1] * s[1], e[2] * s[2]])
        .collect();
    let mut run = vec![255u8; kind.len()];
    for z in order(nz, s[2]) {
        for y in order(ny, s[1]) {
            for x in order(nx, s[0]) {
                let here = at(x, y, z);
                let mut m = 255u8;
                for e in &ahead {
                    let (u, v, w) = (x + e[0], y + e[1], z + e[2]);
                    if !((0..nx).contains(&u) && (0..ny).contains(&v) && (0..nz).contains(&w)) {
                        continue;
                    }
                    let there = at(u, v, w);
                    if kind[there] != kind[here] {
                        m = 1;
                        break;
                    }
                    m = m.min(run[there].saturating_add(1));
                }
                run[here] = m;
            }
        }
    }
    run
}

/// An Amanatides–Woo walk through the cells of a grid along `o + d·t`, `t ∈ [t, t_end]`.
/// Mirrors `shaders/shared/skip.wgsl: CellWalk` (walk_new, walk_boundaries, walk_advance).
#[derive(Clone, Copy, Debug)]
pub struct CellWalk<R> {
    o: V3<R>,
    d: V3<R>,
    cell: [i32; 3],
    step: [i32; 3],
    cells: [i32; 3],
    /// The direction class of `d`, for [`direction_runs`].
    class: usize,
    block: R,
    t: R,
    t_end: R,
}

impl<R: Real> CellWalk<R> {
    /// Starts at `o + d·t0` (clamped into the grid). Mirrors `shaders/shared/skip.wgsl: walk_new`.
    pub fn new(o: V3<R>, d: V3<R>, t0: R, t1: R, block: usize, cells: [usize; 3]) -> Self {
        let b = R::of(block as f64);
        let p = o + d * t0;
        let mut cell = [0i32; 3];
        let mut step = [0i32; 3];
        for a in 0..3 {
            let c = ((p.0[a] + R::of(0.5)) / b)
                .floor()
                .max(R::zero())
                .min(R::of(cells[a] as f64 - 1.0));
            cell[a] = c.to_i32().unwrap_or(0);
            step[a] = if d.0[a] > R::zero() {
                1
            } else if d.0[a] < R::zero() {
                -1
            } else {
                0
            };
        }
        CellWalk {
            o,
            d,
            cell,
            step,
            cells: cells.map(|c| c as i32),
            class: direction_class(step),
            block: b,
            t: t0,
            t_end: t1,
        }
    }

    /// The parameter at which the walk leaves the current cell along axis `a`.
    /// Mirrors `shaders/shared/skip.wgsl: walk_boundaries`.
    #[inline]
    fn boundary(&self, a: usize) -> R {
        self.boundary_beyond(a, 0)
    }

    /// The parameter at which the walk leaves the cell `m` cells further along axis
    /// `a` (in its direction of travel).
    #[inline]
    fn boundary_beyond(&self, a: usize, m: i32) -> R {
        if self.step[a] == 0 {
            return R::of(BIG);
        }
        let edge = self.cell[a] + self.step[a] * m + (self.step[a] > 0) as i32;
        (R::of(edge as f64) * self.block - R::of(0.5) - self.o.0[a]) / self.d.0[a]
    }

    /// Crosses the nearest boundary. Mirrors `shaders/shared/skip.wgsl: walk_advance`.
    #[inline]
    fn advance(&mut self) {
        let b = [self.boundary(0), self.boundary(1), self.boundary(2)];
        let xy = (b[1] < b[0]) as usize;
        let a = if b[2] < b[xy] { 2 } else { xy };
        self.t = self.t.max(b[a]);
        self.cell[a] += self.step[a];
    }

    #[inline]
    fn active(&self) -> bool {
        self.t < self.t_end && (0..3).all(|a| self.cell[a] >= 0 && self.cell[a] < self.cells[a])
    }

    /// Leaps out of the box of cells from the current one to `m ≥ 1` cells ahead
    /// along every axis it travels (all of its kind): to where the ray leaves the box,
    /// into the cell there.
    #[inline(always)]
    fn leap(&mut self, m: i32) {
        let b = [
            self.boundary_beyond(0, m),
            self.boundary_beyond(1, m),
            self.boundary_beyond(2, m),
        ];
        let xy = (b[1] < b[0]) as usize;
        let a = if b[2] < b[xy] { 2 } else { xy };
        let t = self.t.max(b[a]);
        for (q, c) in self.cell.iter_mut().enumerate() {
            if q == a {
                *c += self.step[q] * (m + 1);
            } else if self.step[q] != 0 {
                // The cell along q at t, held inside the box against rounding.
                let p = self.o.0[q] + self.d.0[q] * t;
                let x = (p + R::of(0.5)) / self.block;
                // ⌊x⌋ by truncation, one down for negative non-integers.
                let mut k = x.to_i32().unwrap_or(*c);
                if R::of(k as f64) > x {
                    k -= 1;
                }
                let ahead = *c + self.step[q] * m;
                *c = k.clamp((*c).min(ahead), (*c).max(ahead));
            }
        }
        self.t = t;
    }

    /// One leap, or one cell where the current one borders the other kind.
    #[inline(always)]
    fn go(&mut self, skip: &Skipper<R>) {
        let r = skip.cell_run(self.cell, self.class) as i32;
        if r >= 2 {
            self.leap(r - 1);
        } else {
            self.advance();
        }
    }

    /// [`CellWalk::next_span`] over `skip`'s cells, leaping across boxes of cells of
    /// one kind ahead of the ray ([`Skipper::cell_run`]) instead of stepping through
    /// each: the same spans, up to rounding where the ray grazes a box's corner (and
    /// spans only bound which steps are sampled; a sample in an empty cell is
    /// transparent anyway).
    pub fn next_span_leaping(&mut self, skip: &Skipper<R>) -> Option<(R, R)> {
        while self.active() && skip.cell_empty(self.cell) {
            self.go(skip);
        }
        if !self.active() {
            return None;
        }
        let start = self.t;
        loop {
            self.go(skip);
            if !self.active() || skip.cell_empty(self.cell) {
                break;
            }
        }
        Some((start, self.t.min(self.t_end)))
    }

    /// The next span `[t_a, t_b]` of consecutive non-empty cells, or `None` when the
    /// ray has left the grid or its interval. Mirrors `shaders/shared/skip.wgsl: walk_next_span`.
    pub fn next_span(&mut self, empty: impl Fn([i32; 3]) -> bool) -> Option<(R, R)> {
        while self.active() && empty(self.cell) {
            self.advance();
        }
        if !self.active() {
            return None;
        }
        let start = self.t;
        loop {
            self.advance();
            if !self.active() || empty(self.cell) {
                break;
            }
        }
        Some((start, self.t.min(self.t_end)))
    }
}

/// The sample indices of a ray, in the order they are composited, as inclusive ranges
/// `[k_lo, k_hi]`: all of `0 .. n` without skipping, only those near non-empty cells
/// with it. Step `k` covers `[t_s + kΔt, t_s + (k+1)Δt] ∩ [t_in, t_out]`.
/// Mirrors `shaders/shared/skip.wgsl: SampleRanges`.
#[derive(Clone, Copy, Debug)]
pub struct SampleRanges<R> {
    walk: Option<CellWalk<R>>,
    backward: bool,
    t_s: R,
    dt: R,
    n: i64,
    /// Front to back: the first index not yet handed out; back to front: one past the
    /// last index not yet handed out.
    next: i64,
}

impl<R: Real> SampleRanges<R> {
    /// Ranges for `n` steps from `t_s` of `dt` along `o + d·t`, `t ∈ [t_in, t_out]`;
    /// `backward` hands them out last first. Mirrors `shaders/shared/skip.wgsl: ranges_new`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        skip: Option<&Skipper<R>>,
        o: V3<R>,
        d: V3<R>,
        (t_in, t_out): (R, R),
        t_s: R,
        dt: R,
        n: usize,
        backward: bool,
    ) -> Self {
        let walk = skip.map(|s| {
            if backward {
                CellWalk::new(o, -d, -t_out, -t_in, s.grid.block, s.grid.cells)
            } else {
                CellWalk::new(o, d, t_in, t_out, s.grid.block, s.grid.cells)
            }
        });
        SampleRanges {
            walk,
            backward,
            t_s,
            dt,
            n: n as i64,
            next: if backward { n as i64 } else { 0 },
        }
    }

    /// The next range, or `None` when the ray is done. Mirrors `shaders/shared/skip.wgsl: ranges_next`.
    pub fn next(&mut self, skip: Option<&Skipper<R>>) -> Option<(usize, usize)> {
        let (Some(walk), Some(skip)) = (self.walk.as_mut(), skip) else {
            // No skipping: one range, handed out once.
            if (self.backward && self.next == 0) || (!self.backward && self.next == self.n) {
                return None;
            }
            self.next = if self.backward { 0 } else { self.n };
            return Some((0, self.n as usize - 1));
        };
        loop {
            let (sa, sb) = walk.next_span_leaping(skip)?;
            let (ta, tb) = if self.backward { (-sb, -sa) } else { (sa, sb) };
            let lim = R::of(self.n as f64 + 2.0);
            let k = |t: R| ((t - self.t_s) / self.dt - R::of(0.5)).max(-lim).min(lim);
            let mut lo = k(ta).floor().to_i64().unwrap_or(0) - 1;
            let mut hi = k(tb).ceil().to_i64().unwrap_or(self.n) + 1;
            lo = lo.max(0);
            hi = hi.min(self.n - 1);
            if self.backward {
                hi = hi.min(self.next - 1);
                if lo > hi {
                    continue;
                }
                self.next = lo;
            } else {
                lo = lo.max(self.next);
                if lo > hi {
                    continue;
                }
                self.next = hi + 1;
            }
            return Some((lo as usize, hi as usize));
        }
    }
}

/// A clipping box resolved for the ray caster: a box in index space (voxel boxes) or
/// in world space (world boxes), both cutting the same ray parameter `t`.
#[derive(Clone, Copy, Debug)]
pub struct ClipR<R> {
    pub lo: V3<R>,
    pub hi: V3<R>,
    pub world: bool,
}

impl<R: Real> ClipR<R> {
    /// Resolves a user clip box (voxel boxes grow by ½ to cover whole voxels).
    pub fn new(c: &ClipBox) -> Self {
        let grow = if c.space == ClipSpace::Voxel {
            0.5
        } else {
            0.0
        };
        let v = |x: [f64; 3], s: f64| V3::new(R::of(x[0] + s), R::of(x[1] + s), R::of(x[2] + s));
        ClipR {
            lo: v(c.lo, -grow),
            hi: v(c.hi, grow),
            world: c.space == ClipSpace::World,
        }
    }

    /// The parameter interval of the ray inside the box (index-space ray `o + d·t`,
    /// world-space ray `wo + wd·t`), or `None` if it misses.
    /// Mirrors `shaders/shared/skip.wgsl: clip_interval`.
    pub fn interval(&self, o: V3<R>, d: V3<R>, wo: V3<R>, wd: V3<R>) -> Option<(R, R)> {
        if self.world {
            intersect_box(wo, wd, self.lo, self.hi)
        } else {
            intersect_box(o, d, self.lo, self.hi)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lebesgue_constants() {
        assert_eq!(lebesgue_1d(Filter::Trilinear), 1.0);
        // Catmull–Rom at f = ½: |−1/16| + 9/16 + 9/16 + |−1/16| = 5/4.
        assert!((lebesgue_1d(Filter::CatmullRom) - 1.25 * 1.001).abs() < 1e-9);
        assert!(lebesgue_1d(Filter::Lanczos3) > 1.0);
    }

    #[test]
    fn walk_visits_cells_in_order() {
        // Along +x through a 4×1×1 grid of 2-voxel cells: one span over everything.
        let o = V3::new(-5.0, 0.0, 0.0);
        let d = V3::new(1.0, 0.0, 0.0);
        let mut w = CellWalk::<f64>::new(o, d, 4.5, 12.5, 2, [4, 1, 1]);
        assert_eq!(w.next_span(|_| false), Some((4.5, 12.5)));
        assert_eq!(w.next_span(|_| false), None);
        // Cells 1 and 2 empty: spans [4.5, 6.5] and [10.5, 12.5].
        let mut w = CellWalk::<f64>::new(o, d, 4.5, 12.5, 2, [4, 1, 1]);
        let empty = |c: [i32; 3]| c[0] == 1 || c[0] == 2;
        assert_eq!(w.next_span(empty), Some((4.5, 6.5)));
        assert_eq!(w.next_span(empty), Some((10.5, 12.5)));
        assert_eq!(w.next_span(empty), None);
    }

    /// A small generator for the tests below.
    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Blobs of empty cells in a 13×9×11 grid (a few balls), or none, or all.
    fn blob_kinds(seed: u64, cells: [usize; 3]) -> Vec<bool> {
        let mut st = seed;
        let n = cells[0] * cells[1] * cells[2];
        match seed % 7 {
            0 => return vec![false; n],
            1 => return vec![true; n],
            _ => {}
        }
        let balls: Vec<([f64; 3], f64)> = (0..4)
            .map(|_| {
                let c = [0, 1, 2].map(|a| lcg(&mut st) * cells[a] as f64);
                (c, 1.0 + 3.0 * lcg(&mut st))
            })
            .collect();
        (0..n)
            .map(|i| {
                let p = [
                    i % cells[0],
                    (i / cells[0]) % cells[1],
                    i / (cells[0] * cells[1]),
                ];
                balls
                    .iter()
                    .any(|(c, r)| (0..3).map(|a| (p[a] as f64 - c[a]).powi(2)).sum::<f64>() < r * r)
                    == seed.is_multiple_of(2)
            })
            .collect()
    }

    #[test]
    fn direction_runs_are_the_largest_uniform_boxes_ahead() {
        let cells = [13, 9, 11];
        let at = |p: [i64; 3]| (p[0] + 13 * (p[1] + 9 * p[2])) as usize;
        for seed in 0..4 {
            let kinds = blob_kinds(seed, cells);
            for class in 0..27 {
                let runs = direction_runs(&kinds, cells, class);
                let s = class_steps(class);
                assert_eq!(
                    direction_class(s.map(|x| x as i32)),
                    class,
                    "class {class} from its steps {s:?}"
                );
                for i in 0..kinds.len() {
                    let p = [i % 13, (i / 13) % 9, i / 117].map(|x| x as i64);
                    // Whether the box of side m (extent 1 along an axis the rays do not
                    // move along) takes in a cell of the other kind.
                    let other = |m: i64| {
                        let side = |a: usize| if s[a] == 0 { 1 } else { m };
                        (0..side(0)).any(|a| {
                            (0..side(1)).any(|b| {
                                (0..side(2)).any(|c| {
                                    let q = [p[0] + a * s[0], p[1] + b * s[1], p[2] + c * s[2]];
                                    (0..3).all(|k| (0..cells[k] as i64).contains(&q[k]))
                                        && kinds[at(q)] != kinds[i]
                                })
                            })
                        })
                    };
                    // The largest side without one; 255 when even the side that
                    // reaches across the whole grid (14) has none.
                    let want = (2..=14).find(|&m| other(m)).map_or(255, |m| m - 1);
                    assert_eq!(
                        runs[i] as i64, want,
                        "seed {seed}, class {class}, cell {p:?}"
                    );
                }
            }
        }
    }

    /// The leaping walk finds the spans of the cell-by-cell walk: as many, their ends
    /// the same up to rounding, over rays in every direction (axis-aligned too).
    #[test]
    fn leaping_walk_finds_the_stepping_walks_spans() {
        let cells = [13, 9, 11];
        let block = 4;
        let tf = TransferFunctionLike::prefix();
        let mut st = 99u64;
        let mut spans = 0;
        for seed in 0..14 {
            let empty = blob_kinds(seed, cells);
            let skip = Skipper {
                grid: std::sync::Arc::new(MinMaxGrid {
                    block,
                    radius: 1,
                    cells,
                    minmax: vec![[0.0, 0.0]; empty.len()],
                }),
                tf: tf.clone(),
                runs: Default::default(),
                empty,
            };
            for r in 0..300 {
                let lo = V3::new(-0.5, -0.5, -0.5);
                let hi = V3::new(51.5, 35.5, 43.5);
                let o = V3::new(
                    -10.0 + 70.0 * lcg(&mut st),
                    -10.0 + 55.0 * lcg(&mut st),
                    -10.0 + 60.0 * lcg(&mut st),
                );
                let mut d = V3::new(lcg(&mut st) - 0.5, lcg(&mut st) - 0.5, lcg(&mut st) - 0.5);
                if r % 5 == 0 {
                    // Axis-aligned, either way.
                    let a = r / 5 % 3;
                    let s = if r % 2 == 0 { 1.0 } else { -1.0 };
                    d = V3::new(0.0, 0.0, 0.0);
                    d.0[a] = s;
                }
                let Some((t0, t1)) = crate::real::slab_interval(
                    o.to_dvec(),
                    d.to_dvec(),
                    lo.to_dvec(),
                    hi.to_dvec(),
                ) else {
                    continue;
                };
                let mut a = CellWalk::new(o, d, t0, t1, block, cells);
                let mut b = a;
                loop {
                    let x = a.next_span(|c| skip.cell_empty(c));
                    let y = b.next_span_leaping(&skip);
                    match (x, y) {
                        (None, None) => break,
                        (Some(x), Some(y)) => {
                            spans += 1;
                            let tol = 1e-9 * (1.0 + x.1.abs());
                            assert!(
                                (x.0 - y.0).abs() <= tol && (x.1 - y.1).abs() <= tol,
                                "seed {seed}, ray {r}: {x:?} vs {y:?}"
                            );
                        }
                        _ => panic!("seed {seed}, ray {r}: {x:?} vs {y:?}"),
                    }
                }
            }
        }
        assert!(spans > 1000, "only {spans} spans compared");
    }

    /// A transfer function's prefix count, for building a skipper by hand.
    struct TransferFunctionLike;
    impl TransferFunctionLike {
        fn prefix() -> OpacityPrefix<f64> {
            let lut = crate::transfer::TransferFunction::preset("phantom")
                .unwrap()
                .lut(64)
                .to_real::<f64>();
            opacity_prefix(&lut, 0.0)
        }
    }
}
