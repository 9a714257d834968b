//! The benchmark runner on hand-made cases (no real algorithm): the statistics, the
//! parity gate before timing, the time budget, throughput, the reports and the exit
//! status. The fake backends report known times, so every figure is exact.

mod common;

use std::cell::Cell;
use std::rc::Rc;
use voxlab::bench::report::{parity, slugify, Stats, Status};
use voxlab::bench::{
    parse_families, run_suite, Case, CpuFn, GpuFn, GpuRun, Options, Prepared, Report, Run, Suite,
    Unit, Work, FAMILIES,
};
use voxlab::metrics::Tolerance;
use voxlab::Error;

const TOL: Tolerance = Tolerance::max_abs_rel(1e-6).with_rel_l2(1e-6);
const ORACLE: [f64; 4] = [1.0, -2.0, 3.0, 4.0];
const NO_GPU: Result<&voxlab::gpu::GpuContext, &str> = Err("no GPU in this test");

/// A CPU backend whose n-th call reports `times[n]` (the last one repeated) and
/// returns `output`; `calls` counts the calls.
fn cpu(times: &[f64], output: &[f64], calls: &Rc<Cell<usize>>) -> CpuFn {
    let (times, output, calls) = (times.to_vec(), output.to_vec(), calls.clone());
    Box::new(move || {
        let n = calls.get();
        calls.set(n + 1);
        Ok(Run {
            seconds: times[n.min(times.len() - 1)],
            output: output.clone(),
        })
    })
}

/// A GPU backend reporting `kernel`, `e2e` and `setup` on every call.
fn gpu(kernel: f64, e2e: f64, setup: f64, output: &[f64], calls: &Rc<Cell<usize>>) -> GpuFn {
    let (output, calls) = (output.to_vec(), calls.clone());
    Box::new(move |_| {
        calls.set(calls.get() + 1);
        Ok(GpuRun {
            output: output.clone(),
            kernel,
            kernel_from_timestamps: true,
            end_to_end: e2e,
            setup,
        })
    })
}

/// A case whose prepare hands out the backends `make` builds.
fn case(family: &'static str, name: &str, make: impl Fn() -> Prepared + 'static) -> Case {
    Case::new(family, name, "4", move || Ok(make()))
}

fn prepared(cpu_f64: CpuFn, cpu_f32: Option<CpuFn>, gpu: Option<GpuFn>) -> Prepared {
    Prepared {
        cpu_f64,
        cpu_f32,
        gpu,
        tol_f32: TOL,
        tol_gpu: TOL,
        work: vec![
            Work {
                amount: 1e6,
                unit: Unit::Rays,
            },
            Work {
                amount: 3e9,
                unit: Unit::Flops,
            },
        ],
        note: "fake".into(),
    }
}

fn opts(runs: usize) -> Options {
    Options {
        runs,
        ..Options::new(Suite::Quick)
    }
}

fn counter() -> Rc<Cell<usize>> {
    Rc::new(Cell::new(0))
}

#[test]
fn median_min_max_of_known_samples() {
    let s = Stats::of(&[3.0, 1.0, 2.0, 5.0, 4.0]).unwrap();
    assert_eq!((s.median, s.min, s.max), (3.0, 1.0, 5.0));
    assert_eq!(s.samples, [3.0, 1.0, 2.0, 5.0, 4.0]);
    let s = Stats::of(&[4.0, 1.0, 3.0, 2.0]).unwrap();
    assert_eq!((s.median, s.min, s.max), (2.5, 1.0, 4.0));
    assert!(Stats::of(&[]).is_none());

    // Through the runner: one warm-up (9 s, not in the statistics), five timed runs.
    let calls = counter();
    let c = calls.clone();
    let cases = vec![case("raycast", "known", move || {
        prepared(
            cpu(&[9.0, 3.0, 1.0, 2.0, 5.0, 4.0], &ORACLE, &c),
            None,
            None,
        )
    })];
    let o = Options {
        budget_seconds: 1e9,
        ..opts(5)
    };
    let r = run_suite(cases, &o, NO_GPU, &|_| {});
    let b = &r.cases[0].cpu_f64;
    assert_eq!(b.status, Status::Passed);
    assert_eq!(b.warmup_seconds, [9.0]);
    assert_eq!(b.runs, 5);
    let s = b.seconds.as_ref().unwrap();
    assert_eq!((s.median, s.min, s.max), (3.0, 1.0, 5.0));
    assert_eq!(s.samples, [3.0, 1.0, 2.0, 5.0, 4.0]);
    assert_eq!(calls.get(), 6);
    assert!(r.passed());
}

