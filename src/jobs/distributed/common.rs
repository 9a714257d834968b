//! What the distributed jobs share: the communicator ([`Comm`], MPI's behind feature
//! `mpi`), the agreement that ends every phase ([`agree`]), the ranks' reports, and the
//! checks and writing of a distributed reconstruction's `.npy` output.

use crate::cpu::fbp::{Grid, Region};
use crate::ct::flat_field::{line_integrals_lines, IntensityReport};
use crate::ct::{Geometry, Lines, Projections};
use crate::error::{Error, Result};
use crate::io::npy::npy_f32_header;
use crate::io::projections::{line_stack, read_projection_lines, read_projections_grid};
use crate::io::ReadOptions;
use crate::io::{write_part, SharedOutput};
use crate::jobs::reconstruct::{
    check_request, extension, fbp_grid, geometry_for, npy_shape, read_fields, IterationLog,
    ReconstructRequest,
};
use crate::jobs::{Backend, Progress};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// The processes a distributed job runs on. Every method is a collective: every rank
/// calls it, in the same order.
pub trait Comm {
    /// This process's rank, `0 … size − 1`.
    fn rank(&self) -> usize;
    /// How many ranks there are.
    fn size(&self) -> usize;
    /// Every rank's `values` (each rank gives as many), concatenated in rank order, on
    /// every rank.
    fn all_gather(&self, values: &[f64]) -> Vec<f64>;
    /// `root`'s `bytes` on every rank (replacing theirs).
    fn broadcast(&self, root: usize, bytes: &mut Vec<u8>);
    /// Every rank's `values` summed elementwise, on every rank (replacing this rank's;
    /// each rank gives as many). The default adds the [`Comm::all_gather`]ed buffers in
    /// rank order — rank 0's, plus rank 1's, plus … — so every rank gets the same bits,
    /// and the same number of ranks gives the same bits from the same inputs. It goes
    /// [`REDUCE_CHUNK`] values at a time ([`all_reduce_sum_in_chunks`]), so it holds
    /// `size()` copies of one chunk, not of the buffer, while it adds. An override must
    /// give every rank the same bits too.
    fn all_reduce_sum(&self, values: &mut [f64]) {
        all_reduce_sum_in_chunks(self, values, REDUCE_CHUNK);
    }
    /// Personalised exchange: `messages[r]` goes to rank `r` (one per rank, this
    /// rank's own included); returns what every rank sent this one, in rank order.
    /// The default takes one broadcast per rank; MPI's is `MPI_Alltoallv`.
    fn all_to_all(&self, messages: Vec<Vec<u8>>) -> Vec<Vec<u8>> {
        let (me, size) = (self.rank(), self.size());
        assert_eq!(
            messages.len(),
            size,
            "all_to_all takes one message per rank"
        );
        (0..size)
            .map(|root| {
                let mut packed = Vec::new();
                if root == me {
                    for m in &messages {
                        packed.extend_from_slice(&(m.len() as u64).to_le_bytes());
                        packed.extend_from_slice(m);
                    }
                }
                self.broadcast(root, &mut packed);
                unpack(&packed).swap_remove(me)
            })
            .collect()
    }
    /// Every rank's `bytes` on `root`, in rank order (an empty list on the others).
    /// The default takes one broadcast per rank; MPI's is `MPI_Gatherv`.
    fn gather(&self, root: usize, bytes: Vec<u8>) -> Vec<Vec<u8>> {
        let (me, size) = (self.rank(), self.size());
        let mut out = Vec::new();
        for from in 0..size {
            let mut b = if from == me {
                bytes.clone()
            } else {
                Vec::new()
            };
            self.broadcast(from, &mut b);
            if me == root {
                out.push(b);
            }
        }
        out
    }
}

/// Length-prefixed messages (`u64` little-endian length, then the bytes) back into a
/// list.
fn unpack(mut packed: &[u8]) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    while packed.len() >= 8 {
        let n = u64::from_le_bytes(packed[..8].try_into().expect("eight bytes")) as usize;
        out.push(packed[8..8 + n].to_vec());
        packed = &packed[8 + n..];
    }
    out
}

/// One process alone: the distributed job as a plain one.
pub struct Solo;

