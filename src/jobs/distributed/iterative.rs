//! `voxlab reconstruct --distributed --method sirt|os-sart|cgls|tv`: the iterative
//! methods on the ranks of a [`Comm`], the views cut among the ranks and the image
//! whole on each.
//!
//! # How the work is cut
//! The views are cut into one contiguous run per rank (sizes differing by at most one,
//! as [`super::distributed`] cuts slices). A rank reads only its views' detector lines
//! from a 3-D stack stored in one uncompressed block ([`crate::io::projections::line_stack`]:
//! `.npy`, raw NRRD, binary MetaImage; other inputs are read whole and the rest dropped),
//! and builds Joseph's matched pair over its views alone
//! ([`crate::ct::Geometry::select_views`]: the same rays). Every rank holds the whole
//! image `x`. In every iteration each rank projects `x` onto its views, forms its part
//! of the residual and backprojects it with the exact transpose into a partial image;
//! the partials are summed by an all-reduce ([`Comm::all_reduce_sum`]), and so are the
//! sums over rays (`‖r‖²`, SIRT's weighted `‖r‖²_R`, CGLS's `‖A p‖²`). SIRT's row
//! weights `1 / A𝟙` are per ray, so per rank; its column weights `1 / Aᵀ𝟙` are summed
//! once. Every rank then takes the same step on the same image: the loops are
//! [`crate::cpu::iterative`]'s own ([`solve_shared`]).
//!
//! OS-SART's subsets are cut from all the views (`s, s + k, s + 2k, …`), so each
//! subset has views on every rank: a rank projects `x` onto its views of the subset,
//! backprojects its weighted residual, and the partial updates (and the subset's
//! column weights, when they are not kept from the first pass) are all-reduced before
//! every rank applies the same update; then the next subset. One all-reduce of an
//! image per subset: `k` per iteration instead of SIRT's one. (The one-pass update of
//! a single process, which updates `x` view by view, is not used on more than one
//! rank: the update must be summed first.)
//!
//! TV (Chambolle–Pock): `‖A‖`'s power iteration sums `AᵀA v` over the ranks (20
//! images, once); each iteration sums `Aᵀp` (one image) and `‖A x − b‖²`; the dual
//! `p` lives on the rays, so on their rank; the dual field `q`, the gradients and the
//! primal step are image-sized and computed alike on every rank.
//!
//! `--init fbp`: the FBP/FDK image is made first as the distributed FBP makes it, in
//! slabs ([`super::fbp::whole_image`]), and all-reduced into the whole image on every
//! rank: the single process's first iterate, bit for bit.
//!
//! # What it equals
//! On one rank, the single-process result bit for bit. On more, `Aᵀ r` is summed as
//! `Σ_ranks Σ_views of the rank` (in f64, then rounded to the precision) instead of
//! over all views in order, and the sums over rays start a chunk at each rank's first
//! ray: the image moves by rounding only (docs/distributed.md gives the measured
//! distances). Every rank gets the same bits (the all-reduce adds in rank order).
//!
//! # The output
//! As FBP's: one float32 `.npy` file written through [`crate::io::SharedOutput`], each
//! rank its contiguous share of the values; every phase ends with an agreement, and
//! every iteration agrees on cancellation, so a failure on any rank fails every rank
//! with the lowest failing rank's message and leaves no file.

use super::common::{
    agree, gather_reports, input_geometry, rank_lines, runs, value_range, write_shared_npy, Comm,
    Counted, Distributed, RankReport,
};
use crate::cpu::fbp::Grid;
use crate::cpu::iterative::{solve_shared, IterativeOptions, MatchedPair, Problem, Shares};
use crate::cpu::project::JosephPair;
use crate::ct::flat_field::IntensityReport;
use crate::ct::{Beam, Geometry};
use crate::error::Result;
use crate::jobs::reconstruct::{
    circle_support, init_request, iterative_options, solved, Init, IterationLog, ReconstructRequest,
};
use crate::jobs::{check_cancel, Backend, Progress};
use crate::real::Real;
use std::cell::Cell;
use std::ops::Range;
use std::time::Instant;