#[test]
fn a_wrong_f32_result_fails_and_is_not_timed() {
    let calls = counter();
    let c = calls.clone();
    let cases = vec![case("fft", "wrong", move || {
        prepared(
            cpu(&[1.0], &ORACLE, &counter()),
            // max |Δ| = 0.04 against max |oracle| = 4: 1e-2 relative.
            Some(cpu(&[0.5], &[1.0, -2.0, 3.04, 4.0], &c)),
            None,
        )
    })];
    let r = run_suite(cases, &opts(3), NO_GPU, &|_| {});
    let b = &r.cases[0].cpu_f32;
    assert_eq!(b.status, Status::Failed);
    assert_eq!(calls.get(), 1, "only the checked warm-up run");
    assert!(b.seconds.is_none() && b.throughput.is_empty() && b.runs == 0);
    let p = b.parity.as_ref().unwrap();
    assert!((p.max_abs_rel - 0.01).abs() < 1e-12, "{}", p.max_abs_rel);
    assert!(r.cases[0].speedups.f64_over_f32.is_none());
    assert!(!r.passed());
    assert_eq!(r.cases[0].status(), Status::Failed);
}

#[test]
fn a_wrong_gpu_result_fails_and_is_not_timed() {
    let Some(ctx) = common::gpu("a_wrong_gpu_result_fails_and_is_not_timed") else {
        return;
    };
    let calls = counter();
    let c = calls.clone();
    let cases = vec![case("raycast", "wrong-gpu", move || {
        prepared(
            cpu(&[1.0], &ORACLE, &counter()),
            Some(cpu(&[0.5], &ORACLE, &counter())),
            Some(gpu(1e-3, 2e-3, 0.1, &[1.0, -2.0, 3.0, 4.5], &c)),
        )
    })];
    let r = run_suite(cases, &opts(3), Ok(ctx), &|_| {});
    let g = &r.cases[0].gpu;
    assert_eq!(g.status, Status::Failed);
    assert_eq!(calls.get(), 1);
    assert!(g.kernel.is_none() && g.end_to_end.is_none() && g.setup.is_none());
    assert!(r.cases[0].speedups.f32_over_gpu_kernel.is_none());
    assert_eq!(r.cases[0].cpu_f32.status, Status::Passed);
    assert!(!r.passed());
    let md = r.to_markdown();
    assert!(md.contains("**FAILED**"), "{md}");
    assert!(
        r.problems()[0].contains("GPU FAILED parity"),
        "{:?}",
        r.problems()
    );
}

