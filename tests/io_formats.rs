//! Volume I/O: NRRD and .npy round trips, hand-written files checked against known
//! values, every kind of bad input, and the atomic writer.

mod common;

use common::{
    assert_format, bits, format_field, gzip, oblique_affine, sample_volumes, scratch, XorShift,
};
use glam::{DMat3, DMat4, DVec3};
use std::path::{Path, PathBuf};
use voxlab::io::npy::{read_npy_f32, read_npy_volume, write_npy_f32, write_npy_volume};
use voxlab::io::nrrd::{read_nrrd, write_nrrd, NrrdWriteOptions};
use voxlab::io::{read_volume, write_atomic, write_volume};
use voxlab::{AnyVolume, Error, Volume, VoxelKind};

// ---------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------

/// The names in a directory, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

fn assert_same(a: &AnyVolume, b: &AnyVolume, affine: DMat4) {
    assert_eq!(a.kind(), b.kind());
    assert_eq!(a.dims(), b.dims());
    assert_eq!(b.affine(), affine);
    assert_eq!(bits(a), bits(b));
}

fn write_file(path: &Path, bytes: &[u8]) -> PathBuf {
    std::fs::write(path, bytes).unwrap();
    path.to_path_buf()
}

/// A NRRD file: the header (which must end with its blank line) and the data.
fn nrrd_file(dir: &Path, name: &str, header: &str, data: &[u8]) -> PathBuf {
    let mut bytes = header.as_bytes().to_vec();
    bytes.extend_from_slice(data);
    write_file(&dir.join(name), &bytes)
}

/// An .npy file built from the format specification (not with the writer under
/// test): magic, version, little-endian header length, the dict padded with spaces
/// and ended by a newline so that the whole prefix is a multiple of 64 bytes.
fn npy_bytes(major: u8, dict: &str, data: &[u8]) -> Vec<u8> {
    let len_bytes = if major == 1 { 2 } else { 4 };
    let prefix = 8 + len_bytes;
    let total = (prefix + dict.len() + 1).div_ceil(64) * 64;
    let header_len = total - prefix;
    let mut b = b"\x93NUMPY".to_vec();
    b.extend_from_slice(&[major, 0]);
    b.extend_from_slice(&(header_len as u32).to_le_bytes()[..len_bytes]);
    b.extend_from_slice(dict.as_bytes());
    b.resize(total - 1, b' ');
    b.push(b'\n');
    assert_eq!(b.len() % 64, 0);
    b.extend_from_slice(data);
    b
}

fn npy_dict(descr: &str, fortran: bool, shape: &str) -> String {
    let order = if fortran { "True" } else { "False" };
    format!("{{'descr': '{descr}', 'fortran_order': {order}, 'shape': {shape}, }}")
}

// ---------------------------------------------------------------------------------
// Round trips
// ---------------------------------------------------------------------------------

#[test]
fn nrrd_round_trips_every_type_and_layout() {
    let dir = scratch("nrrd_round_trip");
    for vol in sample_volumes(oblique_affine()) {
        for gzip in [false, true] {
            for detached in [false, true] {
                let ext = if detached { "nhdr" } else { "nrrd" };
                let path = dir.join(format!("v_{}_{gzip}.{ext}", vol.kind().name()));
                write_nrrd(&path, &vol, NrrdWriteOptions { gzip, detached }).unwrap();
                let back = read_nrrd(&path).unwrap();
                assert_same(&vol, &back, oblique_affine());
                if detached {
                    let data = path.with_extension(if gzip { "raw.gz" } else { "raw" });
                    assert!(data.is_file(), "{} missing", data.display());
                }
            }
        }
    }
    // No temporary files are left behind.
    assert!(listing(&dir).iter().all(|n| !n.starts_with('.')));
}

#[test]
fn npy_round_trips_every_type() {
    let dir = scratch("npy_round_trip");
    for vol in sample_volumes(oblique_affine()) {
        let path = dir.join(format!("v_{}.npy", vol.kind().name()));
        write_npy_volume(&path, &vol).unwrap();
        let back = read_npy_volume(&path).unwrap();
        // .npy has no geometry: the affine comes back as the identity.
        assert_same(&vol, &back, DMat4::IDENTITY);
    }
}

