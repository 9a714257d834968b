//! NIfTI-1 I/O: round trips, headers built by hand from the standard in both byte
//! orders, every geometry rule, bad input, fixtures written by nibabel (an independent
//! implementation) and the bundled Colin27 scan.

mod common;

use common::{assert_format, bits, gzip, oblique_affine, sample_volumes, scratch};
use glam::{DMat4, DVec3};
use std::path::{Path, PathBuf};
use voxlab::io::nifti::{
    read_nifti, read_nifti_bytes, write_nifti, write_nifti_version, NiftiVersion,
};
use voxlab::io::{read_volume, write_volume};
use voxlab::{AnyVolume, Error, Volume, VoxelKind};

// ---------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/nifti")
}

/// An oblique, anisotropic affine whose entries are all f32-representable (NIfTI
/// stores the sform as f32).
fn f32_affine() -> DMat4 {
    DMat4::from_cols_array(&oblique_affine().to_cols_array().map(|v| v as f32 as f64))
}

#[track_caller]
fn assert_affine_near(a: DMat4, b: DMat4, tol: f64) {
    let (x, y) = (a.to_cols_array(), b.to_cols_array());
    for i in 0..16 {
        assert!((x[i] - y[i]).abs() <= tol, "affines differ:\n{a:?}\n{b:?}");
    }
}

/// A NIfTI-1 header built field by field from the standard (not by the writer under
/// test), followed by the data bytes.
#[derive(Clone)]
struct Hdr {
    big: bool,
    sizeof_hdr: i32,
    dim: [i16; 8],
    datatype: i16,
    bitpix: i16,
    pixdim: [f32; 8],
    vox_offset: f32,
    scl: [f32; 2],
    xyzt_units: u8,
    qform_code: i16,
    sform_code: i16,
    quatern: [f32; 6],
    srow: [[f32; 4]; 3],
    magic: [u8; 4],
}

impl Hdr {
    /// A 3×2×2 u8 volume, identity pixdim, no geometry codes, data at 352.
    fn new(big: bool) -> Hdr {
        Hdr {
            big,
            sizeof_hdr: 348,
            dim: [3, 3, 2, 2, 1, 1, 1, 1],
            datatype: 2,
            bitpix: 8,
            pixdim: [1.0; 8],
            vox_offset: 352.0,
            scl: [0.0, 0.0],
            xyzt_units: 2,
            qform_code: 0,
            sform_code: 0,
            quatern: [0.0; 6],
            srow: [[0.0; 4]; 3],
            magic: *b"n+1\0",
        }
    }

