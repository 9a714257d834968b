//! One file per subcommand: its arguments and a `run` that maps them to a library job
//! (`voxlab::jobs`), then the job's result to files and messages.

pub mod adaptive;
pub mod bench;
pub mod compare;
pub mod convert;
pub mod d2vr;
pub mod demo;
pub mod fft;
pub mod fvr;
pub mod info;
pub mod phantom;
pub mod process;
pub mod project;
pub mod reconstruct;
pub mod render;
pub mod slice;
pub mod tf;
pub mod view;

use std::process::ExitCode;
use voxlab::jobs::distributed::Comm;
use voxlab::jobs::Progress;
use voxlab::Result;

/// `--distributed`: runs `job` on every rank of the MPI job this process belongs to;
/// rank 0 shows progress, then `report`s the result, or says the error (every rank
/// holds the same one; the others wait for rank 0 to have said it).
#[cfg(feature = "mpi")]
pub fn on_mpi_ranks<T>(
    job: impl FnOnce(&dyn Comm, &dyn Progress) -> Result<T>,
    report: impl FnOnce(T) -> Result<()>,
) -> Result<ExitCode> {
    use voxlab::jobs::distributed::mpi::Mpi;
    let comm = Mpi::init()?;
    let root = comm.rank() == 0;
    let term = root.then(crate::cli::Terminal::bars);
    let progress: &dyn Progress = match &term {
        Some(t) => t,
        None => &(),
    };
    let r = job(&comm, progress);
    // Rank 0 writes the outputs; then every rank learns whether all went well.
    let r = match r {
        Ok(t) if root => report(t),
        Ok(_) => Ok(()),
        Err(e) => Err(e),
    };
    let flags = comm.all_gather(&[if r.is_ok() { 1.0 } else { 0.0 }]);
    if let Err(e) = &r {
        if root {
            crate::report_error(e);
        }
    }
    Ok(if flags.iter().all(|&f| f == 1.0) {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

/// Without the `mpi` feature: says how to get it.
#[cfg(not(feature = "mpi"))]
pub fn on_mpi_ranks<T>(
    _job: impl FnOnce(&dyn Comm, &dyn Progress) -> Result<T>,
    _report: impl FnOnce(T) -> Result<()>,
) -> Result<ExitCode> {
    Err(voxlab::Error::invalid(
        "--distributed",
        "this voxlab was built without MPI: build it with `cargo build --release \
         --features mpi` (Debian: apt install libopenmpi-dev libclang-dev) and run it \
         under `mpirun -n N`",
    ))
}
