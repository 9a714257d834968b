//! The GPU adaptive ray caster, pre-integration table and importance volume against the
//! CPU: the f32 CPU path (same arithmetic: counts and images) and the f64 oracle.
//! The three samplings are stamped out from one case list.

mod common;

use common::Rng;
use glam::DVec3;
use voxlab::camera::{Camera, Orbit, Projection};
use voxlab::cpu::adaptive::{self, medical_tf, AdaptiveSettings, Sampling};
use voxlab::cpu::grid::Grid;
use voxlab::AnyVolume;

#[test]
fn adaptive_shaders_validate() {
    for name in ["adaptive_importance", "adaptive", "preintegrate"] {
        common::validate_wgsl(&voxlab::gpu::shaders::resolve(name), name);
    }
}

#[test]
fn preintegration_table_matches_cpu() {
    let Some(ctx) = common::gpu("preintegration_table_matches_cpu") else {
        return;
    };
    let tf = medical_tf(0.0, 1.0, 0.25, 0.05);
    let gpu = voxlab::gpu::preintegrate::preintegrate(ctx, &tf, 128).unwrap();
    let f32t = voxlab::cpu::preintegrate::preintegrate::<f32>(&tf, 128);
    let f64t = voxlab::cpu::preintegrate::preintegrate::<f64>(&tf, 128);
    // RGBA entries one after the other: dims [4, entries].
    let flat_gpu: Vec<f32> = gpu.iter().flatten().copied().collect();
    let flat32: Vec<f32> = f32t.entries.iter().flatten().copied().collect();
    let flat64: Vec<f64> = f64t.entries.iter().flatten().copied().collect();
    let dims = [4, flat_gpu.len() / 4];
    // Measured on lavapipe (128² entries): 1.9e-5 vs CPU f32 (pow, and sums of up to
    // 1032 sub-steps in another rounding), 1.8e-5 vs f64.
    let tol = voxlab::metrics::Tolerance::max_abs(1e-4);
    let e32 = common::assert_parity_array("preintegration_vs_f32", &dims, &flat32, &flat_gpu, tol);
    let e64 = common::assert_parity_array("preintegration_vs_f64", &dims, &flat64, &flat_gpu, tol);
    eprintln!(
        "pre-integration GPU vs CPU f32 {:.3e}, vs f64 {:.3e}",
        e32.max_abs, e64.max_abs
    );
}

#[test]
fn importance_volume_matches_cpu_exactly() {
    let Some(ctx) = common::gpu("importance_volume_matches_cpu_exactly") else {
        return;
    };
    let mut rng = Rng(9);
    let grid = Grid::<f32> {
        dims: [20, 17, 13],
        data: (0..20 * 17 * 13).map(|_| rng.unit() as f32).collect(),
    };
    for t_max in [1.0, 3.0, 8.0] {
        let cpu = adaptive::importance_volume(&grid, t_max);
        let gpu = voxlab::gpu::adaptive::importance_volume(ctx, &grid, t_max).unwrap();
        for a in 0..3 {
            // Differences, absolute values and maxima of the same f32 numbers: exact.
            assert_eq!(cpu[a].data, gpu[a].data, "axis {a}, T_max {t_max}");
        }
    }
}

fn scene() -> (AnyVolume, voxlab::transfer::TransferFunction, Camera) {
    let av = balls_volume();
    let mut tf = medical_tf(0.0, 1.0, 0.25, 0.05);
    // A shifted function: the window map enters the step and the table lookups.
    tf.window.b = -0.05;
    let cam = Camera::orbit(
        DVec3::splat(31.5),
        [64.0; 3],
        Orbit::default(),
        Projection::Perspective { fov_y_deg: 30.0 },
        32,
        32,
    )
    .unwrap();
    (av, tf, cam)
}

