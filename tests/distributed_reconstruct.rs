//! The distributed reconstruction (`jobs::distributed`) on 1–4 ranks of an in-process
//! communicator (threads), against the single-process job: the output files are equal
//! byte for byte, each rank of a cone beam reads only its band of detector rows, and a
//! rank that fails makes every rank fail with its message, leaving no file behind.
//! (tests/mpi_reconstruct.rs runs the same job under mpirun.)

mod common;

use common::{on_thread_ranks, root, s, scratch, stderr, voxlab};
use std::path::{Path, PathBuf};
use voxlab::jobs::distributed::{self, Comm, Distributed};
use voxlab::jobs::reconstruct::ReconstructRequest;
use voxlab::jobs::{Backend, Progress};
use voxlab::Error;

/// A progress whose `cancelled` is true: the way a test makes one rank fail.
struct Stop;
impl Progress for Stop {
    fn cancelled(&self) -> bool {
        true
    }
}

/// Runs the request on `ranks` threads; rank `failing` (if any) is cancelled.
fn on_ranks(
    req: &ReconstructRequest,
    ranks: usize,
    failing: Option<usize>,
) -> Vec<voxlab::Result<Distributed>> {
    on_thread_ranks(ranks, |comm| {
        let progress: &dyn Progress = if failing == Some(comm.rank()) {
            &Stop
        } else {
            &()
        };
        distributed::run(req, comm, progress)
    })
}

fn ct(name: &str) -> PathBuf {
    root().join("tests/data/ct").join(name)
}

/// FDK of RTK's example (32³, 2 mm) into `out`.
fn rtk(out: PathBuf) -> ReconstructRequest {
    ReconstructRequest {
        input: ct("rtk_joseph32.npy"),
        geometry: Some(ct("rtk_geometry.json").display().to_string()),
        size: Some(32),
        spacing: Some(2.0),
        out: Some(out),
        ..Default::default()
    }
}

/// A projection file made by `voxlab project phantom:sphere` with `args`.
fn projected(dir: &Path, name: &str, args: &[&str]) -> (PathBuf, PathBuf) {
    let proj = dir.join(format!("{name}.npy"));
    let mut all = vec!["project", "phantom:sphere"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--out", s(&proj)]);
    let o = voxlab(&all);
    assert!(o.status.success(), "{}", stderr(&o));
    (proj.clone(), dir.join(format!("{name}.geometry.json")))
}

/// Files in `dir` whose names start with `.` (the temporary files of outputs).
fn temp_files(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.starts_with('.'))
        .collect()
}

/// The cases, each (name, request without `out`).
fn cases(dir: &Path) -> Vec<(&'static str, ReconstructRequest)> {
    let (cone, cone_g) = projected(
        dir,
        "cone",
        &[
            "--geometry",
            "cone",
            "--angles",
            "24",
            "--cols",
            "40",
            "--rows",
            "37",
            "--du",
            "8",
        ],
    );
    let (short, short_g) = projected(
        dir,
        "short",
        &[
            "--geometry",
            "cone",
            "--angles",
            "35",
            "--range",
            "210",
            "--cols",
            "32",
            "--rows",
            "32",
            "--du",
            "8",
        ],
    );
    let (par, _) = projected(
        dir,
        "parallel",
        &[
            "--geometry",
            "parallel",
            "--angles",
            "30",
            "--cols",
            "33",
            "--rows",
            "7",
        ],
    );
    // RTK's example as NRRD: read whole by every rank.
    let nrrd = dir.join("rtk.nrrd");
    let stack = voxlab::io::read_volume(&ct("rtk_joseph32.npy")).unwrap();
    voxlab::io::nrrd::write_nrrd(&nrrd, &stack, Default::default()).unwrap();
    let geometry = |p: &Path| Some(p.display().to_string());
    let base = ReconstructRequest::default;
    vec![
        (
            "RTK's example, f64",
            ReconstructRequest {
                input: ct("rtk_joseph32.npy"),
                geometry: geometry(&ct("rtk_geometry.json")),
                size: Some(32),
                spacing: Some(2.0),
                ..base()
            },
        ),
        (
            "RTK's example, f32",
            ReconstructRequest {
                input: ct("rtk_joseph32.npy"),
                geometry: geometry(&ct("rtk_geometry.json")),
                size: Some(32),
                spacing: Some(2.0),
                backend: Backend::CpuF32,
                ..base()
            },
        ),
        (
            "a cone beam with 37 rows onto 27³, hann",
            ReconstructRequest {
                input: cone,
                geometry: geometry(&cone_g),
                size: Some(27),
                filter: voxlab::cpu::ramp::RampFilter::Hann,
                ..base()
            },
        ),
        (
            "a short scan with Parker's weights, f32",
            ReconstructRequest {
                input: short,
                geometry: geometry(&short_g),
                size: Some(20),
                short_scan: true,
                backend: Backend::CpuF32,
                ..base()
            },
        ),
        (
            "RTK's example from NRRD, read whole",
            ReconstructRequest {
                input: nrrd,
                geometry: geometry(&ct("rtk_geometry.json")),
                size: Some(32),
                spacing: Some(2.0),
                ..base()
            },
        ),
        (
            "scikit-image's sinogram, one image cut along j",
            ReconstructRequest {
                input: ct("skimage_radon64.npy"),
                geometry: Some("parallel".into()),
                angles: Some(ct("skimage_theta.txt").display().to_string()),
                ..base()
            },
        ),
        (
            "a parallel stack of 7 rows, circle",
            ReconstructRequest {
                input: par.clone(),
                geometry: Some("parallel".into()),
                angles: Some("30".into()),
                ..base()
            },
        ),
        (
            "a parallel stack of 7 rows, no circle",
            ReconstructRequest {
                input: par,
                geometry: Some("parallel".into()),
                angles: Some("30".into()),
                no_circle: true,
                ..base()
            },
        ),
    ]
}

