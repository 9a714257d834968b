//! FBP/FDK on ranks: the grid cut into slabs, each rank reading only the detector lines
//! its slab needs (see the module docs of [`super`]).

use super::common::{
    agree, check_distributed, gather_reports, input_geometry, rank_lines, runs, value_range,
    write_shared_npy, Comm, Counted, Distributed, RankReport,
};
use crate::cpu::fbp::{backproject_region, circle_mask_region, region_rows, Grid, Region};
use crate::cpu::ramp::{filter_lines, FilterMethod};
use crate::ct::flat_field::IntensityReport;
use crate::ct::{Beam, Geometry, Lines, Projections};
use crate::error::{Error, Result};
use crate::io::npy::npy_f32_header;
use crate::jobs::reconstruct::{fbp_lines, npy_shape, ReconstructRequest};
use crate::jobs::{Backend, Progress};
use crate::real::Real;
use std::path::PathBuf;
use std::time::Instant;
/// How a grid is cut among the ranks.
#[derive(Clone, Debug, PartialEq)]
pub struct SlabPlan {
    /// The grid axis the slabs are cut along: 1 (`j`) or 2 (`k`).
    pub axis: usize,
    /// Each rank's slab; `None` for the ranks past the grid's slices along `axis`.
    pub slabs: Vec<Option<Region>>,
    /// Each rank's detector lines (`view·rows + row`, sorted), partners included.
    pub lines: Vec<Vec<usize>>,
    /// The detector lines of the whole stack.
    pub total_lines: usize,
}

impl SlabPlan {
    /// The lines all ranks read together (a line read by two ranks counts twice).
    pub fn lines_read(&self) -> usize {
        self.lines.iter().map(Vec::len).sum()
    }
}

/// The detector lines the voxels of `region` need in the filtered stack of `g`
/// ([`region_rows`]), with each line's FFT partner (see the module docs).
pub fn region_lines(g: &Geometry, grid: &Grid, region: &Region) -> Vec<usize> {
    let total = g.n_angles() * g.rows;
    let mut lines = Vec::new();
    for (a, band) in region_rows(g, grid, region).into_iter().enumerate() {
        for r in band {
            let line = a * g.rows + r;
            lines.push(line);
            if line ^ 1 < total {
                lines.push(line ^ 1);
            }
        }
    }
    lines.sort_unstable();
    lines.dedup();
    lines
}

/// Cuts `grid` into one slab per rank along `k`, or along `j` when that gives more
/// ranks a slab (a single image), or as many and reads fewer detector lines in all (a
/// cone beam whose rotation axis is `j`: then each rank reads only its band of rows).
///
/// # Errors
/// No ranks.
pub fn slab_plan(g: &Geometry, grid: &Grid, ranks: usize) -> Result<SlabPlan> {
    if ranks == 0 {
        return Err(Error::invalid(
            "ranks",
            "a distributed job needs at least one",
        ));
    }
    let d = grid.dims;
    let plan_along = |axis: usize| {
        let slabs: Vec<Option<Region>> = runs(d[axis], ranks)
            .into_iter()
            .map(|run| {
                run.map(|run| match axis {
                    1 => Region { j: run, k: 0..d[2] },
                    _ => Region { j: 0..d[1], k: run },
                })
            })
            .collect();
        let lines = slabs
            .iter()
            .map(|s| s.as_ref().map_or(Vec::new(), |s| region_lines(g, grid, s)))
            .collect();
        SlabPlan {
            axis,
            slabs,
            lines,
            total_lines: g.n_angles() * g.rows,
        }
    };
    // First the axis that gives more ranks a slab, then the one that reads less.
    let along_k = plan_along(2);
    let along_j = plan_along(1);
    let busy = |p: &SlabPlan| p.slabs.iter().filter(|s| s.is_some()).count();
    Ok(
        match busy(&along_j)
            .cmp(&busy(&along_k))
            .then_with(|| along_k.lines_read().cmp(&along_j.lines_read()))
        {
            std::cmp::Ordering::Greater => along_j,
            _ => along_k,
        },
    )
}
/// The detector lines this rank reads, their geometry, the grid and the plan.
struct Prepared {
    p: Lines<f64>,
    /// With `--flat`: the counts of the lines' conversion.
    intensity: Option<IntensityReport>,
    g: Geometry,
    grid: Grid,
    plan: SlabPlan,
    lines_read: usize,
    read_seconds: f64,
}

