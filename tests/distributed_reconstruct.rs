//! The distributed reconstruction (`jobs::distributed`) on 1–4 ranks of an in-process
//! communicator (threads), against the single-process job: the output files are equal
//! byte for byte, each rank of a cone beam reads only its band of detector rows, and a
//! rank that fails makes every rank fail with its message, leaving no file behind.
//! (tests/mpi_reconstruct.rs runs the same job under mpirun.)

mod common;

use common::{on_thread_ranks, s, scratch, stderr, voxlab};
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

/// Runs `req` on `ranks` threads into `dir/ranks<N>.npy` (removed first).
fn into_file(
    dir: &Path,
    req: &ReconstructRequest,
    ranks: usize,
) -> (PathBuf, Vec<voxlab::Result<Distributed>>) {
    let out = dir.join(format!("ranks{ranks}.npy"));
    let _ = std::fs::remove_file(&out);
    let many = ReconstructRequest {
        out: Some(out.clone()),
        ..req.clone()
    };
    (out, on_ranks(&many, ranks, None))
}

use common::ct_data as ct;

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

/// The cone beam the cases project: 24 views of 37 rows × 40 columns.
const CONE: &[&str] = &[
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
];

/// The cases, each (name, request without `out`).
fn cases(dir: &Path) -> Vec<(&'static str, ReconstructRequest)> {
    let (cone, cone_g) = projected(dir, "cone", CONE);
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
    // RTK's example as a gzip NRRD: read whole by every rank; as a raw detached one:
    // read by lines.
    let nrrd = dir.join("rtk.nrrd");
    let stack = voxlab::io::read_volume(&ct("rtk_joseph32.npy")).unwrap();
    voxlab::io::nrrd::write_nrrd(&nrrd, &stack, Default::default()).unwrap();
    let nhdr = dir.join("rtk.nhdr");
    let raw = voxlab::io::nrrd::NrrdWriteOptions {
        gzip: false,
        detached: true,
    };
    voxlab::io::nrrd::write_nrrd(&nhdr, &stack, raw).unwrap();
    // RTK's own projections of ellipsoids (compressed MetaImage, a geometry XML that
    // needs the header's detector grid), uncompressed: read by lines.
    let rtk_mha = |case: &str| {
        let mha = dir.join(format!("rtk_{case}.mha"));
        let v = voxlab::io::read_volume(&ct(&format!("rtk_{case}_ellipsoids.mha"))).unwrap();
        let plain = voxlab::io::metaimage::MetaImageWriteOptions { compress: false };
        voxlab::io::metaimage::write_metaimage(&mha, &v, plain).unwrap();
        mha
    };
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
            "RTK's example from a raw NRRD, read by lines",
            ReconstructRequest {
                input: nhdr,
                geometry: geometry(&ct("rtk_geometry.json")),
                size: Some(32),
                spacing: Some(2.0),
                ..base()
            },
        ),
        (
            "RTK's circular scan from an uncompressed MetaImage and RTK's XML, read by lines",
            ReconstructRequest {
                input: rtk_mha("circular"),
                geometry: geometry(&ct("rtk_circular.xml")),
                size: Some(20),
                spacing: Some(4.0),
                ..base()
            },
        ),
        (
            "RTK's tilted scan from an uncompressed MetaImage and RTK's XML, read by lines, f32",
            ReconstructRequest {
                input: rtk_mha("tilted"),
                geometry: geometry(&ct("rtk_tilted.xml")),
                size: Some(20),
                spacing: Some(4.0),
                backend: Backend::CpuF32,
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
            let (out, results) = into_file(&dir, &req, ranks);
            for r in &results {
                assert!(r.is_ok(), "{name}, {ranks} ranks: {:?}", r.as_ref().err());
            }
            let got = std::fs::read(&out).unwrap();
            assert!(got == want, "{name}, {ranks} ranks: the files differ");
            let d = results[0].as_ref().unwrap();
            assert_eq!(d.ranks.len(), ranks);
            // A file read by lines: four ranks read fewer lines than the stack holds; a
            // file read whole: every rank reads all.
            if name.contains("read by lines") && ranks == 4 {
                assert!(
                    d.ranks.iter().all(|r| r.lines_read < d.total_lines),
                    "{name}: {}",
                    d.describe()
                );
            }
            if name.contains("read whole") {
                assert!(
                    d.ranks.iter().all(|r| r.lines_read == d.total_lines),
                    "{name}: {}",
                    d.describe()
                );
            }
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
                truth: Some("phantom:shepp-logan".into()),
                ..base.clone()
            },
            "--truth",
        ),
        (
            ReconstructRequest {
                method: voxlab::jobs::reconstruct::ReconstructMethod::Cgls,
                backend: Backend::Gpu,
                ..base.clone()
            },
            "ranks reconstruct on the CPU",
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

// ---------------------------------------------------------------------------------
// SIRT and CGLS on ranks: the views cut among the ranks, Aᵀ r summed by all-reduce
// ---------------------------------------------------------------------------------

/// The iterative cases, each (name, request without `out`): a few iterations of SIRT
/// (non-negative) and CGLS on scikit-image's 2-D sinogram (read whole by every rank)
/// and on RTK's cone-beam stack (each rank reads its views' lines).
fn iterative_cases() -> Vec<(&'static str, ReconstructRequest)> {
    use voxlab::jobs::reconstruct::Init;
    use voxlab::jobs::reconstruct::ReconstructMethod::{Cgls, OsSart, Sirt, Tv};
    let skimage = ReconstructRequest {
        input: ct("skimage_radon64.npy"),
        geometry: Some("parallel".into()),
        angles: Some(ct("skimage_theta.txt").display().to_string()),
        ..Default::default()
    };
    let cone = ReconstructRequest {
        input: ct("rtk_joseph32.npy"),
        geometry: Some(ct("rtk_geometry.json").display().to_string()),
        size: Some(24),
        spacing: Some(2.5),
        ..Default::default()
    };
    vec![
        (
            "scikit-image's sinogram, SIRT ≥ 0, 6 iterations",
            ReconstructRequest {
                method: Sirt,
                iterations: Some(6),
                nonnegative: true,
                ..skimage.clone()
            },
        ),
        (
            "scikit-image's sinogram, CGLS, 5 iterations",
            ReconstructRequest {
                method: Cgls,
                iterations: Some(5),
                ..skimage.clone()
            },
        ),
        (
            "RTK's cone-beam stack onto 24³, SIRT ≥ 0, 4 iterations",
            ReconstructRequest {
                method: Sirt,
                iterations: Some(4),
                nonnegative: true,
                ..cone.clone()
            },
        ),
        (
            "RTK's cone-beam stack onto 24³, CGLS, 4 iterations",
            ReconstructRequest {
                method: Cgls,
                iterations: Some(4),
                ..cone.clone()
            },
        ),
        // OS-SART: each subset's views are spread over the ranks (interleaved subsets
        // against contiguous runs of views), its update summed before the next subset.
        (
            "scikit-image's sinogram, OS-SART ≥ 0, 5 subsets, 3 iterations",
            ReconstructRequest {
                method: OsSart,
                iterations: Some(3),
                subsets: Some(5),
                nonnegative: true,
                ..skimage.clone()
            },
        ),
        (
            "RTK's cone-beam stack onto 24³, OS-SART, 3 random subsets, 3 iterations",
            ReconstructRequest {
                method: OsSart,
                iterations: Some(3),
                subsets: Some(3),
                subset_order: voxlab::cpu::iterative::SubsetOrder::Random,
                ..cone.clone()
            },
        ),
        // TV: ‖A‖'s power iteration and every Aᵀp summed over the ranks.
        (
            "scikit-image's sinogram, TV ≥ 0, 8 iterations",
            ReconstructRequest {
                method: Tv,
                iterations: Some(8),
                nonnegative: true,
                ..skimage.clone()
            },
        ),
        (
            "RTK's cone-beam stack onto 24³, TV, 6 iterations",
            ReconstructRequest {
                method: Tv,
                iterations: Some(6),
                ..cone.clone()
            },
        ),
        // `--init fbp`: FBP/FDK in slabs first, the slabs all-reduced into the image
        // every rank starts from.
        (
            "scikit-image's sinogram, SIRT from FBP (Hann), 3 iterations",
            ReconstructRequest {
                method: Sirt,
                iterations: Some(3),
                init: Init::Fbp,
                filter: voxlab::cpu::ramp::RampFilter::Hann,
                ..skimage.clone()
            },
        ),
        (
            "RTK's cone-beam stack onto 24³, CGLS from FDK, 3 iterations",
            ReconstructRequest {
                method: Cgls,
                iterations: Some(3),
                init: Init::Fbp,
                ..cone
            },
        ),
    ]
}

fn read_f32(p: &Path) -> Vec<f64> {
    let (_, v) = voxlab::io::npy::read_npy_f32(p).unwrap();
    v.into_iter().map(f64::from).collect()
}

/// `max |Δ| / max |single|` of the written files (float32), on 2–4 ranks, for the
/// f64 and the f32 backend. In f64 the file shows the images' difference (below) only
/// where it moves a value across an f32 rounding boundary (2⁻²⁴ of the value at
/// most) or where CGLS has amplified it. Measured on a 2-core x86-64, the eight cases:
/// f64 0 for SIRT, OS-SART, TV and the cone's CGLS, 2.8e-13 for CGLS on scikit-image's
/// sinogram (5 iterations); f32 ≤ 5.0e-7 (SIRT), ≤ 2.8e-7 (OS-SART), ≤ 1.9e-7 (TV),
/// ≤ 7.3e-7 (CGLS).
const FILE_F64_BOUND: f64 = 1.2e-7;
const FILE_F32_BOUND: f64 = 2e-6;

#[test]
fn the_iterative_methods_on_one_to_four_ranks_follow_the_single_process_file() {
    let dir = scratch("distributed-iterative");
    for (name, req) in iterative_cases() {
        for backend in [Backend::Cpu, Backend::CpuF32] {
            let req = ReconstructRequest {
                backend,
                ..req.clone()
            };
            let single = dir.join("single.npy");
            let _ = std::fs::remove_file(&single);
            let one = ReconstructRequest {
                out: Some(single.clone()),
                ..req.clone()
            };
            let solo =
                voxlab::jobs::reconstruct::run(&one, &()).unwrap_or_else(|e| panic!("{name}: {e}"));
            let solo_log = solo.iterative.unwrap();
            let want_bytes = std::fs::read(&single).unwrap();
            let want = read_f32(&single);
            for ranks in 1..=4 {
                let (out, results) = into_file(&dir, &req, ranks);
                let d = results[0]
                    .as_ref()
                    .unwrap_or_else(|e| panic!("{name}, {backend:?}, {ranks} ranks: {e}"));
                for r in &results {
                    assert!(r.is_ok(), "{name}, {ranks} ranks: {:?}", r.as_ref().err());
                }
                let log = d.iterative.as_ref().unwrap();
                assert_eq!(log.iterations, solo_log.iterations, "{name}");
                // Every rank ends with the same log.
                for r in &results[1..] {
                    let other = r.as_ref().unwrap().iterative.as_ref().unwrap();
                    assert_eq!(other.residual, log.residual, "{name}, {ranks} ranks");
                }
                // The views tile 0..n in rank order.
                let ends: Vec<(usize, usize)> = d
                    .ranks
                    .iter()
                    .map(|r| r.views.clone().map_or((0, 0), |v| (v.start, v.end)))
                    .collect();
                assert_eq!(ends[0].0, 0, "{name}");
                assert!(ends.windows(2).all(|w| w[0].1 == w[1].0), "{ends:?}");
                let got_bytes = std::fs::read(&out).unwrap();
                if ranks == 1 {
                    assert!(
                        got_bytes == want_bytes,
                        "{name}, {backend:?}: one rank differs"
                    );
                    assert_eq!(log.residual, solo_log.residual, "{name}");
                    assert_eq!(log.objective, solo_log.objective, "{name}");
                    continue;
                }
                let got = read_f32(&out);
                let rel = common::max_rel(&got, &want);
                let bound = if backend == Backend::Cpu {
                    FILE_F64_BOUND
                } else {
                    FILE_F32_BOUND
                };
                eprintln!("{name}, {backend:?}, {ranks} ranks: file max |Δ|/max = {rel:.2e}");
                assert!(
                    rel <= bound,
                    "{name}, {backend:?}, {ranks} ranks: {rel:e} > {bound:e}\n{}",
                    d.describe()
                );
                // The residuals follow too (their sums are regrouped as well).
                let last = *log.residual.last().unwrap();
                let solo_last = *solo_log.residual.last().unwrap();
                assert!(
                    ((last - solo_last) / solo_last).abs() < 1e-5,
                    "{name}: {last} vs {solo_last}"
                );
            }
        }
    }
    assert!(temp_files(&dir).is_empty(), "{:?}", temp_files(&dir));
}

/// The shared solver itself, in f64 and f32, against [`voxlab::cpu::iterative::solve`]:
/// the images in their own precision (the file tests above see them through the f32
/// output). A [`voxlab::cpu::iterative::Shares`] over thread ranks, each rank with the
/// pair of its views ([`voxlab::ct::Geometry::select_views`]).
struct CommShares<'a>(&'a dyn Comm);