fn parity(sampling: Sampling) {
    let Some(ctx) = common::gpu(&format!("adaptive_parity_{sampling:?}")) else {
        return;
    };
    let (av, tf, cam) = scene();
    let s = AdaptiveSettings {
        sampling,
        ..Default::default()
    };
    let gpu = voxlab::gpu::adaptive::render(ctx, &av, &tf, &cam, &s)
        .unwrap()
        .output;
    let f32o = adaptive::render::<f32>(&av, &tf, &cam, &s).unwrap();
    let f64o = adaptive::render::<f64>(&av, &tf, &cam, &s).unwrap();
    let (cg, cc) = (
        gpu.samples.as_ref().unwrap(),
        f32o.samples.as_ref().unwrap(),
    );
    let differ = cg.data.iter().zip(&cc.data).filter(|(a, b)| a != b).count();
    // Measured on lavapipe (two balls in 64³, 32²): 1.1e-6 vs CPU f32 (the table's
    // pow), 3.6e-6 max and 1.9e-7 RMSE vs f64, for all three samplings.
    let case = format!("adaptive_parity_{sampling:?}");
    let e32 = common::assert_parity(
        &format!("{case}_vs_f32"),
        &f32o.image,
        &gpu.image,
        voxlab::metrics::Tolerance::max_abs(1e-4),
    );
    let e64 = common::assert_parity(
        &format!("{case}_vs_f64"),
        &f64o.image,
        &gpu.image,
        voxlab::metrics::Tolerance::max_abs(1e-4).with_rmse(2e-5),
    );
    eprintln!(
        "{sampling:?}: counts differ on {differ} of {} rays; image vs CPU f32 max {:.3e}, vs f64 max {:.3e} rmse {:.3e}",
        cg.data.len(),
        e32.max_abs,
        e64.max_abs,
        e64.rmse
    );
    // Same inputs, same order of operations: the step decisions agree. A ray may differ
    // only where early termination or a step bound is decided by the last bit of a pow
    // (measured: 0 of 1024 rays on lavapipe, for all three samplings).
    assert!(differ <= cg.data.len() / 100, "{differ} rays");
}

macro_rules! parity_cases {
    ($($name:ident: $sampling:expr,)*) => {$(
        #[test]
        fn $name() {
            parity($sampling);
        }
    )*};
}

parity_cases! {
    regular_matches_cpu: Sampling::Regular,
    adaptive_matches_cpu: Sampling::Adaptive,
    direct_matches_cpu: Sampling::Direct,
}

/// Two nested balls in empty space (64³, 1 mm voxels): a shell of value 0.6 (radius 10)
/// around a core of 1.0 (radius 4), edges one voxel wide. Most of each ray is empty,
/// so the three samplings place their samples differently.
pub fn balls_volume() -> AnyVolume {
    let n = 64;
    let c = (n as f64 - 1.0) / 2.0;
    let v = voxlab::Volume::<f32>::from_fn([n; 3], [1.0; 3], |i, j, k| {
        let r = ((i as f64 - c).powi(2) + (j as f64 - c).powi(2) + (k as f64 - c).powi(2)).sqrt();
        let edge = |radius: f64| (radius - r + 0.5).clamp(0.0, 1.0);
        (0.6 * edge(10.0) + 0.4 * edge(4.0)) as f32
    })
    .unwrap();
    AnyVolume::F32(v)
}

