//! Benchmark cases of spectral adaptive sampling (family `adaptive`,
//! docs/adaptive-sampling.md).
//!
//! The pre-integrated DVR caster of [`crate::cpu::adaptive`] with each step rule —
//! `regular` (fixed ½-voxel steps, the reference), `adaptive` (steps from the transfer
//! function's spectrum and the importance volume, Suwelack et al. 2010) and `direct`
//! (steps from each block's local spectrum) — on two scenes: the modified Shepp–Logan
//! head on `n³` voxels with the `medical` transfer function of `voxlab adaptive`
//! (transparent below 0.25, a sharp ramp of 0.05), and the bundled micro-CT scan with
//! the same kind of function over its value range, seen by the camera of
//! [`super::raycast::raycast_scene`] / [`super::raycast::microct_scene`].
//!
//! The CPU's preparation (pre-integration table, spectral table and importance volume,
//! or block spectra; [`ca::prepare`]) is made once per precision while the case is
//! prepared, and one timed run is the ray casting ([`ca::render_prepared`]) — the
//! frame time of an interactive session whose transfer function stays put. The GPU
//! port ([`crate::gpu::adaptive::render`]) prepares on the device every call: its
//! kernel time is the ray-casting passes (the CPU runs' counterpart), its end-to-end
//! time adds the uploads, the device preparation and the readback. Work: rays and the oracle's samples, so that the samples/s of
//! `adaptive` and `regular` show what fewer samples buy.

use super::{Case, GpuRun, Prepared, Run, Suite, Unit, Work};
use crate::camera::Camera;
use crate::cpu::adaptive::{self as ca, AdaptiveSettings, Sampling};
use crate::error::Result;
use crate::metrics::Tolerance;
use crate::transfer::TransferFunction;
use crate::AnyVolume;
use std::rc::Rc;
use std::time::Instant;

/// The CPU f32 path and the GPU against the f64 oracle. The pre-integrated lookups
/// and the step rules run in f32; a step decided one way in f64 and the other in f32
/// moves the samples of the rest of the ray by up to a step, and a ray whose opacity
/// lands within rounding of the ERT threshold stops a sample earlier or later (up to
/// its remaining transmittance, 1e-2), as for the plain caster
/// (`bench::raycast` DVR_F32). `tests/gpu_adaptive.rs` holds small scenes to 1e-4
/// max. Measured at 128³ → 256² (docs/bench/lavapipe.md, all three step rules): CPU
/// f32 max 1.0e-4, rel L2 1.5e-6; lavapipe max 2.9e-3, rel L2 1.8e-5 (phantom) and
/// 8.0e-5 / 1.6e-6 (micro-CT). Bound: the plain caster's DVR bound.
const ADAPTIVE_TOL: Tolerance = Tolerance::max_abs_rel(1.2e-2).with_rel_l2(1.5e-4);

/// (scene, sampling, volume side, image side) of every case of a suite.
fn grid(suite: Suite) -> Vec<(&'static str, Sampling, usize, usize)> {
    let all = [Sampling::Regular, Sampling::Adaptive, Sampling::Direct];
    let mut out = Vec::new();
    match suite {
        Suite::Quick => {
            for s in all {
                out.push(("phantom", s, 24, 32));
            }
        }
        Suite::Full => {
            for s in all {
                out.push(("phantom", s, 128, 256));
            }
            for s in all {
                out.push(("microct", s, 128, 256));
            }
        }
    }
    out
}

/// Every adaptive-sampling case of a suite.
pub fn cases(suite: Suite) -> Vec<Case> {
    grid(suite)
        .into_iter()
        .map(|(scene, sampling, n, size)| {
            let size_label = if scene == "microct" {
                format!("128³ micro-CT → {size}²")
            } else {
                format!("{n}³ → {size}²")
            };
            Case::new(
                "adaptive",
                format!("{scene}-{}", sampling.name()),
                size_label,
                move || prepare(scene, sampling, n, size),
            )
        })
        .collect()
}