#[test]
fn one_to_four_ranks_write_the_single_process_file_byte_for_byte() {
    let dir = scratch("distributed-cases");
    for (name, req) in cases(&dir) {
        let single = dir.join("single.npy");
        let _ = std::fs::remove_file(&single);
        let one = ReconstructRequest {
            out: Some(single.clone()),
            ..req.clone()
        };
        voxlab::jobs::reconstruct::run(&one, &()).unwrap_or_else(|e| panic!("{name}: {e}"));
        let want = std::fs::read(&single).unwrap();
        for ranks in 1..=4 {
            let out = dir.join(format!("ranks{ranks}.npy"));
            let _ = std::fs::remove_file(&out);
            let many = ReconstructRequest {
                out: Some(out.clone()),
                ..req.clone()
            };
            let results = on_ranks(&many, ranks, None);
            for r in &results {
                assert!(r.is_ok(), "{name}, {ranks} ranks: {:?}", r.as_ref().err());
            }
            let got = std::fs::read(&out).unwrap();
            assert!(got == want, "{name}, {ranks} ranks: the files differ");
            let d = results[0].as_ref().unwrap();
            assert_eq!(d.ranks.len(), ranks);
            // Every grid here has at least four slices along one axis: all ranks work.
            assert!(
                d.ranks.iter().all(|r| r.slab.is_some()),
                "{name}: {}",
                d.describe()
            );
            // The slabs tile the grid along their axis, in rank order.
            let ends: Vec<(usize, usize)> = d
                .ranks
                .iter()
                .filter_map(|r| r.slab.as_ref())
                .map(|s| {
                    if d.axis == 1 {
                        (s.j.start, s.j.end)
                    } else {
                        (s.k.start, s.k.end)
                    }
                })
                .collect();
            assert_eq!(ends.first().map(|e| e.0), Some(0), "{name}");
            assert_eq!(
                ends.last().map(|e| e.1),
                Some(d.grid.dims[d.axis]),
                "{name}"
            );
            assert!(
                ends.windows(2).all(|w| w[0].1 == w[1].0),
                "{name}: {ends:?}"
            );
        }
        assert!(
            temp_files(&dir).is_empty(),
            "{name}: {:?}",
            temp_files(&dir)
        );
    }
}

/// A cone beam whose rotation axis is the grid's j axis is cut along j, and every rank
/// of four reads well under half of the detector lines (its band and the partners).
#[test]
fn cone_beam_ranks_read_only_their_band_of_rows() {
    let dir = scratch("distributed-band");
    let out = dir.join("fdk.npy");
    let req = rtk(out);
    let results = on_ranks(&req, 4, None);
    let d = results[0].as_ref().unwrap();
    assert_eq!(d.axis, 1, "{}", d.describe());
    for (r, rep) in d.ranks.iter().enumerate() {
        assert!(
            rep.lines_read * 2 < d.total_lines,
            "rank {r}: {} of {} lines\n{}",
            rep.lines_read,
            d.total_lines,
            d.describe()
        );
    }
    // Five agreements of one f64 each; rank 0 also sends the temporary file's name
    // (its length, 8 bytes, then the name).
    for rep in &d.ranks[1..] {
        assert_eq!(rep.bytes_sent, 5 * 8);
    }
    assert!(d.ranks[0].bytes_sent > 5 * 8 + 8 + "fdk.npy".len() as u64);
    // One rank reads the rows the whole grid needs (those the 32³ volume projects
    // onto, 2160 of 2400 here), more than any rank of four.
    let solo = on_ranks(&req, 1, None);
    let solo = solo[0].as_ref().unwrap();
    assert!(solo.ranks[0].lines_read <= solo.total_lines);
    assert!(d
        .ranks
        .iter()
        .all(|r| r.lines_read < solo.ranks[0].lines_read));
}

