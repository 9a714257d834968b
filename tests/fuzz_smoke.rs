//! A short, deterministic fuzz run of every in-memory reader, in the ordinary test
//! suite: each seed in `tests/corpus/seeds/<format>/` is truncated at every length and
//! mutated a few thousand times (bit flips, boundary bytes, inserted and deleted runs,
//! digits replaced by huge numbers), and the reader must answer every input with a
//! volume or an error, never a panic. The same entry points are the cargo-fuzz
//! targets in `fuzz/` (`bash scripts/fuzz.sh` runs those for longer). The CT geometry
//! readers (RTK's XML, ASTRA's and voxlab's JSON) get the same treatment from their
//! seeds in `tests/corpus/seeds/rtk_geometry/` and `astra_geometry/`.

mod common;

use common::Rng;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use voxlab::io::projections::{parse_geometry_bytes, DetectorGrid};
use voxlab::io::{read_volume_bytes, Format};

/// The formats with an in-memory reader, and the folder of their seeds.
const FORMATS: &[(Format, &str)] = &[
    (Format::Nrrd, "nrrd"),
    (Format::Npy, "npy"),
    (Format::Nifti, "nifti"),
    (Format::Pvm, "pvm"),
    (Format::Den, "den"),
    (Format::MetaImage, "metaimage"),
];

/// Mutations per seed.
const MUTATIONS: usize = 10_000;

fn mutate(seed: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..1 + rng.below(4) {
        let n = b.len();
        match rng.below(6) {
            0 if n > 0 => {
                let i = rng.below(n);
                b[i] ^= 1 << rng.below(8);
            }
            1 if n > 0 => {
                let i = rng.below(n);
                b[i] = [0u8, 0xff, 0x7f, 0x80, b'-', b'9'][rng.below(6)];
            }
            2 => {
                let i = rng.below(n + 1);
                let run: Vec<u8> = (0..1 + rng.below(16)).map(|_| rng.next() as u8).collect();
                b.splice(i..i, run);
            }
            3 if n > 0 => {
                let i = rng.below(n);
                let j = (i + 1 + rng.below(16)).min(n);
                b.drain(i..j);
            }
            4 => {
                // Replace a run of ASCII digits (a size, a count, an offset) by a huge
                // or negative number.
                let digits: Vec<usize> = (0..n).filter(|&i| b[i].is_ascii_digit()).collect();
                if !digits.is_empty() {
                    let i = digits[rng.below(digits.len())];
                    let mut j = i;
                    while j < b.len() && b[j].is_ascii_digit() {
                        j += 1;
                    }
                    let big: &[u8] = [
                        &b"18446744073709551617"[..],
                        b"4294967296",
                        b"-1",
                        b"0",
                        b"99999999",
                    ][rng.below(5)];
                    b.splice(i..j, big.iter().copied());
                }
            }
            _ if n > 0 => {
                // Overwrite four bytes with a boundary 32-bit value (binary headers).
                let i = rng.below(n);
                let v = [0u32, u32::MAX, i32::MAX as u32, 0x8000_0000, 348, 1 << 30][rng.below(6)];
                for (k, byte) in v.to_le_bytes().iter().enumerate() {
                    if i + k < b.len() {
                        b[i + k] = *byte;
                    }
                }
            }
            _ => {}
        }
    }
    b
}

fn seeds(dir: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/corpus/seeds")
        .join(dir);
    let mut v: Vec<(PathBuf, Vec<u8>)> = std::fs::read_dir(&root)
        .unwrap_or_else(|e| panic!("{}: {e}", root.display()))
        .map(|e| e.unwrap().path())
        .map(|p| {
            let bytes = std::fs::read(&p).unwrap();
            (p, bytes)
        })
        .collect();
    v.sort();
    assert!(!v.is_empty(), "no seeds in {}", root.display());
    v
}

fn must_not_panic(format: Format, bytes: &[u8], what: &str) -> bool {
    let r = catch_unwind(AssertUnwindSafe(|| {
        let path = Path::new("fuzz.bin");
        let whole = read_volume_bytes(bytes, format, path).is_ok();
        // A file of several 3-D volumes is read one at a time: frame 1 too.
        let frame = voxlab::io::read_volume_bytes_frame(bytes, format, path, Some(1)).is_ok();
        whole || frame
    }));
    match r {
        Ok(ok) => ok,
        Err(_) => {
            let hex: String = bytes.iter().take(512).map(|b| format!("{b:02x}")).collect();
            panic!(
                "{} reader panicked on {what} ({} bytes): {hex}",
                format.name(),
                bytes.len()
            )
        }
    }
}

#[test]
fn readers_answer_every_mutation_with_a_volume_or_an_error() {
    // The panic hook would print every caught panic; the assertion says enough.
    for &(format, dir) in FORMATS {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let (mut ok, mut err) = (0usize, 0usize);
        for (path, seed) in seeds(dir) {
            assert!(
                must_not_panic(format, &seed, "the seed itself"),
                "seed {} does not read",
                path.display()
            );
            for len in 0..seed.len() {
                must_not_panic(format, &seed[..len], &format!("truncation to {len}"));
            }
            for m in 0..MUTATIONS {
                let bytes = mutate(&seed, &mut rng);
                if must_not_panic(
                    format,
                    &bytes,
                    &format!("mutation {m} of {}", path.display()),
                ) {
                    ok += 1;
                } else {
                    err += 1;
                }
            }
        }
        // The mutations must reach the parsers' error paths and not only one branch.
        assert!(
            err > 0 && ok + err > 0,
            "{}: {ok} read, {err} refused",
            format.name()
        );
    }
}

/// Reads `bytes` as a geometry file (any format, with a detector grid for RTK's XML, as
/// the fuzz targets `rtk_geometry` and `astra_geometry` do); panics on a panic.
fn geometry_must_not_panic(bytes: &[u8], what: &str) -> bool {
    let r = catch_unwind(AssertUnwindSafe(|| {
        let path = Path::new("fuzz.geometry");
        let grid = DetectorGrid::centred(24, 20, 4.0, 3.5);
        match parse_geometry_bytes(bytes, path, Some(&grid)) {
            Ok(g) => {
                let _ = g.into_geometry(path);
                true
            }
            Err(_) => false,
        }
    }));
    match r {
        Ok(ok) => ok,
        Err(_) => panic!(
            "geometry reader panicked on {what} ({} bytes): {}",
            bytes.len(),
            String::from_utf8_lossy(&bytes[..bytes.len().min(2048)])
        ),
    }
}

#[test]
fn geometry_readers_answer_every_mutation_with_a_geometry_or_an_error() {
    for dir in ["rtk_geometry", "astra_geometry"] {
        let mut rng = Rng(0x2545_f491_4f6c_dd1d);
        let (mut ok, mut err) = (0usize, 0usize);
        for (path, seed) in seeds(dir) {
            assert!(
                geometry_must_not_panic(&seed, "the seed itself"),
                "seed {} does not read",
                path.display()
            );
            for len in 0..seed.len() {
                geometry_must_not_panic(&seed[..len], &format!("truncation to {len}"));
            }
            for m in 0..MUTATIONS {
                let bytes = mutate(&seed, &mut rng);
                if geometry_must_not_panic(&bytes, &format!("mutation {m} of {}", path.display())) {
                    ok += 1;
                } else {
                    err += 1;
                }
            }
        }
        assert!(ok > 0 && err > 0, "{dir}: {ok} read, {err} refused");
    }
}