#[test]
fn read_and_write_volume_dispatch_on_extension() {
    let dir = scratch("dispatch");
    let vol = &sample_volumes(oblique_affine())[2];
    for name in ["a.nrrd", "b.NHDR", "c.npy", "d.nii", "e.nii.gz"] {
        let path = dir.join(name);
        write_volume(&path, vol).unwrap();
        let back = read_volume(&path).unwrap();
        assert_eq!(bits(&back), bits(vol));
    }
    // The detached header's gzip data file sits beside it.
    assert!(dir.join("b.raw.gz").is_file());
    let header = std::fs::read_to_string(dir.join("b.NHDR")).unwrap();
    assert!(header.contains("data file: b.raw.gz"), "{header}");
    assert!(header.contains("encoding: gzip"), "{header}");

    // Existing files in no format voxlab knows (by magic or extension): the error
    // lists the formats; a raw file asks for its description.
    for (bad, words) in [("x.xyz", ".nrrd"), ("x", ".npy"), ("x.raw", "--raw-dims")] {
        let path = dir.join(bad);
        std::fs::write(&path, b"just some bytes, not a volume").unwrap();
        let e = read_volume(&path).unwrap_err();
        assert!(matches!(e, Error::Invalid { .. }), "{e}");
        assert!(e.to_string().contains(words), "{e}");
        let e = write_volume(&dir.join(bad), vol).unwrap_err();
        assert!(matches!(e, Error::Invalid { .. }), "{e}");
    }
    // The magic number wins over the extension: a NIfTI file named .dat reads.
    std::fs::copy(dir.join("d.nii"), dir.join("renamed.dat")).unwrap();
    assert_eq!(
        bits(&read_volume(&dir.join("renamed.dat")).unwrap()),
        bits(vol)
    );
    let e = read_volume(&dir.join("missing.nrrd")).unwrap_err();
    assert!(matches!(e, Error::Io { .. }), "{e}");
}

#[test]
fn npy_f32_arrays_round_trip() {
    let dir = scratch("npy_f32");
    let path = dir.join("rgba.npy");
    let data: Vec<f32> = (0..2 * 3 * 4).map(|i| i as f32 * 0.25 - 1.0).collect();
    write_npy_f32(&path, &[2, 3, 4], &data).unwrap();
    assert_eq!(read_npy_f32(&path).unwrap(), (vec![2, 3, 4], data.clone()));
    // The header is what the specification asks for.
    let bytes = std::fs::read(&path).unwrap();
    let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
    assert_eq!((10 + header_len) % 64, 0);
    let dict = std::str::from_utf8(&bytes[10..10 + header_len]).unwrap();
    assert_eq!(
        dict.trim_end(),
        "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3, 4), }"
    );
    // A 1-D array needs Python's 1-tuple syntax.
    write_npy_f32(&path, &[3], &data[..3]).unwrap();
    assert_eq!(read_npy_f32(&path).unwrap(), (vec![3], data[..3].to_vec()));
    // The shape must hold the data.
    let e = write_npy_f32(&path, &[5, 5], &data).unwrap_err();
    assert!(matches!(e, Error::Invalid { .. }), "{e}");
}

// ---------------------------------------------------------------------------------
// Hand-written NRRD files
// ---------------------------------------------------------------------------------

const SHORT_BE: &str =
    "NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 1\nendian: big\nencoding: raw\n\n";

#[test]
fn nrrd_big_endian_short() {
    let dir = scratch("nrrd_be");
    let path = nrrd_file(
        &dir,
        "be.nrrd",
        SHORT_BE,
        &[0x01, 0x02, 0xff, 0xfe, 0x80, 0x00, 0x7f, 0xff],
    );
    let AnyVolume::I16(v) = read_nrrd(&path).unwrap() else {
        panic!("expected i16")
    };
    assert_eq!(v.dims(), [2, 2, 1]);
    assert_eq!(v.data(), [258, -2, i16::MIN, i16::MAX]);
    assert_eq!(v.affine(), DMat4::IDENTITY);
}

#[test]
fn nrrd_space_directions_and_origin_give_the_exact_affine() {
    let dir = scratch("nrrd_geometry");
    let header = "NRRD0005\n# an oblique, anisotropic grid\ntype: float\ndimension: 3\n\
        space: left-posterior-superior\nsizes: 2 1 1\n\
        space directions: (0.6,0.8,0) (-1.6, 1.2, 0) (0,0,2.25)\n\
        space origin: (-10.5,20,5.125)\nkinds: domain domain domain\n\
        endian: little\nencoding: raw\nmeasurement frame: (1,0,0) (0,1,0) (0,0,1)\n\
        note:=key: value pairs are ignored\n\n";
    let data: Vec<u8> = [1.5f32, -2.0]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let path = nrrd_file(&dir, "geo.nrrd", header, &data);
    let vol = read_nrrd(&path).unwrap();
    let want = DMat4::from_cols(
        DVec3::new(0.6, 0.8, 0.0).extend(0.0),
        DVec3::new(-1.6, 1.2, 0.0).extend(0.0),
        DVec3::new(0.0, 0.0, 2.25).extend(0.0),
        DVec3::new(-10.5, 20.0, 5.125).extend(1.0),
    );
    // LPS stays LPS: nothing is flipped.
    assert_eq!(vol.affine(), want);
    assert_eq!(vol.values_f64(), [1.5, -2.0]);
    assert_eq!(vol.spacing()[2], 2.25);
}

