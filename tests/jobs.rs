//! The front door (`voxlab::jobs`): a request from JSON does what the command line
//! does, to the bit; progress reaches the caller; a caller can stop a long job; a job
//! refuses what it cannot do with a typed error.

mod common;

use common::{s, scratch, stderr, voxlab};
use std::sync::atomic::{AtomicU64, Ordering};
use voxlab::jobs::input::{NonFinite, VolumeInput};
use voxlab::jobs::{self, Backend, Progress};
use voxlab::{Error, Volume};

/// Counts what a job reports, and asks it to stop after `stop_after` row updates.
struct Recorder {
    advances: AtomicU64,
    last: AtomicU64,
    warnings: std::sync::Mutex<Vec<String>>,
    stages: std::sync::Mutex<Vec<String>>,
    stop_after: u64,
}

impl Recorder {
    fn new(stop_after: u64) -> Self {
        Recorder {
            advances: AtomicU64::new(0),
            last: AtomicU64::new(0),
            warnings: Default::default(),
            stages: Default::default(),
            stop_after,
        }
    }
}

impl Progress for Recorder {
    fn begin(&self, stage: &str, _unit: &str, _steps: u64) {
        self.stages.lock().unwrap().push(stage.to_string());
    }
    fn advance(&self, done: u64, steps: u64) {
        assert!(done <= steps, "{done} of {steps}");
        self.advances.fetch_add(1, Ordering::SeqCst);
        self.last.fetch_max(done, Ordering::SeqCst);
    }
    fn warn(&self, text: &str) {
        self.warnings.lock().unwrap().push(text.to_string());
    }
    fn cancelled(&self) -> bool {
        self.advances.load(Ordering::SeqCst) >= self.stop_after
    }
}

/// The float32 values of an `.npy` the command line wrote.
fn npy(path: &std::path::Path) -> (Vec<usize>, Vec<f32>) {
    voxlab::io::npy::read_npy_f32(path).unwrap()
}