impl voxlab::cpu::iterative::Shares for CommShares<'_> {
    fn count(&self) -> usize {
        self.0.size()
    }
    fn sum(&self, values: &mut [f64]) {
        self.0.all_reduce_sum(values)
    }
}

/// `max |x_ranks − x_single| / max |x_single|` over the 12 iterates of SIRT (≥ 0) and
/// CGLS, 2–4 ranks, measured on a 2-core x86-64:
///
/// | problem | SIRT f64 | SIRT f32 | CGLS f64 | CGLS f32 |
/// |---|---|---|---|---|
/// | RTK's cone beam (60 views) onto 20³ | 1.3e-15 | 6.9e-7 | 1.7e-15 | 5.8e-7 |
/// | scikit-image's sinogram (45 views) onto 64² | 6.4e-16 | 4.3e-7 | 1.5e-6 | 3.4e-3 |
///
/// SIRT's iteration is a contraction: the regrouped rounding stays at the precision's
/// level. CGLS on the 45-view sinogram (under-determined on the 64² disc) amplifies any
/// rounding change by about 8× per iteration (f64: 3e-15 at iteration 1, 1.5e-6 at
/// 12), in bursts that die away again (30 iterations: peaks of 6.6e-3 at iteration 15
/// and 1.3e-3 at 28, 2.8e-11 between, in f64); f32 against f64 on one process parts
/// the same way (docs/iterative.md). The cone's CGLS stays at rounding for 22
/// iterations, then grows too (2.9e-11 at 30).
const IMAGE_BOUNDS: [(&str, [f64; 4]); 2] = [
    ("cone", [5e-15, 2e-6, 5e-15, 2e-6]),
    ("skimage", [5e-15, 2e-6, 5e-6, 1e-2]),
];

