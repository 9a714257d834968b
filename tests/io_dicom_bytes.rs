//! DICOM files built byte by byte, without a DICOM library: every transfer syntax the
//! reader takes × BitsAllocated 8, 16, 32 × PixelRepresentation 0, 1 × pixel data as
//! OB or OW, read back against the values written. (Explicit VR big endian with 32-bit
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
}

impl Syntax {
    fn uid(self) -> &'static str {
        match self {
            Syntax::ImplicitLittle => "1.2.840.10008.1.2",
            Syntax::ExplicitLittle => "1.2.840.10008.1.2.1",
            Syntax::ExplicitBig => "1.2.840.10008.1.2.2",
            Syntax::DeflatedLittle => "1.2.840.10008.1.2.1.99",
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
    if values.is_some() {
        let vr = if ow { b"OW" } else { b"OB" };
        element(&mut ds, syntax, 0x7FE0, 0x0010, vr, &px);
    }
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
    ] {
        for bits in [8u16, 16, 32] {
            for signed in [false, true] {
                for ow in [false, true] {
                    if !syntax.explicit() && !ow {
                        // Implicit VR writes no VR: one file per bit depth and sign.
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
    assert_eq!(cases, 42);
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