#[test]
fn nrrd_spacings_and_2d_images() {
    let dir = scratch("nrrd_2d");
    let header =
        "NRRD0004\ntype: uint8_t\ndimension: 2\nsizes: 3 2\nspacings: 0.5 0.25\nencoding: raw\n\n";
    let path = nrrd_file(&dir, "img.nrrd", header, &[1, 2, 3, 4, 5, 6]);
    let vol = read_nrrd(&path).unwrap();
    assert_eq!(vol.kind(), VoxelKind::U8);
    assert_eq!(vol.dims(), [3, 2, 1]);
    assert_eq!(vol.affine(), DMat4::from_scale(DVec3::new(0.5, 0.25, 1.0)));

    // A 2-D image placed in 3-D space: the third column is the unit normal.
    let header = "NRRD0004\ntype: uchar\ndimension: 2\nsizes: 3 2\nspace: RAS\n\
        space directions: (0,2,0) (0,0,3)\nencoding: raw\n\n";
    let path = nrrd_file(&dir, "slice.nrrd", header, &[0; 6]);
    let m = DMat3::from_mat4(read_nrrd(&path).unwrap().affine());
    assert_eq!(m.z_axis, DVec3::X);
}

#[test]
fn nrrd_byte_skip_and_line_skip() {
    let dir = scratch("nrrd_skip");
    let values = [0x0102u16.to_le_bytes(), 0xa0b0u16.to_le_bytes()].concat();
    let head =
        "NRRD0004\ntype: ushort\ndimension: 3\nsizes: 2 1 1\nendian: little\nencoding: raw\n";

    let mut data = b"JUNK!".to_vec();
    data.extend_from_slice(&values);
    let path = nrrd_file(
        &dir,
        "skip5.nrrd",
        &format!("{head}byte skip: 5\n\n"),
        &data,
    );
    assert_eq!(read_nrrd(&path).unwrap().values_f64(), [258.0, 41136.0]);

    // -1: the data is the last bytes of the file, whatever comes before.
    let mut data = b"any preamble of any length".to_vec();
    data.extend_from_slice(&values);
    let path = nrrd_file(
        &dir,
        "skipm1.nrrd",
        &format!("{head}byte skip: -1\n\n"),
        &data,
    );
    assert_eq!(read_nrrd(&path).unwrap().values_f64(), [258.0, 41136.0]);

    // line skip counts lines of the data file; here a detached one, with byte skip too.
    let mut data = b"line one\nline two\nXX".to_vec();
    data.extend_from_slice(&values);
    std::fs::create_dir_all(dir.join("data")).unwrap();
    write_file(&dir.join("data/vol.raw"), &data);
    let header = format!("{head}line skip: 2\nbyte skip: 2\ndata file: data/vol.raw\n");
    let path = nrrd_file(&dir, "lines.nhdr", &header, b"");
    assert_eq!(read_nrrd(&path).unwrap().values_f64(), [258.0, 41136.0]);

    // With gzip, byte skip counts decompressed bytes.
    let mut plain = b"123".to_vec();
    plain.extend_from_slice(&values);
    let header = "NRRD0004\ntype: ushort\ndimension: 3\nsizes: 2 1 1\nendian: little\n\
        encoding: gz\nbyte skip: 3\n\n";
    let path = nrrd_file(&dir, "gz.nrrd", header, &gzip(&plain));
    assert_eq!(read_nrrd(&path).unwrap().values_f64(), [258.0, 41136.0]);
}

#[test]
fn nrrd_ascii_encoding() {
    let dir = scratch("nrrd_ascii");
    let header = "NRRD0001\ntype: signed char\ndimension: 3\nsizes: 3 2 1\nencoding: ascii\n\n";
    let path = nrrd_file(&dir, "i8.nrrd", header, b"-128 0 127\n1,2 3\n");
    let AnyVolume::I16(v) = read_nrrd(&path).unwrap() else {
        panic!("int8 is read as i16")
    };
    assert_eq!(v.data(), [-128, 0, 127, 1, 2, 3]);

    // Multi-byte text data needs no endian field.
    let header = "NRRD0004\ntype: float\ndimension: 2\nsizes: 2 2\nencoding: text\n\n";
    let path = nrrd_file(&dir, "f.nrrd", header, b"0.1 -2.5e3\nnan inf\n");
    let vals = read_nrrd(&path).unwrap().values_f64();
    assert_eq!(vals[..2], [0.1f32 as f64, -2500.0]);
    assert!(vals[2].is_nan() && vals[3] == f64::INFINITY);

    let header = "NRRD0004\ntype: uchar\ndimension: 2\nsizes: 2 2\nencoding: ascii\n\n";
    let path = nrrd_file(&dir, "bad.nrrd", header, b"1 2 256 3");
    assert_format(read_nrrd(&path), "data", "'256'");
}