/// The [`Shares`] of a rank: the all-reduce of its [`Comm`], timed, and where its
/// views lie among all.
struct RankShares<'a> {
    comm: &'a dyn Comm,
    seconds: Cell<f64>,
    /// The rank's first view and the problem's view count.
    first_view: usize,
    total_views: usize,
}

impl Shares for RankShares<'_> {
    fn count(&self) -> usize {
        self.comm.size()
    }
    fn sum(&self, values: &mut [f64]) {
        let t = Instant::now();
        self.comm.all_reduce_sum(values);
        self.seconds
            .set(self.seconds.get() + t.elapsed().as_secs_f64());
    }
    fn views(&self, _local: usize) -> (usize, usize) {
        (self.first_view, self.total_views)
    }
}

/// The pair of a rank without views (more ranks than views): `A x` is empty and
/// `Aᵀ y` zero; the rank still takes part in every sum.
struct NoViews {
    dims: [usize; 3],
    per_view: usize,
}

impl<R: Real> MatchedPair<R> for NoViews {
    fn dims(&self) -> [usize; 3] {
        self.dims
    }
    fn n_views(&self) -> usize {
        0
    }
    fn per_view(&self) -> usize {
        self.per_view
    }
    fn forward(&self, _x: &[R], views: &[usize]) -> Result<Vec<R>> {
        assert!(views.is_empty(), "a rank without views projects none");
        Ok(Vec::new())
    }
    fn transpose(&self, _y: &[R], views: &[usize]) -> Result<Vec<R>> {
        assert!(views.is_empty(), "a rank without views backprojects none");
        Ok(vec![R::zero(); self.dims.iter().product()])
    }
}

/// What a rank has read and set up before it iterates.
struct Prepared {
    /// The whole geometry.
    g: Geometry,
    grid: Grid,
    opts: IterativeOptions,
    support: Option<Vec<bool>>,
    /// This rank's views (`None`: more ranks than views).
    views: Option<Range<usize>>,
    /// Their projections, view after view.
    b: Vec<f64>,
    lines_read: usize,
    read_seconds: f64,
    /// With `--flat`: the counts of its views' conversion.
    intensity: Option<IntensityReport>,
}

fn prepare(a: &ReconstructRequest, comm: &dyn Comm, progress: &dyn Progress) -> Result<Prepared> {
    let t = Instant::now();
    let (whole, g, grid) = input_geometry(a, progress)?;
    let method = a.method.iterative().expect("an iterative method");
    let opts = iterative_options(a, method, g.n_angles())?;
    let views = runs(g.n_angles(), comm.size()).swap_remove(comm.rank());
    let mut intensity = None;
    let (b, lines_read) = match &views {
        None => (Vec::new(), 0),
        Some(v) => {
            // Only this rank's views' lines, which are consecutive (the rest dropped
            // when the file was read whole).
            let lines: Vec<usize> = (v.start * g.rows..v.end * g.rows).collect();
            let read = if whole.is_some() {
                g.n_angles() * g.rows
            } else {
                lines.len()
            };
            let (p, counts) = rank_lines(a, whole.as_ref(), &lines)?;
            intensity = counts;
            (p.data, read)
        }
    };
    let support = (g.beam == Beam::Parallel && !a.no_circle).then(|| circle_support(grid.dims));
    Ok(Prepared {
        g,
        grid,
        opts,
        support,
        views,
        b,
        lines_read,
        read_seconds: t.elapsed().as_secs_f64(),
        intensity,
    })
}

/// What a rank's iterations give: the image, the log, and the seconds building the
/// pair, iterating and all-reducing.
type Iterated = (Vec<f64>, IterationLog, [f64; 3]);

