//! The distributed render (`jobs::distributed_render`) on 1–4 ranks of an in-process
//! communicator (threads), against the single-process render of the same request:
//! MIP and MinIP equal it exactly; X-ray and DVR within the bounds below, measured on
//! these cases (the regrouping of the sums by brick). Bricks of unequal size (odd
//! dimensions, 3 ranks), views along every axis, oblique and perspective views, an
//! oblique anisotropic affine, both compositing orders, shading, jitter and a clipping
//! box; each rank reads only its brick (and ghost voxels) from a raw file.
//! (tests/mpi_render.rs runs the same job under mpirun.)

mod common;

use voxlab::metrics::max_abs_error;

use common::{brick_test_volume, on_thread_ranks, scratch};
use voxlab::jobs::distributed_render::{self, DistributedRendering};
use voxlab::jobs::input::VolumeInput;
use voxlab::jobs::render::{RenderRequest, SceneRequest, ViewRequest};
use voxlab::jobs::Backend;
use voxlab::settings::{Compositing, Filter, Mode};

/// X-ray and DVR against the single-process image in f64, relative to the image's
/// largest value: measured on these cases, up to 1.1e-11 on X-ray values up to 21692
/// (5.0e-16 relative) and 4.4e-16 on DVR; the bound leaves room for other rank counts
/// and machines.
const F64_BOUND: f64 = 1e-12;
/// The same in f32: measured up to 5.9e-3 on X-ray values up to 23079 (2.5e-7
/// relative) and 1.8e-7 on DVR.
const F32_BOUND: f64 = 1e-6;

fn request(input: &str, mode: Mode, backend: Backend) -> RenderRequest {
    RenderRequest {
        scene: SceneRequest {
            input: VolumeInput::new(input),
            mode,
            width: Some(48),
            height: Some(40),
            ..SceneRequest::default()
        },
        backend,
        ..RenderRequest::default()
    }
}

/// The cases: a name, a request and whether the image must be exactly the
/// single-process one.
fn cases(file: &str) -> Vec<(&'static str, RenderRequest, bool)> {
    let axis = |a: &str| ViewRequest {
        axis: Some(a.into()),
        ..ViewRequest::default()
    };
    let mut out = Vec::new();
    for (name, a) in [
        ("mip +x", "+x"),
        ("mip -y", "-y"),
        ("mip +z", "+z"),
        ("mip -x", "-x"),
        ("mip +y", "+y"),
        ("mip -z", "-z"),
    ] {
        let mut r = request(file, Mode::Mip, Backend::Cpu);
        r.scene.view = axis(a);
        r.scene.width = None;
        r.scene.height = None;
        out.push((name, r, true));
    }
    let mut r = request(file, Mode::Mip, Backend::Cpu);
    r.scene.window = Some([900.0, 400.0]);
    out.push(("mip perspective, windowed", r, true));
    let mut r = request(file, Mode::Minip, Backend::CpuF32);
    r.scene.view.azimuth = 123.0;
    r.scene.view.elevation = -35.0;
    r.scene.filter = Filter::CatmullRom;
    out.push(("minip f32 catmull-rom oblique", r, true));
    let mut r = request(file, Mode::Mip, Backend::Cpu);
    r.scene.ortho = true;
    r.scene.filter = Filter::Lanczos3;
    r.scene.accel.clip_box = Some([5.0, 3.0, 2.0, 30.0, 25.0, 18.0]);
    r.scene.accel.clip_space = voxlab::settings::ClipSpace::Voxel;
    out.push(("mip orthographic lanczos3 clipped", r, true));
    let mut r = request(file, Mode::Xray, Backend::Cpu);
    r.scene.accel.jitter = Some(7);
    out.push(("xray perspective jittered", r, false));
    let mut r = request(file, Mode::Xray, Backend::CpuF32);
    r.scene.view.azimuth = 200.0;
    r.scene.view.elevation = 10.0;
    r.scene.ortho = true;
    out.push(("xray f32 orthographic", r, false));
    let mut r = request(file, Mode::Dvr, Backend::Cpu);
    r.scene.ert = 1.0;
    out.push(("dvr shaded front to back", r, false));
    let mut r = request(file, Mode::Dvr, Backend::Cpu);
    r.scene.compositing = Compositing::BackToFront;
    r.scene.view.azimuth = -70.0;
    r.scene.precompute_gradients = true;
    r.scene.background = [0.2, 0.3, 0.4, 0.5];
    out.push(("dvr back to front, precomputed gradients", r, false));
    let mut r = request(file, Mode::Dvr, Backend::CpuF32);
    r.scene.shading = false;
    r.scene.ert = 1.0;
    r.scene.view.elevation = 60.0;
    out.push(("dvr f32 unshaded", r, false));
    // Pre-classified: each brick classifies its own voxels and ghosts, sampled at
    // p − origin; with empty-space skipping over its own cells.
    let mut r = request(file, Mode::Dvr, Backend::Cpu);
    r.scene.classification = voxlab::settings::Classification::Pre;
    r.scene.ert = 1.0;
    r.scene.view.azimuth = 40.0;
    out.push(("dvr pre-classified", r, false));
    let mut r = request(file, Mode::Dvr, Backend::CpuF32);
    r.scene.classification = voxlab::settings::Classification::Pre;
    r.scene.ert = 1.0;
    r.scene.accel.skip_empty = Some(true);
    r.scene.accel.block_size = Some(4);
    r.scene.filter = Filter::CatmullRom;
    out.push(("dvr f32 pre-classified catmull-rom, skipping", r, false));
    out
}