#[test]
fn nan_or_infinity_fails() {
    let tol = Tolerance::max_abs_rel(1.0).with_rel_l2(1.0);
    let p = parity(&ORACLE, &[1.0, f64::NAN, 3.0, 4.0], tol);
    assert!(!p.passed && p.non_finite == 1, "{p:?}");
    let p = parity(&ORACLE, &[1.0, -2.0, f64::INFINITY, 4.0], tol);
    assert!(!p.passed && p.non_finite == 1, "{p:?}");
    let p = parity(&ORACLE, &[1.0, -2.0, 3.0], tol);
    assert!(!p.passed && p.message.contains("3 values"), "{p:?}");
    // Exact relative errors: Δ = (0, 0, 0, 0.4), ‖oracle‖ = √30.
    let p = parity(&ORACLE, &[1.0, -2.0, 3.0, 4.4], tol);
    assert!(p.passed);
    assert!((p.max_abs_rel - 0.1).abs() < 1e-12);
    assert!((p.rel_l2 - 0.4 / 30f64.sqrt()).abs() < 1e-12);

    // Through the runner: a NaN from f32 fails it; a NaN from the oracle is an error.
    let cases = vec![
        case("fft", "nan-f32", || {
            prepared(
                cpu(&[1.0], &ORACLE, &counter()),
                Some(cpu(&[1.0], &[1.0, f64::NAN, 3.0, 4.0], &counter())),
                None,
            )
        }),
        case("fft", "nan-oracle", || {
            prepared(
                cpu(&[1.0], &[1.0, f64::NAN, 3.0, 4.0], &counter()),
                Some(cpu(&[1.0], &ORACLE, &counter())),
                None,
            )
        }),
    ];
    let r = run_suite(cases, &opts(1), NO_GPU, &|_| {});
    assert_eq!(r.cases[0].cpu_f32.status, Status::Failed);
    assert_eq!(r.cases[1].cpu_f64.status, Status::Errored);
    assert_eq!(r.cases[1].cpu_f32.status, Status::Skipped);
    assert_eq!(r.cases[1].status(), Status::Errored);
}

/// 1e6 rays and 3e9 FLOP per run; f64 2 s, f32 0.5 s, GPU kernel 10 ms, end to end
/// 20 ms.
fn timed_report() -> Option<Report> {
    let ctx = common::gpu("bench_runner timed_report")?;
    let cases = vec![
        case("raycast", "timed", || {
            prepared(
                cpu(&[2.0], &ORACLE, &counter()),
                Some(cpu(&[0.5], &ORACLE, &counter())),
                Some(gpu(0.01, 0.02, 0.3, &ORACLE, &counter())),
            )
        }),
        Case::new("fft", "broken", "8", || {
            Err(Error::invalid("size", "too big for this test"))
        }),
        case("fft", "after-the-error", || {
            prepared(cpu(&[1.0], &ORACLE, &counter()), None, None)
        }),
    ];
    Some(run_suite(cases, &opts(3), Ok(ctx), &|_| {}))
}

#[test]
fn throughput_and_speedups() {
    let Some(r) = timed_report() else { return };
    let c = &r.cases[0];
    let tp = |b: &voxlab::bench::report::BackendReport| {
        b.throughput.iter().map(|t| t.value).collect::<Vec<_>>()
    };
    // 1e6 rays / 2 s = 0.5 Mrays/s; 3e9 FLOP / 2 s = 1.5 GFLOP/s.
    assert_eq!(tp(&c.cpu_f64), [0.5, 1.5]);
    assert_eq!(tp(&c.cpu_f32), [2.0, 6.0]);
    assert_eq!(c.cpu_f32.throughput[0].label, "Mrays/s");
    assert_eq!(c.cpu_f32.throughput[1].label, "GFLOP/s");
    // The GPU over its kernel time, and over end to end.
    assert_eq!(tp(&c.gpu), [100.0, 300.0]);
    assert_eq!(c.gpu.throughput[0].value_end_to_end, Some(50.0));
    let s = &c.speedups;
    assert_eq!(s.f64_over_f32, Some(4.0));
    assert_eq!(s.f32_over_gpu_kernel, Some(50.0));
    assert_eq!(s.f32_over_gpu_end_to_end, Some(25.0));
    assert_eq!(s.f64_over_gpu_kernel, Some(200.0));
    assert_eq!(c.gpu.setup.as_ref().unwrap().median, 0.3);
    assert_eq!(c.gpu.kernel_from_timestamps, Some(true));
    assert!(c.prepare_seconds.is_some());
}

