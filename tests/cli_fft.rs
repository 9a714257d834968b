//! `voxlab fft`: the transforms checked against the exact DFT from the command line.

mod common;

use common::{s, scratch, stderr, voxlab};

#[test]
fn fft_checks_cpu_shapes_and_writes_json() {
    let d = scratch("cli-fft");
    let json = d.join("fft.json");
    let o = voxlab(&[
        "fft",
        "64",
        "16x8",
        "4x4x4",
        "--backend",
        "cpu",
        "--runs",
        "2",
        "--json",
        s(&json),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("all within tolerance"), "{out}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(r["runs"], 2);
    assert_eq!(r["passed"], true);
    assert!(r["adapter"].is_null());
    let cases = r["cases"].as_array().unwrap();
    // Three shapes, CPU f64 and f32 each.
    assert_eq!(cases.len(), 6);
    let shapes: Vec<Vec<u64>> = vec![vec![64], vec![16, 8], vec![4, 4, 4]];
    for (i, c) in cases.iter().enumerate() {
        let shape: Vec<u64> = c["shape"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        assert_eq!(shape, shapes[i / 2]);
        assert_eq!(c["backend"], ["cpu-f64", "cpu-f32"][i % 2]);
        // Small shapes are checked against the exact DFT.
        assert_eq!(c["reference"], "exact-dft");
        let (err, tol) = (
            c["rel_l2"].as_f64().unwrap(),
            c["tolerance"].as_f64().unwrap(),
        );
        let bound = if i % 2 == 0 { 1e-14 } else { 1e-6 };
        assert!(err < bound && err <= tol, "{c}");
        assert_eq!(c["passed"], true);
        for k in ["median_s", "gflops", "gbps"] {
            let v = c[k].as_f64().unwrap();
            assert!(v.is_finite() && v >= 0.0, "{k}: {c}");
        }
        assert!(c["kernel_median_s"].is_null() && c["skipped"].is_null());
    }
}

#[test]
fn fft_refuses_bad_shapes_and_backends() {
    // A bad value of a choice is a usage error (exit 2, from the argument parser); a
    // bad shape or count is refused by the job (exit 1).
    for (args, code) in [
        (&["fft", "16x0"][..], 1),
        (&["fft", "abc"], 1),
        (&["fft", "16", "--backend", "tpu"], 2),
        (&["fft", "16", "--runs", "0"], 1),
    ] {
        let o = voxlab(args);
        assert_eq!(o.status.code(), Some(code), "{args:?}");
        assert!(stderr(&o).contains("invalid"), "{args:?}: {}", stderr(&o));
    }
}

fn report(args: &[&str], name: &str) -> serde_json::Value {
    let json = scratch(name).join("fft.json");
    let mut all = args.to_vec();
    all.extend(["--json", s(&json)]);
    let o = voxlab(&all);
    assert!(o.status.success(), "{}", stderr(&o));
    serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap()
}

/// Above N·ΣN = 1e9 the reference is the CPU f64 FFT, and the report says so.
#[test]
fn fft_falls_back_to_the_f64_fft_as_reference_for_large_shapes() {
    let r = report(
        &["fft", "32768", "--backend", "cpu", "--runs", "1"],
        "cli-fft-large",
    );
    let cases = r["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 2);
    for c in cases {
        assert_eq!(c["reference"], "cpu-f64-fft", "{c}");
        assert_eq!(c["passed"], true, "{c}");
    }
    assert_eq!(cases[0]["rel_l2"], 0.0);
}

/// Both GPU variants, checked against the exact DFT, on a power-of-two shape and on a
/// length that runs Bluestein's algorithm.
#[test]
fn fft_checks_the_gpu_variants() {
    if common::gpu("fft_checks_the_gpu_variants").is_none() {
        return;
    }
    let r = report(
        &["fft", "8x16", "12", "--backend", "gpu", "--runs", "1"],
        "cli-fft-gpu",
    );
    assert!(r["adapter"].is_string());
    let cases = r["cases"].as_array().unwrap();
    let names: Vec<&str> = cases
        .iter()
        .map(|c| c["backend"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "gpu-stockham",
            "gpu-split-stream",
            "gpu-stockham",
            "gpu-split-stream"
        ]
    );
    for c in cases {
        assert_eq!(c["reference"], "exact-dft");
        assert!(c["rel_l2"].as_f64().unwrap() < 1e-6, "{c}");
        assert!(c["kernel_median_s"].as_f64().unwrap() > 0.0, "{c}");
        assert!(c["kernel_gbps"].as_f64().unwrap() > 0.0, "{c}");
    }
    // Dispatches per transform: Stockham does each axis of 8 and 16 in workgroup
    // memory (one each); the split-stream passes are log2 n − 1 per axis (its last
    // two stages are one), 2 + 3.
    assert_eq!(cases[0]["dispatches"], 2);
    assert_eq!(cases[1]["dispatches"], 5);
    // The roofline against the adapter's peak, where the part is known (not lavapipe).
    match r["adapter_peak"].as_object() {
        None => assert!(cases[0]["of_peak_bandwidth"].is_null()),
        Some(p) => {
            let want =
                cases[0]["kernel_gbps"].as_f64().unwrap() / p["memory_gbps"].as_f64().unwrap();
            assert_eq!(cases[0]["of_peak_bandwidth"].as_f64(), Some(want));
        }
    }
    // Length 12 runs Bluestein's algorithm with M = 32: a load, the forward passes, a
    // multiplication, the inverse passes and a store; Stockham does each length-32
    // FFT in one dispatch, the split stream in 4.
    assert_eq!(cases[2]["dispatches"], 5);
    assert_eq!(cases[3]["dispatches"], 11);
}

/// Without a usable adapter, `--backend all` says so and runs the CPU; `--backend gpu`
/// fails naming the problem.
#[test]
fn fft_without_an_adapter_runs_the_cpu_or_fails_clearly() {
    let o = common::voxlab_command(&["fft", "16", "--runs", "1"])
        .env("VOXLAB_ADAPTER", "no-such-adapter")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("GPU: none available"), "{out}");
    assert!(out.contains("cpu-f32") && !out.contains("gpu-"), "{out}");
    let o = common::voxlab_command(&["fft", "16", "--backend", "gpu"])
        .env("VOXLAB_ADAPTER", "no-such-adapter")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("no GPU adapter"), "{}", stderr(&o));
}

/// The library side: shapes, tolerances, and the report of a CPU run.
#[test]
fn fft_check_library_parses_shapes_and_sets_tolerances() {
    use voxlab::jobs::fft::{parse_shape, run, tolerance};
    use voxlab::jobs::BackendSet;
    assert_eq!(parse_shape("64x64x64").unwrap(), vec![64, 64, 64]);
    assert_eq!(parse_shape("1024").unwrap(), vec![1024]);
    assert!(parse_shape("4x").is_err() && parse_shape("0").is_err());
    assert!(matches!(
        parse_shape("65536x65536"),
        Err(voxlab::Error::TooLarge { .. })
    ));
    assert!((tolerance(1024, true) - 1e-5).abs() < 1e-20);
    assert_eq!(tolerance(1, true), 1e-6);
    assert_eq!(tolerance(1024, false), 1e-12);
    let backends = BackendSet::Cpu;
    let mut lines = 0;
    let r = run(&[vec![3, 5]], backends, 1, None, &mut |_| lines += 1).unwrap();
    assert_eq!((lines, r.cases.len()), (2, 2));
    assert!(r.passed && r.adapter.is_none());
    assert!(run(&[vec![3]], backends, 0, None, &mut |_| {}).is_err());
}

#[test]
fn a_gpu_fft_past_a_lowered_binding_is_split_and_gives_the_same_numbers() {
    if common::gpu("a_gpu_fft_past_a_lowered_binding_is_split_and_gives_the_same_numbers").is_none()
    {
        return;
    }
    let d = scratch("cli-fft-split");
    let run = |json: &std::path::Path, binding: Option<&str>| {
        let args = [
            "fft",
            "64x32",
            "32x16x8",
            "--backend",
            "gpu",
            "--runs",
            "1",
            "--json",
            s(json),
        ];
        // 64 × 32 and 32 × 16 × 8 complex values are 16 and 32 KiB.
        let o = common::voxlab_with_binding(&args, binding);
        assert!(o.status.success(), "{}", stderr(&o));
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
        assert_eq!(r["passed"], true);
        r["cases"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| {
                (
                    (c["backend"].to_string(), c["rel_l2"].as_f64().unwrap()),
                    c["split"].as_str().map(str::to_string),
                )
            })
            .unzip::<_, _, Vec<_>, Vec<_>>()
    };
    let (whole, unsplit) = run(&d.join("whole.json"), None);
    let (split, how) = run(&d.join("split.json"), Some("4KiB"));
    assert_eq!(whole.len(), 4, "{whole:?}");
    // The same transforms bit for bit, so the same errors against the exact DFT.
    assert_eq!(whole, split);
    // Each case says how it was cut: 64 × 32 in slabs of 512-byte lines along axis 1
    // (8 per 4 KiB) and of 256-byte slices along axis 0 (16 per 4 KiB); 32 × 16 × 8 in
    // 2 KiB and 1 KiB pieces.
    assert!(unsplit.iter().all(Option::is_none), "{unsplit:?}");
    let s64 = "FFT in 4 slabs along axis 1 (axis 0's lines), then 4 slabs along axis 0 \
               (the other axes)";
    let s32 = "FFT in 8 slabs along axis 1 (axis 0's lines), then 8 slabs along axis 0 \
               (the other axes)";
    let want: Vec<Option<String>> = [s64, s64, s32, s32]
        .iter()
        .map(|s| Some(s.to_string()))
        .collect();
    assert_eq!(how, want);
}

/// `--dry-run` prints each shape's plan (and the split a lowered binding forces) and
/// transforms and writes nothing.
#[test]
fn fft_dry_run_prints_each_shapes_plan_and_writes_nothing() {
    if common::gpu("fft_dry_run_prints_each_shapes_plan_and_writes_nothing").is_none() {
        return;
    }
    let json = scratch("cli-fft-dry-run").join("never.json");
    let args = [
        "fft",
        "64x32",
        "12",
        "4096",
        "--backend",
        "gpu",
        "--json",
        s(&json),
        "--dry-run",
    ];
    let o = common::voxlab_with_binding(&args, Some("4KiB"));
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    for want in [
        "dry run: fft 64x32 on gpu",
        // 64 × 32 complex f32: 16 KiB in 4 KiB slabs, two ping-pong buffers of one.
        "split:  FFT in 4 slabs along axis 1 (axis 0's lines), then 4 slabs along axis 0",
        "the largest buffer 4.0 KiB",
        "dry run: fft 12 on gpu",
        // Bluestein's two work buffers of M = 32 values (256 bytes each) next to the
        // two data buffers of 96 bytes, and the tables: the chirp (12 values), the
        // kernel and the inner twiddles both ways (32 each), 8 bytes a value.
        "device: 1.5 KiB at once, the largest buffer 256 B",
        // A 1-D array past the binding: four steps over its 64 × 64 view.
        "dry run: fft 4096 on gpu",
        "split:  FFT in four steps as 64 × 64: 8 slabs along axis 1",
    ] {
        assert!(text.contains(want), "no '{want}' in:\n{text}");
    }
    assert!(!text.contains("rel L2"), "{text}");
    assert!(!json.exists());
}
