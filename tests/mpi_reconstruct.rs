//! `mpirun -n N voxlab reconstruct … --distributed` (feature `mpi`, OpenMPI's mpirun)
//! on 1–4 ranks against the single-process command: the output files are equal byte
//! for byte (FBP/FDK, from `.npy` and from a MetaImage read by lines; SIRT and CGLS on one rank, within rounding on more); a failure
//! on the ranks is one clear message and no file, in bounded time.
#![cfg(feature = "mpi")]

mod common;

use common::{mpirun, s, scratch, stderr, voxlab};
use std::path::Path;

fn ct(name: &str) -> String {
    common::ct_data(name).display().to_string()
}

fn same_file_on_every_rank_count(name: &str, dir: &Path, args: &[&str]) {
    let single = dir.join(format!("{name}-single.npy"));
    let mut one: Vec<&str> = vec!["reconstruct"];
    one.extend_from_slice(args);
    one.extend_from_slice(&["--out", s(&single)]);
    let o = voxlab(&one);
    assert!(o.status.success(), "{}", stderr(&o));
    let want = std::fs::read(&single).unwrap();
    for ranks in 1..=4 {
        let out = dir.join(format!("{name}-{ranks}.npy"));
        let mut many = one.clone();
        let n = many.len();
        many[n - 1] = s(&out);
        many.push("--distributed");
        let o = mpirun(ranks, &many);
        assert!(o.status.success(), "{name}, {ranks} ranks: {}", stderr(&o));
        let text = String::from_utf8_lossy(&o.stdout).into_owned();
        // Rank 0 reports every rank, once.
        assert_eq!(text.matches("rank 0:").count(), 1, "{text}");
        assert!(text.contains(&format!("rank {}:", ranks - 1)), "{text}");
        assert!(
            std::fs::read(&out).unwrap() == want,
            "{name}, {ranks} ranks: the files differ"
        );
    }
}

#[test]
fn one_to_four_mpi_ranks_write_the_single_process_file_byte_for_byte() {
    let dir = scratch("mpi-cases");
    same_file_on_every_rank_count(
        "rtk",
        &dir,
        &[
            &ct("rtk_joseph32.npy"),
            "--geometry",
            &ct("rtk_geometry.json"),
            "--size",
            "32",
            "--spacing",
            "2",
        ],
    );
    same_file_on_every_rank_count(
        "rtk-f32-27",
        &dir,
        &[
            &ct("rtk_joseph32.npy"),
            "--geometry",
            &ct("rtk_geometry.json"),
            "--size",
            "27",
            "--backend",
            "cpu-f32",
            "--filter",
            "hann",
        ],
    );
    // RTK's own projections as an uncompressed MetaImage (read by lines) with its XML
    // geometry, which takes the detector grid from the MetaImage's header.
    let mha = dir.join("rtk_tilted.mha");
    let o = voxlab(&["convert", &ct("rtk_tilted_ellipsoids.mha"), s(&mha)]);
    assert!(o.status.success(), "{}", stderr(&o));
    same_file_on_every_rank_count(
        "rtk-tilted-mha",
        &dir,
        &[
            s(&mha),
            "--geometry",
            &ct("rtk_tilted.xml"),
            "--size",
            "20",
            "--spacing",
            "4",
        ],
    );
}

#[test]
fn a_failure_on_the_ranks_is_one_message_and_no_file() {
    let dir = scratch("mpi-fail");
    let out = dir.join("never.npy");
    let missing = dir.join("missing.npy");
    let o = mpirun(
        3,
        &[
            "reconstruct",
            s(&missing),
            "--geometry",
            &ct("rtk_geometry.json"),
            "--out",
            s(&out),
            "--distributed",
        ],
    );
    assert!(!o.status.success());
    let e = stderr(&o);
    assert_eq!(e.matches("voxlab: error:").count(), 1, "{e}");
    assert!(
        e.contains("rank 0 of 3") && e.contains("missing.npy"),
        "{e}"
    );
    assert!(std::fs::read_dir(&dir).unwrap().next().is_none());
}

/// `max |Δ| / max |single|` of two float32 `.npy` files.
fn file_rel(a: &Path, b: &Path) -> f64 {
    let read = |p: &Path| -> Vec<f64> {
        let (_, v) = voxlab::io::npy::read_npy_f32(p).unwrap();
        v.into_iter().map(f64::from).collect()
    };
    common::max_rel(&read(a), &read(b))
}