/// Builds this rank's pair in `R` (agreed), then iterates from `x0` (the whole image,
/// every rank the same; zeros when `None`).
fn iterate<R: Real>(
    pre: &Prepared,
    x0: Option<&[f64]>,
    comm: &dyn Comm,
    progress: &dyn Progress,
) -> Result<Iterated> {
    let t = Instant::now();
    let dims = pre.grid.dims;
    let per_view = pre.g.rows * pre.g.cols;
    let built = (|| -> Result<Box<dyn MatchedPair<R>>> {
        check_cancel(progress)?;
        Ok(match &pre.views {
            Some(v) => Box::new(JosephPair::<R>::new(
                dims,
                pre.grid.affine,
                &pre.g.select_views(v.clone())?,
            )?),
            None => Box::new(NoViews { dims, per_view }),
        })
    })();
    let pair = agree(comm, built)?;
    let pair_seconds = t.elapsed().as_secs_f64();
    let b: Vec<R> = pre.b.iter().map(|&v| R::of(v)).collect();
    let x0: Vec<R> = match x0 {
        Some(x0) => x0.iter().map(|&v| R::of(v)).collect(),
        None => vec![R::zero(); dims.iter().product()],
    };
    let prob = Problem {
        pair: &*pair,
        b: &b,
        support: pre.support.as_deref(),
    };
    let shares = RankShares {
        comm,
        seconds: Cell::new(0.0),
        first_view: pre.views.as_ref().map_or(0, |v| v.start),
        total_views: pre.g.n_angles(),
    };
    let total = pre.opts.iterations as u64;
    // Every rank stops at the same iteration: cancellation is agreed on.
    let mut hook = |it: usize, _: &[R], _: f64| {
        progress.advance(it as u64, total);
        agree(comm, check_cancel(progress))
    };
    let t = Instant::now();
    let sol = solve_shared(&prob, x0, &pre.opts, &shares, &mut hook)?;
    let secs = t.elapsed().as_secs_f64();
    let (x, log) = solved(&pre.opts, sol, secs);
    Ok((x, log, [pair_seconds, secs, shares.seconds.get()]))
}

/// The distributed FBP/FDK `--init fbp` runs first (`None` from zero): the single
/// process's, keeping the output its checks ask for (it writes nothing).
fn start_request(a: &ReconstructRequest) -> Option<ReconstructRequest> {
    (a.init == Init::Fbp).then(|| ReconstructRequest {
        out: a.out.clone(),
        ..init_request(a)
    })
}