fn shared_solver_case<R: voxlab::real::Real>(
    name: &str,
    g: &voxlab::ct::Geometry,
    dims: [usize; 3],
    affine: glam::DMat4,
    support: Option<&[bool]>,
    b: &[f64],
) {
    let f32_path = std::mem::size_of::<R>() == 4;
    let bounds = IMAGE_BOUNDS.iter().find(|(n, _)| *n == name).unwrap().1;
    use voxlab::cpu::iterative::{solve, solve_shared, IterativeOptions, Method, Problem};
    use voxlab::cpu::project::JosephPair;
    let n: usize = dims.iter().product();
    for (m, (method, nonnegative)) in [(Method::Sirt, true), (Method::Cgls, false)]
        .into_iter()
        .enumerate()
    {
        let bound = bounds[2 * m + usize::from(f32_path)];
        let opts = IterativeOptions {
            method,
            iterations: 12,
            nonnegative,
            ..Default::default()
        };
        let b_r: Vec<R> = b.iter().map(|&v| R::of(v)).collect();
        let pair = JosephPair::<R>::new(dims, affine, g).unwrap();
        let prob = Problem {
            pair: &pair,
            b: &b_r,
            support,
        };
        // Every iterate, as f64.
        let mut want: Vec<Vec<f64>> = Vec::new();
        let mut keep = |_: usize, x: &[R], _: f64| {
            want.push(x.iter().map(|v| v.f64()).collect());
            Ok(())
        };
        solve(&prob, vec![R::zero(); n], &opts, &mut keep).unwrap();
        for ranks in 1..=4 {
            let got = on_thread_ranks(ranks, |comm| {
                let nv = g.n_angles();
                let (r, m) = (comm.rank(), ranks);
                let views = r * nv / m..(r + 1) * nv / m;
                let per_view = g.rows * g.cols;
                let pair =
                    JosephPair::<R>::new(dims, affine, &g.select_views(views.clone()).unwrap())
                        .unwrap();
                let b_mine = &b_r[views.start * per_view..views.end * per_view];
                let prob = Problem {
                    pair: &pair,
                    b: b_mine,
                    support,
                };
                let shares = CommShares(comm);
                let mut iterates: Vec<Vec<f64>> = Vec::new();
                let mut keep = |_: usize, x: &[R], _: f64| {
                    iterates.push(x.iter().map(|v| v.f64()).collect());
                    Ok(())
                };
                solve_shared(&prob, vec![R::zero(); n], &opts, &shares, &mut keep).unwrap();
                iterates
            });
            for other in &got[1..] {
                assert!(other == &got[0], "{name}: the ranks' images differ");
            }
            let got = &got[0];
            assert_eq!(got.len(), want.len());
            let rels: Vec<f64> = got
                .iter()
                .zip(&want)
                .map(|(a, b)| common::max_rel(a, b))
                .collect();
            let rel = rels.iter().fold(0.0f64, |m, &v| m.max(v));
            eprintln!(
                "{name}, {method:?}, {}, {ranks} ranks: image max |Δ|/max per iteration = {}",
                std::any::type_name::<R>(),
                rels.iter()
                    .map(|r| format!("{r:.1e}"))
                    .collect::<Vec<_>>()
                    .join(" ")
            );
            if ranks == 1 {
                assert!(got == &want, "{name}, {method:?}: one rank differs");
            } else {
                assert!(rel <= bound, "{name}, {method:?}, {ranks} ranks: {rel:e}");
            }
        }
    }
}

