//! DICOM reading: the bundled MR series and single files in several transfer
//! syntaxes, checked against numbers computed independently with pydicom + numpy
//! (`tests/data/dicom_reference.py`); a synthetic multi-frame file; and every kind of
//! broken series (missing slice, mixed sizes, two series, garbage).

mod common;

use common::{format_err, root, scratch};
use dicom_core::value::DataSetSequence;
use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::tags;
use dicom_object::{FileMetaTableBuilder, InMemDicomObject};
use glam::{DMat3, DVec3};
use std::path::{Path, PathBuf};
use voxlab::io::dicom::read_dicom;
use voxlab::io::read_volume;
use voxlab::{AnyVolume, Error, VoxelKind};

const SERIES: &str = "data/mr-brain-dicom";
const CORPUS: &str = "tests/corpus/dicom";

/// A copy of the MR series in a scratch directory.
fn series_copy(name: &str) -> PathBuf {
    let dir = scratch(name);
    for e in std::fs::read_dir(root().join(SERIES)).unwrap() {
        let p = e.unwrap().path();
        std::fs::copy(&p, dir.join(p.file_name().unwrap())).unwrap();
    }
    dir
}

fn assert_vec(got: DVec3, want: [f64; 3], tol: f64, what: &str) {
    let want = DVec3::from_array(want);
    assert!(
        (got - want).abs().max_element() <= tol,
        "{what}: got {got}, want {want}"
    );
}

// ---------------------------------------------------------------------------------
// The MR series
// ---------------------------------------------------------------------------------

#[test]
fn mr_series_matches_pydicom() {
    let v = read_volume(&root().join(SERIES)).unwrap();
    // pydicom: 20 slices of 256 x 256, BitsStored 16, PixelRepresentation 1 (signed),
    // no rescale → i16.
    assert_eq!(v.dims(), [256, 256, 20]);
    assert_eq!(v.kind(), VoxelKind::I16);
    // Reference (tests/data/dicom_reference.py, pydicom 3 + numpy, slices sorted by
    // IPP · normal): x step = (0.859375, 0, 0), y step = (0, 0.85160625, 0.11529203),
    // mean step along the normal 7.000524011 mm, z step = (0, -0.9391763,
    // 6.93723927), origin = IPP of brain_001 = (-110.5, -78.3063, -72.7575).
    let a = v.affine();
    let lin = DMat3::from_mat4(a);
    assert_vec(lin.x_axis, [0.859375, 0.0, 0.0], 1e-5, "x step");
    assert_vec(lin.y_axis, [0.0, 0.85160625, 0.11529203], 1e-5, "y step");
    assert_vec(lin.z_axis, [0.0, -0.9391763, 6.93723927], 1e-4, "z step");
    assert_vec(
        a.w_axis.truncate(),
        [-110.5, -78.3063, -72.7575],
        1e-9,
        "origin",
    );
    assert!(
        (v.spacing()[2] - 7.000524011).abs() < 1e-4,
        "{:?}",
        v.spacing()
    );
    // Reference: min 0, max 1059, sum 219593921, weighted sum 27553588492.
    let (lo, hi, sum, wsum) = common::volume_stats(&v);
    assert_eq!((lo, hi), (0.0, 1059.0));
    assert_eq!(sum, 219593921.0);
    assert_eq!(wsum, 27553588492.0);
}

#[test]
fn series_order_does_not_follow_file_names() {
    // Rename the files so that name order is reversed: the volume is the same.
    let dir = scratch("renamed");
    for e in std::fs::read_dir(root().join(SERIES)).unwrap() {
        let p = e.unwrap().path();
        let n: usize = p.file_stem().unwrap().to_str().unwrap()[6..]
            .parse()
            .unwrap();
        std::fs::copy(&p, dir.join(format!("im{:02}.dcm", 21 - n))).unwrap();
    }
    std::fs::write(dir.join("README"), "not a DICOM file").unwrap();
    let a = read_dicom(&dir).unwrap();
    let b = read_dicom(&root().join(SERIES)).unwrap();
    assert_eq!(a, b);
}