    fn bytes(&self, data: &[u8]) -> Vec<u8> {
        let mut b = vec![0u8; 352];
        let big = self.big;
        let i16b = |v: i16| {
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        let f32b = |v: f32| {
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        let s = if big {
            self.sizeof_hdr.to_be_bytes()
        } else {
            self.sizeof_hdr.to_le_bytes()
        };
        b[0..4].copy_from_slice(&s);
        for i in 0..8 {
            b[40 + 2 * i..42 + 2 * i].copy_from_slice(&i16b(self.dim[i]));
            b[76 + 4 * i..80 + 4 * i].copy_from_slice(&f32b(self.pixdim[i]));
        }
        b[70..72].copy_from_slice(&i16b(self.datatype));
        b[72..74].copy_from_slice(&i16b(self.bitpix));
        b[108..112].copy_from_slice(&f32b(self.vox_offset));
        b[112..116].copy_from_slice(&f32b(self.scl[0]));
        b[116..120].copy_from_slice(&f32b(self.scl[1]));
        b[123] = self.xyzt_units;
        b[252..254].copy_from_slice(&i16b(self.qform_code));
        b[254..256].copy_from_slice(&i16b(self.sform_code));
        for i in 0..6 {
            b[256 + 4 * i..260 + 4 * i].copy_from_slice(&f32b(self.quatern[i]));
        }
        for r in 0..3 {
            for c in 0..4 {
                let o = 280 + 16 * r + 4 * c;
                b[o..o + 4].copy_from_slice(&f32b(self.srow[r][c]));
            }
        }
        b[344..348].copy_from_slice(&self.magic);
        b.extend_from_slice(data);
        b
    }
}

fn read(bytes: &[u8]) -> voxlab::Result<AnyVolume> {
    read_nifti_bytes(bytes, Path::new("t.nii"))
}

fn read_frame(bytes: &[u8], frame: Option<usize>) -> voxlab::Result<AnyVolume> {
    voxlab::io::nifti::read_nifti_bytes_frame(bytes, Path::new("t.nii"), frame)
}

// ---------------------------------------------------------------------------------
// Round trips
// ---------------------------------------------------------------------------------

#[test]
fn round_trips_every_type_plain_and_gzip() {
    let dir = scratch("round_trip");
    let affine = f32_affine();
    for v in sample_volumes(affine) {
        for name in ["v.nii", "v.nii.gz"] {
            let p = dir.join(name);
            write_nifti(&p, &v).unwrap();
            let back = read_nifti(&p).unwrap();
            assert_eq!(back.kind(), v.kind(), "{name}");
            assert_eq!(back.dims(), v.dims());
            assert_eq!(
                back.affine(),
                affine,
                "{name}: the sform gives the affine back exactly"
            );
            assert_eq!(bits(&back), bits(&v), "{name} {:?}", v.kind());
            // The dispatching functions and the in-memory reader agree.
            write_volume(&p, &v).unwrap();
            assert_eq!(bits(&read_volume(&p).unwrap()), bits(&v));
            let bytes = std::fs::read(&p).unwrap();
            assert_eq!(bits(&read_nifti_bytes(&bytes, &p).unwrap()), bits(&v));
        }
    }
    // Nothing but the two files is left in the directory.
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 2);
}

#[test]
fn written_header_fields() {
    let dir = scratch("fields");
    let affine = f32_affine();
    let v: AnyVolume = Volume::with_affine([5, 4, 3], affine, vec![0i16; 60])
        .unwrap()
        .into();
    let p = dir.join("h.nii");
    write_nifti(&p, &v).unwrap();
    let b = std::fs::read(&p).unwrap();
    assert_eq!(b.len(), 352 + 120);
    let i16_at = |o: usize| i16::from_le_bytes([b[o], b[o + 1]]);
    let f32_at = |o: usize| f32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
    assert_eq!(i32::from_le_bytes([b[0], b[1], b[2], b[3]]), 348);
    assert_eq!(&b[344..348], b"n+1\0");
    assert_eq!((i16_at(70), i16_at(72)), (4, 16));
    assert_eq!(f32_at(108), 352.0);
    assert_eq!(b[123], 2);
    assert_eq!((i16_at(252), i16_at(254)), (2, 2));
    assert_eq!(f32_at(76), 1.0);
    for (i, s) in [0.5f32, 1.25, 2.0].iter().enumerate() {
        assert!((f32_at(80 + 4 * i) - s).abs() < 1e-6);
    }
    // The qform alone (sform_code set to 0) gives the same geometry to f32 precision.
    let mut q = b.clone();
    q[254..256].copy_from_slice(&0i16.to_le_bytes());
    assert_affine_near(read(&q).unwrap().affine(), affine, 1e-5);

    // A reflection is written as qfac = −1; a shear has no qform.
    let flip = affine * DMat4::from_scale(DVec3::new(1.0, 1.0, -1.0));
    let v: AnyVolume = Volume::with_affine([2, 2, 2], flip, vec![0u8; 8])
        .unwrap()
        .into();
    write_nifti(&p, &v).unwrap();
    let mut b = std::fs::read(&p).unwrap();
    assert_eq!(f32::from_le_bytes(b[76..80].try_into().unwrap()), -1.0);
    b[254..256].copy_from_slice(&0i16.to_le_bytes());
    assert_affine_near(read(&b).unwrap().affine(), flip, 1e-5);
    let shear = DMat4::from_cols_array(&[
        1.0, 0.0, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
    ]);
    let v: AnyVolume = Volume::with_affine([2, 2, 2], shear, vec![0u8; 8])
        .unwrap()
        .into();
    write_nifti(&p, &v).unwrap();
    let b = std::fs::read(&p).unwrap();
    assert_eq!(i16::from_le_bytes([b[252], b[253]]), 0);
    assert_eq!(read(&b).unwrap().affine(), shear);
}

#[test]
fn axes_longer_than_nifti1_allows_are_written_as_nifti2() {
    let dir = scratch("long");
    let v: AnyVolume = Volume::new(
        [32768, 1, 2],
        [0.5, 1.0, 2.0],
        (0..65536u32).map(|i| (i % 251) as u8).collect(),
    )
    .unwrap()
    .into();
    // NIfTI-1 cannot hold the axis.
    let e = write_nifti_version(&dir.join("one.nii"), &v, NiftiVersion::One).unwrap_err();
    assert!(
        matches!(e, Error::Invalid { .. }) && e.to_string().contains("32767"),
        "{e}"
    );
    assert!(!dir.join("one.nii").exists());
    let p = dir.join("x.nii");
    write_nifti(&p, &v).unwrap();
    let b = std::fs::read(&p).unwrap();
    assert_eq!(i32::from_le_bytes([b[0], b[1], b[2], b[3]]), 540);
    assert_eq!(i64::from_le_bytes(b[24..32].try_into().unwrap()), 32768);
    assert_eq!(bits(&read_nifti(&p).unwrap()), bits(&v));
}

/// A NIfTI-2 header built field by field from the standard (540 bytes, 64-bit sizes,
/// f64 geometry), the extension flag, then the data.
#[allow(clippy::too_many_arguments)]
fn nifti2_bytes(
    big: bool,
    dim: [i64; 8],
    datatype: i16,
    bitpix: i16,
    pixdim: [f64; 8],
    vox_offset: i64,
    sform: Option<[[f64; 4]; 3]>,
    magic: &[u8; 8],
    data: &[u8],
) -> Vec<u8> {
    let mut b = vec![0u8; vox_offset.max(544) as usize];
    macro_rules! put {
        ($off:expr, $v:expr) => {{
            let v = $v;
            let bytes = if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            };
            b[$off..$off + bytes.len()].copy_from_slice(&bytes);
        }};
    }
    put!(0, 540i32);
    b[4..12].copy_from_slice(magic);
    put!(12, datatype);
    put!(14, bitpix);
    for i in 0..8 {
        put!(16 + 8 * i, dim[i]);
        put!(104 + 8 * i, pixdim[i]);
    }
    put!(168, vox_offset);
    put!(176, 0.0f64);
    put!(184, 0.0f64);
    if let Some(rows) = sform {
        put!(348, 1i32);
        for r in 0..3 {
            for c in 0..4 {
                put!(400 + 32 * r + 8 * c, rows[r][c]);
            }
        }
    }
    put!(500, 2i32);
    b.extend_from_slice(data);
    b
}

