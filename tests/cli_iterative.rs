//! `voxlab reconstruct --method sirt|cgls|os-sart|tv`: the command line gives the
//! library's iterates, writes the convergence log, reports the error against a phantom, and refuses
//! options that do not fit the method (with no output left behind).

mod common;

use common::{max_rel, s, scratch, stderr, voxlab};
use voxlab::cpu::fbp::parallel_stack_grid;
use voxlab::cpu::iterative::{solve, IterativeOptions, Method, Problem};
use voxlab::cpu::project::JosephPair;
use voxlab::io::npy::read_npy_f64;
use voxlab::io::projections::read_geometry;

/// A 64-bin, 24-view sinogram of the Shepp–Logan phantom (and its geometry JSON).
fn sinogram(dir: &std::path::Path) -> std::path::PathBuf {
    let sino = dir.join("sino.npy");
    let o = voxlab(&[
        "project",
        "phantom:shepp-logan-modified:64",
        "--geometry",
        "parallel",
        "--angles",
        "24",
        "--cols",
        "64",
        "--du",
        "4",
        "--out",
        s(&sino),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    sino
}

fn rms_of(stdout: &str) -> f64 {
    stdout
        .lines()
        .find_map(|l| l.strip_prefix("RMS error against shepp-logan-modified: "))
        .and_then(|t| t.trim().parse().ok())
        .unwrap_or_else(|| panic!("{stdout}"))
}

#[test]
fn every_method_runs_and_the_cli_gives_the_librarys_iterates() {
    let d = scratch("cli-iterative");
    let sino = sinogram(&d);
    let mut rms = Vec::new();
    for m in ["fbp", "sirt", "cgls", "os-sart", "tv"] {
        let out = d.join(format!("{m}.npy"));
        let csv = d.join(format!("{m}.csv"));
        let mut args = vec![
            "reconstruct",
            s(&sino),
            "--method",
            m,
            "--out",
            s(&out),
            "--truth",
            "phantom:shepp-logan-modified",
        ];
        if m != "fbp" {
            args.extend(["--iterations", "40", "--convergence", s(&csv)]);
        }
        let o = voxlab(&args);
        assert!(o.status.success(), "{m}: {}", stderr(&o));
        let text = String::from_utf8_lossy(&o.stdout).to_string();
        rms.push(rms_of(&text));
        if m != "fbp" {
            assert!(text.contains("residual ‖b − Ax‖"), "{text}");
            let log = std::fs::read_to_string(&csv).unwrap();
            let lines: Vec<&str> = log.lines().collect();
            assert_eq!(lines[0], "iteration,residual,objective");
            assert_eq!(lines.len(), 42, "{m}: the initial image and 40 iterations");
            let res = |l: &str| l.split(',').nth(1).unwrap().parse::<f64>().unwrap();
            assert!(res(lines[41]) < 0.5 * res(lines[1]), "{m}: {log}");
        }
    }
    // A real error against the phantom for every method (TV's advantage over FBP is
    // tested in tests/iterative.rs, on a piecewise-constant phantom).
    assert!(rms.iter().all(|r| *r > 0.0 && *r < 0.5), "{rms:?}");

    // The SIRT image is the library's, on the sinogram as read, rounded to f32.
    let (shape, b, _) = read_npy_f64(&sino).unwrap();
    let (cols, angles) = (shape[0], shape[1]);
    let mut stack = vec![0.0; b.len()];
    for c in 0..cols {
        for k in 0..angles {
            stack[k * cols + c] = b[c * angles + k];
        }
    }
    let g = read_geometry(&d.join("sino.geometry.json")).unwrap();
    assert_eq!((g.cols, g.n_angles(), g.du), (cols, angles, 4.0));
    let grid = parallel_stack_grid(cols, &g);
    let pair = JosephPair::<f64>::new(grid.dims, grid.affine, &g).unwrap();
    let r = (cols / 2) as i64;
    let disc: Vec<bool> = (0..cols * cols)
        .map(|i| {
            let (x, y) = ((i % cols) as i64 - r, (i / cols) as i64 - r);
            x * x + y * y <= r * r
        })
        .collect();
    let prob = Problem {
        pair: &pair,
        b: &stack,
        support: Some(&disc),
    };
    let o = IterativeOptions {
        method: Method::Sirt,
        iterations: 40,
        ..Default::default()
    };
    let sol = solve(&prob, vec![0.0; cols * cols], &o, &mut |_, _, _| Ok(())).unwrap();
    let (_, cli, _) = read_npy_f64(&d.join("sirt.npy")).unwrap();
    for (a, c) in sol.x.iter().zip(&cli) {
        assert_eq!(*a as f32 as f64, *c);
    }
}

#[test]
fn options_that_do_not_fit_the_method_are_refused() {
    let d = scratch("cli-iterative-errors");
    let sino = sinogram(&d);
    let out = d.join("out.npy");
    for (extra, words) in [
        (
            vec!["--iterations", "5"],
            vec!["--iterations", "iterative --method"],
        ),
        (
            vec!["--method", "sirt", "--subsets", "4"],
            vec!["--subsets", "os-sart"],
        ),
        (
            vec!["--method", "os-sart", "--subsets", "99"],
            vec!["--subsets", "24"],
        ),
        (
            vec!["--method", "sirt", "--relaxation", "2.5"],
            vec!["--relaxation", "(0, 2)"],
        ),
        (
            vec!["--method", "cgls", "--nonnegative"],
            vec!["--nonnegative", "CGLS"],
        ),
        (
            vec!["--method", "sirt", "--short-scan"],
            vec!["--short-scan", "FDK"],
        ),
        (
            vec!["--method", "tv", "--tv-weight=-1"],
            vec!["--tv-weight"],
        ),
        (
            vec!["--method", "sirt", "--iterations", "0"],
            vec!["--iterations", "1 to"],
        ),
        (vec!["--method", "art"], vec!["method", "sirt"]),
        (
            vec!["--method", "sirt", "--convergence", "log.txt"],
            vec!["--convergence", "csv"],
        ),
    ] {
        let mut args = vec!["reconstruct", s(&sino), "--out", s(&out)];
        args.extend(extra.iter().copied());
        let o = voxlab(&args);
        assert!(!o.status.success(), "{args:?} succeeded");
        let e = stderr(&o);
        for w in &words {
            assert!(e.contains(w), "{args:?}: '{w}' not in {e}");
        }
        assert!(!out.exists(), "{args:?} left {}", out.display());
    }
}

/// The cases of `the_gpu_backend_follows_the_f64_oracle`: (name, projection flags,
/// reconstruction flags, bound on `max |x − x_f64| / max |x_f64|` for both f32 paths).
/// A parallel sinogram (measured on lavapipe: gpu 2.7e-6, cpu-f32 2.6e-6) and a cone
/// beam, a 24³ volume (gpu 4.46e-5, cpu-f32 4.45e-5: f32 cone-beam rays move samples
/// by ~1e-5 voxel, tests/gpu_ct_project.rs, and TV's steps carry that).
const GPU_CASES: [(&str, &[&str], &[&str], f64); 2] = [
    (
        "parallel",
        &["--angles", "24", "--cols", "64", "--du", "4"],
        &["--method", "sirt", "--iterations", "8", "--nonnegative"],
        1e-5,
    ),
    (
        "cone",
        &[
            "--geometry",
            "cone",
            "--angles",
            "24",
            "--cols",
            "32",
            "--rows",
            "24",
        ],
        &["--method", "tv", "--iterations", "6", "--size", "24"],
        2e-4,
    ),
];

#[test]
fn the_gpu_backend_follows_the_f64_oracle() {
    if common::gpu("cli_iterative gpu").is_none() {
        return;
    }
    let d = scratch("cli-iterative-gpu");
    for (name, proj, rec, bound) in GPU_CASES {
        let p = d.join(format!("{name}.npy"));
        let mut args = vec!["project", "phantom:shepp-logan-modified"];
        args.extend_from_slice(proj);
        args.extend_from_slice(&["--out", s(&p)]);
        let o = voxlab(&args);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let mut got = Vec::new();
        for backend in ["cpu", "gpu", "cpu-f32"] {
            let out = d.join(format!("{name}-{backend}.npy"));
            let csv = d.join(format!("{name}-{backend}.csv"));
            let mut args = vec!["reconstruct", s(&p)];
            args.extend_from_slice(rec);
            args.extend_from_slice(&[
                "--backend",
                backend,
                "--convergence",
                s(&csv),
                "--out",
                s(&out),
            ]);
            let o = voxlab(&args);
            assert!(o.status.success(), "{name} {backend}: {}", stderr(&o));
            let (_, x, _) = read_npy_f64(&out).unwrap();
            let log = std::fs::read_to_string(&csv).unwrap();
            let residuals: Vec<f64> = log
                .lines()
                .skip(1)
                .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
                .collect();
            got.push((
                x,
                residuals,
                String::from_utf8_lossy(&o.stdout).into_owned(),
            ));
        }
        let (cpu, gpu) = (&got[0], &got[1]);
        let e = max_rel(&gpu.0, &cpu.0);
        let er = max_rel(&gpu.1, &cpu.1);
        let e32 = max_rel(&got[2].0, &cpu.0);
        eprintln!("{name}: image {e:.2e} (cpu-f32 {e32:.2e}), residuals {er:.2e}");
        assert!(e <= bound, "{name}: image {e:e}");
        assert!(e32 <= bound, "{name}: cpu-f32 image {e32:e}");
        assert!(er <= 1e-5, "{name}: residuals {er:e}");
        assert!(
            cpu.1.last().unwrap() < &(0.5 * cpu.1[0]),
            "{name} converges"
        );
        assert!(gpu.2.contains("gpu"), "{name}: {}", gpu.2);
        // Past one binding (the cone's 24³ grid and 72 KiB of projections under a
        // 16 KiB binding): the pair in pieces, the iterations on the host in f32, the
        // same image within the same bound.
        if name == "cone" {
            let out = d.join(format!("{name}-split.npy"));
            let mut args = vec!["reconstruct", s(&p)];
            args.extend_from_slice(rec);
            args.extend_from_slice(&["--backend", "gpu", "--out", s(&out)]);
            let o = common::voxlab_with_binding(&args, Some("16KiB"));
            assert!(o.status.success(), "{name} split: {}", stderr(&o));
            let says = "GPU iterative: the pair in 4 slabs of 7 slices and 5 chunks of 5 views";
            assert!(stderr(&o).contains(says), "{}", stderr(&o));
            let (_, x, _) = read_npy_f64(&out).unwrap();
            let (es, ew) = (max_rel(&x, &cpu.0), max_rel(&x, &gpu.0));
            eprintln!("{name} split: image {es:.2e} (from the whole gpu {ew:.2e})");
            assert!(es <= bound, "{name} split: image {es:e}");
            assert!(ew <= bound, "{name} split against whole: {ew:e}");
            // The dry run plans that cut and writes nothing.
            let planned = d.join(format!("{name}-planned.npy"));
            let mut args = vec!["reconstruct", s(&p)];
            args.extend_from_slice(rec);
            args.extend_from_slice(&["--backend", "gpu", "--dry-run", "--out", s(&planned)]);
            let o = common::voxlab_with_binding(&args, Some("16KiB"));
            assert!(o.status.success(), "{name} dry run: {}", stderr(&o));
            let text = String::from_utf8_lossy(&o.stdout);
            assert!(text.contains(&format!("split:  {says}")), "{text}");
            assert!(!planned.exists());
        }
    }
}