#[test]
fn nrrd_wide_types_are_rounded_to_f32() {
    let dir = scratch("nrrd_wide");
    let head = |t: &str| {
        format!("NRRD0004\ntype: {t}\ndimension: 2\nsizes: 2 1\nendian: little\nencoding: raw\n\n")
    };
    let doubles: Vec<u8> = [0.1f64, 1e300]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let vol = read_nrrd(&nrrd_file(&dir, "d.nrrd", &head("double"), &doubles)).unwrap();
    assert_eq!(vol.kind(), VoxelKind::F32);
    assert_eq!(vol.values_f64(), [0.1f32 as f64, f64::INFINITY]);

    let ints: Vec<u8> = [16_777_217i32, -5]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let vol = read_nrrd(&nrrd_file(&dir, "i.nrrd", &head("int32_t"), &ints)).unwrap();
    assert_eq!(vol.values_f64(), [16_777_216.0, -5.0]);

    let longs: Vec<u8> = [u64::MAX, 7].iter().flat_map(|x| x.to_be_bytes()).collect();
    let header = head("unsigned long long int").replace("little", "big");
    let vol = read_nrrd(&nrrd_file(&dir, "u.nrrd", &header, &longs)).unwrap();
    assert_eq!(vol.values_f64(), [u64::MAX as f32 as f64, 7.0]);
}

// ---------------------------------------------------------------------------------
// Hand-made .npy files
// ---------------------------------------------------------------------------------

#[test]
fn npy_hand_made_little_endian_u16() {
    let dir = scratch("npy_hand");
    // a[z, y, x] = 1000 * (x + 4 * (y + 3 * z)) with shape (2, 3, 4): C order, x fastest.
    let data: Vec<u8> = (0..24u16).flat_map(|i| (i * 1000).to_le_bytes()).collect();
    let bytes = npy_bytes(1, &npy_dict("<u2", false, "(2, 3, 4)"), &data);
    let path = write_file(&dir.join("u2.npy"), &bytes);
    let AnyVolume::U16(v) = read_npy_volume(&path).unwrap() else {
        panic!("expected u16")
    };
    assert_eq!(v.dims(), [4, 3, 2]);
    assert_eq!(*v.get(3, 2, 1), 23000);
    assert_eq!(*v.get(1, 0, 1), 13000);
    assert_eq!(v.affine(), DMat4::IDENTITY);
    assert_eq!(v.spacing(), [1.0; 3]);
}

#[test]
fn npy_hand_made_big_endian_and_other_dtypes() {
    let dir = scratch("npy_dtypes");
    // Big-endian float32, 2-D: nz = 1.
    let vals = [1.5f32, -2.25, 3.0e-3, 1e30, -0.0, 7.0];
    let data: Vec<u8> = vals.iter().flat_map(|x| x.to_be_bytes()).collect();
    let path = write_file(
        &dir.join("be.npy"),
        &npy_bytes(1, &npy_dict(">f4", false, "(2, 3)"), &data),
    );
    let AnyVolume::F32(v) = read_npy_volume(&path).unwrap() else {
        panic!("expected f32")
    };
    assert_eq!(v.dims(), [3, 2, 1]);
    assert_eq!(
        v.data().iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
        vals.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
    );
    assert_eq!(read_npy_f32(&path).unwrap(), (vec![2, 3], vals.to_vec()));

    // int8 becomes i16 exactly; version 2.0 header.
    let data = [0x80u8, 0xff, 0x00, 0x7f];
    let path = write_file(
        &dir.join("i1.npy"),
        &npy_bytes(2, &npy_dict("|i1", false, "(1, 2, 2)"), &data),
    );
    let AnyVolume::I16(v) = read_npy_volume(&path).unwrap() else {
        panic!("expected i16")
    };
    assert_eq!(v.data(), [-128, -1, 0, 127]);

    // float64 is rounded to f32, big-endian too; version 3.0 header.
    let data: Vec<u8> = [0.1f64, -1e-50]
        .iter()
        .flat_map(|x| x.to_be_bytes())
        .collect();
    let path = write_file(
        &dir.join("f8.npy"),
        &npy_bytes(3, &npy_dict(">f8", false, "(1, 2)"), &data),
    );
    assert_eq!(
        read_npy_volume(&path).unwrap().values_f64(),
        [0.1f32 as f64, -0.0]
    );
    assert_eq!(read_npy_f32(&path).unwrap().1, [0.1f32, -0.0]);

    // Fortran order: the same a[z, y, x] as numpy.load gives, reordered to x fastest.
    let mut data = Vec::new();
    for x in 0..3u8 {
        for y in 0..2u8 {
            data.push(10 * y + x);
        }
    }
    let path = write_file(
        &dir.join("f.npy"),
        &npy_bytes(1, &npy_dict("|u1", true, "(2, 3)"), &data),
    );
    assert_eq!(
        read_npy_volume(&path).unwrap().values_f64(),
        [0.0, 1.0, 2.0, 10.0, 11.0, 12.0]
    );
}