/// The stack when it must be read whole (`None`: it is read line by line), the
/// geometry, the grid and the slab plan for `ranks`.
type Planned = (Option<Projections<f64>>, Geometry, Grid, SlabPlan);

fn planned(a: &ReconstructRequest, ranks: usize, progress: &dyn Progress) -> Result<Planned> {
    let (whole, g, grid) = input_geometry(a, progress)?;
    let plan = slab_plan(&g, &grid, ranks)?;
    Ok((whole, g, grid, plan))
}

fn prepare(a: &ReconstructRequest, comm: &dyn Comm, progress: &dyn Progress) -> Result<Prepared> {
    let t = Instant::now();
    let (whole, g, grid, plan) = planned(a, comm.size(), progress)?;
    let mine = &plan.lines[comm.rank()];
    // Read whole: only this rank's lines are kept.
    let lines_read = if whole.is_some() {
        plan.total_lines
    } else {
        mine.len()
    };
    let (p, intensity) = rank_lines(a, whole.as_ref(), mine)?;
    Ok(Prepared {
        p,
        intensity,
        g,
        grid,
        plan,
        lines_read,
        read_seconds: t.elapsed().as_secs_f64(),
    })
}

/// What a distributed reconstruction on `ranks` ranks would do ([`plan`]).
#[derive(Clone, Debug)]
pub struct DistributedPlan {
    pub grid: Grid,
    pub slabs: SlabPlan,
    /// Whether every rank would read the whole stack (not a stack
    /// [`crate::io::projections::line_stack`] accepts).
    pub reads_whole: bool,
    /// Each rank's large host arrays at their peak (bytes): its detector lines (f64),
    /// their padded, weighted and filtered copies, the bordered band of rows the
    /// backprojection reads, the slab and its bytes to write (the whole stack too,
    /// while it is read, when the file is read whole).
    pub host_bytes: Vec<u64>,
    /// The output and its size in bytes.
    pub out: PathBuf,
    pub out_bytes: u64,
}

impl DistributedPlan {
    /// The plan as text, one rank per line.
    pub fn describe(&self) -> String {
        use crate::gpu::plan::human_bytes;
        let axis = if self.slabs.axis == 1 { 'j' } else { 'k' };
        let d = self.grid.dims;
        let mut s = format!(
            "dry run: reconstruct on {} ranks (nothing is computed or written)\n\
             grid:   {}×{}×{} in slabs along {axis}; the stack holds {} detector lines{}\n",
            self.slabs.slabs.len(),
            d[0],
            d[1],
            d[2],
            self.slabs.total_lines,
            if self.reads_whole {
                " (read whole by every rank: not a 3-D .npy, raw NRRD or binary MetaImage)"
            } else {
                ""
            }
        );
        for (r, (slab, lines)) in self.slabs.slabs.iter().zip(&self.slabs.lines).enumerate() {
            let host = human_bytes(self.host_bytes[r]);
            match slab {
                Some(sl) => {
                    let run = if self.slabs.axis == 1 { &sl.j } else { &sl.k };
                    s += &format!(
                        "rank {r}: {axis} {}..{} ({} voxels), reads {} lines, host {host} at the peak\n",
                        run.start,
                        run.end,
                        sl.voxels(d[0]),
                        if self.reads_whole { self.slabs.total_lines } else { lines.len() },
                    );
                }
                None => s += &format!("rank {r}: no slab (more ranks than slices), host {host}\n"),
            }
        }
        s += &format!(
            "would write: {} ({} bytes)\n",
            self.out.display(),
            self.out_bytes
        );
        s
    }
}

