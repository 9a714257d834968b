//! Running Rust work from Python: on a worker thread with the GIL released, with
//! progress, Ctrl-C and panics handled on the calling thread.
//!
//! The calling thread waits (GIL released) in slices of [`POLL`]; between slices it
//! takes the GIL back to hand the latest progress to the Python callback and to run
//! `PyErr_CheckSignals` (signals can only be checked on the main thread, which is why
//! the work itself runs elsewhere). A pending Ctrl-C, or an exception raised by the
//! callback, sets the flag [`Progress::cancelled`] returns; the job stops between rows,
//! views or iterations, and the Python exception (`KeyboardInterrupt`, or the
//! callback's) is raised once the worker has stopped.

use crate::errors;
use pyo3::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{mpsc, Mutex};
use std::time::Duration;
use voxlab::jobs::Progress;

/// Seconds the last job's Rust work took on its worker thread (f64 bits), for the
/// Python-overhead benchmark (`_last_job_seconds`).
static LAST_SECONDS: AtomicU64 = AtomicU64::new(0);

/// Seconds the last finished job spent in Rust (the worker's closure, nothing of the
/// conversions around it).
pub fn last_seconds() -> f64 {
    f64::from_bits(LAST_SECONDS.load(Ordering::SeqCst))
}

/// How long the calling thread waits between two looks at signals and progress.
const POLL: Duration = Duration::from_millis(25);

/// What the job reported since the last look.
#[derive(Default)]
struct State {
    stage: String,
    done: u64,
    steps: u64,
    changed: bool,
    warnings: Vec<String>,
    notes: Vec<String>,
}

/// The [`Progress`] a job sees.
#[derive(Default)]
pub struct Shared {
    cancel: AtomicBool,
    state: Mutex<State>,
}

impl Shared {
    fn with(&self, f: impl FnOnce(&mut State)) {
        let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
        f(&mut s);
    }
}

impl Progress for Shared {
    fn begin(&self, stage: &str, _unit: &str, steps: u64) {
        self.with(|s| {
            s.stage = stage.to_string();
            s.done = 0;
            s.steps = steps;
            s.changed = true;
        });
    }
    fn advance(&self, done: u64, steps: u64) {
        self.with(|s| {
            // Rows finish out of order on worker threads: report the most done.
            s.done = s.done.max(done);
            s.steps = steps;
            s.changed = true;
        });
    }
    fn end(&self, _seconds: f64) {
        self.with(|s| {
            s.done = s.steps;
            s.changed = true;
        });
    }
    fn note(&self, text: &str) {
        self.with(|s| s.notes.push(text.to_string()));
    }
    fn warn(&self, text: &str) {
        self.with(|s| s.warnings.push(text.to_string()));
    }
    fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::SeqCst)
    }
}

/// Hands what the job reported to Python: warnings as `voxlab.VoxlabWarning`, notes to
/// the `voxlab` logger, progress to `callback(stage, done, total)`.
fn deliver(py: Python<'_>, shared: &Shared, callback: Option<&Bound<'_, PyAny>>) -> PyResult<()> {
    let (warnings, notes, progress) = {
        let mut s = shared.state.lock().unwrap_or_else(|p| p.into_inner());
        let progress = s.changed.then(|| (s.stage.clone(), s.done, s.steps));
        s.changed = false;
        (
            std::mem::take(&mut s.warnings),
            std::mem::take(&mut s.notes),
            progress,
        )
    };
    if !warnings.is_empty() {
        let category = py.import("voxlab._errors")?.getattr("VoxlabWarning")?;
        let warn = py.import("warnings")?.getattr("warn")?;
        for w in warnings {
            warn.call1((w, &category, 3))?;
        }
    }
    if !notes.is_empty() {
        let logger = py
            .import("logging")?
            .getattr("getLogger")?
            .call1(("voxlab",))?;
        for n in notes {
            logger.call_method1("info", (n,))?;
        }
    }
    if let (Some(cb), Some((stage, done, steps))) = (callback, progress) {
        cb.call1((stage, done, steps))?;
    }
    Ok(())
}

/// Runs `f` on a worker thread with the GIL released; see the module docs.
///
/// # Errors
/// The job's error as a `voxlab` exception; `KeyboardInterrupt` (or the callback's
/// exception) when the job was stopped for it; `voxlab.InternalError` for a panic.
pub fn run<T: Send>(
    py: Python<'_>,
    callback: Option<&Bound<'_, PyAny>>,
    f: impl FnOnce(&dyn Progress) -> voxlab::Result<T> + Send,
) -> PyResult<T> {
    let shared = Shared::default();
    let mut stop: Option<PyErr> = None;
    let outcome = std::thread::scope(|scope| {
        let (tx, rx) = mpsc::channel::<()>();
        let s = &shared;
        let worker = scope.spawn(move || {
            let t = std::time::Instant::now();
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| f(s)));
            LAST_SECONDS.store(t.elapsed().as_secs_f64().to_bits(), Ordering::SeqCst);
            let _ = tx.send(());
            r
        });
        // (A Receiver is not Sync; the lock lends it to the detached closure.)
        let rx = Mutex::new(rx);
        loop {
            let finished = py.detach(|| {
                let rx = rx.lock().unwrap_or_else(|p| p.into_inner());
                !matches!(rx.recv_timeout(POLL), Err(mpsc::RecvTimeoutError::Timeout))
            });
            if stop.is_none() {
                let checked = py
                    .check_signals()
                    .and_then(|()| deliver(py, &shared, callback));
                if let Err(e) = checked {
                    shared.cancel.store(true, Ordering::SeqCst);
                    stop = Some(e);
                }
            }
            if finished {
                break;
            }
        }
        worker.join()
    });
    if let Some(e) = stop {
        return Err(e);
    }
    deliver(py, &shared, callback)?;
    match outcome {
        Ok(Ok(Ok(v))) => Ok(v),
        Ok(Ok(Err(e))) => Err(errors::to_py(py, &e)),
        Ok(Err(payload)) | Err(payload) => Err(errors::panic_to_py(py, payload.as_ref())),
    }
}

/// A callback argument: `None` is no callback.
pub fn callback<'py>(cb: &'py Option<Bound<'py, PyAny>>) -> Option<&'py Bound<'py, PyAny>> {
    cb.as_ref().filter(|c| !c.is_none())
}
