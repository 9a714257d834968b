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

/// The GPU tests' scene: the head from 24 views of 32², a 32³ grid, a 48² image.
const GPU_HEAD: [&str; 10] = [
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
];

/// The GPU render under a lowered binding limit binds its projections over several
/// bindings and bands its image, says so, and writes the unsplit image byte for byte;
/// `--dry-run` prints that split and writes nothing.
#[test]
fn a_split_gpu_d2vr_says_so_and_writes_the_unsplit_image() {
    if common::gpu("a_split_gpu_d2vr_says_so_and_writes_the_unsplit_image").is_none() {
        return;
    }
    let dir = scratch("cli_d2vr_split");
    let args = [&GPU_HEAD[..], &["--backend", "gpu"]].concat();
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

/// `--hardware-filtering`: the projections in texture arrays, every value filtered by
/// the texture unit. The run says so; under a lowered binding limit the arrays are cut
/// (and `--dry-run` says how) and the image is the unsplit one byte for byte; on a CPU
/// adapter (f32 filtering) the image is within a hair of the exact path's. Off the GPU
/// it is refused, writing nothing.
#[test]
fn hardware_filtering_reads_the_projections_from_textures() {
    let Some(ctx) = common::gpu("hardware_filtering_reads_the_projections_from_textures") else {
        return;
    };
    // f16 textures filter on every adapter; f32 ones need FLOAT32_FILTERABLE.
    let f32_filterable = ctx.features.contains(wgpu::Features::FLOAT32_FILTERABLE);
    let (backend, line) = if f32_filterable {
        // 34 × 34 texels of 4 bytes a bordered view: 4 views in 20 KiB, 6 arrays.
        (
            "gpu",
            "D²VR projections in 6 bindings of 4 views (one texture array each)",
        )
    } else {
        // 2 bytes a texel: 8 views in 20 KiB, 3 arrays.
        (
            "gpu-f16",
            "D²VR projections in 3 bindings of 8 views (one texture array each)",
        )
    };
    let dir = scratch("cli_d2vr_hardware");
    let exact_args = [&GPU_HEAD[..], &["--mode", "mip", "--backend", backend]].concat();
    let args = [&exact_args[..], &["--hardware-filtering"]].concat();
    let says = [
        "D²VR projections in textures, filtered by the texture unit",
        line,
        "D²VR image in 2 bands of 26 rows",
    ];
    let quiet = common::split_writes_the_unsplit_file(&dir, &args, "20KiB", &says);
    let one = "D²VR projections in 1 binding of 24 views (one texture array each)";
    assert!(quiet.contains(says[0]) && quiet.contains(one), "{quiet}");
    let never = dir.join("never.npy");
    let dry = [&args[..], &["--dry-run", "--out", s(&never)]].concat();
    let o = common::voxlab_with_binding(&dry, Some("20KiB"));
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains(&format!("split:  {line}")), "{text}");
    assert!(!never.exists());

    let exact = dir.join("exact.npy");
    let o = voxlab(&[&exact_args[..], &["--out", s(&exact)]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let (_, a, _) = voxlab::io::npy::read_npy_f64(&exact).unwrap();
    let (_, b, _) = voxlab::io::npy::read_npy_f64(&dir.join("whole.npy")).unwrap();
    let peak = a.iter().fold(0f64, |m, v| m.max(v.abs()));
    let off = a
        .iter()
        .zip(&b)
        .fold(0f64, |m, (x, y)| m.max((x - y).abs()));
    eprintln!(
        "hardware MIP on {}: {:.1e} of the peak from the exact path",
        ctx.summary.name,
        off / peak
    );
    if ctx.summary.is_cpu() {
        // As tests/gpu_d2vr.rs: hardware_sampling_is_within_the_texture_units_bound.
        assert!(peak > 0.5 && off <= 2e-5 * peak, "{off:e} of {peak:e}");
    }

    for backend in ["cpu-f32", "cpu"] {
        let out = dir.join(format!("{backend}.npy"));
        let o = voxlab(&[
            "d2vr",
            "phantom:sphere",
            "--hardware-filtering",
            "--backend",
            backend,
            "--out",
            s(&out),
        ]);
        assert!(!o.status.success());
        assert!(
            stderr(&o).contains("--hardware-filtering") && stderr(&o).contains("gpu"),
            "{}",
            stderr(&o)
        );
        assert!(!out.exists());
    }
}
