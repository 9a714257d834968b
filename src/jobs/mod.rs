//! The front door: one library function per user task.
//!
//! Every `voxlab` subcommand is a job here, and the command line, the Python package
//! and the interactive lab call the same job with the same validation and the same
//! error messages. A job takes a typed request (serde, so it can come from JSON or
//! Python keyword arguments), runs on a [`Backend`], reports progress and listens for
//! cancellation through a [`Progress`] the caller supplies, and returns its output in
//! memory with timings, sample counts and statistics. Writing files and printing
//! messages is the caller's business (the command line does it with `io`).
//!
//! | subcommand | job |
//! |---|---|
//! | `voxlab render` | [`render::run`] ([`render::RenderRequest`]) |
//! | `voxlab compare` | [`compare::run`] |
//! | `voxlab phantom` | [`phantom::run`] |
//! | `voxlab info` | [`info::run`], [`info::gpu`] |
//! | `voxlab convert` | [`convert::run`] |
//! | `voxlab slice` | [`slice::run`] |
//! | `voxlab tf` | [`tf::list`], [`tf::get`] |
//! | `voxlab fvr` | [`fvr::run`] |
//! | `voxlab project` | [`project::run`] |
//! | `voxlab reconstruct` | [`reconstruct::run`] |
//! | (Python: `voxlab.transform.radon`) | [`radon::radon`] |
//! | `voxlab d2vr` | [`d2vr::run`] |
//! | `voxlab fft` | [`fft::run`] |
//! | `voxlab process` | [`process::run`] |
//! | `voxlab adaptive` | [`adaptive::run`] |
//! | `voxlab demo` | [`demo::run`] |
//! | `voxlab view` (the lab) | [`view::ViewState`] (`render --state` draws it) |
//! | `voxlab bench` | [`crate::bench::job::run`] |
//!
//! Inputs name a volume file or a phantom with [`input::VolumeInput`]; the algorithms
//! themselves live in [`crate::cpu`] (the oracle) and [`crate::gpu`] (the port).

pub mod accumulate;
pub mod adaptive;
pub mod compare;
pub mod convert;
pub mod d2vr;
pub mod demo;
pub mod distributed;
pub mod distributed_render;
pub mod embedded;
pub mod fft;
pub mod fvr;
pub mod info;
pub mod input;
pub mod phantom;
pub mod plan;
pub mod process;
pub mod project;
pub mod radon;
pub mod reconstruct;
pub mod render;
pub mod renderer;
pub mod slice;
pub mod stereo;
pub mod tf;
pub mod view;

use crate::error::{Error, Result};
use crate::gpu::GpuContext;

crate::choice_enum! {
    /// Who computes a job: the same names for every job.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
    pub enum Backend: "backend", default Cpu {
        /// The CPU oracle in f64.
        Cpu = "cpu",
        /// The same CPU code in f32: the fair baseline for speed comparisons.
        CpuF32 = "cpu-f32",
        /// The WGSL port on the GPU (f32).
        Gpu = "gpu",
        /// The GPU when a hardware adapter exists, else the CPU oracle (a CPU-emulated
        /// adapter such as lavapipe is used only when `VOXLAB_ADAPTER` names it).
        Auto = "auto",
    }
}

impl Backend {
    /// How messages name the backend: `cpu (f64 oracle)`, `cpu-f32`, `gpu`, `auto`.
    pub fn label(self) -> &'static str {
        match self {
            Backend::Cpu => "cpu (f64 oracle)",
            Backend::CpuF32 => "cpu-f32",
            Backend::Gpu => "gpu",
            Backend::Auto => "auto",
        }
    }

    /// Refuses a backend that `job` does not implement: `supported` lists those it does
    /// (`Auto` is always accepted when `Cpu` or `Gpu` is).
    ///
    /// # Errors
    /// [`Error::Unsupported`] naming the job, the backend and what it runs on.
    pub fn require(self, job: &str, supported: &[Backend]) -> Result<()> {
        let auto_ok = supported.contains(&Backend::Cpu) || supported.contains(&Backend::Gpu);
        if supported.contains(&self) || (self == Backend::Auto && auto_ok) {
            return Ok(());
        }
        let names: Vec<&str> = supported.iter().map(|b| b.name()).collect();
        Err(Error::unsupported(
            job,
            self,
            format!("it runs on {}", crate::choice::or_list(&names)),
        ))
    }
}

crate::choice_enum! {
    /// Which backends a check or a benchmark runs (the CPU f64 oracle always runs once,
    /// as the reference).
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum BackendSet: "backends" {
        /// The CPU f64 and f32 paths.
        Cpu = "cpu",
        /// The GPU (with the oracle as the reference).
        Gpu = "gpu",
        /// Both.
        All = "all",
    }
}

impl BackendSet {
    /// Whether the CPU paths run.
    pub fn cpu(self) -> bool {
        self != BackendSet::Gpu
    }
    /// Whether the GPU runs.
    pub fn gpu(self) -> bool {
        self != BackendSet::Cpu
    }
}