#[test]
fn the_shared_solver_follows_the_single_process_one_in_f64_and_f32() {
    use voxlab::ct::Geometry;
    use voxlab::io::projections::read_projections;
    // scikit-image's sinogram onto its 64² grid, the inscribed disc as the support.
    let p = read_projections::<f64>(&ct("skimage_radon64.npy")).unwrap();
    let theta: Vec<f64> = std::fs::read_to_string(ct("skimage_theta.txt"))
        .unwrap()
        .split_whitespace()
        .map(|t| t.parse().unwrap())
        .collect();
    let g = Geometry::parallel_skimage(p.cols, theta).unwrap();
    let n = p.cols;
    let grid = voxlab::cpu::fbp::skimage_grid(n);
    let r = (n / 2) as i64;
    let disc: Vec<bool> = (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as i64 - r, (i / n) as i64 - r);
            x * x + y * y <= r * r
        })
        .collect();
    let (dims, affine) = (grid.dims, grid.affine);
    shared_solver_case::<f64>("skimage", &g, dims, affine, Some(&disc), &p.data);
    shared_solver_case::<f32>("skimage", &g, dims, affine, Some(&disc), &p.data);
    // RTK's cone beam onto a centred 20³ grid of 3 mm.
    let cone = read_projections::<f64>(&ct("rtk_joseph32.npy")).unwrap();
    let g = voxlab::io::projections::read_geometry(&ct("rtk_geometry.json")).unwrap();
    let grid = voxlab::cpu::fbp::rtk_grid([20; 3], [3.0; 3]);
    shared_solver_case::<f64>("cone", &g, grid.dims, grid.affine, None, &cone.data);
    shared_solver_case::<f32>("cone", &g, grid.dims, grid.affine, None, &cone.data);
}

