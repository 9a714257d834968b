//! The distributed render with `--backend gpu` (each rank ray-casts its brick on the
//! GPU, `gpu::raycast::render_owned`) on 1–4 ranks of an in-process communicator,
//! against the single-process GPU render of the same request: the same rays, step
//! grids and sample positions, each sample taken by the brick that owns it, so MIP and
//! MinIP are equal bit for bit and X-ray and DVR within the regrouping of their sums.

mod common;

use voxlab::metrics::max_abs_error;

use common::{brick_test_volume, gpu, on_thread_ranks, scratch};
use voxlab::jobs::distributed_render;
use voxlab::jobs::input::VolumeInput;
use voxlab::jobs::render::{RenderRequest, SceneRequest};
use voxlab::jobs::Backend;
use voxlab::settings::{Compositing, Filter, Mode};

/// X-ray and DVR against the single-process GPU image, relative to its largest value:
/// measured on lavapipe up to 2.4e-7 (X-ray, 5.9e-3 of 24130) and 2.1e-7 (DVR); the bound leaves room
/// for other adapters' rounding.
const GPU_BOUND: f64 = 2e-6;

/// MIDA and iso-surfaces split into bricks against the unsplit GPU image: the same
/// samples and the same arithmetic in the same order (each ray's state handed from
/// brick to brick), finished on the host instead of the device: 0 measured on
/// lavapipe; the bound admits the last bits of an adapter that fuses the finish's
/// multiply-adds (the host does not).
const CARRIED_BOUND: f64 = 4.0 * f32::EPSILON as f64;

fn request(input: &str, mode: Mode) -> RenderRequest {
    RenderRequest {
        scene: SceneRequest {
            input: VolumeInput::new(input),
            mode,
            width: Some(40),
            height: Some(32),
            ..SceneRequest::default()
        },
        backend: Backend::Gpu,
        ..RenderRequest::default()
    }
}

#[test]
fn gpu_ranks_render_the_single_process_gpu_image() {
    if gpu("gpu_ranks_render_the_single_process_gpu_image").is_none() {
        return;
    }
    let dir = scratch("gpu-cases");
    let file = brick_test_volume(&dir);
    let file = file.to_str().unwrap();
    let mut cases: Vec<(&str, RenderRequest, bool)> = Vec::new();
    cases.push(("mip perspective", request(file, Mode::Mip), true));
    let mut r = request(file, Mode::Minip);
    r.scene.view.azimuth = 140.0;
    r.scene.filter = Filter::CatmullRom;
    r.scene.ortho = true;
    cases.push(("minip catmull-rom orthographic", r, true));
    let mut r = request(file, Mode::Xray);
    r.scene.view.elevation = -40.0;
    cases.push(("xray", r, false));
    let mut r = request(file, Mode::Dvr);
    r.scene.ert = 1.0;
    cases.push(("dvr shaded, skipping", r, false));
    let mut r = request(file, Mode::Dvr);
    r.scene.compositing = Compositing::BackToFront;
    r.scene.precompute_gradients = true;
    r.scene.background = [0.2, 0.3, 0.4, 0.5];
    cases.push(("dvr back to front", r, false));
    for (name, req, exact) in cases {
        let want = voxlab::jobs::render::run(&req, &()).unwrap().output.image;
        let top = want.data.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for ranks in 1..=4 {
            let got = on_thread_ranks(ranks, |comm| distributed_render::run(&req, comm, &()));
            let d = got[0].as_ref().unwrap();
            assert_eq!(d.what, "gpu");
            let img = d.image.as_ref().unwrap();
            let worst = max_abs_error(&img.data, &want.data);
            eprintln!("{name}, {ranks} ranks: max |Δ| {worst:.3e} (image max {top:.3})");
            if exact || ranks == 1 {
                assert!(worst == 0.0, "{name}, {ranks} ranks: {worst:e}");
            } else {
                assert!(
                    worst <= GPU_BOUND * top.max(1.0),
                    "{name}, {ranks} ranks: {worst:e}"
                );
            }
        }
    }
}

