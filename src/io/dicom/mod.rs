//! DICOM images: one file (single- or multi-frame) or a directory holding one series.
//! Files are parsed with `dicom-object`; the pixel data is decoded here.
//!
//! # What is read
//!
//! - **A directory** is one series: every regular file in it (not in subdirectories)
//!   that carries the `DICM` marker at byte 128 is parsed; other files (a `README`, a
//!   thumbnail) are skipped, and so are DICOM objects without pixel data (`DICOMDIR`,
//!   structured reports); an image (it has Rows and Columns) without its pixel data is
//!   an error naming the file. A directory with no DICOM image at all is an error that says
//!   what was skipped. The images are grouped by SeriesInstanceUID (0020,000E); more
//!   than one series is an error listing each (UID, description, file count): point
//!   at a directory that holds one series.
//! - **Slice order** is by the position of each slice along the slice normal, the
//!   projection of ImagePositionPatient (0020,0032) onto the cross product of the two
//!   ImageOrientationPatient (0020,0037) vectors — never by file name or
//!   InstanceNumber, which scanners do not order reliably.
//! - **Slice spacing** comes from those positions, not from SliceThickness (which is
//!   the thickness of the excited slab, not the distance between slices) nor from
//!   SpacingBetweenSlices. With steps `d₁ … dₙ₋₁` between consecutive slices and `d`
//!   their median:
//!   - two slices at the same position (a step below 0.001 mm) are an error naming
//!     both files;
//!   - a step within 10 % of `k·d` for an integer `k ≥ 2` is a *missing slice* error
//!     naming the files on either side of the gap;
//!   - any other step that differs from `d` by more than `max(0.1 mm, 2 % of d)` is
//!     an *inconsistent spacing* error naming the files on either side. (Scanners
//!     often round positions to 0.1 mm: the bundled MR series has steps of 6.9 and
//!     7.0 mm, which a tighter tolerance would refuse.)
//!   - The spacing is the mean step, (last position − first position) / (n − 1).
//!   - Slices must lie along the normal: a slice that lies sideways of the normal
//!     through the first slice by more than 0.1 mm + 5 % of the spacing per slice
//!     (a tilted gantry, a sheared stack) is refused. Smaller sideways drift
//!     (rounding in the positions) is ignored.
//! - All slices must share Rows, Columns, PixelSpacing, ImageOrientationPatient
//!   (within 1e-4), BitsAllocated, BitsStored, HighBit and PixelRepresentation;
//!   otherwise the error says "mixed sizes" (or which attribute differs) and names
//!   the two files.
//! - **Multi-frame files** (NumberOfFrames > 1): each frame is a slice. Positions
//!   come from PerFrameFunctionalGroupsSequence → PlanePositionSequence →
//!   ImagePositionPatient; orientation and pixel spacing from the per-frame or the
//!   SharedFunctionalGroupsSequence (PlaneOrientationSequence, PixelMeasuresSequence),
//!   else from the top-level attributes; a frame with its own orientation or pixel
//!   spacing must match frame 1. An RT dose places its frames by
//!   GridFrameOffsetVector instead (below). When every frame has a position, frames are
//!   sorted and checked like a series. Otherwise frames are taken in file order with
//!   the spacing given by SpacingBetweenSlices, else SliceThickness, else 1 mm.
//!   A directory may hold one multi-frame file, but not a multi-frame file mixed
//!   with other images.
//! - **Time series** (a cardiac or perfusion series, an enhanced multi-frame image
//!   with a temporal dimension): when every position holds the same number `t ≥ 2` of
//!   slices, told apart by the first of TemporalPositionIdentifier,
//!   TemporalPositionIndex (FrameContentSequence), TriggerTime, AcquisitionTime and
//!   InstanceNumber (a multi-frame image: its frame order) that every slice has and
//!   that differs between the slices at one position, the series holds `t` 3-D
//!   volumes, ordered by that key; one is read at a time ([`read_dicom_frame`],
//!   `--frame K`), and without a choice the series is refused naming the count and
//!   the key. Positions held by unequal numbers of slices, or slices no key tells
//!   apart, stay *duplicate slice position* errors.
//!
//! # Values
//!
//! BitsAllocated 8, 16 or 32; the BitsStored bits ending at HighBit are kept, and
//! sign-extended when PixelRepresentation is 1. RescaleSlope and RescaleIntercept
//! (per slice, or per frame from the functional groups) are applied, giving
//! Hounsfield units for CT. The voxel type is chosen from the data: when every slope
//! is 1 and every intercept an integer, the values are kept as integers — `u8` (8-bit
//! unsigned data, no intercept), `i16` when the data is signed or shifted below zero
//! and fits, else `u16` when it fits, else `i16` when it fits; in all other cases
//! (fractional slope or intercept, or a range that fits neither) the values are
//! `f32`. SamplesPerPixel must be 1: colour (RGB, YBR) is refused, and so is
//! PALETTE COLOR (one sample that indexes a colour table). BitsAllocated 1 (bitmaps:
//! masks, overlays) is refused. MONOCHROME1 images (where low values are displayed
//! bright) keep their stored values: nothing is inverted, so a transfer function sees
//! what the scanner measured (invert the transfer function, not the data).
//!
//! # Geometry
//!
//! World coordinates are DICOM patient coordinates (LPS: +x towards the patient's
//! left, +y posterior, +z head), in millimetres, as written. The affine's columns:
//! x step = row direction cosine (IOP\[0..3\]) × PixelSpacing\[1\] (the column
//! spacing), y step = column direction cosine (IOP\[3..6\]) × PixelSpacing\[0\] (the
//! row spacing), z step = the unit slice normal × the slice spacing, with its sign
//! such that slice k sits at IPP₀ + k·step; the origin is the first slice's IPP. A
//! single image without IOP/IPP gets identity orientation at the origin, with
//! PixelSpacing when present (else 1 mm) and 1 mm along z.
//!
//! # Transfer syntaxes
//!
//! Uncompressed: implicit VR little endian, explicit VR little endian, explicit VR big
//! endian (samples of 16 and 32 bits turned around whole, whether the pixel data is OB
//! or OW) and deflated explicit VR little endian.
//!
//! Compressed (encapsulated) pixel data is decoded into the same stored samples
//! (`src/io/dicom/encapsulated.rs` says which decoder reads what):
//!
//! | syntax | UID | notes |
//! |---|---|---|
//! | RLE Lossless | 1.2.840.10008.1.2.5 | 8, 16 and 32 bits |
//! | JPEG Baseline (process 1) | …1.2.4.50 | 8 bits |
//! | JPEG Extended (processes 2 & 4) | …1.2.4.51 | 8 and 12 bits |
//! | JPEG Lossless (process 14), and its selection value 1 | …1.2.4.57, …1.2.4.70 | 2 to 16 bits |
//! | JPEG-LS Lossless, Near-Lossless | …1.2.4.80, …1.2.4.81 | 2 to 16 bits |
//! | JPEG 2000 (lossless only, and lossy; Part 2 with one component) | …1.2.4.90, .91, .92, .93 | up to 32 bits |
//!
//! Frames are found from the basic offset table when there is one; without it, one
//! frame is all the fragments, as many fragments as frames are one frame each, and
//! otherwise a fragment that starts a codestream (JPEG SOI, JPEG 2000 SOC) starts a
//! frame. Each frame's own header must agree with Rows, Columns, SamplesPerPixel 1 and
//! BitsAllocated before it is decoded; a corrupt frame is an error naming the file,
//! the frame and the field. Other compressed syntaxes (High-Throughput JPEG 2000, JPEG
//! XL, MPEG, …) are refused with their UID and name; decompress them first with
//! `gdcmconv --raw in.dcm out.dcm` (GDCM).
//!
//! # RT dose grids
//!
//! An RT dose is a multi-frame image without functional groups: frame k lies at
//! ImagePositionPatient + GridFrameOffsetVector\[k\] − GridFrameOffsetVector\[0\] along
//! the slice normal (which reads both forms the standard allows: offsets relative to
//! the first frame, whose first value is 0, and absolute z coordinates, whose first
//! value is the first frame's z), and the frames are then sorted and checked like a
//! series. DoseGridScaling multiplies the stored values (after any rescale): the
//! voxels are doses in Gy, as `f32`.