impl Comm for Solo {
    fn rank(&self) -> usize {
        0
    }
    fn size(&self) -> usize {
        1
    }
    fn all_gather(&self, values: &[f64]) -> Vec<f64> {
        values.to_vec()
    }
    fn broadcast(&self, _root: usize, _bytes: &mut Vec<u8>) {}
    fn all_to_all(&self, messages: Vec<Vec<u8>>) -> Vec<Vec<u8>> {
        messages
    }
    fn gather(&self, _root: usize, bytes: Vec<u8>) -> Vec<Vec<u8>> {
        vec![bytes]
    }
}

/// A [`Comm`] that counts the bytes this rank sends through it to other ranks.
pub(crate) struct Counted<'a> {
    inner: &'a dyn Comm,
    sent: std::cell::Cell<u64>,
}

impl<'a> Counted<'a> {
    pub(crate) fn new(inner: &'a dyn Comm) -> Self {
        Counted {
            inner,
            sent: std::cell::Cell::new(0),
        }
    }
    /// Bytes sent so far.
    pub(crate) fn sent(&self) -> u64 {
        self.sent.get()
    }
}

impl Comm for Counted<'_> {
    fn rank(&self) -> usize {
        self.inner.rank()
    }
    fn size(&self) -> usize {
        self.inner.size()
    }
    fn all_gather(&self, values: &[f64]) -> Vec<f64> {
        self.sent.set(self.sent.get() + 8 * values.len() as u64);
        self.inner.all_gather(values)
    }
    fn all_reduce_sum(&self, values: &mut [f64]) {
        // This rank's contribution, as for all_gather.
        self.sent.set(self.sent.get() + 8 * values.len() as u64);
        self.inner.all_reduce_sum(values)
    }
    fn broadcast(&self, root: usize, bytes: &mut Vec<u8>) {
        if root == self.rank() {
            // The length, then the bytes.
            self.sent.set(self.sent.get() + 8 + bytes.len() as u64);
        }
        self.inner.broadcast(root, bytes)
    }
    fn all_to_all(&self, messages: Vec<Vec<u8>>) -> Vec<Vec<u8>> {
        let me = self.rank();
        let out: u64 = messages
            .iter()
            .enumerate()
            .filter(|(r, _)| *r != me)
            .map(|(_, m)| m.len() as u64)
            .sum();
        self.sent.set(self.sent.get() + out);
        self.inner.all_to_all(messages)
    }
    fn gather(&self, root: usize, bytes: Vec<u8>) -> Vec<Vec<u8>> {
        if root != self.rank() {
            self.sent.set(self.sent.get() + bytes.len() as u64);
        }
        self.inner.gather(root, bytes)
    }
}

/// The end of a phase: `r` on every rank when it succeeded on all; otherwise, on
/// every rank, [`Error::Rank`] with the lowest failing rank's message (one process
/// alone gets its own error back unchanged). An error that is already an agreement's
/// (an [`Error::Rank`] of this many ranks, which every rank then holds: an agreement
/// within the phase, as the iterative methods make every iteration) passes through
/// unchanged.
pub fn agree<T>(comm: &dyn Comm, r: Result<T>) -> Result<T> {
    let size = comm.size();
    let flag = match &r {
        Ok(_) => 1.0,
        Err(Error::Rank { ranks, .. }) if *ranks == size && size > 1 => 2.0,
        Err(_) => 0.0,
    };
    let flags = comm.all_gather(&[flag]);
    let Some(first) = flags.iter().position(|&f| f != 1.0) else {
        return r;
    };
    if size == 1 || flags[first] == 2.0 {
        return r;
    }
    let mut message = match &r {
        Err(e) if comm.rank() == first => e.to_string().into_bytes(),
        _ => Vec::new(),
    };
    comm.broadcast(first, &mut message);
    Err(Error::Rank {
        rank: first,
        ranks: comm.size(),
        message: String::from_utf8_lossy(&message).into_owned(),
    })
}

/// `n` slices cut into `ranks` runs differing by at most one; the ranks past the `n`th
/// get `None`.
pub(super) fn runs(n: usize, ranks: usize) -> Vec<Option<Range<usize>>> {
    // With more ranks than slices, the first `n` get one each.
    let m = n.min(ranks);
    (0..ranks)
        .map(|r| (r < m).then(|| r * n / m..(r + 1) * n / m))
        .collect()
}

/// Values per all-gather of [`Comm::all_reduce_sum`] (8 MiB of f64).
pub const REDUCE_CHUNK: usize = 1 << 20;