#[test]
fn missing_slice_is_an_error() {
    let dir = series_copy("missing");
    std::fs::remove_file(dir.join("brain_010.dcm")).unwrap();
    let e = format_err(read_dicom(&dir));
    assert!(e.contains("missing slice"), "{e}");
    assert!(
        e.contains("brain_009.dcm") && e.contains("brain_011.dcm"),
        "{e}"
    );
}

#[test]
fn duplicate_slice_is_an_error() {
    let dir = series_copy("duplicate");
    std::fs::copy(dir.join("brain_004.dcm"), dir.join("brain_004_copy.dcm")).unwrap();
    let e = format_err(read_dicom(&dir));
    assert!(e.contains("duplicate slice position"), "{e}");
    assert!(e.contains("brain_004"), "{e}");
}

#[test]
fn mixed_sizes_are_an_error() {
    let dir = series_copy("mixed");
    // brain_005 shrunk to 128 x 128 (keeping its first 128 x 128 samples).
    let path = dir.join("brain_005.dcm");
    let mut obj = dicom_object::open_file(&path).unwrap();
    let pixels: Vec<u16> = obj
        .element(tags::PIXEL_DATA)
        .unwrap()
        .value()
        .primitive()
        .unwrap()
        .to_bytes()
        .chunks_exact(2)
        .take(128 * 128)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .collect();
    obj.put(DataElement::new(
        tags::ROWS,
        VR::US,
        PrimitiveValue::from(128u16),
    ));
    obj.put(DataElement::new(
        tags::COLUMNS,
        VR::US,
        PrimitiveValue::from(128u16),
    ));
    obj.put(DataElement::new(
        tags::PIXEL_DATA,
        VR::OW,
        PrimitiveValue::U16(pixels.into()),
    ));
    obj.write_to_file(&path).unwrap();
    let e = format_err(read_dicom(&dir));
    assert!(e.contains("mixed sizes"), "{e}");
    assert!(e.contains("brain_005.dcm"), "{e}");
}

#[test]
fn two_series_are_listed() {
    let dir = series_copy("two-series");
    std::fs::copy(
        root().join(CORPUS).join("implicit_little.dcm"),
        dir.join("other.dcm"),
    )
    .unwrap();
    let e = format_err(read_dicom(&dir));
    assert!(e.contains("2 series"), "{e}");
    assert!(e.contains("0.0.0.0.3.8811.2.20010413115754.12432"), "{e}");
    assert!(
        e.contains("1.2.840.113619.2.1.3352.1136944889.4.834485379"),
        "{e}"
    );
    assert!(e.contains("20 files") && e.contains("1 files"), "{e}");
    assert!(e.contains("one series"), "{e}");
}

#[test]
fn directory_without_dicom_is_an_error() {
    let dir = scratch("no-dicom");
    std::fs::write(dir.join("README"), "hello").unwrap();
    let e = format_err(read_dicom(&dir));
    assert!(e.contains("no DICOM image") && e.contains("README"), "{e}");
}

#[test]
fn garbage_and_truncated_files_are_errors() {
    let dir = scratch("garbage");
    let bytes = std::fs::read(root().join(SERIES).join("brain_001.dcm")).unwrap();
    // Truncated in the header, and in the pixel data (bytes 1842..132914).
    for (name, len) in [("head.dcm", 300), ("pixels.dcm", 100_000)] {
        let p = dir.join(name);
        std::fs::write(&p, &bytes[..len]).unwrap();
        let e = format_err(read_dicom(&p));
        assert!(e.contains(name), "{e}");
    }
    // A DICM marker followed by noise.
    let mut noise = vec![0u8; 128];
    noise.extend_from_slice(b"DICM");
    let mut x = 12345u32;
    for _ in 0..4000 {
        x = x.wrapping_mul(1664525).wrapping_add(1013904223);
        noise.push((x >> 24) as u8);
    }
    let p = dir.join("noise.dcm");
    std::fs::write(&p, &noise).unwrap();
    format_err(read_dicom(&p));
    // Not DICOM at all.
    let p = dir.join("text.dcm");
    std::fs::write(&p, b"just some text").unwrap();
    let e = format_err(read_dicom(&p));
    assert!(e.contains("not a DICOM file"), "{e}");
}