mod encapsulated;

use super::Samples;
use crate::error::{Error, Result};
use crate::volume::{check_dims, AnyVolume};
use dicom_dictionary_std::tags;
use dicom_object::mem::InMemDicomObject;
use dicom_object::{DefaultDicomObject, Tag};
use encapsulated::Codec;
use glam::{DMat4, DVec3, DVec4};
use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};

/// Transfer syntaxes whose pixel data is stored uncompressed.
const NATIVE_SYNTAXES: [&str; 4] = [
    "1.2.840.10008.1.2",
    "1.2.840.10008.1.2.1",
    "1.2.840.10008.1.2.2",
    "1.2.840.10008.1.2.1.99",
];

/// Names of the common compressed transfer syntaxes, for error messages.
const COMPRESSED_SYNTAXES: [(&str, &str); 16] = [
    ("1.2.840.10008.1.2.4.50", "JPEG Baseline (Process 1)"),
    ("1.2.840.10008.1.2.4.51", "JPEG Extended (Process 2 & 4)"),
    (
        "1.2.840.10008.1.2.4.57",
        "JPEG Lossless, Non-Hierarchical (Process 14)",
    ),
    (
        "1.2.840.10008.1.2.4.70",
        "JPEG Lossless, Non-Hierarchical, First-Order Prediction (Process 14, Selection Value 1)",
    ),
    ("1.2.840.10008.1.2.4.80", "JPEG-LS Lossless"),
    ("1.2.840.10008.1.2.4.81", "JPEG-LS Lossy (Near-Lossless)"),
    ("1.2.840.10008.1.2.4.90", "JPEG 2000 (Lossless Only)"),
    ("1.2.840.10008.1.2.4.91", "JPEG 2000"),
    (
        "1.2.840.10008.1.2.4.92",
        "JPEG 2000 Part 2 Multi-component (Lossless Only)",
    ),
    ("1.2.840.10008.1.2.4.93", "JPEG 2000 Part 2 Multi-component"),
    (
        "1.2.840.10008.1.2.4.201",
        "High-Throughput JPEG 2000 (Lossless Only)",
    ),
    ("1.2.840.10008.1.2.4.203", "High-Throughput JPEG 2000"),
    ("1.2.840.10008.1.2.4.110", "JPEG XL Lossless"),
    ("1.2.840.10008.1.2.4.112", "JPEG XL"),
    ("1.2.840.10008.1.2.5", "RLE Lossless"),
    ("1.2.840.10008.1.2.8.1", "Deflated Image Frame Compression"),
];

/// Relative tolerance on IOP components and pixel spacings shared by a series.
const SAME_TOL: f64 = 1e-4;

/// A step between slices may differ from the typical (median) step by this fraction
/// of it, or by [`STEP_TOL_MM`], whichever is larger.
const STEP_TOL: f64 = 0.02;

/// Positions are often written rounded to 0.1 mm (the bundled MR series alternates
/// steps of 6.9 and 7.0 mm), so steps may differ by this much.
const STEP_TOL_MM: f64 = 0.1;

/// Sideways drift allowed per slice, as a fraction of the slice spacing.
const SHEAR_TOL: f64 = 0.05;

/// Reads a DICOM file (single- or multi-frame) or a directory holding one series;
/// see the module docs for what is accepted.
pub fn read_dicom(path: &Path) -> Result<AnyVolume> {
    read_dicom_frame(path, None)
}

/// [`read_dicom`] of time point `frame` of a series (or multi-frame image) that holds
/// several 3-D volumes, the same positions at several times (module docs); `None`
/// reads one of a single volume.
pub fn read_dicom_frame(path: &Path, frame: Option<usize>) -> Result<AnyVolume> {
    let images = read_images(path)?;
    let a = assemble(&images, frame)?;
    decode(&images, &a.slices)?.into_volume(a.dims, a.affine)
}

/// How many 3-D volumes (time points) a DICOM file or series holds.
pub fn dicom_frames(path: &Path) -> Result<usize> {
    let images = read_images(path)?;
    Ok(assemble(&images, Some(0))?.frames)
}

fn read_images(path: &Path) -> Result<Vec<Image>> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if meta.is_dir() {
        return read_directory(path);
    }
    let (obj, raw) = parse_file(path)?;
    check_syntax(path, &obj)?;
    if !has_pixels(&obj, &raw) {
        return Err(Error::format(
            path,
            "PixelData",
            "the DICOM object holds no image (no PixelData element)",
        ));
    }
    Ok(vec![Image::new(path.to_path_buf(), obj, raw)?])
}

// ---------------------------------------------------------------------------------
// Files
// ---------------------------------------------------------------------------------

/// One parsed DICOM file with pixel data, and its pixel format.
struct Image {
    path: PathBuf,
    obj: DefaultDicomObject,
    /// The pixel data as little-endian bytes, when it was located by hand
    /// ([`locate_pixel_data`]) rather than parsed into `obj`.
    raw: Option<Vec<u8>>,
    px: PixelFormat,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct PixelFormat {
    rows: usize,
    cols: usize,
    frames: usize,
    bits_allocated: u32,
    bits_stored: u32,
    high_bit: u32,
    signed: bool,
}

impl Image {
    fn new(path: PathBuf, obj: DefaultDicomObject, raw: Option<Vec<u8>>) -> Result<Self> {
        let px = pixel_format(&path, &obj)?;
        let raw = match raw {
            Some(mut bytes) if obj.meta().transfer_syntax() == "1.2.840.10008.1.2.2" => {
                // Explicit VR big endian: words are stored most significant byte first.
                let size = (px.bits_allocated / 8) as usize;
                bytes.chunks_exact_mut(size).for_each(|w| w.reverse());
                Some(bytes)
            }
            r => r,
        };
        Ok(Image { path, obj, raw, px })
    }

    fn name(&self) -> String {
        self.path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| self.path.display().to_string())
    }
}

/// Whether the file has the `DICM` marker after a 128-byte preamble.
fn has_dicm_marker(path: &Path) -> Result<bool> {
    let mut head = [0u8; 132];
    let (mut f, _) = super::open(path)?;
    let mut got = 0;
    while got < head.len() {
        match f.read(&mut head[got..]) {
            Ok(0) => break,
            Ok(k) => got += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(Error::io(path, e)),
        }
    }
    Ok(got == 132 && &head[128..132] == b"DICM")
}

fn has_pixels(obj: &DefaultDicomObject, raw: &Option<Vec<u8>>) -> bool {
    raw.is_some() || obj.element_opt(tags::PIXEL_DATA).ok().flatten().is_some()
}

/// Parses a DICOM file, with `dicom-object`. A panic inside the parser (on input it
/// did not foresee) is reported as a format error, like any other parse failure.
///
/// Some files carry bytes after the pixel data that are not DICOM elements (the
/// bundled MR series is padded with 2.5 MB of zeros), which the parser reads as
/// elements and fails on. When the whole file does not parse, the attributes before
/// the pixel data are parsed on their own and the pixel data is located by hand
/// ([`locate_pixel_data`]), returned as the second value.
fn parse_file(path: &Path) -> Result<(DefaultDicomObject, Option<Vec<u8>>)> {
    if !has_dicm_marker(path)? {
        return Err(Error::format(
            path,
            "preamble",
            "not a DICOM file (no 'DICM' marker at byte 128)",
        ));
    }
    prescan::check_lengths(path)?;
    let open = |until: bool| {
        let p = path.to_path_buf();
        std::panic::catch_unwind(move || {
            let options = dicom_object::OpenFileOptions::new();
            if until {
                options.read_until(tags::PIXEL_DATA).open_file(&p)
            } else {
                options.read_to(tags::PIXEL_DATA).open_file(&p)
            }
        })
    };
    let error = match open(false) {
        Ok(Ok(obj)) => return Ok((obj, None)),
        Ok(Err(e)) => format!(
            "cannot be parsed as DICOM (corrupt or truncated): {}",
            chain(&e)
        ),
        Err(_) => "cannot be parsed as DICOM (corrupt or truncated)".to_string(),
    };
    if let Ok(Ok(obj)) = open(true) {
        if NATIVE_SYNTAXES[..3].contains(&obj.meta().transfer_syntax()) {
            let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
            if let Some(raw) = locate_pixel_data(&bytes, obj.meta().transfer_syntax()) {
                return Ok((obj, Some(raw)));
            }
        } else if !NATIVE_SYNTAXES.contains(&obj.meta().transfer_syntax())
            && Codec::of(obj.meta().transfer_syntax()).is_none()
        {
            // Let the caller report the unsupported syntax rather than a parse error.
            return Ok((obj, None));
        }
    }
    Err(Error::format(path, "file", error))
}

