//! `voxlab process`: each operation end to end on a small phantom, the written volume
//! checked against the library, and the refusals (no file left behind on error).

mod common;

use common::{s, scratch, stderr, voxlab};
use voxlab::cpu::process::{self as cp, Region, ResampleSpec};
use voxlab::settings::Filter;

fn read(p: &std::path::Path) -> voxlab::Volume<f32> {
    voxlab::io::read_volume(p).unwrap().to_f32()
}

#[test]
fn process_ops_write_what_the_library_computes() {
    let dir = scratch("ops");
    let input = voxlab::phantom::Phantom::shepp_logan()
        .sample([16, 16, 16])
        .unwrap();
    let src = dir.join("in.nrrd");
    voxlab::io::write_volume(&src, &input.clone().into()).unwrap();

    let out = dir.join("r.nrrd");
    let o = voxlab(&[
        "process",
        s(&src),
        "--op",
        "resample",
        "--dims",
        "24,8,12",
        "--filter",
        "catmull-rom",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let got = read(&out);
    let want = cp::resample::<f64, f32>(
        &input,
        &ResampleSpec {
            region: Region::Whole,
            dims: [24, 8, 12],
            filter: Filter::CatmullRom,
        },
    )
    .unwrap()
    .to_volume()
    .unwrap();
    assert_eq!(got.dims(), [24, 8, 12]);
    assert_eq!(got.data(), want.data());
    assert!((got.affine() - want.affine()).abs_diff_eq(glam::DMat4::ZERO, 1e-9));

    // --spacing over an index box: 8 voxels × 16 mm/voxel / 8 mm = 16 voxels per axis.
    let out = dir.join("b.npy");
    let o = voxlab(&[
        "process",
        s(&src),
        "--op",
        "resample",
        "--box",
        "3.5,3.5,3.5,11.5,11.5,11.5",
        "--spacing",
        "8",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(read(&out).dims(), [16, 16, 16]);

    for (op, extra, f) in [
        (
            "gaussian",
            vec!["--sigma", "1.5"],
            cp::gaussian::<f64, f32>(&input, [1.5; 3]).unwrap(),
        ),
        (
            "median",
            vec!["--size", "3"],
            cp::median::<f64, f32>(&input, 3).unwrap(),
        ),
        (
            "gradient-magnitude",
            vec![],
            cp::gradient_magnitude::<f64, f32>(&input).unwrap(),
        ),
    ] {
        let out = dir.join(format!("{op}.nii.gz"));
        let mut args = vec!["process", s(&src), "--op", op, "--out", s(&out)];
        args.extend(extra);
        let o = voxlab(&args);
        assert!(o.status.success(), "{op}: {}", stderr(&o));
        assert_eq!(read(&out).data(), f.to_volume().unwrap().data(), "{op}");
    }
}

#[test]
fn process_refuses_bad_options_and_leaves_no_file() {
    let dir = scratch("refusals");
    let bad: [(&[&str], &str); 7] = [
        (&["--op", "gaussian", "--sigma", "0"], "sigma"),
        (&["--op", "gaussian", "--sigma", "nan"], "sigma"),
        (&["--op", "gaussian"], "--sigma"),
        (&["--op", "median", "--size", "4"], "window"),
        (&["--op", "resample"], "--dims"),
        (
            &[
                "--op",
                "resample",
                "--dims",
                "4,4,4",
                "--box",
                "0,0,0,4,0,4",
            ],
            "box",
        ),
        (
            &["--op", "resample", "--dims", "100000,100000,100000"],
            "voxels",
        ),
    ];
    for (n, (args, words)) in bad.iter().enumerate() {
        let out = dir.join(format!("o{n}.nrrd"));
        let mut a = vec!["process", "phantom:shepp-logan:8", "--out", s(&out)];
        a.extend_from_slice(args);
        let o = voxlab(&a);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(stderr(&o).contains(words), "{args:?}: {}", stderr(&o));
        assert!(!out.exists(), "{args:?} left a file");
    }
    let o = voxlab(&[
        "process",
        "phantom:shepp-logan:8",
        "--op",
        "median",
        "--out",
        s(&dir.join("x.png")),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains(".nrrd"), "{}", stderr(&o));
    // Nothing but the refused outputs' absence: the folder stays empty.
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
}

#[test]
fn process_on_the_gpu_matches_the_oracle() {
    if common::gpu("process_on_the_gpu_matches_the_oracle").is_none() {
        return;
    }
    let dir = scratch("gpu");
    let input = voxlab::phantom::Phantom::shepp_logan()
        .sample([12, 12, 12])
        .unwrap();
    for (op, extra, want) in [
        (
            "median",
            vec!["--size", "5"],
            cp::median::<f64, f32>(&input, 5).unwrap(),
        ),
        (
            "gaussian",
            vec!["--sigma", "0.8,1.1,1.7"],
            cp::gaussian::<f64, f32>(&input, [0.8, 1.1, 1.7]).unwrap(),
        ),
    ] {
        let out = dir.join(format!("{op}.npy"));
        let mut args = vec![
            "process",
            "phantom:shepp-logan:12",
            "--backend",
            "gpu",
            "--op",
            op,
            "--out",
            s(&out),
        ];
        args.extend(extra);
        let o = voxlab(&args);
        assert!(o.status.success(), "{op}: {}", stderr(&o));
        let got = read(&out);
        let worst = got
            .data()
            .iter()
            .zip(&want.grid.data)
            .map(|(a, b)| (*a as f64 - b).abs())
            .fold(0.0, f64::max);
        // The median is exact; the Gaussian measured 3.0e-8 on lavapipe (values 0 … 2).
        assert!(worst < 2e-7, "{op}: {worst}");
        if op == "median" {
            assert_eq!(worst, 0.0);
        }
    }
}

#[test]
fn a_split_gpu_gaussian_says_so_and_writes_the_unsplit_volume() {
    if common::gpu("a_split_gpu_gaussian_says_so_and_writes_the_unsplit_volume").is_none() {
        return;
    }
    let dir = scratch("split");
    let input = voxlab::phantom::Phantom::shepp_logan()
        .sample([16, 16, 16])
        .unwrap();
    let src = dir.join("in.nrrd");
    voxlab::io::write_volume(&src, &input.into()).unwrap();
    let args = [
        "process",
        s(&src),
        "--op",
        "gaussian",
        "--sigma",
        "1",
        "--backend",
        "gpu",
    ];
    // 16 × 16 slices of 1,024 bytes: 10 fit, 4 ghosts on either side.
    let line = "processing in 8 slabs of 2 slices (4 ghost slices on either side)";
    let quiet = common::split_writes_the_unsplit_file(&dir, &args, "10240", &[line]);
    assert!(!quiet.contains("slabs"), "{quiet}");
}

#[test]
fn process_dry_run_prints_the_slabs_and_writes_nothing() {
    if common::gpu("process_dry_run_prints_the_slabs_and_writes_nothing").is_none() {
        return;
    }
    let dir = scratch("dry-run");
    let input = voxlab::phantom::Phantom::shepp_logan()
        .sample([16, 16, 16])
        .unwrap();
    let src = dir.join("in.nrrd");
    voxlab::io::write_volume(&src, &input.into()).unwrap();
    let out = dir.join("never.nrrd");
    let args = [
        "process",
        s(&src),
        "--op",
        "median",
        "--size",
        "5",
        "--backend",
        "gpu",
        "--out",
        s(&out),
        "--dry-run",
    ];
    // Slices of 1 KiB: 8 fit 8 KiB, 2 ghosts on either side leave 4 per slab.
    let o = common::voxlab_with_binding(&args, Some("8KiB"));
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    for want in [
        "dry run: process: median 5³ on gpu",
        // 16³ f32 in and out.
        "host:   32.0 KiB at the peak",
        "split:  processing in 4 slabs of 4 slices (2 ghost slices on either side)",
    ] {
        assert!(text.contains(want), "no '{want}' in:\n{text}");
    }
    assert!(!out.exists());
}

#[test]
fn a_split_gpu_resample_says_so_and_writes_the_unsplit_volume() {
    if common::gpu("a_split_gpu_resample_says_so_and_writes_the_unsplit_volume").is_none() {
        return;
    }
    let dir = scratch("split-resample");
    let input = voxlab::phantom::Phantom::shepp_logan()
        .sample([16, 16, 16])
        .unwrap();
    let src = dir.join("in.nrrd");
    voxlab::io::write_volume(&src, &input.into()).unwrap();
    let args = [
        "process",
        s(&src),
        "--op",
        "resample",
        "--dims",
        "24,20,28",
        "--filter",
        "lanczos3",
        "--backend",
        "gpu",
    ];
    let run = |out: &std::path::Path, binding: Option<&str>, extra: &[&str]| {
        let all = [&args[..], &["--out", s(out)], extra].concat();
        common::voxlab_with_binding(&all, binding)
    };
    // Output slices of 24 × 20 × 4 = 1,920 bytes, input slices of 1,024: 10 KiB hold 5
    // output and 10 input slices; Lanczos-3 reaches 3 input slices either side.
    let line = "resampling in 6 slabs of 5 slices (each reading at most 10 input slices)";
    let quiet = common::split_writes_the_unsplit_file(&dir, &args, "10KiB", &[line]);
    assert!(!quiet.contains("slabs"), "{quiet}");
    let never = dir.join("never.npy");
    let o = run(&never, Some("10KiB"), &["--dry-run"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("split:  resampling in 6 slabs of 5 slices"),
        "{text}"
    );
    assert!(!never.exists());
    // One output slice with its reach of input slices past the binding.
    let o = run(&never, Some("4KiB"), &[]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("input slices of 1024 bytes"),
        "{}",
        stderr(&o)
    );
    assert!(!never.exists());
}