#[test]
fn truncated_headers_never_panic() {
    // Truncations every 19 bytes through the header (the pixel data starts at byte
    // ~1800): every outcome is an error, never a panic. (Random byte flips are not
    // tested here: a corrupted length field makes the parser allocate and zero up to
    // 4 GiB before it fails, which takes seconds; it fails cleanly.)
    let dir = scratch("corrupt");
    let path = dir.join("c.dcm");
    let bytes = std::fs::read(root().join(CORPUS).join("implicit_little.dcm")).unwrap();
    let cases: Vec<&[u8]> = (0..1900).step_by(19).map(|n| &bytes[..n]).collect();
    for b in cases {
        std::fs::write(&path, b).unwrap();
        assert!(read_dicom(&path).is_err());
    }
}

// ---------------------------------------------------------------------------------
// Single files in several transfer syntaxes
// ---------------------------------------------------------------------------------

#[test]
fn uncompressed_syntaxes_match_pydicom() {
    // (file, dims, kind, min, max, sum, weighted sum) from tests/data/dicom_reference.py.
    let cases = [
        (
            "implicit_little.dcm",
            [256, 256, 1],
            VoxelKind::I16,
            0.0,
            575.0,
            4294431.0,
            526622210.0,
        ),
        (
            "explicit_big.dcm",
            [256, 256, 1],
            VoxelKind::I16,
            0.0,
            891.0,
            12795755.0,
            1633201332.0,
        ),
        (
            "deflated.dcm",
            [512, 512, 1],
            VoxelKind::U8,
            0.0,
            255.0,
            33322688.0,
            4199268233.0,
        ),
    ];
    for (name, dims, kind, lo, hi, sum, wsum) in cases {
        let v = read_dicom(&root().join(CORPUS).join(name)).unwrap();
        assert_eq!(v.dims(), dims, "{name}");
        assert_eq!(v.kind(), kind, "{name}");
        assert_eq!(common::volume_stats(&v), (lo, hi, sum, wsum), "{name}");
    }
    // implicit_little: PixelSpacing 0.859375, IOP identity, IPP (-110, -109.8, -47.5),
    // SpacingBetweenSlices 6 used for the single slice's z step.
    let v = read_dicom(&root().join(CORPUS).join("implicit_little.dcm")).unwrap();
    let a = v.affine();
    assert_vec(DMat3::from_mat4(a).x_axis, [0.859375, 0.0, 0.0], 1e-9, "x");
    assert_vec(DMat3::from_mat4(a).z_axis, [0.0, 0.0, 6.0], 1e-9, "z");
    assert_vec(
        a.w_axis.truncate(),
        [-110.0, -109.800003, -47.5],
        1e-9,
        "origin",
    );
}

#[test]
fn trailing_padding_is_ignored_in_every_native_syntax() {
    // Bytes after the pixel data that do not parse as elements (zeros in
    // brain_001.dcm; here a truncated element) must not change the volume. The
    // explicit VR parsers fail on them and the pixel data is then located by hand
    // (big endian here, little endian in the MR series); the implicit VR parser stops
    // quietly.
    let dir = scratch("padded");
    for name in ["implicit_little.dcm", "explicit_big.dcm"] {
        let src = root().join(CORPUS).join(name);
        let mut bytes = std::fs::read(&src).unwrap();
        bytes.extend_from_slice(&[0xFF, 0xFF, 0xFF, 0xFF, 0x10, 0x00, 0x00, 0x00, 1, 2, 3]);
        let p = dir.join(name);
        std::fs::write(&p, &bytes).unwrap();
        let padded = read_dicom(&p).unwrap();
        assert_eq!(padded, read_dicom(&src).unwrap(), "{name}");
    }
}