/// A pass over the element headers before the parser runs: every element, item and
/// sequence whose length is given must fit in what remains of its container and of
/// the file, so that a lying length (a PixelData element claiming 4 GiB in an 826-byte
/// file) is refused in milliseconds, before anything is allocated or read.
mod prescan {
    use crate::error::{Error, Result};
    use std::io::{BufReader, Read, Seek, SeekFrom};
    use std::path::Path;

    /// Elements visited before the pass gives up (and leaves the file to the parser).
    const MAX_ELEMENTS: usize = 4_000_000;
    const MAX_DEPTH: usize = 64;
    const UNDEFINED: u32 = 0xFFFF_FFFF;

    /// What a walk found: the container ended, or bytes that are not element headers
    /// (padding after the data, a corrupt tail) stopped it; the parser judges those.
    enum Flow {
        Done,
        Stop,
    }

    struct Walker<'a> {
        file: BufReader<std::fs::File>,
        pos: u64,
        len: u64,
        path: &'a Path,
        big: bool,
        implicit: bool,
        steps: usize,
        /// A delimiter ended the current undefined-length container.
        delimited: bool,
    }

    /// Checks the lengths of `path`'s elements (meta group, then the data set in its
    /// transfer syntax; a deflated data set is left to the parser).
    pub(super) fn check_lengths(path: &Path) -> Result<()> {
        let (file, len) = super::super::open(path)?;
        let mut w = Walker {
            file: BufReader::new(file),
            pos: 0,
            len,
            path,
            big: false,
            implicit: false,
            steps: 0,
            delimited: false,
        };
        w.seek(132)?;
        // The meta group (0002,xxxx) is always explicit VR little endian.
        let mut syntax = String::new();
        loop {
            let Some(group) = w.peek_group()? else {
                return Ok(());
            };
            if group != 0x0002 {
                break;
            }
            match w.element(len, 0, true, Some(&mut syntax))? {
                Flow::Done => {}
                Flow::Stop => return Ok(()),
            }
        }
        match syntax.trim_end_matches(['\0', ' ']) {
            "1.2.840.10008.1.2" => w.implicit = true,
            "1.2.840.10008.1.2.2" => w.big = true,
            "1.2.840.10008.1.2.1.99" => return Ok(()),
            _ => {}
        }
        w.walk(len, 0, true).map(|_| ())
    }

    impl Walker<'_> {
        fn seek(&mut self, to: u64) -> Result<()> {
            self.file
                .seek(SeekFrom::Start(to))
                .map_err(|e| Error::io(self.path, e))?;
            self.pos = to;
            Ok(())
        }

        fn bytes<const N: usize>(&mut self) -> Result<Option<[u8; N]>> {
            if self.pos + N as u64 > self.len {
                return Ok(None);
            }
            let mut b = [0u8; N];
            self.file
                .read_exact(&mut b)
                .map_err(|e| Error::io(self.path, e))?;
            self.pos += N as u64;
            Ok(Some(b))
        }

        fn u16(&self, b: [u8; 2]) -> u16 {
            if self.big {
                u16::from_be_bytes(b)
            } else {
                u16::from_le_bytes(b)
            }
        }

        fn u32(&self, b: [u8; 4]) -> u32 {
            if self.big {
                u32::from_be_bytes(b)
            } else {
                u32::from_le_bytes(b)
            }
        }

        fn peek_group(&mut self) -> Result<Option<u16>> {
            let at = self.pos;
            let g = self.bytes::<2>()?.map(u16::from_le_bytes);
            self.seek(at)?;
            Ok(g)
        }

        /// Elements up to `end` (or a delimiter); the items met hold data sets
        /// (`datasets`: a sequence's) or bytes (encapsulated pixel data's fragments).
        fn walk(&mut self, end: u64, depth: usize, datasets: bool) -> Result<Flow> {
            while self.pos + 8 <= end {
                match self.element(end, depth, datasets, None)? {
                    Flow::Done => {}
                    Flow::Stop => return Ok(Flow::Stop),
                }
                if self.delimited {
                    self.delimited = false;
                    return Ok(Flow::Done);
                }
            }
            Ok(Flow::Done)
        }

        /// One element (or item, or delimiter) within `end`; the transfer syntax UID
        /// is kept in `syntax` when asked for.
        fn element(
            &mut self,
            end: u64,
            depth: usize,
            datasets: bool,
            syntax: Option<&mut String>,
        ) -> Result<Flow> {
            self.steps += 1;
            if self.steps > MAX_ELEMENTS || depth > MAX_DEPTH {
                return Ok(Flow::Stop);
            }
            let Some(t) = self.bytes::<4>()? else {
                return Ok(Flow::Stop);
            };
            let group = self.u16([t[0], t[1]]);
            let elem = self.u16([t[2], t[3]]);
            if group == 0xFFFE {
                let Some(l) = self.bytes::<4>()? else {
                    return Ok(Flow::Stop);
                };
                let len = self.u32(l);
                return match elem {
                    0xE00D | 0xE0DD => {
                        self.delimited = true;
                        Ok(Flow::Done)
                    }
                    0xE000 if len == UNDEFINED && datasets => self.walk(end, depth + 1, true),
                    0xE000 if len == UNDEFINED => Ok(Flow::Stop),
                    0xE000 => {
                        let stop = self.fits(group, elem, "item", len as u64, end)?;
                        if datasets {
                            self.walk(stop, depth + 1, true)?;
                            self.delimited = false;
                        }
                        self.seek(stop)?;
                        Ok(Flow::Done)
                    }
                    _ => Ok(Flow::Stop),
                };
            }
            let (vr, len) = if self.implicit && group != 0x0002 {
                let Some(l) = self.bytes::<4>()? else {
                    return Ok(Flow::Stop);
                };
                (*b"--", self.u32(l))
            } else {
                let Some(vr) = self.bytes::<2>()? else {
                    return Ok(Flow::Stop);
                };
                if !vr.iter().all(u8::is_ascii_uppercase) {
                    return Ok(Flow::Stop);
                }
                let long = matches!(
                    &vr,
                    b"OB"
                        | b"OD"
                        | b"OF"
                        | b"OL"
                        | b"OV"
                        | b"OW"
                        | b"SQ"
                        | b"SV"
                        | b"UC"
                        | b"UN"
                        | b"UR"
                        | b"UT"
                        | b"UV"
                );
                let len = if long {
                    match (self.bytes::<2>()?, self.bytes::<4>()?) {
                        (Some(_), Some(l)) => self.u32(l),
                        _ => return Ok(Flow::Stop),
                    }
                } else {
                    match self.bytes::<2>()? {
                        Some(l) => u32::from(self.u16(l)),
                        None => return Ok(Flow::Stop),
                    }
                };
                (vr, len)
            };
            if len == UNDEFINED {
                // A sequence, or encapsulated pixel data: items up to the delimiter.
                let fragments = (group, elem) == (0x7FE0, 0x0010) || matches!(&vr, b"OB" | b"OW");
                let flow = self.walk(end, depth + 1, !fragments)?;
                self.delimited = false;
                if depth == 0 && (group, elem) == (0x7FE0, 0x0010) {
                    return Ok(Flow::Stop);
                }
                return Ok(flow);
            }
            let stop = self.fits(
                group,
                elem,
                std::str::from_utf8(&vr).unwrap_or("--"),
                len as u64,
                end,
            )?;
            if depth == 0 && (group, elem) == (0x7FE0, 0x0010) {
                // What follows the top-level pixel data is padding in some files (the
                // parser's fallback skips it), not elements to check.
                return Ok(Flow::Stop);
            }
            if let (Some(s), 0x0002, 0x0010) = (syntax, group, elem) {
                let mut b = vec![0u8; (len as usize).min(128)];
                self.file
                    .read_exact(&mut b)
                    .map_err(|e| Error::io(self.path, e))?;
                *s = String::from_utf8_lossy(&b).into_owned();
            } else if &vr == b"SQ" {
                self.walk(stop, depth + 1, true)?;
                self.delimited = false;
            }
            self.seek(stop)?;
            Ok(Flow::Done)
        }

        /// The end of a value of `len` bytes starting here, refused when it passes the
        /// end of its container or of the file.
        fn fits(&self, group: u16, elem: u16, vr: &str, len: u64, end: u64) -> Result<u64> {
            let stop = self.pos + len;
            if stop <= end.min(self.len) {
                return Ok(stop);
            }
            use dicom_core::dictionary::{DataDictionary, DataDictionaryEntry};
            // The element's keyword (PixelData, MediaStorageSOPInstanceUID), else its tag.
            let name = dicom_object::StandardDataDictionary
                .by_tag(dicom_object::Tag(group, elem))
                .map(|e| e.alias().to_string())
                .filter(|a| !a.is_empty() && group != 0xFFFE)
                .unwrap_or_else(|| format!("({group:04X},{elem:04X})"));
            let remain = end.min(self.len).saturating_sub(self.pos);
            Err(Error::format(
                self.path,
                name.clone(),
                format!(
                    "element {name} ({group:04X},{elem:04X}) {vr} at byte {} claims {len} \
                     bytes, but only {remain} \
                     remain in {} of {} bytes: the file is truncated or its length field \
                     is corrupt",
                    self.pos,
                    if end < self.len {
                        "its container"
                    } else {
                        "the file"
                    },
                    self.len
                ),
            ))
        }
    }
}