/// SIRT and CGLS under mpirun on 1–4 ranks against the single-process command: one
/// rank writes the same file byte for byte; more ranks regroup the backprojection's
/// sums, within the bounds of tests/distributed_reconstruct.rs (measured there: f64
/// files equal or within 2.8e-13, f32 ≤ 7.3e-7).
fn iterative_on_every_rank_count(name: &str, dir: &Path, args: &[&str], bound: f64) {
    let single = dir.join(format!("{name}-single.npy"));
    let mut one: Vec<&str> = vec!["reconstruct"];
    one.extend_from_slice(args);
    one.extend_from_slice(&["--out", s(&single)]);
    let o = voxlab(&one);
    assert!(o.status.success(), "{}", stderr(&o));
    let want = std::fs::read(&single).unwrap();
    for ranks in 1..=4 {
        let out = dir.join(format!("{name}-{ranks}.npy"));
        let mut many = one.clone();
        let n = many.len();
        many[n - 1] = s(&out);
        many.push("--distributed");
        let o = mpirun(ranks, &many);
        assert!(o.status.success(), "{name}, {ranks} ranks: {}", stderr(&o));
        let text = String::from_utf8_lossy(&o.stdout).into_owned();
        assert_eq!(text.matches("rank 0: views 0..").count(), 1, "{text}");
        assert!(
            text.contains(&format!("rank {}: views", ranks - 1)),
            "{text}"
        );
        assert!(text.contains("residual ‖b − Ax‖"), "{text}");
        if ranks == 1 {
            assert!(
                std::fs::read(&out).unwrap() == want,
                "{name}: one rank differs"
            );
        } else {
            let rel = file_rel(&out, &single);
            assert!(rel <= bound, "{name}, {ranks} ranks: {rel:e} > {bound:e}");
        }
    }
}

#[test]
fn the_iterative_methods_on_one_to_four_mpi_ranks_follow_the_single_process_file() {
    let dir = scratch("mpi-iterative");
    // RTK's cone-beam example onto 24³ (spacing 2.5), then the method's flags.
    let (stack, geometry) = (ct("rtk_joseph32.npy"), ct("rtk_geometry.json"));
    // scikit-image's sinogram with its angles, then the method's flags.
    let (sino, theta) = (ct("skimage_radon64.npy"), ct("skimage_theta.txt"));
    let sinogram = |rest: &[&'static str]| {
        let mut v = vec![&sino[..], "--geometry", "parallel", "--angles", &theta];
        v.extend_from_slice(rest);
        v
    };
    let cone24 = |rest: &[&'static str]| {
        let mut v = vec![
            &stack[..],
            "--geometry",
            &geometry,
            "--size",
            "24",
            "--spacing",
            "2.5",
        ];
        v.extend_from_slice(rest);
        v
    };
    iterative_on_every_rank_count(
        "sirt-skimage",
        &dir,
        &sinogram(&["--method", "sirt", "--iterations", "6", "--nonnegative"]),
        1.2e-7,
    );
    iterative_on_every_rank_count(
        "cgls-cone-f32",
        &dir,
        &cone24(&[
            "--method",
            "cgls",
            "--iterations",
            "4",
            "--backend",
            "cpu-f32",
        ]),
        2e-6,
    );
    // OS-SART: every subset's update summed over the ranks.
    iterative_on_every_rank_count(
        "os-sart-cone",
        &dir,
        &cone24(&["--method", "os-sart", "--subsets", "4", "--iterations", "2"]),
        1.2e-7,
    );
    // TV: the power iteration's and every iteration's Aᵀ sums over the ranks.
    iterative_on_every_rank_count(
        "tv-skimage-f32",
        &dir,
        &sinogram(&[
            "--method",
            "tv",
            "--iterations",
            "5",
            "--backend",
            "cpu-f32",
        ]),
        2e-6,
    );
    // `--init fbp`: FDK in slabs first, all-reduced into the image every rank starts
    // from.
    iterative_on_every_rank_count(
        "sirt-from-fdk-cone",
        &dir,
        &cone24(&["--method", "sirt", "--init", "fbp", "--iterations", "3"]),
        1.2e-7,
    );
}