/// [`super::run`] for SIRT, OS-SART, CGLS and TV (module docs).
pub(super) fn run(
    a: &ReconstructRequest,
    comm: &dyn Comm,
    progress: &dyn Progress,
) -> Result<Distributed> {
    let counted = Counted::new(comm);
    let comm: &dyn Comm = &counted;
    let (rank, size) = (comm.rank(), comm.size());
    let pre = agree(comm, prepare(a, comm, progress))?;
    // `--init fbp`: FBP/FDK in slabs, then the whole image on every rank (the single
    // process's, bit for bit).
    let init = match start_request(a) {
        None => None,
        Some(first) => {
            let w = super::fbp::whole_image(&first, comm, progress)?;
            if w.grid != pre.grid {
                return Err(crate::Error::invalid(
                    "--init fbp",
                    "the FBP grid is not the iterative method's",
                ));
            }
            Some(w)
        }
    };
    let x0 = init.as_ref().map(|w| &w.image[..]);
    let f32_path = a.backend == Backend::CpuF32;
    let method = pre.opts.method;
    progress.begin(
        &format!("{} iterations", method.name()),
        "iterations",
        pre.opts.iterations as u64,
    );
    let t = Instant::now();
    let iterated = if f32_path {
        iterate::<f32>(&pre, x0, comm, progress)
    } else {
        iterate::<f64>(&pre, x0, comm, progress)
    };
    let (x, log, [pair_seconds, iterate_seconds, reduce_seconds]) = agree(comm, iterated)?;
    progress.end(t.elapsed().as_secs_f64());
    if log.converged {
        progress.note(&format!(
            "stopped after {} iterations: the objective fell by less than {} in the last",
            log.iterations, a.tolerance
        ));
    }

    // Every rank holds the image: each writes its contiguous share of the values.
    let out = a.out.clone().expect("checked by check_distributed");
    let t = Instant::now();
    let part = runs(x.len(), size).swap_remove(rank).unwrap_or(0..0);
    let values: Vec<f32> = x[part.clone()].iter().map(|&v| v as f32).collect();
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let parts = if bytes.is_empty() {
        Vec::new()
    } else {
        vec![(4 * part.start as u64, &bytes[..])]
    };
    let bytes_written = write_shared_npy(comm, &out, pre.grid.dims, parts)?;
    // Every rank holds the same log: rank 0 writes `--convergence` (atomically, as
    // one process does), and every rank agrees on how that went.
    let convergence = match (&a.convergence, rank) {
        (Some(path), 0) => {
            let text = log.csv();
            crate::io::write_atomic(path, |w| {
                w.write_all(text.as_bytes())
                    .map_err(|e| crate::Error::io(path.clone(), e))
            })
        }
        _ => Ok(()),
    };
    agree(comm, convergence)?;
    let write_seconds = t.elapsed().as_secs_f64();

    let [init_read, init_filter, init_backproject] = init.as_ref().map_or([0.0; 3], |w| w.seconds);
    let mine = RankReport {
        views: pre.views.clone(),
        lines_read: pre.lines_read + init.as_ref().map_or(0, |w| w.lines_read),
        read_seconds: pre.read_seconds + init_read,
        filter_seconds: init_filter,
        backproject_seconds: init_backproject,
        write_seconds,
        pair_seconds,
        iterate_seconds,
        reduce_seconds,
        bytes_written,
        bytes_sent: counted.sent(),
        intensity: pre.intensity,
        ..Default::default()
    };
    let (ranks, range) = gather_reports(comm, &mine, value_range(&values));
    Ok(Distributed {
        grid: pre.grid,
        parallel: pre.g.beam == Beam::Parallel,
        what: if f32_path { "cpu f32" } else { "cpu f64" }.into(),
        axis: 0,
        total_lines: pre.g.n_angles() * pre.g.rows,
        range,
        out,
        ranks,
        iterative: Some(log),
    })
}

impl Distributed {
    /// [`Self::describe`] of an iterative method: one line per rank.
    pub(super) fn describe_iterative(&self) -> String {
        let iterations = self.iterative.as_ref().map_or(0, |l| l.iterations);
        // The ranks' views tile 0..n in rank order.
        let views = self
            .ranks
            .iter()
            .filter_map(|r| r.views.as_ref().map(|v| v.end))
            .max()
            .unwrap_or(0);
        let mut s = String::new();
        for (r, rep) in self.ranks.iter().enumerate() {
            let which = match &rep.views {
                Some(v) => format!("views {}..{} of {views}", v.start, v.end),
                None => "no views".into(),
            };
            // `--init fbp`: the FBP/FDK slab's filtering and backprojection.
            let init = rep.filter_seconds + rep.backproject_seconds;
            let init = if init > 0.0 {
                format!(", FBP start {init:.3} s")
            } else {
                String::new()
            };
            s.push_str(&format!(
                "rank {r}: {which}, read {} of {} detector lines in {:.3} s{init}, pair {:.3} s, \
                 {iterations} iterations {:.3} s (all-reduce {:.3} s), wrote {} bytes in \
                 {:.3} s, sent {} bytes\n",
                rep.lines_read,
                self.total_lines,
                rep.read_seconds,
                rep.pair_seconds,
                rep.iterate_seconds,
                rep.reduce_seconds,
                rep.bytes_written,
                rep.write_seconds,
                rep.bytes_sent
            ));
        }
        s
    }
}

