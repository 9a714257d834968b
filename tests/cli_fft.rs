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
    for args in [
        &["fft", "16x0"][..],
        &["fft", "abc"],
        &["fft", "16", "--backend", "tpu"],
        &["fft", "16", "--runs", "0"],
    ] {
        let o = voxlab(args);
        assert_eq!(o.status.code(), Some(1), "{args:?}");
        assert!(stderr(&o).contains("invalid"), "{args:?}: {}", stderr(&o));
    }
}
