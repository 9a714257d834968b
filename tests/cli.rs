//! The `voxlab` command line as a user meets it: the demo, rendering files and
//! phantoms, and clear errors (with no output left behind) for bad input.

mod common;

use common::{s, scratch, stderr, voxlab};
use std::process::Command;

#[test]
fn demo_writes_the_gallery() {
    let d = scratch("demo");
    let o = voxlab(&["demo", "--out", s(&d)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let pngs: Vec<_> = std::fs::read_dir(&d)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.path().extension().is_some_and(|x| x == "png"))
        .collect();
    assert_eq!(pngs.len(), 11);
    assert!(d.join("microct-bone-dvr.png").is_file() && d.join("mr-brain-dvr.png").is_file());
    assert!(d.join("index.html").is_file() && d.join("README.md").is_file());
    // Every picture decodes and is not blank.
    for p in pngs {
        let img = image::open(p.path()).unwrap().to_rgba8();
        assert!(
            img.pixels().any(|px| px.0[0] > 40),
            "{:?} is blank",
            p.path()
        );
    }
}

/// Render an X-ray along +z of a phantom written to NRRD, as .npy, and compare with the
/// sum over z of the same NRRD's voxels times the z spacing.
#[test]
fn render_xray_of_a_file_equals_the_array_sum() {
    let d = scratch("xray");
    let vol = d.join("ellipsoid.nrrd");
    let o = voxlab(&["phantom", "ellipsoid:20,16,12", "--out", s(&vol)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let img = d.join("xray.npy");
    let o = voxlab(&[
        "render",
        s(&vol),
        "--mode",
        "xray",
        "--view",
        "+z",
        "--step",
        "1",
        "--out",
        s(&img),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v = voxlab::io::read_volume(&vol).unwrap().to_f32();
    let (shape, px) = voxlab::io::npy::read_npy_f32(&img).unwrap();
    assert_eq!(shape, vec![16, 20]);
    let dz = v.spacing()[2];
    for j in 0..16 {
        for i in 0..20 {
            let want: f64 = (0..12).map(|k| *v.get(i, j, k) as f64).sum::<f64>() * dz;
            let got = px[j * 20 + i] as f64;
            assert!(
                (got - want).abs() <= 1e-5 * want.abs().max(1.0),
                "({i},{j}) {got} vs {want}"
            );
        }
    }
    assert!(px.iter().any(|&x| x > 10.0));
}

/// NumPy, an independent implementation, agrees: MIP along −y of an .npy volume equals
/// `np.load(v).max(axis=1)`. Skipped (with a message) where NumPy is not installed.
#[test]
fn mip_agrees_with_numpy() {
    let have_numpy = Command::new("python3")
        .args(["-c", "import numpy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !have_numpy {
        eprintln!("SKIPPED mip_agrees_with_numpy: python3 with numpy not found");
        return;
    }
    let d = scratch("numpy");
    let vol = d.join("spheres.npy");
    assert!(voxlab(&["phantom", "spheres:24,20,16", "--out", s(&vol)])
        .status
        .success());
    let img = d.join("mip.npy");
    let o = voxlab(&[
        "render",
        s(&vol),
        "--mode",
        "mip",
        "--view",
        "-y",
        "--filter",
        "nearest",
        "--step",
        "1",
        "--out",
        s(&img),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let script = format!(
        "import numpy as np, sys\nv = np.load('{}')\nm = np.load('{}')\nr = v.max(axis=1)\n\
         assert m.shape == r.shape, (m.shape, r.shape)\nprint(float(np.abs(m - r).max()))",
        s(&vol),
        s(&img)
    );
    let o = Command::new("python3")
        .args(["-c", &script])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let diff: f64 = String::from_utf8_lossy(&o.stdout).trim().parse().unwrap();
    assert_eq!(diff, 0.0);
}

#[test]
fn dvr_png_and_samples_image() {
    let d = scratch("dvr");
    let out = d.join("dvr.png");
    let samples = d.join("samples.npy");
    let o = voxlab(&[
        "render",
        "phantom:shepp-logan-modified:48",
        "--width",
        "40",
        "--height",
        "30",
        "--backend",
        "cpu-f32",
        "--sixteen-bit",
        "--samples",
        s(&samples),
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let img = image::open(&out).unwrap();
    assert_eq!((img.width(), img.height()), (40, 30));
    assert!(matches!(img, image::DynamicImage::ImageRgba16(_)));
    let (shape, counts) = voxlab::io::npy::read_npy_f32(&samples).unwrap();
    assert_eq!(shape, vec![30, 40]);
    assert!(counts.iter().any(|&c| c > 10.0));
}

/// Bad input: a clear message on stderr, exit status 1, and no output file.
#[test]
fn bad_input_gets_a_clear_error_and_no_output() {
    let d = scratch("bad");
    let out = d.join("out.png");
    let truncated = d.join("truncated.nrrd");
    std::fs::write(&truncated, b"NRRD0004\ntype: float\ndimension: 3\nsizes: 4 4 4\nencoding: raw\nendian: little\n\n\x00\x00").unwrap();
    let nan = d.join("nan.npy");
    voxlab::io::npy::write_npy_f32(
        &nan,
        &[2, 2, 2],
        &[0.0, 1.0, f32::NAN, 0.5, 0.0, 0.0, 0.0, 0.0],
    )
    .unwrap();
    let (bmp, missing) = (d.join("out.bmp"), d.join("missing/out.png"));
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["render", "no/such/file.nrrd", "--out", s(&out)],
            "no/such/file.nrrd",
        ),
        (
            vec!["render", s(&truncated), "--out", s(&out)],
            "truncated.nrrd",
        ),
        // NaN voxels are replaced by default (tests/cli_io.rs checks the values);
        // --non-finite error refuses them.
        (
            vec!["render", s(&nan), "--non-finite", "error", "--out", s(&out)],
            "non-finite",
        ),
        (
            vec!["render", "phantom:nope:8", "--out", s(&out)],
            "not one of",
        ),
        (
            vec!["render", "phantom:sphere:0", "--out", s(&out)],
            "empty axis",
        ),
        (
            vec![
                "render",
                "phantom:sphere:8",
                "--step",
                "0",
                "--out",
                s(&out),
            ],
            "step",
        ),
        (
            vec![
                "render",
                "phantom:sphere:8",
                "--view",
                "+w",
                "--out",
                s(&out),
            ],
            "+w",
        ),
        (
            vec![
                "render",
                "phantom:sphere:8",
                "--tf",
                "no-such-tf.json",
                "--out",
                s(&out),
            ],
            "no-such-tf.json",
        ),
        (
            vec!["render", "phantom:sphere:8", "--out", s(&bmp)],
            ".png or .npy",
        ),
        (
            vec!["render", "phantom:sphere:8", "--out", s(&missing)],
            "does not exist",
        ),
        (
            vec![
                "render",
                "phantom:sphere:8",
                "--window",
                "0",
                "--level",
                "1",
                "--out",
                s(&out),
            ],
            "window",
        ),
        (
            vec![
                "render",
                "phantom:sphere:8",
                "--width",
                "0",
                "--out",
                s(&out),
            ],
            "image size",
        ),
        (
            vec![
                "render",
                "phantom:sphere:16",
                "--filter",
                "sinc",
                "--width",
                "512",
                "--height",
                "512",
                "--step",
                "0.01",
                "--out",
                s(&out),
            ],
            "too large",
        ),
    ];
    for (args, needle) in cases {
        let o = voxlab(&args);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?} should fail: {err}");
        assert!(
            err.contains("voxlab: error:") && err.contains(needle),
            "{args:?}: '{err}' lacks '{needle}'"
        );
        assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
        assert!(!out.exists(), "{args:?} left an output file");
    }
    // Nothing half-written is left in the folder (no temporary files either).
    let left: Vec<_> = std::fs::read_dir(&d)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name())
        .collect();
    assert_eq!(left.len(), 2, "{left:?}");
}

#[test]
fn info_and_tf_listing() {
    let o = voxlab(&["info", "phantom:shepp-logan-modified:32", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["dims"], serde_json::json!([32, 32, 32]));
    assert_eq!(j["spacing_mm"][0], serde_json::json!(8.0));
    assert_eq!(j["range"]["max"], serde_json::json!(1.0));
    let o = voxlab(&["tf"]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("ct-bone"));
    let o = voxlab(&["tf", "ct-bone"]);
    assert!(
        voxlab::transfer::TransferFunction::from_json(&String::from_utf8_lossy(&o.stdout)).is_ok()
    );
}

/// `voxlab compare` on a file: images, stats, timings, and exit status 3 over tolerance.
#[test]
fn compare_writes_evidence_and_enforces_tolerances() {
    if common::gpu("compare_writes_evidence_and_enforces_tolerances").is_none() {
        return;
    }
    let d = scratch("compare");
    let vol = d.join("head.nrrd");
    assert!(
        voxlab(&["phantom", "shepp-logan-modified:32", "--out", s(&vol)])
            .status
            .success()
    );
    let out_dir = d.join("cmp");
    let common_args = ["--width", "48", "--height", "40", "--out-dir", s(&out_dir)];
    let mut args = vec![
        "compare",
        s(&vol),
        "--tf",
        "phantom",
        "--max-abs",
        "1e-3",
        "--rmse",
        "5e-5",
    ];
    args.extend(common_args);
    let o = voxlab(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("max |Δ|") && stdout.contains("kernel"),
        "{stdout}"
    );
    for f in ["cpu.png", "gpu.png", "diff.png", "stats.json"] {
        assert!(out_dir.join(f).is_file(), "{f}");
    }
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("stats.json")).unwrap())
            .unwrap();
    assert_eq!(stats["passed"], serde_json::json!(true));
    assert!(stats["stats"]["max_abs"].as_f64().unwrap() < 1e-3);
    assert!(stats["gpu_seconds"]["kernel"].as_f64().unwrap() > 0.0);
    // An impossible tolerance: exit status 3 and a message naming the worst element.
    let mut args = vec!["compare", s(&vol), "--tf", "phantom", "--max-abs", "1e-12"];
    args.extend(common_args);
    let o = voxlab(&args);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    assert!(stderr(&o).contains("tolerance exceeded"));
}

/// `--backend gpu` renders the same MIP as the oracle along an axis view.
#[test]
fn render_backend_gpu_matches_the_array() {
    if common::gpu("render_backend_gpu_matches_the_array").is_none() {
        return;
    }
    let d = scratch("gpu-render");
    let vol = d.join("spheres.npy");
    assert!(voxlab(&["phantom", "spheres:24,20,16", "--out", s(&vol)])
        .status
        .success());
    let img = d.join("mip.npy");
    let o = voxlab(&[
        "render",
        s(&vol),
        "--backend",
        "gpu",
        "--mode",
        "mip",
        "--view",
        "+z",
        "--filter",
        "nearest",
        "--step",
        "1",
        "--out",
        s(&img),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("on gpu"), "{}", stderr(&o));
    let v = voxlab::io::read_volume(&vol).unwrap().to_f32();
    let (_, px) = voxlab::io::npy::read_npy_f32(&img).unwrap();
    for j in 0..20 {
        for i in 0..24 {
            let want = (0..16).map(|k| *v.get(i, j, k)).fold(f32::MIN, f32::max);
            assert_eq!(px[j * 24 + i], want, "({i},{j})");
        }
    }
}

/// `--dry-run` refuses what the run refuses, with the same message and before any
/// work, writing nothing: options checked only deep inside a run (a GPU's median
/// window, a Dirichlet slice's work, a filter the GPU ray caster lacks) used to pass the
/// dry run.
#[test]
fn every_dry_run_refuses_what_its_run_refuses() {
    let dir = scratch("cli_dry_run_refusals");
    let out = dir.join("never.npy");
    let vol = dir.join("never.nrrd");
    let (sino, geometry) = (
        common::ct_data("rtk_joseph32.npy"),
        common::ct_data("rtk_geometry.json"),
    );
    // A volume of 2 mm rows and 1 mm columns and slices (FVR needs isotropic voxels).
    let aniso = dir.join("aniso.nrrd");
    let mut nrrd = b"NRRD0004\ntype: float\ndimension: 3\nsizes: 8 8 8\nspace dimension: 3\n\
space directions: (1,0,0) (0,2,0) (0,0,1)\nendian: little\nencoding: raw\n\n"
        .to_vec();
    nrrd.extend((0..512).flat_map(|i| (i as f32).to_le_bytes()));
    std::fs::write(&aniso, nrrd).unwrap();
    let recon = [
        "reconstruct",
        s(&sino),
        "--geometry",
        s(&geometry),
        "--size",
        "16",
        "--out",
        s(&out),
    ];
    // 32³ voxels (a diagonal of 55.4) at 1e-4 voxel through 2048² rays: 2.3e12 samples.
    let tiny_step = [
        "render",
        "phantom:sphere:32",
        "--step",
        "1e-4",
        "--width",
        "2048",
        "--height",
        "2048",
        "--out",
        s(&out),
    ];
    let median = [
        "process",
        "phantom:sphere:8",
        "--op",
        "median",
        "--out",
        s(&vol),
    ];
    let multi = [
        "render",
        "phantom:sphere:8",
        "--volume",
        "phantom:sphere:8",
        "--out",
        s(&out),
    ];
    // 64³ (a diagonal of 110.9) at adaptive's least step, 1e-3 voxel, through 4096²
    // rays: 1.9e12 samples.
    let adaptive_tiny_step = [
        "adaptive",
        "phantom:sphere:64",
        "--step",
        "1e-3",
        "--size",
        "4096",
        "--out",
        s(&out),
    ];
    let mut cases: Vec<(Vec<&str>, &str)> = vec![
        (
            [&recon[..], &["--method", "sirt", "--iterations", "0"]].concat(),
            "invalid --iterations: 0",
        ),
        (
            vec![
                "process",
                "phantom:sphere:8",
                "--op",
                "gaussian",
                "--sigma",
                "0",
                "--out",
                s(&vol),
            ],
            "invalid Gaussian sigma",
        ),
        (
            [&median[..], &["--size", "4"]].concat(),
            "invalid median window size: 4",
        ),
        (
            vec![
                "fvr",
                "phantom:sphere:128",
                "--kernel",
                "dirichlet",
                "--backend",
                "cpu",
                "--out",
                s(&out),
            ],
            "Dirichlet slice is too large",
        ),
        (
            vec!["fvr", s(&aniso), "--backend", "cpu", "--out", s(&out)],
            "only isotropic, unsheared voxels",
        ),
        (
            vec!["d2vr", "phantom:sphere", "--size", "0", "--out", s(&out)],
            "invalid image size: 0×0",
        ),
        (
            vec![
                "d2vr",
                "phantom:sphere",
                "--tf",
                "no-such-preset",
                "--out",
                s(&out),
            ],
            "no-such-preset",
        ),
        (
            [&tiny_step[..], &["--backend", "cpu"]].concat(),
            "render is too large: step 0.0001 gives up to 2.3e12 samples per frame \
             (554256 per ray, 4194304 rays; at most 1e12)",
        ),
        (
            [
                &tiny_step[..],
                &["--volume", "phantom:sphere:8", "--backend", "cpu"],
            ]
            .concat(),
            "multi-volume render is too large: step 0.0001 gives up to",
        ),
        (
            vec![
                "d2vr",
                "phantom:sphere",
                "--step",
                "1e-4",
                "--size",
                "1024",
                "--out",
                s(&out),
            ],
            "D²VR is too large: step 0.0001 gives up to",
        ),
        (
            vec![
                "render",
                "phantom:sphere:8",
                "--sampling",
                "adaptive",
                "--mode",
                "mip",
                "--out",
                s(&out),
            ],
            "the adaptive caster renders DVR only",
        ),
        (
            [&multi[..], &["--filter", "sinc", "--backend", "cpu"]].concat(),
            "the full sinc filter is not supported with several volumes",
        ),
        (
            [
                &multi[..],
                &[
                    "--volume",
                    "phantom:sphere:8",
                    "--volume",
                    "phantom:sphere:8",
                ],
            ]
            .concat(),
            "3 given: at most 2 extra volumes",
        ),
        (
            [&adaptive_tiny_step[..], &["--backend", "cpu"]].concat(),
            "adaptive render is too large: step 0.001 gives up to 1.9e12 samples per frame \
             (110851 per ray, 16777216 rays; at most 1e12)",
        ),
        (
            vec![
                "adaptive",
                "phantom:sphere:8",
                "--runs",
                "0",
                "--out",
                s(&out),
            ],
            "invalid --runs: must lie in 1..=100",
        ),
    ];
    if common::gpu("every_dry_run_refuses_what_its_run_refuses").is_some() {
        let gpu: Vec<(Vec<&str>, &str)> = vec![
            (
                vec![
                    "render",
                    "phantom:sphere:8",
                    "--filter",
                    "sinc",
                    "--backend",
                    "gpu",
                    "--out",
                    s(&out),
                ],
                "the full sinc runs on the CPU only",
            ),
            (
                vec![
                    "render",
                    "phantom:sphere:8",
                    "--filter",
                    "catmull-rom",
                    "--hardware-filtering",
                    "--backend",
                    "gpu",
                    "--out",
                    s(&out),
                ],
                "the sampler filters trilinearly only",
            ),
            (
                [&median[..], &["--size", "7", "--backend", "gpu"]].concat(),
                "on the GPU the window side must be odd, from 1 to 5",
            ),
            (
                [&tiny_step[..], &["--backend", "gpu"]].concat(),
                "render is too large: step 0.0001 gives up to 2.3e12 samples per frame",
            ),
            (
                [&multi[..], &["--filter", "catmull-rom", "--backend", "gpu"]].concat(),
                "the GPU multi-volume caster reconstructs with nearest or trilinear",
            ),
            (
                [&adaptive_tiny_step[..], &["--backend", "gpu"]].concat(),
                "adaptive render is too large: step 0.001 gives up to 1.9e12 samples",
            ),
        ];
        cases.extend(gpu);
    }
    for (args, says) in cases {
        let run = voxlab(&args);
        let dry = voxlab(&[&args[..], &["--dry-run"]].concat());
        for (o, how) in [(&run, "run"), (&dry, "dry run")] {
            assert_eq!(o.status.code(), Some(1), "{how} of {args:?}: {}", stderr(o));
            assert!(
                stderr(o).contains(says),
                "{how} of {args:?}: no '{says}' in {}",
                stderr(o)
            );
        }
        assert_eq!(stderr(&run), stderr(&dry), "{args:?}");
        assert!(!out.exists() && !vol.exists(), "{args:?} wrote");
    }
}

/// Past the device memory a job may fill (`VOXLAB_GPU_MEMORY`) the multi-volume GPU
/// caster, when not even its tables and a band's buffers leave room for a cell, and the
/// adaptive caster, when not even its tables fit, refuse alike in the run and its dry
/// run, before uploading, with the numbers; nothing is written. (The casters cut their
/// volumes where the pieces fit: `tests/gpu_distributed_render.rs`,
/// `tests/gpu_adaptive.rs`, `tests/gpu_multi.rs`.)
#[test]
fn gpu_casters_refuse_past_the_device_memory_when_no_piece_fits() {
    if common::gpu("gpu_casters_refuse_past_the_device_memory_when_no_piece_fits").is_none() {
        return;
    }
    let dir = scratch("cli_device_memory");
    let out = dir.join("never.png");
    // Adaptive sampling of 32³ into 64²: 64 KiB of memory make the binding 8 KiB, which
    // the pre-integrated table (256² RGBA f32, 1 MiB) exceeds, checked before the
    // volume is cut into bricks (where no brick with its 11 ghost voxels each way fits:
    // `tests/cli_adaptive.rs` under the texture limit, `tests/gpu_adaptive.rs` under
    // the memory).
    let size = ["--width", "64", "--height", "64"];
    let table = "preintegrated table is too large: 1048576 bytes exceed";
    for (args, says) in [
        (
            [
                &["render", "phantom:sphere:32", "--sampling", "adaptive"][..],
                &size,
            ]
            .concat(),
            table,
        ),
        (vec!["adaptive", "phantom:sphere:32", "--size", "64"], table),
        (
            vec![
                "render",
                "phantom:sphere:8",
                "--volume",
                "phantom:sphere:32",
            ],
            "multi-volume render is too large: the lookup tables and a band's buffers alone",
        ),
    ] {
        let mut said = Vec::new();
        for dry in [&[][..], &["--dry-run"]] {
            let a = [&args[..], &["--backend", "gpu", "--out", s(&out)], dry].concat();
            let o = common::voxlab_command(&a)
                .env("VOXLAB_GPU_MEMORY", "64KiB")
                .output()
                .unwrap();
            assert_eq!(o.status.code(), Some(1), "{a:?}");
            let e = stderr(&o);
            assert!(e.contains(says), "{a:?}: {e}");
            assert!(!out.exists(), "{a:?} wrote");
            said.push(e);
        }
        assert_eq!(said[0], said[1], "{args:?}");
    }
}