/// `voxlab reconstruct --distributed --dry-run --ranks N`: how [`super::run`] on `ranks`
/// ranks would cut the grid and what each rank would read and hold, after reading the
/// input's header and geometry (no MPI needed), computing and writing nothing.
///
/// # Errors
/// As [`super::run`] up to the work.
pub fn plan(
    a: &ReconstructRequest,
    ranks: usize,
    progress: &dyn Progress,
) -> Result<DistributedPlan> {
    if a.method.iterative().is_some() {
        check_distributed(a)?;
        return Err(Error::invalid(
            "--dry-run",
            "an iterative method's ranks cut the views, not the grid: plan them with \
             jobs::distributed::dry_run (what the command line calls)",
        ));
    }
    let (whole, g, grid, slabs) = planned(a, ranks, progress)?;
    let real = if a.backend == Backend::CpuF32 { 4 } else { 8 };
    // A parallel sinogram is padded to the circle's diagonal.
    let pcols = if g.beam == Beam::Parallel && !a.no_circle {
        crate::ct::circle_diagonal(g.cols)
    } else {
        g.cols
    } as u64;
    let stack = (g.n_angles() * g.rows * g.cols) as u64;
    let host_bytes = slabs
        .slabs
        .iter()
        .zip(&slabs.lines)
        .map(|(s, lines)| {
            let Some(s) = s else {
                return 0;
            };
            let voxels = s.voxels(grid.dims[0]) as u64;
            let lines = lines.len() as u64;
            // The band of rows every view's bordered copy holds.
            let bands = region_rows(&g, &grid, s);
            let first = bands
                .iter()
                .filter(|b| !b.is_empty())
                .map(|b| b.start)
                .min();
            let band = first.map_or(0, |f| bands.iter().map(|b| b.end).max().unwrap_or(f) - f);
            let bordered = (g.n_angles() * (band + 2)) as u64 * (pcols + 2);
            // Read (f64), padded (f64) and weighted, narrowed and filtered copies, the
            // band, the slab and its f32 values and bytes.
            let read = if whole.is_some() { 8 * stack } else { 0 };
            read + 8 * lines * g.cols as u64
                + 8 * lines * pcols
                + 2 * real * lines * pcols
                + real * bordered
                + voxels * (real + 8)
        })
        .collect();
    let d = grid.dims;
    let shape = npy_shape(d);
    Ok(DistributedPlan {
        grid,
        slabs,
        reads_whole: whole.is_some(),
        host_bytes,
        out: a.out.clone().expect("checked by check_distributed"),
        out_bytes: npy_f32_header(&shape).len() as u64 + 4 * d.iter().product::<usize>() as u64,
    })
}

/// This rank's slab (none: no values), its lines prepared ([`fbp_lines`]), filtered
/// and backprojected in the request's precision, masked to the circle for a parallel
/// beam (unless `no_circle`), widened to f64 (exactly); and the seconds filtering and
/// backprojecting.
fn slab(
    a: &ReconstructRequest,
    p: Lines<f64>,
    g: &Geometry,
    grid: &Grid,
    slab: Option<&Region>,
    progress: &dyn Progress,
) -> Result<(Vec<f64>, f64, f64)> {
    crate::jobs::check_cancel(progress)?;
    let Some(slab) = slab else {
        return Ok((Vec::new(), 0.0, 0.0));
    };
    let (p, g) = fbp_lines(a, p, g.clone())?;
    if a.backend == Backend::CpuF32 {
        slab_values(a, &p.map(|v| v as f32), &g, grid, slab, progress)
    } else {
        slab_values(a, &p, &g, grid, slab, progress)
    }
}

/// [`slab`] in `R`.
fn slab_values<R: Real + rustfft::FftNum>(
    a: &ReconstructRequest,
    p: &Lines<R>,
    g: &Geometry,
    grid: &Grid,
    slab: &Region,
    progress: &dyn Progress,
) -> Result<(Vec<f64>, f64, f64)> {
    let t = Instant::now();
    let q = if a.short_scan {
        filter_lines(
            &crate::cpu::parker::weigh_lines(p, g)?,
            g,
            a.filter,
            FilterMethod::Fft,
        )?
    } else {
        filter_lines(p, g, a.filter, FilterMethod::Fft)?
    };
    let filter_seconds = t.elapsed().as_secs_f64();
    let t = Instant::now();
    progress.begin("reconstructing", "voxel lines", 0);
    let rows = |done, total| progress.advance(done as u64, total as u64);
    let mut v = backproject_region(&q, g, grid, slab, &rows)?;
    progress.end(t.elapsed().as_secs_f64());
    if g.beam == Beam::Parallel && !a.no_circle {
        circle_mask_region(grid.dims, slab, &mut v)?;
    }
    Ok((
        v.iter().map(|x| x.f64()).collect(),
        filter_seconds,
        t.elapsed().as_secs_f64(),
    ))
}

/// What [`whole_image`] gives a rank.
pub(super) struct WholeImage {
    pub grid: Grid,
    /// The image, voxel `(i, j, k)` at `(k·ny + j)·nx + i`.
    pub image: Vec<f64>,
    /// The detector lines this rank read for its slab, and its seconds reading,
    /// filtering and backprojecting.
    pub lines_read: usize,
    pub seconds: [f64; 3],
}