/// Finds the last top-level PixelData element (7FE0,0010) of a file in a native,
/// non-deflated transfer syntax by its tag bytes, and returns its value: the last
/// occurrence whose header is well formed (a binary VR in explicit syntaxes) and whose
/// value fits in the file. Earlier occurrences can be icons in sequences.
fn locate_pixel_data(bytes: &[u8], syntax: &str) -> Option<Vec<u8>> {
    let implicit = syntax == "1.2.840.10008.1.2";
    let big = syntax == "1.2.840.10008.1.2.2";
    let tag: [u8; 4] = if big {
        [0x7F, 0xE0, 0x00, 0x10]
    } else {
        [0xE0, 0x7F, 0x10, 0x00]
    };
    let u32_at = |at: usize| -> Option<usize> {
        let b: [u8; 4] = bytes.get(at..at + 4)?.try_into().ok()?;
        Some(if big {
            u32::from_be_bytes(b)
        } else {
            u32::from_le_bytes(b)
        } as usize)
    };
    let mut end = bytes.len();
    while let Some(at) = bytes[..end].windows(4).rposition(|w| w == tag) {
        end = at + 3;
        let (len, start) = if implicit {
            (u32_at(at + 4), at + 8)
        } else {
            let vr = bytes.get(at + 4..at + 6)?;
            if !matches!(vr, b"OW" | b"OB" | b"UN") {
                continue;
            }
            (u32_at(at + 8), at + 12)
        };
        match len {
            Some(len) if len != 0xFFFF_FFFF && start + len <= bytes.len() => {
                return Some(bytes[start..start + len].to_vec());
            }
            _ => continue,
        }
    }
    None
}

/// An error with its causes, "outer: inner: innermost".
fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cur = e.source();
    while let Some(c) = cur {
        s.push_str(": ");
        s.push_str(&c.to_string());
        cur = c.source();
    }
    s
}

/// Refuses the transfer syntaxes whose pixel data voxlab does not decode.
fn check_syntax(path: &Path, obj: &DefaultDicomObject) -> Result<()> {
    let uid = obj.meta().transfer_syntax();
    if NATIVE_SYNTAXES.contains(&uid) || Codec::of(uid).is_some() {
        return Ok(());
    }
    let name = COMPRESSED_SYNTAXES
        .iter()
        .find(|(u, _)| *u == uid)
        .map(|(_, n)| *n)
        .unwrap_or("unknown or compressed transfer syntax");
    Err(Error::format(
        path,
        "TransferSyntaxUID",
        format!(
            "transfer syntax {uid} ({name}) is not supported: voxlab reads uncompressed \
             DICOM (implicit/explicit VR little endian, explicit VR big endian, deflated), \
             RLE Lossless, JPEG (baseline, extended 8-bit, lossless), JPEG-LS and JPEG \
             2000; decompress first, e.g. `gdcmconv --raw in.dcm out.dcm`"
        ),
    ))
}

/// Reads every DICOM image of a directory, checking that they form one series.
fn read_directory(dir: &Path) -> Result<Vec<Image>> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| Error::io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    paths.sort();
    let mut skipped = Vec::new();
    let mut images = Vec::new();
    for p in paths {
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if !has_dicm_marker(&p)? {
            skipped.push(format!("{name} (not DICOM)"));
            continue;
        }
        let (obj, raw) = parse_file(&p)?;
        if !has_pixels(&obj, &raw) {
            // An image (Rows, Columns) without its pixels is a broken slice, not a
            // DICOMDIR or a report: said as such, rather than found later as a gap.
            if int(&obj, tags::ROWS).is_some() && int(&obj, tags::COLUMNS).is_some() {
                return Err(Error::format(
                    &p,
                    "PixelData",
                    "this image (it has Rows and Columns) has no pixel data: the file is \
                     incomplete (an interrupted transfer or export?); the series cannot be \
                     read without it",
                ));
            }
            skipped.push(format!("{name} (DICOM without pixel data)"));
            continue;
        }
        check_syntax(&p, &obj)?;
        images.push(Image::new(p, obj, raw)?);
    }
    if images.is_empty() {
        let shown: Vec<&str> = skipped.iter().take(8).map(String::as_str).collect();
        let more = if skipped.len() > 8 {
            format!(" and {} more", skipped.len() - 8)
        } else {
            String::new()
        };
        return Err(Error::format(
            dir,
            "directory",
            if skipped.is_empty() {
                "the directory holds no files; a DICOM series is a directory of DICOM files"
                    .to_string()
            } else {
                format!(
                    "no DICOM image in the directory; skipped: {}{more}",
                    shown.join(", ")
                )
            },
        ));
    }
    // Group by series.
    let mut series: BTreeMap<String, (String, usize)> = BTreeMap::new();
    for im in &images {
        let uid = text(&im.obj, tags::SERIES_INSTANCE_UID).unwrap_or_default();
        let desc = text(&im.obj, tags::SERIES_DESCRIPTION).unwrap_or_default();
        series.entry(uid).or_insert((desc, 0)).1 += 1;
    }
    if series.len() > 1 {
        let list: Vec<String> = series
            .iter()
            .map(|(uid, (desc, n))| {
                let uid = if uid.is_empty() { "(none)" } else { uid };
                let desc = if desc.is_empty() {
                    "no description"
                } else {
                    desc
                };
                format!("{uid} ('{desc}', {n} files)")
            })
            .collect();
        return Err(Error::format(
            dir,
            "SeriesInstanceUID",
            format!(
                "the directory holds {} series: {}; point at a directory that holds one series",
                series.len(),
                list.join("; ")
            ),
        ));
    }
    if images.len() > 1 {
        if let Some(im) = images.iter().find(|im| im.px.frames > 1) {
            return Err(Error::format(
                &im.path,
                "NumberOfFrames",
                format!(
                    "a multi-frame file ({} frames) is mixed with {} other images in {}; \
                     read it on its own",
                    im.px.frames,
                    images.len() - 1,
                    dir.display()
                ),
            ));
        }
    }
    Ok(images)
}

// ---------------------------------------------------------------------------------
// Attributes
// ---------------------------------------------------------------------------------

fn text(obj: &InMemDicomObject, tag: Tag) -> Option<String> {
    let e = obj.element_opt(tag).ok().flatten()?;
    let s = e.to_str().ok()?;
    Some(s.trim_end_matches(['\0', ' ']).trim().to_string())
}

