//! TIFF stacks: a multi-page TIFF whose pages are the z slices of a volume, or a
//! directory of single-page TIFFs ([`read_tiff_dir`]). Decoded with the `tiff` crate
//! (uncompressed, LZW, Deflate and PackBits pages, strips or tiles, classic TIFF or
//! BigTIFF).
//!
//! # What is read
//!
//! - Every page (IFD, in file order) is one slice: page k is z = k, its rows are y
//!   (top row first) and its columns x. All pages must have the same width, height
//!   and sample type; a page that differs is an error naming it.
//! - Grayscale pages only (one sample per pixel), mapped like the table in
//!   [`crate::io`]: unsigned 8-bit → u8, signed 8-bit → i16, unsigned 16-bit → u16,
//!   signed 16-bit → i16; 16-bit floats → f32 (exact), 32-bit floats → f32;
//!   32/64-bit integers and 64-bit floats → f32, rounded to nearest. WhiteIsZero pages
//!   keep their stored values (nothing is inverted). RGB, palette, CMYK, YCbCr,
//!   grayscale with alpha and other multi-sample pages are refused: a volume holds one
//!   value per voxel (convert first, e.g. to 8-bit grayscale in ImageJ/Fiji). Bit
//!   depths other than 8, 16, 32 and 64 (bilevel, 12-bit) are refused too.
//! - The number of pages and the page size are checked against the voxel limit
//!   ([`max_voxels`](crate::volume::max_voxels)) before any page is decoded.
//!
//! # Geometry
//!
//! The affine is diagonal (the TIFF has no orientation), with voxel (0,0,0) at the
//! origin. The spacing is 1 mm on every axis unless the file is an ImageJ hyperstack
//! whose ImageDescription starts with `ImageJ=` and carries a `unit=`: then
//! - x and y spacing are 1 / XResolution and 1 / YResolution (pixels per unit; a
//!   missing resolution means 1 unit), z spacing is `spacing=` (else 1 unit);
//! - the unit is converted to mm: `micron`, `um`, `µm` × 0.001; `nm` × 1e-6; `mm`
//!   × 1; `cm` × 10; `m`, `meter` × 1000; `inch` × 25.4. Any other unit (ImageJ's
//!   `pixel`, or none) leaves 1 mm on every axis.
//!
//! Outside ImageJ files the resolution tags are ignored: most writers store a nominal
//! 72 dpi that says nothing about the voxel size. tifffile/qim3d stacks usually carry
//! no calibration and read with 1 mm voxels; give the spacing explicitly where it
//! matters.

use super::{reserve, Samples};
use crate::error::{Error, Result};
use crate::volume::{check_dims, AnyVolume};
use glam::{DMat4, DVec3};
use std::io::{BufReader, Cursor, Read, Seek};
use std::path::{Path, PathBuf};
use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::Tag;
use tiff::ColorType;

/// Reads a multi-page TIFF as a volume, one page per slice; see the module docs.
pub fn read_tiff(path: &Path) -> Result<AnyVolume> {
    read_stack(&[Input::File(path.to_path_buf())], path)
}

/// Reads a multi-page TIFF held in memory (`path` only names it in errors), exactly
/// as [`read_tiff`] reads a file; the demo reads its embedded scan this way.
pub fn read_tiff_bytes(bytes: &[u8], path: &Path) -> Result<AnyVolume> {
    read_stack(&[Input::Bytes(bytes, path.to_path_buf())], path)
}

/// Where a TIFF file comes from: the disk, or memory.
enum Input<'a> {
    File(PathBuf),
    Bytes(&'a [u8], PathBuf),
}

impl Input<'_> {
    fn path(&self) -> &Path {
        match self {
            Input::File(p) | Input::Bytes(_, p) => p,
        }
    }
}

/// A TIFF byte source: a file or a slice.
trait Source: Read + Seek {}
impl<T: Read + Seek> Source for T {}
type Dec<'a> = Decoder<Box<dyn Source + 'a>>;

