//! `voxlab render` with empty-space skipping, clipping and jittered sampling: skipping
//! does not change the image but lowers the sample count, a clip box removes what lies
//! outside it, accumulation averages frames, and bad values are refused clearly.

mod common;

use common::{s, scratch, stderr, voxlab};

fn render(dir: &std::path::Path, name: &str, extra: &[&str]) -> (Vec<f32>, Vec<f32>) {
    let (px, n, _) = render_logged(dir, name, extra);
    (px, n)
}

/// [`render`], also returning what the command printed.
fn render_logged(
    dir: &std::path::Path,
    name: &str,
    extra: &[&str],
) -> (Vec<f32>, Vec<f32>, String) {
    let img = dir.join(format!("{name}.npy"));
    let samples = dir.join(format!("{name}-samples.npy"));
    let mut args = vec![
        "render",
        "phantom:shepp-logan-modified:40",
        "--tf",
        "phantom",
        "--width",
        "48",
        "--height",
        "36",
        "--out",
        s(&img),
        "--samples",
        s(&samples),
    ];
    args.extend_from_slice(extra);
    let o = voxlab(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let (_, px) = voxlab::io::npy::read_npy_f32(&img).unwrap();
    let (_, n) = voxlab::io::npy::read_npy_f32(&samples).unwrap();
    (px, n, stderr(&o))
}

#[test]
fn skipping_keeps_the_image_and_saves_samples() {
    let d = scratch("cli-skip");
    let (on, n_on) = render(&d, "on", &["--block-size", "8"]);
    let (off, n_off) = render(&d, "off", &["--skip-empty", "off"]);
    assert_eq!(on, off, "skipping changed the image");
    let (a, b): (f32, f32) = (n_on.iter().sum(), n_off.iter().sum());
    eprintln!("samples: {a} with skipping, {b} without");
    assert!(a < b, "skipping must take fewer samples");
}

#[test]
fn clip_box_and_accumulation() {
    let d = scratch("cli-clip");
    let (full, _) = render(&d, "full", &[]);
    // A box around nothing but air in one corner: an empty image (background only).
    let (clipped, n) = render(&d, "corner", &["--clip-box", "0,0,0,2,2,2"]);
    assert!(n.iter().sum::<f32>() < 100.0 * 48.0);
    assert!(
        clipped.chunks(4).all(|p| p[0] < 1e-6),
        "nothing visible in the corner box"
    );
    assert!(full.chunks(4).any(|p| p[0] > 0.05));
    // World-space box with negative corners parses.
    let (_, _) = render(
        &d,
        "world",
        &[
            "--clip-box",
            "-60,-60,-60,60,60,60",
            "--clip-space",
            "world",
        ],
    );
    // Two accumulated frames differ from one unjittered frame, but only slightly.
    let (acc, _) = render(&d, "acc", &["--jitter", "5", "--accumulate", "2"]);
    let diff = voxlab::metrics::max_abs_error(&acc, &full);
    assert!(diff > 0.0 && diff < 0.5, "{diff}");
    let (inter, _) = render(&d, "inter", &["--interleaved"]);
    assert_ne!(inter, full);
}

#[test]
fn bad_acceleration_flags_are_refused() {
    let d = scratch("cli-skip-bad");
    let out = d.join("x.png");
    for (args, words) in [
        (vec!["--block-size", "0"], "block size"),
        (vec!["--clip-box", "5,0,0,1,2,2"], "clip box"),
        (vec!["--accumulate", "0"], "accumulate"),
        (vec!["--accumulate", "2", "--interleaved"], "interleaved"),
    ] {
        let mut a = vec!["render", "phantom:sphere:8", "--out", s(&out)];
        a.extend_from_slice(&args);
        let o = voxlab(&a);
        assert!(!o.status.success(), "{args:?} must fail");
        assert!(stderr(&o).contains(words), "{args:?}: {}", stderr(&o));
        assert!(!out.exists());
    }
    let o = voxlab(&[
        "render",
        "phantom:sphere:8",
        "--out",
        s(&out),
        "--jitter",
        "1",
        "--interleaved",
    ]);
    assert!(!o.status.success());
}

/// `--repeat N` renders the frame N times from one prepared volume: the image and
/// sample counts are a single render's, the per-frame median is reported, and it
/// refuses what it cannot time.
#[test]
fn repeat_times_frames_of_the_same_image() {
    let d = scratch("cli-repeat");
    for backend in ["cpu-f32", "cpu"] {
        let (one, n_one) = render(&d, "one", &["--backend", backend, "--no-shading"]);
        let (rep, n_rep, err) = render_logged(
            &d,
            "rep",
            &["--backend", backend, "--no-shading", "--repeat", "3"],
        );
        assert!(err.contains("per frame: median"), "{err}");
        assert!(err.contains("of 3 frames"), "{err}");
        assert_eq!(one, rep, "{backend}: --repeat changed the image");
        assert_eq!(
            n_one, n_rep,
            "{backend}: --repeat changed the sample counts"
        );
    }
    for (extra, words) in [
        (vec!["--repeat", "2", "--accumulate", "2"], "--accumulate"),
        (vec!["--repeat", "0"], "repeat"),
        (vec!["--repeat", "2", "--stereo", "anaglyph"], "--stereo"),
    ] {
        let never = d.join("never.png");
        let mut args = vec![
            "render",
            "phantom:shepp-logan-modified:24",
            "--out",
            s(&never),
        ];
        args.extend_from_slice(&extra);
        let o = voxlab(&args);
        assert!(!o.status.success(), "{extra:?} was accepted");
        assert!(stderr(&o).contains(words), "{extra:?}: {}", stderr(&o));
        assert!(!never.exists(), "{extra:?} left an output behind");
    }
}