fn int(obj: &InMemDicomObject, tag: Tag) -> Option<i64> {
    let e = obj.element_opt(tag).ok().flatten()?;
    e.to_int::<i64>().ok()
}

fn floats(obj: &InMemDicomObject, tag: Tag) -> Option<Vec<f64>> {
    let e = obj.element_opt(tag).ok().flatten()?;
    let v = e.to_multi_float64().ok()?;
    (!v.is_empty() && v.iter().all(|x| x.is_finite())).then_some(v)
}

/// A numeric attribute that must have `n` values when present.
fn floats_n(
    path: &Path,
    obj: &InMemDicomObject,
    tag: Tag,
    name: &str,
    n: usize,
) -> Result<Option<Vec<f64>>> {
    let Some(e) = obj.element_opt(tag).ok().flatten() else {
        return Ok(None);
    };
    if e.to_str().map(|s| s.trim().is_empty()).unwrap_or(false) {
        return Ok(None);
    }
    match floats(obj, tag) {
        Some(v) if v.len() == n => Ok(Some(v)),
        _ => Err(Error::format(
            path,
            name,
            format!(
                "expected {n} finite numbers, found '{}'",
                e.to_str().map(|s| super::snippet(&s)).unwrap_or_default()
            ),
        )),
    }
}

/// The first item of a sequence attribute.
fn first_item(obj: &InMemDicomObject, tag: Tag) -> Option<&InMemDicomObject> {
    obj.element_opt(tag).ok().flatten()?.items()?.first()
}

/// A required unsigned attribute of the pixel module.
fn required(path: &Path, obj: &InMemDicomObject, tag: Tag, name: &str) -> Result<u32> {
    let v = int(obj, tag).ok_or_else(|| {
        Error::format(
            path,
            name,
            "missing or not a number (required for an image)",
        )
    })?;
    u32::try_from(v).map_err(|_| Error::format(path, name, format!("{v} is out of range")))
}

fn pixel_format(path: &Path, obj: &InMemDicomObject) -> Result<PixelFormat> {
    let spp = int(obj, tags::SAMPLES_PER_PIXEL).unwrap_or(1);
    let photometric = text(obj, tags::PHOTOMETRIC_INTERPRETATION).unwrap_or_default();
    if spp != 1 || photometric.starts_with("PALETTE") {
        return Err(Error::format(
            path,
            if spp != 1 {
                "SamplesPerPixel"
            } else {
                "PhotometricInterpretation"
            },
            format!(
                "colour images are not supported (SamplesPerPixel = {spp}, \
                 PhotometricInterpretation = '{photometric}'); voxlab reads grayscale \
                 (MONOCHROME1/MONOCHROME2) volumes"
            ),
        ));
    }
    let rows = required(path, obj, tags::ROWS, "Rows")? as usize;
    let cols = required(path, obj, tags::COLUMNS, "Columns")? as usize;
    let bits_allocated = required(path, obj, tags::BITS_ALLOCATED, "BitsAllocated")?;
    if bits_allocated == 1 {
        return Err(Error::format(
            path,
            "BitsAllocated",
            "1-bit (bitmap) pixel data is not supported: voxlab reads 8, 16 or 32 bits \
             per sample (a 1-bit image is a mask or an overlay, not a volume of values)",
        ));
    }
    if ![8, 16, 32].contains(&bits_allocated) {
        return Err(Error::format(
            path,
            "BitsAllocated",
            format!("{bits_allocated} bits per sample are not supported (8, 16 or 32)"),
        ));
    }
    let bits_stored = int(obj, tags::BITS_STORED).unwrap_or(bits_allocated as i64);
    if !(1..=bits_allocated as i64).contains(&bits_stored) {
        return Err(Error::format(
            path,
            "BitsStored",
            format!("{bits_stored} with BitsAllocated {bits_allocated}"),
        ));
    }
    let bits_stored = bits_stored as u32;
    let high_bit = int(obj, tags::HIGH_BIT).unwrap_or(bits_stored as i64 - 1);
    if high_bit < bits_stored as i64 - 1 || high_bit >= bits_allocated as i64 {
        return Err(Error::format(
            path,
            "HighBit",
            format!("{high_bit} with BitsStored {bits_stored} and BitsAllocated {bits_allocated}"),
        ));
    }
    let signed = match int(obj, tags::PIXEL_REPRESENTATION).unwrap_or(0) {
        0 => false,
        1 => true,
        v => {
            return Err(Error::format(
                path,
                "PixelRepresentation",
                format!("{v} (must be 0, unsigned, or 1, signed)"),
            ))
        }
    };
    let frames = match text(obj, tags::NUMBER_OF_FRAMES) {
        None => 1,
        Some(s) if s.is_empty() => 1,
        Some(s) => s.parse::<usize>().ok().filter(|&n| n >= 1).ok_or_else(|| {
            Error::format(
                path,
                "NumberOfFrames",
                format!("'{}' is not a positive integer", super::snippet(&s)),
            )
        })?,
    };
    if rows == 0 || cols == 0 {
        return Err(Error::format(
            path,
            "Rows",
            format!("empty image ({rows} x {cols})"),
        ));
    }
    Ok(PixelFormat {
        rows,
        cols,
        frames,
        bits_allocated,
        bits_stored,
        high_bit: high_bit as u32,
        signed,
    })
}

// ---------------------------------------------------------------------------------
// Slices and geometry
// ---------------------------------------------------------------------------------

/// One z slice: a frame of an image, with its position and value rescaling.
struct Slice {
    image: usize,
    frame: usize,
    /// Names the slice in messages: a file name, or "file, frame n".
    label: String,
    position: Option<DVec3>,
    slope: f64,
    intercept: f64,
    /// What orders the slices at one position in time, by [`TIME_KEYS`].
    time: [Option<f64>; 5],
}

/// The attributes that order a time series' slices at one position, the first that
/// every slice has and that tells them apart winning: TemporalPositionIdentifier
/// (0020,0100), a multi-frame image's TemporalPositionIndex (0020,9128), TriggerTime
/// (0018,1060), AcquisitionTime (0008,0032), and InstanceNumber (0020,0013) — or, in a
/// multi-frame image, the frame's place in the file.
const TIME_KEYS: [&str; 5] = [
    "TemporalPositionIdentifier",
    "TemporalPositionIndex",
    "TriggerTime",
    "AcquisitionTime",
    "InstanceNumber",
];

/// The time keys ([`TIME_KEYS`]) of a file's image.
fn time_keys(obj: &InMemDicomObject) -> [Option<f64>; 5] {
    let number = |tag| {
        text(obj, tag).and_then(|t| t.trim().trim_end_matches('\0').trim().parse::<f64>().ok())
    };
    [
        number(tags::TEMPORAL_POSITION_IDENTIFIER),
        None,
        number(tags::TRIGGER_TIME),
        number(tags::ACQUISITION_TIME),
        number(tags::INSTANCE_NUMBER),
    ]
}

/// The slices, sorted and checked, of one 3-D volume, and how many the series holds.
struct Assembled {
    slices: Vec<Slice>,
    dims: [usize; 3],
    affine: DMat4,
    frames: usize,
}

/// A series that holds the same positions at several times: the slices of time point
/// `frame` and the count, else all the slices and 1. Positions are grouped along the
/// normal (within 0.001 mm); every position must hold the same number `t ≥ 2` of
/// slices, told apart by one of [`TIME_KEYS`] — otherwise the slices are left as they
/// are, and [`sort_and_check`] names the duplicates.
fn time_point(
    mut slices: Vec<Slice>,
    normal: DVec3,
    where_: &Path,
    frame: Option<usize>,
) -> Result<(Vec<Slice>, usize)> {
    let proj = |s: &Slice| s.position.unwrap_or_default().dot(normal);
    slices.sort_by(|a, b| proj(a).total_cmp(&proj(b)));
    let mut groups: Vec<Vec<Slice>> = Vec::new();
    for s in slices {
        match groups.last_mut() {
            Some(g) if proj(&s) - proj(&g[0]) < 1e-3 => g.push(s),
            _ => groups.push(vec![s]),
        }
    }
    let t = groups[0].len();
    let distinct = |k: usize| {
        groups.iter().all(|g| {
            let mut v: Vec<f64> = g.iter().filter_map(|s| s.time[k]).collect();
            v.sort_by(f64::total_cmp);
            v.len() == g.len() && v.windows(2).all(|w| w[0] != w[1])
        })
    };
    let key = (0..TIME_KEYS.len()).find(|&k| distinct(k));
    let (Some(key), true) = (key, t >= 2 && groups.iter().all(|g| g.len() == t)) else {
        super::choose_frame(where_, "frame", 1, "", frame)?;
        return Ok((groups.into_iter().flatten().collect(), 1));
    };
    let axes = format!(
        "{t} time points at each of {} positions, ordered by {}",
        groups.len(),
        TIME_KEYS[key]
    );
    let k = super::choose_frame(where_, TIME_KEYS[key], t, &axes, frame)?;
    let picked = groups
        .into_iter()
        .map(|mut g| {
            g.sort_by(|a, b| {
                a.time[key]
                    .unwrap_or(0.0)
                    .total_cmp(&b.time[key].unwrap_or(0.0))
            });
            g.swap_remove(k)
        })
        .collect();
    Ok((picked, t))
}