/// Reads a directory of TIFF files (`.tif` or `.tiff`, any case) as one stack, the
/// files in natural order of their names (`slice2.tif` before `slice10.tif`); each
/// file contributes its pages in order. Other files are ignored; the spacing comes
/// from the first file. All pages of all files must share size and sample type.
pub fn read_tiff_dir(dir: &Path) -> Result<AnyVolume> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| Error::io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_file()
                && p.extension().and_then(|e| e.to_str()).is_some_and(|e| {
                    e.eq_ignore_ascii_case("tif") || e.eq_ignore_ascii_case("tiff")
                })
        })
        .collect();
    if files.is_empty() {
        return Err(Error::format(
            dir,
            "directory",
            "no .tif or .tiff files in the directory",
        ));
    }
    files.sort_by(|a, b| natural_cmp(&file_name(a), &file_name(b)));
    let inputs: Vec<Input> = files.into_iter().map(Input::File).collect();
    read_stack(&inputs, dir)
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Compares names with runs of digits compared as numbers ("a2" < "a10").
fn natural_cmp(a: &str, b: &str) -> std::cmp::Ordering {
    fn chunks(s: &str) -> Vec<(bool, &str)> {
        let mut out = Vec::new();
        let mut start = 0;
        let b = s.as_bytes();
        for i in 1..=b.len() {
            if i == b.len() || b[i].is_ascii_digit() != b[start].is_ascii_digit() {
                out.push((b[start].is_ascii_digit(), &s[start..i]));
                start = i;
            }
        }
        out
    }
    let (ca, cb) = (chunks(a), chunks(b));
    for (x, y) in ca.iter().zip(&cb) {
        let ord = match (x, y) {
            ((true, x), (true, y)) => {
                let (tx, ty) = (x.trim_start_matches('0'), y.trim_start_matches('0'));
                tx.len()
                    .cmp(&ty.len())
                    .then(tx.cmp(ty))
                    .then(x.len().cmp(&y.len()))
            }
            ((_, x), (_, y)) => x.cmp(y),
        };
        if ord.is_ne() {
            return ord;
        }
    }
    ca.len().cmp(&cb.len())
}

/// The sample type of a page: bits per sample and TIFF SampleFormat (1 unsigned,
/// 2 signed, 3 float).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct SampleType {
    bits: u8,
    format: u16,
}

impl SampleType {
    fn name(self) -> String {
        let kind = match self.format {
            2 => "signed",
            3 => "float",
            _ => "unsigned",
        };
        format!("{kind} {}-bit", self.bits)
    }
}

fn tiff_error(path: &Path, e: tiff::TiffError) -> Error {
    match e {
        tiff::TiffError::IoError(e) if e.kind() != std::io::ErrorKind::UnexpectedEof => {
            Error::io(path, e)
        }
        e => Error::format(
            path,
            "file",
            format!("cannot be decoded as TIFF (corrupt, truncated or unsupported): {e}"),
        ),
    }
}

/// Opens a TIFF decoder. `page_bytes` is the size of one decoded page (already checked
/// against the voxel limit), or 0 while only tags are read; the crate's default
/// buffer limit (256 MiB, which also bounds the values a tag may claim) is raised to
/// it, never removed.
fn open<'a>(input: &'a Input, page_bytes: usize) -> Result<Dec<'a>> {
    let path = input.path();
    let source: Box<dyn Source + 'a> = match input {
        Input::File(p) => Box::new(BufReader::new(super::open(p)?.0)),
        Input::Bytes(b, _) => Box::new(Cursor::new(*b)),
    };
    let mut limits = Limits::default();
    limits.decoding_buffer_size = limits.decoding_buffer_size.max(page_bytes);
    Ok(Decoder::new(source)
        .map_err(|e| tiff_error(path, e))?
        .with_limits(limits))
}

/// The size and sample type of the current page; refuses non-grayscale pages.
fn page_info(dec: &mut Dec, path: &Path, page: usize) -> Result<([usize; 2], SampleType)> {
    let (w, h) = dec.dimensions().map_err(|e| tiff_error(path, e))?;
    let color = dec.colortype().map_err(|e| tiff_error(path, e))?;
    let bits = match color {
        ColorType::Gray(b) => b,
        other => {
            return Err(Error::format(
                path,
                "PhotometricInterpretation",
                format!(
                    "page {page} is {other:?}: only grayscale pages (one sample per pixel) \
                     can be read as a volume; convert to grayscale first"
                ),
            ))
        }
    };
    if ![8, 16, 32, 64].contains(&bits) {
        return Err(Error::format(
            path,
            "BitsPerSample",
            format!("page {page} has {bits} bits per sample (8, 16, 32 or 64 are read)"),
        ));
    }
    let format = match dec.find_tag(Tag::SampleFormat) {
        Ok(Some(v)) => v
            .into_u16_vec()
            .ok()
            .and_then(|v| v.first().copied())
            .unwrap_or(1),
        _ => 1,
    };
    Ok(([w as usize, h as usize], SampleType { bits, format }))
}

