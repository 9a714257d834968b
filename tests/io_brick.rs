//! Bricks read straight from a file (`io::brick`): each brick of a k-d tree, with and
//! without ghost voxels, equals the same box cut from the whole volume bit for bit,
//! with the affine moved to its first voxel, for every voxel type, from `.npy` and
//! raw NRRD (attached, detached, `byte skip: -1`) and MetaImage (`.mha`, `.mhd`);
//! compressed files are not random
//! access; the k-d bricks tile the volume.

mod common;

use common::{bits, oblique_affine, sample_volumes, scratch};
use glam::{DMat4, DVec3};
use std::path::{Path, PathBuf};
use voxlab::io::brick::{kd_bricks, raw_layout, read_brick, Brick};
use voxlab::io::metaimage::{write_metaimage, MetaImageWriteOptions};
use voxlab::io::npy::write_npy_volume;
use voxlab::io::nrrd::{write_nrrd, NrrdWriteOptions};
use voxlab::io::read_volume;
use voxlab::volume::{AnyVolume, Volume};

/// A larger volume than the samples, so that bricks have room: 9×7×6 of `f32`s.
fn larger(affine: DMat4) -> AnyVolume {
    let data: Vec<f32> = (0..9 * 7 * 6)
        .map(|i| (i as f32 * 0.37).sin() * 100.0)
        .collect();
    Volume::with_affine([9, 7, 6], affine, data).unwrap().into()
}

/// Every way this test writes `v` into `dir` as a random-access file.
fn files(dir: &Path, name: &str, v: &AnyVolume) -> Vec<PathBuf> {
    let npy = dir.join(format!("{name}.npy"));
    write_npy_volume(&npy, v).unwrap();
    let nrrd = dir.join(format!("{name}.nrrd"));
    write_nrrd(
        &nrrd,
        v,
        NrrdWriteOptions {
            gzip: false,
            detached: false,
        },
    )
    .unwrap();
    let nhdr = dir.join(format!("{name}.nhdr"));
    write_nrrd(
        &nhdr,
        v,
        NrrdWriteOptions {
            gzip: false,
            detached: true,
        },
    )
    .unwrap();
    let mut out = vec![npy, nrrd, nhdr];
    for ext in ["mha", "mhd"] {
        let mi = dir.join(format!("{name}-mi.{ext}"));
        write_metaimage(&mi, v, MetaImageWriteOptions { compress: false }).unwrap();
        out.push(mi);
    }
    out
}

fn check_bricks(path: &Path, n: usize, ghost: usize) {
    let whole = read_volume(path).unwrap();
    let layout = raw_layout(path).unwrap().expect("random access");
    assert_eq!(layout.dims, whole.dims(), "{}", path.display());
    let bricks = kd_bricks(whole.dims(), n).unwrap();
    assert_eq!(bricks.len(), n);
    for b in bricks {
        let b = b.with_ghost(ghost, whole.dims());
        let got = read_brick(&layout, &b, path).unwrap();
        let want = whole.crop(b.lo, b.hi).unwrap();
        assert_eq!(got.dims(), b.dims());
        assert_eq!(bits(&got), bits(&want), "{} {b:?}", path.display());
        // Voxel 0 of the brick sits where voxel `lo` of the whole does.
        let lo = DVec3::new(b.lo[0] as f64, b.lo[1] as f64, b.lo[2] as f64);
        let p = got.affine().transform_point3(DVec3::ZERO);
        let q = whole.affine().transform_point3(lo);
        assert!(
            (p - q).length() < 1e-9,
            "{} {b:?}: {p} vs {q}",
            path.display()
        );
    }
}

#[test]
fn bricks_equal_the_same_box_of_the_whole_volume() {
    let dir = scratch("brick-files");
    let mut volumes = sample_volumes(oblique_affine());
    volumes.push(larger(oblique_affine()));
    for (t, v) in volumes.iter().enumerate() {
        for path in files(&dir, &format!("v{t}"), v) {
            for n in 1..=5 {
                for ghost in [0, 1] {
                    check_bricks(&path, n, ghost);
                }
            }
        }
    }
}

