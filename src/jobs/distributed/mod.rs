//! `voxlab reconstruct --distributed`: FBP/FDK on several processes (the ranks of a
//! [`Comm`], MPI's under `mpirun`), the volume cut into slabs, one per rank; SIRT and
//! CGLS with the views cut among the ranks instead (`distributed/iterative.rs`: every
//! rank holds the whole image, and the backprojections of the ranks' views are added
//! by [`Comm::all_reduce_sum`] every iteration).
//!
//! # How the work is cut
//! [`slab_plan`] cuts the reconstruction grid along `k` (z-slabs) or `j`, whichever
//! makes the ranks read fewer detector lines in all: a slab's voxels project, in every
//! view, into a band of detector rows (the extreme rows are those of the slab box's
//! corners, since a projection maps the box to the hull of its corners' images), and a
//! rank reads only those rows, one more on each side for the bilinear taps, from a 3-D
//! stack in one uncompressed block (`.npy`, raw NRRD, binary MetaImage; other files are
//! read whole, and only the rank's lines are kept), and
//! holds only them: they are weighted and filtered as [`crate::ct::Lines`], and the
//! backprojection copies the band of rows the slab reads, so a rank's memory follows
//! its slab, not the detector. The ramp filter transforms two detector
//! lines in one complex FFT (lines `2m` and `2m + 1`, [`crate::cpu::ramp`]), so each
//! line's partner is read too: the filtered lines a slab uses are then bit for bit
//! those of the whole stack, and so is the slab ([`crate::cpu::fbp::backproject_region`]). The result
//! file equals the single-process one byte for byte, whatever the number of ranks.
//!
//! # The output
//! One float32 `.npy` file: rank 0 creates it beside the output at its final length,
//! each rank writes its slab's byte ranges, and rank 0 renames it once every rank has
//! written ([`crate::io::SharedOutput`]). A failure on any rank fails the job on every
//! rank after the phase it happened in (every phase ends with an agreement,
//! [`agree`]), with the lowest failing rank's message; no file is left behind.
//!
//! `--dry-run --ranks N` ([`dry_run`]) prints either cut without MPI.
//!
//! Not distributed yet: the GPU backend, `--truth`.

mod common;
mod fbp;
mod iterative;

#[cfg(feature = "mpi")]
pub use common::mpi;
pub(crate) use common::Counted;
pub use common::{
    agree, all_reduce_sum_in_chunks, Comm, Distributed, RankReport, Solo, REDUCE_CHUNK,
};
pub use fbp::{plan, region_lines, slab_plan, DistributedPlan, SlabPlan};
pub use iterative::ViewsPlan;

use super::reconstruct::ReconstructRequest;
use super::Progress;
use crate::error::Result;

/// What `voxlab reconstruct --distributed --dry-run --ranks N` prints: the slab plan
/// of FBP/FDK ([`plan`]) or the view plan of the iterative methods ([`ViewsPlan`]), after
/// reading the input's header and geometry, computing and writing nothing.
///
/// # Errors
/// As [`run`] up to the work.
pub fn dry_run(a: &ReconstructRequest, ranks: usize, progress: &dyn Progress) -> Result<String> {
    if a.method.iterative().is_some() {
        Ok(iterative::plan(a, ranks, progress)?.describe())
    } else {
        Ok(plan(a, ranks, progress)?.describe())
    }
}

/// Reconstructs on every rank of `comm` and writes one `.npy` file (module docs):
/// FBP/FDK in slabs, the iterative methods with the views cut among the ranks. Every rank calls
/// it with the same request; `progress` reports this rank's part (give rank 0 a
/// terminal and the others `&()`).
///
/// # Errors
/// As [`super::reconstruct::run`]; options `--distributed` does not take (the GPU,
/// `--truth`, `--flat`/`--frame`, an output that is not `.npy`); on more than one rank,
/// [`crate::Error::Rank`] with the lowest failing rank's message.
pub fn run(
    a: &ReconstructRequest,
    comm: &dyn Comm,
    progress: &dyn Progress,
) -> Result<Distributed> {
    if a.method.iterative().is_some() {
        iterative::run(a, comm, progress)
    } else {
        fbp::run(a, comm, progress)
    }
}