/// A progress that asks to stop once `after` iterations have been reported.
struct StopAfter {
    after: u64,
    seen: std::sync::atomic::AtomicU64,
}
impl Progress for StopAfter {
    fn advance(&self, done: u64, _steps: u64) {
        self.seen.store(done, std::sync::atomic::Ordering::Relaxed);
    }
    fn cancelled(&self) -> bool {
        self.seen.load(std::sync::atomic::Ordering::Relaxed) >= self.after
    }
}

/// A rank that fails before the iterations (cancelled while its pair is built) or
/// within them (cancelled after the second) fails every rank with its message, at the
/// same point, and no file is left.
#[test]
fn a_failing_rank_fails_every_iterating_rank_and_leaves_no_file() {
    let dir = scratch("distributed-iterative-fail");
    let out = dir.join("never.npy");
    let (_, sirt) = iterative_cases().swap_remove(0);
    let req = ReconstructRequest {
        out: Some(out.clone()),
        ..sirt
    };
    for within in [false, true] {
        let results = on_thread_ranks(3, |comm| {
            let stop = StopAfter {
                after: if within { 2 } else { 0 },
                seen: Default::default(),
            };
            let progress: &dyn Progress = if comm.rank() == 1 { &stop } else { &() };
            distributed::run(&req, comm, progress)
        });
        for r in results {
            match r {
                Err(Error::Rank {
                    rank: 1,
                    ranks: 3,
                    message,
                }) => assert_eq!(message, "cancelled"),
                other => panic!("within {within}: {:?}", other.map(|d| d.describe())),
            }
        }
        assert!(!out.exists());
        assert!(temp_files(&dir).is_empty(), "{:?}", temp_files(&dir));
    }
    // More ranks than views: the last rank holds none and still takes part.
    let (two, _) = projected(
        &dir,
        "two",
        &["--geometry", "parallel", "--angles", "2", "--cols", "16"],
    );
    let few = ReconstructRequest {
        input: two,
        geometry: Some("parallel".into()),
        angles: Some("2".into()),
        method: voxlab::jobs::reconstruct::ReconstructMethod::Cgls,
        iterations: Some(3),
        out: Some(dir.join("single.npy")),
        ..Default::default()
    };
    voxlab::jobs::reconstruct::run(&few, &()).unwrap();
    let want = read_f32(&dir.join("single.npy"));
    let three = ReconstructRequest {
        out: Some(dir.join("three.npy")),
        ..few.clone()
    };
    let d = on_ranks(&three, 3, None).swap_remove(0).unwrap();
    assert_eq!(d.ranks[2].views, None, "{}", d.describe());
    assert!(
        d.describe().contains("rank 2: no views"),
        "{}",
        d.describe()
    );
    let rel = common::max_rel(&read_f32(&dir.join("three.npy")), &want);
    assert!(rel <= FILE_F64_BOUND, "{rel:e}");
    // The dry run of an iterative method plans the views the ranks then take.
    let text = distributed::dry_run(&three, 3, &()).unwrap();
    for want in [
        "dry run: reconstruct cgls (3 iterations) on 3 ranks",
        // A 2-D sinogram is read whole by every rank.
        "rank 0: views 0..1 (1), reads 2 lines",
        "rank 1: views 1..2 (1), reads 2 lines",
        "rank 2: no views (more ranks than views)",
        // The 16 × 16 image in f64 and three sums.
        "sends:  2.0 KiB per rank and iteration",
    ] {
        assert!(text.contains(want), "no '{want}' in:\n{text}");
    }
    for (r, rep) in d.ranks.iter().enumerate() {
        assert_eq!(rep.views, [Some(0..1), Some(1..2), None][r]);
        assert_eq!(rep.lines_read, [2, 2, 0][r]);
        // Every iteration's all-reduce, besides the set-up's sums and the reports.
        assert!(
            rep.bytes_sent >= 3 * (16 * 16 * 8 + 24),
            "{}",
            rep.bytes_sent
        );
    }
    // OS-SART sends one partial image per subset (its column weights, kept, once).
    let subsets = ReconstructRequest {
        method: voxlab::jobs::reconstruct::ReconstructMethod::OsSart,
        subsets: Some(2),
        out: Some(dir.join("os-sart.npy")),
        ..few.clone()
    };
    let text = distributed::dry_run(&subsets, 3, &()).unwrap();
    // Two 16 × 16 images in f64 and two sums: 4112 bytes.
    assert!(
        text.contains("sends:  4.0 KiB per rank and iteration"),
        "{text}"
    );
    let d = on_ranks(&subsets, 3, None).swap_remove(0).unwrap();
    for rep in &d.ranks {
        assert!(
            rep.bytes_sent >= 3 * (2 * 16 * 16 * 8 + 16),
            "{}",
            rep.bytes_sent
        );
    }
    // (The fbp plan itself names the iterative one.)
    let e = distributed::plan(&few, 3, &()).unwrap_err();
    assert!(e.to_string().contains("dry_run"), "{e}");
}