/// [`Comm::all_reduce_sum`]'s default, `chunk` values at a time: each chunk is
/// all-gathered and added in rank order, so the sums are the same bits whatever the
/// chunk (every value is summed alone). A collective: every rank calls it with as many
/// values and the same `chunk`.
pub fn all_reduce_sum_in_chunks<C: Comm + ?Sized>(comm: &C, values: &mut [f64], chunk: usize) {
    use rayon::prelude::*;
    let size = comm.size();
    for part in values.chunks_mut(chunk.max(1)) {
        let n = part.len();
        let all = comm.all_gather(part);
        assert_eq!(all.len(), n * size, "all_reduce_sum: one buffer per rank");
        part.par_iter_mut().enumerate().for_each(|(i, v)| {
            // Rank 0's value first (not 0 + it: that would turn −0 into +0).
            let mut s = all[i];
            for r in 1..size {
                s += all[r * n + i];
            }
            *v = s;
        });
    }
}

/// What one rank did.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct RankReport {
    /// FBP/FDK: its slab (`None`: more ranks than slices; an iterative method).
    pub slab: Option<Region>,
    /// An iterative method: its views (`None`: FBP/FDK; more ranks than views).
    pub views: Option<Range<usize>>,
    /// The detector lines it read from the file.
    pub lines_read: usize,
    /// Seconds reading, filtering, backprojecting and writing.
    pub read_seconds: f64,
    pub filter_seconds: f64,
    pub backproject_seconds: f64,
    pub write_seconds: f64,
    /// An iterative method: seconds building its views' matched pair, iterating (the
    /// weights included), and of those, in the all-reduces (waiting for the other
    /// ranks included).
    pub pair_seconds: f64,
    pub iterate_seconds: f64,
    pub reduce_seconds: f64,
    /// Bytes of the output it wrote (rank 0's include the header).
    pub bytes_written: u64,
    /// Bytes it sent to the other ranks before the reports (its all-gather and
    /// all-reduce inputs and what it broadcast as the root): the agreements, the
    /// output's name and, for an iterative method, the sums over the views.
    pub bytes_sent: u64,
    /// With `--flat`: the counts of its lines' conversion from intensities.
    pub intensity: Option<IntensityReport>,
}

/// The number of values [`RankReport::values`] gives.
const REPORT_VALUES: usize = 22;

impl RankReport {
    /// The report as numbers, for the all-gather at the end.
    fn values(&self) -> [f64; REPORT_VALUES] {
        let range =
            |r: Option<&Range<usize>>| r.map_or([-1.0, -1.0], |r| [r.start as f64, r.end as f64]);
        let [j0, j1] = range(self.slab.as_ref().map(|s| &s.j));
        let [k0, k1] = range(self.slab.as_ref().map(|s| &s.k));
        let [v0, v1] = range(self.views.as_ref());
        let i = self.intensity.map_or([-1.0, 0.0, 0.0, 0.0, 0.0, 0.0], |i| {
            [
                i.samples as f64,
                i.pixels as f64,
                i.dead_pixels as f64,
                i.starved as f64,
                i.clamped as f64,
                i.above_flat as f64,
            ]
        });
        [
            j0,
            j1,
            k0,
            k1,
            v0,
            v1,
            self.lines_read as f64,
            self.read_seconds,
            self.filter_seconds,
            self.backproject_seconds,
            self.write_seconds,
            self.pair_seconds,
            self.iterate_seconds,
            self.reduce_seconds,
            self.bytes_written as f64,
            self.bytes_sent as f64,
            i[0],
            i[1],
            i[2],
            i[3],
            i[4],
            i[5],
        ]
    }

    /// The report from [`Self::values`].
    fn from_values(r: &[f64]) -> RankReport {
        let range = |a: f64, b: f64| (a >= 0.0).then_some(a as usize..b as usize);
        RankReport {
            slab: range(r[0], r[1]).map(|j| Region {
                j,
                k: r[2] as usize..r[3] as usize,
            }),
            views: range(r[4], r[5]),
            lines_read: r[6] as usize,
            read_seconds: r[7],
            filter_seconds: r[8],
            backproject_seconds: r[9],
            write_seconds: r[10],
            pair_seconds: r[11],
            iterate_seconds: r[12],
            reduce_seconds: r[13],
            bytes_written: r[14] as u64,
            bytes_sent: r[15] as u64,
            intensity: (r[16] >= 0.0).then(|| IntensityReport {
                samples: r[16] as usize,
                pixels: r[17] as usize,
                dead_pixels: r[18] as usize,
                starved: r[19] as usize,
                clamped: r[20] as usize,
                above_flat: r[21] as usize,
            }),
        }
    }
}