#[test]
fn npy_fixture_from_numpy_when_available() {
    let dir = scratch("npy_numpy");
    let path = dir.join("np.npy");
    let script = format!(
        "import numpy as np; a = np.arange(24, dtype='>i2').reshape(2, 3, 4) * -3; \
         np.save(r'{}', np.asfortranarray(a))",
        path.display()
    );
    let status = std::process::Command::new("python3")
        .args(["-c", &script])
        .stderr(std::process::Stdio::null())
        .status();
    match status {
        Ok(s) if s.success() => {
            let vol = read_npy_volume(&path).unwrap();
            assert_eq!(vol.dims(), [4, 3, 2]);
            let want: Vec<f64> = (0..24).map(|i| (i * -3) as f64).collect();
            assert_eq!(vol.values_f64(), want);
        }
        _ => println!("note: python3 with numpy is not available; numpy fixture test skipped"),
    }
}

// ---------------------------------------------------------------------------------
// Bad NRRD input
// ---------------------------------------------------------------------------------

/// A valid uchar header with the given extra fields and one field removed.
fn uchar_header(without: &str, extra: &str) -> String {
    let fields = [
        "type: uchar",
        "dimension: 3",
        "sizes: 2 2 2",
        "encoding: raw",
    ];
    let mut h = "NRRD0004\n".to_string();
    for f in fields
        .iter()
        .filter(|f| without.is_empty() || !f.starts_with(without))
    {
        h.push_str(f);
        h.push('\n');
    }
    h.push_str(extra);
    h.push('\n');
    h
}

