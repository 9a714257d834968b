//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::io::Write;
use voxlab::gpu::GpuContext;

/// Opens the GPU, or decides what a missing adapter means: a failure, unless
/// `VOXLAB_ALLOW_NO_GPU=1`, in which case the skip is announced loudly (straight to the
/// terminal, past the test harness's output capture) and recorded in
/// `target/gpu-tests-skipped.txt`, which the test script reports at the end.
pub fn gpu(test: &str) -> Option<GpuContext> {
    match GpuContext::new() {
        Ok(ctx) => Some(ctx),
        Err(e) => {
            if std::env::var("VOXLAB_ALLOW_NO_GPU").as_deref() == Ok("1") {
                let msg = format!(
                    "\n*** GPU TEST SKIPPED: {test}: {e}\n*** (VOXLAB_ALLOW_NO_GPU=1 allows this; the GPU code was NOT tested)\n"
                );
                let _ = std::io::stderr().write_all(msg.as_bytes());
                let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target");
                let _ = std::fs::create_dir_all(&dir);
                if let Ok(mut f) = std::fs::OpenOptions::new()
                    .create(true)
                    .append(true)
                    .open(dir.join("gpu-tests-skipped.txt"))
                {
                    let _ = writeln!(f, "{test}");
                }
                None
            } else {
                panic!(
                    "no GPU adapter for {test}: {e}\n\
                     Install a Vulkan driver (the README's test command does this when run as root), \
                     or set VOXLAB_ALLOW_NO_GPU=1 to skip the GPU tests."
                )
            }
        }
    }
}

/// Asserts parity of `port` against `oracle`, writing `target/parity/<case>/` on failure.
pub fn assert_parity(
    case: &str,
    oracle: &voxlab::frame::Frame,
    port: &voxlab::frame::Frame,
    tol: voxlab::metrics::Tolerance,
) -> voxlab::metrics::ErrorStats {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("target/parity")
        .join(case);
    let report = voxlab::metrics::check_parity(case, oracle, port, tol, Some(&dir)).unwrap();
    assert!(report.passed, "{}", report.message);
    report.stats
}