/// Every rank's report, in rank order, and the smallest and largest of the values
/// every rank wrote (`lo`, `hi`: this rank's), on every rank. Its all-gather is not
/// counted in the reports' `bytes_sent`.
pub(super) fn gather_reports(
    comm: &dyn Comm,
    mine: &RankReport,
    (lo, hi): (f64, f64),
) -> (Vec<RankReport>, (f64, f64)) {
    let mut v = mine.values().to_vec();
    v.extend_from_slice(&[lo, hi]);
    let n = v.len();
    let all = comm.all_gather(&v);
    let reports = all
        .chunks_exact(n)
        .map(|r| RankReport::from_values(&r[..REPORT_VALUES]))
        .collect();
    let range = all
        .chunks_exact(n)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), r| {
            (l.min(r[n - 2]), h.max(r[n - 1]))
        });
    (reports, range)
}

/// A distributed reconstruction, as every rank knows it at the end.
#[derive(Clone, Debug)]
pub struct Distributed {
    pub grid: Grid,
    /// FBP (parallel) or FDK (cone).
    pub parallel: bool,
    /// `cpu f64` or `cpu f32`.
    pub what: String,
    /// FBP/FDK: the grid axis the slabs run along, 1 (`j`) or 2 (`k`); 0 for an
    /// iterative method (every rank holds the whole grid).
    pub axis: usize,
    /// The detector lines of the whole stack.
    pub total_lines: usize,
    /// The smallest and largest value written.
    pub range: (f64, f64),
    /// The output written.
    pub out: PathBuf,
    /// Every rank's report, in rank order.
    pub ranks: Vec<RankReport>,
    /// An iterative method: its residuals and objectives per iteration (the same on
    /// every rank).
    pub iterative: Option<IterationLog>,
}

impl Distributed {
    /// With `--flat`: the conversion from intensities over every rank's lines — the
    /// counts summed over the ranks (a line several ranks read counted by each; the
    /// views of an iterative method are read once, so there the sums are the single
    /// process's), the dead pixels the flat image's.
    pub fn intensity(&self) -> Option<IntensityReport> {
        let mut it = self.ranks.iter().filter_map(|r| r.intensity);
        let first = it.next()?;
        Some(it.fold(first, |s, r| IntensityReport {
            samples: s.samples + r.samples,
            starved: s.starved + r.starved,
            clamped: s.clamped + r.clamped,
            above_flat: s.above_flat + r.above_flat,
            ..s
        }))
    }

    /// One line per rank: its slab or views, what it read, its times.
    pub fn describe(&self) -> String {
        if self.iterative.is_some() {
            return self.describe_iterative();
        }
        let axis = if self.axis == 1 { 'j' } else { 'k' };
        let mut s = String::new();
        for (r, rep) in self.ranks.iter().enumerate() {
            let slab = match &rep.slab {
                Some(sl) if self.axis == 1 => format!("{axis} {}..{}", sl.j.start, sl.j.end),
                Some(sl) => format!("{axis} {}..{}", sl.k.start, sl.k.end),
                None => "no slab".into(),
            };
            s.push_str(&format!(
                "rank {r}: {slab}, read {} of {} detector lines in {:.3} s, filter {:.3} s, \
                 backprojection {:.3} s, wrote {} bytes in {:.3} s, sent {} bytes\n",
                rep.lines_read,
                self.total_lines,
                rep.read_seconds,
                rep.filter_seconds,
                rep.backproject_seconds,
                rep.bytes_written,
                rep.write_seconds,
                rep.bytes_sent
            ));
        }
        s
    }
}