#[test]
fn nrrd_bad_headers() {
    let dir = scratch("nrrd_bad");
    let eight = [7u8; 8];
    let read =
        |name: &str, header: &str, data: &[u8]| read_nrrd(&nrrd_file(&dir, name, header, data));

    assert_format(read("magic.nrrd", "PNG\n\n", &eight), "magic", "NRRD0001");
    assert_format(read("empty.nrrd", "", b""), "magic", "NRRD");
    for field in ["type", "dimension", "sizes", "encoding"] {
        let h = uchar_header(field, "");
        assert_format(read("missing.nrrd", &h, &eight), field, "missing");
    }
    assert_format(
        read("sizes.nrrd", &uchar_header("sizes", "sizes: 2 2\n"), &eight),
        "sizes",
        "dimension is 3",
    );
    assert_format(
        read(
            "sizes2.nrrd",
            &uchar_header("sizes", "sizes: 2 -2 2\n"),
            &eight,
        ),
        "sizes",
        "'-2'",
    );
    assert_format(
        read("type.nrrd", &uchar_header("type", "type: block\n"), &eight),
        "type",
        "block",
    );
    assert_format(
        read(
            "enc.nrrd",
            &uchar_header("encoding", "encoding: bzip2\n"),
            &eight,
        ),
        "encoding",
        "bzip2",
    );
    assert_format(
        read(
            "enc2.nrrd",
            &uchar_header("encoding", "encoding: hex\n"),
            &eight,
        ),
        "encoding",
        "hex",
    );
    assert_format(
        read(
            "dim.nrrd",
            &uchar_header("dimension", "dimension: 0\n"),
            &eight,
        ),
        "dimension",
        "1 to 16",
    );
    assert_format(
        read(
            "dim4.nrrd",
            &uchar_header("", "")
                .replace("dimension: 3", "dimension: 4")
                .replace("2 2 2", "2 2 2 2"),
            &[0; 16],
        ),
        "sizes",
        "2 3-D volumes (axis 3: 2); choose one with --frame",
    );
    assert_format(
        read(
            "dim1.nrrd",
            &uchar_header("", "")
                .replace("dimension: 3", "dimension: 1")
                .replace("2 2 2", "8"),
            &eight,
        ),
        "dimension",
        "2-D or 3-D",
    );
    assert_format(
        read("twice.nrrd", &uchar_header("", "type: uchar\n"), &eight),
        "type",
        "twice",
    );
    assert_format(
        read("line.nrrd", &uchar_header("", "just some words\n"), &eight),
        "header",
        "just some words",
    );

    // Multi-byte raw data needs its byte order.
    let h = uchar_header("type", "type: short\n");
    assert_format(read("endian.nrrd", &h, &[0; 16]), "endian", "required");
    let h = uchar_header("type", "type: short\nendian: middle\n");
    assert_format(read("endian2.nrrd", &h, &[0; 16]), "endian", "middle");

    // Absurd sizes are refused from the header alone, before allocating.
    let h = uchar_header("sizes", "sizes: 100000 100000 100000\n");
    assert_format(read("huge.nrrd", &h, &eight), "sizes", "exceeds the limit");
    let h = uchar_header("sizes", "sizes: 0 2 2\n");
    assert_format(read("zero.nrrd", &h, &eight), "sizes", "empty axis");

    // Geometry.
    for (bad, words) in [
        ("nan 1 1", "finite and positive"),
        ("1 0 1", "finite and positive"),
        ("1 -2 1", "finite and positive"),
        ("1 1 inf", "finite and positive"),
        ("1 x 1", "'x'"),
        ("1 1", "dimension is 3"),
    ] {
        let h = uchar_header("", &format!("spacings: {bad}\n"));
        assert_format(read("spacing.nrrd", &h, &eight), "spacings", words);
    }
    for (bad, words) in [
        ("(1,0,0) (2,0,0) (0,0,1)", "singular"),
        ("(1,0,0) (0,0,0) (0,0,1)", "singular"),
        ("(1,0,0) (0,1,0)", "dimension is 3"),
        ("(1,0,0) (0,1) (0,0,1)", "components"),
        ("(1,0,0) (0,1,0) (0,0,nan)", "finite"),
        ("(1,0,0) (0,1,0) (0,0,1", "not closed"),
    ] {
        let h = uchar_header(
            "",
            &format!("space dimension: 3\nspace directions: {bad}\n"),
        );
        assert_format(read("dirs.nrrd", &h, &eight), "space directions", words);
    }
    // A `none` direction makes its axis number frames (io_frames.rs); one spatial axis
    // is not a volume.
    let h = uchar_header(
        "",
        "space dimension: 3\nspace directions: none (0,1,0) (0,0,1)\n",
    );
    assert_format(read("dirs.nrrd", &h, &eight), "sizes", "--frame");
    let h = uchar_header(
        "",
        "space dimension: 3\nspace directions: none none (0,0,1)\n",
    );
    assert_format(read("dirs.nrrd", &h, &eight), "dimension", "1 spatial axis");
    let h = uchar_header("", "space: RAST\n");
    assert_format(read("time.nrrd", &h, &eight), "space", "time");
    let h = uchar_header("", "space: somewhere\n");
    assert_format(read("space.nrrd", &h, &eight), "space", "somewhere");
    let h = uchar_header("", "space dimension: 3\nspace origin: (1,2)\n");
    assert_format(
        read("origin.nrrd", &h, &eight),
        "space origin",
        "components",
    );

    // Skips.
    let h = uchar_header("", "byte skip: 100\n");
    assert_format(read("skip.nrrd", &h, &eight), "byte skip", "past the end");
    let h = uchar_header("", "byte skip: -2\n");
    assert_format(read("skip2.nrrd", &h, &eight), "byte skip", "-2");
    let h = uchar_header("encoding", "encoding: gzip\nbyte skip: -1\n");
    assert_format(read("skip3.nrrd", &h, &gzip(&eight)), "byte skip", "raw");
    let h = uchar_header("", "line skip: 3\n");
    assert_format(
        read("lines.nrrd", &h, b"one\ntwo"),
        "line skip",
        "ends after 2",
    );

    // Multi-file data.
    let h = uchar_header("", "data file: LIST\n");
    assert_format(
        read("list.nhdr", &h, b"a.raw\nb.raw\n"),
        "data file",
        "LIST",
    );
    let h = uchar_header("", "data file: slice%03d.raw 1 8 1\n");
    assert_format(read("printf.nhdr", &h, b""), "data file", "printf");
}