#[test]
fn nifti2_headers_built_by_hand_in_both_byte_orders() {
    let magic = b"n+2\0\r\n\x1a\n";
    // An sform no f32 holds exactly: NIfTI-2 keeps it to the last bit.
    let rows = [
        [0.1, 0.0, 0.0, -12.345678901234],
        [0.0, 0.2, 0.0, 1.0 / 3.0],
        [0.0, 0.0, 0.30000000000000004, 7.0],
    ];
    for big in [false, true] {
        let data: Vec<u8> = (0..24u16)
            .flat_map(|v| {
                if big {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                }
            })
            .collect();
        let pixdim = [1.0, 0.1, 0.2, 0.3, 1.0, 1.0, 1.0, 1.0];
        let bytes = nifti2_bytes(
            big,
            [4, 2, 3, 2, 2, 1, 1, 1],
            512,
            16,
            pixdim,
            544,
            Some(rows),
            magic,
            &data,
        );
        // Two frames of 2×3×2 u16.
        assert_format(read(&bytes), "dim[4]", "2 3-D volumes");
        let v = read_frame(&bytes, Some(1)).unwrap();
        assert_eq!(v.kind(), VoxelKind::U16);
        assert_eq!(v.dims(), [2, 3, 2]);
        assert_eq!(v.values_f64(), (12..24).map(f64::from).collect::<Vec<_>>());
        let a = v.affine();
        for (r, row) in rows.iter().enumerate() {
            assert_eq!(&a.row(r).to_array(), row, "big {big}");
        }
        // Gzip too.
        assert_eq!(bits(&read_frame(&gzip(&bytes), Some(1)).unwrap()), bits(&v));
        // Fields checked as in NIfTI-1.
        let bad = nifti2_bytes(
            big,
            [3, 2, 3, 2, 1, 1, 1, 1],
            512,
            8,
            pixdim,
            544,
            None,
            magic,
            &data,
        );
        assert_format(read(&bad), "bitpix", "does not match");
        let bad = nifti2_bytes(
            big,
            [3, 2, 3, 2, 1, 1, 1, 1],
            512,
            16,
            pixdim,
            540,
            None,
            magic,
            &data,
        );
        assert_format(read(&bad), "vox_offset", "at least 544");
        let bad = nifti2_bytes(
            big,
            [3, 2, 3, 2, 1, 1, 1, 1],
            512,
            16,
            pixdim,
            544,
            None,
            b"n+1\0\0\0\0\0",
            &data,
        );
        assert_format(read(&bad), "magic", "not a NIfTI-2 file");
        let bad = nifti2_bytes(
            big,
            [3, 2, -3, 2, 1, 1, 1, 1],
            512,
            16,
            pixdim,
            544,
            None,
            magic,
            &data,
        );
        assert_format(read(&bad), "dim[2]", "at least 1");
        let huge = nifti2_bytes(
            big,
            [3, 1 << 40, 1 << 40, 2, 1, 1, 1, 1],
            512,
            16,
            pixdim,
            544,
            None,
            magic,
            &data,
        );
        assert!(read(&huge).is_err());
    }
}