/// `--convergence` on ranks: rank 0 writes the log every rank holds, as one process
/// writes its own (on one rank, the same bytes); on three, the log the ranks report.
#[test]
fn the_ranks_write_the_convergence_log() {
    let dir = scratch("distributed-convergence");
    let (_, base) = iterative_cases().swap_remove(1);
    let single = ReconstructRequest {
        out: Some(dir.join("single.npy")),
        convergence: Some(dir.join("single.csv")),
        ..base.clone()
    };
    voxlab::jobs::reconstruct::run(&single, &()).unwrap();
    for ranks in [1, 3] {
        let csv = dir.join(format!("ranks{ranks}.csv"));
        let _ = std::fs::remove_file(&csv);
        let many = ReconstructRequest {
            out: Some(dir.join(format!("ranks{ranks}.npy"))),
            convergence: Some(csv.clone()),
            ..base.clone()
        };
        let d = on_ranks(&many, ranks, None).swap_remove(0).unwrap();
        let text = std::fs::read_to_string(&csv).unwrap();
        assert_eq!(text, d.iterative.as_ref().unwrap().csv(), "{ranks} ranks");
        assert_eq!(
            text.lines().count(),
            1 + 1 + 5,
            "header, x0 and 5 iterations"
        );
        if ranks == 1 {
            assert_eq!(
                text,
                std::fs::read_to_string(dir.join("single.csv")).unwrap()
            );
        }
    }
    assert!(temp_files(&dir).is_empty(), "{:?}", temp_files(&dir));
}

/// The all-reduce goes a chunk at a time (holding every rank's copy of one chunk, not
/// of the whole image): every chunk size gives the same bits, on every rank, as adding
/// the ranks' values in rank order (rank 0's first, so a −0 stays −0).
#[test]
fn the_chunked_all_reduce_adds_in_rank_order_whatever_the_chunk() {
    let n = 23;
    let value = |rank: usize, i: usize| -> f64 {
        if i == 5 {
            -0.0
        } else {
            ((rank * 7919 + i * 104_729) % 1000) as f64 * 0.1 - 37.3 + 1e-9 * i as f64
        }
    };
    let want: Vec<f64> = (0..n)
        .map(|i| (1..3).fold(value(0, i), |s, r| s + value(r, i)))
        .collect();
    assert!(want[5].is_sign_negative() && want[5] == 0.0);
    for chunk in [1, 3, 7, n, distributed::REDUCE_CHUNK] {
        let got = on_thread_ranks(3, |comm| {
            let mut v: Vec<f64> = (0..n).map(|i| value(comm.rank(), i)).collect();
            if chunk == distributed::REDUCE_CHUNK {
                comm.all_reduce_sum(&mut v);
            } else {
                distributed::all_reduce_sum_in_chunks(comm, &mut v, chunk);
            }
            v
        });
        for v in got {
            let same = v.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same, "chunk {chunk}: {v:?}");
        }
    }
}

