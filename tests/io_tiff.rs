//! TIFF stacks: the bundled micro-CT stack checked against numbers computed
//! independently with tifffile + numpy (`tests/data/tiff_reference.py`), crafted
//! stacks written with the `tiff` crate's encoder (types, ImageJ calibration,
//! directories of single pages), and bad input.

mod common;

use common::{format_err, scratch};
use std::fs::File;
use std::path::Path;
use tiff::encoder::{colortype, Rational, TiffEncoder};
use tiff::tags::{ResolutionUnit, Tag};
use voxlab::io::read_volume;
use voxlab::io::tiff::{read_tiff, read_tiff_dir};
use voxlab::{AnyVolume, Error, VoxelKind};

/// Writes pages of `w` x `h` samples of colour type `C`.
fn write_pages<C: colortype::ColorType>(path: &Path, w: u32, h: u32, pages: &[Vec<C::Inner>])
where
    [C::Inner]: tiff::encoder::TiffValue,
{
    let mut enc = TiffEncoder::new(File::create(path).unwrap()).unwrap();
    for p in pages {
        enc.write_image::<C>(w, h, p).unwrap();
    }
}

#[test]
fn microct_bone_matches_tifffile() {
    let v = read_volume(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("data/microct-bone/bone_128x128x128.tif"),
    )
    .unwrap();
    // Reference (tests/data/tiff_reference.py, tifffile + numpy): 128 pages of
    // 128 x 128 uint8; min 0, max 255, sum 243509780, weighted sum Σ v[i]·(i mod 251
    // + 1) = 30682413148, voxel (x 10, y 20, z 30) = 1. The file is an ImageJ stack
    // with a blank unit (`unit= `), so its calibration (1.953125 units) is not used.
    assert_eq!(v.dims(), [128, 128, 128]);
    let AnyVolume::U8(v) = v else {
        panic!("expected u8, got {:?}", v.kind())
    };
    assert_eq!(v.spacing(), [1.0, 1.0, 1.0]);
    let (mut sum, mut wsum) = (0u64, 0u64);
    for (i, &x) in v.data().iter().enumerate() {
        sum += x as u64;
        wsum += x as u64 * (i % 251 + 1) as u64;
    }
    assert_eq!(sum, 243509780);
    assert_eq!(wsum, 30682413148);
    assert_eq!(v.data().iter().min(), Some(&0));
    assert_eq!(v.data().iter().max(), Some(&255));
    assert_eq!(*v.get(10, 20, 30), 1);
}

#[test]
fn u16_stack_with_imagej_calibration() {
    let dir = scratch("u16");
    let path = dir.join("stack.tif");
    let (w, h) = (5u32, 3u32);
    let page = |k: u16| {
        (0..15u16)
            .map(|i| k * 1000 + i * 7 + 60000 * (i == 14) as u16 / (k + 1))
            .collect::<Vec<u16>>()
    };
    let mut enc = TiffEncoder::new(File::create(&path).unwrap()).unwrap();
    for k in 0..4u16 {
        let mut img = enc.new_image::<colortype::Gray16>(w, h).unwrap();
        // 4 pixels per micron in x, 2 in y; 2.5 micron between slices.
        img.encoder()
            .write_tag(
                Tag::ImageDescription,
                "ImageJ=1.53t\nimages=4\nslices=4\nunit=micron\nspacing=2.5\nloop=false\n",
            )
            .unwrap();
        img.x_resolution(Rational { n: 4, d: 1 });
        img.y_resolution(Rational { n: 2, d: 1 });
        img.resolution_unit(ResolutionUnit::None);
        img.write_data(&page(k)).unwrap();
    }
    drop(enc);
    let v = read_tiff(&path).unwrap();
    assert_eq!(v.dims(), [5, 3, 4]);
    let spacing = v.spacing();
    for (got, want) in spacing.iter().zip([0.00025, 0.0005, 0.0025]) {
        assert!((got - want).abs() < 1e-15, "{spacing:?}");
    }
    let AnyVolume::U16(v) = v else {
        panic!("expected u16")
    };
    for k in 0..4 {
        assert_eq!(&v.data()[k * 15..(k + 1) * 15], &page(k as u16)[..]);
    }
    assert_eq!(*v.get(4, 2, 0), 60000 + 14 * 7);
}