/// Checks every page of every file, then decodes them into one volume.
fn read_stack(inputs: &[Input], what: &Path) -> Result<AnyVolume> {
    // Pass 1: sizes and types, without decoding any pixels.
    let mut first: Option<([usize; 2], SampleType, &Input)> = None;
    let mut pages = 0usize;
    for input in inputs {
        let path = input.path();
        let mut dec = open(input, 0)?;
        let mut page = 0;
        loop {
            let (size, ty) = page_info(&mut dec, path, page)?;
            match &first {
                None => first = Some((size, ty, input)),
                Some((size0, ty0, path0)) => {
                    if size != *size0 {
                        return Err(Error::format(
                            path,
                            "ImageWidth/ImageLength",
                            format!(
                                "page {page} is {}x{} but page 0 of {} is {}x{}: all pages of \
                                 a stack must have the same size",
                                size[0],
                                size[1],
                                path0.path().display(),
                                size0[0],
                                size0[1]
                            ),
                        ));
                    }
                    if ty != *ty0 {
                        return Err(Error::format(
                            path,
                            "SampleFormat",
                            format!(
                                "page {page} holds {} samples but page 0 of {} holds {}: all \
                                 pages of a stack must have the same sample type",
                                ty.name(),
                                path0.path().display(),
                                ty0.name()
                            ),
                        ));
                    }
                }
            }
            pages += 1;
            let [w, h] = first.as_ref().map(|f| f.0).unwrap_or_default();
            // Refuses a huge page, or a page count beyond the limit, before decoding.
            check_dims([w, h, pages]).map_err(|e| match e {
                Error::TooLarge { what: _, message } => {
                    Error::too_large(format!("TIFF stack {}", what.display()), message)
                }
                e => Error::format(path, "ImageWidth/ImageLength", e.to_string()),
            })?;
            if !dec.more_images() {
                break;
            }
            dec.next_image().map_err(|e| tiff_error(path, e))?;
            page += 1;
        }
    }
    let Some(([w, h], first_type, first_input)) = first else {
        return Err(Error::format(what, "file", "no pages"));
    };
    let dims = [w, h, pages];
    let n = check_dims(dims)?;
    let spacing = spacing(first_input)?;
    let page_bytes = w * h * (first_type.bits as usize / 8);

    // Pass 2: decode, converting each page to the volume's type.
    let mut out: Option<Samples> = None;
    for input in inputs {
        let path = input.path();
        let mut dec = open(input, page_bytes)?;
        let mut page = 0;
        loop {
            let data = dec.read_image().map_err(|e| tiff_error(path, e))?;
            append(&mut out, data, n, w * h, path, page)?;
            if !dec.more_images() {
                break;
            }
            dec.next_image().map_err(|e| tiff_error(path, e))?;
            page += 1;
        }
    }
    let samples = out.ok_or_else(|| Error::format(what, "file", "no pages"))?;
    let affine = DMat4::from_scale(DVec3::from_array(spacing));
    samples.into_volume(dims, affine)
}

/// Appends one decoded page, converted as in the module docs.
fn append(
    out: &mut Option<Samples>,
    data: DecodingResult,
    n: usize,
    page_len: usize,
    path: &Path,
    page: usize,
) -> Result<()> {
    let len = match &data {
        DecodingResult::U8(v) => v.len(),
        DecodingResult::I8(v) => v.len(),
        DecodingResult::U16(v) => v.len(),
        DecodingResult::I16(v) => v.len(),
        DecodingResult::U32(v) => v.len(),
        DecodingResult::I32(v) => v.len(),
        DecodingResult::U64(v) => v.len(),
        DecodingResult::I64(v) => v.len(),
        DecodingResult::F16(v) => v.len(),
        DecodingResult::F32(v) => v.len(),
        DecodingResult::F64(v) => v.len(),
    };
    if len != page_len {
        return Err(Error::format(
            path,
            "data",
            format!("page {page} decoded to {len} samples, expected {page_len}"),
        ));
    }
    if out.is_none() {
        *out = Some(match &data {
            DecodingResult::U8(_) => Samples::U8(reserve(n, path)?),
            DecodingResult::U16(_) => Samples::U16(reserve(n, path)?),
            DecodingResult::I8(_) | DecodingResult::I16(_) => Samples::I16(reserve(n, path)?),
            _ => Samples::F32(reserve(n, path)?),
        });
    }
    let mismatch = || {
        Error::format(
            path,
            "SampleFormat",
            format!("page {page} has a different sample type from page 0"),
        )
    };
    match (out.as_mut().expect("set above"), data) {
        (Samples::U8(o), DecodingResult::U8(v)) => o.extend_from_slice(&v),
        (Samples::U16(o), DecodingResult::U16(v)) => o.extend_from_slice(&v),
        (Samples::I16(o), DecodingResult::I16(v)) => o.extend_from_slice(&v),
        (Samples::I16(o), DecodingResult::I8(v)) => o.extend(v.into_iter().map(i16::from)),
        (Samples::F32(o), DecodingResult::F32(v)) => o.extend_from_slice(&v),
        (Samples::F32(o), DecodingResult::F16(v)) => o.extend(v.into_iter().map(|x| x.to_f32())),
        (Samples::F32(o), DecodingResult::F64(v)) => o.extend(v.into_iter().map(|x| x as f32)),
        (Samples::F32(o), DecodingResult::U32(v)) => o.extend(v.into_iter().map(|x| x as f32)),
        (Samples::F32(o), DecodingResult::I32(v)) => o.extend(v.into_iter().map(|x| x as f32)),
        (Samples::F32(o), DecodingResult::U64(v)) => o.extend(v.into_iter().map(|x| x as f32)),
        (Samples::F32(o), DecodingResult::I64(v)) => o.extend(v.into_iter().map(|x| x as f32)),
        _ => return Err(mismatch()),
    }
    Ok(())
}