/// In-plane geometry shared by all slices.
struct Plane {
    /// Unit row and column direction cosines (IOP), if given.
    orientation: Option<(DVec3, DVec3)>,
    /// PixelSpacing: (row spacing, column spacing), if given.
    spacing: Option<[f64; 2]>,
}

fn rescale(path: &Path, obj: &InMemDicomObject) -> Result<Option<(f64, f64)>> {
    let slope = floats_n(path, obj, tags::RESCALE_SLOPE, "RescaleSlope", 1)?;
    let intercept = floats_n(path, obj, tags::RESCALE_INTERCEPT, "RescaleIntercept", 1)?;
    if slope.is_none() && intercept.is_none() {
        return Ok(None);
    }
    let slope = slope.map_or(1.0, |v| v[0]);
    if slope == 0.0 {
        return Err(Error::format(path, "RescaleSlope", "must not be 0"));
    }
    Ok(Some((slope, intercept.map_or(0.0, |v| v[0]))))
}

/// DoseGridScaling (3004,000E) of an RT dose: the dose in Gy is the stored value times it.
fn dose_scaling(path: &Path, obj: &InMemDicomObject) -> Result<Option<f64>> {
    let Some(v) = floats_n(path, obj, tags::DOSE_GRID_SCALING, "DoseGridScaling", 1)? else {
        return Ok(None);
    };
    if v[0] > 0.0 {
        Ok(Some(v[0]))
    } else {
        Err(Error::format(
            path,
            "DoseGridScaling",
            format!("{} must be positive", v[0]),
        ))
    }
}

/// A rescale (slope, intercept), then a dose grid scaling, as one (slope, intercept).
fn with_dose(rescale: Option<(f64, f64)>, dose: Option<f64>) -> (f64, f64) {
    let (slope, intercept) = rescale.unwrap_or((1.0, 0.0));
    let d = dose.unwrap_or(1.0);
    (slope * d, intercept * d)
}

fn plane_of(path: &Path, obj: &InMemDicomObject) -> Result<Plane> {
    let iop = floats_n(
        path,
        obj,
        tags::IMAGE_ORIENTATION_PATIENT,
        "ImageOrientationPatient",
        6,
    )?;
    let orientation = match iop {
        None => None,
        Some(v) => {
            let r = DVec3::new(v[0], v[1], v[2]);
            let c = DVec3::new(v[3], v[4], v[5]);
            let (rl, cl) = (r.length(), c.length());
            if (rl - 1.0).abs() > 0.01 || (cl - 1.0).abs() > 0.01 || r.dot(c).abs() > 0.01 {
                return Err(Error::format(
                    path,
                    "ImageOrientationPatient",
                    format!("{v:?} are not two orthogonal unit vectors"),
                ));
            }
            Some((r / rl, c / cl))
        }
    };
    let spacing = floats_n(path, obj, tags::PIXEL_SPACING, "PixelSpacing", 2)?;
    if let Some(s) = &spacing {
        if !s.iter().all(|&x| x > 0.0) {
            return Err(Error::format(
                path,
                "PixelSpacing",
                format!("{s:?} must be positive"),
            ));
        }
    }
    Ok(Plane {
        orientation,
        spacing: spacing.map(|s| [s[0], s[1]]),
    })
}

fn position(path: &Path, obj: &InMemDicomObject) -> Result<Option<DVec3>> {
    Ok(floats_n(
        path,
        obj,
        tags::IMAGE_POSITION_PATIENT,
        "ImagePositionPatient",
        3,
    )?
    .map(|v| DVec3::new(v[0], v[1], v[2])))
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= SAME_TOL * a.abs().max(b.abs()).max(1.0)
}

fn same_plane(a: &Plane, b: &Plane) -> std::result::Result<(), &'static str> {
    match (a.orientation, b.orientation) {
        (None, None) => {}
        (Some((r1, c1)), Some((r2, c2))) => {
            if (r1 - r2).abs().max_element() > SAME_TOL || (c1 - c2).abs().max_element() > SAME_TOL
            {
                return Err("ImageOrientationPatient");
            }
        }
        _ => return Err("ImageOrientationPatient"),
    }
    match (a.spacing, b.spacing) {
        (None, None) => Ok(()),
        (Some(s), Some(t)) if close(s[0], t[0]) && close(s[1], t[1]) => Ok(()),
        _ => Err("PixelSpacing"),
    }
}

