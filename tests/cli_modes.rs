//! `voxlab render` with the modes of `cpu::modes`: MIDA, windowed MIP, iso-surfaces,
//! and clear errors for bad values (no output left behind).

mod common;

use common::{s, scratch, stderr, voxlab};
use std::path::Path;
use voxlab::cpu::modes::{window_map, window_preset};

const SCENE: [&str; 6] = [
    "phantom:shepp-logan-modified:24",
    "--width",
    "32",
    "--height",
    "24",
    "--backend",
];

/// Renders with `args` after the common scene (CPU oracle) into `out` (.npy).
fn render(out: &Path, args: &[&str]) -> (Vec<usize>, Vec<f32>) {
    let mut all = vec!["render"];
    all.extend(SCENE);
    all.extend(["cpu", "--out", s(out)]);
    all.extend(args);
    let o = voxlab(&all);
    assert!(o.status.success(), "{:?}: {}", args, stderr(&o));
    voxlab::io::npy::read_npy_f32(out).unwrap()
}

#[test]
fn windowed_mip_from_the_command_line() {
    let d = scratch("cli-modes-window");
    let (shape, plain) = render(&d.join("mip.npy"), &["--mode", "mip"]);
    assert_eq!(shape, vec![24, 32]);
    let (_, pair) = render(&d.join("wc.npy"), &["--mode", "mip", "--window", "0.4,0.3"]);
    let (_, level) = render(
        &d.join("wl.npy"),
        &["--mode", "mip", "--window", "0.4", "--level", "0.3"],
    );
    assert_eq!(pair, level);
    // Rays that miss keep the miss value 0, which this window maps to 0 as well.
    for (w, p) in pair.iter().zip(&plain) {
        let e = window_map(*p as f64, [0.4, 0.3]);
        assert!((*w as f64 - e).abs() < 1e-6, "{w} vs {e}");
    }
    // An axis view: every ray hits (a miss keeps the raw miss value 0, unwindowed).
    let (_, bone) = render(
        &d.join("bone.npy"),
        &["--mode", "minip", "--view", "+z", "--window-preset", "bone"],
    );
    let (_, minip) = render(&d.join("minip.npy"), &["--mode", "minip", "--view", "+z"]);
    for (b, p) in bone.iter().zip(&minip) {
        let e = window_map(*p as f64, window_preset("bone").unwrap());
        assert!((*b as f64 - e).abs() < 1e-6, "{b} vs {e}");
    }
}

#[test]
fn mida_at_gamma_minus_one_is_dvr_from_the_command_line() {
    let d = scratch("cli-modes-mida");
    let (shape, dvr) = render(&d.join("dvr.npy"), &["--ert", "1"]);
    assert_eq!(shape, vec![24, 32, 4]);
    let (_, mida) = render(
        &d.join("mida.npy"),
        &["--mode", "mida", "--mida-gamma", "-1", "--ert", "1"],
    );
    assert_eq!(dvr, mida);
    let (_, half) = render(
        &d.join("half.npy"),
        &["--mode", "mida", "--mida-gamma", "0.5"],
    );
    assert_ne!(half, mida);
}

#[test]
fn iso_surfaces_from_the_command_line() {
    let d = scratch("cli-modes-iso");
    let (shape, img) = render(
        &d.join("iso.npy"),
        &[
            "--mode",
            "iso",
            "--iso",
            "0.15:#ff0000:0.3",
            "--iso",
            "0.5:#00ff80:1",
        ],
    );
    assert_eq!(shape, vec![24, 32, 4]);
    // The red surface shows somewhere, and the opaque green one too.
    assert!(img.chunks(4).any(|p| p[0] > 0.1));
    assert!(img.chunks(4).any(|p| p[1] > 0.1));
    let png = d.join("shadows.png");
    let mut args = vec!["render"];
    args.extend(SCENE);
    args.extend([
        "cpu",
        "--out",
        s(&png),
        "--iso",
        "0.25:#ccbb99:1",
        "--iso-opaque",
        "--shadows",
        "--light",
        "1,-1,0.5",
    ]);
    let o = voxlab(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(png.is_file());
}

#[test]
fn bad_mode_values_are_refused_clearly() {
    let d = scratch("cli-modes-errors");
    let out = d.join("never.png");
    let cases: [(&[&str], &str); 8] = [
        (&["--mode", "mida", "--mida-gamma", "1.5"], "[-1, 1]"),
        (&["--mode", "mida", "--mida-gamma", "-2"], "[-1, 1]"),
        (&["--iso", "0.3:#gg0000:0.4"], "#rrggbb"),
        (&["--iso", "0.3:red"], "VALUE:COLOUR:OPACITY"),
        (&["--iso", "0.3:#ff0000:1.5"], "opacity"),
        (&["--mode", "mip", "--window-preset", "elbow"], "bone"),
        (
            &["--mode", "iso", "--iso", "0.3:#ff0000:1", "--shadows"],
            "opaque",
        ),
        (&["--mode", "mip", "--window", "0.4"], "centre"),
    ];
    for (extra, words) in cases {
        let mut args = vec!["render"];
        args.extend(SCENE);
        args.extend(["cpu", "--out", s(&out)]);
        args.extend(extra);
        let o = voxlab(&args);
        let e = stderr(&o);
        assert!(!o.status.success(), "{extra:?} succeeded");
        assert!(e.contains(words), "{extra:?}: {e}");
        assert!(!out.exists());
    }
}