/// What a job tells its caller while it runs, and how the caller stops it.
///
/// Every method has a default that does nothing, so `&()` is a silent, uncancellable
/// progress. Jobs call it from one thread at a time, but kernels report rows from
/// worker threads, hence `Sync`.
pub trait Progress: Sync {
    /// A stage of `steps` steps (0: unknown) begins, counted in `unit`.
    fn begin(&self, _stage: &str, _unit: &str, _steps: u64) {}
    /// `done` of the current stage's `steps` steps are done.
    fn advance(&self, _done: u64, _steps: u64) {}
    /// The current stage has ended after `seconds`.
    fn end(&self, _seconds: f64) {}
    /// Something the user should know (which file a job chose, which device it fell
    /// back to).
    fn note(&self, _text: &str) {}
    /// A warning (values replaced, a request adjusted).
    fn warn(&self, _text: &str) {}
    /// Whether the caller wants the job to stop. Jobs poll it between steps and then
    /// return [`Error::Cancelled`].
    fn cancelled(&self) -> bool {
        false
    }
}

impl Progress for () {}

/// `Err(Error::Cancelled)` once the caller has asked to stop.
pub fn check_cancel(progress: &dyn Progress) -> Result<()> {
    if progress.cancelled() {
        Err(Error::Cancelled)
    } else {
        Ok(())
    }
}

/// A stage: reports begin and end (with its time) around `f`.
pub fn stage<T>(
    progress: &dyn Progress,
    what: &str,
    unit: &str,
    steps: u64,
    f: impl FnOnce() -> Result<T>,
) -> Result<T> {
    check_cancel(progress)?;
    progress.begin(what, unit, steps);
    let t = std::time::Instant::now();
    let r = f()?;
    progress.end(t.elapsed().as_secs_f64());
    check_cancel(progress)?;
    Ok(r)
}

/// What a kernel's progress callback reaches inside [`cancellable`]: it reports to
/// the caller's [`Progress`] and, once the caller has asked to stop, leaves the kernel.
pub struct Checkpoint<'a> {
    progress: &'a dyn Progress,
}

/// The payload that carries a cancellation out of a kernel.
struct Cancelled;

impl Checkpoint<'_> {
    /// Leaves the kernel (unwinding, without a panic message, to [`cancellable`]) when
    /// the caller has asked to stop.
    pub fn check(&self) {
        if self.progress.cancelled() {
            std::panic::resume_unwind(Box::new(Cancelled));
        }
    }

    /// `done` of `total` steps are done (after [`Checkpoint::check`]).
    pub fn advance(&self, done: usize, total: usize) {
        self.check();
        self.progress.advance(done as u64, total as u64);
    }
}

/// Runs a kernel whose progress callbacks go through the [`Checkpoint`] it is given.
///
/// Kernels report progress through plain callbacks (`Fn(rows done, rows total)`, called
/// from worker threads) and cannot return early from inside a parallel loop; so the
/// checkpoint leaves a cancelled kernel by unwinding out of it (with
/// `std::panic::resume_unwind`, which prints nothing; rayon carries it back to this
/// thread once the rows in flight are done), and this function turns that into
/// [`Error::Cancelled`]. A kernel's parallel loop takes rayon's `panic_fuse()`, so
/// that rows not yet begun are skipped once one row has unwound (without it rayon
/// still begins every split it has queued, one row each). Nothing a kernel owns outlives it, so nothing is left half
/// done. Any other panic goes on unwinding.
///
/// # Errors
/// `f`'s errors; [`Error::Cancelled`].
pub fn cancellable<T>(
    progress: &dyn Progress,
    f: impl FnOnce(&Checkpoint) -> Result<T>,
) -> Result<T> {
    check_cancel(progress)?;
    let cp = Checkpoint { progress };
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| f(&cp))) {
        Ok(r) => r,
        Err(payload) if payload.is::<Cancelled>() => Err(Error::Cancelled),
        Err(payload) => std::panic::resume_unwind(payload),
    }
}

/// A backend made ready: [`Backend::Auto`] resolved, and for the GPU the process's
/// device ([`GpuContext::shared`]) open.
#[derive(Clone, Copy)]
pub struct Engine {
    backend: Backend,
    gpu: Option<&'static GpuContext>,
    fallback: Option<&'static str>,
}

impl std::fmt::Debug for Engine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.describe())
    }
}

/// Why `Auto` did not take the GPU, kept for the process (the device is looked for
/// once).
fn auto_fallback() -> &'static Option<String> {
    static WHY: std::sync::OnceLock<Option<String>> = std::sync::OnceLock::new();
    WHY.get_or_init(|| match GpuContext::shared() {
        // A CPU emulating a GPU (lavapipe) is slower than the CPU oracle itself; auto
        // takes it only when VOXLAB_ADAPTER chose it.
        Ok(ctx) if ctx.summary.is_cpu() && std::env::var_os("VOXLAB_ADAPTER").is_none() => {
            Some(format!(
                "the only adapter, {}, is a CPU emulating a GPU; the CPU oracle is faster \
                 (set VOXLAB_ADAPTER to use it anyway)",
                ctx.summary.name
            ))
        }
        Ok(_) => None,
        Err(e) => Some(e.to_string()),
    })
}