/// Early ray termination inside a brick: the bricks behind add at most `1 − ert`.
#[test]
fn early_termination_costs_at_most_one_minus_the_threshold() {
    let dir = scratch("ert");
    let file = brick_test_volume(&dir);
    let mut req = request(file.to_str().unwrap(), Mode::Dvr, Backend::Cpu);
    req.scene.ert = 0.9;
    req.scene.tf = "ct-bone".into();
    let want = single(&req);
    for ranks in 2..=4 {
        let got = on_ranks(&req, ranks);
        let img = got[0].as_ref().unwrap().image.clone().unwrap();
        let worst = max_abs_error(&img.data, &want.data);
        eprintln!("ert 0.9, {ranks} ranks: max |Δ| {worst:.3e}");
        assert!(worst <= 0.1 + 1e-12, "{ranks} ranks: {worst:e}");
    }
}

/// Empty-space skipping on the bricks (each walks its own cells): fewer samples, the
/// same image as without it.
#[test]
fn bricks_skip_empty_space_and_render_the_same_image() {
    let dir = scratch("skip");
    let file = brick_test_volume(&dir);
    // Opaque only near the volume's peak (values above 900 of −250 … 1136).
    let tf = dir.join("peak.json");
    std::fs::write(
        &tf,
        r#"{"name": "peak", "domain": [-300.0, 1200.0], "points": [
            {"value": -300.0, "rgba": [0, 0, 0, 0]}, {"value": 900.0, "rgba": [1, 0.5, 0.2, 0]},
            {"value": 1200.0, "rgba": [1, 0.9, 0.6, 0.6]}]}"#,
    )
    .unwrap();
    let mut req = request(file.to_str().unwrap(), Mode::Dvr, Backend::Cpu);
    req.scene.tf = tf.to_str().unwrap().into();
    req.scene.ert = 1.0;
    req.scene.accel.block_size = Some(4);
    let mut plain = req.clone();
    plain.scene.accel.skip_empty = Some(false);
    for ranks in [1, 3] {
        let skipping = on_ranks(&req, ranks).remove(0).unwrap();
        let every = on_ranks(&plain, ranks).remove(0).unwrap();
        eprintln!(
            "{ranks} ranks: {} samples skipping, {} without",
            skipping.total_samples, every.total_samples
        );
        assert!(skipping.total_samples * 2 < every.total_samples);
        assert_eq!(skipping.image, every.image);
    }
}

fn single(req: &RenderRequest) -> voxlab::frame::Frame {
    voxlab::jobs::render::run(req, &()).unwrap().output.image
}

fn on_ranks(req: &RenderRequest, ranks: usize) -> Vec<voxlab::Result<DistributedRendering>> {
    on_thread_ranks(ranks, |comm| distributed_render::run(req, comm, &()))
}

