//! DICOM files built byte by byte, without a DICOM library: every transfer syntax the
//! reader takes × BitsAllocated 8, 16, 32 × PixelRepresentation 0, 1 × pixel data as
//! OB or OW (RLE Lossless: encoded here, with and without an offset table), read back
//! against the values written; RT dose grids; refusals; the DICM marker. (Explicit VR big endian with 32-bit
//! samples in OW, an RT dose grid's layout, once came back with its 16-bit halves
//! swapped, silently.)

mod common;

use common::scratch;
use std::io::Write;
use std::path::Path;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Syntax {
    ImplicitLittle,
    ExplicitLittle,
    ExplicitBig,
    DeflatedLittle,
    /// RLE Lossless: explicit VR little endian, the pixel data encapsulated.
    Rle,
}

impl Syntax {
    fn uid(self) -> &'static str {
        match self {
            Syntax::ImplicitLittle => "1.2.840.10008.1.2",
            Syntax::ExplicitLittle => "1.2.840.10008.1.2.1",
            Syntax::ExplicitBig => "1.2.840.10008.1.2.2",
            Syntax::DeflatedLittle => "1.2.840.10008.1.2.1.99",
            Syntax::Rle => "1.2.840.10008.1.2.5",
        }
    }
    fn big(self) -> bool {
        self == Syntax::ExplicitBig
    }
    fn explicit(self) -> bool {
        self != Syntax::ImplicitLittle
    }
}

