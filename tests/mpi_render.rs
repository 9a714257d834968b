//! `mpirun -n N voxlab render … --distributed` (feature `mpi`, OpenMPI's mpirun) on
//! 1–4 ranks against the single-process command: the MIP file is equal byte for byte,
//! the DVR image within the f64 bound of tests/distributed_render.rs; a failure on the
//! ranks is one clear message and no file, in bounded time.
#![cfg(feature = "mpi")]

mod common;

use voxlab::metrics::max_abs_error;

use common::{brick_test_volume, mpirun, mpirun_env, s, scratch, stderr, voxlab};
use voxlab::io::npy::read_npy_f32;

#[test]
fn one_to_four_mpi_ranks_render_the_single_process_image() {
    let dir = scratch("mpi-render");
    let file = brick_test_volume(&dir);
    for (name, mode, exact) in [("mip", "mip", true), ("dvr", "dvr", false)] {
        let single = dir.join(format!("{name}-single.npy"));
        let args = [
            "render",
            s(&file),
            "--mode",
            mode,
            "--width",
            "40",
            "--height",
            "32",
            "--azimuth",
            "70",
            "--ert",
            "1",
            "--out",
        ];
        let mut one: Vec<&str> = args.to_vec();
        one.push(s(&single));
        let o = voxlab(&one);
        assert!(o.status.success(), "{}", stderr(&o));
        let want = std::fs::read(&single).unwrap();
        let (_, want_values) = read_npy_f32(&single).unwrap();
        for ranks in 1..=4 {
            let out = dir.join(format!("{name}-{ranks}.npy"));
            let mut many = args.to_vec();
            many.push(s(&out));
            many.push("--distributed");
            let o = mpirun(ranks, &many);
            assert!(o.status.success(), "{name}, {ranks} ranks: {}", stderr(&o));
            let text = String::from_utf8_lossy(&o.stdout).into_owned();
            assert_eq!(text.matches("rank 0:").count(), 1, "{text}");
            assert!(text.contains(&format!("rank {}:", ranks - 1)), "{text}");
            if exact {
                assert!(
                    std::fs::read(&out).unwrap() == want,
                    "{name}, {ranks} ranks"
                );
            } else {
                let (_, got) = read_npy_f32(&out).unwrap();
                let worst = max_abs_error(&got, &want_values);
                // f64 pixels written as f32: at most one rounding apart.
                assert!(worst <= 1e-7, "{name}, {ranks} ranks: {worst:e}");
            }
        }
    }
}

#[test]
fn a_failed_distributed_render_is_one_message_and_no_file() {
    let dir = scratch("mpi-render-fail");
    let out = dir.join("never.png");
    let missing = dir.join("missing.nrrd");
    let o = mpirun(
        3,
        &["render", s(&missing), "--out", s(&out), "--distributed"],
    );
    assert!(!o.status.success());
    let e = stderr(&o);
    assert_eq!(e.matches("voxlab: error:").count(), 1, "{e}");
    assert!(
        e.contains("rank 0 of 3") && e.contains("missing.nrrd"),
        "{e}"
    );
    assert!(std::fs::read_dir(&dir).unwrap().next().is_none());
}

/// A rank that never answers (stalled on purpose) does not hang the job: the others
/// give up after `VOXLAB_MPI_TIMEOUT` seconds in their collective, saying so.
#[test]
fn a_stuck_rank_ends_the_job_after_the_collective_timeout() {
    let dir = scratch("mpi-render-stuck");
    let out = dir.join("never.png");
    let start = std::time::Instant::now();
    let o = mpirun_env(
        3,
        &[
            "render",
            "phantom:sphere:16",
            "--out",
            s(&out),
            "--distributed",
        ],
        &[("VOXLAB_MPI_TIMEOUT", "2"), ("VOXLAB_MPI_STALL_RANK", "1")],
    );
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("no answer from the other ranks after 2 s in all_gather"),
        "{e}"
    );
    assert!(start.elapsed().as_secs() < 60, "{:?}", start.elapsed());
    assert!(!out.exists());
}
