//! The device keeps what every GPU job compiles (`GpuContext::program`,
//! `GpuContext::kept`): each job, run twice in one process through its front door (the
//! requests the command line and the Python package send), compiles its pipelines on
//! the first call and takes every one of them from the device on the second, with the
//! same result. One test, so that no other test compiles on the shared device between
//! the two calls.

mod common;

use voxlab::gpu::GpuContext;
use voxlab::jobs::{self, Backend};

fn parse<T: serde::de::DeserializeOwned>(json: &str) -> T {
    serde_json::from_str(json).unwrap_or_else(|e| panic!("{json}: {e}"))
}

/// A job's output, flattened for comparing the two calls bit for bit.
type Job<'a> = Box<dyn Fn() -> voxlab::Result<Vec<f64>> + 'a>;

fn render(json: &str) -> Job<'_> {
    Box::new(move || Ok(jobs::render::run(&parse(json), &())?.output.image.data))
}

fn process(json: &str) -> Job<'_> {
    Box::new(move || {
        let r = jobs::process::run(&parse(json), &())?;
        Ok(r.volume.data().iter().map(|&v| v as f64).collect())
    })
}

/// How many pipelines and kept objects `job` made on `ctx` on its first and its second
/// call, after checking that both calls give the same output.
fn made_by(ctx: &GpuContext, name: &str, job: &Job) -> (usize, usize) {
    let before = ctx.kept_made();
    let a = job().unwrap_or_else(|e| panic!("{name}: {e}"));
    let first = ctx.kept_made() - before;
    let b = job().unwrap_or_else(|e| panic!("{name}, second call: {e}"));
    let second = ctx.kept_made() - before - first;
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert!(!a.is_empty(), "{name}: no output");
    assert!(bits(&a) == bits(&b), "{name}: the two calls differ");
    (first, second)
}

#[test]
fn a_second_call_of_every_gpu_job_compiles_nothing() {
    let Some(ctx) = common::gpu("a_second_call_of_every_gpu_job_compiles_nothing") else {
        return;
    };
    let projected = jobs::project::run(
        &parse(
            r#"{"method": "joseph", "beam": "cone", "angles": 40, "range": 220, "cols": 32,
                "rows": 24, "input": {"source": "phantom:shepp-logan-modified:24"}}"#,
        ),
        &(),
    )
    .expect("projections on the CPU");
    let reconstruct = |json: &'static str| -> Job {
        Box::new(|| {
            let p = projected.projections.clone();
            let g = projected.geometry.clone();
            let r = jobs::reconstruct::reconstruct(&parse(json), p, g, None, &())?;
            Ok(r.reconstruction.data)
        })
    };
    let sinogram: Vec<f64> = (0..32 * 45)
        .map(|i| ((i % 32) as f64 - 15.5).abs().min(9.0) * (1.0 + (i / 32) as f64 * 0.01))
        .collect();
    let theta: Vec<f64> = (0..45).map(|a| a as f64 * 4.0).collect();
    let cases: Vec<(&str, Job)> = vec![
        (
            "render: shaded DVR, skipping, precomputed gradients",
            render(
                r#"{"scene": {"width": 32, "height": 32, "shading": true, "precompute_gradients": true,
                    "input": {"source": "phantom:shepp-logan-modified:24"}},
                    "backend": "gpu"}"#,
            ),
        ),
        (
            "render: two volumes",
            render(
                r#"{"scene": {"width": 32, "height": 32,
                    "input": {"source": "phantom:shepp-logan-modified:24"}},
                    "volumes": [{"input": "phantom:sphere:16"}], "backend": "gpu"}"#,
            ),
        ),
        (
            "render: pre-integrated, adaptive sampling",
            render(
                r#"{"scene": {"width": 32, "height": 32,
                    "input": {"source": "phantom:marschner-lobb:16"}},
                    "sampling": "adaptive", "backend": "gpu"}"#,
            ),
        ),
        (
            "project: Joseph",
            Box::new(|| {
                let r = jobs::project::run(
                    &parse(
                        r#"{"method": "joseph", "backend": "gpu", "cols": 32, "angles": 12,
                            "input": {"source": "phantom:shepp-logan-modified:24"}}"#,
                    ),
                    &(),
                )?;
                Ok(r.projections.data)
            }),
        ),
        (
            "reconstruct: FDK of a short scan",
            reconstruct(r#"{"short_scan": true, "backend": "gpu"}"#),
        ),
        (
            "reconstruct: SIRT",
            reconstruct(r#"{"method": "sirt", "iterations": 2, "backend": "gpu"}"#),
        ),
        (
            "fvr",
            Box::new(|| {
                let r = jobs::fvr::run(
                    &parse(
                        r#"{"backend": "gpu",
                            "input": {"source": "phantom:shepp-logan-modified:24"}}"#,
                    ),
                    &(),
                )?;
                Ok(r.frame.data)
            }),
        ),
        (
            "process: gaussian",
            process(
                r#"{"op": "gaussian", "sigma": [1.0], "backend": "gpu",
                    "input": {"source": "phantom:shepp-logan-modified:24"}}"#,
            ),
        ),
        (
            "process: median",
            process(
                r#"{"op": "median", "size": 3, "backend": "gpu",
                    "input": {"source": "phantom:shepp-logan-modified:24"}}"#,
            ),
        ),
        (
            "process: resample",
            process(
                r#"{"op": "resample", "dims": [20, 20, 20], "backend": "gpu",
                    "input": {"source": "phantom:shepp-logan-modified:24"}}"#,
            ),
        ),
        (
            "d2vr",
            Box::new(|| {
                let r = jobs::d2vr::run(
                    &parse(r#"{"backend": "gpu", "input": "phantom:shepp-logan-modified"}"#),
                    &(),
                )?;
                Ok(r.render.image.data)
            }),
        ),
        (
            "iradon",
            Box::new(|| {
                let options = jobs::radon::IradonOptions {
                    output_size: 24,
                    filter: voxlab::cpu::ramp::RampFilter::RamLak,
                    interpolation: voxlab::cpu::radon::Interpolation::Linear,
                    circle: true,
                };
                let r = jobs::radon::iradon::<f32>(
                    &sinogram,
                    32,
                    &theta,
                    None,
                    &options,
                    Backend::Gpu,
                    &(),
                )?;
                Ok(r.data.iter().map(|&v| v as f64).collect())
            }),
        ),
        (
            "iradon_sart",
            Box::new(|| {
                let s: Vec<f32> = sinogram.iter().map(|&v| v as f32).collect();
                let t: Vec<f32> = theta.iter().map(|&v| v as f32).collect();
                let options = jobs::radon::SartOptions {
                    image: None,
                    shifts: None,
                    clip: None,
                    relaxation: 0.15,
                };
                let r = jobs::radon::iradon_sart(&s, 32, &t, &options, Backend::Gpu, &())?;
                Ok(r.iter().map(|&v| v as f64).collect())
            }),
        ),
    ];
    for (name, job) in &cases {
        let (first, second) = made_by(ctx, name, job);
        eprintln!("{name}: {first} made by the first call, {second} by the second");
        assert!(
            first > 0,
            "{name}: the first call made nothing: did it run on the GPU?"
        );
        assert_eq!(second, 0, "{name}: the second call made {second}");
    }
}