/// Turns the images into slices and geometry, and decodes the voxels.
fn assemble(images: &[Image], frame: Option<usize>) -> Result<Assembled> {
    let first = &images[0];
    // Refuse absurd sizes (NumberOfFrames can claim anything) before building slices.
    let frames = images
        .iter()
        .fold(0usize, |acc, im| acc.saturating_add(im.px.frames));
    check_dims([first.px.cols, first.px.rows, frames]).map_err(|e| match e {
        Error::TooLarge { message, .. } => {
            Error::too_large(format!("DICOM volume {}", first.path.display()), message)
        }
        e => e,
    })?;
    let plane;
    let mut slices = Vec::new();
    let mut fallback_dz = None;
    if images.len() == 1 && first.px.frames > 1 {
        // A multi-frame image: functional groups first, top-level attributes after.
        let path = &first.path;
        let obj: &InMemDicomObject = &first.obj;
        let shared = first_item(obj, tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE);
        let per_frame: &[InMemDicomObject] = obj
            .element_opt(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
            .ok()
            .flatten()
            .and_then(|e| e.items())
            .unwrap_or(&[]);
        // The item of a functional group sequence for a frame: its own, else the shared.
        let group = |frame: usize, seq: Tag| -> Option<&InMemDicomObject> {
            per_frame
                .get(frame)
                .and_then(|g| first_item(g, seq))
                .or_else(|| shared.and_then(|g| first_item(g, seq)))
        };
        // Orientation and spacing: frame 0's groups, the shared groups, the top level.
        let orient_src = group(0, tags::PLANE_ORIENTATION_SEQUENCE).unwrap_or(obj);
        let measures = group(0, tags::PIXEL_MEASURES_SEQUENCE);
        let mut p = plane_of(path, orient_src)?;
        if p.orientation.is_none() {
            p.orientation = plane_of(path, obj)?.orientation;
        }
        if let Some(m) = measures {
            if let Some(s) = plane_of(path, m)?.spacing {
                p.spacing = Some(s);
            }
        }
        if p.spacing.is_none() {
            p.spacing = plane_of(path, obj)?.spacing;
        }
        plane = p;
        let thickness = |o: &InMemDicomObject| {
            floats(o, tags::SPACING_BETWEEN_SLICES)
                .or_else(|| floats(o, tags::SLICE_THICKNESS))
                .and_then(|v| v.first().copied())
                .filter(|&x| x > 0.0)
        };
        fallback_dz = measures.and_then(thickness).or_else(|| thickness(obj));
        let top_rescale = rescale(path, obj)?;
        let dose = dose_scaling(path, obj)?;
        // An RT dose grid places its frames by GridFrameOffsetVector (module docs).
        let grid = floats_n(
            path,
            obj,
            tags::GRID_FRAME_OFFSET_VECTOR,
            "GridFrameOffsetVector",
            first.px.frames,
        )?;
        let grid_origin = match (&grid, plane.orientation) {
            (Some(_), Some((r, c))) => position(path, obj)?.map(|p| (p, r.cross(c))),
            _ => None,
        };
        let name = first.name();
        for f in 0..first.px.frames {
            let pos = match per_frame
                .get(f)
                .and_then(|g| first_item(g, tags::PLANE_POSITION_SEQUENCE))
            {
                Some(g) => position(path, g)?,
                None => None,
            };
            let pos = match (pos, &grid, grid_origin) {
                (None, Some(g), Some((p0, normal))) => Some(p0 + normal * (g[f] - g[0])),
                (pos, ..) => pos,
            };
            let rs = match group(f, tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE) {
                Some(g) => rescale(path, g)?.or(top_rescale),
                None => top_rescale,
            };
            let (slope, intercept) = with_dose(rs, dose);
            // Every frame must share frame 1's orientation and pixel spacing.
            for seq in [
                tags::PLANE_ORIENTATION_SEQUENCE,
                tags::PIXEL_MEASURES_SEQUENCE,
            ] {
                if let Some(g) = per_frame.get(f).and_then(|g| first_item(g, seq)) {
                    let mut own = plane_of(path, g)?;
                    own.orientation = own.orientation.or(plane.orientation);
                    own.spacing = own.spacing.or(plane.spacing);
                    if let Err(field) = same_plane(&own, &plane) {
                        return Err(Error::format(
                            path,
                            field,
                            format!(
                                "mixed sizes: frame {} has a different {field} from frame 1",
                                f + 1
                            ),
                        ));
                    }
                }
            }
            let index = per_frame
                .get(f)
                .and_then(|g| first_item(g, tags::FRAME_CONTENT_SEQUENCE))
                .and_then(|g| int(g, tags::TEMPORAL_POSITION_INDEX))
                .map(|i| i as f64);
            slices.push(Slice {
                image: 0,
                frame: f,
                label: format!("{name}, frame {}", f + 1),
                position: pos,
                slope,
                intercept,
                time: [None, index, None, None, Some(f as f64)],
            });
        }
    } else {
        plane = plane_of(&first.path, &first.obj)?;
        for (i, im) in images.iter().enumerate() {
            if im.px.rows != first.px.rows || im.px.cols != first.px.cols {
                return Err(Error::format(
                    &im.path,
                    "Rows/Columns",
                    format!(
                        "mixed sizes in the series: {} is {}x{} (columns x rows) but {} is {}x{}",
                        im.name(),
                        im.px.cols,
                        im.px.rows,
                        first.name(),
                        first.px.cols,
                        first.px.rows
                    ),
                ));
            }
            if im.px != first.px {
                return Err(Error::format(
                    &im.path,
                    "BitsAllocated",
                    format!(
                        "mixed sample types in the series: {} has {:?}, {} has {:?}",
                        im.name(),
                        im.px,
                        first.name(),
                        first.px
                    ),
                ));
            }
            let p = plane_of(&im.path, &im.obj)?;
            if let Err(field) = same_plane(&p, &plane) {
                return Err(Error::format(
                    &im.path,
                    field,
                    format!(
                        "mixed sizes in the series: {field} of {} differs from {}",
                        im.name(),
                        first.name()
                    ),
                ));
            }
            let (slope, intercept) = with_dose(
                rescale(&im.path, &im.obj)?,
                dose_scaling(&im.path, &im.obj)?,
            );
            slices.push(Slice {
                image: i,
                frame: 0,
                label: im.name(),
                position: position(&im.path, &im.obj)?,
                slope,
                intercept,
                time: time_keys(&im.obj),
            });
        }
        if images.len() == 1 {
            let t = |tag| {
                floats(&first.obj, tag)
                    .and_then(|v| v.first().copied())
                    .filter(|&x| x > 0.0)
            };
            fallback_dz = t(tags::SPACING_BETWEEN_SLICES).or_else(|| t(tags::SLICE_THICKNESS));
        }
    }

    let where_ = if images.len() == 1 {
        first.path.clone()
    } else {
        first
            .path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default()
    };
    let (row, col) = plane.orientation.unwrap_or((DVec3::X, DVec3::Y));
    let [row_spacing, col_spacing] = plane.spacing.unwrap_or([1.0, 1.0]);
    let normal = row.cross(col);
    let all_positioned = plane.orientation.is_some() && slices.iter().all(|s| s.position.is_some());
    let (mut slices, frames) = if all_positioned && slices.len() > 1 {
        time_point(slices, normal, &where_, frame)?
    } else {
        super::choose_frame(&where_, "frame", 1, "", frame)?;
        (slices, 1)
    };
    let n = slices.len();

    let (origin, dz_vec) = if n > 1 && all_positioned {
        sort_and_check(&mut slices, normal, &where_)?
    } else if n > 1 && slices.iter().any(|s| s.position.is_some()) && images.len() > 1 {
        let missing = slices
            .iter()
            .find(|s| s.position.is_none())
            .map(|s| s.label.clone());
        return Err(Error::format(
            &where_,
            "ImagePositionPatient",
            format!(
                "{} has no ImagePositionPatient (or ImageOrientationPatient is missing); \
                 slices cannot be ordered",
                missing.unwrap_or_else(|| first.name())
            ),
        ));
    } else if n > 1 && images.len() > 1 {
        return Err(Error::format(
            &where_,
            "ImagePositionPatient",
            "the images have no ImagePositionPatient/ImageOrientationPatient; slices cannot be ordered",
        ));
    } else {
        let origin = slices[0].position.unwrap_or(DVec3::ZERO);
        (origin, normal * fallback_dz.unwrap_or(1.0))
    };

    let dims = [first.px.cols, first.px.rows, n];
    check_dims(dims)?;
    let affine = DMat4::from_cols(
        (row * col_spacing).extend(0.0),
        (col * row_spacing).extend(0.0),
        dz_vec.extend(0.0),
        DVec4::new(origin.x, origin.y, origin.z, 1.0),
    );
    Ok(Assembled {
        slices,
        dims,
        affine,
        frames,
    })
}

/// Sorts slices along the normal and checks the steps; returns the origin and the
/// z step vector.
fn sort_and_check(slices: &mut [Slice], normal: DVec3, where_: &Path) -> Result<(DVec3, DVec3)> {
    let proj = |s: &Slice| s.position.unwrap_or_default().dot(normal);
    slices.sort_by(|a, b| proj(a).total_cmp(&proj(b)));
    let steps: Vec<f64> = slices
        .windows(2)
        .map(|w| proj(&w[1]) - proj(&w[0]))
        .collect();
    for (i, &d) in steps.iter().enumerate() {
        if d < 1e-3 {
            return Err(Error::format(
                where_,
                "ImagePositionPatient",
                format!(
                    "duplicate slice position: {} and {} are both at {:.4} mm along the \
                     slice normal (the same slice twice, or two acquisitions in one series)",
                    slices[i].label,
                    slices[i + 1].label,
                    proj(&slices[i])
                ),
            ));
        }
    }
    let mut sorted = steps.clone();
    sorted.sort_by(f64::total_cmp);
    let d = sorted[sorted.len() / 2];
    let tol = (STEP_TOL * d).max(STEP_TOL_MM);
    for (i, &s) in steps.iter().enumerate() {
        if (s - d).abs() <= tol {
            continue;
        }
        let k = (s / d).round();
        let (a, b) = (&slices[i].label, &slices[i + 1].label);
        if k >= 2.0 && (s - k * d).abs() <= 0.1 * d {
            return Err(Error::format(
                where_,
                "ImagePositionPatient",
                format!(
                    "missing slice(s): the gap between {a} and {b} is {s:.4} mm, about {k} \
                     times the typical step of {d:.4} mm ({} slice(s) missing)",
                    k - 1.0
                ),
            ));
        }
        return Err(Error::format(
            where_,
            "ImagePositionPatient",
            format!(
                "inconsistent slice spacing: the step between {a} and {b} is {s:.4} mm, \
                 the typical step is {d:.4} mm (tolerance {tol:.4} mm)"
            ),
        ));
    }
    // The spacing is the mean step, so that rounding in single positions does not
    // accumulate along the stack.
    let n = slices.len();
    let spacing = (proj(&slices[n - 1]) - proj(&slices[0])) / (n - 1) as f64;
    let origin = slices[0].position.unwrap_or_default();
    let step = normal * spacing;
    for (k, s) in slices.iter().enumerate() {
        let off = s.position.unwrap_or_default() - origin;
        let sideways = (off - normal * off.dot(normal)).length();
        if sideways > SHEAR_TOL * spacing * k as f64 + STEP_TOL_MM {
            return Err(Error::format(
                where_,
                "ImagePositionPatient",
                format!(
                    "the slices are sheared: {} lies {sideways:.3} mm sideways of the slice \
                     normal through the first slice (a tilted gantry?); sheared stacks are \
                     not supported",
                    s.label,
                ),
            ));
        }
    }
    Ok((origin, step))
}

// ---------------------------------------------------------------------------------
// Pixel values
// ---------------------------------------------------------------------------------

/// The pixel data of an image as little-endian bytes.
fn pixel_bytes(im: &Image) -> Result<std::borrow::Cow<'_, [u8]>> {
    use dicom_object::mem::InMemElement;
    if let Some(raw) = &im.raw {
        return Ok(std::borrow::Cow::Borrowed(raw));
    }
    let e: &InMemElement = im
        .obj
        .element(tags::PIXEL_DATA)
        .map_err(|_| Error::format(&im.path, "PixelData", "missing"))?;
    let dicom_core_value = e.value();
    if let (Some(fragments), Some(offsets)) = (
        dicom_core_value.fragments(),
        dicom_core_value.offset_table(),
    ) {
        return encapsulated_bytes(im, offsets, fragments).map(std::borrow::Cow::Owned);
    }
    let prim = dicom_core_value
        .primitive()
        .ok_or_else(|| Error::format(&im.path, "PixelData", "neither native nor encapsulated"))?;
    if let Some(codec) = Codec::of(im.obj.meta().transfer_syntax()) {
        return Err(Error::format(
            &im.path,
            "PixelData",
            format!(
                "the transfer syntax is {} but the pixel data is not encapsulated \
                 (no fragments)",
                codec.name()
            ),
        ));
    }
    if cfg!(target_endian = "big") {
        // Values other than bytes are held in the machine's order.
        return Err(Error::format(
            &im.path,
            "PixelData",
            "reading DICOM on a big-endian machine is not supported",
        ));
    }
    let big = im.obj.meta().transfer_syntax() == "1.2.840.10008.1.2.2";
    let size = (im.px.bits_allocated / 8) as usize;
    use dicom_core::PrimitiveValue as P;
    Ok(match prim {
        // Bytes in the file's order (VR OB): samples of a big-endian file are turned
        // around whole.
        P::U8(_) if big && size > 1 => {
            let mut b = prim.to_bytes().into_owned();
            b.chunks_exact_mut(size).for_each(|w| w.reverse());
            std::borrow::Cow::Owned(b)
        }
        // 16-bit words already in the machine's order (VR OW): a 32-bit sample of a
        // big-endian file holds its high word first, so the two words are swapped.
        P::U16(_) | P::I16(_) if big && size == 4 => {
            let mut b = prim.to_bytes().into_owned();
            b.chunks_exact_mut(4).for_each(|w| {
                let (hi, lo) = w.split_at_mut(2);
                hi.swap_with_slice(lo);
            });
            std::borrow::Cow::Owned(b)
        }
        // Values of the sample's own width in the machine's order, or bytes of 8-bit
        // samples: already little-endian samples.
        _ => prim.to_bytes(),
    })
}

