//! PVM and VolPack `.den` readers: files written per the formats' reference C code,
//! the bundled VolPack brain, bad input, truncations and garbage.

mod common;

use common::{assert_format, scratch, XorShift};
use std::path::Path;
use voxlab::io::den::{read_den, read_den_bytes};
use voxlab::io::pvm::{read_pvm, read_pvm_bytes};
use voxlab::io::{detect_format, read_volume, Format};
use voxlab::{AnyVolume, Error, VoxelKind};

// ---------------------------------------------------------------------------------
// VolPack .den
// ---------------------------------------------------------------------------------

/// A `.den` file as VolPack's `denfile.c` `write_den` writes it: version 1, the
/// original, extracted and map boxes (min 0, max n−1, len n), 0 warps, the voxel
/// count, the voxels; all 16/32-bit fields in the writer's byte order.
fn den_file(dims: [i16; 3], data: &[u8], big: bool) -> Vec<u8> {
    let mut out = Vec::new();
    let mut put16 = |v: i16| {
        out.extend(if big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        })
    };
    put16(1);
    for _ in 0..3 {
        dims.iter().for_each(|_| put16(0));
        dims.iter().for_each(|&d| put16(d - 1));
        dims.iter().for_each(|&d| put16(d));
    }
    put16(0);
    let n: i32 = dims.iter().map(|&d| i32::from(d)).product();
    out.extend(if big {
        n.to_be_bytes()
    } else {
        n.to_le_bytes()
    });
    out.extend_from_slice(data);
    out
}

/// The classic UNC MR brain from VolPack's examples, downsampled. Independent check
/// (Python, reading the file per denfile.c): `h = struct.unpack('<29hi', b[:62])`
/// gives version 1, map_len (128, 128, 84), 3 warps, map_length 1376256; then
/// `d = b[62:]`: len 1376256, `sum(d)` = 19284185, `max(d)` = 202, `min(d)` = 0,
/// `d[0]` = 2, `d[64 + 128·64 + 128·128·42]` = 65.
#[test]
fn volpack_brain() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/mr-brain-volpack/brainsmall.den");
    assert_eq!(detect_format(&p).unwrap(), Format::Den);
    let v = read_volume(&p).unwrap();
    assert_eq!(v.kind(), VoxelKind::U8);
    assert_eq!(v.dims(), [128, 128, 84]);
    assert_eq!(v.spacing(), [1.0; 3]);
    let AnyVolume::U8(v) = v else { unreachable!() };
    let sum: u64 = v.data().iter().map(|&x| u64::from(x)).sum();
    assert_eq!(sum, 19_284_185);
    assert_eq!(v.data().iter().max(), Some(&202));
    assert_eq!(v.data().iter().min(), Some(&0));
    assert_eq!(*v.get(0, 0, 0), 2);
    assert_eq!(*v.get(64, 64, 42), 65);
}

#[test]
fn den_crafted_files_both_orders() {
    let dir = scratch("den");
    let data: Vec<u8> = (0..60).map(|i| (i * 7) as u8).collect();
    for big in [false, true] {
        let p = dir.join(format!("v{big}.den"));
        std::fs::write(&p, den_file([5, 4, 3], &data, big)).unwrap();
        let v = read_den(&p).unwrap();
        assert_eq!(v.dims(), [5, 4, 3]);
        let AnyVolume::U8(v) = v else { unreachable!() };
        assert_eq!(v.data(), &data[..]);
        assert_eq!(*v.get(1, 2, 0), data[1 + 5 * 2]);
    }
    // Trailing bytes are ignored, as denfile.c ignores them.
    let mut f = den_file([5, 4, 3], &data, false);
    f.extend([1, 2, 3]);
    assert_eq!(
        read_den_bytes(&f, Path::new("t.den")).unwrap().dims(),
        [5, 4, 3]
    );
}

