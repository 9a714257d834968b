//! The shaders' parameter blocks, bound as uniform buffers (a GPU) or as read-only
//! storage buffers (a CPU adapter: `GpuContext::params_in_storage`).
//!
//! - Both bindings compute the same numbers: the ray caster, the FFT and the Radon
//!   transform on one context of each kind, bit for bit. On a GPU the default is the
//!   uniform binding, which CI's lavapipe would otherwise never run.
//! - A renderer session's memory stays flat over many frames. Lavapipe compiles a
//!   shader again whenever a uniform block its loops read is bound, and keeps every
//!   copy until the process ends (about 1.5 MiB for the ray caster: 150 MiB over 100
//!   frames); with the blocks in storage buffers it does not.

mod common;

use rustfft::num_complex::Complex;
use voxlab::cpu::dft::{Direction, Normalization};
use voxlab::gpu::context::GpuContext;
use voxlab::gpu::fft::GpuFftVariant;
use voxlab::jobs::input::VolumeInput;
use voxlab::jobs::render::{build_view, SceneRequest};
use voxlab::settings::Mode;
use voxlab::volume::AnyVolume;

/// The two tests one after another: the memory one measures the process.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// A context whose parameter blocks are bound as `in_storage` says.
fn context(in_storage: bool) -> GpuContext {
    let mut ctx = GpuContext::new().expect("a second context on the test adapter");
    ctx.params_in_storage = in_storage;
    ctx
}

fn phantom() -> AnyVolume {
    VolumeInput::new("phantom:shepp-logan-modified:32")
        .read()
        .unwrap()
}

/// One frame of `mode` from `azimuth`, with `session`.
fn frame(
    session: &mut voxlab::gpu::raycast::RaycastSession<'_>,
    volume: &AnyVolume,
    mode: Mode,
    azimuth: f64,
) -> Vec<u64> {
    let mut scene = SceneRequest {
        input: VolumeInput::new("phantom:shepp-logan-modified:32"),
        mode,
        width: Some(40),
        height: Some(32),
        ..SceneRequest::default()
    };
    scene.view.azimuth = azimuth;
    let (tf, camera, settings) = build_view(&scene, volume, false).unwrap();
    let out = session.render(&tf, &camera, &settings, &|_, _| {}).unwrap();
    out.output.image.data.iter().map(|v| v.to_bits()).collect()
}

#[test]
fn uniform_and_storage_parameter_blocks_compute_the_same_numbers() {
    if common::gpu("uniform_and_storage_parameter_blocks_compute_the_same_numbers").is_none() {
        return;
    }
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let (uniform, storage) = (context(false), context(true));
    let volume = phantom();

    // The ray caster: shaded DVR (skipping, early termination) and MIDA.
    for (mode, azimuth) in [(Mode::Dvr, 30.0), (Mode::Mida, 200.0)] {
        let mut a = voxlab::gpu::raycast::RaycastSession::new(&uniform, &volume).unwrap();
        let mut b = voxlab::gpu::raycast::RaycastSession::new(&storage, &volume).unwrap();
        let (x, y) = (
            frame(&mut a, &volume, mode, azimuth),
            frame(&mut b, &volume, mode, azimuth),
        );
        assert!(
            x.iter().any(|&v| f64::from_bits(v) != 0.0),
            "{mode:?}: empty"
        );
        assert_eq!(x, y, "{mode:?}: the two bindings differ");
    }

    // The FFT: a 3-D transform through the workgroup-memory and the global passes.
    let mut rng = common::Rng(0x9e37_79b9_7f4a_7c15);
    let shape = [8usize, 16, 32];
    let data: Vec<Complex<f32>> = (0..shape.iter().product::<usize>())
        .map(|_| Complex::new(rng.unit() as f32 - 0.5, rng.unit() as f32 - 0.5))
        .collect();
    for variant in [GpuFftVariant::Stockham, GpuFftVariant::StockhamGlobal] {
        let run = |ctx: &GpuContext| {
            voxlab::gpu::fft::fft_nd(
                ctx,
                &data,
                &shape,
                Direction::Forward,
                Normalization::Unitary,
                variant,
            )
            .unwrap()
        };
        let (x, y) = (run(&uniform), run(&storage));
        assert!(x.iter().any(|c| c.norm() > 0.0));
        assert_eq!(x, y, "{variant:?}: the two bindings differ");
    }

    // The Radon transform of a square.
    let n = 24;
    let img: Vec<f32> = (0..n * n)
        .map(|i| {
            ((i % n) as f32 - 11.5)
                .hypot((i / n) as f32 - 11.5)
                .min(9.0)
        })
        .collect();
    let maps: Vec<[f64; 6]> = [0.0f64, 35.0, 90.0]
        .iter()
        .map(|d| {
            let (s, c) = d.to_radians().sin_cos();
            let h = (n as f64 - 1.0) / 2.0;
            [c, -s, h - c * h + s * h, s, c, h - s * h - c * h]
        })
        .collect();
    let x = voxlab::gpu::radon::radon_square(&uniform, &img, n, &maps).unwrap();
    let y = voxlab::gpu::radon::radon_square(&storage, &img, n, &maps).unwrap();
    assert!(x.iter().any(|&v| v > 0.0));
    assert_eq!(x, y, "radon: the two bindings differ");
}

/// The process's resident memory, in MiB (Linux).
fn resident_mib() -> Option<f64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: f64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4096.0 / 1048576.0)
}

#[test]
fn a_renderer_session_keeps_its_memory_over_many_frames() {
    let Some(ctx) = common::gpu("a_renderer_session_keeps_its_memory_over_many_frames") else {
        return;
    };
    if resident_mib().is_none() {
        eprintln!("no /proc/self/statm here: the resident memory is not measured");
        return;
    }
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let volume = phantom();
    let mut session = voxlab::gpu::raycast::RaycastSession::new(ctx, &volume).unwrap();
    // The first frames compile and upload; the memory is measured after them.
    for az in 0..5 {
        frame(&mut session, &volume, Mode::Mip, az as f64);
    }
    let before = resident_mib().unwrap();
    let frames = 100;
    for az in 0..frames {
        frame(&mut session, &volume, Mode::Mip, az as f64);
    }
    let grown = resident_mib().unwrap() - before;
    eprintln!("{frames} frames of one session: the resident memory grew by {grown:.1} MiB");
    // Measured on lavapipe: 0.1 MiB with the parameter blocks in storage buffers,
    // 150 MiB with them in uniform buffers. The bound leaves room for the allocator.
    assert!(
        grown < 24.0,
        "{frames} frames of one session grew the resident memory by {grown:.1} MiB"
    );
}