/// What SIRT, OS-SART, CGLS or TV on `ranks` ranks would do ([`super::dry_run`]): each
/// rank's views, what it reads and holds, and what it sends.
#[derive(Clone, Debug)]
pub struct ViewsPlan {
    pub grid: Grid,
    /// `sirt`, `os-sart`, `cgls` or `tv`.
    pub method: String,
    pub iterations: usize,
    /// Each rank's views (`None`: more ranks than views).
    pub views: Vec<Option<Range<usize>>>,
    /// Detector lines per view, and of the whole stack.
    pub rows: usize,
    pub total_lines: usize,
    /// Whether every rank reads the whole stack (not a stack
    /// [`crate::io::projections::line_stack`] accepts).
    pub reads_whole: bool,
    /// Each rank's large host arrays at their peak (bytes): its projections (f64,
    /// read, and their residual), the image and the solver's vectors (four, f64, as
    /// the single-process plan counts them), and the all-reduce's copies of one chunk
    /// of the partial image (one per rank, f64, [`super::REDUCE_CHUNK`] values).
    pub host_bytes: Vec<u64>,
    /// Bytes each rank sends per iteration: its partial image and its sums, f64.
    pub bytes_per_iteration: u64,
    pub out: std::path::PathBuf,
    pub out_bytes: u64,
    /// `--init fbp`: the FBP/FDK in slabs that comes first (its host bytes are in
    /// `host_bytes`'s peaks).
    pub init: Option<super::DistributedPlan>,
}

impl ViewsPlan {
    /// The plan as text, one rank per line.
    pub fn describe(&self) -> String {
        use crate::gpu::plan::human_bytes;
        let d = self.grid.dims;
        let ranks = self.views.len();
        let mut s = format!(
            "dry run: reconstruct {} ({} iterations) on {ranks} ranks (nothing is computed or \
             written)\n\
             grid:   {}×{}×{}, whole on every rank; the views cut among the ranks, their \
             backprojections summed every iteration; the stack holds {} detector lines{}\n",
            self.method,
            self.iterations,
            d[0],
            d[1],
            d[2],
            self.total_lines,
            if self.reads_whole {
                " (read whole by every rank: not a 3-D .npy, raw NRRD or binary MetaImage)"
            } else {
                ""
            }
        );
        for (r, (views, host)) in self.views.iter().zip(&self.host_bytes).enumerate() {
            let host = human_bytes(*host);
            match views {
                Some(v) => {
                    let lines = if self.reads_whole {
                        self.total_lines
                    } else {
                        v.len() * self.rows
                    };
                    s += &format!(
                        "rank {r}: views {}..{} ({}), reads {lines} lines, host {host} at \
                         the peak\n",
                        v.start,
                        v.end,
                        v.len()
                    );
                }
                None => s += &format!("rank {r}: no views (more ranks than views), host {host}\n"),
            }
        }
        if let Some(init) = &self.init {
            let lines: Vec<String> = init
                .slabs
                .lines
                .iter()
                .map(|l| {
                    if init.reads_whole {
                        init.slabs.total_lines
                    } else {
                        l.len()
                    }
                    .to_string()
                })
                .collect();
            s += &format!(
                "start:  --init fbp, FBP/FDK in slabs along {} (ranks read {} lines), the \
                 slabs all-reduced into the image on every rank\n",
                if init.slabs.axis == 1 { 'j' } else { 'k' },
                lines.join(", ")
            );
        }
        s += &format!(
            "sends:  {} per rank and iteration ({} in {} iterations)\n\
             would write: {} ({} bytes)\n",
            human_bytes(self.bytes_per_iteration),
            human_bytes(self.bytes_per_iteration * self.iterations as u64),
            self.iterations,
            self.out.display(),
            self.out_bytes
        );
        s
    }
}