#[test]
fn a_render_request_in_json_gives_the_command_lines_image_bit_for_bit() {
    let d = scratch("render-json");
    let out = d.join("cli.npy");
    let o = voxlab(&[
        "render",
        "phantom:shepp-logan-modified:40",
        "--width",
        "36",
        "--height",
        "30",
        "--filter",
        "catmull-rom",
        "--azimuth",
        "-40",
        "--backend",
        "cpu-f32",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let req: jobs::render::RenderRequest = serde_json::from_str(
        r#"{
            "scene": {
                "input": { "source": "phantom:shepp-logan-modified:40" },
                "width": 36, "height": 30, "filter": "catmull-rom",
                "view": { "azimuth": -40 }
            },
            "backend": "cpu-f32"
        }"#,
    )
    .unwrap();
    let r = jobs::render::run(&req, &()).unwrap();
    let (shape, cli) = npy(&out);
    assert_eq!(shape, vec![30, 36, 4]);
    let job: Vec<f32> = r.output.image.data.iter().map(|&v| v as f32).collect();
    assert_eq!(cli, job, "the job and the command line differ");
    assert_eq!(r.engine.backend(), Backend::CpuF32);
    assert!(r.output.total_samples > 0);
}

#[test]
fn requests_refuse_unknown_fields_and_names() {
    let e = serde_json::from_str::<jobs::render::RenderRequest>(r#"{"backnd": "gpu"}"#)
        .unwrap_err()
        .to_string();
    assert!(e.contains("unknown field `backnd`"), "{e}");
    let e = serde_json::from_str::<jobs::render::RenderRequest>(r#"{"backend": "tpu"}"#)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("unknown variant `tpu`") && e.contains("cpu-f32"),
        "{e}"
    );
    let e = serde_json::from_str::<jobs::reconstruct::ReconstructRequest>(
        r#"{"input": "p.npy", "filter": "ram-lak"}"#,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("unknown variant `ram-lak`"), "{e}");
}

#[test]
fn a_job_names_the_feature_and_the_backend_it_refuses() {
    let req = jobs::d2vr::D2vrRequest {
        input: "phantom:sphere".into(),
        f16_projections: true,
        backend: Backend::Cpu,
        ..Default::default()
    };
    let e = jobs::d2vr::run(&req, &()).unwrap_err();
    assert!(matches!(e, Error::Unsupported { .. }), "{e:?}");
    let text = e.to_string();
    assert!(
        text.contains("16-bit projections") && text.contains("cpu"),
        "{text}"
    );
}

#[test]
fn progress_reaches_the_caller_and_every_row_is_counted() {
    let mut req = jobs::render::RenderRequest::default();
    req.scene.input = VolumeInput::new("phantom:sphere:24");
    (req.scene.width, req.scene.height) = (Some(20), Some(17));
    let p = Recorder::new(u64::MAX);
    jobs::render::run(&req, &p).unwrap();
    assert_eq!(p.last.load(Ordering::SeqCst), 17, "rows done");
    assert_eq!(p.advances.load(Ordering::SeqCst), 17, "one report per row");
    let stages = p.stages.lock().unwrap();
    assert_eq!(stages.len(), 1);
    assert!(
        stages[0].starts_with("rendering (cpu (f64 oracle))"),
        "{stages:?}"
    );
}

#[test]
fn a_caller_stops_a_render_and_a_reconstruction_midway() {
    // A render stopped after 5 of its 200 rows.
    let mut req = jobs::render::RenderRequest::default();
    req.scene.input = VolumeInput::new("phantom:shepp-logan-modified:48");
    (req.scene.width, req.scene.height) = (Some(64), Some(200));
    let p = Recorder::new(5);
    let e = jobs::render::run(&req, &p).unwrap_err();
    assert!(matches!(e, Error::Cancelled), "{e:?}");
    let n = p.advances.load(Ordering::SeqCst);
    assert!(
        n < 5 + 4 * rayon::current_num_threads() as u64,
        "{n} rows ran"
    );

    // An FDK reconstruction stopped after 3 voxel lines.
    let d = scratch("cancel-fdk");
    let proj = d.join("p.npy");
    let o = voxlab(&[
        "project",
        "phantom:shepp-logan:32",
        "--geometry",
        "cone",
        "--cols",
        "48",
        "--rows",
        "48",
        "--angles",
        "36",
        "--du",
        "8",
        "--out",
        s(&proj),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let req = jobs::reconstruct::ReconstructRequest {
        input: proj.clone(),
        size: Some(40),
        out: Some(d.join("r.npy")),
        ..Default::default()
    };
    let p = Recorder::new(3);
    let e = jobs::reconstruct::run(&req, &p).unwrap_err();
    assert!(matches!(e, Error::Cancelled), "{e:?}");
    assert!(!d.join("r.npy").exists(), "a stopped job writes nothing");
    // Not stopped, the same request runs to its end and writes its output.
    jobs::reconstruct::run(&req, &Recorder::new(u64::MAX)).unwrap();
    assert!(d.join("r.npy").is_file());
}

#[test]
fn non_finite_voxels_are_a_warning_or_an_error_as_asked() {
    let mut data = vec![0.5f32; 27];
    data[13] = f32::NAN;
    let vol: voxlab::AnyVolume = Volume::new([3, 3, 3], [1.0; 3], data).unwrap().into();
    let input = VolumeInput::memory("array", vol);
    let p = Recorder::new(u64::MAX);
    let v = input.load(&p).unwrap();
    assert_eq!(v.non_finite().total(), 0);
    let w = p.warnings.lock().unwrap();
    assert_eq!(w.len(), 1);
    assert!(w[0].starts_with("array: 1 NaN"), "{w:?}");
    let mut strict = input.clone();
    strict.load.non_finite = NonFinite::Error;
    assert!(matches!(
        strict.load(&()).unwrap_err(),
        Error::NonFinite {
            count: 1,
            first: 13,
            ..
        }
    ));
}

#[test]
fn auto_takes_a_backend_the_job_runs_on() {
    let e = jobs::Engine::open(Backend::Auto).unwrap();
    assert_ne!(e.backend(), Backend::Auto);
    match e.gpu() {
        Some(_) => assert_eq!(e.backend(), Backend::Gpu),
        None => {
            assert_eq!(e.backend(), Backend::Cpu);
            assert!(e.fallback_reason().is_some());
        }
    }
}

#[test]
fn an_in_memory_transfer_function_renders_as_its_file_does() {
    use voxlab::jobs::render::{build_scene, SceneRequest};
    let dir = std::env::temp_dir().join(format!("voxlab-jobs-tf-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let tf = voxlab::transfer::TransferFunction::preset("ct-bone").unwrap();
    let file = dir.join("bone.json");
    tf.save(&file).unwrap();
    let from_file = SceneRequest {
        input: voxlab::jobs::input::VolumeInput::new("phantom:sphere:8"),
        tf: file.to_str().unwrap().into(),
        ..Default::default()
    };
    let in_memory = SceneRequest {
        input: voxlab::jobs::input::VolumeInput::new("phantom:sphere:8"),
        transfer: Some(tf.clone()),
        ..Default::default()
    };
    let (a, _) = build_scene(&from_file, false, &()).unwrap();
    let (b, _) = build_scene(&in_memory, false, &()).unwrap();
    assert_eq!(a.transfer, b.transfer);
    assert_eq!(b.transfer, tf);
    // An invalid one is refused like a file's.
    let mut bad = tf;
    bad.points.clear();
    let r = build_scene(
        &SceneRequest {
            transfer: Some(bad),
            ..Default::default()
        },
        false,
        &(),
    );
    assert!(r.is_err());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// On the GPU a prepared scene keeps one render session: its frames (an orbit, a new
/// transfer function, another filter and mode) equal `Renderer::render` of the same
/// scene bit for bit, and the volume is uploaded once.
#[test]
fn prepared_gpu_frames_equal_one_shot_renders_and_upload_once() {
    use voxlab::jobs::render::{build_scene, Renderer, SceneRequest};
    use voxlab::settings::{Filter, Mode};
    if common::gpu("prepared_gpu_frames_equal_one_shot_renders_and_upload_once").is_none() {
        return;
    }
    let renderer = Renderer::new(Backend::Gpu).unwrap();
    let request = SceneRequest {
        input: VolumeInput::new("phantom:shepp-logan-modified:32"),
        width: Some(40),
        height: Some(30),
        ..Default::default()
    };
    let (mut scene, settings) = build_scene(&request, true, &()).unwrap();
    let prepared = renderer.prepare(&scene, &settings).unwrap();
    let bits = |f: &voxlab::frame::Frame| f.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    let mut tf2 = scene.transfer.clone();
    tf2.points.iter_mut().for_each(|p| p.rgba[3] *= 0.25);
    for (k, azimuth) in [30.0, 100.0, 170.0, 240.0].into_iter().enumerate() {
        let frame_request = SceneRequest {
            view: jobs::render::ViewRequest {
                azimuth,
                ..Default::default()
            },
            ..request.clone()
        };
        scene.camera = build_scene(&frame_request, true, &()).unwrap().0.camera;
        let mut s = settings.clone();
        if k == 2 {
            s.filter = Filter::CatmullRom;
            s.mode = Mode::Mip;
        }
        let tf = if k == 3 { &tf2 } else { &scene.transfer };
        let got = renderer
            .render_prepared_with(&prepared, tf, &scene.camera, &s, &|_, _| {})
            .unwrap();
        let one_shot_scene = voxlab::jobs::render::Scene {
            transfer: tf.clone(),
            ..scene.clone()
        };
        let want = renderer.render(&one_shot_scene, &s, &|_, _| {}).unwrap();
        assert_eq!(
            bits(&got.output.image),
            bits(&want.output.image),
            "frame {k}"
        );
        assert_eq!(
            bits(got.output.samples.as_ref().unwrap()),
            bits(want.output.samples.as_ref().unwrap()),
            "frame {k}"
        );
        let session = got.gpu_session.expect("a GPU frame reports its session");
        assert_eq!(session.volume_uploads, 1);
        assert_eq!(session.frames, k + 1);
        assert_eq!(prepared.gpu_stats(), Some(session));
        let timings = got.gpu_timings.unwrap();
        if k == 1 {
            // Only the camera changed.
            assert_eq!((timings.upload, timings.prepare), (0.0, 0.0), "{timings:?}");
        }
        // The one-shot render made its own session of one frame.
        assert_eq!(want.gpu_session.unwrap().frames, 1);
    }
    // `render_prepared` renders with the prepared transfer function.
    let a = renderer
        .render_prepared(&prepared, &scene.camera, &settings, &|_, _| {})
        .unwrap();
    let b = renderer.render(&scene, &settings, &|_, _| {}).unwrap();
    assert_eq!(bits(&a.output.image), bits(&b.output.image));
}

/// `voxlab render --repeat N` on the GPU uploads the volume once: the frames after the
/// first report no upload, and the session counts one.
#[test]
fn a_repeated_gpu_render_uploads_the_volume_once() {
    if common::gpu("a_repeated_gpu_render_uploads_the_volume_once").is_none() {
        return;
    }
    let mut req = jobs::render::RenderRequest::default();
    req.scene.input = VolumeInput::new("phantom:shepp-logan-modified:32");
    req.scene.width = Some(32);
    req.scene.height = Some(32);
    req.backend = Backend::Gpu;
    req.repeat = Some(4);
    let out = jobs::render::run(&req, &()).unwrap();
    let frames = out.frames.unwrap();
    let session = frames.gpu_session.unwrap();
    assert_eq!((session.volume_uploads, session.frames), (1, 4));
    assert_eq!(frames.gpu_uploads.len(), 4);
    assert!(frames.gpu_uploads[0] > 0.0, "{:?}", frames.gpu_uploads);
    assert!(
        frames.gpu_uploads[1..].iter().all(|&u| u == 0.0),
        "{:?}",
        frames.gpu_uploads
    );
    // The same image as one render.
    req.repeat = None;
    let one = jobs::render::run(&req, &()).unwrap();
    assert_eq!(one.output.image.data, out.output.image.data);
    // The command line says so.
    let d = scratch("repeat-gpu");
    let png = d.join("r.png");
    let o = voxlab(&[
        "render",
        "phantom:shepp-logan-modified:24",
        "--backend",
        "gpu",
        "--width",
        "24",
        "--height",
        "24",
        "--repeat",
        "3",
        "--out",
        s(&png),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        // 24³ f32 voxels: 55,296 bytes.
        stderr(&o).contains("the volume uploaded 1 time(s) (54.0 KiB on the device) for 3 frames"),
        "{}",
        stderr(&o)
    );
    // The frames' ray casting on the device, within each frame's wall time.
    let e = stderr(&o);
    let ms = |prefix: &str, unit: &str| -> f64 {
        let at = e.find(prefix).unwrap_or_else(|| panic!("{prefix}: {e}")) + prefix.len();
        e[at..].split(unit).next().unwrap().trim().parse().unwrap()
    };
    let kernel = ms("GPU ray casting per frame: median", "ms");
    let frame = ms("per frame: median", "s of") * 1e3;
    assert!(kernel > 0.0 && kernel <= frame, "{e}");
}