#[test]
fn compressed_syntaxes_voxlab_does_not_decode_are_refused_clearly() {
    // jpeg_2000.dcm relabelled High-Throughput JPEG 2000 (…4.201): the transfer syntax
    // UID in the meta group grows from 22 to 24 bytes, and the group's length with it.
    let src = std::fs::read(root().join(CORPUS).join("jpeg_2000.dcm")).unwrap();
    let old = b"1.2.840.10008.1.2.4.91";
    let at = src.windows(old.len()).position(|w| w == old).unwrap();
    let mut b = src[..at - 2].to_vec();
    b.extend(24u16.to_le_bytes());
    b.extend(b"1.2.840.10008.1.2.4.201\0");
    b.extend(&src[at + old.len()..]);
    let group = u32::from_le_bytes(b[140..144].try_into().unwrap()) + 2;
    b[140..144].copy_from_slice(&group.to_le_bytes());
    let path = scratch("htj2k").join("htj2k.dcm");
    std::fs::write(&path, b).unwrap();
    let e = format_err(read_dicom(&path));
    assert!(e.contains("TransferSyntaxUID"), "{e}");
    assert!(e.contains("1.2.840.10008.1.2.4.201"), "{e}");
    assert!(e.contains("High-Throughput JPEG 2000"), "{e}");
    assert!(e.contains("not supported"), "{e}");
    assert!(e.contains("gdcmconv --raw"), "{e}");
}

// ---------------------------------------------------------------------------------
// Synthetic files
// ---------------------------------------------------------------------------------

fn seq(tag: dicom_core::Tag, items: Vec<InMemDicomObject>) -> DataElement<InMemDicomObject> {
    DataElement::new(tag, VR::SQ, DataSetSequence::from(items))
}

fn item(elements: Vec<DataElement<InMemDicomObject>>) -> InMemDicomObject {
    InMemDicomObject::from_element_iter(elements)
}

fn ds(tag: dicom_core::Tag, v: &str) -> DataElement<InMemDicomObject> {
    DataElement::new(tag, VR::DS, PrimitiveValue::from(v))
}

/// Writes a 4 x 3 image with `frames` frames of u16 samples `f·100 + i`, plus the
/// given extra elements, as explicit VR little endian.
fn write_synthetic(path: &Path, frames: u16, extra: Vec<DataElement<InMemDicomObject>>) {
    let n = 12 * frames as usize;
    let pixels: Vec<u16> = (0..n).map(|i| ((i / 12) * 100 + i % 12) as u16).collect();
    let mut elements = vec![
        DataElement::new(
            tags::SOP_CLASS_UID,
            VR::UI,
            PrimitiveValue::from("1.2.840.10008.5.1.4.1.1.7"),
        ),
        DataElement::new(
            tags::SOP_INSTANCE_UID,
            VR::UI,
            PrimitiveValue::from("1.2.3.4.5"),
        ),
        DataElement::new(
            tags::SERIES_INSTANCE_UID,
            VR::UI,
            PrimitiveValue::from("1.2.3.4"),
        ),
        DataElement::new(tags::SAMPLES_PER_PIXEL, VR::US, PrimitiveValue::from(1u16)),
        DataElement::new(
            tags::PHOTOMETRIC_INTERPRETATION,
            VR::CS,
            PrimitiveValue::from("MONOCHROME2"),
        ),
        DataElement::new(tags::ROWS, VR::US, PrimitiveValue::from(3u16)),
        DataElement::new(tags::COLUMNS, VR::US, PrimitiveValue::from(4u16)),
        DataElement::new(tags::BITS_ALLOCATED, VR::US, PrimitiveValue::from(16u16)),
        DataElement::new(tags::BITS_STORED, VR::US, PrimitiveValue::from(12u16)),
        DataElement::new(tags::HIGH_BIT, VR::US, PrimitiveValue::from(11u16)),
        DataElement::new(
            tags::PIXEL_REPRESENTATION,
            VR::US,
            PrimitiveValue::from(0u16),
        ),
        DataElement::new(
            tags::NUMBER_OF_FRAMES,
            VR::IS,
            PrimitiveValue::from(frames.to_string()),
        ),
        DataElement::new(tags::PIXEL_DATA, VR::OW, PrimitiveValue::U16(pixels.into())),
    ];
    elements.extend(extra);
    let obj = InMemDicomObject::from_element_iter(elements)
        .with_meta(
            FileMetaTableBuilder::new()
                .transfer_syntax("1.2.840.10008.1.2.1")
                .media_storage_sop_class_uid("1.2.840.10008.5.1.4.1.1.7"),
        )
        .unwrap();
    obj.write_to_file(path).unwrap();
}

