//! `voxlab d2vr`: a phantom rendered end to end, and the refusals.

mod common;

use common::{s, scratch, stderr, voxlab};

#[test]
fn d2vr_renders_a_phantom_and_refuses_bad_options() {
    let dir = scratch("cli_d2vr");
    let out = dir.join("x.npy");
    let o = voxlab(&[
        "d2vr",
        "phantom:sphere",
        "--beam",
        "parallel",
        "--mode",
        "xray",
        "--angles",
        "32",
        "--detector",
        "32",
        "--grid",
        "32",
        "--size",
        "16",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("reconstructed"), "{}", stderr(&o));
    assert!(out.exists());
    let o = voxlab(&[
        "d2vr",
        "phantom:sphere",
        "--backend",
        "tpu",
        "--out",
        s(&dir.join("y.png")),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--backend"), "{}", stderr(&o));
    let o = voxlab(&[
        "d2vr",
        "phantom:sphere",
        "--beam",
        "fan",
        "--out",
        s(&dir.join("z.png")),
    ]);
    assert!(!o.status.success());
}