/// The options `--distributed` refuses, checked before anything is read.
pub(super) fn check_distributed(a: &ReconstructRequest) -> Result<PathBuf> {
    if a.backend == Backend::Gpu {
        return Err(Error::Unsupported {
            job: "a distributed reconstruction".into(),
            backend: "gpu".into(),
            message: "the ranks reconstruct on the CPU (--backend cpu or cpu-f32)".into(),
        });
    }
    if a.frame.is_some() {
        return Err(Error::invalid(
            "--frame",
            "does not go with --distributed yet (the ranks read their lines from a file \
             of one stack): pick the frame on one process first (voxlab convert --frame)",
        ));
    }
    if a.truth.is_some() {
        return Err(Error::invalid(
            "--truth",
            "does not go with --distributed (reconstruct on one process to compare)",
        ));
    }
    let out = a
        .out
        .clone()
        .ok_or_else(|| Error::invalid("--out", "a distributed reconstruction needs an output"))?;
    if extension(&out).as_deref() != Some("npy") {
        return Err(Error::invalid(
            "--out",
            "a distributed reconstruction is written as one .npy file",
        ));
    }
    Ok(out)
}

/// The request checked, the stack when it must be read whole (`None`: a stack read by
/// lines, [`line_stack`], of which only the header is read here), the geometry and the
/// grid.
pub(super) fn input_geometry(
    a: &ReconstructRequest,
    progress: &dyn Progress,
) -> Result<(Option<Projections<f64>>, Geometry, Grid)> {
    check_request(a)?;
    check_distributed(a)?;
    // The geometry is checked against the stack's shape; only a header is read so far.
    // A stack read by lines: its shape and detector grid alone, nothing of it held yet.
    let (whole, header, shape) = match line_stack(&a.input)? {
        Some(l) => (None, l.grid, l.shape),
        None => {
            let (p, header) = read_projections_grid::<f64>(&a.input, &ReadOptions::default())?;
            let shape = [p.angles, p.rows, p.cols];
            (Some(p), header, shape)
        }
    };
    let (g, geometry_file) = geometry_for(a, shape, header.as_ref())?;
    if let Some(f) = &geometry_file {
        progress.note(&format!("using the geometry {}", f.display()));
    }
    let grid = fbp_grid(a, &g, progress)?;
    Ok((whole, g, grid))
}

/// This rank's detector lines `ids` as line integrals: taken from the stack read whole
/// (`whole`) or read from the file by lines, then, with `--flat` (and `--dark`),
/// converted from intensities line by line ([`line_integrals_lines`]: each value the
/// single process's bit for bit), with the counts of that conversion.
///
/// # Errors
/// The readers' errors; flat or dark images that do not fit the detector.
pub(super) fn rank_lines(
    a: &ReconstructRequest,
    whole: Option<&Projections<f64>>,
    ids: &[usize],
) -> Result<(Lines<f64>, Option<IntensityReport>)> {
    let p = match whole {
        Some(p) => p.lines(ids)?,
        None => read_projection_lines::<f64>(&a.input, ids)?,
    };
    match read_fields(a, p.rows, p.cols)? {
        None => Ok((p, None)),
        Some((flat, dark)) => {
            let (p, report) = line_integrals_lines(&p, &flat, dark.as_deref())?;
            Ok((p, Some(report)))
        }
    }
}

/// The bytes of a path, to send it to the other ranks.
pub(super) fn path_bytes(p: &Path) -> Vec<u8> {
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        p.as_os_str().as_bytes().to_vec()
    }
    #[cfg(not(unix))]
    {
        p.to_string_lossy().into_owned().into_bytes()
    }
}

pub(super) fn bytes_path(b: Vec<u8>) -> PathBuf {
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStringExt;
        PathBuf::from(std::ffi::OsString::from_vec(b))
    }
    #[cfg(not(unix))]
    {
        PathBuf::from(String::from_utf8_lossy(&b).into_owned())
    }
}

/// The smallest and largest of `values` (infinities when there are none).
pub(super) fn value_range(values: &[f32]) -> (f64, f64) {
    values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
            (l.min(v as f64), h.max(v as f64))
        })
}