#[test]
fn multi_frame_positions_from_functional_groups() {
    let dir = scratch("multiframe");
    let path = dir.join("mf.dcm");
    // Frames stored at z = 10, 0, 5 (file order); the volume must be sorted 0, 5, 10.
    let per_frame: Vec<InMemDicomObject> = ["10", "0", "5"]
        .iter()
        .map(|z| {
            item(vec![seq(
                tags::PLANE_POSITION_SEQUENCE,
                vec![item(vec![ds(
                    tags::IMAGE_POSITION_PATIENT,
                    &format!("-3\\7\\{z}"),
                )])],
            )])
        })
        .collect();
    let shared = item(vec![
        seq(
            tags::PLANE_ORIENTATION_SEQUENCE,
            vec![item(vec![ds(
                tags::IMAGE_ORIENTATION_PATIENT,
                "1\\0\\0\\0\\1\\0",
            )])],
        ),
        seq(
            tags::PIXEL_MEASURES_SEQUENCE,
            vec![item(vec![
                ds(tags::PIXEL_SPACING, "0.5\\0.25"),
                ds(tags::SLICE_THICKNESS, "2"),
            ])],
        ),
        seq(
            tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE,
            vec![item(vec![
                ds(tags::RESCALE_SLOPE, "1"),
                ds(tags::RESCALE_INTERCEPT, "-100"),
            ])],
        ),
    ]);
    write_synthetic(
        &path,
        3,
        vec![
            seq(tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE, vec![shared]),
            seq(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE, per_frame),
        ],
    );
    let v = read_volume(&path).unwrap();
    assert_eq!(v.dims(), [4, 3, 3]);
    // Intercept -100 → signed integers.
    let AnyVolume::I16(v) = v else {
        panic!("expected i16, got {:?}", v.kind())
    };
    // x step = column spacing 0.25, y step = row spacing 0.5, z step 5 (positions).
    let a = v.affine();
    assert_vec(DMat3::from_mat4(a).x_axis, [0.25, 0.0, 0.0], 1e-12, "x");
    assert_vec(DMat3::from_mat4(a).y_axis, [0.0, 0.5, 0.0], 1e-12, "y");
    assert_vec(DMat3::from_mat4(a).z_axis, [0.0, 0.0, 5.0], 1e-12, "z");
    assert_vec(a.w_axis.truncate(), [-3.0, 7.0, 0.0], 1e-12, "origin");
    // Slice k is file frame [1, 2, 0][k], holding 100·frame + i, minus 100.
    for (k, frame) in [1i16, 2, 0].into_iter().enumerate() {
        for i in 0..12 {
            assert_eq!(*v.get(i % 4, i / 4, k), frame * 100 + i as i16 - 100);
        }
    }
}

#[test]
fn multi_frame_with_mixed_orientations_is_refused() {
    let dir = scratch("multiframe-mixed");
    let path = dir.join("mf.dcm");
    let per_frame: Vec<InMemDicomObject> = [("0", "1\\0\\0\\0\\1\\0"), ("5", "0\\1\\0\\1\\0\\0")]
        .iter()
        .map(|(z, iop)| {
            item(vec![
                seq(
                    tags::PLANE_POSITION_SEQUENCE,
                    vec![item(vec![ds(
                        tags::IMAGE_POSITION_PATIENT,
                        &format!("0\\0\\{z}"),
                    )])],
                ),
                seq(
                    tags::PLANE_ORIENTATION_SEQUENCE,
                    vec![item(vec![ds(tags::IMAGE_ORIENTATION_PATIENT, iop)])],
                ),
            ])
        })
        .collect();
    write_synthetic(
        &path,
        2,
        vec![seq(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE, per_frame)],
    );
    let e = format_err(read_dicom(&path));
    assert!(
        e.contains("frame 2") && e.contains("ImageOrientationPatient"),
        "{e}"
    );
}

#[test]
fn multi_frame_without_positions_uses_thickness_and_float_rescale() {
    let dir = scratch("multiframe-plain");
    let path = dir.join("mf.dcm");
    write_synthetic(
        &path,
        2,
        vec![
            ds(tags::SLICE_THICKNESS, "1.5"),
            ds(tags::PIXEL_SPACING, "2\\3"),
            ds(tags::RESCALE_SLOPE, "0.5"),
            ds(tags::RESCALE_INTERCEPT, "1"),
        ],
    );
    let v = read_dicom(&path).unwrap();
    assert_eq!(v.dims(), [4, 3, 2]);
    assert_eq!(v.spacing(), [3.0, 2.0, 1.5]);
    let AnyVolume::F32(v) = v else {
        panic!("expected f32")
    };
    assert_eq!(*v.get(3, 2, 1), (111.0 * 0.5 + 1.0) as f32);
}