/// `--init fbp` on ranks: the dry run names the slab plan of the FBP/FDK that comes
/// first, and each rank then reads its views' lines and its slab's.
#[test]
fn the_fbp_start_is_planned_and_read_by_slabs() {
    let dir = scratch("distributed-init");
    let (_, req) = iterative_cases().pop().unwrap();
    assert_eq!(req.init, voxlab::jobs::reconstruct::Init::Fbp);
    let req = ReconstructRequest {
        out: Some(dir.join("cgls.npy")),
        ..req
    };
    let text = distributed::dry_run(&req, 3, &()).unwrap();
    let fdk = ReconstructRequest {
        method: voxlab::jobs::reconstruct::ReconstructMethod::Fbp,
        init: voxlab::jobs::reconstruct::Init::Zero,
        iterations: None,
        ..req.clone()
    };
    let slabs = distributed::plan(&fdk, 3, &()).unwrap().slabs;
    let read: Vec<String> = slabs.lines.iter().map(|l| l.len().to_string()).collect();
    let want = format!(
        "start:  --init fbp, FBP/FDK in slabs along j (ranks read {} lines)",
        read.join(", ")
    );
    assert!(text.contains(&want), "no '{want}' in:\n{text}");
    let d = on_ranks(&req, 3, None).swap_remove(0).unwrap();
    let rows = 40;
    for (r, rep) in d.ranks.iter().enumerate() {
        let views = rep.views.as_ref().unwrap().len();
        assert_eq!(
            rep.lines_read,
            views * rows + slabs.lines[r].len(),
            "rank {r}"
        );
        assert!(rep.backproject_seconds > 0.0, "rank {r}");
    }
    assert!(d.describe().contains("FBP start"), "{}", d.describe());
}

/// A value that is not finite in the lines a rank reads fails every rank, naming the
/// file and where the value is, and leaves no file.
#[test]
fn a_nan_in_a_ranks_lines_is_named_by_view_row_and_column() {
    use voxlab::io::projections::{read_projections, write_projections, Layout};
    let dir = scratch("distributed-nan");
    let mut p = read_projections::<f64>(&ct("rtk_joseph32.npy")).unwrap();
    // View 5, row 20 (mid-detector: every rank of two reads it), column 7.
    let (rows, cols) = (p.rows, p.cols);
    p.data[(5 * rows + 20) * cols + 7] = f64::NAN;
    let bad = dir.join("nan.npy");
    write_projections(&bad, &p, Layout::Stack, None).unwrap();
    let out = dir.join("never.npy");
    let req = ReconstructRequest {
        input: bad.clone(),
        ..rtk(out.clone())
    };
    for r in on_ranks(&req, 2, None) {
        let e = r.unwrap_err().to_string();
        assert!(e.contains("nan.npy"), "{e}");
        assert!(e.contains("view 5, row 20, column 7 is NaN"), "{e}");
    }
    assert!(!out.exists());
    assert!(temp_files(&dir).is_empty(), "{:?}", temp_files(&dir));
}