/// Writes one float32 `.npy` file of a grid of `dims` voxels from every rank's
/// `parts` (byte offsets into the data after the header, and the bytes): rank 0
/// creates a temporary file beside `out` at its final length and writes the header,
/// every rank writes its parts and syncs, and rank 0 renames the file once all have
/// written; each step ends with an agreement ([`agree`]), so a failure anywhere leaves
/// no file. Returns the bytes this rank wrote.
///
/// # Errors
/// I/O errors on any rank, as [`Error::Rank`] on more than one.
pub(super) fn write_shared_npy(
    comm: &dyn Comm,
    out: &Path,
    dims: [usize; 3],
    parts: Vec<(u64, &[u8])>,
) -> Result<u64> {
    let rank = comm.rank();
    let header = npy_f32_header(&npy_shape(dims));
    let total = header.len() as u64 + 4 * dims.iter().product::<usize>() as u64;
    let created = if rank == 0 {
        SharedOutput::create(out, total).map(Some)
    } else {
        Ok(None)
    };
    let created = agree(comm, created)?;
    let mut temp = created
        .as_ref()
        .map_or(Vec::new(), |c| path_bytes(c.temp_path()));
    comm.broadcast(0, &mut temp);
    let temp = bytes_path(temp);
    let skip = header.len() as u64;
    let mut at: Vec<(u64, &[u8])> = Vec::with_capacity(parts.len() + 1);
    if rank == 0 {
        at.push((0, &header));
    }
    at.extend(parts.into_iter().map(|(o, b)| (skip + o, b)));
    let bytes_written: u64 = at.iter().map(|(_, b)| b.len() as u64).sum();
    agree(comm, write_part(&temp, out, &at))?;
    let committed = match created {
        Some(c) => c.commit(),
        None => Ok(()),
    };
    agree(comm, committed)?;
    Ok(bytes_written)
}

/// MPI's world communicator as a [`Comm`] (feature `mpi`; run under `mpirun`).
#[cfg(feature = "mpi")]
pub mod mpi {
    use super::Comm;
    use crate::error::{Error, Result};
    use mpi::topology::SimpleCommunicator;
    use mpi::traits::{Communicator, Root};

    use std::sync::{Arc, Mutex};
    use std::time::{Duration, Instant};

    /// MPI, initialised for the life of this value (finalised when it is dropped).
    ///
    /// Every collective is watched: a rank that waits longer than the limit for the
    /// others (one of them is stuck, or died without ending the job) says so and exits
    /// with status 1, which makes `mpirun` end the job, instead of hanging forever. The
    /// limit is `VOXLAB_MPI_TIMEOUT` seconds ([`DEFAULT_TIMEOUT`] without it). For the
    /// tests of that, `VOXLAB_MPI_STALL_RANK=R` makes rank `R` stall in [`Mpi::init`].
    pub struct Mpi {
        _universe: mpi::environment::Universe,
        world: SimpleCommunicator,
        watch: Arc<Watch>,
    }

    /// How long a rank waits in one collective before it gives up, in seconds.
    pub const DEFAULT_TIMEOUT: f64 = 3600.0;

    /// The collective a rank is in, and since when.
    struct Watch {
        inside: Mutex<Option<(Instant, &'static str)>>,
    }

    /// Clears the watch when the collective returns.
    struct Inside<'a>(&'a Watch);