#[test]
fn nrrd_bad_data() {
    let dir = scratch("nrrd_bad_data");
    let read =
        |name: &str, header: &str, data: &[u8]| read_nrrd(&nrrd_file(&dir, name, header, data));
    let short = "NRRD0004\ntype: short\ndimension: 3\nsizes: 2 3 4\nendian: little\n";

    // Too short: the message says how many bytes were expected and found.
    let h = format!("{short}encoding: raw\n\n");
    assert_format(
        read("short.nrrd", &h, &[0; 20]),
        "data",
        "expected 48 bytes, found 20",
    );
    assert_format(
        read("nodata.nrrd", &h, b""),
        "data",
        "expected 48 bytes, found 0",
    );
    let h = format!("{short}encoding: raw\nbyte skip: -1\n\n");
    assert_format(
        read("short2.nrrd", &h, &[0; 47]),
        "data",
        "expected 48 bytes, found 47",
    );

    // Gzip: too short, corrupt, truncated, not gzip at all.
    let h = format!("{short}encoding: gzip\n\n");
    assert_format(
        read("gzshort.nrrd", &h, &gzip(&[0; 30])),
        "data",
        "expected 48 bytes, found 30",
    );
    let mut corrupt = gzip(&(0..48).collect::<Vec<u8>>());
    let mid = corrupt.len() / 2;
    corrupt[mid] ^= 0xff;
    corrupt[mid + 1] ^= 0x5a;
    assert_eq!(
        format_field(&read("gzbad.nrrd", &h, &corrupt).unwrap_err()),
        "data"
    );
    let whole = gzip(&[1; 48]);
    assert_eq!(
        format_field(&read("gzcut.nrrd", &h, &whole[..whole.len() - 4]).unwrap_err()),
        "data"
    );
    assert_format(read("gznot.nrrd", &h, &[1; 48]), "data", "decoded");

    // A missing detached data file: the error names it.
    let h = format!("{short}encoding: raw\ndata file: nowhere/vol.raw\n");
    let e = read("detached.nhdr", &h, b"").unwrap_err();
    assert_eq!(format_field(&e), "data file");
    assert!(e.to_string().contains("vol.raw"), "{e}");
}

#[test]
fn nrrd_truncations_and_garbage_give_errors_not_panics() {
    let dir = scratch("nrrd_fuzz");
    let vol: AnyVolume = Volume::from_fn([3, 2, 2], [0.5, 1.0, 2.0], |i, j, k| {
        (i + 3 * j + 6 * k) as i16 * 100
    })
    .unwrap()
    .into();
    let mut rng = XorShift(0x2545_f491_4f6c_dd1d);
    let target = dir.join("t.nrrd");
    for gzip in [false, true] {
        let path = dir.join(format!("valid_{gzip}.nrrd"));
        write_nrrd(
            &path,
            &vol,
            NrrdWriteOptions {
                gzip,
                detached: false,
            },
        )
        .unwrap();
        let valid = std::fs::read(&path).unwrap();
        for cut in 0..valid.len() {
            std::fs::write(&target, &valid[..cut]).unwrap();
            assert!(read_nrrd(&target).is_err(), "gzip {gzip}, cut at {cut}");
        }
        for _ in 0..500 {
            let mut b = valid.clone();
            for _ in 0..1 + rng.next() % 3 {
                let i = (rng.next() as usize) % b.len();
                b[i] = rng.next() as u8;
            }
            std::fs::write(&target, &b).unwrap();
            let _ = read_nrrd(&target); // any result but a panic
        }
    }
    for len in [0, 1, 9, 100, 1000] {
        let b: Vec<u8> = (0..len).map(|_| rng.next() as u8).collect();
        std::fs::write(&target, &b).unwrap();
        assert!(read_nrrd(&target).is_err());
    }
}

// ---------------------------------------------------------------------------------
// Bad .npy input
// ---------------------------------------------------------------------------------

