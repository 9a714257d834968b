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

/// The GPU render under a lowered binding limit binds its projections over several
/// bindings and bands its image, says so, and writes the unsplit image byte for byte;
/// `--dry-run` prints that split and writes nothing.
#[test]
fn a_split_gpu_d2vr_says_so_and_writes_the_unsplit_image() {
    if common::gpu("a_split_gpu_d2vr_says_so_and_writes_the_unsplit_image").is_none() {
        return;
    }
    let dir = scratch("cli_d2vr_split");
    let args = [
        "d2vr",
        "phantom:shepp-logan-modified",
        "--angles",
        "24",
        "--detector",
        "32",
        "--grid",
        "32",
        "--size",
        "48",
        "--backend",
        "gpu",
    ];
    let run = |out: &std::path::Path, binding: Option<&str>, extra: &[&str]| {
        let all = [&args[..], &["--out", s(out)], extra].concat();
        common::voxlab_with_binding(&all, binding)
    };
    // 32 × 32 values of 4 bytes: 4 KiB a view, so 5 views in 20 KiB (5 bindings for
    // 24 views); image rows of 48 pixels, 768 bytes: 26 rows a band.
    let says = [
        "D²VR projections in 5 bindings of 5 views (one storage binding each)",
        "D²VR image in 2 bands of 26 rows",
    ];
    let quiet = common::split_writes_the_unsplit_file(&dir, &args, "20KiB", &says);
    assert!(!quiet.contains("bindings"), "{quiet}");
    let never = dir.join("never.npy");
    let o = run(&never, Some("20KiB"), &["--dry-run"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    for want in [
        "dry run: d2vr dvr on gpu",
        "split:  D²VR projections in 5 bindings of 5 views",
        "split:  D²VR image in 2 bands of 26 rows",
        "storage binding lowered to 20480 bytes by VOXLAB_GPU_MAX_BINDING",
    ] {
        assert!(text.contains(want), "no '{want}' in:\n{text}");
    }
    assert!(!never.exists());
    // Past what even a split can bind: 2 views a binding would need 12 bindings.
    let o = run(&never, Some("8KiB"), &[]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("12 storage bindings"), "{}", stderr(&o));
    assert!(!never.exists());
}