/// FBP/FDK of `a` in slabs on the ranks of `comm` (as [`run`] computes them), after
/// which every rank holds the whole image: the slabs, each in a zero image, summed by
/// [`Comm::all_reduce_sum`] — exact, since they do not overlap, so the image is the
/// single process's bit for bit. `--init fbp` of the iterative methods on ranks.
///
/// # Errors
/// As [`run`] up to the writing.
pub(super) fn whole_image(
    a: &ReconstructRequest,
    comm: &dyn Comm,
    progress: &dyn Progress,
) -> Result<WholeImage> {
    let pre = agree(comm, prepare(a, comm, progress))?;
    let mine = pre.plan.slabs[comm.rank()].clone();
    let computed = slab(a, pre.p, &pre.g, &pre.grid, mine.as_ref(), progress);
    let (values, filter_seconds, backproject_seconds) = agree(comm, computed)?;
    let d = pre.grid.dims;
    let mut image = vec![0.0; d.iter().product()];
    if let Some(s) = &mine {
        let lines = values.chunks(d[0]);
        let at =
            s.k.clone()
                .flat_map(|k| s.j.clone().map(move |j| (k * d[1] + j) * d[0]));
        for (line, at) in lines.zip(at) {
            image[at..at + d[0]].copy_from_slice(line);
        }
    }
    comm.all_reduce_sum(&mut image);
    Ok(WholeImage {
        grid: pre.grid,
        image,
        lines_read: pre.lines_read,
        seconds: [pre.read_seconds, filter_seconds, backproject_seconds],
    })
}

/// Reconstructs on every rank of `comm` and writes one `.npy` file (module docs). Every
/// rank calls it with the same request; `progress` reports this rank's slab (give rank
/// 0 a terminal and the others `&()`).
///
/// # Errors
/// As [`crate::jobs::reconstruct::run`]; options `--distributed` does not take (an
/// iterative method, the GPU, `--truth`, an output that is not `.npy`); on more than
/// one rank, [`Error::Rank`] with the lowest failing rank's message.
pub(super) fn run(
    a: &ReconstructRequest,
    comm: &dyn Comm,
    progress: &dyn Progress,
) -> Result<Distributed> {
    let counted = Counted::new(comm);
    let comm: &dyn Comm = &counted;
    let rank = comm.rank();
    let pre = agree(comm, prepare(a, comm, progress))?;
    let Prepared {
        p,
        intensity,
        g,
        grid,
        plan,
        lines_read,
        read_seconds,
    } = pre;
    let parallel = g.beam == Beam::Parallel;
    let slab_of_rank = plan.slabs[rank].clone();
    let f32_path = a.backend == Backend::CpuF32;
    let computed = slab(a, p, &g, &grid, slab_of_rank.as_ref(), progress);
    let (values, filter_seconds, backproject_seconds) = agree(comm, computed)?;
    let values: Vec<f32> = values.iter().map(|&v| v as f32).collect();
    let slab = slab_of_rank;

    // The output: one run of `nx·nj` values per slice `k` of this rank's slab.
    let out = a.out.clone().expect("checked in prepare");
    let d = grid.dims;
    let t = Instant::now();
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let mut parts: Vec<(u64, &[u8])> = Vec::new();
    if let Some(s) = &slab {
        let run = 4 * d[0] * s.j.len();
        for (n, k) in s.k.clone().enumerate() {
            let at = 4 * d[0] * (s.j.start + d[1] * k);
            parts.push((at as u64, &bytes[n * run..(n + 1) * run]));
        }
    }
    let bytes_written = write_shared_npy(comm, &out, d, parts)?;
    let write_seconds = t.elapsed().as_secs_f64();

    // Every rank's report and the value range.
    let mine = RankReport {
        slab: slab.clone(),
        lines_read,
        read_seconds,
        filter_seconds,
        backproject_seconds,
        write_seconds,
        bytes_written,
        bytes_sent: counted.sent(),
        intensity,
        ..Default::default()
    };
    let (ranks, range) = gather_reports(comm, &mine, value_range(&values));
    Ok(Distributed {
        grid,
        parallel,
        what: if f32_path { "cpu f32" } else { "cpu f64" }.into(),
        axis: plan.axis,
        total_lines: plan.total_lines,
        range,
        out,
        ranks,
        iterative: None,
    })
}
