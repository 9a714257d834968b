//! Bricks read straight from a file (`io::brick`): each brick of a k-d tree, with and
//! without ghost voxels, equals the same box cut from the whole volume bit for bit,
//! with the affine moved to its first voxel, for every voxel type, from `.npy` and
//! raw NRRD (attached, detached, `byte skip: -1`) and MetaImage (`.mha`, `.mhd`);
//! compressed files are not random
//! access; the k-d bricks tile the volume. A projection stack in such a file is read
//! by detector lines (`io::projections::read_projection_lines`), each line the whole
//! stack's bit for bit.

mod common;

use common::{bits, oblique_affine, sample_volumes, scratch};
use glam::{DMat4, DVec3};
use std::path::{Path, PathBuf};
use voxlab::io::brick::{kd_bricks, raw_layout, read_brick, Brick};
use voxlab::io::metaimage::{write_metaimage, MetaImageWriteOptions};
use voxlab::io::npy::write_npy_volume;
use voxlab::io::nrrd::{write_nrrd, NrrdWriteOptions};
use voxlab::io::projections::{line_stack, read_projection_lines, read_projections_grid};
use voxlab::io::{read_volume, ReadOptions};
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

/// `dir/skip.nrrd`, written by hand: 4×3×2 big-endian u16 values (returned) as the
/// last bytes of the file (`byte skip: -1`, after some junk).
fn skip_nrrd(dir: &Path) -> (PathBuf, Vec<u16>) {
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
    (path, values)
}

