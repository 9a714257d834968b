//! `voxlab render --volume …`: multi-volume rendering from the command line, and clear
//! errors for bad volume lists and transforms.

mod common;

use common::{s, scratch, stderr, voxlab};
use voxlab::io::npy::read_npy_f32;

const PHANTOM: &str = "phantom:shepp-logan-modified:24";
const SIZE: [&str; 4] = ["--width", "20", "--height", "16"];

fn render(extra: &[&str], out: &std::path::Path) -> std::process::Output {
    let mut args = vec!["render", PHANTOM, "--out", s(out)];
    args.extend_from_slice(&SIZE);
    args.extend_from_slice(extra);
    voxlab(&args)
}

/// X-ray of INPUT with a coincident copy is twice INPUT alone (the line integrals add);
/// a shifted, rotated copy with its own transfer function renders DVR on both CPU
/// backends.
#[test]
fn extra_volumes_render_on_the_cpu_backends() {
    let d = scratch("cli_multi_render");
    let one = d.join("one.npy");
    let two = d.join("two.npy");
    let o = render(&["--mode", "xray"], &one);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = render(&["--mode", "xray", "--volume", PHANTOM], &two);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("2 volumes"), "{}", stderr(&o));
    let (shape, a) = read_npy_f32(&one).unwrap();
    let (_, b) = read_npy_f32(&two).unwrap();
    assert_eq!(shape, vec![16, 20]);
    assert!(a.iter().any(|&x| x > 10.0));
    for (x, y) in a.iter().zip(&b) {
        // f32 files of f64 renders: relative rounding 6e-8.
        assert!((2.0 * x - y).abs() <= 1e-6 * y.abs().max(1.0), "{x} {y}");
    }
    for backend in ["cpu", "cpu-f32"] {
        let png = d.join(format!("dvr-{backend}.png"));
        let o = render(
            &[
                "--volume",
                PHANTOM,
                "--transform",
                "0,-1,0,60,1,0,0,-20,0,0,1,0",
                "--volume-tf",
                "grayscale",
                "--backend",
                backend,
            ],
            &png,
        );
        assert!(o.status.success(), "{backend}: {}", stderr(&o));
        assert!(png.is_file());
    }
}

#[test]
fn bad_volume_lists_and_transforms_are_refused_clearly() {
    let d = scratch("cli_multi_errors");
    let out = d.join("x.png");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "--volume", PHANTOM, "--volume", PHANTOM, "--volume", PHANTOM,
            ],
            "at most 2 extra volumes",
        ),
        (
            vec!["--volume", PHANTOM, "--transform", "1,0,0,0,0,1,0,0,0,0,1"],
            "11 values",
        ),
        (
            vec![
                "--volume",
                PHANTOM,
                "--transform",
                "1,0,0,0,0,1,0,0,0,0,0,0",
            ],
            "singular",
        ),
        (
            vec![
                "--volume",
                PHANTOM,
                "--transform",
                "1,0,0,NaN,0,1,0,0,0,0,1,0",
            ],
            "not finite",
        ),
        (
            vec!["--transform", "1,0,0,0,0,1,0,0,0,0,1,0"],
            "at least one --volume",
        ),
        (
            vec![
                "--volume",
                PHANTOM,
                "--volume-tf",
                "grayscale",
                "--volume-tf",
                "grayscale",
            ],
            "at most one per --volume",
        ),
        (vec!["--volume", PHANTOM, "--mode", "mida"], "not supported"),
    ];
    for (args, words) in cases {
        let o = render(&args, &out);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(
            stderr(&o).contains(words),
            "{args:?}: '{words}' not in {}",
            stderr(&o)
        );
    }
}