#[test]
fn one_to_four_ranks_render_the_single_process_image() {
    let dir = scratch("cases");
    let file = brick_test_volume(&dir);
    let file = file.to_str().unwrap();
    for (name, req, exact) in cases(file) {
        let want = single(&req);
        let top = want.data.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for ranks in 1..=4 {
            let got = on_ranks(&req, ranks);
            let d = got[0].as_ref().unwrap();
            let img = d.image.as_ref().unwrap();
            assert_eq!(
                (img.width, img.height, img.channels),
                (want.width, want.height, want.channels)
            );
            let worst = max_abs_error(&img.data, &want.data);
            eprintln!("{name}, {ranks} ranks: max |Δ| {worst:.3e} (image max {top:.3})");
            if exact || ranks == 1 {
                // One rank owns every sample of every ray: the sums are not regrouped.
                assert!(worst == 0.0, "{name}, {ranks} ranks: max |Δ| {worst:e}");
            } else if req.backend == Backend::CpuF32 {
                assert!(
                    worst <= F32_BOUND * top.max(1.0),
                    "{name}, {ranks} ranks: {worst:e}"
                );
            } else {
                assert!(
                    worst <= F64_BOUND * top.max(1.0),
                    "{name}, {ranks} ranks: {worst:e}"
                );
            }
            // Every rank knows the same report; the ranks took every sample once.
            for r in &got[1..] {
                let r = r.as_ref().unwrap();
                assert!(r.image.is_none());
                assert_eq!(r.ranks, d.ranks);
            }
            assert_eq!(d.ranks.len(), ranks);
            for rep in &d.ranks {
                assert!(
                    rep.composite_bytes <= rep.composite_bound,
                    "{name}: {rep:?}"
                );
            }
        }
    }
}

#[test]
fn each_rank_reads_only_its_brick_and_ghost_voxels() {
    let dir = scratch("bricks");
    let file = brick_test_volume(&dir);
    let req = request(file.to_str().unwrap(), Mode::Mip, Backend::Cpu);
    let got = on_ranks(&req, 3);
    let d = got[0].as_ref().unwrap();
    assert!(!d.reads_whole);
    let total = 37 * 29 * 23;
    let mut bricks = 0;
    for rep in &d.ranks {
        let b = rep.brick;
        bricks += b.voxels();
        // Trilinear: three ghost voxels each side, within the volume.
        let g = b.with_ghost(3, [37, 29, 23]);
        assert_eq!(rep.voxels_read, g.voxels() as u64, "{rep:?}");
        assert!(rep.voxels_read < total as u64 * 3 / 4, "{rep:?}");
    }
    assert_eq!(bricks, total, "the bricks tile the volume");
    // Unequal bricks: 37 is cut 18 | 19, then the 19 side into two.
    assert!(d
        .ranks
        .iter()
        .any(|r| r.brick.dims() != d.ranks[0].brick.dims()));
}

#[test]
fn a_phantom_is_read_whole_and_rendered_the_same() {
    let req = request("phantom:shepp-logan-modified:40", Mode::Mip, Backend::Cpu);
    let want = single(&req);
    let got = on_ranks(&req, 2);
    let d = got[0].as_ref().unwrap();
    assert!(d.reads_whole);
    assert_eq!(d.image.as_ref().unwrap().data, want.data);
}

#[test]
fn refusals_and_failures_are_one_message_on_every_rank() {
    let dir = scratch("refusals");
    let file = brick_test_volume(&dir);
    let file = file.to_str().unwrap();
    let mut stereo = request(file, Mode::Mip, Backend::Cpu);
    stereo.stereo = Some(voxlab::jobs::render::StereoRequest {
        layout: voxlab::jobs::stereo::StereoLayout::Anaglyph,
        eye_separation: 65.0,
        convergence: None,
    });
    let mut mida = request(file, Mode::Mida, Backend::Cpu);
    mida.scene.width = Some(8);
    let mut sinc = request(file, Mode::Dvr, Backend::Cpu);
    sinc.scene.filter = Filter::Sinc;
    let missing = request(
        dir.join("missing.nrrd").to_str().unwrap(),
        Mode::Mip,
        Backend::Cpu,
    );
    for (req, says) in [
        (stereo, "--stereo"),
        (mida, "MIDA"),
        (sinc, "--filter"),
        (missing, "missing.nrrd"),
    ] {
        for r in on_ranks(&req, 3) {
            let e = r.expect_err("refused").to_string();
            assert!(e.contains(says), "{e}");
        }
    }
    // More ranks than a tiny volume can be cut into (2³ voxels, 9 ranks).
    let tiny = request("phantom:sphere:2", Mode::Mip, Backend::Cpu);
    for r in on_ranks(&tiny, 9) {
        let e = r.expect_err("refused").to_string();
        assert!(e.contains("bricks"), "{e}");
    }
}