/// One GPU, a volume past the 3-D texture limit or the device memory: bricks rendered one
/// after another and composited on the host (`gpu::raycast::render_bricked`), against
/// the unsplit render.
#[test]
fn bricks_past_the_texture_limit_render_the_unsplit_image() {
    let Some(ctx) = gpu("bricks_past_the_texture_limit_render_the_unsplit_image") else {
        return;
    };
    use voxlab::gpu::raycast::{brick_plan, render_bricked, RaycastSession};
    let dir = scratch("gpu-bricked");
    let file = brick_test_volume(&dir);
    let volume = VolumeInput::new(file.to_str().unwrap()).read().unwrap();
    let pre = |s: &mut SceneRequest| {
        s.classification = voxlab::settings::Classification::Pre;
        s.accel.skip_empty = Some(true);
    };
    let gamma = |g: f64| move |s: &mut SceneRequest| s.mida_gamma = g;
    type Case<'a> = (Mode, Filter, f64, &'a dyn Fn(&mut SceneRequest));
    let iso = |value: f64, opacity: f64| voxlab::settings::IsoSurface {
        value,
        color: [0.9, 0.5 * opacity, 0.2],
        opacity,
    };
    let cases: [Case; 19] = [
        (Mode::Mip, Filter::Trilinear, 0.0, &|_| {}),
        (Mode::Minip, Filter::CatmullRom, 0.0, &|_| {}),
        (Mode::Xray, Filter::Trilinear, GPU_BOUND, &|_| {}),
        (Mode::Dvr, Filter::Trilinear, GPU_BOUND, &|_| {}),
        // Pre-classified (each brick classifies its own voxels on the device).
        (Mode::Dvr, Filter::Nearest, GPU_BOUND, &pre),
        // MIDA: each ray's state handed from brick to brick in the ray's order, so the
        // unsplit render's samples and arithmetic in its order, finished on the host.
        (Mode::Mida, Filter::Trilinear, CARRIED_BOUND, &gamma(0.0)),
        (Mode::Mida, Filter::CatmullRom, CARRIED_BOUND, &gamma(-0.5)),
        (Mode::Mida, Filter::Trilinear, CARRIED_BOUND, &gamma(0.6)),
        (
            Mode::Mida,
            Filter::Nearest,
            CARRIED_BOUND,
            &|s: &mut SceneRequest| {
                pre(s);
                s.mida_gamma = 0.3;
            },
        ),
        (
            Mode::Mida,
            Filter::Trilinear,
            CARRIED_BOUND,
            &|s: &mut SceneRequest| {
                s.ortho = true;
                s.shading = true;
                s.mida_gamma = 0.4;
            },
        ),
        // The interpolating B-splines: every brick samples the whole volume's
        // coefficients (prefiltered along whole lines), so MIP is still bit for bit.
        (Mode::Mip, Filter::BsplineInterp, 0.0, &|_| {}),
        (
            Mode::Dvr,
            Filter::BsplineFastInterp,
            GPU_BOUND,
            &|s: &mut SceneRequest| {
                s.shading = true;
            },
        ),
        (
            Mode::Mida,
            Filter::BsplineInterp,
            CARRIED_BOUND,
            &gamma(0.2),
        ),
        // Pre-classified colours and precomputed gradients, prefiltered along whole
        // lines too: every brick is given its part of the whole volume's.
        (Mode::Dvr, Filter::BsplineInterp, GPU_BOUND, &pre),
        (
            Mode::Dvr,
            Filter::BsplineFastInterp,
            GPU_BOUND,
            &|s: &mut SceneRequest| {
                s.shading = true;
                s.precompute_gradients = true;
            },
        ),
        (
            Mode::Mida,
            Filter::BsplineFastInterp,
            CARRIED_BOUND,
            &|s: &mut SceneRequest| {
                pre(s);
                s.shading = true;
                s.precompute_gradients = true;
                s.mida_gamma = -0.3;
            },
        ),
        // Iso-surfaces, handed on the same way: a crossing between two bricks' samples
        // is found and shaded by the later brick (its ghost voxels reach a step out).
        (
            Mode::Iso,
            Filter::Trilinear,
            CARRIED_BOUND,
            &|s: &mut SceneRequest| {
                s.iso = vec![iso(200.0, 0.4), iso(600.0, 0.7)];
            },
        ),
        (
            Mode::Iso,
            Filter::CatmullRom,
            CARRIED_BOUND,
            &|s: &mut SceneRequest| {
                s.iso = vec![iso(400.0, 1.0)];
                s.iso_opaque = true;
                s.iso_refine = false;
                s.ortho = true;
                s.step = 3.0;
                s.precompute_gradients = true;
            },
        ),
        (
            Mode::Dvr,
            Filter::Trilinear,
            CARRIED_BOUND,
            &|s: &mut SceneRequest| {
                s.iso = vec![iso(500.0, 0.5)];
                s.ert = 0.9;
            },
        ),
    ];
    for (mode, filter, bound, tweak) in cases {
        let mut req = request(file.to_str().unwrap(), mode);
        req.scene.filter = filter;
        req.scene.ert = 1.0;
        tweak(&mut req.scene);
        let (tf, camera, settings) =
            voxlab::jobs::render::build_view(&req.scene, &volume, false).unwrap();
        let want = RaycastSession::new(ctx, &volume)
            .unwrap()
            .render(&tf, &camera, &settings, &|_, _| {})
            .unwrap()
            .output
            .image;
        let top = want.data.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        // Texels per axis (28, 20), and texels in all (a device memory of 9,000 f32
        // texels: 37 × 29 × 23 = 24,679 voxels do not fit).
        for (limit, most) in [(28, None), (20, None), (64, Some(9000))] {
            let (tree, bricks) = brick_plan(volume.dims(), &settings, limit, most).unwrap();
            let ghost = voxlab::gpu::raycast::brick_ghost_for(&settings);
            for b in &bricks {
                let g = b.with_ghost(ghost, volume.dims());
                assert!(g.dims().iter().all(|&n| n <= limit), "{g:?}");
                assert!(most.is_none_or(|m| g.voxels() as u64 <= m), "{g:?}");
            }
            let cut = (&tree, &bricks[..]);
            let got =
                render_bricked(ctx, &volume, &tf, &camera, &settings, cut, &|_, _| {}).unwrap();
            let n = bricks.len();
            assert!(n > 1, "{mode:?}: the limit {limit} splits the volume");
            let worst = max_abs_error(&got.output.image.data, &want.data);
            eprintln!(
                "{mode:?}, {n} bricks of ≤ {limit} ({most:?}): max |Δ| {worst:.3e} (image max {top:.3})"
            );
            assert!(
                worst <= bound * top.max(1.0),
                "{mode:?}, {n} bricks: {worst:e}"
            );
        }
    }
    // A limit below the ghost voxels cannot be met.
    let trilinear = voxlab::settings::RenderSettings::default();
    assert_eq!(trilinear.filter, Filter::Trilinear);
    let e = brick_plan(volume.dims(), &trilinear, 6, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("cannot be cut into bricks"), "{e}");
}