    impl Drop for Inside<'_> {
        fn drop(&mut self) {
            *self.0.inside.lock().unwrap_or_else(|e| e.into_inner()) = None;
        }
    }

    impl Mpi {
        /// Initialises MPI and starts the watch of its collectives.
        ///
        /// # Errors
        /// MPI already initialised in this process; a `VOXLAB_MPI_TIMEOUT` that is not
        /// a positive number of seconds.
        pub fn init() -> Result<Mpi> {
            let limit = match std::env::var("VOXLAB_MPI_TIMEOUT") {
                Err(_) => DEFAULT_TIMEOUT,
                Ok(v) => match v.trim().parse::<f64>() {
                    Ok(t) if t > 0.0 && t.is_finite() => t,
                    _ => {
                        return Err(Error::invalid(
                            "VOXLAB_MPI_TIMEOUT",
                            format!("{v:?} is not a positive number of seconds"),
                        ))
                    }
                },
            };
            let universe = mpi::initialize().ok_or_else(|| {
                Error::invalid("MPI", "could not be initialised (it already was)")
            })?;
            let world = universe.world();
            let (rank, size) = (world.rank(), world.size());
            let watch = Arc::new(Watch {
                inside: Mutex::new(None),
            });
            let w = watch.clone();
            std::thread::spawn(move || loop {
                std::thread::sleep(Duration::from_millis(100));
                let inside = *w.inside.lock().unwrap_or_else(|e| e.into_inner());
                if let Some((since, what)) = inside {
                    if since.elapsed().as_secs_f64() > limit {
                        eprintln!(
                            "voxlab: error: rank {rank} of {size}: no answer from the other \
                             ranks after {limit} s in {what} (a rank is stuck or died); \
                             ending the job (VOXLAB_MPI_TIMEOUT sets the limit)"
                        );
                        std::process::exit(1);
                    }
                }
            });
            if std::env::var("VOXLAB_MPI_STALL_RANK").ok().as_deref()
                == Some(rank.to_string().as_str())
            {
                loop {
                    std::thread::sleep(Duration::from_secs(1));
                }
            }
            Ok(Mpi {
                _universe: universe,
                world,
                watch,
            })
        }

        fn enter(&self, what: &'static str) -> Inside<'_> {
            *self.watch.inside.lock().unwrap_or_else(|e| e.into_inner()) =
                Some((Instant::now(), what));
            Inside(&self.watch)
        }
    }

    impl Comm for Mpi {
        fn rank(&self) -> usize {
            self.world.rank() as usize
        }
        fn size(&self) -> usize {
            self.world.size() as usize
        }
        fn all_gather(&self, values: &[f64]) -> Vec<f64> {
            let _watch = self.enter("all_gather");
            use mpi::traits::CommunicatorCollectives;
            let mut out = vec![0.0; values.len() * self.size()];
            self.world.all_gather_into(values, &mut out[..]);
            out
        }
        fn broadcast(&self, root: usize, bytes: &mut Vec<u8>) {
            let _watch = self.enter("broadcast");
            let root = self.world.process_at_rank(root as i32);
            let mut len = bytes.len() as u64;
            root.broadcast_into(&mut len);
            bytes.resize(len as usize, 0);
            root.broadcast_into(&mut bytes[..]);
        }
        fn all_to_all(&self, messages: Vec<Vec<u8>>) -> Vec<Vec<u8>> {
            let _watch = self.enter("all_to_all");
            use mpi::datatype::{Partition, PartitionMut};
            use mpi::traits::CommunicatorCollectives;
            let size = self.size();
            assert_eq!(
                messages.len(),
                size,
                "all_to_all takes one message per rank"
            );
            // The lengths first, then the bytes.
            let lens: Vec<u64> = messages.iter().map(|m| m.len() as u64).collect();
            let mut theirs = vec![0u64; size];
            self.world.all_to_all_into(&lens[..], &mut theirs[..]);
            let counts = |l: &[u64]| l.iter().map(|&n| n as i32).collect::<Vec<i32>>();
            let displs = |c: &[i32]| {
                c.iter()
                    .scan(0i32, |at, &n| {
                        let d = *at;
                        *at += n;
                        Some(d)
                    })
                    .collect::<Vec<i32>>()
            };
            let (sc, rc) = (counts(&lens), counts(&theirs));
            let (sd, rd) = (displs(&sc), displs(&rc));
            let send: Vec<u8> = messages.concat();
            let mut recv = vec![0u8; theirs.iter().sum::<u64>() as usize];
            {
                let s = Partition::new(&send[..], &sc[..], &sd[..]);
                let mut r = PartitionMut::new(&mut recv[..], &rc[..], &rd[..]);
                self.world.all_to_all_varcount_into(&s, &mut r);
            }
            (0..size)
                .map(|r| recv[rd[r] as usize..(rd[r] + rc[r]) as usize].to_vec())
                .collect()
        }
        fn gather(&self, root: usize, bytes: Vec<u8>) -> Vec<Vec<u8>> {
            let _watch = self.enter("gather");
            use mpi::datatype::PartitionMut;
            let size = self.size();
            let len = bytes.len() as u64;
            let at = self.world.process_at_rank(root as i32);
            if self.rank() == root {
                let mut lens = vec![0u64; size];
                at.gather_into_root(&len, &mut lens[..]);
                let rc: Vec<i32> = lens.iter().map(|&n| n as i32).collect();
                let rd: Vec<i32> = rc
                    .iter()
                    .scan(0i32, |a, &n| {
                        let d = *a;
                        *a += n;
                        Some(d)
                    })
                    .collect();
                let mut recv = vec![0u8; lens.iter().sum::<u64>() as usize];
                {
                    let mut r = PartitionMut::new(&mut recv[..], &rc[..], &rd[..]);
                    at.gather_varcount_into_root(&bytes[..], &mut r);
                }
                (0..size)
                    .map(|r| recv[rd[r] as usize..(rd[r] + rc[r]) as usize].to_vec())
                    .collect()
            } else {
                at.gather_into(&len);
                at.gather_varcount_into(&bytes[..]);
                Vec::new()
            }
        }
    }
}