#[test]
fn a_failing_rank_fails_every_rank_with_its_message_and_leaves_no_file() {
    let dir = scratch("distributed-fail");
    let out = dir.join("never.npy");
    let req = rtk(out.clone());
    let results = on_ranks(&req, 3, Some(2));
    for r in results {
        match r {
            Err(Error::Rank {
                rank: 2,
                ranks: 3,
                message,
            }) => assert_eq!(message, "cancelled"),
            other => panic!("{:?}", other.map(|d| d.describe())),
        }
    }
    assert!(!out.exists());
    assert!(temp_files(&dir).is_empty(), "{:?}", temp_files(&dir));
}

#[test]
fn what_it_does_not_take_is_refused_clearly() {
    let dir = scratch("distributed-refused");
    let base = ReconstructRequest {
        input: ct("rtk_joseph32.npy"),
        geometry: Some(ct("rtk_geometry.json").display().to_string()),
        size: Some(32),
        out: Some(dir.join("x.npy")),
        ..Default::default()
    };
    let cases = [
        (
            ReconstructRequest {
                method: voxlab::jobs::reconstruct::ReconstructMethod::Sirt,
                ..base.clone()
            },
            "only --method fbp",
        ),
        (
            ReconstructRequest {
                backend: Backend::Gpu,
                ..base.clone()
            },
            "ranks reconstruct on the CPU",
        ),
        (
            ReconstructRequest {
                out: Some(dir.join("x.nrrd")),
                ..base.clone()
            },
            "one .npy file",
        ),
        (
            ReconstructRequest {
                input: dir.join("missing.npy"),
                ..base.clone()
            },
            "missing.npy",
        ),
    ];
    for (req, words) in cases {
        let e = distributed::run(&req, &distributed::Solo, &()).unwrap_err();
        assert!(e.to_string().contains(words), "{e}");
    }
    assert!(std::fs::read_dir(&dir).unwrap().next().is_none());
}

/// Without the `mpi` feature, `--distributed` says how to get it.
#[cfg(not(feature = "mpi"))]
#[test]
fn the_command_line_without_mpi_says_how_to_build_it() {
    let dir = scratch("distributed-cli");
    let o = voxlab(&[
        "reconstruct",
        s(&ct("rtk_joseph32.npy")),
        "--geometry",
        s(&ct("rtk_geometry.json")),
        "--out",
        s(&dir.join("x.npy")),
        "--distributed",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--features mpi"), "{}", stderr(&o));
}

/// The dry run's plan is the one the ranks then follow, and it writes nothing.
#[test]
fn the_dry_run_plans_what_the_ranks_then_do() {
    let dir = scratch("distributed-plan");
    let out = dir.join("fdk.npy");
    let req = rtk(out.clone());
    let plan = distributed::plan(&req, 3, &()).unwrap();
    assert!(!out.exists());
    let text = plan.describe();
    assert!(text.contains("rank 2: j 21..32 (11264 voxels)"), "{text}");
    let done = on_ranks(&req, 3, None);
    let d = done[0].as_ref().unwrap();
    for (r, rep) in d.ranks.iter().enumerate() {
        assert_eq!(rep.slab, plan.slabs.slabs[r]);
        assert_eq!(rep.lines_read, plan.slabs.lines[r].len());
    }
    assert_eq!(std::fs::metadata(&out).unwrap().len(), plan.out_bytes);
    // More ranks than slices: the last ones get none.
    let many = distributed::plan(&req, 40, &()).unwrap();
    assert!(
        many.describe().contains("rank 39: no slab"),
        "{}",
        many.describe()
    );
    let o = voxlab(&[
        "reconstruct",
        s(&ct("rtk_joseph32.npy")),
        "--geometry",
        s(&ct("rtk_geometry.json")),
        "--size",
        "32",
        "--spacing",
        "2",
        "--out",
        s(&dir.join("cli.npy")),
        "--distributed",
        "--dry-run",
        "--ranks",
        "3",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        String::from_utf8_lossy(&o.stdout),
        text.replace("fdk.npy", "cli.npy")
    );
    assert!(!dir.join("cli.npy").exists());
}