/// `voxlab reconstruct --distributed --dry-run --ranks N` for the iterative methods: how [`run`]
/// on `ranks` ranks would cut the views and what each rank would read, hold and send,
/// after reading the input's header and geometry (no MPI needed), computing and
/// writing nothing.
///
/// # Errors
/// As [`run`] up to the work.
pub(super) fn plan(
    a: &ReconstructRequest,
    ranks: usize,
    progress: &dyn Progress,
) -> Result<ViewsPlan> {
    let (whole, g, grid) = input_geometry(a, progress)?;
    let method = a.method.iterative().expect("an iterative method");
    let opts = iterative_options(a, method, g.n_angles())?;
    if ranks == 0 {
        return Err(crate::Error::invalid(
            "ranks",
            "a distributed job needs at least one",
        ));
    }
    let views = runs(g.n_angles(), ranks);
    let voxels = grid.dims.iter().product::<usize>() as u64;
    let init = match start_request(a) {
        None => None,
        Some(first) => Some(super::fbp::plan(&first, ranks, progress)?),
    };
    let per_view = (g.rows * g.cols) as u64;
    // OS-SART: each subset's update is summed over the ranks, and its column weights
    // too unless every subset's are kept (then they are summed once). TV: one image
    // (`Aᵀp`) and one sum per iteration, and it holds its dual field (one image per
    // live axis) and the dual `p` of its rays besides.
    use crate::cpu::iterative::Method;
    let os_sart = method == Method::OsSart;
    let tv = method == Method::Tv;
    let tv_extra = |rays: u64| {
        if tv {
            crate::cpu::iterative::live_axes(grid.dims).len() as u64 * voxels * 8
                + rays * 8
                + 2 * voxels * 8
        } else {
            0
        }
    };
    let real = if a.backend == Backend::CpuF32 { 4 } else { 8 };
    let keep = crate::cpu::iterative::keeps_column_weights(opts.subsets, voxels as usize, real);
    let kept_weights = if os_sart && keep {
        opts.subsets as u64 * voxels * real as u64
    } else {
        0
    };
    let host_bytes = views
        .iter()
        .map(|v| {
            let rays = v.as_ref().map_or(0, |v| v.len() as u64) * per_view;
            // A stack read whole is held whole while the rank keeps its views.
            let read = if whole.is_some() {
                g.n_angles() as u64 * per_view * 8
            } else {
                0
            };
            // The all-reduce holds every rank's copy of one chunk.
            let gathered = if ranks > 1 {
                ranks as u64 * voxels.min(super::common::REDUCE_CHUNK as u64) * 8
            } else {
                0
            };
            read + 2 * rays * 8 + 4 * voxels * 8 + gathered + kept_weights + tv_extra(rays)
        })
        .enumerate()
        .map(|(r, iterating)| {
            // `--init fbp`: the slab's peak, its whole image and the all-reduce's copies,
            // beside this rank's views' projections.
            let start = init.as_ref().map_or(0, |i| {
                let rays = views[r].as_ref().map_or(0, |v| v.len() as u64) * per_view;
                let gathered = ranks as u64 * voxels.min(super::common::REDUCE_CHUNK as u64) * 8;
                rays * 8 + i.host_bytes[r] + voxels * 8 + gathered
            });
            iterating.max(start)
        })
        .collect();
    let shape = crate::jobs::reconstruct::npy_shape(grid.dims);
    Ok(ViewsPlan {
        method: a.method.name().to_string(),
        iterations: opts.iterations,
        views,
        rows: g.rows,
        total_lines: g.n_angles() * g.rows,
        reads_whole: whole.is_some(),
        host_bytes,
        // The partial image and up to three sums over rays, f64, to every other rank;
        // OS-SART one partial update per subset (and its column weights when they are
        // not kept) and two sums.
        bytes_per_iteration: match (ranks > 1, os_sart, tv) {
            (false, _, _) => 0,
            (true, true, _) => opts.subsets as u64 * voxels * 8 * if keep { 1 } else { 2 } + 16,
            (true, _, true) => voxels * 8 + 8,
            (true, false, false) => voxels * 8 + 24,
        },
        out: a.out.clone().expect("checked by check_distributed"),
        out_bytes: crate::io::npy::npy_f32_header(&shape).len() as u64 + 4 * voxels,
        grid,
        init,
    })
}