#[test]
fn bits_stored_are_masked_and_sign_extended() {
    let dir = scratch("bits");
    let path = dir.join("signed12.dcm");
    // 12 stored bits, signed: 0x0FFF is -1, 0x0800 is -2048, 0x07FF is 2047; the bits
    // above the high bit (set in the first two words) are ignored.
    let words: Vec<u16> = vec![0xF000 | 5, 0xFFFF, 0x0800, 0x07FF, 0, 1, 2, 3, 4, 5, 6, 7];
    write_synthetic(
        &path,
        1,
        vec![
            DataElement::new(
                tags::PIXEL_REPRESENTATION,
                VR::US,
                PrimitiveValue::from(1u16),
            ),
            DataElement::new(tags::PIXEL_DATA, VR::OW, PrimitiveValue::U16(words.into())),
        ],
    );
    let AnyVolume::I16(v) = read_dicom(&path).unwrap() else {
        panic!("expected i16")
    };
    assert_eq!(&v.data()[..6], &[5, -1, -2048, 2047, 0, 1]);
}

#[test]
fn absurd_frame_count_is_refused_before_allocating() {
    let dir = scratch("frames");
    let path = dir.join("many.dcm");
    write_synthetic(
        &path,
        1,
        vec![DataElement::new(
            tags::NUMBER_OF_FRAMES,
            VR::IS,
            PrimitiveValue::from("999999999999"),
        )],
    );
    match read_dicom(&path) {
        Err(e @ Error::TooLarge { .. }) => {
            assert!(
                e.to_string().contains("many.dcm") && e.to_string().contains("voxels"),
                "{e}"
            )
        }
        other => panic!("expected TooLarge, got {other:?}"),
    }
    // A frame count the pixel data does not hold is a short-data error.
    write_synthetic(
        &path,
        1,
        vec![DataElement::new(
            tags::NUMBER_OF_FRAMES,
            VR::IS,
            PrimitiveValue::from("3"),
        )],
    );
    let e = format_err(read_dicom(&path));
    assert!(e.contains("too short"), "{e}");
}

#[test]
fn colour_is_refused() {
    let dir = scratch("colour");
    let path = dir.join("rgb.dcm");
    write_synthetic(
        &path,
        1,
        vec![DataElement::new(
            tags::SAMPLES_PER_PIXEL,
            VR::US,
            PrimitiveValue::from(3u16),
        )],
    );
    let e = format_err(read_dicom(&path));
    assert!(
        e.contains("colour") && e.contains("SamplesPerPixel = 3"),
        "{e}"
    );
}

fn is(tag: dicom_core::Tag, v: &str) -> DataElement<InMemDicomObject> {
    DataElement::new(tag, VR::IS, PrimitiveValue::from(v))
}

