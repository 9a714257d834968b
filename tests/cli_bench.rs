//! `voxlab bench`: the quick suite end to end (every case must pass its parity checks),
//! `--only`, `--list`, and the refusals.

mod common;

use common::{s, scratch, stderr, voxlab};
use voxlab::bench::{cases, Suite, FAMILIES};

/// The one JSON report in `dir`.
fn report(dir: &std::path::Path) -> serde_json::Value {
    let json: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    assert_eq!(json.len(), 1, "{json:?}");
    let stem = json[0].file_stem().unwrap().to_str().unwrap().to_string();
    for ext in ["md", "svg"] {
        assert!(dir.join(format!("{stem}.{ext}")).is_file(), "{stem}.{ext}");
    }
    serde_json::from_str(&std::fs::read_to_string(&json[0]).unwrap()).unwrap()
}

/// Every case passed: no preparation error, no backend failed or errored; the GPU ran
/// wherever the case has a port, unless VOXLAB_ALLOW_NO_GPU=1 and there is no adapter.
fn assert_all_passed(j: &serde_json::Value) {
    let no_gpu_allowed = std::env::var("VOXLAB_ALLOW_NO_GPU").as_deref() == Ok("1");
    let has_adapter = !j["machine"]["adapter"].is_null();
    assert!(
        has_adapter || no_gpu_allowed,
        "no adapter: {}",
        j["machine"]
    );
    for c in j["cases"].as_array().unwrap() {
        let id = format!("{}/{} {}", c["family"], c["name"], c["size"]);
        assert!(c["error"].is_null(), "{id}: {}", c["error"]);
        for b in ["cpu_f64", "cpu_f32", "gpu"] {
            let st = c[b]["status"].as_str().unwrap();
            assert!(
                st == "passed" || st == "skipped",
                "{id} {b}: {st}: {}",
                c[b]["message"]
            );
        }
        assert_eq!(c["cpu_f64"]["status"], "passed", "{id}");
        if has_adapter && c["gpu"]["message"] != "no GPU port" {
            assert_eq!(
                c["gpu"]["status"], "passed",
                "{id}: {}",
                c["gpu"]["message"]
            );
        }
    }
}

#[test]
fn the_quick_suite_runs_every_family_and_passes() {
    let dir = scratch("quick");
    let out = dir.join("results");
    let o = voxlab(&[
        "bench",
        "--suite",
        "quick",
        "--out",
        s(&out),
        "--name",
        "quick",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j = report(&out);
    assert_all_passed(&j);
    let listed = cases(Suite::Quick);
    let found = j["cases"].as_array().unwrap();
    assert_eq!(found.len(), listed.len());
    for fam in FAMILIES {
        let n = listed.iter().filter(|c| c.family == fam).count();
        if n == 0 {
            eprintln!("family {fam} has no quick cases yet");
            continue;
        }
        let m = found.iter().filter(|c| c["family"] == fam).count();
        assert_eq!(m, n, "family {fam}");
    }
    assert_eq!(j["suite"], "quick");
}

#[test]
fn only_runs_the_families_named() {
    let dir = scratch("only");
    let o = voxlab(&[
        "bench",
        "--suite",
        "quick",
        "--only",
        "fft",
        "--runs",
        "1",
        "--out",
        s(&dir),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j = report(&dir);
    assert_all_passed(&j);
    let n = cases(Suite::Quick)
        .iter()
        .filter(|c| c.family == "fft")
        .count();
    let found = j["cases"].as_array().unwrap();
    assert_eq!(found.len(), n);
    assert!(found.iter().all(|c| c["family"] == "fft"));
    assert_eq!(j["runs"], 1);
}

#[test]
fn list_prints_the_cases_and_runs_nothing() {
    let dir = scratch("list");
    let o = voxlab(&[
        "bench",
        "--suite",
        "quick",
        "--list",
        "--out",
        s(&dir.join("r")),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    let all = cases(Suite::Quick);
    for c in &all {
        assert!(text.contains(&c.id()), "{} not in {text}", c.id());
    }
    assert!(text.contains(&format!("{} case(s)", all.len())), "{text}");
    assert!(!dir.join("r").exists());
}

#[test]
fn bad_options_are_refused_and_leave_nothing() {
    let o = voxlab(&["bench", "--only", "nonsense", "--list"]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("'nonsense'") && e.contains(&FAMILIES.join(", ")),
        "{e}"
    );

    let dir = scratch("refused");
    let file = dir.join("results");
    std::fs::write(&file, "not a folder").unwrap();
    let o = voxlab(&[
        "bench",
        "--suite",
        "quick",
        "--only",
        "fft",
        "--out",
        s(&file),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("is a file"), "{}", stderr(&o));
    assert_eq!(std::fs::read_to_string(&file).unwrap(), "not a folder");
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);

    for args in [
        ["--suite", "huge"],
        ["--backends", "tpu"],
        ["--runs", "0"],
        ["--name", "A B"],
    ] {
        let mut a = vec!["bench", "--list"];
        a.extend(args);
        let o = voxlab(&a);
        assert!(!o.status.success(), "{args:?}");
        assert!(stderr(&o).contains(args[0]), "{args:?}: {}", stderr(&o));
    }
}

#[test]
fn merge_folds_a_later_run_into_a_report_and_rerender_rewrites_it() {
    let dir = scratch("merge");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "bench",
            "--suite",
            "quick",
            "--backends",
            "cpu",
            "--runs",
            "1",
            "--out",
        ];
        args.push(s(&dir));
        args.extend_from_slice(&["--name", "m"]);
        args.extend_from_slice(extra);
        voxlab(&args)
    };
    let o = run(&["--only", "fft/2d"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(&["--only", "fft/3d,fft/2d", "--merge"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j = report(&dir);
    let ids: Vec<String> = j["cases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            format!(
                "{}/{}",
                c["family"].as_str().unwrap(),
                c["name"].as_str().unwrap()
            )
        })
        .collect();
    assert_eq!(
        ids,
        ["fft/2d", "fft/3d"],
        "replaced, joined, in suite order"
    );
    assert_eq!(j["merged"].as_array().unwrap().len(), 1);
    let md = std::fs::read_to_string(dir.join("m.md")).unwrap();
    assert!(md.contains("later run, merged"), "{md}");
    // Re-rendering runs nothing and rewrites the Markdown from the JSON.
    std::fs::write(dir.join("m.md"), "stale").unwrap();
    let o = voxlab(&["bench", "--rerender", "--name", "m", "--out", s(&dir)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read_to_string(dir.join("m.md")).unwrap(), md);
    // Both need the report's name; a missing report is a clear error.
    let o = voxlab(&["bench", "--merge", "--out", s(&dir)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("needs --name"), "{}", stderr(&o));
    let o = voxlab(&["bench", "--rerender", "--name", "nope", "--out", s(&dir)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("nope.json"), "{}", stderr(&o));
}