#[test]
fn an_erroring_case_is_reported_and_the_suite_goes_on() {
    let Some(r) = timed_report() else { return };
    assert_eq!(r.cases.len(), 3);
    assert!(r.cases[1].error.as_deref().unwrap().contains("too big"));
    assert_eq!(r.cases[1].status(), Status::Errored);
    assert_eq!(r.cases[2].status(), Status::Passed);
    assert_eq!(r.cases[2].cpu_f32.status, Status::Skipped);
    assert_eq!(r.cases[2].gpu.status, Status::Skipped);
    // The exit status: one errored case fails the run.
    assert!(!r.passed());
    assert_eq!(r.problems().len(), 1, "{:?}", r.problems());
    let mut ok = r.clone();
    ok.cases.remove(1);
    assert!(ok.passed() && ok.problems().is_empty());
}

#[test]
fn markdown_and_json_carry_the_figures() {
    let Some(r) = timed_report() else { return };
    let md = r.to_markdown();
    for want in [
        "## raycast",
        "## fft",
        "| timed | 4 | 2.00 s",
        "500 ms",
        "4.00×",
        "10.0 ms",
        "20.0 ms",
        "300 ms",
        "50.0×",
        "25.0×",
        "0.500 / 2.00 / 100 Mrays/s",
        "1.50 / 6.00 / 300 GFLOP/s",
        "**ERROR**: invalid size: too big for this test",
        "1 problem(s)",
        &r.machine.cpu_model,
    ] {
        assert!(md.contains(want), "'{want}' not in:\n{md}");
    }
    let j: serde_json::Value = serde_json::from_str(&r.to_json()).unwrap();
    let c = &j["cases"][0];
    assert_eq!(
        c["cpu_f64"]["seconds"]["samples"],
        serde_json::json!([2.0, 2.0, 2.0])
    );
    assert_eq!(c["gpu"]["kernel"]["median"], 0.01);
    assert_eq!(c["speedups"]["f32_over_gpu_kernel"], 50.0);
    assert_eq!(c["cpu_f32"]["status"], "passed");
    assert_eq!(
        j["cases"][1]["error"],
        "invalid size: too big for this test"
    );
    assert_eq!(j["suite"], "quick");
    assert!(j["machine"]["adapter"]["name"].is_string());
    // It reads back.
    let back: Report = serde_json::from_str(&r.to_json()).unwrap();
    assert_eq!(back.cases.len(), 3);
}

/// Checks that every tag opened is closed in order (a minimal XML well-formedness test).
fn assert_balanced(svg: &str) {
    let mut stack: Vec<String> = Vec::new();
    let mut rest = svg;
    while let Some(i) = rest.find('<') {
        let j = rest[i..].find('>').expect("an unclosed tag") + i;
        let tag = &rest[i + 1..j];
        assert!(!tag.contains('<'), "'<' inside a tag: {tag}");
        if let Some(name) = tag.strip_prefix('/') {
            assert_eq!(stack.pop().as_deref(), Some(name.trim()), "at </{name}>");
        } else if !tag.ends_with('/') {
            stack.push(tag.split_whitespace().next().unwrap().to_string());
        }
        rest = &rest[j + 1..];
    }
    assert!(stack.is_empty(), "unclosed: {stack:?}");
}

#[test]
fn the_chart_is_well_formed() {
    let Some(r) = timed_report() else { return };
    let svg = r.to_svg();
    assert!(svg.starts_with("<svg xmlns=\"http://www.w3.org/2000/svg\""));
    assert!(svg.trim_end().ends_with("</svg>"));
    assert_balanced(&svg);
    assert!(svg.contains("50.0×") && svg.contains("25.0×"), "{svg}");
    assert!(svg.contains(">raycast<") && svg.contains(">fft<"));
    assert!(svg.contains(&r.machine.adapter.as_ref().unwrap().name));
    // Without any GPU figure it is still well-formed.
    let mut none = r.clone();
    none.cases.truncate(0);
    assert_balanced(&none.to_svg());
}