#[test]
fn other_sample_types() {
    let dir = scratch("types");
    // f32, uncalibrated: 1 mm voxels, exact values (NaN and infinities included).
    let p = dir.join("f32.tif");
    let pages: Vec<Vec<f32>> = (0..3)
        .map(|k| (0..6).map(|i| k as f32 * 0.5 - i as f32 * 1.25).collect())
        .collect();
    let mut with_special = pages.clone();
    with_special[2][5] = f32::NEG_INFINITY;
    write_pages::<colortype::Gray32Float>(&p, 3, 2, &with_special);
    let v = read_tiff(&p).unwrap();
    assert_eq!(
        (v.dims(), v.kind(), v.spacing()),
        ([3, 2, 3], VoxelKind::F32, [1.0; 3])
    );
    let AnyVolume::F32(v) = v else { unreachable!() };
    assert_eq!(v.data(), with_special.concat().as_slice());
    // i16 exact; i8 widened to i16.
    let p = dir.join("i16.tif");
    write_pages::<colortype::GrayI16>(&p, 2, 2, &[vec![-32768, -1, 0, 32767], vec![5, 6, 7, 8]]);
    let AnyVolume::I16(v) = read_tiff(&p).unwrap() else {
        panic!("expected i16")
    };
    assert_eq!(v.data(), &[-32768, -1, 0, 32767, 5, 6, 7, 8]);
    let p = dir.join("i8.tif");
    write_pages::<colortype::GrayI8>(&p, 2, 1, &[vec![-128, 127]]);
    let AnyVolume::I16(v) = read_tiff(&p).unwrap() else {
        panic!("expected i16")
    };
    assert_eq!(v.data(), &[-128, 127]);
    // u32 and f64 → f32, rounded to nearest.
    let p = dir.join("u32.tif");
    write_pages::<colortype::Gray32>(&p, 2, 1, &[vec![16_777_217, 3]]);
    let AnyVolume::F32(v) = read_tiff(&p).unwrap() else {
        panic!("expected f32")
    };
    assert_eq!(v.data(), &[16_777_216.0, 3.0]);
    let p = dir.join("f64.tif");
    write_pages::<colortype::Gray64Float>(&p, 2, 1, &[vec![0.1, -2.5]]);
    let AnyVolume::F32(v) = read_tiff(&p).unwrap() else {
        panic!("expected f32")
    };
    assert_eq!(v.data(), &[0.1f32, -2.5]);
}

#[test]
fn directory_of_pages_in_natural_order() {
    let dir = scratch("dir");
    for k in [1u8, 2, 10] {
        write_pages::<colortype::Gray8>(&dir.join(format!("slice{k}.tif")), 2, 2, &[vec![k; 4]]);
    }
    std::fs::write(dir.join("notes.txt"), "ignored").unwrap();
    let AnyVolume::U8(v) = read_tiff_dir(&dir).unwrap() else {
        panic!("expected u8")
    };
    assert_eq!(v.dims(), [2, 2, 3]);
    assert_eq!(
        (*v.get(0, 0, 0), *v.get(0, 0, 1), *v.get(1, 1, 2)),
        (1, 2, 10)
    );
    let empty = scratch("dir-empty");
    let e = format_err(read_tiff_dir(&empty));
    assert!(e.contains("no .tif"), "{e}");
}