/// A camera that sees part of the volume: the bricks no ray meets are skipped and the
/// others cast only the rays of their rectangles (`gpu::raycast::bricks_seen`), and the
/// image is still the unsplit one (MIP bit for bit, DVR within the regrouped sums, MIDA
/// and shadowed iso-surfaces handed from brick to brick through the bricks in view, the
/// shadow rays through all of them); turned away, no brick is cast and the image is the
/// unsplit one.
#[test]
fn bricks_out_of_view_are_skipped_and_the_image_is_the_unsplit_one() {
    let Some(ctx) = gpu("bricks_out_of_view_are_skipped_and_the_image_is_the_unsplit_one") else {
        return;
    };
    use voxlab::gpu::raycast::{brick_plan, bricks_seen, render_bricked, RaycastSession};
    let dir = scratch("gpu-bricked-view");
    let file = brick_test_volume(&dir);
    let volume = VolumeInput::new(file.to_str().unwrap()).read().unwrap();
    let shadows = |s: &mut SceneRequest| {
        s.iso = vec![voxlab::settings::IsoSurface {
            value: 450.0,
            color: [0.9, 0.6, 0.2],
            opacity: 1.0,
        }];
        s.iso_opaque = true;
        s.shadows = true;
        s.shading = true;
        s.light = Some([-0.6, 0.5, -0.62]);
    };
    type Case<'a> = (Mode, f64, &'a dyn Fn(&mut SceneRequest));
    let cases: [Case; 4] = [
        (Mode::Mip, 0.0, &|_| {}),
        (Mode::Dvr, GPU_BOUND, &|_| {}),
        (Mode::Mida, CARRIED_BOUND, &|s| s.mida_gamma = 0.3),
        (Mode::Iso, CARRIED_BOUND, &shadows),
    ];
    for (mode, bound, tweak) in cases {
        let mut req = request(file.to_str().unwrap(), mode);
        // A narrow view of the volume's middle (the distance given, or the orbit would
        // step back until the whole volume is in view).
        req.scene.fov = 14.0;
        req.scene.distance = Some(60.0);
        req.scene.view.azimuth = 25.0;
        tweak(&mut req.scene);
        let (tf, camera, settings) =
            voxlab::jobs::render::build_view(&req.scene, &volume, false).unwrap();
        let want = RaycastSession::new(ctx, &volume)
            .unwrap()
            .render(&tf, &camera, &settings, &|_, _| {})
            .unwrap()
            .output
            .image;
        let top = want.data.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(top > 0.0, "{mode:?}: an empty image");
        let (tree, bricks) = brick_plan(volume.dims(), &settings, 12, None).unwrap();
        let seen = bricks_seen(&camera, volume.affine(), &bricks);
        let skipped = seen.iter().filter(|v| v.is_none()).count();
        assert!(
            skipped > 0 && skipped < bricks.len(),
            "{mode:?}: {skipped} of {} bricks out of view",
            bricks.len()
        );
        // The rays the bricks cast: far fewer than every pixel's for every brick seen.
        let cast: usize = seen.iter().flatten().map(|r| r.len()).sum();
        let every = (bricks.len() - skipped) * camera.width * camera.height;
        assert!(cast * 2 < every, "{mode:?}: {cast} rays cast of {every}");
        let cut = (&tree, &bricks[..]);
        let got = render_bricked(ctx, &volume, &tf, &camera, &settings, cut, &|_, _| {}).unwrap();
        let worst = max_abs_error(&got.output.image.data, &want.data);
        eprintln!(
            "{mode:?}: {skipped} of {} bricks out of view, {cast} rays cast of {every}, \
             max |Δ| {worst:.3e} (image max {top:.3})",
            bricks.len()
        );
        assert!(worst <= bound * top.max(1.0), "{mode:?}: {worst:e}");
        // Turned away from the volume (the eye outside it): no brick is cast, and the
        // image is the unsplit one, every pixel missing the volume.
        let mut away = req.clone();
        away.scene.distance = None;
        let (_, mut camera, _) =
            voxlab::jobs::render::build_view(&away.scene, &volume, false).unwrap();
        (camera.forward, camera.right) = (-camera.forward, -camera.right);
        let seen = bricks_seen(&camera, volume.affine(), &bricks);
        assert!(
            seen.iter().all(Option::is_none),
            "{mode:?}: a brick in view"
        );
        let want = RaycastSession::new(ctx, &volume)
            .unwrap()
            .render(&tf, &camera, &settings, &|_, _| {})
            .unwrap()
            .output;
        let got = render_bricked(ctx, &volume, &tf, &camera, &settings, cut, &|_, _| {}).unwrap();
        assert!(
            got.output.image.data == want.image.data,
            "{mode:?}: the image of no brick differs from the unsplit one"
        );
        assert_eq!(got.output.total_samples, 0, "{mode:?}: samples taken");
        assert_eq!(
            want.total_samples, 0,
            "{mode:?}: the unsplit render took samples"
        );
    }
}

