//! `voxlab reconstruct --method sirt|cgls|os-sart|tv`: the command line gives the
//! library's iterates, writes the convergence log, reports the error against a phantom, and refuses
//! options that do not fit the method (with no output left behind).

mod common;

use common::{s, scratch, stderr, voxlab};
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
            vec!["--method", "cgls", "--backend", "gpu"],
            vec!["gpu", "cpu or cpu-f32"],
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
