//! `voxlab view` in a real window: under the X server of `$DISPLAY`, or a virtual one
//! (`xvfb-run`, which the test command installs), on the GPU (lavapipe in CI). The lab
//! draws a few frames, writes its screenshot and its state and exits; `voxlab render
//! --state` of that state must give the screenshot's image.

mod common;

use common::{gpu, s, scratch, stderr, voxlab_command};
use std::process::Command;
use voxlab::jobs::view::ViewState;
use voxlab::metrics::error_stats;

/// The lab's command line, under a virtual X server unless one is given.
fn view_command(test: &str, args: &[&str]) -> Option<Command> {
    gpu(test)?;
    if std::env::var_os("DISPLAY").is_some() {
        let mut c = voxlab_command(&["view"]);
        c.args(args);
        return Some(c);
    }
    let xvfb = Command::new("sh")
        .args(["-c", "command -v xvfb-run"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    assert!(
        xvfb,
        "{test}: no X server ($DISPLAY unset) and no xvfb-run; the test command installs \
         xvfb as root, or install it (apt-get install xvfb xauth)"
    );
    let mut x = Command::new("xvfb-run");
    x.args([
        "-a",
        "-s",
        "-screen 0 1400x900x24",
        env!("CARGO_BIN_EXE_voxlab"),
        "view",
    ])
    .args(args)
    .env("XDG_RUNTIME_DIR", std::env::temp_dir())
    .env_remove("VOXLAB_MAX_VOXELS");
    Some(x)
}

/// Runs the lab (`voxlab view ARGS`) for four frames with the CPU side shown, writing
/// its screenshot to `shot` (.npy) and its state to `state`, and checks it succeeded;
/// false when the test has no GPU (and skips).
fn run_lab(test: &str, args: &[&str], shot: &std::path::Path, state: &std::path::Path) -> bool {
    let tail = [
        "--frames",
        "4",
        "--compare",
        "--screenshot",
        s(shot),
        "--save-state",
        s(state),
    ];
    let Some(mut cmd) = view_command(test, &[args, &tail].concat()) else {
        return false;
    };
    let o = cmd.output().expect("the lab runs");
    assert!(o.status.success(), "voxlab view failed: {}", stderr(&o));
    true
}

fn npy(path: &std::path::Path) -> (Vec<usize>, Vec<f32>) {
    voxlab::io::npy::read_npy_f32(path).unwrap()
}

/// `voxlab render --state STATE --backend BACKEND` into `out` (.npy): its shape and
/// values.
fn render_state(
    state: &std::path::Path,
    backend: &str,
    out: &std::path::Path,
) -> (Vec<usize>, Vec<f32>) {
    let args = [
        "render",
        "--state",
        s(state),
        "--backend",
        backend,
        "--out",
        s(out),
    ];
    let o = voxlab_command(&args).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    npy(out)
}

#[test]
fn the_lab_screenshot_is_what_render_state_draws() {
    let dir = scratch("lab-window");
    let (shot, state) = (dir.join("shot.npy"), dir.join("state.json"));
    let window = dir.join("window.png");
    if !run_lab(
        "lab window",
        &[
            "phantom:shepp-logan-modified:48",
            "--width",
            "96",
            "--height",
            "80",
            "--window-screenshot",
            s(&window),
        ],
        &shot,
        &state,
    ) {
        return;
    }

    // The state is the lab's default view of the phantom at the asked size.
    let st = ViewState::load(&state).unwrap();
    assert_eq!((st.width, st.height), (96, 80));
    assert_eq!(st.input.source, "phantom:shepp-logan-modified:48");

    // The window's own picture was written, at the window's size.
    let png = image::open(&window).unwrap();
    assert!(
        png.width() >= 1000 && png.height() >= 700,
        "{}×{}",
        png.width(),
        png.height()
    );

    // `render --state` on the GPU gives the screenshot; the CPU oracle gives it within
    // the ray caster's GPU tolerance.
    let (shape, lab) = npy(&shot);
    assert_eq!(shape, vec![80, 96, 4]);
    for (backend, exact) in [("gpu", true), ("cpu", false)] {
        let (shape2, img) = render_state(&state, backend, &dir.join(format!("{backend}.npy")));
        assert_eq!(shape2, shape);
        let stats = error_stats(&img, &lab, 0.0);
        if exact {
            assert_eq!(
                stats.max_abs, 0.0,
                "GPU render of the state vs the screenshot"
            );
        } else {
            let (_, tol) = voxlab::bench::raycast::raycast_tolerances(&st.settings);
            assert!(
                tol.admits(&stats),
                "CPU oracle vs the lab's screenshot: {:?} outside {:?}",
                stats,
                tol
            );
            assert!(stats.max_abs > 0.0 || img.iter().all(|&x| x == 0.0));
        }
    }
}

/// The lab's "texture-unit filtering (GPU)" setting: started from a state with it on,
/// the lab keeps it, its GPU side draws what `render --state` draws on the GPU with
/// hardware filtering, byte for byte, and the CPU side (the oracle, which interpolates
/// exactly) is within the hardware path's tolerance of it.
#[test]
fn the_lab_filters_with_the_texture_unit_when_asked() {
    let dir = scratch("lab-window-hardware");
    let (start, state, shot) = (
        dir.join("start.json"),
        dir.join("state.json"),
        dir.join("shot.npy"),
    );
    let input = voxlab::jobs::input::VolumeInput::new("phantom:shepp-logan-modified:40");
    let volume = input.load(&()).unwrap();
    let mut st = ViewState::new(input, &volume, 72, 64).unwrap();
    st.settings.hardware_filtering = true;
    st.save(&start).unwrap();
    if !run_lab(
        "lab window, texture-unit filtering",
        &["--state", s(&start)],
        &shot,
        &state,
    ) {
        return;
    }
    let saved = ViewState::load(&state).unwrap();
    assert!(saved.settings.hardware_filtering);
    let (shape, lab) = npy(&shot);
    assert_eq!(shape, vec![64, 72, 4]);
    let render =
        |backend: &str| render_state(&state, backend, &dir.join(format!("{backend}.npy"))).1;
    assert!(
        render("gpu") == lab,
        "the GPU render of the state differs from the lab's"
    );
    // The exact path's image is another (1,403 of 18,432 values differ on lavapipe).
    let mut exact = saved.clone();
    exact.settings.hardware_filtering = false;
    let exact_state = dir.join("exact.json");
    exact.save(&exact_state).unwrap();
    let (_, exact_image) = render_state(&exact_state, "gpu", &dir.join("exact.npy"));
    assert!(exact_image != lab, "the lab's GPU side drew the exact path");
    let stats = error_stats(&render("cpu"), &lab, 0.0);
    let (_, tol) = voxlab::bench::raycast::raycast_tolerances(&saved.settings);
    assert!(
        tol.admits(&stats),
        "CPU oracle vs the lab: {stats:?} outside {tol:?}"
    );
}

#[test]
fn the_lab_refuses_bad_outputs_before_opening() {
    let dir = scratch("lab-window-bad");
    let o = voxlab_command(&[
        "view",
        "phantom:sphere:8",
        "--screenshot",
        s(&dir.join("x.gif")),
    ])
    .output()
    .unwrap();
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--screenshot"), "{}", stderr(&o));
    // No display: the error says how to run the lab without one.
    let o = voxlab_command(&["view", "phantom:sphere:8", "--backend", "cpu-f32"])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("WAYLAND_SOCKET")
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(stderr(&o).contains("xvfb-run"), "{}", stderr(&o));
    let o = voxlab_command(&["view", "--state", s(&dir.join("missing.json"))])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(stderr(&o).contains("missing.json"), "{}", stderr(&o));
}