#[test]
fn den_bad_input() {
    let p = Path::new("t.den");
    let good = den_file([5, 4, 3], &[0; 60], true);
    let patched = |off: usize, bytes: &[u8]| {
        let mut b = good.clone();
        b[off..off + bytes.len()].copy_from_slice(bytes);
        read_den_bytes(&b, p)
    };
    assert_format(patched(0, &[0, 2]), "map_version", "not a VolPack");
    assert_format(patched(52, &[0, 0]), "map_len", "at least 1");
    assert_format(patched(54, &[0xff, 0xfd]), "map_len", "at least 1");
    assert_format(patched(58, &[0, 0, 0, 61]), "map_length", "product");
    assert_format(patched(58, &[0xff, 0, 0, 0]), "map_length", "product");
    assert_format(read_den_bytes(&good[..61], p), "header", "truncated");
    assert_format(
        read_den_bytes(&good[..100], p),
        "data",
        "expected 60 bytes, found 38",
    );
    // The largest dims a .den header can hold pass the voxel limit; the data is absent.
    let mut huge = den_file([32767, 32767, 1], &[], true);
    huge[58..62].copy_from_slice(&(32767i32 * 32767).to_be_bytes());
    assert_format(read_den_bytes(&huge, p), "data", "too short");
    for n in 0..good.len() {
        assert!(read_den_bytes(&good[..n], p).is_err());
    }
    let mut rng = XorShift(0x1234_5678_9abc_def1);
    for len in [0usize, 1, 2, 61, 62, 63, 500] {
        let mut g: Vec<u8> = (0..len).map(|_| rng.next() as u8).collect();
        let _ = read_den_bytes(&g, p);
        if len >= 2 {
            g[..2].copy_from_slice(&[1, 0]);
            let _ = read_den_bytes(&g, p);
        }
    }
}

// ---------------------------------------------------------------------------------
// PVM
// ---------------------------------------------------------------------------------

#[test]
fn pvm_files_of_every_version() {
    let dir = scratch("pvm");
    let data: Vec<u8> = (0..24).map(|i| (i * 11) as u8).collect();
    let cases: [(&[u8], [f64; 3]); 3] = [
        (b"PVM\n4 3 2\n1\n", [1.0; 3]),
        (b"PVM2\n4 3 2\n0.5 0.25 2\n1\n", [0.5, 0.25, 2.0]),
        (b"PVM3\n4 3 2\n1.5 1.5 3\n1\n", [1.5, 1.5, 3.0]),
    ];
    for (i, (header, spacing)) in cases.iter().enumerate() {
        let mut f = header.to_vec();
        f.extend(&data);
        if i == 2 {
            f.extend(b"a description\0courtesy of\0\0\0");
        }
        let p = dir.join(format!("v{i}.pvm"));
        std::fs::write(&p, &f).unwrap();
        assert_eq!(detect_format(&p).unwrap(), Format::Pvm);
        let v = read_volume(&p).unwrap();
        assert_eq!((v.kind(), v.dims()), (VoxelKind::U8, [4, 3, 2]));
        assert_eq!(v.spacing(), *spacing);
        assert_eq!(
            v.values_f64(),
            data.iter().map(|&x| f64::from(x)).collect::<Vec<_>>()
        );
    }
    // 16-bit: most significant byte first.
    let mut f = b"PVM2\n2 1 1\n1 1 1\n2\n".to_vec();
    f.extend([0x12, 0x34, 0xff, 0x00]);
    let p = dir.join("w.pvm");
    std::fs::write(&p, &f).unwrap();
    let v = read_pvm(&p).unwrap();
    assert_eq!(v.kind(), VoxelKind::U16);
    assert_eq!(v.values_f64(), [f64::from(0x1234u16), f64::from(0xff00u16)]);
}

#[test]
fn pvm_bad_input() {
    let p = Path::new("t.pvm");
    let cases: [(&[u8], &str, &str); 11] = [
        (b"PVM5\n1 1 1\n1\n\0", "magic", "PVM5"),
        (b"P", "magic", "not a PVM"),
        (b"PVM\n1 1 x\n1\n\0", "dimensions", "three numbers"),
        (b"PVM\n1 1 1 1\n1\n\0", "dimensions", "three numbers"),
        (b"PVM2\n1 1 1\n1 1\n1\n\0", "scale", "three"),
        (b"PVM2\n1 1 1\n1 -1 1\n1\n\0", "scale", "positive"),
        (b"PVM\n1 1 1\n4\n\0\0\0\0", "components", "scalar"),
        (b"PVM\n1 1 1\n0\n", "components", "scalar"),
        (b"PVM\n2 2 2\n2\n\0\0", "data", "expected 16 bytes, found 2"),
        (b"PVM\n4000 4000 4000\n1\n", "dimensions", "limit"),
        (b"PVM\n1000 1000 1000\n1\n", "data", "too short"),
    ];
    for (bytes, field, words) in cases {
        assert_format(read_pvm_bytes(bytes, p), field, words);
    }
    let long = format!("PVM\n{}\n", "1 ".repeat(300));
    assert_format(
        read_pvm_bytes(long.as_bytes(), p),
        "dimensions",
        "longer than",
    );
    // Missing file.
    let e = read_pvm(Path::new("/nonexistent/x.pvm")).unwrap_err();
    assert!(matches!(e, Error::Io { .. }), "{e}");
}