/// A raw NRRD written by hand whose data is the last bytes of the file
/// (`byte skip: -1`, after some junk) and big-endian.
#[test]
fn a_raw_nrrd_with_byte_skip_minus_one_reads_by_bricks() {
    let (path, values) = skip_nrrd(&scratch("brick-skip"));
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

/// Each voxel of `dims` in exactly one of `bricks`.
fn tiles(dims: [usize; 3], bricks: &[Brick]) -> bool {
    let mut count = vec![0u8; dims.iter().product()];
    for b in bricks {
        for k in b.lo[2]..b.hi[2] {
            for j in b.lo[1]..b.hi[1] {
                for i in b.lo[0]..b.hi[0] {
                    count[i + dims[0] * (j + dims[1] * k)] += 1;
                }
            }
        }
    }
    count.iter().all(|&c| c == 1)
}

/// `fitting_kd_tree` (the GPU casters' bricks): every brick with its ghost voxels fits
/// the limits, the bricks tile the volume, the tree's leaves are the bricks, and there
/// are never more of them than the fewest proportional k-d cuts that fit (the smallest
/// `n` whose `kd_bricks` fit, searched here) — fewer where a regular grid fits: a 64³
/// volume under 32 texels with 3 ghost voxels takes 3 × 3 × 3 bricks of 21–22 voxels a
/// side, not 60; 128³ under 64 texels likewise 27, not 58.
#[test]
fn fitting_kd_trees_take_the_fewest_bricks_that_fit() {
    use voxlab::io::brick::{fitting_kd_tree, grid_tree};
    let fits = |dims: [usize; 3], g: usize, max: usize, voxels: Option<u64>| {
        move |b: &Brick| {
            let w = b.with_ghost(g, dims);
            w.dims().iter().all(|&n| n <= max) && voxels.is_none_or(|m| w.voxels() as u64 <= m)
        }
    };
    for (dims, ghost, max, voxels, want) in [
        ([64, 64, 64], 3, 32, None, Some(27)),
        ([128, 128, 128], 3, 64, None, Some(27)),
        ([64, 64, 64], 3, 64, None, Some(1)),
        ([64, 64, 64], 1, 64, Some(40_000), None),
        ([48, 48, 48], 2, 28, None, None),
        ([48, 48, 48], 1, 22, None, None),
        ([48, 48, 48], 1, 4096, Some(9_000), None),
        ([37, 29, 23], 2, 16, None, None),
        ([100, 30, 7], 3, 4096, Some(5_000), None),
        ([9, 7, 6], 1, 5, None, None),
    ] {
        let case = format!("{dims:?}, ghost {ghost}, {max} texels, {voxels:?} in all");
        let ok = fits(dims, ghost, max, voxels);
        let (tree, bricks) = fitting_kd_tree(dims, ghost, max, voxels, "ghost").unwrap();
        assert!(bricks.iter().all(ok), "{case}: {bricks:?}");
        assert!(
            tiles(dims, &bricks),
            "{case}: the bricks do not tile the volume"
        );
        let mut order = Vec::new();
        tree.front_to_back([1.0, 1.0, 1.0], &mut order);
        assert_eq!(order, (0..bricks.len()).collect::<Vec<_>>(), "{case}");
        let fewer = (1..bricks.len()).find(|&n| kd_bricks(dims, n).is_ok_and(|b| b.iter().all(ok)));
        assert_eq!(fewer, None, "{case}: {} bricks", bricks.len());
        if let Some(n) = want {
            assert_eq!(bricks.len(), n, "{case}");
        }
    }
    let (_, bricks) = fitting_kd_tree([64; 3], 3, 32, None, "ghost").unwrap();
    assert!(bricks
        .iter()
        .all(|b| b.dims().iter().all(|&n| n == 21 || n == 22)));
    // A limit below the ghost voxels fits nothing (a brick of the middle voxel is 7
    // texels wide with them; 7 takes one-voxel bricks), and neither does a memory below
    // 7³ texels.
    let e = fitting_kd_tree([64; 3], 3, 6, None, "the filter's 3 ghost voxels").unwrap_err();
    assert!(
        e.to_string()
            .contains("cannot be cut into bricks of at most 6 texels"),
        "{e}"
    );
    assert_eq!(
        fitting_kd_tree([16; 3], 3, 7, None, "ghost")
            .unwrap()
            .1
            .len(),
        16 * 16 * 16
    );
    assert!(fitting_kd_tree([64; 3], 3, 64, Some(342), "ghost").is_err());
    assert!(fitting_kd_tree([24; 3], 3, 64, Some(343), "ghost").is_ok());
    // Two pieces of an axis each have one inner face: 64 under 35 texels with 3 ghost
    // voxels is 2 × 2 × 2 bricks of 32 + 3.
    let (_, b) = fitting_kd_tree([64; 3], 3, 35, None, "ghost").unwrap();
    assert_eq!(b.len(), 8);
    // The grid itself: 2 × 3 × 1 pieces of a 10 × 7 × 3 volume at ⌊i·n/k⌋.
    let (_, g) = grid_tree([10, 7, 3], [2, 3, 1]);
    assert_eq!(g.len(), 6);
    assert!(tiles([10, 7, 3], &g));
    let xs: Vec<[usize; 2]> = g.iter().map(|b| [b.lo[0], b.hi[0]]).collect();
    let ys: Vec<[usize; 2]> = g.iter().map(|b| [b.lo[1], b.hi[1]]).collect();
    assert!(xs.iter().all(|x| *x == [0, 5] || *x == [5, 10]), "{xs:?}");
    assert!(
        ys.iter().all(|y| [[0, 2], [2, 4], [4, 7]].contains(y)),
        "{ys:?}"
    );
}

/// `halved_kd_tree` (the multi-volume caster's cells): every brick fits, the bricks tile
/// the volume (each voxel in exactly one), a volume that fits is not cut, the tree's
/// leaves are its bricks, and a rule not even one voxel meets gives `None`.
#[test]
fn halved_kd_trees_tile_the_volume_in_bricks_that_fit() {
    use voxlab::io::brick::{halved_kd_tree, KdTree};
    let dims = [10, 7, 3];
    let fits = |b: &Brick| b.voxels() <= 20;
    let (tree, bricks) = halved_kd_tree(dims, &fits).unwrap();
    let mut owner = vec![0u32; 210];
    for b in &bricks {
        assert!(b.voxels() <= 20 && b.voxels() > 0, "{b:?}");
        for z in b.lo[2]..b.hi[2] {
            for y in b.lo[1]..b.hi[1] {
                for x in b.lo[0]..b.hi[0] {
                    owner[(z * 7 + y) * 10 + x] += 1;
                }
            }
        }
    }
    assert!(
        owner.iter().all(|&n| n == 1),
        "the bricks do not tile the volume"
    );
    let mut order = Vec::new();
    tree.front_to_back([1.0, 1.0, 1.0], &mut order);
    assert_eq!(order, (0..bricks.len()).collect::<Vec<_>>());
    let (whole, one) = halved_kd_tree(dims, &|_: &Brick| true).unwrap();
    assert_eq!((whole, one), (KdTree::Leaf(0), vec![Brick::all(dims)]));
    assert!(halved_kd_tree(dims, &|b: &Brick| b.voxels() == 0).is_none());
}

/// `fewest_kd_tree` (the multi-volume caster's cells): never more cells than the
/// halvings, every cell fits, the cells tile the volume and the tree's leaves are its
/// cells; a regular grid where it takes fewer (48³ under 20 voxels a side: 3 × 3 × 3
/// cells, where halving takes 4 × 4 × 4), the halvings on a tie (64³ under 32: 8).
#[test]
fn fewest_kd_trees_take_a_grid_where_it_has_fewer_cells() {
    use voxlab::io::brick::{fewest_kd_tree, halved_kd_tree};
    for (dims, side, voxels, want) in [
        ([48, 48, 48], 20, u64::MAX, Some(27)),
        ([64, 64, 64], 32, u64::MAX, Some(8)),
        ([10, 7, 3], 10, 20, None),
        ([37, 29, 23], 13, 1500, None),
        ([100, 30, 7], 100, 4000, None),
    ] {
        let fits = |b: &Brick| b.dims().iter().all(|&n| n <= side) && b.voxels() as u64 <= voxels;
        let (tree, cells) = fewest_kd_tree(dims, &fits).unwrap();
        let halved = halved_kd_tree(dims, &fits).unwrap().1.len();
        let case = format!("{dims:?} under {side} a side, {voxels} in all");
        assert!(cells.len() <= halved, "{case}: {} > {halved}", cells.len());
        assert!(cells.iter().all(|c| fits(c) && c.voxels() > 0), "{case}");
        assert!(
            tiles(dims, &cells),
            "{case}: the cells do not tile the volume"
        );
        let mut order = Vec::new();
        tree.front_to_back([1.0, 1.0, 1.0], &mut order);
        assert_eq!(order, (0..cells.len()).collect::<Vec<_>>(), "{case}");
        if let Some(n) = want {
            assert_eq!(cells.len(), n, "{case}");
        }
    }
    assert!(fewest_kd_tree([4, 4, 4], &|b: &Brick| b.voxels() == 0).is_none());
}

/// The line sets each stack is read by: one line, the last, every line, every third,
/// and runs with gaps.
fn line_sets(total: usize) -> Vec<Vec<usize>> {
    vec![
        vec![0],
        vec![total - 1],
        (0..total).collect(),
        (1..total).step_by(3).collect(),
        (0..total)
            .filter(|l| l % 5 < 2 || *l == total - 1)
            .collect(),
    ]
}

/// A projection stack (x, y, z = column, row, view) stored in one uncompressed block is
/// read by detector lines: each line read alone is the whole read's bit for bit, in
/// f64 and f32, for every voxel type and every random-access format, and the header
/// gives the detector grid the whole read gives.
#[test]
fn detector_lines_are_the_whole_stacks_bit_for_bit() {
    let dir = scratch("brick-lines");
    let affine = DMat4::from_scale_rotation_translation(
        DVec3::new(0.5, 0.75, 1.0),
        glam::DQuat::IDENTITY,
        DVec3::new(-2.0, -1.5, 0.0),
    );
    // The f32 sample holds NaNs (a stack refuses them): the larger volume stands in.
    let mut vols = sample_volumes(affine);
    vols[3] = larger(affine);
    let mut checked = 0;
    for (i, v) in vols.iter().enumerate() {
        for path in files(&dir, &format!("lines{i}"), v) {
            let name = path.display().to_string();
            let whole = read_projections_grid::<f64>(&path, &ReadOptions::default());
            if name.ends_with(".npy") && !matches!(v, AnyVolume::F32(_)) {
                // A projection .npy is float: read whole or by lines, it is refused.
                assert!(whole.is_err(), "{name}");
                assert!(line_stack(&path).is_err(), "{name}");
                continue;
            }
            let (whole, grid) = whole.unwrap();
            let stack = line_stack(&path).unwrap().expect("read by lines");
            assert_eq!(
                stack.shape,
                [whole.angles, whole.rows, whole.cols],
                "{name}"
            );
            assert_eq!(stack.grid, grid, "{name}");
            assert_eq!(grid.is_some(), !name.ends_with(".npy"), "{name}");
            let whole32 = voxlab::io::projections::read_projections::<f32>(&path).unwrap();
            for ids in line_sets(whole.angles * whole.rows) {
                let got = read_projection_lines::<f64>(&path, &ids).unwrap();
                let want = whole.lines(&ids).unwrap();
                assert_eq!(got.ids, want.ids, "{name}");
                assert_eq!(
                    got.data.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                    want.data.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                    "{name} {ids:?}"
                );
                let got = read_projection_lines::<f32>(&path, &ids).unwrap();
                let want = whole32.lines(&ids).unwrap();
                assert_eq!(
                    got.data.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                    want.data.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                    "{name} {ids:?} f32"
                );
            }
            checked += 1;
        }
    }
    // u8, u16, i16: NRRD ×2 and MetaImage ×2 each; f32: those and .npy.
    assert_eq!(checked, 3 * 4 + 5);
    // Big-endian, data at the end of the file: the lines are the values written.
    let (path, values) = skip_nrrd(&dir);
    let got = read_projection_lines::<f64>(&path, &[4, 1]).unwrap();
    assert_eq!(got.ids, [1, 4]);
    let want: Vec<f64> = [4..8, 16..20]
        .into_iter()
        .flatten()
        .map(|k| values[k] as f64)
        .collect();
    assert_eq!(got.data, want);
}

/// What cannot be read by lines is said: a compressed or 2-D file has no line stack
/// (it is read whole), asking for its lines names the file; a line past the stack and
/// a NaN in the lines read are named.
#[test]
fn detector_lines_refuse_what_they_cannot_read() {
    let dir = scratch("brick-lines-bad");
    let v = larger(DMat4::IDENTITY);
    let gz = dir.join("gz.nrrd");
    write_nrrd(&gz, &v, NrrdWriteOptions::default()).unwrap();
    assert!(line_stack(&gz).unwrap().is_none());
    let e = read_projection_lines::<f64>(&gz, &[0])
        .unwrap_err()
        .to_string();
    assert!(e.contains("gz.nrrd") && e.contains("detector lines"), "{e}");
    let zmha = dir.join("z.mha");
    write_metaimage(&zmha, &v, MetaImageWriteOptions { compress: true }).unwrap();
    assert!(line_stack(&zmha).unwrap().is_none());
    // One slice: a 2-D scikit-image sinogram, read whole.
    let flat: AnyVolume = Volume::new([6, 5, 1], [1.0; 3], vec![1.0f32; 30])
        .unwrap()
        .into();
    let sino = dir.join("sino.nrrd");
    write_nrrd(
        &sino,
        &flat,
        NrrdWriteOptions {
            gzip: false,
            detached: false,
        },
    )
    .unwrap();
    assert!(line_stack(&sino).unwrap().is_none());
    let raw = dir.join("v.nrrd");
    write_nrrd(
        &raw,
        &v,
        NrrdWriteOptions {
            gzip: false,
            detached: false,
        },
    )
    .unwrap();
    let e = read_projection_lines::<f64>(&raw, &[3, 42])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("v.nrrd") && e.contains("line 42") && e.contains("42 lines"),
        "{e}"
    );
    // A NaN at (column 2, row 1, view 3): named when its line is read, not otherwise.
    let mut data: Vec<f32> = (0..9 * 7 * 6).map(|i| i as f32).collect();
    data[2 + 9 * (1 + 7 * 3)] = f32::NAN;
    let nan: AnyVolume = Volume::new([9, 7, 6], [1.0; 3], data).unwrap().into();
    let path = dir.join("nan.mha");
    write_metaimage(&path, &nan, MetaImageWriteOptions { compress: false }).unwrap();
    let e = read_projection_lines::<f64>(&path, &[0, 22, 23])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("nan.mha") && e.contains("view 3, row 1, column 2"),
        "{e}"
    );
    assert!(read_projection_lines::<f64>(&path, &[0, 21, 23]).is_ok());
}