// ---------------------------------------------------------------------------------
// Spacing
// ---------------------------------------------------------------------------------

/// Millimetres per unit for the units ImageJ writes.
fn unit_mm(unit: &str) -> Option<f64> {
    Some(match unit.trim().to_ascii_lowercase().as_str() {
        "micron" | "microns" | "um" | "\u{00b5}m" | "\u{03bc}m" => 1e-3,
        "nm" | "nanometer" => 1e-6,
        "mm" | "millimeter" => 1.0,
        "cm" | "centimeter" => 10.0,
        "m" | "meter" => 1000.0,
        "inch" | "in" => 25.4,
        _ => return None,
    })
}

/// A resolution tag (pixels per unit) as a number.
fn resolution(dec: &mut Dec, tag: Tag) -> Option<f64> {
    use tiff::decoder::ifd::Value;
    let v = dec.find_tag(tag).ok()??;
    let x = match v {
        Value::Rational(n, d) if d != 0 => n as f64 / d as f64,
        Value::Float(f) => f as f64,
        Value::Double(f) => f,
        Value::List(l) => match l.first()? {
            Value::Rational(n, d) if *d != 0 => *n as f64 / *d as f64,
            _ => return None,
        },
        _ => return None,
    };
    (x.is_finite() && x > 0.0).then_some(x)
}

/// The spacing (mm) from the first page of `input`; see the module docs.
fn spacing(input: &Input) -> Result<[f64; 3]> {
    let mut dec = open(input, 0)?;
    let desc = match dec.find_tag(Tag::ImageDescription) {
        Ok(Some(v)) => v.into_string().unwrap_or_default(),
        _ => String::new(),
    };
    Ok(imagej_spacing(
        &desc,
        resolution(&mut dec, Tag::XResolution),
        resolution(&mut dec, Tag::YResolution),
    )
    .unwrap_or([1.0; 3]))
}

/// The spacing an ImageJ description and the resolution tags give, if calibrated.
fn imagej_spacing(desc: &str, xres: Option<f64>, yres: Option<f64>) -> Option<[f64; 3]> {
    if !desc.starts_with("ImageJ=") {
        return None;
    }
    let value = |key: &str| {
        desc.lines()
            .filter_map(|l| l.split_once('='))
            .find(|(k, _)| k.trim() == key)
            .map(|(_, v)| v.trim().to_string())
    };
    let mm = unit_mm(&value("unit")?)?;
    let z = value("spacing")
        .and_then(|s| s.parse::<f64>().ok())
        .filter(|s| s.is_finite() && *s > 0.0)
        .unwrap_or(1.0);
    let s = [mm / xres.unwrap_or(1.0), mm / yres.unwrap_or(1.0), mm * z];
    s.iter().all(|x| x.is_finite() && *x > 0.0).then_some(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order() {
        let mut v = vec!["s10.tif", "s2.tif", "s1.tif", "s02.tif", "a.tif"];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(v, ["a.tif", "s1.tif", "s2.tif", "s02.tif", "s10.tif"]);
    }

    #[test]
    fn imagej_units() {
        let d = "ImageJ=1.53t\nimages=10\nslices=10\nunit=micron\nspacing=2.5\nloop=false\n";
        let s = imagej_spacing(d, Some(2.0), Some(4.0)).unwrap();
        assert_eq!(s, [0.0005, 0.00025, 0.0025]);
        let d = "ImageJ=1.53t\nunit=cm\n";
        assert_eq!(imagej_spacing(d, None, None).unwrap(), [10.0, 10.0, 10.0]);
        assert!(imagej_spacing("ImageJ=1.5\nunit=pixel\n", Some(1.0), None).is_none());
        assert!(imagej_spacing("{\"shape\": [3, 4, 5]}", Some(3.0), None).is_none());
        assert_eq!(unit_mm("\u{00b5}m"), Some(1e-3));
    }
}