/// Every frame of encapsulated (compressed) pixel data, decoded and joined: the bytes
/// native pixel data would hold. [`assemble`] has checked the volume's size before
/// this allocates it.
fn encapsulated_bytes(im: &Image, offsets: &[u32], fragments: &[Vec<u8>]) -> Result<Vec<u8>> {
    let uid = im.obj.meta().transfer_syntax();
    let codec = Codec::of(uid).ok_or_else(|| {
        Error::format(
            &im.path,
            "TransferSyntaxUID",
            format!(
                "the pixel data is encapsulated (compressed) but transfer syntax {} is \
                 not one voxlab decodes",
                super::snippet(uid)
            ),
        )
    })?;
    let px = &im.px;
    let frames = encapsulated::split_frames(&im.path, codec, offsets, fragments, px.frames)?;
    let frame_bytes = px.rows * px.cols * (px.bits_allocated / 8) as usize;
    let mut out = Vec::with_capacity(frame_bytes * px.frames);
    for (k, data) in frames.iter().enumerate() {
        out.extend(encapsulated::decode_frame(&im.path, codec, data, px, k)?);
    }
    Ok(out)
}

/// Decodes all slices; chooses the voxel type from the values (module docs).
fn decode(images: &[Image], slices: &[Slice]) -> Result<Samples> {
    let px = images[0].px;
    let per_frame = px.rows * px.cols;
    let bytes_per = (px.bits_allocated / 8) as usize;
    let frame_bytes = per_frame * bytes_per;
    let shift = px.high_bit + 1 - px.bits_stored;
    let mask: u32 = if px.bits_stored == 32 {
        u32::MAX
    } else {
        (1u32 << px.bits_stored) - 1
    };
    let sign_bit = 1u32 << (px.bits_stored - 1);
    let value = move |word: u32| -> i64 {
        let v = (word >> shift) & mask;
        if px.signed && v & sign_bit != 0 {
            v as i64 - (mask as i64 + 1)
        } else {
            v as i64
        }
    };
    let word = move |b: &[u8]| -> u32 {
        match b.len() {
            1 => b[0] as u32,
            2 => u16::from_le_bytes([b[0], b[1]]) as u32,
            _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        }
    };
    // Check lengths and collect the bytes of each image once.
    let mut data = Vec::with_capacity(images.len());
    for im in images {
        let b = pixel_bytes(im)?;
        let need = frame_bytes as u64 * im.px.frames as u64;
        if (b.len() as u64) < need {
            return Err(super::too_short(&im.path, need, b.len() as u64));
        }
        data.push(b);
    }
    let frame = |s: &Slice| &data[s.image][s.frame * frame_bytes..(s.frame + 1) * frame_bytes];

    // Integers when every rescale is the identity up to an integral shift.
    let integral = slices
        .iter()
        .all(|s| s.slope == 1.0 && s.intercept.fract() == 0.0 && s.intercept.abs() < 1e9);
    let n = per_frame * slices.len();
    if integral {
        let (mut lo, mut hi) = (i64::MAX, i64::MIN);
        for s in slices {
            let b = s.intercept as i64;
            for c in frame(s).chunks_exact(bytes_per) {
                let v = value(word(c)) + b;
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        let shifted_negative = px.signed || slices.iter().any(|s| s.intercept < 0.0);
        let fits_u16 = lo >= 0 && hi <= u16::MAX as i64;
        let fits_i16 = lo >= i16::MIN as i64 && hi <= i16::MAX as i64;
        let all = |f: &mut dyn FnMut(i64)| {
            for s in slices {
                let b = s.intercept as i64;
                for c in frame(s).chunks_exact(bytes_per) {
                    f(value(word(c)) + b);
                }
            }
        };
        if px.bits_allocated == 8 && !px.signed && slices.iter().all(|s| s.intercept == 0.0) {
            let mut v = Vec::with_capacity(n);
            all(&mut |x| v.push(x as u8));
            return Ok(Samples::U8(v));
        }
        if fits_i16 && (shifted_negative || !fits_u16) {
            let mut v = Vec::with_capacity(n);
            all(&mut |x| v.push(x as i16));
            return Ok(Samples::I16(v));
        }
        if fits_u16 {
            let mut v = Vec::with_capacity(n);
            all(&mut |x| v.push(x as u16));
            return Ok(Samples::U16(v));
        }
    }
    let mut v = Vec::with_capacity(n);
    for s in slices {
        for c in frame(s).chunks_exact(bytes_per) {
            v.push((value(word(c)) as f64 * s.slope + s.intercept) as f32);
        }
    }
    Ok(Samples::F32(v))
}