#[test]
fn npy_bad_input() {
    let dir = scratch("npy_bad");
    let read = |name: &str, bytes: &[u8]| read_npy_volume(&write_file(&dir.join(name), bytes));
    let f4 = |shape: &str, data: &[u8]| npy_bytes(1, &npy_dict("<f4", false, shape), data);

    assert_format(
        read("magic.npy", b"NUMPY\x01\x00\x10\x00{}"),
        "magic",
        "x93NUMPY",
    );
    assert_format(read("empty.npy", b""), "magic", "not a .npy");
    assert_format(
        read("version.npy", b"\x93NUMPY\x04\x00\x00\x00"),
        "version",
        "4.0",
    );
    assert_format(
        read("len.npy", b"\x93NUMPY\x01\x00\x10"),
        "header length",
        "ends",
    );
    assert_format(
        read("past.npy", b"\x93NUMPY\x01\x00\xff\x00{'descr'"),
        "header length",
        "past the end",
    );

    // Truncated data: expected and found byte counts.
    assert_format(
        read("short.npy", &f4("(2, 3)", &[0; 20])),
        "data",
        "expected 24 bytes, found 20",
    );
    // Shapes.
    for (shape, words) in [
        ("(-2, 3)", "negative"),
        ("(2.0, 3)", "not an integer"),
        ("('a', 3)", "not an integer"),
        ("(3000000000, 3000000000, 3000000000)", "limit"),
        ("(65536, 65536, 1024)", "limit"),
        ("(1, 2, 2, 2)", "2-D (ny, nx) or 3-D"),
        ("(4,)", "2-D (ny, nx) or 3-D"),
        ("(0, 3)", "empty axis"),
        ("[2, 3]", "tuple"),
    ] {
        assert_format(read("shape.npy", &f4(shape, &[0; 64])), "shape", words);
    }
    // Malformed dicts.
    for dict in [
        "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3)",
        "{'descr': '<f4' 'fortran_order': False, 'shape': (2, 3)}",
        "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3)} extra",
        "['descr', '<f4']",
        "{'descr: '<f4', 'fortran_order': False, 'shape': (2, 3)}",
    ] {
        let e = read("dict.npy", &npy_bytes(1, dict, &[0; 24])).unwrap_err();
        assert_eq!(format_field(&e), "header", "{dict}: {e}");
    }
    assert_format(
        read(
            "nokey.npy",
            &npy_bytes(1, "{'descr': '<f4', 'shape': (2, 3)}", &[0; 24]),
        ),
        "fortran_order",
        "no 'fortran_order'",
    );
    assert_format(
        read(
            "order.npy",
            &npy_bytes(
                1,
                "{'descr': '<f4', 'fortran_order': 0, 'shape': (2, 3)}",
                &[0; 24],
            ),
        ),
        "fortran_order",
        "True or False",
    );
    // Unsupported dtypes: the message lists the supported ones.
    for descr in ["<i4", "<u8", "|b1", "<c8", "|f4", "<f2", "S3"] {
        let bytes = npy_bytes(1, &npy_dict(descr, false, "(2, 3)"), &[0; 96]);
        let e = read("dtype.npy", &bytes).unwrap_err();
        assert_eq!(format_field(&e), "descr", "{descr}: {e}");
    }
    let bytes = npy_bytes(1, &npy_dict("<i4", false, "(2, 3)"), &[0; 96]);
    assert_format(read("dtype.npy", &bytes), "descr", "|u1, |i1, <u2");
    let dict = "{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': (2,)}";
    assert_format(
        read("rec.npy", &npy_bytes(1, dict, &[0; 8])),
        "descr",
        "structured",
    );
    // read_npy_f32 takes floats only.
    let path = write_file(
        &dir.join("u1.npy"),
        &npy_bytes(1, &npy_dict("|u1", false, "(2,)"), &[1, 2]),
    );
    assert_format(read_npy_f32(&path), "descr", "<f4, >f4, <f8, >f8");
}

// ---------------------------------------------------------------------------------
// Atomic writes
// ---------------------------------------------------------------------------------

#[test]
fn atomic_writer_leaves_nothing_behind_on_failure() {
    let dir = scratch("atomic");
    let path = dir.join("out.nrrd");

    // No file before: none after a failed write.
    let r = write_atomic(&path, |w| {
        w.write_all(b"NRRD0004\npartial").unwrap();
        Err(Error::invalid("test", "the writer fails halfway"))
    });
    assert!(matches!(r, Err(Error::Invalid { .. })));
    assert!(listing(&dir).is_empty(), "{:?}", listing(&dir));

    // An existing file is unchanged by a failed write.
    let vol = &sample_volumes(oblique_affine())[0];
    write_volume(&path, vol).unwrap();
    let before = std::fs::read(&path).unwrap();
    let r = write_atomic(&path, |w| {
        w.write_all(&[0; 1000]).unwrap();
        Err(Error::invalid("test", "the writer fails halfway"))
    });
    assert!(r.is_err());
    assert_eq!(std::fs::read(&path).unwrap(), before);
    assert_eq!(listing(&dir), ["out.nrrd"]);

    // A successful write replaces the file in one step.
    write_atomic(&path, |w| {
        w.write_all(b"new").map_err(|e| Error::io(&path, e))
    })
    .unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), b"new");
    assert_eq!(listing(&dir), ["out.nrrd"]);
}

#[test]
fn writing_into_a_missing_directory_is_an_io_error_naming_the_path() {
    let dir = scratch("atomic_missing");
    let vol = &sample_volumes(oblique_affine())[3];
    for name in ["out.nrrd", "out.nhdr", "out.npy"] {
        let path = dir.join("no/such/dir").join(name);
        let e = write_volume(&path, vol).unwrap_err();
        assert!(matches!(e, Error::Io { .. }), "{e}");
        assert!(e.to_string().contains("no/such/dir"), "{e}");
    }
    let e = write_npy_f32(&dir.join("nope/x.npy"), &[1], &[1.0]).unwrap_err();
    assert!(
        matches!(e, Error::Io { .. }) && e.to_string().contains("nope"),
        "{e}"
    );
    assert!(listing(&dir).is_empty());
}
