//! MetaImage files built byte by byte: every layout the reader accepts gives the values
//! written, and every lie a header can tell gets an error naming the file and the field.
//! (ITK's own files, both ways, are checked in python/tests/test_metaimage.py.)

mod common;

use common::{assert_format, scratch};
use glam::{DMat4, DVec4};
use std::path::{Path, PathBuf};
use voxlab::io::metaimage::{read_metaimage, write_metaimage, MetaImageWriteOptions};
use voxlab::io::{read_volume, read_volume_bytes, Format};
use voxlab::volume::Volume;
use voxlab::AnyVolume;

fn header(extra: &str, data: &str) -> String {
    format!(
        "ObjectType = Image\nNDims = 3\nDimSize = 3 2 2\nElementSpacing = 0.5 1 2\n\
         Offset = 10 -20 30\n{extra}ElementDataFile = {data}\n"
    )
}

fn file(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn values(v: &AnyVolume) -> Vec<f64> {
    v.values_f64()
}

const TWELVE: [i16; 12] = [0, 1, -2, 300, -400, 5, 6000, -7, 8, 9, 10, -32768];

#[test]
fn local_data_in_both_byte_orders_and_as_text() {
    let dir = scratch("mha-local");
    for msb in [false, true] {
        let mut b = header(
            &format!(
                "ElementType = MET_SHORT\nElementByteOrderMSB = {}\n",
                if msb { "True" } else { "False" }
            ),
            "LOCAL",
        )
        .into_bytes();
        for v in TWELVE {
            b.extend(if msb {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            });
        }
        let v = read_metaimage(&file(&dir, "a.mha", &b)).unwrap();
        assert_eq!(v.dims(), [3, 2, 2]);
        assert_eq!(values(&v), TWELVE.map(f64::from).to_vec());
        assert_eq!(v.spacing(), [0.5, 1.0, 2.0]);
        assert_eq!(v.affine().w_axis, DVec4::new(10.0, -20.0, 30.0, 1.0));
        // The same bytes from memory (the fuzz targets' entry point).
        let m = read_volume_bytes(&b, Format::MetaImage, Path::new("a.mha")).unwrap();
        assert_eq!(values(&m), values(&v));
    }
    let text = TWELVE.map(|v| v.to_string()).join(" ");
    let b = header("ElementType = MET_SHORT\nBinaryData = False\n", "LOCAL") + &text + "\n";
    let v = read_metaimage(&file(&dir, "t.mha", b.as_bytes())).unwrap();
    assert_eq!(values(&v), TWELVE.map(f64::from).to_vec());
}

#[test]
fn the_affine_is_itks_directions_times_spacing_plus_offset() {
    let dir = scratch("mha-affine");
    let mut b = header(
        "ElementType = MET_UCHAR\nTransformMatrix = 0 1 0 -1 0 0 0 0 1\n",
        "LOCAL",
    )
    .into_bytes();
    b.extend(0u8..12);
    let v = read_volume(&file(&dir, "r.mha", &b)).unwrap();
    // Index axis x runs along world +y (0.5 mm), y along −x (1 mm), z along +z (2 mm).
    let want = DMat4::from_cols(
        DVec4::new(0.0, 0.5, 0.0, 0.0),
        DVec4::new(-1.0, 0.0, 0.0, 0.0),
        DVec4::new(0.0, 0.0, 2.0, 0.0),
        DVec4::new(10.0, -20.0, 30.0, 1.0),
    );
    assert_eq!(v.affine(), want);
}

#[test]
fn detached_files_header_size_and_lists() {
    let dir = scratch("mha-detached");
    let le: Vec<u8> = TWELVE.iter().flat_map(|v| v.to_le_bytes()).collect();
    file(&dir, "d.raw", &le);
    let h = header("ElementType = MET_SHORT\n", "d.raw");
    let v = read_volume(&file(&dir, "d.mhd", h.as_bytes())).unwrap();
    assert_eq!(values(&v), TWELVE.map(f64::from).to_vec());
    // HeaderSize skips a prefix; −1 takes the data from the end of the file.
    let mut pre = b"JUNKJUNK".to_vec();
    pre.extend(&le);
    file(&dir, "p.raw", &pre);
    for hs in ["8", "-1"] {
        let h = header(
            &format!("ElementType = MET_SHORT\nHeaderSize = {hs}\n"),
            "p.raw",
        );
        let v = read_volume(&file(&dir, "p.mhd", h.as_bytes())).unwrap();
        assert_eq!(
            values(&v),
            TWELVE.map(f64::from).to_vec(),
            "HeaderSize {hs}"
        );
    }
    // One file per slice.
    file(&dir, "s0.raw", &le[..12]);
    file(&dir, "s1.raw", &le[12..]);
    let h = header("ElementType = MET_SHORT\n", "LIST") + "s0.raw\ns1.raw\n";
    let v = read_volume(&file(&dir, "l.mhd", h.as_bytes())).unwrap();
    assert_eq!(values(&v), TWELVE.map(f64::from).to_vec());
    let h = header("ElementType = MET_SHORT\n", "LIST") + "s0.raw\n";
    assert_format(
        read_volume(&file(&dir, "l1.mhd", h.as_bytes())),
        "ElementDataFile",
        "one per 2-D image",
    );
}

#[test]
fn writes_read_back_exactly() {
    let dir = scratch("mha-write");
    let affine = DMat4::from_cols(
        DVec4::new(0.3, 0.1, 0.0, 0.0),
        DVec4::new(-0.2, 0.6, 0.0, 0.0),
        DVec4::new(0.0, 0.0, 1.7, 0.0),
        DVec4::new(-1e-3, 123.456, 7.0, 1.0),
    );
    let vols: Vec<AnyVolume> = vec![
        Volume::<u8>::from_fn([4, 3, 2], [1.0; 3], |i, j, k| (i + 4 * j + 12 * k) as u8)
            .unwrap()
            .into(),
        Volume::<u16>::from_fn([4, 3, 2], [1.0; 3], |i, j, k| (i * 1000 + j + k) as u16)
            .unwrap()
            .into(),
        Volume::<i16>::from_fn([4, 3, 2], [1.0; 3], |i, j, k| {
            i as i16 - 300 * j as i16 + k as i16
        })
        .unwrap()
        .into(),
        Volume::<f32>::from_fn([4, 3, 2], [1.0; 3], |i, j, k| {
            [f32::NAN, f32::INFINITY, -0.0, 1e-30][i] + (j * 2 + k) as f32
        })
        .unwrap()
        .into(),
    ];
    for mut v in vols {
        voxlab::with_volume!(&mut v, v => v.set_affine(affine)).unwrap();
        for (name, compress) in [
            ("w.mha", false),
            ("w.mhd", false),
            ("z.mha", true),
            ("z.mhd", true),
        ] {
            let p = dir.join(name);
            write_metaimage(&p, &v, MetaImageWriteOptions { compress }).unwrap();
            let back = read_volume(&p).unwrap();
            assert_eq!(back.dims(), v.dims());
            assert_eq!(common::bits(&back), common::bits(&v), "{name}");
            let (a, b) = (back.affine(), v.affine());
            let err = (a - b)
                .to_cols_array()
                .iter()
                .fold(0.0f64, |m, x| m.max(x.abs()));
            assert!(err <= 1e-15 * 200.0, "{name}: affine off by {err}");
        }
    }
    assert!(dir.join("z.zraw").exists() && dir.join("w.raw").exists());
}

#[test]
fn lies_name_the_file_and_the_field() {
    let dir = scratch("mha-lies");
    let le: Vec<u8> = TWELVE.iter().flat_map(|v| v.to_le_bytes()).collect();
    let case = |name: &str, text: String, data: &[u8], field: &str, words: &str| {
        let mut b = text.into_bytes();
        b.extend(data);
        let p = file(&dir, name, &b);
        let r = read_volume(&p);
        assert!(r.is_err(), "{name} was read");
        assert_format(r, field, words);
    };
    let t = "ElementType = MET_SHORT\n";
    case(
        "short.mha",
        header(t, "LOCAL"),
        &le[..20],
        "data",
        "too short",
    );
    let mut long = le.clone();
    long.push(0);
    case("long.mha", header(t, "LOCAL"), &long, "data", "longer");
    case(
        "type.mha",
        header("ElementType = MET_QUATERNION\n", "LOCAL"),
        &le,
        "ElementType",
        "MET_QUATERNION",
    );
    case(
        "dims.mha",
        "ObjectType = Image\nNDims = 3\nDimSize = 3 2\nElementType = MET_SHORT\nElementDataFile = LOCAL\n".into(),
        &le,
        "DimSize",
        "NDims is 3",
    );
    case(
        "huge.mha",
        "ObjectType = Image\nNDims = 3\nDimSize = 100000 100000 100000\nElementType = MET_SHORT\nElementDataFile = LOCAL\n".into(),
        &le,
        "DimSize",
        "",
    );
    case(
        "spacing.mha",
        header(t, "LOCAL").replace("ElementSpacing = 0.5 1 2", "ElementSpacing = 1 0 1"),
        &le,
        "ElementSpacing",
        "",
    );
    case(
        "twice.mha",
        header("ElementType = MET_SHORT\nElementSpacing = 1 1 1\n", "LOCAL"),
        &le,
        "ElementSpacing",
        "twice",
    );
    case(
        "matrix.mha",
        header(
            "ElementType = MET_SHORT\nTransformMatrix = 1 0 0 1 0 0 0 0 1\n",
            "LOCAL",
        ),
        &le,
        "TransformMatrix",
        "singular",
    );
    case(
        "object.mha",
        header(t, "LOCAL").replace("Image", "Mesh"),
        &le,
        "ObjectType",
        "not an image",
    );
    case(
        "nofile.mhd",
        header(t, "missing.raw"),
        b"",
        "data file",
        "missing.raw",
    );
    case(
        "zlib.mha",
        header("ElementType = MET_SHORT\nCompressedData = True\n", "LOCAL"),
        b"not zlib at all",
        "data",
        "decoded",
    );
    case(
        "skip.mhd",
        header("ElementType = MET_SHORT\nHeaderSize = 1000\n", "short.mha"),
        b"",
        "HeaderSize",
        "1000",
    );
    case(
        "end.mha",
        "ObjectType = Image\nNDims = 3\n".into(),
        b"",
        "ElementDataFile",
        "ends",
    );
    // A vector image without --frame: its channels are frames (io_frames.rs).
    let p = file(
        &dir,
        "rgb.mha",
        header(
            "ElementType = MET_UCHAR\nElementNumberOfChannels = 3\n",
            "LOCAL",
        )
        .as_bytes(),
    );
    let e = read_volume(&p).unwrap_err().to_string();
    assert!(e.contains("ElementNumberOfChannels"), "{e}");
}

#[test]
fn confined_data_files_stay_in_the_headers_folder() {
    let dir = scratch("mha-confine");
    let sub = dir.join("h");
    std::fs::create_dir_all(&sub).unwrap();
    let le: Vec<u8> = TWELVE.iter().flat_map(|v| v.to_le_bytes()).collect();
    file(&dir, "outside.raw", &le);
    let p = file(
        &sub,
        "c.mhd",
        header("ElementType = MET_SHORT\n", "../outside.raw").as_bytes(),
    );
    assert!(read_volume(&p).is_ok(), "the format allows ../ by default");
    let r = voxlab::io::read_volume_with(
        &p,
        &voxlab::io::ReadOptions {
            confine_data_files: true,
            ..Default::default()
        },
    );
    assert_format(r, "data file", "outside");
}