/// A time series: three positions at each of two times, as six single-frame files
/// (in a scrambled order, TemporalPositionIdentifier telling the times apart), and as
/// one multi-frame image (FrameContentSequence's TemporalPositionIndex). Each slice's
/// RescaleIntercept encodes its time and position, so the values say which slices
/// were read. Without --frame the series is refused naming the count.
#[test]
fn time_series_read_one_time_point_at_a_time() {
    let dir = scratch("dicom-time");
    let series = dir.join("series");
    std::fs::create_dir_all(&series).unwrap();
    let intercept = |t: usize, z: usize| 1000 * t + 10 * z;
    for (n, (t, z)) in [(1, 2), (0, 0), (1, 0), (0, 2), (0, 1), (1, 1)]
        .into_iter()
        .enumerate()
    {
        write_synthetic(
            &series.join(format!("im{n}.dcm")),
            1,
            vec![
                ds(tags::IMAGE_POSITION_PATIENT, &format!("0\\0\\{}", 2 * z)),
                ds(tags::IMAGE_ORIENTATION_PATIENT, "1\\0\\0\\0\\1\\0"),
                ds(tags::PIXEL_SPACING, "1\\1"),
                ds(tags::RESCALE_INTERCEPT, &intercept(t, z).to_string()),
                is(tags::TEMPORAL_POSITION_IDENTIFIER, &(t + 1).to_string()),
                is(tags::INSTANCE_NUMBER, &(n + 1).to_string()),
            ],
        );
    }
    assert_eq!(voxlab::io::frame_count(&series).unwrap(), 2);
    let e = format_err(read_dicom(&series));
    assert!(
        e.contains("TemporalPositionIdentifier") && e.contains("2 3-D volumes"),
        "{e}"
    );
    for t in 0..2 {
        let v = voxlab::io::dicom::read_dicom_frame(&series, Some(t)).unwrap();
        assert_eq!(v.dims(), [4, 3, 3]);
        assert_eq!(v.spacing(), [1.0, 1.0, 2.0]);
        let want: Vec<f64> = (0..3)
            .flat_map(|z| (0..12).map(move |i| (i + intercept(t, z)) as f64))
            .collect();
        assert_eq!(v.values_f64(), want, "time point {t}");
    }
    let e = voxlab::io::dicom::read_dicom_frame(&series, Some(2)).unwrap_err();
    assert!(e.to_string().contains("past the file's 2"), "{e}");
    // Without a key that tells the times apart, the same position twice is a duplicate.
    let dup = dir.join("dup");
    std::fs::create_dir_all(&dup).unwrap();
    for (n, z) in [0, 1, 0, 1].into_iter().enumerate() {
        write_synthetic(
            &dup.join(format!("im{n}.dcm")),
            1,
            vec![
                ds(tags::IMAGE_POSITION_PATIENT, &format!("0\\0\\{z}")),
                ds(tags::IMAGE_ORIENTATION_PATIENT, "1\\0\\0\\0\\1\\0"),
            ],
        );
    }
    let e = format_err(read_dicom(&dup));
    assert!(e.contains("duplicate slice position"), "{e}");

    // One multi-frame image: frames at z = 0, 0, 5, 5 with temporal indices 2, 1, 1, 2.
    let path = dir.join("mf.dcm");
    let per_frame: Vec<InMemDicomObject> = [("0", "2"), ("0", "1"), ("5", "1"), ("5", "2")]
        .iter()
        .map(|(z, t)| {
            item(vec![
                seq(
                    tags::PLANE_POSITION_SEQUENCE,
                    vec![item(vec![ds(
                        tags::IMAGE_POSITION_PATIENT,
                        &format!("0\\0\\{z}"),
                    )])],
                ),
                seq(
                    tags::FRAME_CONTENT_SEQUENCE,
                    vec![item(vec![DataElement::new(
                        tags::TEMPORAL_POSITION_INDEX,
                        VR::UL,
                        PrimitiveValue::from(t.parse::<u32>().unwrap()),
                    )])],
                ),
            ])
        })
        .collect();
    let shared = item(vec![seq(
        tags::PLANE_ORIENTATION_SEQUENCE,
        vec![item(vec![ds(
            tags::IMAGE_ORIENTATION_PATIENT,
            "1\\0\\0\\0\\1\\0",
        )])],
    )]);
    write_synthetic(
        &path,
        4,
        vec![
            seq(tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE, vec![shared]),
            seq(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE, per_frame),
        ],
    );
    assert_eq!(voxlab::io::frame_count(&path).unwrap(), 2);
    let e = format_err(read_dicom(&path));
    assert!(e.contains("TemporalPositionIndex"), "{e}");
    // Frame f holds 100·f + i: time 1 (index 1) is file frames 1 (z 0) and 2 (z 5).
    for (t, frames) in [(0, [1, 2]), (1, [0, 3])] {
        let v = voxlab::io::dicom::read_dicom_frame(&path, Some(t)).unwrap();
        assert_eq!(v.dims(), [4, 3, 2]);
        let want: Vec<f64> = frames
            .iter()
            .flat_map(|f| (0..12).map(move |i| (100 * f + i) as f64))
            .collect();
        assert_eq!(v.values_f64(), want, "time point {t}");
    }
}