/// Past the 3-D texture limit or the device memory the adaptive caster renders in
/// bricks, handing each ray's state from brick to brick in the rays' order: every
/// sampling's image and sample counts equal the unsplit render's, bit for bit on
/// lavapipe (the bound, 4 f32 ulps of the brightest channel, is for adapters that fuse
/// the finish's multiply-adds, which the host does not). Views along an axis (rays in
/// the cut planes), oblique, orthographic and perspective, from outside and inside.
#[test]
fn bricks_past_the_texture_limit_or_the_memory_render_the_unsplit_image() {
    use voxlab::gpu::adaptive::{brick_ghost, device_tables, render, volume_split};
    use voxlab::gpu::context::GpuContext;
    use voxlab::gpu::plan::DeviceMemory;
    use voxlab::gpu::raycast::bricks_in_view;
    let Some(ctx) = common::gpu("adaptive bricks") else {
        return;
    };
    let (av, tf, _) = scene();
    let s0 = AdaptiveSettings::default();
    let ghost = brick_ghost(&s0);
    // 64³ with 11 ghost voxels: 48 texels per axis cut it into bricks of ≤ 26 voxels.
    let mut textures = GpuContext::new().unwrap();
    textures.limits.max_texture_dimension_3d = 48;
    // The memory of the tables and a 40³ brick's textures (and importance volumes): a
    // cut by the memory alone.
    let mut memory = GpuContext::new().unwrap();
    let cams = [
        (
            "perspective",
            30.0,
            20.0,
            None,
            Projection::Perspective { fov_y_deg: 30.0 },
        ),
        (
            "along x",
            90.0,
            0.0,
            None,
            Projection::Orthographic {
                width_mm: 80.0,
                height_mm: 70.0,
            },
        ),
        (
            "oblique orthographic",
            35.0,
            -50.0,
            None,
            Projection::Orthographic {
                width_mm: 90.0,
                height_mm: 80.0,
            },
        ),
        // The eye inside the volume, 5 mm from the centre.
        (
            "inside",
            200.0,
            10.0,
            Some(5.0),
            Projection::Perspective { fov_y_deg: 70.0 },
        ),
    ];
    // Bricks no ray meets (behind the eye inside the volume) are skipped: counted here.
    let mut skipped = 0;
    for (cam_name, az, el, dist, proj) in cams {
        let cam = Camera::orbit(
            DVec3::splat(31.5),
            [64.0; 3],
            Orbit {
                azimuth_deg: az,
                elevation_deg: el,
                distance_mm: dist,
            },
            proj,
            28,
            24,
        )
        .unwrap();
        for sampling in Sampling::ALL {
            let s = AdaptiveSettings {
                sampling,
                sample_count: true,
                ..Default::default()
            };
            let per_voxel = if sampling == Sampling::Adaptive {
                36
            } else {
                4
            };
            // The tables (the pre-integrated one is 1 MiB), a band's buffers (under
            // 64 KiB here) and a 40³ brick.
            let tables: u64 = device_tables(av.dims(), &s).iter().map(|t| t.1).sum();
            let bytes = tables + (64 << 10) + per_voxel * 40 * 40 * 40;
            memory.memory = Some(DeviceMemory {
                bytes,
                source: "the test".into(),
            });
            let want = render(ctx, &av, &tf, &cam, &s).unwrap();
            assert!(want.split.is_none());
            for (limit, c) in [("texture", &textures), ("memory", &memory)] {
                let c: &GpuContext = c;
                let case = format!("adaptive bricks {cam_name} {sampling:?} ({limit})");
                let cut = volume_split(c, av.dims(), &cam, &s)
                    .unwrap()
                    .expect("a split");
                assert!(cut.bricks.len() >= 8, "{case}: {} bricks", cut.bricks.len());
                match limit {
                    "texture" => assert!(cut.largest.iter().all(|&n| n <= 48), "{case}"),
                    _ => assert!(
                        cut.largest.iter().product::<usize>() as u64 * per_voxel <= bytes - tables,
                        "{case}: {:?}",
                        cut.largest
                    ),
                }
                skipped += bricks_in_view(&cam, av.affine(), &cut.bricks)
                    .iter()
                    .filter(|&&v| !v)
                    .count();
                let got = render(c, &av, &tf, &cam, &s).unwrap();
                let line = got.split.as_deref().expect("the split's line");
                assert!(
                    line.starts_with(&format!(
                        "adaptive ray casting in {} bricks",
                        cut.bricks.len()
                    )) && line.contains(&format!("{ghost} ghost voxels")),
                    "{case}: {line}"
                );
                let peak = want
                    .output
                    .image
                    .data
                    .iter()
                    .fold(0.0f64, |m, v| m.max(v.abs()));
                let bound = 4.0 * f32::EPSILON as f64 * peak.max(1.0);
                common::assert_parity(
                    &case,
                    &want.output.image,
                    &got.output.image,
                    voxlab::metrics::Tolerance::max_abs(bound),
                );
                assert_eq!(
                    want.output.samples.as_ref().unwrap().data,
                    got.output.samples.as_ref().unwrap().data,
                    "{case}: the samples per ray"
                );
            }
        }
    }
    assert!(skipped > 0, "no brick was out of view");
}