/// One element in `syntax` (the meta group is always explicit VR little endian).
fn element(out: &mut Vec<u8>, syntax: Syntax, group: u16, elem: u16, vr: &[u8; 2], value: &[u8]) {
    let meta = group == 0x0002;
    let big = syntax.big() && !meta;
    let explicit = syntax.explicit() || meta;
    let u16b = |v: u16| {
        if big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    let u32b = |v: u32| {
        if big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    let mut v = value.to_vec();
    if v.len() % 2 == 1 {
        v.push(if vr == b"UI" || vr == b"OB" { 0 } else { b' ' });
    }
    out.extend(u16b(group));
    out.extend(u16b(elem));
    if explicit {
        out.extend(vr);
        if matches!(vr, b"OB" | b"OW" | b"SQ" | b"UN" | b"UT") {
            out.extend([0, 0]);
            out.extend(u32b(v.len() as u32));
        } else {
            out.extend(u16b(v.len() as u16));
        }
    } else {
        out.extend(u32b(v.len() as u32));
    }
    out.extend(v);
}

/// A 2 × 3 image of `values` (BitsStored = BitsAllocated) as a DICOM file.
fn file(syntax: Syntax, bits: u16, signed: bool, ow: bool, values: &[i64]) -> Vec<u8> {
    image_file(syntax, bits, signed, ow, Some(values))
}

/// [`file`], or the same image without its PixelData element (`values` = `None`).
fn image_file(
    syntax: Syntax,
    bits: u16,
    signed: bool,
    ow: bool,
    values: Option<&[i64]>,
) -> Vec<u8> {
    let us = |v: u16| {
        if syntax.big() {
            v.to_be_bytes().to_vec()
        } else {
            v.to_le_bytes().to_vec()
        }
    };
    let mut ds = Vec::new();
    element(
        &mut ds,
        syntax,
        0x0008,
        0x0016,
        b"UI",
        b"1.2.840.10008.5.1.4.1.1.7",
    );
    element(&mut ds, syntax, 0x0008, 0x0018, b"UI", b"1.2.3.4.5");
    element(&mut ds, syntax, 0x0020, 0x000E, b"UI", b"1.2.3.4");
    element(&mut ds, syntax, 0x0028, 0x0002, b"US", &us(1));
    element(&mut ds, syntax, 0x0028, 0x0004, b"CS", b"MONOCHROME2");
    element(&mut ds, syntax, 0x0028, 0x0010, b"US", &us(2));
    element(&mut ds, syntax, 0x0028, 0x0011, b"US", &us(3));
    element(&mut ds, syntax, 0x0028, 0x0100, b"US", &us(bits));
    element(&mut ds, syntax, 0x0028, 0x0101, b"US", &us(bits));
    element(&mut ds, syntax, 0x0028, 0x0102, b"US", &us(bits - 1));
    element(
        &mut ds,
        syntax,
        0x0028,
        0x0103,
        b"US",
        &us(u16::from(signed)),
    );
    // The samples, each in the file's byte order: for OW the file holds 16-bit words,
    // most significant byte first in big endian, so a 32-bit sample is its high word
    // then its low word, each turned around; for OB the bytes of each sample.
    let mut px = Vec::new();
    for &v in values.unwrap_or(&[]) {
        let w = v as u32; // two's complement for negative values
        match bits {
            8 => px.push(w as u8),
            16 if syntax.big() => px.extend((w as u16).to_be_bytes()),
            16 => px.extend((w as u16).to_le_bytes()),
            _ if syntax.big() => px.extend(w.to_be_bytes()),
            _ => px.extend(w.to_le_bytes()),
        }
    }
    if bits == 8 && ow && syntax.big() {
        // 8-bit samples in OW words: each word's bytes turned around.
        if px.len() % 2 == 1 {
            px.push(0);
        }
        px.chunks_exact_mut(2).for_each(|w| w.swap(0, 1));
    }
    if values.is_some() && syntax == Syntax::Rle {
        // Signed images: with a basic offset table, the frame cut into two fragments;
        // unsigned ones: no table, one fragment.
        let frame = rle_frame(&px, (bits / 8) as usize);
        let (bot, fragments): (Vec<u8>, Vec<&[u8]>) = if signed {
            let half = (frame.len() / 2) & !1;
            (vec![0; 4], vec![&frame[..half], &frame[half..]])
        } else {
            (Vec::new(), vec![&frame[..]])
        };
        encapsulated(&mut ds, &bot, &fragments);
    } else if values.is_some() {
        let vr = if ow { b"OW" } else { b"OB" };
        element(&mut ds, syntax, 0x7FE0, 0x0010, vr, &px);
    }
    wrap(syntax, ds)
}

/// A data set (its elements in `syntax`, ascending tags) as a DICOM file: preamble,
/// `DICM`, the meta group, the data set (deflated for the deflated syntax).
fn wrap(syntax: Syntax, mut ds: Vec<u8>) -> Vec<u8> {
    if syntax == Syntax::DeflatedLittle {
        let mut z = flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&ds).unwrap();
        ds = z.finish().unwrap();
    }
    let mut meta = Vec::new();
    element(&mut meta, syntax, 0x0002, 0x0001, b"OB", &[0, 1]);
    element(
        &mut meta,
        syntax,
        0x0002,
        0x0002,
        b"UI",
        b"1.2.840.10008.5.1.4.1.1.7",
    );
    element(&mut meta, syntax, 0x0002, 0x0003, b"UI", b"1.2.3.4.5");
    element(
        &mut meta,
        syntax,
        0x0002,
        0x0010,
        b"UI",
        syntax.uid().as_bytes(),
    );
    let mut out = vec![0u8; 128];
    out.extend(b"DICM");
    element(
        &mut out,
        syntax,
        0x0002,
        0x0000,
        b"UL",
        &(meta.len() as u32).to_le_bytes(),
    );
    out.extend(meta);
    out.extend(ds);
    out
}

/// Encapsulated PixelData (PS3.5 A.4), explicit VR little endian: undefined length,
/// the basic offset table item, one item per fragment, the sequence delimiter.
fn encapsulated(out: &mut Vec<u8>, bot: &[u8], fragments: &[&[u8]]) {
    out.extend([
        0xE0, 0x7F, 0x10, 0x00, b'O', b'B', 0, 0, 0xFF, 0xFF, 0xFF, 0xFF,
    ]);
    for item in std::iter::once(bot).chain(fragments.iter().copied()) {
        out.extend([0xFE, 0xFF, 0x00, 0xE0]);
        out.extend((item.len() as u32).to_le_bytes());
        out.extend(item);
    }
    out.extend([0xFE, 0xFF, 0xDD, 0xE0, 0, 0, 0, 0]);
}

/// One RLE Lossless frame (PS3.5 Annex G) of little-endian samples of `size` bytes:
/// the 64-byte header, then per byte of a sample (most significant first) a
/// PackBits-coded segment: a repeat run for two or more equal bytes, else literals.
/// Segments are padded to even lengths.
fn rle_frame(samples: &[u8], size: usize) -> Vec<u8> {
    let n = samples.len() / size;
    let mut segments = Vec::new();
    for s in 0..size {
        let plane: Vec<u8> = (0..n).map(|i| samples[i * size + size - 1 - s]).collect();
        let mut seg = Vec::new();
        let mut i = 0;
        while i < plane.len() {
            let mut run = 1;
            while i + run < plane.len() && run < 128 && plane[i + run] == plane[i] {
                run += 1;
            }
            if run >= 2 {
                seg.push((1 - run as i32) as i8 as u8);
                seg.push(plane[i]);
                i += run;
            } else {
                let mut j = i + 1;
                while j < plane.len() && j - i < 128 && plane.get(j + 1) != Some(&plane[j]) {
                    j += 1;
                }
                seg.push((j - i - 1) as u8);
                seg.extend(&plane[i..j]);
                i = j;
            }
        }
        if seg.len() % 2 == 1 {
            seg.push(0);
        }
        segments.push(seg);
    }
    let mut header = vec![0u8; 64];
    header[..4].copy_from_slice(&(size as u32).to_le_bytes());
    let mut at = 64u32;
    for (k, seg) in segments.iter().enumerate() {
        header[4 + 4 * k..8 + 4 * k].copy_from_slice(&at.to_le_bytes());
        at += seg.len() as u32;
    }
    let mut out = header;
    for seg in segments {
        out.extend(seg);
    }
    out
}

/// Six values that use the whole range of each sample type (exact in f32 for 32 bits).
fn values(bits: u16, signed: bool) -> Vec<i64> {
    match (bits, signed) {
        (8, false) => vec![0, 1, 127, 128, 200, 255],
        (8, true) => vec![-128, -1, 0, 1, 100, 127],
        (16, false) => vec![0, 1, 255, 256, 0x1234, 65535],
        (16, true) => vec![-32768, -2, 0, 1, 0x1234, 32767],
        (32, false) => vec![0, 1, 65535, 65536, 0x00AB_CDEF, 1 << 31],
        _ => vec![-(1 << 31), -65537, -1, 0, 0x0012_3456, 0x7FFF_FF80],
    }
}

#[test]
fn every_syntax_bit_depth_sign_and_vr_reads_the_values_written() {
    let dir = scratch("bytes");
    let mut cases = 0;
    for syntax in [
        Syntax::ImplicitLittle,
        Syntax::ExplicitLittle,
        Syntax::ExplicitBig,
        Syntax::DeflatedLittle,
        Syntax::Rle,
    ] {
        for bits in [8u16, 16, 32] {
            for signed in [false, true] {
                for ow in [false, true] {
                    if (!syntax.explicit() || syntax == Syntax::Rle) && !ow {
                        // Implicit VR writes no VR, encapsulated data is OB: one file
                        // per bit depth and sign.
                        continue;
                    }
                    let want = values(bits, signed);
                    let name = format!(
                        "{syntax:?}-{bits}-{signed}-{}.dcm",
                        if ow { "ow" } else { "ob" }
                    );
                    let path = dir.join(&name);
                    std::fs::write(&path, file(syntax, bits, signed, ow, &want)).unwrap();
                    let v = voxlab::io::read_volume(Path::new(&path))
                        .unwrap_or_else(|e| panic!("{name}: {e}"));
                    assert_eq!(v.dims(), [3, 2, 1], "{name}");
                    let got = v.values_f64();
                    let want: Vec<f64> = want.iter().map(|&x| x as f64).collect();
                    assert_eq!(got, want, "{name}");
                    cases += 1;
                }
            }
        }
    }
    assert_eq!(cases, 48);
}

#[test]
fn a_slice_without_its_pixel_data_is_named() {
    let dir = scratch("no_pixels");
    let syntax = Syntax::ExplicitLittle;
    std::fs::write(
        dir.join("a.dcm"),
        file(syntax, 16, false, true, &values(16, false)),
    )
    .unwrap();
    std::fs::write(dir.join("b.dcm"), image_file(syntax, 16, false, true, None)).unwrap();
    common::assert_format(
        voxlab::io::read_volume(&dir),
        "PixelData",
        "has no pixel data: the file is incomplete",
    );
    let e = voxlab::io::read_volume(&dir).unwrap_err().to_string();
    assert!(e.contains("b.dcm"), "{e}");
}

// ---------------------------------------------------------------------------------
// Files of any elements
// ---------------------------------------------------------------------------------

/// One element to write: (group, element, VR, value in the file's byte order).
type Element = (u16, u16, [u8; 2], Vec<u8>);

/// A file of `elements` (sorted here by tag) in `syntax`.
fn build(syntax: Syntax, mut elements: Vec<Element>) -> Vec<u8> {
    elements.sort_by_key(|e| (e.0, e.1));
    let mut ds = Vec::new();
    for (g, e, vr, v) in &elements {
        element(&mut ds, syntax, *g, *e, vr, v);
    }
    wrap(syntax, ds)
}

/// Unsigned shorts in the file's byte order.
fn us(syntax: Syntax, v: &[u16]) -> Vec<u8> {
    v.iter()
        .flat_map(|&x| {
            if syntax.big() {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            }
        })
        .collect()
}

/// The image attributes of a `cols` × `rows` grayscale image.
fn image_elements(
    syntax: Syntax,
    rows: u16,
    cols: u16,
    bits: u16,
    photometric: &str,
) -> Vec<Element> {
    vec![
        (
            0x0008,
            0x0016,
            *b"UI",
            b"1.2.840.10008.5.1.4.1.1.481.2".to_vec(),
        ),
        (0x0008, 0x0018, *b"UI", b"1.2.3.4.5".to_vec()),
        (0x0020, 0x000E, *b"UI", b"1.2.3.4".to_vec()),
        (0x0028, 0x0002, *b"US", us(syntax, &[1])),
        (0x0028, 0x0004, *b"CS", photometric.as_bytes().to_vec()),
        (0x0028, 0x0010, *b"US", us(syntax, &[rows])),
        (0x0028, 0x0011, *b"US", us(syntax, &[cols])),
        (0x0028, 0x0100, *b"US", us(syntax, &[bits])),
        (0x0028, 0x0101, *b"US", us(syntax, &[bits.max(1)])),
        (0x0028, 0x0102, *b"US", us(syntax, &[bits.max(1) - 1])),
        (0x0028, 0x0103, *b"US", us(syntax, &[0])),
    ]
}

/// An RT dose grid of 2 × 3 × 3 frames, 32-bit unsigned samples `k·1000003 + i` (k the
/// frame, i the voxel, past 2^16 so that the two halves of a word matter), as RT dose
/// files hold them: OW, NumberOfFrames, GridFrameOffsetVector `offsets`,
/// DoseGridScaling 2.5e-5, IPP (−10, −20, 30), PixelSpacing 2 (rows) \ 3 (columns).
fn dose_file(syntax: Syntax, offsets: &str) -> Vec<u8> {
    let mut e = image_elements(syntax, 2, 3, 32, "MONOCHROME2");
    e.push((0x0028, 0x0008, *b"IS", b"3".to_vec()));
    e.push((0x0020, 0x0032, *b"DS", b"-10\\-20\\30".to_vec()));
    e.push((0x0020, 0x0037, *b"DS", b"1\\0\\0\\0\\1\\0".to_vec()));
    e.push((0x0028, 0x0030, *b"DS", b"2\\3".to_vec()));
    e.push((0x3004, 0x000C, *b"DS", offsets.as_bytes().to_vec()));
    e.push((0x3004, 0x000E, *b"DS", b"2.5e-5".to_vec()));
    let mut px = Vec::new();
    for k in 0..3u32 {
        for i in 0..6u32 {
            let w = k * 1_000_003 + i;
            px.extend(if syntax.big() {
                w.to_be_bytes()
            } else {
                w.to_le_bytes()
            });
        }
    }
    e.push((0x7FE0, 0x0010, *b"OW", px));
    build(syntax, e)
}

#[test]
fn rt_dose_grids_are_scaled_and_placed_by_their_frame_offsets() {
    let dir = scratch("rt_dose");
    // GridFrameOffsetVector relative to IPP (first value 0), absolute z (first value
    // IPP z), and decreasing (frames stored from head to feet).
    for syntax in [
        Syntax::ExplicitBig,
        Syntax::ExplicitLittle,
        Syntax::ImplicitLittle,
    ] {
        for (offsets, reversed) in [
            ("0\\2.5\\5", false),
            ("30\\32.5\\35", false),
            ("0\\-2.5\\-5", true),
        ] {
            let name = format!("{syntax:?}-{}.dcm", offsets.replace('\\', "_"));
            let path = dir.join(&name);
            std::fs::write(&path, dose_file(syntax, offsets)).unwrap();
            let v = voxlab::io::read_volume(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(v.dims(), [3, 2, 3], "{name}");
            let got = v.values_f64();
            for (n, &g) in got.iter().enumerate() {
                let (z, i) = (n / 6, n % 6);
                let k = if reversed { 2 - z } else { z };
                let want = ((k * 1_000_003 + i) as f64 * 2.5e-5) as f32 as f64;
                assert_eq!(g, want, "{name}: voxel {n}");
            }
            let a = v.affine();
            let z0 = if reversed { 25.0 } else { 30.0 };
            let want = [
                [3.0, 0.0, 0.0, 0.0],
                [0.0, 2.0, 0.0, 0.0],
                [0.0, 0.0, 2.5, 0.0],
                [-10.0, -20.0, z0, 1.0],
            ];
            for (c, w) in want.iter().enumerate() {
                let got = a.col(c).to_array();
                assert!(
                    got.iter().zip(w).all(|(g, w)| (g - w).abs() < 1e-9),
                    "{name}: affine column {c} is {got:?}, want {w:?}"
                );
            }
        }
    }
    // A vector of the wrong length names the field.
    let path = dir.join("short.dcm");
    std::fs::write(&path, dose_file(Syntax::ExplicitLittle, "0\\2.5")).unwrap();
    common::assert_format(
        voxlab::io::read_volume(&path),
        "GridFrameOffsetVector",
        "expected 3 finite numbers",
    );
}

/// A 2 × 3 image of 16-bit samples 0, 1000, … with `photometric`, in explicit VR LE.
fn photometric_file(photometric: &str, bits: u16) -> Vec<u8> {
    let syntax = Syntax::ExplicitLittle;
    let mut e = image_elements(syntax, 2, 3, bits, photometric);
    let px: Vec<u8> = (0..6u16).flat_map(|i| (i * 1000).to_le_bytes()).collect();
    e.push((0x7FE0, 0x0010, *b"OW", px));
    build(syntax, e)
}

#[test]
fn monochrome1_keeps_its_stored_values() {
    // MONOCHROME1 means low values are shown bright; voxlab does not invert them
    // (io::dicom module docs): the values are what was measured.
    let path = scratch("mono1").join("m1.dcm");
    std::fs::write(&path, photometric_file("MONOCHROME1", 16)).unwrap();
    let v = voxlab::io::read_volume(&path).unwrap();
    assert_eq!(
        v.values_f64(),
        [0.0, 1000.0, 2000.0, 3000.0, 4000.0, 5000.0]
    );
}

#[test]
fn palette_colour_and_one_bit_data_are_refused_clearly() {
    let dir = scratch("refused");
    let path = dir.join("palette.dcm");
    std::fs::write(&path, photometric_file("PALETTE COLOR", 16)).unwrap();
    common::assert_format(
        voxlab::io::read_volume(&path),
        "PhotometricInterpretation",
        "colour images are not supported",
    );
    let path = dir.join("bitmap.dcm");
    std::fs::write(&path, photometric_file("MONOCHROME2", 1)).unwrap();
    common::assert_format(
        voxlab::io::read_volume(&path),
        "BitsAllocated",
        "1-bit (bitmap) pixel data is not supported",
    );
}

#[test]
fn the_dicm_marker_wins_over_other_magic_and_names() {
    // Preambles that start like a TIFF, an NRRD or a NumPy file, in files named as
    // those formats: the DICM marker at byte 128 makes them DICOM.
    let dir = scratch("dicm_wins");
    let series = scratch("dicm_wins_series");
    let want: Vec<f64> = values(16, false).iter().map(|&x| x as f64).collect();
    for (name, magic) in [
        ("a.tif", &b"II*\0\x08\0\0\0"[..]),
        ("b.nrrd", b"NRRD0004\n"),
        ("c.npy", b"\x93NUMPY\x01\x00"),
    ] {
        let mut bytes = file(Syntax::ExplicitLittle, 16, false, true, &values(16, false));
        bytes[..magic.len()].copy_from_slice(magic);
        let path = dir.join(name);
        std::fs::write(&path, &bytes).unwrap();
        assert_eq!(
            voxlab::io::detect_format(&path).unwrap(),
            voxlab::io::Format::Dicom,
            "{name}"
        );
        let v = voxlab::io::read_volume(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(v.values_f64(), want, "{name}");
        if name.ends_with(".tif") {
            std::fs::write(series.join(name), &bytes).unwrap();
        }
    }
    // A directory whose one image is named .tif is a DICOM series, not a TIFF stack.
    assert_eq!(
        voxlab::io::detect_format(&series).unwrap(),
        voxlab::io::Format::Dicom
    );
    let v = voxlab::io::read_volume(&series).unwrap();
    assert_eq!(v.values_f64(), want);
}

/// Items of a sequence of defined length (explicit VR little endian): each item's
/// elements, sorted by tag.
fn sequence(items: Vec<Vec<Element>>) -> Vec<u8> {
    let mut out = Vec::new();
    for mut item in items {
        item.sort_by_key(|e| (e.0, e.1));
        let mut body = Vec::new();
        for (g, e, vr, v) in &item {
            element(&mut body, Syntax::ExplicitLittle, *g, *e, vr, v);
        }
        out.extend([0xFE, 0xFF, 0x00, 0xE0]);
        out.extend((body.len() as u32).to_le_bytes());
        out.extend(body);
    }
    out
}

#[test]
fn compressed_multi_frame_with_functional_groups_is_a_volume_in_place() {
    // An enhanced multi-frame image, RLE-coded, 3 frames of 2 × 3 signed 16-bit
    // samples 100·k − i stored in the order z = 10, 0, 5 along an oblique normal;
    // orientation and pixel spacing in the shared functional groups, each frame's
    // position and rescale intercept in its own.
    let syntax = Syntax::Rle;
    let (r, c) = ([0.6, 0.8, 0.0], [0.0, 0.0, -1.0]);
    // normal = r × c = (−0.8, 0.6, 0)
    let n = [-0.8, 0.6, 0.0];
    let origin = [5.0, -3.0, 7.0];
    let zs = [10.0, 0.0, 5.0];
    let intercepts = [0.0, -1000.0, 7.0];
    let ds = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x}"))
            .collect::<Vec<_>>()
            .join("\\")
            .into_bytes()
    };
    let mut e = image_elements(syntax, 2, 3, 16, "MONOCHROME2");
    e.retain(|x| (x.0, x.1) != (0x0028, 0x0103));
    e.push((0x0028, 0x0103, *b"US", us(syntax, &[1])));
    e.push((0x0028, 0x0008, *b"IS", b"3".to_vec()));
    let shared = sequence(vec![vec![
        (
            0x0020,
            0x9116,
            *b"SQ",
            sequence(vec![vec![(
                0x0020,
                0x0037,
                *b"DS",
                ds(&[r[0], r[1], r[2], c[0], c[1], c[2]]),
            )]]),
        ),
        (
            0x0028,
            0x9110,
            *b"SQ",
            sequence(vec![vec![(0x0028, 0x0030, *b"DS", ds(&[0.5, 0.25]))]]),
        ),
    ]]);
    e.push((0x5200, 0x9229, *b"SQ", shared));
    let per_frame: Vec<Vec<Element>> = (0..3)
        .map(|k| {
            let p: Vec<f64> = (0..3).map(|a| origin[a] + n[a] * zs[k]).collect();
            vec![
                (
                    0x0020,
                    0x9113,
                    *b"SQ",
                    sequence(vec![vec![(0x0020, 0x0032, *b"DS", ds(&p))]]),
                ),
                (
                    0x0028,
                    0x9145,
                    *b"SQ",
                    sequence(vec![vec![
                        (0x0028, 0x1052, *b"DS", ds(&[intercepts[k]])),
                        (0x0028, 0x1053, *b"DS", ds(&[1.0])),
                    ]]),
                ),
            ]
        })
        .collect();
    e.push((0x5200, 0x9230, *b"SQ", sequence(per_frame)));
    // The frames, each one RLE fragment, with a basic offset table.
    let frames: Vec<Vec<u8>> = (0..3i16)
        .map(|k| {
            let px: Vec<u8> = (0..6i16)
                .flat_map(|i| (100 * k - i).to_le_bytes())
                .collect();
            rle_frame(&px, 2)
        })
        .collect();
    let mut bot = Vec::new();
    let mut at = 0u32;
    for f in &frames {
        bot.extend(at.to_le_bytes());
        at += 8 + f.len() as u32;
    }
    let mut data = Vec::new();
    for (g, el, vr, v) in {
        e.sort_by_key(|x| (x.0, x.1));
        &e
    } {
        element(&mut data, syntax, *g, *el, vr, v);
    }
    let refs: Vec<&[u8]> = frames.iter().map(Vec::as_slice).collect();
    encapsulated(&mut data, &bot, &refs);
    let path = scratch("enhanced").join("enhanced.dcm");
    std::fs::write(&path, wrap(syntax, data)).unwrap();

    let v = voxlab::io::read_volume(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(v.dims(), [3, 2, 3]);
    // Sorted along the normal: frames 1 (z 0), 2 (z 5), 0 (z 10).
    let mut want = Vec::new();
    for k in [1usize, 2, 0] {
        for i in 0..6 {
            want.push((100 * k as i64 - i) as f64 + intercepts[k]);
        }
    }
    assert_eq!(v.values_f64(), want);
    let a = v.affine();
    let cols = [
        [r[0] * 0.25, r[1] * 0.25, r[2] * 0.25],
        [c[0] * 0.5, c[1] * 0.5, c[2] * 0.5],
        [n[0] * 5.0, n[1] * 5.0, n[2] * 5.0],
        [origin[0], origin[1], origin[2]],
    ];
    for (k, w) in cols.iter().enumerate() {
        let got = a.col(k).truncate().to_array();
        assert!(
            got.iter().zip(w).all(|(g, w)| (g - w).abs() < 1e-9),
            "affine column {k} is {got:?}, want {w:?}"
        );
    }
}

#[test]
fn a_series_of_compressed_slices_is_read_like_any_series() {
    // Three RLE slices of 2 × 3 unsigned 16-bit samples 1000·z + i, written in the
    // order z = 2, 0, 1 under file names that do not follow it; one slice without
    // a basic offset table.
    let dir = scratch("rle_series");
    for (file, z) in [("a.dcm", 2u16), ("b.dcm", 0), ("c.dcm", 1)] {
        let syntax = Syntax::Rle;
        let mut e = image_elements(syntax, 2, 3, 16, "MONOCHROME2");
        e.push((
            0x0020,
            0x0032,
            *b"DS",
            format!("0\\0\\{}", 1.5 * f64::from(z)).into_bytes(),
        ));
        e.push((0x0020, 0x0037, *b"DS", b"1\\0\\0\\0\\1\\0".to_vec()));
        e.sort_by_key(|x| (x.0, x.1));
        let mut data = Vec::new();
        for (g, el, vr, v) in &e {
            element(&mut data, syntax, *g, *el, vr, v);
        }
        let px: Vec<u8> = (0..6u16)
            .flat_map(|i| (1000 * z + i).to_le_bytes())
            .collect();
        let frame = rle_frame(&px, 2);
        let bot = if z == 1 { Vec::new() } else { vec![0; 4] };
        encapsulated(&mut data, &bot, &[&frame]);
        std::fs::write(dir.join(file), wrap(syntax, data)).unwrap();
    }
    let v = voxlab::io::read_volume(&dir).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(v.dims(), [3, 2, 3]);
    let want: Vec<f64> = (0..3)
        .flat_map(|z| (0..6).map(move |i| f64::from(1000 * z + i)))
        .collect();
    assert_eq!(v.values_f64(), want);
    assert_eq!(v.affine().col(2).to_array(), [0.0, 0.0, 1.5, 0.0]);
}