#[test]
fn pvm_truncations_and_garbage_give_errors_not_panics() {
    let p = Path::new("t.pvm");
    let mut f = b"PVM3\n3 2 2\n1 2 3\n2\n".to_vec();
    f.extend(0..24u8);
    assert!(read_pvm_bytes(&f, p).is_ok());
    for n in 0..f.len() {
        assert!(read_pvm_bytes(&f[..n], p).is_err(), "cut at {n}");
    }
    let mut rng = XorShift(0x0fed_cba9_8765_4321);
    for len in [0usize, 1, 5, 8, 9, 20, 100, 1000] {
        for prefix in [&b""[..], b"PVM\n", b"PVM3\n", b"DDS v3d\n", b"DDS v3e\n"] {
            let mut g = prefix.to_vec();
            g.extend((0..len).map(|_| rng.next() as u8));
            let _ = read_pvm_bytes(&g, p);
        }
    }
    for _ in 0..1000 {
        let mut m = f.clone();
        let i = (rng.next() % m.len() as u64) as usize;
        m[i] = rng.next() as u8;
        let _ = read_pvm_bytes(&m, p);
    }
}

/// The plain PVM files that tests/data/pvm/*.pvm hold DDS-compressed (see the README
/// there): `ramp16` is PVM3 16-bit with trailing strings, `ramp8` PVM2 8-bit.
fn ramp16_plain() -> Vec<u8> {
    let mut out = b"PVM3\n12 10 6\n0.5 0.75 1.25\n2\n".to_vec();
    for k in 0..6u32 {
        for j in 0..10u32 {
            for i in 0..12u32 {
                let v = 1000 + 37 * i + 11 * j * j + 300 * k + ((7 * i + 13 * j + 29 * k) % 5) * 50;
                out.extend((v as u16).to_be_bytes());
            }
        }
    }
    out.extend(b"ramp\0\0\0\0");
    out
}

fn ramp8_plain() -> Vec<u8> {
    let mut out = b"PVM2\n16 8 5\n1 1 2\n1\n".to_vec();
    for k in 0..5u32 {
        for j in 0..8u32 {
            for i in 0..16u32 {
                out.push(((i * i + 3 * j + 17 * k + ((i * j * k) % 7) * 9) % 256) as u8);
            }
        }
    }
    out
}

/// Files compressed by the reference DDS encoder decode to the plain files.
#[test]
fn dds_files_from_the_reference_encoder() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/pvm");
    let p16 = dir.join("ramp16_v3d.pvm");
    assert!(std::fs::read(&p16).unwrap().starts_with(b"DDS v3d\n"));
    let v = read_volume(&p16).unwrap();
    assert_eq!(v, read_pvm_bytes(&ramp16_plain(), &p16).unwrap());
    assert_eq!((v.kind(), v.dims()), (VoxelKind::U16, [12, 10, 6]));
    assert_eq!(v.spacing(), [0.5, 0.75, 1.25]);
    assert_eq!(
        v.values_f64()[1 + 12 * 2 + 120 * 3],
        1000.0 + 37.0 + 44.0 + 900.0 + 50.0 * ((7 + 26 + 87) % 5) as f64
    );

    let p8 = dir.join("ramp8_v3e.pvm");
    assert!(std::fs::read(&p8).unwrap().starts_with(b"DDS v3e\n"));
    let v = read_pvm(&p8).unwrap();
    assert_eq!(v, read_pvm_bytes(&ramp8_plain(), &p8).unwrap());
    assert_eq!(
        (v.kind(), v.dims(), v.spacing()),
        (VoxelKind::U8, [16, 8, 5], [1.0, 1.0, 2.0])
    );
}
