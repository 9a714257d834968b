//! Benchmark cases of the multi-volume ray caster (family `raycast`, variant
//! `multi-dvr-2-volumes`): the benchmark head of [`super::raycast::raycast_scene`]
//! (`n³`, `phantom` transfer function, perspective orbit camera, `size²` pixels) plus
//! a second copy rotated 30° about y and shifted by (40, 0, −30) mm with the colours
//! permuted, rendered as shaded DVR, step ½ voxel, trilinear. One run is
//! `cpu::multi::render::<R>` or `gpu::multi::render` end to end. Tolerances: the
//! single-volume caster's DVR bounds (`tests/gpu_multi.rs` measures the same f32
//! rounding at 32³). Work: rays and the oracle's samples (steps along the union).

use super::{Case, GpuRun, Prepared, Run, Suite, Unit, Work};
use crate::error::Result;
use crate::multi::{rotation_translation, MultiVolume};
use crate::settings::RenderSettings;
use std::rc::Rc;
use std::time::Instant;

/// (volume side, image side) of the multi-volume cases of a suite.
fn grid(suite: Suite) -> Vec<(usize, usize)> {
    match suite {
        Suite::Quick => vec![(24, 32)],
        Suite::Full => vec![(128, 256)],
    }
}

/// The multi-volume cases of a suite.
pub fn cases(suite: Suite) -> Vec<Case> {
    grid(suite)
        .into_iter()
        .map(|(n, size)| {
            Case::new(
                "raycast",
                "multi-dvr-2-volumes",
                format!("2 × {n}³ → {size}²"),
                move || prepare(n, size),
            )
        })
        .collect()
}

/// The two-volume scene: the head, and a rotated, shifted copy with permuted colours.
pub fn multi_scene(n: usize, size: usize) -> Result<(Vec<MultiVolume>, crate::camera::Camera)> {
    let (vol, tf, cam) = super::raycast::raycast_scene(n, size)?;
    let mut other = tf.clone();
    for p in other.points.iter_mut() {
        let [r, g, b, a] = p.rgba;
        p.rgba = [b, r, g, a];
    }
    let second = MultiVolume::new(vol.clone(), other).with_transform(rotation_translation(
        1,
        30.0,
        glam::DVec3::new(40.0, 0.0, -30.0),
    ));
    Ok((vec![MultiVolume::new(vol, tf), second], cam))
}

fn prepare(n: usize, size: usize) -> Result<Prepared> {
    let (vols, cam) = multi_scene(n, size)?;
    let settings = RenderSettings::default();
    let scene = Rc::new((vols, cam, settings));
    let oracle = crate::cpu::multi::render::<f64>(&scene.0, &scene.1, &scene.2, &|_, _| {})?;
    let (tol_f32, tol_gpu) = super::raycast::raycast_tolerances(&scene.2);
    type Scene = (Vec<MultiVolume>, crate::camera::Camera, RenderSettings);
    let cpu = |s: Rc<Scene>, f64_path: bool| {
        Box::new(move || {
            let t = Instant::now();
            let out = if f64_path {
                crate::cpu::multi::render::<f64>(&s.0, &s.1, &s.2, &|_, _| {})?
            } else {
                crate::cpu::multi::render::<f32>(&s.0, &s.1, &s.2, &|_, _| {})?
            };
            Ok(Run {
                seconds: t.elapsed().as_secs_f64(),
                output: out.image.data,
            })
        }) as super::CpuFn
    };
    let g = scene.clone();
    let gpu = Box::new(move |ctx: &crate::gpu::GpuContext| {
        let r = crate::gpu::multi::render(ctx, &g.0, &g.1, &g.2, &|_, _| {})?;
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
        cpu_f64: cpu(scene.clone(), true),
        cpu_f32: Some(cpu(scene.clone(), false)),
        gpu: Some(gpu),
        tol_f32,
        tol_gpu,
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
        note: "Two volumes: the Shepp–Logan head and a copy rotated 30° about y, shifted \
               (40, 0, −30) mm, colours permuted; shaded DVR, trilinear, step 0.5 voxel; \
               end to end per backend. Samples: steps along the union of the boxes (the \
               f64 oracle's count)."
            .into(),
    })
}