/// Opaque iso-surfaces with shadows in bricks: each hit keeps its two endings, and its
/// shadow ray is marched afterwards through the bricks in the light's order, handed on
/// from brick to brick (`cpu::modes::shadow_steps`): the unsplit image, for directional
/// lights, perspective and orthographic, and a perspective camera inside the volume,
/// whose headlight's shadow rays pass the eye (a second sweep). (A headlight from outside
/// casts no shadows to speak of: its shadow rays go back along the rays.)
#[test]
fn iso_surface_shadows_in_bricks_render_the_unsplit_image() {
    let Some(ctx) = gpu("iso_surface_shadows_in_bricks_render_the_unsplit_image") else {
        return;
    };
    use voxlab::gpu::raycast::{brick_plan, render_bricked, RaycastSession};
    let dir = scratch("gpu-bricked-shadows");
    let file = brick_test_volume(&dir);
    let volume = VolumeInput::new(file.to_str().unwrap()).read().unwrap();
    let iso = |value: f64, color: [f64; 3]| voxlab::settings::IsoSurface {
        value,
        color,
        opacity: 1.0,
    };
    type Case<'a> = (&'a str, Mode, Filter, &'a dyn Fn(&mut SceneRequest));
    let cases: [Case; 4] = [
        (
            "directional light",
            Mode::Iso,
            Filter::Trilinear,
            &|s: &mut SceneRequest| s.light = Some([-0.6, 0.5, -0.62]),
        ),
        (
            "orthographic, long steps, light from the side",
            Mode::Iso,
            Filter::CatmullRom,
            &|s: &mut SceneRequest| {
                s.light = Some([-0.2, -0.9, 0.3]);
                s.ortho = true;
                s.view.azimuth = 70.0;
                s.step = 3.0;
                s.iso_refine = false;
            },
        ),
        (
            "headlight, from inside the volume",
            Mode::Iso,
            Filter::Trilinear,
            &|s: &mut SceneRequest| {
                // Shadow rays that pass the eye: the first sweep (the rays' order
                // reversed) leaves them waiting, the second (the rays' order) ends them.
                s.distance = Some(13.0);
                s.fov = 100.0;
                s.view.azimuth = 120.0;
                s.view.elevation = 60.0;
                s.iso = vec![iso(600.0, [0.9, 0.6, 0.2])];
            },
        ),
        (
            "DVR between the surfaces, directional light",
            Mode::Dvr,
            Filter::Trilinear,
            &|s: &mut SceneRequest| {
                s.light = Some([-0.3, 0.8, 0.5]);
                s.ert = 0.95;
            },
        ),
    ];
    for (name, mode, filter, tweak) in cases {
        let mut req = request(file.to_str().unwrap(), mode);
        req.scene.filter = filter;
        req.scene.ert = 1.0;
        req.scene.shading = true;
        req.scene.iso = vec![iso(450.0, [0.9, 0.6, 0.2]), iso(900.0, [0.2, 0.5, 0.9])];
        req.scene.iso_opaque = true;
        req.scene.shadows = true;
        tweak(&mut req.scene);
        let (tf, camera, settings) =
            voxlab::jobs::render::build_view(&req.scene, &volume, false).unwrap();
        let unsplit = |settings: &voxlab::settings::RenderSettings| {
            RaycastSession::new(ctx, &volume)
                .unwrap()
                .render(&tf, &camera, settings, &|_, _| {})
                .unwrap()
                .output
                .image
        };
        let want = unsplit(&settings);
        // The shadows are there: pixels differ from the unshadowed image.
        let mut lit = settings.clone();
        lit.iso_shadows = false;
        let lit = unsplit(&lit);
        let dark = want
            .data
            .chunks(4)
            .zip(lit.data.chunks(4))
            .filter(|(a, b)| a != b)
            .count();
        assert!(dark >= 40, "{name}: {dark} pixels in shadow");
        let top = want.data.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (limit, most) in [(28, None), (22, None), (64, Some(9000))] {
            let (tree, bricks) = brick_plan(volume.dims(), &settings, limit, most).unwrap();
            let got = render_bricked(
                ctx,
                &volume,
                &tf,
                &camera,
                &settings,
                (&tree, &bricks),
                &|_, _| {},
            )
            .unwrap();
            let n = bricks.len();
            assert!(n > 1, "{name}: the limit {limit} splits the volume");
            let worst = max_abs_error(&got.output.image.data, &want.data);
            eprintln!(
                "{name}, {n} bricks of ≤ {limit} ({most:?}): max |Δ| {worst:.3e}, {dark} \
                 pixels in shadow (image max {top:.3})"
            );
            assert!(
                worst <= CARRIED_BOUND * top.max(1.0),
                "{name}, {n} bricks: {worst:e}"
            );
        }
    }
}

