//! `voxlab bench`: the same inputs on the CPU f64 oracle, the CPU f32 baseline and the
//! GPU; warm-up runs, then timed runs; medians with min/max; set-up apart from
//! execution; every timed result checked against the oracle first.
//!
//! The cases live with their families (`raycast`, `fourier`, `ct`); `cargo bench
//! --bench suite` runs the same list.

pub mod case;
pub mod ct;
pub mod d2vr;
pub mod fourier;
pub mod raycast;

pub use case::{Case, CpuFn, GpuFn, GpuRun, Prepared, Run, Suite, Tol, Unit, Work};

/// The algorithm families, in report order (`--only` takes a comma-separated subset).
pub const FAMILIES: [&str; 8] = [
    "raycast", "gradient", "fft", "fvr", "project", "fbp", "fdk", "d2vr",
];

/// Every case of a suite, in report order.
pub fn cases(suite: Suite) -> Vec<Case> {
    let mut all = Vec::new();
    all.extend(raycast::cases(suite));
    all.extend(fourier::cases(suite));
    all.extend(ct::cases(suite));
    all.extend(d2vr::cases(suite));
    all
}
