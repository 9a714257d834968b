//! `voxlab._voxlab`: the native half of the Python package `voxlab`.
//!
//! A thin shell over [`voxlab::jobs`]: NumPy arrays become volumes, images and
//! projection stacks; JSON (built from keyword arguments by the Python half) becomes
//! the jobs' serde requests, so an unknown keyword is the job's own error naming the
//! field. Every call runs the Rust work on a worker thread with the GIL released
//! (`job::run`); the calling thread waits, delivers progress to a Python callback,
//! and checks for Ctrl-C, which cancels the job through [`voxlab::jobs::Progress`].
//! Library errors become `voxlab.VoxlabError` subclasses with the library's messages,
//! and a Rust panic becomes `voxlab.InternalError`, never a crash.

mod arrays;
mod ct;
mod errors;
mod fft;
mod job;
mod jobs;
mod plan;
mod render;
mod volumes;

use pyo3::prelude::*;

/// Panics inside a job (for the tests: a panic must become `voxlab.InternalError`).
#[pyfunction]
fn _panic_in_job(py: Python<'_>, message: String) -> PyResult<()> {
    job::run(py, None, |_| -> voxlab::Result<()> { panic!("{message}") })
}

/// Seconds the last job spent in Rust on its worker thread (the Python-overhead
/// benchmark compares this with the wall-clock time of the Python call).
#[pyfunction]
fn _last_job_seconds() -> f64 {
    job::last_seconds()
}

#[pymodule]
fn _voxlab(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(_panic_in_job, m)?)?;
    m.add_function(wrap_pyfunction!(_last_job_seconds, m)?)?;
    volumes::register(m)?;
    render::register(m)?;
    fft::register(m)?;
    ct::register(m)?;
    jobs::register(m)?;
    plan::register(m)?;
    Ok(())
}