#[test]
fn mismatched_pages_are_errors() {
    let dir = scratch("mismatch");
    let p = dir.join("sizes.tif");
    {
        let mut enc = TiffEncoder::new(File::create(&p).unwrap()).unwrap();
        enc.write_image::<colortype::Gray8>(2, 2, &[1, 2, 3, 4])
            .unwrap();
        enc.write_image::<colortype::Gray8>(3, 2, &[1, 2, 3, 4, 5, 6])
            .unwrap();
    }
    let e = format_err(read_tiff(&p));
    assert!(
        e.contains("page 1 is 3x2") && e.contains("same size"),
        "{e}"
    );
    let p = dir.join("types.tif");
    {
        let mut enc = TiffEncoder::new(File::create(&p).unwrap()).unwrap();
        enc.write_image::<colortype::Gray8>(2, 1, &[1, 2]).unwrap();
        enc.write_image::<colortype::Gray16>(2, 1, &[1, 2]).unwrap();
    }
    let e = format_err(read_tiff(&p));
    assert!(e.contains("same sample type"), "{e}");
}

#[test]
fn colour_is_refused() {
    let dir = scratch("rgb");
    let p = dir.join("rgb.tif");
    write_pages::<colortype::RGB8>(&p, 2, 1, &[vec![1, 2, 3, 4, 5, 6]]);
    let e = format_err(read_tiff(&p));
    assert!(e.contains("RGB") && e.contains("grayscale"), "{e}");
}

#[test]
fn truncated_and_garbage_are_errors() {
    let dir = scratch("bad");
    let good = dir.join("good.tif");
    let pages: Vec<Vec<u16>> = (0..3).map(|k| vec![k; 64 * 64]).collect();
    write_pages::<colortype::Gray16>(&good, 64, 64, &pages);
    let bytes = std::fs::read(&good).unwrap();
    for cut in [4, 20, bytes.len() / 2, bytes.len() - 10] {
        let p = dir.join(format!("cut{cut}.tif"));
        std::fs::write(&p, &bytes[..cut]).unwrap();
        let e = format_err(read_tiff(&p));
        assert!(e.contains(&format!("cut{cut}.tif")), "{e}");
    }
    let mut noise = b"II*\0".to_vec();
    let mut x = 7u32;
    for _ in 0..5000 {
        x = x.wrapping_mul(1664525).wrapping_add(1013904223);
        noise.push((x >> 24) as u8);
    }
    let p = dir.join("noise.tif");
    std::fs::write(&p, &noise).unwrap();
    assert!(read_tiff(&p).is_err());
}

#[test]
fn corrupted_files_never_panic() {
    // Random bytes overwritten in a small two-page stack, and random truncations:
    // every outcome is a volume or an error (no panic, no huge allocation).
    let dir = scratch("corrupt");
    let good = dir.join("good.tif");
    let pages: Vec<Vec<u16>> = (0..2).map(|k| vec![k; 16 * 8]).collect();
    write_pages::<colortype::Gray16>(&good, 16, 8, &pages);
    let bytes = std::fs::read(&good).unwrap();
    let path = dir.join("c.tif");
    let mut x = 5u64;
    let mut rnd = || {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (x >> 33) as usize
    };
    for t in 0..300 {
        let mut b = bytes.clone();
        if t % 4 == 0 {
            b.truncate(rnd() % b.len());
        } else {
            for _ in 0..1 + t % 5 {
                let i = rnd() % b.len();
                b[i] = rnd() as u8;
            }
        }
        std::fs::write(&path, &b).unwrap();
        let _ = read_tiff(&path);
    }
}

#[test]
fn page_count_is_checked_against_the_voxel_limit() {
    // A 1000 x 1000 page times 3 pages exceeds a limit of 2.5 million voxels;
    // refused without decoding. The limit is process-wide: this is the only test here
    // that sets it, it restores it, and the other stacks read meanwhile (the bundled
    // 128³ one included) stay below it.
    let dir = scratch("limit");
    let p = dir.join("big.tif");
    let page = vec![0u8; 1000 * 1000];
    write_pages::<colortype::Gray8>(&p, 1000, 1000, &[page.clone(), page.clone(), page]);
    let old = voxlab::volume::max_voxels();
    voxlab::volume::set_max_voxels(2_500_000);
    let r = read_tiff(&p);
    voxlab::volume::set_max_voxels(old);
    match r {
        Err(e @ Error::TooLarge { .. }) => assert!(e.to_string().contains("big.tif"), "{e}"),
        other => panic!("expected TooLarge, got {other:?}"),
    }
}