impl Engine {
    /// Opens `backend`. `Gpu` fails without an adapter; `Auto` takes a hardware GPU,
    /// else falls back to the CPU oracle and records why ([`Engine::fallback_reason`]).
    ///
    /// # Errors
    /// [`Error::NoAdapter`] or [`Error::Gpu`] for `Gpu` without a usable device.
    pub fn open(backend: Backend) -> Result<Engine> {
        match backend {
            Backend::Gpu => Ok(Engine {
                backend,
                gpu: Some(GpuContext::shared()?),
                fallback: None,
            }),
            Backend::Auto => match auto_fallback() {
                None => Ok(Engine {
                    backend: Backend::Gpu,
                    gpu: Some(GpuContext::shared()?),
                    fallback: None,
                }),
                Some(why) => Ok(Engine {
                    backend: Backend::Cpu,
                    gpu: None,
                    fallback: Some(why.as_str()),
                }),
            },
            b => Ok(Engine {
                backend: b,
                gpu: None,
                fallback: None,
            }),
        }
    }

    /// [`Engine::open`] after [`Backend::require`].
    pub fn open_for(job: &str, backend: Backend, supported: &[Backend]) -> Result<Engine> {
        backend.require(job, supported)?;
        Engine::open(backend)
    }

    /// The backend jobs run on (never `Auto`).
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// The GPU device, for the GPU backend.
    pub fn gpu(&self) -> Option<&'static GpuContext> {
        self.gpu
    }

    /// Why `Auto` fell back to the CPU, if it did.
    pub fn fallback_reason(&self) -> Option<&str> {
        self.fallback
    }

    /// The backend, and the adapter for the GPU: `cpu (f64 oracle)`,
    /// `gpu (NVIDIA H200, Vulkan)`.
    pub fn describe(&self) -> String {
        match self.gpu {
            Some(ctx) => format!("gpu ({}, {})", ctx.summary.name, ctx.summary.backend),
            None => self.backend.label().to_string(),
        }
    }
}

/// The seconds since `t`.
pub(crate) fn since(t: std::time::Instant) -> f64 {
    t.elapsed().as_secs_f64()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backends_parse_and_refuse_by_name() {
        assert_eq!("cpu-f32".parse::<Backend>().unwrap(), Backend::CpuF32);
        let e = Backend::CpuF32
            .require("the analytic projection", &[Backend::Cpu])
            .unwrap_err();
        assert!(matches!(e, Error::Unsupported { .. }));
        assert_eq!(
            e.to_string(),
            "the analytic projection does not run on the cpu-f32 backend: it runs on cpu"
        );
        assert!(Backend::Auto.require("x", &[Backend::Cpu]).is_ok());
        assert!(Backend::Auto.require("x", &[Backend::CpuF32]).is_err());
        assert!(BackendSet::All.cpu() && BackendSet::All.gpu());
        assert!(!BackendSet::Gpu.cpu());
    }

    #[test]
    fn a_cancelled_kernel_stops_between_rows() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        /// Asks to stop once 10 rows are done.
        struct After10(AtomicUsize);
        impl Progress for After10 {
            fn advance(&self, _: u64, _: u64) {
                self.0.fetch_add(1, Ordering::SeqCst);
            }
            fn cancelled(&self) -> bool {
                self.0.load(Ordering::SeqCst) >= 10
            }
        }
        let p = After10(AtomicUsize::new(0));
        let rows_run = AtomicUsize::new(0);
        let r: Result<()> = cancellable(&p, |cp| {
            use rayon::prelude::*;
            (0..10_000usize)
                .into_par_iter()
                .panic_fuse()
                .for_each(|row| {
                    rows_run.fetch_add(1, Ordering::SeqCst);
                    cp.advance(row, 10_000);
                });
            Ok(())
        });
        assert!(matches!(r, Err(Error::Cancelled)), "{r:?}");
        // Every thread stops at its next row once the flag is up.
        let n = rows_run.load(Ordering::SeqCst);
        assert!(n < 10 + rayon::current_num_threads() * 2, "{n} rows ran");
        // Without a request to stop, the kernel runs to its end and its value comes back.
        assert_eq!(
            cancellable(&(), |cp| {
                cp.advance(1, 1);
                Ok(7)
            })
            .unwrap(),
            7
        );
    }

    #[test]
    #[should_panic(expected = "a real bug")]
    fn other_panics_go_on_unwinding() {
        let _ = cancellable(&(), |_| -> Result<()> { panic!("a real bug") });
    }

    #[test]
    fn a_cancelled_stage_stops_before_it_runs() {
        struct Stop;
        impl Progress for Stop {
            fn cancelled(&self) -> bool {
                true
            }
        }
        let mut ran = false;
        let r = stage(&Stop, "work", "steps", 1, || {
            ran = true;
            Ok(())
        });
        assert!(matches!(r, Err(Error::Cancelled)) && !ran);
    }
}
