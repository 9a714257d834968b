//! GPU stereo pairs against the CPU f64 pair: every layout, rendered on the process-wide
//! GPU context (`stereo::render_pair_gpu`), within the ray caster's GPU tolerance.

mod common;

use glam::DVec3;
use voxlab::camera::{Camera, Orbit, Projection};
use voxlab::jobs::render::{Backend, Renderer, Scene};
use voxlab::jobs::stereo::{combine, render_pair, render_pair_gpu, StereoLayout};
use voxlab::metrics::Tolerance;
use voxlab::phantom::Phantom;
use voxlab::settings::{Mode, RenderSettings};
use voxlab::transfer::TransferFunction;

/// The ray caster's exact-path tolerances (tests/gpu_raycast.rs: EXACT_DVR, and
/// EXACT_SCALAR relative to the image's scale); each eye is one ray-cast image.
/// Measured on lavapipe (Shepp–Logan 32×35×30, 40×30 per eye, 65 mm eyes): DVR max |Δ|
/// 8.3e-5 (rmse 6.1e-6) in every layout, MIP 1.3e-5 of the scale (rmse 1.7e-6).
const DVR: Tolerance = Tolerance {
    max_abs: 1e-3,
    rmse: 5e-5,
    ..Tolerance::NONE
};
const SCALAR: Tolerance = Tolerance {
    max_abs: 5e-5,
    rmse: 1e-5,
    ..Tolerance::NONE
};

fn scene() -> Scene {
    Scene {
        volume: Phantom::shepp_logan_modified()
            .sample([32, 35, 30])
            .unwrap()
            .into(),
        transfer: TransferFunction::preset("phantom").unwrap(),
        camera: Camera::orbit(
            DVec3::ZERO,
            [256.0; 3],
            Orbit {
                azimuth_deg: 30.0,
                elevation_deg: 20.0,
                distance_mm: Some(540.0),
            },
            Projection::Perspective { fov_y_deg: 30.0 },
            40,
            30,
        )
        .unwrap(),
    }
}

fn check(name: &str, mode: Mode, layouts: &[StereoLayout], tol: Tolerance) {
    let Some(ctx) = common::gpu(name) else {
        return;
    };
    let sc = scene();
    let s = RenderSettings {
        mode,
        ..RenderSettings::default()
    };
    let cpu = Renderer::new(Backend::Cpu).unwrap();
    let a = render_pair(&cpu, &sc, &s, 65.0, 540.0, &|_, _| {}).unwrap();
    let b = render_pair_gpu(ctx, &sc, &s, 65.0, 540.0, &|_, _| {}).unwrap();
    assert_eq!(a.cameras, b.cameras);
    assert!(a.cameras.shift_px > 0, "the eyes must see different views");
    for &layout in layouts {
        let x = combine(&a.left, &a.right, layout).unwrap();
        let y = combine(&b.left, &b.right, layout).unwrap();
        let tol = if mode == Mode::Dvr || layout == StereoLayout::Anaglyph {
            // Anaglyph maps scalar images onto [0, 1] by their joint range.
            tol
        } else {
            tol.scaled(x.data.iter().fold(1.0f64, |m, v| m.max(v.abs())))
        };
        let stats = common::assert_parity(&format!("{name}_{layout:?}"), &x, &y, tol);
        eprintln!(
            "{name} {layout:?}: max |Δ| {:.2e}, rmse {:.2e}",
            stats.max_abs, stats.rmse
        );
    }
}

#[test]
fn dvr_stereo_pair_matches_cpu_in_every_layout() {
    check(
        "dvr_stereo_pair_matches_cpu_in_every_layout",
        Mode::Dvr,
        &[
            StereoLayout::Anaglyph,
            StereoLayout::SideBySide,
            StereoLayout::Interlaced,
        ],
        DVR,
    );
}

#[test]
fn mip_stereo_pair_matches_cpu() {
    check(
        "mip_stereo_pair_matches_cpu",
        Mode::Mip,
        &[StereoLayout::SideBySide, StereoLayout::Interlaced],
        SCALAR,
    );
}