/// The scene of a case: volume, the `medical` transfer function, camera.
pub fn adaptive_scene(
    scene: &str,
    n: usize,
    size: usize,
) -> Result<(AnyVolume, TransferFunction, Camera)> {
    if scene == "microct" {
        let (vol, _, cam) = super::raycast::microct_scene(size)?;
        let r = vol.value_range();
        let (lo, hi) = (r.min, r.max.max(r.min + 1e-6));
        let tf = ca::medical_tf(lo, hi, lo + 0.6 * (hi - lo), 0.05 * (hi - lo));
        Ok((vol, tf, cam))
    } else {
        let (vol, _, cam) = super::raycast::raycast_scene(n, size)?;
        Ok((vol, ca::medical_tf(0.0, 1.0, 0.25, 0.05), cam))
    }
}

type Scene = (AnyVolume, TransferFunction, Camera, AdaptiveSettings);

fn prepare(scene: &str, sampling: Sampling, n: usize, size: usize) -> Result<Prepared> {
    let (vol, tf, cam) = adaptive_scene(scene, n, size)?;
    let settings = AdaptiveSettings {
        sampling,
        sample_count: false,
        ..AdaptiveSettings::default()
    };
    let s: Rc<Scene> = Rc::new((vol, tf, cam, settings));
    let t = Instant::now();
    let p64 = Rc::new(ca::prepare::<f64>(&s.0, &s.1, &s.3)?);
    let prep64 = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let p32 = Rc::new(ca::prepare::<f32>(&s.0, &s.1, &s.3)?);
    let prep32 = t.elapsed().as_secs_f64();
    let oracle = ca::render_prepared(&p64, &s.2, &s.3)?;
    fn cpu<R: crate::real::Real>(p: &ca::AdaptiveScene<R>, s: &Scene) -> Result<Run> {
        let t = Instant::now();
        let out = ca::render_prepared(p, &s.2, &s.3)?;
        let seconds = t.elapsed().as_secs_f64();
        Ok(Run {
            seconds,
            output: out.image.data,
        })
    }
    let (s64, s32, sg) = (Rc::clone(&s), Rc::clone(&s), Rc::clone(&s));
    let gpu = Box::new(move |ctx: &crate::gpu::GpuContext| {
        let r = crate::gpu::adaptive::render(ctx, &sg.0, &sg.1, &sg.2, &sg.3)?;
        let t = r.timings;
        Ok(GpuRun {
            output: r.output.image.data,
            kernel: t.kernel,
            kernel_from_timestamps: t.kernel_from_timestamps,
            end_to_end: t.total - t.setup,
            setup: t.setup,
        })
    }) as super::GpuFn;
    Ok(Prepared {
        cpu_f64: Box::new(move || cpu(&p64, &s64)),
        cpu_f32: Some(Box::new(move || cpu(&p32, &s32))),
        gpu: Some(gpu),
        tol_f32: ADAPTIVE_TOL,
        tol_gpu: ADAPTIVE_TOL,
        work: vec![
            Work {
                amount: (size * size) as f64,
                unit: Unit::Rays,
            },
            Work {
                amount: oracle.total_samples as f64,
                unit: Unit::Samples,
            },
        ],
        note: format!(
            "Pre-integrated DVR, {} steps (T_min ½ voxel, T_max 8, oversampling 2, 99 % \
             energy), `medical` transfer function, ERT 0.99. CPU runs: the ray casting; \
             its preparation (tables, importance volume or block spectra) was made once, \
             not timed with the runs: f64 {:.3} s, f32 {:.3} s. GPU kernel: the \
             ray-casting passes; end to end adds uploads, the device preparation and \
             readback. Samples: the f64 oracle's count ({}).",
            sampling.name(),
            prep64,
            prep32,
            oracle.total_samples
        ),
    })
}