/// `voxlab render --backend gpu` under a lowered 3-D texture limit and under a lowered
/// device memory: `--dry-run` prints the brick split and writes nothing; the render says
/// how it split and writes the unsplit MIP, MIDA and opaque iso-surface images byte for
/// byte. A 48³ f32 volume's texture
/// (432 KiB) and the 64² image's buffers (80 KiB) exceed 256 KiB of device memory; the
/// bricks hold at most (256 − 80) KiB / 4 bytes = 45,056 texels with their ghost voxels.
#[test]
fn the_command_splits_past_the_texture_limit_and_the_memory_and_says_so() {
    if gpu("the_command_splits_past_the_texture_limit_and_the_memory_and_says_so").is_none() {
        return;
    }
    let dir = scratch("gpu-bricked-cli");
    let (one, split) = (dir.join("one.npy"), dir.join("split.npy"));
    let args = |out: &std::path::Path, mode: &str| {
        vec![
            "render".to_string(),
            "phantom:shepp-logan-modified:48".into(),
            "--mode".into(),
            mode.into(),
            "--backend".into(),
            "gpu".into(),
            "--width".into(),
            "64".into(),
            "--height".into(),
            "64".into(),
            "--out".into(),
            out.display().to_string(),
        ]
    };
    let run = |a: &[String], limit: Option<(&str, &str)>| {
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        let mut c = common::voxlab_command(&a);
        if let Some((k, v)) = limit {
            c.env(k, v);
        }
        c.output().unwrap()
    };
    let text = |o: &std::process::Output| {
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr)
    };
    let one_mida = dir.join("one-mida.npy");
    let one_iso = dir.join("one-iso.npy");
    let one_shadows = dir.join("one-shadows.npy");
    // Long steps: a crossing between two bricks' samples lies up to 4 voxels outside
    // the later brick, which shades it (its ghost voxels reach that far; without them 3
    // pixels differ by 0.049).
    let with_iso = |mut a: Vec<String>, more: &[&str]| {
        a.extend(
            [
                "--iso",
                "0.5:#ff0000:1",
                "--step",
                "4",
                "--filter",
                "catmull-rom",
            ]
            .map(String::from),
        );
        a.extend(more.iter().map(|s| s.to_string()));
        a
    };
    text(&run(&args(&one, "mip"), None));
    text(&run(&args(&one_mida, "mida"), None));
    text(&run(
        &with_iso(args(&one_iso, "iso"), &["--iso-opaque"]),
        None,
    ));
    let shadows = ["--iso-opaque", "--shadows", "--light", "-0.6,0.5,-0.62"];
    text(&run(&with_iso(args(&one_shadows, "iso"), &shadows), None));
    // The shadows are there.
    assert_ne!(
        std::fs::read(&one_iso).unwrap(),
        std::fs::read(&one_shadows).unwrap()
    );
    for (limit, why, limits) in [
        (
            ("VOXLAB_GPU_MAX_TEXTURE_3D", "32"),
            "exceeds the 3-D texture limit of 32 texels per axis",
            "3-D texture 32 per axis",
        ),
        (
            ("VOXLAB_GPU_MEMORY", "256KiB"),
            "textures and the image's buffers, 512.0 KiB, exceed the 256.0 KiB of device \
             memory a job may fill",
            ", device memory 256.0 KiB",
        ),
    ] {
        let mut dry = args(&split, "mip");
        dry.push("--dry-run".into());
        let said = text(&run(&dry, Some(limit)));
        assert!(said.contains("split:  ray casting in"), "{said}");
        assert!(said.contains(why), "{limit:?}: {said}");
        assert!(said.contains(limits), "{limit:?}: {said}");
        assert!(!split.exists());
        // MIP composited sort-last, MIDA and iso-surfaces with each ray's state handed
        // from brick to brick, and their shadow rays after them: each the unsplit image
        // (on lavapipe, byte for byte).
        // (Under the lowered memory the carried states, 52 bytes a pixel, leave the
        // 48³ volume hundreds of bricks of a few voxels: MIDA and iso-surfaces run under
        // the texture limit only.)
        let carried = limit.0 == "VOXLAB_GPU_MAX_TEXTURE_3D";
        for (a, whole) in [
            (args(&split, "mip"), &one),
            (args(&split, "mida"), &one_mida),
            (with_iso(args(&split, "iso"), &["--iso-opaque"]), &one_iso),
            (with_iso(args(&split, "iso"), &shadows), &one_shadows),
        ]
        .into_iter()
        .filter(|(_, whole)| carried || *whole == &one)
        {
            let said = text(&run(&a, Some(limit)));
            assert!(
                said.contains("voxlab: ray casting in") && said.contains(why),
                "{said}"
            );
            assert_eq!(
                said.contains(
                    "; the shadow rays in sweeps through the bricks in the light's order)"
                ),
                whole == &one_shadows,
                "{said}"
            );
            assert_eq!(
                std::fs::read(whole).unwrap(),
                std::fs::read(&split).unwrap()
            );
            std::fs::remove_file(&split).unwrap();
        }
        // A renderer session's frames (`--repeat`, the volume whole) are refused by the
        // run and its dry run alike, saying why the volume is cut.
        let mut mip_repeat = args(&split, "mip");
        mip_repeat.extend(["--repeat".into(), "2".into()]);
        let says = "invalid --repeat: times the frames of one renderer session, which holds \
                    the volume whole, but this frame needs ray casting in ";
        let mut said = Vec::new();
        for dry in [false, true] {
            let mut a = mip_repeat.clone();
            if dry {
                a.push("--dry-run".into());
            }
            let o = run(&a, Some(limit));
            assert_eq!(o.status.code(), Some(1), "{a:?}");
            let e = String::from_utf8_lossy(&o.stderr).into_owned();
            assert!(e.contains(says) && e.contains(why), "{e}");
            assert!(!split.exists());
            said.push(e);
        }
        assert_eq!(said[0], said[1]);
    }
    assert_eq!(
        text(&run(
            &["info".into(), "--gpu".into()],
            Some(("VOXLAB_GPU_MEMORY", "256KiB"))
        ))
        .lines()
        .filter(|l| l.starts_with("memory:"))
        .collect::<Vec<_>>(),
        ["memory:       256.0 KiB for a job (VOXLAB_GPU_MEMORY)"]
    );
}