#[test]
fn the_budget_cuts_slow_backends_short() {
    // 20 s per run, 5 asked, budget 30 s after 3 runs: 3 runs.
    let calls = counter();
    let c = calls.clone();
    let cases = vec![case("fdk", "slow", move || {
        prepared(cpu(&[20.0], &ORACLE, &c), None, None)
    })];
    let r = run_suite(cases, &opts(5), NO_GPU, &|_| {});
    assert_eq!(r.cases[0].cpu_f64.runs, 3);
    assert_eq!(calls.get(), 4, "one warm-up and three timed runs");
    assert_eq!(r.budget_seconds, 30.0);
}

#[test]
fn families_and_reports_on_disk() {
    assert_eq!(parse_families("raycast, fft").unwrap(), ["raycast", "fft"]);
    let e = parse_families("raycast,nonsense").unwrap_err().to_string();
    assert!(
        e.contains("'nonsense'") && e.contains(&FAMILIES.join(", ")),
        "{e}"
    );
    assert_eq!(slugify("NVIDIA H200"), "nvidia-h200");
    assert_eq!(
        slugify("llvmpipe (LLVM 15.0.6, 256 bits)"),
        "llvmpipe-llvm-15-0-6-256-bits"
    );

    let cases = vec![case("gradient", "disk", || {
        prepared(cpu(&[1.0], &ORACLE, &counter()), None, None)
    })];
    let r = run_suite(cases, &opts(1), NO_GPU, &|_| {});
    assert_eq!(r.default_slug(), "cpu-only");
    let dir = common::scratch("reports");
    let out = dir.join("nested/out");
    let paths = r.write(&out, "x").unwrap();
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(
        names,
        ["x.json", "x.md", "x.svg"],
        "no temporary files left"
    );
    assert_eq!(paths.len(), 3);
    // A file where the folder should be is refused, and nothing is written.
    let file = dir.join("a-file");
    std::fs::write(&file, "keep").unwrap();
    let e = r.write(&file, "x").unwrap_err().to_string();
    assert!(e.contains("is a file"), "{e}");
    assert!(r.write(&file.join("sub"), "x").is_err());
    assert_eq!(std::fs::read_to_string(&file).unwrap(), "keep");
}

#[test]
fn only_picks_families_and_case_prefixes() {
    use voxlab::bench::{parse_only, select_picks, Pick};
    let picks = parse_only("fft, raycast/mip").unwrap();
    assert_eq!(
        picks,
        [Pick::Family("fft"), Pick::Cases("raycast/mip".to_string())]
    );
    let make = || {
        vec![
            case("raycast", "mip-trilinear", || {
                prepared(cpu(&[1.0], &ORACLE, &counter()), None, None)
            }),
            case("raycast", "dvr", || {
                prepared(cpu(&[1.0], &ORACLE, &counter()), None, None)
            }),
            case("fft", "2d", || {
                prepared(cpu(&[1.0], &ORACLE, &counter()), None, None)
            }),
        ]
    };
    let ids: Vec<String> = select_picks(make(), Some(&picks))
        .unwrap()
        .iter()
        .map(|c| c.id())
        .collect();
    assert_eq!(ids, ["raycast/mip-trilinear 4", "fft/2d 4"]);
    // A prefix that matches nothing is an error, not an empty run.
    let none = parse_only("raycast/nothing").unwrap();
    let e = match select_picks(make(), Some(&none)) {
        Ok(_) => panic!("a prefix matching nothing was accepted"),
        Err(e) => e.to_string(),
    };
    assert!(
        e.contains("no case id starts with 'raycast/nothing'"),
        "{e}"
    );
    // The family part of a prefix is checked.
    assert!(parse_only("nonsense/x").is_err());
}