/// `--backend gpu` renders the same scene as the f64 oracle, within the parity bound of
/// tests/gpu_multi.rs (DVR max |Δ| 5e-3; measured here on lavapipe: 6.4e-5).
#[test]
fn extra_volumes_render_on_the_gpu_backend() {
    if common::gpu("extra_volumes_render_on_the_gpu_backend").is_none() {
        return;
    }
    let d = scratch("cli_multi_gpu");
    let mut images = Vec::new();
    for backend in ["cpu", "gpu"] {
        let npy = d.join(format!("dvr-{backend}.npy"));
        let o = render(
            &[
                "--volume",
                PHANTOM,
                "--transform",
                "0,-1,0,60,1,0,0,-20,0,0,1,0",
                "--volume-tf",
                "grayscale",
                "--backend",
                backend,
            ],
            &npy,
        );
        assert!(o.status.success(), "{backend}: {}", stderr(&o));
        assert!(stderr(&o).contains("2 volumes"), "{}", stderr(&o));
        images.push(read_npy_f32(&npy).unwrap());
    }
    assert_eq!(images[0].0, images[1].0, "shapes");
    let worst = voxlab::metrics::max_abs_error(&images[0].1, &images[1].1);
    assert!(images[0].1.iter().any(|&x| x > 0.1), "an empty image");
    eprintln!("cli gpu vs cpu: max |Δ| {worst:.2e}");
    assert!(worst <= 5e-3, "max |Δ| {worst:.2e}");
}

/// Past the 3-D texture limit (`VOXLAB_GPU_MAX_TEXTURE_3D`) `render --volume …
/// --backend gpu` renders in cells, says so, and writes the unsplit file byte for byte
/// (DVR, shaded by default, and X-ray); the dry run prints the split and writes nothing; a limit no
/// cell fits is refused alike by the run and the dry run, naming the limit, writing
/// nothing.
#[test]
fn extra_volumes_past_the_texture_limit_render_in_cells() {
    if common::gpu("extra_volumes_past_the_texture_limit_render_in_cells").is_none() {
        return;
    }
    let d = scratch("cli_multi_cells");
    let run = |extra: &[&str], out: &std::path::Path, limit: &str| {
        let mut args = vec!["render", PHANTOM, "--out", s(out), "--backend", "gpu"];
        args.extend_from_slice(&SIZE);
        args.extend_from_slice(&[
            "--volume",
            PHANTOM,
            "--transform",
            "0,-1,0,60,1,0,0,-20,0,0,1,0",
        ]);
        args.extend_from_slice(extra);
        let mut c = common::voxlab_command(&args);
        if !limit.is_empty() {
            c.env("VOXLAB_GPU_MAX_TEXTURE_3D", limit);
        }
        c.output().unwrap()
    };
    let cells = "cells (volume 0, [24, 24, 24], exceeds the 3-D texture limit of 16 texels \
                 per axis; the largest cell holds";
    for extra in [&[][..], &["--mode", "xray"]] {
        let (whole, split) = (d.join("whole.npy"), d.join("split.npy"));
        let a = run(extra, &whole, "");
        let b = run(extra, &split, "16");
        assert!(a.status.success(), "{extra:?}: {}", stderr(&a));
        assert!(b.status.success(), "{extra:?}: {}", stderr(&b));
        assert!(stderr(&b).contains(cells), "{extra:?}: {}", stderr(&b));
        assert!(!stderr(&a).contains("ray casting in"), "{}", stderr(&a));
        assert_eq!(
            std::fs::read(&whole).unwrap(),
            std::fs::read(&split).unwrap(),
            "{extra:?}: the split file differs from the unsplit one"
        );
    }
    let never = d.join("never.npy");
    let dry = run(&["--dry-run"], &never, "16");
    assert!(dry.status.success(), "{}", stderr(&dry));
    let plan = String::from_utf8_lossy(&dry.stdout);
    assert!(
        plan.contains("split:  multi-volume ray casting in ") && plan.contains(cells),
        "{plan}"
    );
    let mut said = Vec::new();
    for extra in [&[][..], &["--dry-run"]] {
        let o = run(extra, &never, "2");
        assert_eq!(o.status.code(), Some(1), "{extra:?}: {}", stderr(&o));
        said.push(stderr(&o));
    }
    assert!(
        said[0].contains(
            "scene is too large: the multi-volume scene cannot be cut into cells whose parts \
             of the volumes fit 2 texels per axis"
        ),
        "{}",
        said[0]
    );
    assert_eq!(said[0], said[1]);
    assert!(!never.exists(), "wrote");
}