/// A raw NRRD written by hand whose data is the last bytes of the file
/// (`byte skip: -1`, after some junk) and big-endian.
#[test]
fn a_raw_nrrd_with_byte_skip_minus_one_reads_by_bricks() {
    let dir = scratch("brick-skip");
    let path = dir.join("skip.nrrd");
    let values: Vec<u16> = (0..4 * 3 * 2).map(|i| (i * 2731) as u16).collect();
    let mut bytes = b"NRRD0004\ntype: uint16\ndimension: 3\nsizes: 4 3 2\n\
encoding: raw\nendian: big\nbyte skip: -1\n\n"
        .to_vec();
    bytes.extend_from_slice(b"junk before the data");
    for v in &values {
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    std::fs::write(&path, bytes).unwrap();
    for n in 1..=4 {
        check_bricks(&path, n, 0);
    }
    let layout = raw_layout(&path).unwrap().unwrap();
    let b = read_brick(
        &layout,
        &Brick {
            lo: [1, 1, 1],
            hi: [3, 3, 2],
        },
        &path,
    )
    .unwrap();
    // Voxel (i, j, k) holds values[i + 4 (j + 3 k)].
    let want: Vec<f64> = [(1, 1), (2, 1), (1, 2), (2, 2)]
        .iter()
        .map(|&(i, j)| values[i + 4 * (j + 3)] as f64)
        .collect();
    assert_eq!(b.values_f64(), want);
}

#[test]
fn compressed_and_fortran_files_are_not_random_access() {
    let dir = scratch("brick-none");
    let v = larger(DMat4::IDENTITY);
    let gz = dir.join("gz.nrrd");
    write_nrrd(&gz, &v, NrrdWriteOptions::default()).unwrap();
    assert!(raw_layout(&gz).unwrap().is_none());
    let zmha = dir.join("z.mha");
    write_metaimage(&zmha, &v, MetaImageWriteOptions { compress: true }).unwrap();
    assert!(raw_layout(&zmha).unwrap().is_none());
    let fortran = dir.join("f.npy");
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    let dict = "{'descr': '<f4', 'fortran_order': True, 'shape': (2, 3), }";
    let pad = 64 - (10 + dict.len() + 1) % 64;
    let header = format!("{dict}{}\n", " ".repeat(pad % 64));
    b.extend_from_slice(&(header.len() as u16).to_le_bytes());
    b.extend_from_slice(header.as_bytes());
    b.extend_from_slice(&[0u8; 24]);
    std::fs::write(&fortran, b).unwrap();
    assert!(raw_layout(&fortran).unwrap().is_none());
    assert!(raw_layout(Path::new("x.tif")).unwrap().is_none());
}

#[test]
fn bad_bricks_and_short_files_give_clear_errors() {
    let dir = scratch("brick-bad");
    let v = larger(DMat4::IDENTITY);
    let path = dir.join("v.npy");
    write_npy_volume(&path, &v).unwrap();
    let layout = raw_layout(&path).unwrap().unwrap();
    for b in [
        Brick {
            lo: [0, 0, 0],
            hi: [10, 7, 6],
        },
        Brick {
            lo: [3, 0, 0],
            hi: [3, 7, 6],
        },
    ] {
        let e = read_brick(&layout, &b, &path).unwrap_err().to_string();
        assert!(e.contains("v.npy") && e.contains("9×7×6"), "{e}");
    }
    // A file cut short: the layout itself is refused.
    let bytes = std::fs::read(&path).unwrap();
    let short = dir.join("short.npy");
    std::fs::write(&short, &bytes[..bytes.len() - 5]).unwrap();
    let e = raw_layout(&short).unwrap_err().to_string();
    assert!(e.contains("short.npy"), "{e}");
}

#[test]
fn kd_bricks_tile_the_volume_in_balanced_boxes() {
    for (dims, n) in [
        ([64, 64, 64], 8),
        ([100, 30, 7], 5),
        ([9, 7, 6], 3),
        ([1, 1, 7], 7),
    ] {
        let bricks = kd_bricks(dims, n).unwrap();
        assert_eq!(bricks.len(), n);
        let mut count = vec![0u8; dims.iter().product()];
        for b in &bricks {
            for k in b.lo[2]..b.hi[2] {
                for j in b.lo[1]..b.hi[1] {
                    for i in b.lo[0]..b.hi[0] {
                        count[i + dims[0] * (j + dims[1] * k)] += 1;
                    }
                }
            }
        }
        assert!(count.iter().all(|&c| c == 1), "{dims:?} into {n}");
        let sizes: Vec<usize> = bricks.iter().map(Brick::voxels).collect();
        let (lo, hi) = (sizes.iter().min().unwrap(), sizes.iter().max().unwrap());
        // Balanced: no brick more than twice another (exactly equal for 64³ into 8).
        assert!(*hi <= 2 * lo, "{dims:?} into {n}: {sizes:?}");
        if n == 8 {
            assert!(sizes.iter().all(|&s| s == 32 * 32 * 32));
        }
    }
    assert!(kd_bricks([2, 1, 1], 3).is_err());
    assert!(kd_bricks([4, 4, 4], 0).is_err());
}