#[test]
fn merge_replaces_rerun_cases_and_keeps_the_rest_in_suite_order() {
    let run = |names: &[&'static str], seconds: f64| {
        let cases = names
            .iter()
            .map(|&n| {
                case("fdk", n, move || {
                    prepared(cpu(&[seconds], &ORACLE, &counter()), None, None)
                })
            })
            .collect();
        run_suite(cases, &opts(1), NO_GPU, &|_| {})
    };
    let mut old = run(&["a", "b"], 1.0);
    let newer = run(&["c", "b"], 2.0);
    let order: Vec<String> = ["a", "b", "c"]
        .iter()
        .map(|n| format!("fdk/{n} 4"))
        .collect();
    old.merge(newer, &order).unwrap();
    let got: Vec<(String, f64)> = old
        .cases
        .iter()
        .map(|c| (c.id(), c.cpu_f64.seconds.as_ref().unwrap().median))
        .collect();
    assert_eq!(
        got,
        [
            ("fdk/a 4".to_string(), 1.0),
            ("fdk/b 4".to_string(), 2.0),
            ("fdk/c 4".to_string(), 2.0)
        ]
    );
    assert_eq!(old.merged.len(), 1);
    assert_eq!(old.merged[0].cases, ["fdk/c 4", "fdk/b 4"]);
    assert!(old.to_markdown().contains("later run, merged"));
    // The report survives a JSON round trip with its merge history.
    let back: Report = serde_json::from_str(&old.to_json()).unwrap();
    assert_eq!(back, old);
    // Another machine's run is refused.
    let mut other = run(&["a"], 3.0);
    other.machine.cpu_model = "another CPU".into();
    let e = old.merge(other, &order).unwrap_err().to_string();
    assert!(e.contains("another CPU"), "{e}");
}

/// The roofline: on an adapter whose part is known, every GPU throughput in GFLOP/s or
/// GB/s is set against the data-sheet peak; on one that is not (lavapipe), the page
/// says there is no peak.
#[test]
fn the_roofline_sets_gpu_throughput_against_the_parts_peak() {
    let Some(mut r) = timed_report() else { return };
    // The adapter the test ran on: a software rasteriser, no peak.
    let adapter = r.machine.adapter.clone().unwrap();
    if adapter.peak.is_none() {
        assert!(r.cases[0]
            .gpu
            .throughput
            .iter()
            .all(|t| t.of_peak.is_none()));
        let md = r.to_markdown();
        assert!(md.contains("## Roofline"), "{md}");
        assert!(md.contains("is not in the table of GPUs"), "{md}");
    }
    // The same run as if on an H200 (4800 GB/s, 67 TFLOP/s FP32): 300 GFLOP/s is
    // 300 / 67,000 of the FP32 peak; rays have no peak.
    let a = r.machine.adapter.as_mut().unwrap();
    a.name = "NVIDIA H200".into();
    a.peak = Some(voxlab::bench::machine::AdapterPeak {
        part: "NVIDIA H200 (SXM, HBM3e)".into(),
        memory_gbps: 4800.0,
        fp32_tflops: 67.0,
    });
    r.apply_peak();
    let gpu = &r.cases[0].gpu.throughput;
    assert_eq!(gpu[0].of_peak, None);
    assert_eq!(gpu[1].of_peak, Some(300.0 / 67_000.0));
    // The CPU columns are never set against the GPU's peak.
    assert!(r.cases[0]
        .cpu_f32
        .throughput
        .iter()
        .all(|t| t.of_peak.is_none()));
    let md = r.to_markdown();
    for want in [
        "## Roofline",
        "NVIDIA H200 (SXM, HBM3e)'s data-sheet peaks: 4800 GB/s",
        "| raycast/timed | 4 | 10.0 ms | 300 GFLOP/s | 67000 GFLOP/s | 0.4 % |",
    ] {
        assert!(md.contains(want), "'{want}' not in:\n{md}");
    }
    let back: Report = serde_json::from_str(&r.to_json()).unwrap();
    assert_eq!(
        back.machine.adapter.unwrap().peak.unwrap().memory_gbps,
        4800.0
    );
}
