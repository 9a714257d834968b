//! What one benchmark case is: how to build its inputs, how to run it on each backend,
//! how much work one run does, and how close each backend must come to the oracle (a
//! [`crate::metrics::Tolerance`]).
//!
//! Every family of algorithms (`raycast`, `fft`, `ct`, …) lists its cases in its own
//! module; the runner in [`super`] times them all the same way.

use crate::error::Result;
use crate::gpu::GpuContext;
use crate::metrics::Tolerance;

crate::choice_enum! {
    /// Which suite a case belongs to.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Suite: "suite" {
        /// Tiny inputs, every algorithm once: under a minute even on lavapipe. A smoke
        /// test of correctness, not of speed.
        Quick = "quick",
        /// The real sizes (volumes 64³ … 512³, images 256² … 1024², where memory allows).
        Full = "full",
    }
}

/// One timed CPU run: the wall-clock time of the computation alone (inputs built
/// before, conversion of the result after), and its result flattened to f64 for the
/// parity check.
#[derive(Clone, Debug, Default)]
pub struct Run {
    pub seconds: f64,
    pub output: Vec<f64>,
}

/// One timed GPU run. `end_to_end` is upload + every pass + readback, without the
/// one-off set-up (shader compilation, pipelines), which is reported apart in `setup`.
#[derive(Clone, Debug, Default)]
pub struct GpuRun {
    pub output: Vec<f64>,
    /// The compute passes alone: from timestamp queries where the adapter has them.
    pub kernel: f64,
    /// Whether `kernel` came from timestamp queries (otherwise: wall clock of the
    /// waited-for submissions).
    pub kernel_from_timestamps: bool,
    pub end_to_end: f64,
    pub setup: f64,
}

/// What a throughput figure counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Unit {
    /// Rays (pixels) cast: Mrays/s.
    Rays,
    /// Samples taken along rays: Msamples/s.
    Samples,
    /// Voxel updates (one voxel, one view) in backprojection: Gupdates/s.
    VoxelUpdates,
    /// Bytes moved (read + written once per pass, as counted by the case): GB/s.
    Bytes,
    /// Floating-point operations (e.g. 5 N log₂N per complex FFT): GFLOP/s.
    Flops,
}

/// How much work one run does, in one unit. A case may give several.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Work {
    pub amount: f64,
    pub unit: Unit,
}

/// A CPU backend of a prepared case: each call runs the computation once.
pub type CpuFn = Box<dyn FnMut() -> Result<Run>>;
/// The GPU backend of a prepared case: each call runs the computation once.
pub type GpuFn = Box<dyn FnMut(&GpuContext) -> Result<GpuRun>>;

/// A case whose inputs are built: closures that own them.
pub struct Prepared {
    /// The oracle. Its first result is the reference every other backend is held to.
    pub cpu_f64: CpuFn,
    /// The fair CPU baseline (speedups are quoted against it). None only where no f32
    /// CPU path exists.
    pub cpu_f32: Option<CpuFn>,
    /// None where the algorithm has no GPU port.
    pub gpu: Option<GpuFn>,
    /// How close the f32 CPU result must come to the oracle's; the bench bounds
    /// [`Tolerance::max_abs_rel`] (max |Δ| relative to the oracle's largest |value|) and
    /// [`Tolerance::rel_l2`] (‖port − oracle‖ / ‖oracle‖). A result outside either fails,
    /// and its timings are not reported (a fast wrong answer never counts).
    pub tol_f32: Tolerance,
    /// The same for the GPU result.
    pub tol_gpu: Tolerance,
    /// The work one run does (the same on every backend).
    pub work: Vec<Work>,
    /// Anything a reader needs to know about what is timed (shown in the report).
    pub note: String,
}

/// A benchmark case: a name, a size, and how to build its inputs.
pub struct Case {
    /// The algorithm family, one of [`super::FAMILIES`] (what `--only` filters on).
    pub family: &'static str,
    /// The variant within the family, e.g. `dvr-shaded-trilinear`.
    pub name: String,
    /// The problem size in words, e.g. `128³ → 256²`.
    pub size: String,
    /// Builds the inputs (not timed).
    pub prepare: Box<dyn Fn() -> Result<Prepared>>,
}

impl Case {
    pub fn new(
        family: &'static str,
        name: impl Into<String>,
        size: impl Into<String>,
        prepare: impl Fn() -> Result<Prepared> + 'static,
    ) -> Self {
        Case {
            family,
            name: name.into(),
            size: size.into(),
            prepare: Box::new(prepare),
        }
    }

    /// `family/name size`, unique within a suite.
    pub fn id(&self) -> String {
        format!("{}/{} {}", self.family, self.name, self.size)
    }
}

/// Flattens RGBA or scalar f32/f64 results for the parity check.
pub fn flat<T: Copy + Into<f64>>(data: &[T]) -> Vec<f64> {
    data.iter().map(|&v| v.into()).collect()
}