/// A NIfTI-2 file is told by its content, whatever its name; `ni2` pairs keep their
/// voxels (every frame) in the `.img`; `voxlab info` names the frames and `--frame`
/// picks one on the command line.
#[test]
fn nifti2_files_on_disk_pairs_and_the_command_line() {
    let dir = scratch("nifti2-disk");
    let data: Vec<u8> = (0..24).collect();
    let pixdim = [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0];
    let dim = [4, 3, 2, 2, 2, 1, 1, 1];
    for big in [false, true] {
        let single = nifti2_bytes(big, dim, 2, 8, pixdim, 544, None, b"n+2\0\r\n\x1a\n", &data);
        let p = dir.join(format!("scan-{big}.bin"));
        std::fs::write(&p, &single).unwrap();
        assert_eq!(
            voxlab::io::detect_format(&p).unwrap(),
            voxlab::io::Format::Nifti
        );
        assert_eq!(voxlab::io::frame_count(&p).unwrap(), 2);
        let opts = voxlab::io::ReadOptions {
            frame: Some(1),
            ..Default::default()
        };
        let v = voxlab::io::read_volume_with(&p, &opts).unwrap();
        assert_eq!(v.values_f64(), (12..24).map(f64::from).collect::<Vec<_>>());

        // A pair: the header alone in p.hdr, both frames in p.img from vox_offset 0.
        let pair = nifti2_bytes(big, dim, 2, 8, pixdim, 0, None, b"ni2\0\r\n\x1a\n", &[]);
        let hdr = dir.join(format!("pair-{big}.hdr"));
        std::fs::write(&hdr, &pair[..540]).unwrap();
        std::fs::write(dir.join(format!("pair-{big}.img")), &data).unwrap();
        assert_eq!(voxlab::io::read_volume_with(&hdr, &opts).unwrap(), v);
        assert_format(read_nifti(&hdr), "dim[4]", "2 3-D volumes");
    }
    let p = dir.join("scan-false.bin");
    let p = p.to_str().unwrap();
    let out = common::voxlab(&["info", p]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("NIfTI") && text.contains("frames"), "{text}");
    assert!(text.contains("2 3-D volumes"), "{text}");
    let out = common::voxlab(&["info", p, "--frame", "2"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("past the file's 2"),
        "{err}"
    );
}

#[test]
fn nifti2_round_trips_with_the_affine_exact() {
    let dir = scratch("nifti2");
    for v in sample_volumes(oblique_affine()) {
        for name in ["v.nii", "v.nii.gz"] {
            let p = dir.join(name);
            write_nifti_version(&p, &v, NiftiVersion::Two).unwrap();
            let back = read_nifti(&p).unwrap();
            assert_eq!(bits(&back), bits(&v), "{name}");
            // f64 geometry: exactly the affine written (NIfTI-1 rounds it to f32).
            assert_eq!(back.affine(), v.affine(), "{name}");
        }
    }
}

// ---------------------------------------------------------------------------------
// Hand-built headers
// ---------------------------------------------------------------------------------

#[test]
fn hand_built_headers_in_both_byte_orders() {
    for big in [false, true] {
        // u8
        let h = Hdr::new(big);
        let v = read(&h.bytes(&(0..12).collect::<Vec<u8>>())).unwrap();
        assert_eq!((v.kind(), v.dims()), (VoxelKind::U8, [3, 2, 2]));
        assert_eq!(v.values_f64(), (0..12).map(f64::from).collect::<Vec<_>>());
        assert_eq!(v.affine(), DMat4::IDENTITY);

        // Every stored type, with the value −2 or 200 and 7.
        let cases: [Case; 10] = [
            (2, 8, vec![200, 7], VoxelKind::U8, [200.0, 7.0]),
            (256, 8, vec![0xfe, 7], VoxelKind::I16, [-2.0, 7.0]),
            (
                4,
                16,
                enc(big, &[(-2i16).to_be_bytes(), 7i16.to_be_bytes()]),
                VoxelKind::I16,
                [-2.0, 7.0],
            ),
            (
                512,
                16,
                enc(big, &[200u16.to_be_bytes(), 7u16.to_be_bytes()]),
                VoxelKind::U16,
                [200.0, 7.0],
            ),
            (
                8,
                32,
                enc(big, &[(-2i32).to_be_bytes(), 7i32.to_be_bytes()]),
                VoxelKind::F32,
                [-2.0, 7.0],
            ),
            (
                768,
                32,
                enc(big, &[200u32.to_be_bytes(), 7u32.to_be_bytes()]),
                VoxelKind::F32,
                [200.0, 7.0],
            ),
            (
                1024,
                64,
                enc(big, &[(-2i64).to_be_bytes(), 7i64.to_be_bytes()]),
                VoxelKind::F32,
                [-2.0, 7.0],
            ),
            (
                1280,
                64,
                enc(big, &[200u64.to_be_bytes(), 7u64.to_be_bytes()]),
                VoxelKind::F32,
                [200.0, 7.0],
            ),
            (
                16,
                32,
                enc(big, &[(-2f32).to_be_bytes(), 7f32.to_be_bytes()]),
                VoxelKind::F32,
                [-2.0, 7.0],
            ),
            (
                64,
                64,
                enc(big, &[(-2f64).to_be_bytes(), 7f64.to_be_bytes()]),
                VoxelKind::F32,
                [-2.0, 7.0],
            ),
        ];
        for (datatype, bitpix, data, kind, values) in cases {
            let mut h = Hdr::new(big);
            h.dim = [2, 2, 1, 1, 0, 0, 0, 0]; // dims beyond dim[0] are ignored
            h.datatype = datatype;
            h.bitpix = bitpix;
            let v = read(&h.bytes(&data)).unwrap();
            assert_eq!(v.kind(), kind, "datatype {datatype}");
            assert_eq!(v.dims(), [2, 1, 1]);
            assert_eq!(v.values_f64(), values, "datatype {datatype} big {big}");
        }
    }
}

/// datatype, bitpix, data bytes, the kind read and the values read.
type Case = (i16, i16, Vec<u8>, VoxelKind, [f64; 2]);

/// Big-endian byte arrays, reversed for a little-endian file.
fn enc<const N: usize>(big: bool, values: &[[u8; N]]) -> Vec<u8> {
    values
        .iter()
        .flat_map(|v| {
            let mut v = *v;
            if !big {
                v.reverse();
            }
            v
        })
        .collect()
}

#[test]
fn scaling() {
    let data: Vec<u8> = (0..12).collect();
    let scaled = |slope: f32, inter: f32| {
        let mut h = Hdr::new(true);
        h.scl = [slope, inter];
        read(&h.bytes(&data))
    };
    let v = scaled(2.0, -1.5).unwrap();
    assert_eq!(v.kind(), VoxelKind::F32);
    assert_eq!(
        v.values_f64(),
        (0..12).map(|x| x as f64 * 2.0 - 1.5).collect::<Vec<_>>()
    );
    let v = scaled(1.0, 5.0).unwrap();
    assert_eq!(v.values_f64()[3], 8.0);
    // No scaling: slope 0, non-finite slope, or exactly (1, 0).
    for (s, i) in [
        (0.0, 7.0),
        (f32::NAN, 7.0),
        (f32::INFINITY, 0.0),
        (1.0, 0.0),
    ] {
        let v = scaled(s, i).unwrap();
        assert_eq!(v.kind(), VoxelKind::U8, "slope {s} inter {i}");
        assert_eq!(v.values_f64()[3], 3.0);
    }
    assert_format(scaled(2.0, f32::NAN), "scl_inter", "not finite");
}

#[test]
fn geometry_rules() {
    let data = [0u8; 12];
    // Neither code: the diagonal of pixdim (method 1).
    let mut h = Hdr::new(false);
    h.pixdim = [1.0, 0.5, 2.0, 3.0, 1.0, 1.0, 1.0, 1.0];
    let v = read(&h.bytes(&data)).unwrap();
    assert_eq!(v.affine(), DMat4::from_scale(DVec3::new(0.5, 2.0, 3.0)));
    // Units: metres and micrometres become millimetres.
    h.xyzt_units = 1 | 8; // metres, seconds
    assert_eq!(
        read(&h.bytes(&data)).unwrap().affine(),
        DMat4::from_scale(DVec3::new(500.0, 2000.0, 3000.0))
    );
    h.xyzt_units = 3;
    assert_affine_near(
        read(&h.bytes(&data)).unwrap().affine(),
        DMat4::from_scale(DVec3::new(0.0005, 0.002, 0.003)),
        1e-15,
    );

    // qform only: 90° about z (b = c = 0, d = sin 45°), pixdim (2, 3, 4), qfac −1.
    let mut h = Hdr::new(true);
    h.qform_code = 1;
    h.pixdim = [-1.0, 2.0, 3.0, 4.0, 1.0, 1.0, 1.0, 1.0];
    h.quatern = [0.0, 0.0, std::f32::consts::FRAC_1_SQRT_2, 10.0, -20.0, 30.0];
    let want = DMat4::from_cols_array(&[
        0.0, 2.0, 0.0, 0.0, //
        -3.0, 0.0, 0.0, 0.0, //
        0.0, 0.0, -4.0, 0.0, //
        10.0, -20.0, 30.0, 1.0,
    ]);
    assert_affine_near(read(&h.bytes(&data)).unwrap().affine(), want, 1e-6);
    // qfac 0 counts as 1.
    h.pixdim[0] = 0.0;
    let got = read(&h.bytes(&data)).unwrap().affine();
    assert!((got.z_axis.z - 4.0).abs() < 1e-6);

    // sform (any code > 0) wins over the qform.
    h.sform_code = 1;
    h.srow = [
        [0.0, 0.0, 1.5, -1.0],
        [0.0, -2.0, 0.0, 2.0],
        [0.25, 0.0, 0.0, 3.0],
    ];
    let want = DMat4::from_cols_array(&[
        0.0, 0.0, 0.25, 0.0, //
        0.0, -2.0, 0.0, 0.0, //
        1.5, 0.0, 0.0, 0.0, //
        -1.0, 2.0, 3.0, 1.0,
    ]);
    assert_eq!(read(&h.bytes(&data)).unwrap().affine(), want);
    // sform only.
    h.qform_code = 0;
    assert_eq!(read(&h.bytes(&data)).unwrap().affine(), want);
}

#[test]
fn bad_geometry_is_refused_naming_the_field() {
    let data = [0u8; 12];
    let mut h = Hdr::new(false);
    h.sform_code = 2; // all-zero srow: singular
    assert_format(read(&h.bytes(&data)), "sform", "singular");
    h.srow = [
        [1.0, 0.0, 0.0, f32::NAN],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ];
    assert_format(read(&h.bytes(&data)), "sform", "not finite");
    let mut h = Hdr::new(false);
    h.qform_code = 1;
    h.quatern = [0.0, 2.0, 0.0, 0.0, 0.0, 0.0];
    assert_format(read(&h.bytes(&data)), "qform", "not a rotation");
    h.quatern = [0.0, 0.0, 0.0, f32::INFINITY, 0.0, 0.0];
    assert_format(read(&h.bytes(&data)), "qform", "not finite");
    h.quatern = [0.0; 6];
    h.pixdim[2] = 0.0;
    assert_format(read(&h.bytes(&data)), "pixdim", "non-zero");
    h.qform_code = 0;
    h.pixdim[2] = f32::NAN;
    assert_format(read(&h.bytes(&data)), "pixdim", "finite");
}

#[test]
fn four_d_files_give_the_frame_asked_for_and_trailing_unit_axes_are_fine() {
    let data: Vec<u8> = (0..36).collect();
    let mut h = Hdr::new(false);
    h.dim = [4, 3, 2, 2, 3, 1, 1, 1];
    // Three 3×2×2 volumes: without a frame the file is refused, naming how many.
    assert_format(read(&h.bytes(&data)), "dim[4]", "3 3-D volumes (t 3)");
    for k in 0..3 {
        let v = read_frame(&h.bytes(&data), Some(k)).unwrap();
        assert_eq!(v.dims(), [3, 2, 2]);
        assert_eq!(
            v.values_f64(),
            (12 * k..12 * k + 12).map(|x| x as f64).collect::<Vec<_>>()
        );
    }
    assert_format(
        read_frame(&h.bytes(&data), Some(3)),
        "dim[4]",
        "past the file's 3",
    );
    // Axes 4 … 7 count as one, the fourth fastest: (t 1, u 2) holds two volumes.
    h.dim = [5, 3, 2, 2, 1, 2, 1, 1];
    assert_format(read(&h.bytes(&data)), "dim[4]", "t 1, u 2");
    assert_eq!(
        read_frame(&h.bytes(&data), Some(1)).unwrap().values_f64()[0],
        12.0
    );
    // Every frame must be in the file, though one is read.
    h.dim = [4, 3, 2, 2, 4, 1, 1, 1];
    assert_format(read_frame(&h.bytes(&data), Some(0)), "data", "too short");
    h.dim = [7, 3, 2, 2, 1, 1, 1, 1];
    assert_eq!(read(&h.bytes(&data)).unwrap().dims(), [3, 2, 2]);
    h.dim = [2, 3, 2, 9, 9, 9, 9, 9];
    assert_eq!(read(&h.bytes(&data)).unwrap().dims(), [3, 2, 1]);
}

#[test]
fn bad_headers_name_the_field() {
    let data = [0u8; 12];
    let good = Hdr::new(false);
    let with = |f: &dyn Fn(&mut Hdr)| {
        let mut h = good.clone();
        f(&mut h);
        read(&h.bytes(&data))
    };
    assert_format(with(&|h| h.sizeof_hdr = 347), "sizeof_hdr", "neither 348");
    assert_format(with(&|h| h.sizeof_hdr = 347), "sizeof_hdr", "NIfTI-2");
    // 540 says NIfTI-2, whose 540-byte header this short file does not hold.
    assert_format(with(&|h| h.sizeof_hdr = 540), "header", "truncated");
    assert_format(with(&|h| h.magic = *b"n+2\0"), "magic", "not a NIfTI-1");
    assert_format(with(&|h| h.magic = [0; 4]), "magic", "Analyze");
    assert_format(with(&|h| h.dim[0] = 0), "dim[0]", "1 to 7");
    assert_format(with(&|h| h.dim[0] = 8), "dim[0]", "1 to 7");
    assert_format(with(&|h| h.dim[2] = -2), "dim[2]", "at least 1");
    assert_format(with(&|h| h.dim[1] = 0), "dim[1]", "at least 1");
    assert_format(with(&|h| h.bitpix = 16), "bitpix", "does not match");
    assert_format(with(&|h| h.datatype = 128), "datatype", "RGB24");
    assert_format(with(&|h| h.datatype = 32), "datatype", "complex64");
    assert_format(with(&|h| h.datatype = 2304), "datatype", "RGBA32");
    assert_format(with(&|h| h.datatype = 1536), "datatype", "float128");
    assert_format(
        with(&|h| h.datatype = 7),
        "datatype",
        "not a NIfTI datatype",
    );
    assert_format(
        with(&|h| h.vox_offset = 348.0),
        "vox_offset",
        "at least 352",
    );
    assert_format(
        with(&|h| h.vox_offset = 352.5),
        "vox_offset",
        "whole number",
    );
    assert_format(
        with(&|h| h.vox_offset = f32::NAN),
        "vox_offset",
        "whole number",
    );
    assert_format(
        with(&|h| h.vox_offset = 4000.0),
        "vox_offset",
        "past the end",
    );
    assert_format(
        with(&|h| h.vox_offset = 356.0),
        "data",
        "expected 12 bytes, found 8",
    );
    // Absurd sizes are refused from the header, before anything is allocated.
    assert_format(
        with(&|h| h.dim = [3, 32767, 32767, 32767, 1, 1, 1, 1]),
        "dim",
        "limit",
    );
    // A size within the limit that the data cannot hold is refused before allocating.
    assert_format(
        with(&|h| h.dim = [3, 1000, 1000, 1000, 1, 1, 1, 1]),
        "data",
        "too short",
    );
    let mut gz = good.clone();
    gz.dim = [3, 1000, 1000, 1000, 1, 1, 1, 1];
    assert_format(read(&gzip(&gz.bytes(&data))), "data", "cannot fit");
    // A short header.
    assert_format(read(&good.bytes(&data)[..200]), "header", "truncated");
    assert_format(read(&[]), "sizeof_hdr", "too short");
}

#[test]
fn truncations_and_garbage_give_errors_not_panics() {
    let mut h = Hdr::new(true);
    h.datatype = 4;
    h.bitpix = 16;
    h.scl = [0.5, 1.0];
    h.qform_code = 1;
    h.quatern = [0.1, 0.2, 0.3, 1.0, 2.0, 3.0];
    let plain = h.bytes(&[7u8; 24]);
    let packed = gzip(&plain);
    assert!(read(&plain).is_ok() && read(&packed).is_ok());
    for n in 0..plain.len() {
        assert!(read(&plain[..n]).is_err(), "plain cut at {n}");
    }
    for n in 0..packed.len() {
        assert!(read(&packed[..n]).is_err(), "gzip cut at {n}");
    }
    // Random bytes, and a valid header with random bytes changed.
    let mut x: u64 = 0x243f6a8885a308d3;
    let mut next = || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    for len in [0, 1, 4, 100, 348, 352, 400, 1000] {
        let g: Vec<u8> = (0..len).map(|_| next() as u8).collect();
        let _ = read(&g);
        let _ = read(&gzip(&g));
    }
    for _ in 0..2000 {
        let mut m = plain.clone();
        for _ in 0..1 + next() % 4 {
            let i = (next() % m.len() as u64) as usize;
            m[i] = next() as u8;
        }
        let _ = read(&m);
    }
}

#[test]
fn hdr_img_pairs() {
    let dir = scratch("pair");
    let mut h = Hdr::new(false);
    h.magic = *b"ni1\0";
    h.vox_offset = 0.0;
    let header = h.bytes(&[]);
    std::fs::write(dir.join("p.hdr"), &header[..348]).unwrap();
    std::fs::write(dir.join("p.img"), (0..12).collect::<Vec<u8>>()).unwrap();
    let v = read_nifti(&dir.join("p.hdr")).unwrap();
    assert_eq!(v.values_f64(), (0..12).map(f64::from).collect::<Vec<_>>());
    // The format is told from the magic at byte 344.
    assert_eq!(read_volume(&dir.join("p.hdr")).unwrap(), v);
    // Compressed pair.
    std::fs::write(dir.join("q.hdr.gz"), gzip(&header[..348])).unwrap();
    std::fs::write(dir.join("q.img.gz"), gzip(&(0..12).collect::<Vec<u8>>())).unwrap();
    assert_eq!(read_nifti(&dir.join("q.hdr.gz")).unwrap(), v);
    // A data offset inside the .img file.
    h.vox_offset = 2.0;
    std::fs::write(dir.join("r.hdr"), &h.bytes(&[])[..348]).unwrap();
    std::fs::write(dir.join("r.img"), (0..14).collect::<Vec<u8>>()).unwrap();
    assert_eq!(read_nifti(&dir.join("r.hdr")).unwrap().values_f64()[0], 2.0);
    // Missing .img, and a ni1 header in memory.
    std::fs::remove_file(dir.join("p.img")).unwrap();
    assert_format(read_nifti(&dir.join("p.hdr")), "magic", "p.img");
    assert_format(read(&header), "magic", "separate .img");
}

// ---------------------------------------------------------------------------------
// Peer check against nibabel, and the bundled Colin27 scan
// ---------------------------------------------------------------------------------

/// tests/data/nifti holds files written by nibabel (make_fixtures.py) and
/// expected.json: nibabel's `img.affine` and `get_fdata()` values for each.
#[test]
fn nibabel_fixtures_match() {
    let text = std::fs::read_to_string(data_dir().join("expected.json")).unwrap();
    let expected: serde_json::Value = serde_json::from_str(&text).unwrap();
    let files = expected.as_object().unwrap();
    assert_eq!(files.len(), 4);
    for (name, e) in files {
        let v = read_nifti(&data_dir().join(name)).unwrap();
        let shape: Vec<usize> = e["shape"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap() as usize)
            .collect();
        assert_eq!(v.dims().to_vec(), shape, "{name}");
        let rows = e["affine"].as_array().unwrap();
        let mut want = [0.0; 16];
        for (r, row) in rows.iter().enumerate() {
            for (c, x) in row.as_array().unwrap().iter().enumerate() {
                want[c * 4 + r] = x.as_f64().unwrap();
            }
        }
        let want = DMat4::from_cols_array(&want);
        let diff = (v.affine() - want)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |m, d| m.max(d.abs()));
        eprintln!("{name}: largest affine difference from nibabel {diff:e}");
        assert_affine_near(v.affine(), want, 1e-5);
        let values: Vec<f64> = e["values"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        let got = v.values_f64();
        assert_eq!(got.len(), values.len());
        for (g, w) in got.iter().zip(&values) {
            assert!(
                (g - w).abs() <= 1e-6 * w.abs().max(1.0),
                "{name}: {g} vs {w}"
            );
        }
        let kind = match e["datatype"].as_i64().unwrap() {
            2 => VoxelKind::U8,
            4 if e["slope_inter"][0].as_f64() == Some(1.0) => VoxelKind::I16,
            _ => VoxelKind::F32,
        };
        assert_eq!(v.kind(), kind, "{name}");
    }
}

/// Files written by voxlab read back in nibabel with the same affine (from the sform
/// and from the qform, which includes a reflection here) and values. Runs when a Python
/// with nibabel is available: `$VOXLAB_PYTHON`, else `python3`.
#[test]
fn written_files_read_in_nibabel_when_available() {
    let dir = scratch("to_nibabel");
    let affine = f32_affine() * DMat4::from_scale(DVec3::new(1.0, -1.0, 1.0));
    let values: Vec<i16> = (0..60).map(|i| (i * 97 % 1000 - 500) as i16).collect();
    let v: AnyVolume = Volume::with_affine([5, 4, 3], affine, values.clone())
        .unwrap()
        .into();
    let path = dir.join("w.nii.gz");
    write_nifti(&path, &v).unwrap();
    let script = format!(
        "import json, nibabel as nib, numpy as np; img = nib.load(r'{}'); \
         d = np.asarray(img.dataobj); \
         print(json.dumps({{'affine': img.affine.tolist(), 'qform': img.get_qform().tolist(), \
         'codes': [int(img.header['qform_code']), int(img.header['sform_code'])], \
         'dtype': str(d.dtype), 'shape': list(d.shape), \
         'values': d.ravel(order='F').astype(float).tolist()}}))",
        path.display()
    );
    let python = std::env::var("VOXLAB_PYTHON").unwrap_or_else(|_| "python3".into());
    let out = std::process::Command::new(python)
        .args(["-c", &script])
        .stderr(std::process::Stdio::null())
        .output();
    let out = match out {
        Ok(o) if o.status.success() => o.stdout,
        _ => {
            println!("note: no Python with nibabel; nibabel read-back test skipped");
            return;
        }
    };
    let e: serde_json::Value = serde_json::from_slice(&out).unwrap();
    let matrix = |key: &str| {
        let mut m = [0.0; 16];
        for (r, row) in e[key].as_array().unwrap().iter().enumerate() {
            for (c, x) in row.as_array().unwrap().iter().enumerate() {
                m[c * 4 + r] = x.as_f64().unwrap();
            }
        }
        DMat4::from_cols_array(&m)
    };
    assert_eq!(matrix("affine"), affine);
    assert_affine_near(matrix("qform"), affine, 1e-5);
    assert_eq!(e["codes"], serde_json::json!([2, 2]));
    assert_eq!(e["dtype"], "int16");
    assert_eq!(e["shape"], serde_json::json!([5, 4, 3]));
    let got: Vec<f64> = e["values"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert_eq!(
        got,
        values.iter().map(|&x| f64::from(x)).collect::<Vec<_>>()
    );
}

/// The Colin27 average brain (ch2.nii.gz, from Debian's mricron-data). Expected
/// numbers from nibabel 5: `img = nib.load(...)`; `img.shape` = (181, 217, 181),
/// dtype uint8, sform_code 4, `img.affine` = [[1,0,0,-90],[0,1,0,-125],[0,0,1,-71]];
/// `d = np.asarray(img.dataobj)`: `d.sum()` = 317151210, `d.min()` = 0, `d.max()` = 254,
/// `d[90, 108, 90]` = 33 (nibabel indexes d[x, y, z]).
#[test]
fn colin27() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/mr-colin27/ch2.nii.gz");
    let v = read_volume(&p).unwrap();
    assert_eq!(v.kind(), VoxelKind::U8);
    assert_eq!(v.dims(), [181, 217, 181]);
    let want = DMat4::from_cols_array(&[
        1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -90.0, -125.0, -71.0, 1.0,
    ]);
    assert_eq!(v.affine(), want);
    let AnyVolume::U8(v) = v else { unreachable!() };
    let sum: u64 = v.data().iter().map(|&x| u64::from(x)).sum();
    assert_eq!(sum, 317_151_210);
    assert_eq!(v.data().iter().max(), Some(&254));
    assert_eq!(v.data().iter().min(), Some(&0));
    assert_eq!(*v.get(90, 108, 90), 33);
}