/// Intensities with a flat and a dark field (`--flat`, `--dark`) on 1–4 ranks: each rank
/// converts only its lines, so FDK writes the single process's file byte for byte, from
/// a MetaImage read by lines and from a gzip NRRD read whole; SIRT too on one rank, and
/// with the views cut among the ranks their conversion counts add up to the single
/// process's.
#[test]
fn intensities_with_flat_and_dark_fields_on_ranks_are_the_single_process_file() {
    use voxlab::io::metaimage::{write_metaimage, MetaImageWriteOptions};
    use voxlab::volume::{AnyVolume, Volume};
    let dir = scratch("distributed-flat");
    let (cone, cone_g) = projected(&dir, "cone", CONE);
    let p = voxlab::io::projections::read_projections::<f64>(&cone).unwrap();
    let (a, r, c) = (p.angles, p.rows, p.cols);
    let pixels = r * c;
    let flat: Vec<f64> = (0..pixels)
        .map(|k| 4000.0 + 300.0 * ((k as f64) * 0.37).sin())
        .collect();
    let mut dark: Vec<f64> = (0..pixels).map(|k| 50.0 + (k % 13) as f64).collect();
    dark[3 * c + 5] = flat[3 * c + 5] + 1.0; // a dead pixel
                                             // Attenuation scaled to at most e⁻², so only the sample made so below is starved.
    let scale = 2.0 / p.data.iter().fold(0.0f64, |m, &v| m.max(v));
    let mut i: Vec<f64> = (0..a * pixels)
        .map(|n| {
            let (f, d) = (flat[n % pixels], dark[n % pixels]);
            d + (f - d) * (-scale * p.data[n]).exp()
        })
        .collect();
    i[5 * pixels + 20 * c + 7] = dark[20 * c + 7] - 3.0; // starved
    i[9 * pixels + 2 * c + 1] = flat[2 * c + 1] + 40.0; // above the flat
    let vol = |dims: [usize; 3], v: &[f64]| -> AnyVolume {
        let v: Vec<f32> = v.iter().map(|&x| x as f32).collect();
        Volume::new(dims, [1.0; 3], v).unwrap().into()
    };
    let mha = dir.join("i.mha");
    let plain = MetaImageWriteOptions { compress: false };
    write_metaimage(&mha, &vol([c, r, a], &i), plain).unwrap();
    let gz = dir.join("i.nrrd");
    voxlab::io::nrrd::write_nrrd(&gz, &vol([c, r, a], &i), Default::default()).unwrap();
    // Three flat frames averaging to `flat`; one dark image.
    let frames: Vec<f64> = [-2.0, 0.5, 1.5]
        .iter()
        .flat_map(|d| flat.iter().map(move |f| f + d))
        .collect();
    let flat_file = dir.join("flat.mha");
    write_metaimage(&flat_file, &vol([c, r, 3], &frames), plain).unwrap();
    let dark_file = dir.join("dark.mha");
    write_metaimage(&dark_file, &vol([c, r, 1], &dark), plain).unwrap();
    let with_fields = |input: &Path| ReconstructRequest {
        input: input.to_path_buf(),
        geometry: Some(cone_g.display().to_string()),
        size: Some(27),
        flat: Some(flat_file.clone()),
        dark: Some(dark_file.clone()),
        ..Default::default()
    };
    let sirt = |input: &Path| ReconstructRequest {
        method: voxlab::jobs::reconstruct::ReconstructMethod::Sirt,
        iterations: Some(3),
        ..with_fields(input)
    };
    for (name, req, by_lines) in [
        ("FDK from a MetaImage", with_fields(&mha), true),
        ("FDK from a gzip NRRD", with_fields(&gz), false),
        ("SIRT from a MetaImage", sirt(&mha), true),
    ] {
        let single = dir.join("single.npy");
        let one = ReconstructRequest {
            out: Some(single.clone()),
            ..req.clone()
        };
        let done =
            voxlab::jobs::reconstruct::run(&one, &()).unwrap_or_else(|e| panic!("{name}: {e}"));
        let want_counts = done.intensity.expect("converted");
        assert_eq!(
            (
                want_counts.dead_pixels,
                want_counts.starved,
                want_counts.above_flat
            ),
            (1, 1, 1),
            "{name}: {want_counts:?}"
        );
        let want = std::fs::read(&single).unwrap();
        let iterative = req.method.iterative().is_some();
        for ranks in 1..=4 {
            if iterative && ranks > 1 {
                continue;
            }
            let (out, results) = into_file(&dir, &req, ranks);
            let d = results[0]
                .as_ref()
                .unwrap_or_else(|e| panic!("{name}, {ranks} ranks: {e}"));
            assert!(
                std::fs::read(&out).unwrap() == want,
                "{name}, {ranks} ranks: the files differ"
            );
            let counts = d.intensity().expect("converted on the ranks");
            assert_eq!(
                (counts.pixels, counts.dead_pixels),
                (pixels, 1),
                "{name}: {counts:?}"
            );
            if iterative {
                assert_eq!(counts, want_counts, "{name}");
            }
            if by_lines && ranks == 4 && !iterative {
                assert!(d.ranks.iter().all(|r| r.lines_read < d.total_lines));
            }
        }
    }
    // The views cut among 3 ranks: each converts its own views once; the counts add
    // up to the single process's.
    let req = ReconstructRequest {
        out: Some(dir.join("sirt3.npy")),
        ..sirt(&mha)
    };
    let one = ReconstructRequest {
        out: Some(dir.join("sirt1.npy")),
        ..sirt(&mha)
    };
    let want = voxlab::jobs::reconstruct::run(&one, &()).unwrap().intensity;
    let results = on_ranks(&req, 3, None);
    assert_eq!(results[0].as_ref().unwrap().intensity(), want);
    // --dark without --flat is refused on the ranks as on one process.
    let req = ReconstructRequest {
        flat: None,
        out: Some(dir.join("never.npy")),
        ..with_fields(&mha)
    };
    for r in on_ranks(&req, 2, None) {
        let e = r.unwrap_err().to_string();
        assert!(e.contains("--dark") && e.contains("--flat"), "{e}");
    }
    assert!(!dir.join("never.npy").exists());
}
