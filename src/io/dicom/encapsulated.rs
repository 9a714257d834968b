//! Compressed (encapsulated) DICOM pixel data: which fragments hold which frame
//! (PS3.5 A.4), and each frame decoded to the bytes an uncompressed file would hold —
//! little-endian samples of BitsAllocated bits, the stored bit pattern — so that the
//! rest of the reader (masking to BitsStored, sign extension, rescaling) is shared.
//!
//! | transfer syntax | UID | decoder |
//! |---|---|---|
//! | RLE Lossless | 1.2.840.10008.1.2.5 | here ([`rle`], PS3.5 Annex G) |
//! | JPEG Baseline (process 1), Extended (processes 2 & 4), Lossless (process 14, and its selection value 1) | …1.2.4.50, .51, .57, .70 | `jpeg-decoder` (8-bit DCT, 2–16-bit lossless) |
//! | JPEG-LS Lossless, Near-Lossless | …1.2.4.80, .81 | `pure_jpegls` |
//! | JPEG 2000 (lossless only, and lossy), and Part 2 with one component | …1.2.4.90, .91, .92, .93 | `jpeg2k` on `openjp2`, the Rust port of OpenJPEG |
//!
//! Before a decoder runs, the frame's own header (JPEG SOF, JPEG-LS SOF55 and its
//! parameters, JPEG 2000 SIZ) is read here and must agree with the DICOM attributes —
//! one component, Columns × Rows, a precision that fits BitsAllocated — so that no
//! decoder allocates what a corrupt stream merely claims, and so that each refusal names
//! the field. A decoder's own failure is an error naming the file and the frame; a panic
//! inside a decoder (on input it did not foresee) is caught and reported the same way,
//! as a last resort.

use super::PixelFormat;
use crate::error::{Error, Result};
use std::borrow::Cow;
use std::path::Path;

/// The codec of a compressed transfer syntax voxlab decodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Codec {
    Rle,
    Jpeg,
    JpegLs,
    Jpeg2000,
}

impl Codec {
    /// The codec of a transfer syntax UID, when voxlab decodes it.
    pub(super) fn of(uid: &str) -> Option<Codec> {
        Some(match uid {
            "1.2.840.10008.1.2.5" => Codec::Rle,
            "1.2.840.10008.1.2.4.50"
            | "1.2.840.10008.1.2.4.51"
            | "1.2.840.10008.1.2.4.57"
            | "1.2.840.10008.1.2.4.70" => Codec::Jpeg,
            "1.2.840.10008.1.2.4.80" | "1.2.840.10008.1.2.4.81" => Codec::JpegLs,
            "1.2.840.10008.1.2.4.90"
            | "1.2.840.10008.1.2.4.91"
            | "1.2.840.10008.1.2.4.92"
            | "1.2.840.10008.1.2.4.93" => Codec::Jpeg2000,
            _ => return None,
        })
    }

    pub(super) fn name(self) -> &'static str {
        match self {
            Codec::Rle => "RLE",
            Codec::Jpeg => "JPEG",
            Codec::JpegLs => "JPEG-LS",
            Codec::Jpeg2000 => "JPEG 2000",
        }
    }

    /// Whether a fragment starts a codestream (JPEG and JPEG-LS SOI, JPEG 2000 SOC or
    /// a JP2 signature box): how frames are told apart without an offset table.
    fn starts_frame(self, b: &[u8]) -> bool {
        match self {
            Codec::Rle => false,
            Codec::Jpeg | Codec::JpegLs => b.starts_with(&[0xFF, 0xD8]),
            Codec::Jpeg2000 => b.starts_with(&[0xFF, 0x4F]) || b.starts_with(&JP2_SIGNATURE),
        }
    }
}

const JP2_SIGNATURE: [u8; 8] = [0, 0, 0, 12, b'j', b'P', b' ', b' '];

/// The compressed bytes of each of `frames` frames, from the fragments of the
/// encapsulated pixel data and its basic offset table (PS3.5 A.4):
/// - with an offset table, frame k starts at the fragment at offset\[k\] (bytes from the
///   first fragment's item tag; each fragment counts its 8-byte item header);
/// - without one, a single frame is every fragment joined; as many fragments as frames
///   are one frame each; otherwise a fragment that starts a codestream starts a frame.
pub(super) fn split_frames<'a>(
    path: &Path,
    codec: Codec,
    offsets: &[u32],
    fragments: &'a [Vec<u8>],
    frames: usize,
) -> Result<Vec<Cow<'a, [u8]>>> {
    let err = |field: &str, m: String| Error::format(path, field, m);
    let join = |part: &'a [Vec<u8>]| -> Cow<'a, [u8]> {
        match part {
            [one] => Cow::Borrowed(one.as_slice()),
            _ => Cow::Owned(part.concat()),
        }
    };
    if fragments.is_empty() {
        return Err(err(
            "PixelData",
            "the encapsulated pixel data holds no fragment".into(),
        ));
    }
    let starts: Vec<usize> = if !offsets.is_empty() {
        if offsets.len() != frames {
            return Err(err(
                "PixelData",
                format!(
                    "the basic offset table lists {} frames, NumberOfFrames says {frames}",
                    offsets.len()
                ),
            ));
        }
        // Where each fragment's item starts, counted as the offsets are.
        let mut at = Vec::with_capacity(fragments.len());
        let mut pos = 0u64;
        for f in fragments {
            at.push(pos);
            pos += 8 + f.len() as u64;
        }
        let mut starts = Vec::with_capacity(frames);
        for (k, &o) in offsets.iter().enumerate() {
            let i = at.binary_search(&u64::from(o)).map_err(|_| {
                err(
                    "PixelData",
                    format!(
                        "the basic offset table puts frame {} at byte {o}, which is not \
                         the start of a fragment",
                        k + 1
                    ),
                )
            })?;
            if starts.last().is_some_and(|&s| i <= s) || (k == 0 && i != 0) {
                return Err(err(
                    "PixelData",
                    format!(
                        "the basic offset table is not increasing from 0 (frame {} at byte {o})",
                        k + 1
                    ),
                ));
            }
            starts.push(i);
        }
        starts
    } else if frames == 1 {
        vec![0]
    } else if fragments.len() == frames {
        (0..frames).collect()
    } else {
        let starts: Vec<usize> = (0..fragments.len())
            .filter(|&i| i == 0 || codec.starts_frame(&fragments[i]))
            .collect();
        if starts.len() != frames {
            return Err(err(
                "PixelData",
                format!(
                    "{} fragments for {frames} frames, without a basic offset table, and \
                     {} of them start a {} codestream: which fragments belong to which \
                     frame cannot be told",
                    fragments.len(),
                    starts.len(),
                    codec.name()
                ),
            ));
        }
        starts
    };
    Ok((0..frames)
        .map(|k| {
            let end = starts.get(k + 1).copied().unwrap_or(fragments.len());
            join(&fragments[starts[k]..end])
        })
        .collect())
}

/// Decodes frame `k` (for messages) of `codec` to little-endian samples of
/// `px.bits_allocated` bits: `px.rows × px.cols` of them.
pub(super) fn decode_frame(
    path: &Path,
    codec: Codec,
    data: &[u8],
    px: &PixelFormat,
    k: usize,
) -> Result<Vec<u8>> {
    let what = format!("{} frame {}", codec.name(), k + 1);
    let err = |field: &str, m: String| Error::format(path, field, format!("{what}: {m}"));
    // A decoder's panic is the last resort: the headers are checked first.
    let run = std::panic::catch_unwind(|| match codec {
        Codec::Rle => rle(data, px).map_err(|m| err("PixelData", m)),
        Codec::Jpeg => jpeg(data, px, &err),
        Codec::JpegLs => jpeg_ls(data, px, &err),
        Codec::Jpeg2000 => jpeg_2000(data, px, &err),
    });
    let out = run.unwrap_or_else(|_| {
        Err(err(
            "PixelData",
            "the decoder failed on this data (corrupt compressed data)".into(),
        ))
    })?;
    let want = px.rows * px.cols * (px.bits_allocated / 8) as usize;
    if out.len() != want {
        return Err(err(
            "PixelData",
            format!("decoded to {} bytes, expected {want}", out.len()),
        ));
    }
    Ok(out)
}

/// Samples (each below 2^32) as little-endian words of `bytes` bytes.
fn widen(values: impl Iterator<Item = u32>, n: usize, bytes: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(n * bytes);
    for v in values {
        out.extend_from_slice(&v.to_le_bytes()[..bytes]);
    }
    out
}

// ---------------------------------------------------------------------------------
// RLE Lossless (PS3.5 Annex G)
// ---------------------------------------------------------------------------------

/// RLE Lossless: a 64-byte header (the number of segments, then up to 15 segment
/// offsets), then one PackBits-coded segment per byte of a sample, most significant
/// byte first. A run past the end of its segment's plane is cut off; a segment that
/// ends before its plane is full is an error.
fn rle(data: &[u8], px: &PixelFormat) -> std::result::Result<Vec<u8>, String> {
    let bytes = (px.bits_allocated / 8) as usize;
    let n = px.rows * px.cols;
    if data.len() < 64 {
        return Err(format!(
            "the RLE header needs 64 bytes, the frame holds {}",
            data.len()
        ));
    }
    let word = |i: usize| u32::from_le_bytes([data[i], data[i + 1], data[i + 2], data[i + 3]]);
    let segments = word(0) as usize;
    if segments != bytes {
        return Err(format!(
            "the RLE header lists {segments} segments; {}-bit grayscale samples need {bytes}",
            px.bits_allocated
        ));
    }
    let offsets: Vec<usize> = (0..segments).map(|s| word(4 + 4 * s) as usize).collect();
    for s in 0..segments {
        let end = offsets.get(s + 1).copied().unwrap_or(data.len());
        if (s == 0 && offsets[0] != 64) || offsets[s] > end || end > data.len() {
            return Err(format!(
                "RLE segment offsets {offsets:?} do not fit the frame's {} bytes (the first \
                 segment starts at byte 64)",
                data.len()
            ));
        }
    }
    let mut out = vec![0u8; n * bytes];
    for s in 0..segments {
        let end = offsets.get(s + 1).copied().unwrap_or(data.len());
        let seg = &data[offsets[s]..end];
        // Segment 0 holds the most significant bytes; samples are little-endian.
        let lane = bytes - 1 - s;
        let (mut i, mut p) = (0usize, 0usize);
        while p < n {
            let Some(&h) = seg.get(i) else {
                return Err(format!(
                    "RLE segment {} ends after {p} of its {n} bytes",
                    s + 1
                ));
            };
            let h = h as i8;
            i += 1;
            if h >= 0 {
                let len = h as usize + 1;
                let Some(lit) = seg.get(i..i + len) else {
                    return Err(format!(
                        "RLE segment {} ends inside a literal run after {p} of its {n} bytes",
                        s + 1
                    ));
                };
                for &b in lit.iter().take(n - p) {
                    out[p * bytes + lane] = b;
                    p += 1;
                }
                i += len;
            } else if h != -128 {
                let len = (1 - h as isize) as usize;
                let Some(&b) = seg.get(i) else {
                    return Err(format!(
                        "RLE segment {} ends inside a repeat run after {p} of its {n} bytes",
                        s + 1
                    ));
                };
                for _ in 0..len.min(n - p) {
                    out[p * bytes + lane] = b;
                    p += 1;
                }
                i += 1;
            }
        }
    }
    Ok(out)
}

// ---------------------------------------------------------------------------------
// JPEG (ITU T.81)
// ---------------------------------------------------------------------------------

/// The first frame header (SOFn) of a JPEG stream.
struct Sof {
    marker: u8,
    precision: u32,
    height: usize,
    width: usize,
    components: usize,
}

/// Reads marker segments from SOI up to the first frame header (a marker for which
/// `is_sof` holds).
fn jpeg_sof(data: &[u8], is_sof: fn(u8) -> bool) -> std::result::Result<Sof, String> {
    if !data.starts_with(&[0xFF, 0xD8]) {
        return Err("the data does not start with a JPEG SOI marker (FF D8)".into());
    }
    let mut pos = 2;
    loop {
        // Fill bytes (FF FF …) may precede a marker.
        while data.get(pos) == Some(&0xFF) && data.get(pos + 1) == Some(&0xFF) {
            pos += 1;
        }
        let (Some(&0xFF), Some(&m)) = (data.get(pos), data.get(pos + 1)) else {
            return Err(format!(
                "no JPEG frame header (SOF) before byte {pos} (a marker was expected there)"
            ));
        };
        if matches!(m, 0x01 | 0xD0..=0xD8) {
            pos += 2;
            continue;
        }
        if m == 0xDA || m == 0xD9 {
            return Err("the JPEG stream has no frame header (SOF) before its scan".into());
        }
        let len = match data.get(pos + 2..pos + 4) {
            Some(l) => u16::from_be_bytes([l[0], l[1]]) as usize,
            None => return Err("the JPEG stream ends inside a marker segment".into()),
        };
        let body = data
            .get(pos + 4..pos + 2 + len.max(2))
            .filter(|_| len >= 2)
            .ok_or_else(|| {
                format!("JPEG marker FF{m:02X} at byte {pos} claims {len} bytes past the end")
            })?;
        if is_sof(m) {
            if body.len() < 6 {
                return Err(format!("the JPEG frame header (FF{m:02X}) is too short"));
            }
            return Ok(Sof {
                marker: m,
                precision: u32::from(body[0]),
                height: u16::from_be_bytes([body[1], body[2]]) as usize,
                width: u16::from_be_bytes([body[3], body[4]]) as usize,
                components: body[5] as usize,
            });
        }
        pos += 2 + len;
    }
}

fn jpeg(data: &[u8], px: &PixelFormat, err: &dyn Fn(&str, String) -> Error) -> Result<Vec<u8>> {
    let sof = jpeg_sof(data, |m| {
        matches!(m, 0xC0..=0xCF) && !matches!(m, 0xC4 | 0xC8 | 0xCC)
    })
    .map_err(|m| err("PixelData", m))?;
    let lossless = sof.marker == 0xC3;
    let mode = match sof.marker {
        0xC0..=0xC3 => None,
        0xC5..=0xC7 => Some("hierarchical (differential) JPEG"),
        _ => Some("arithmetic-coded JPEG"),
    };
    if let Some(mode) = mode {
        return Err(err(
            "PixelData",
            format!(
                "the stream is {mode} (SOF marker FF{:02X}), which the decoder \
                 (jpeg-decoder) does not read",
                sof.marker
            ),
        ));
    }
    check_frame(
        px,
        sof.width,
        sof.height,
        sof.components,
        sof.precision,
        err,
    )?;
    if !lossless && sof.precision != 8 {
        return Err(err(
            "BitsStored",
            format!(
                "{}-bit lossy JPEG (JPEG Extended, process 4) is not supported: the \
                 decoder (jpeg-decoder) reads 8-bit DCT data only; decompress first, e.g. \
                 `dcmdjpeg in.dcm out.dcm` (DCMTK) or `gdcmconv --raw in.dcm out.dcm`",
                sof.precision
            ),
        ));
    }
    let n = px.rows * px.cols;
    let mut d = jpeg_decoder::Decoder::new(data);
    d.set_max_decoding_buffer_size(n * 2);
    let pixels = d
        .decode()
        .map_err(|e| err("PixelData", format!("corrupt JPEG data: {e}")))?;
    let bytes = (px.bits_allocated / 8) as usize;
    // The decoder gives one byte per sample for 8-bit data, else u16 samples in the
    // machine's order (lossless data of 2 to 7 bits too).
    Ok(if pixels.len() == n {
        widen(pixels.iter().map(|&b| u32::from(b)), n, bytes)
    } else if pixels.len() != 2 * n {
        return Err(err(
            "PixelData",
            format!("decoded to {} bytes for {n} samples", pixels.len()),
        ));
    } else {
        widen(
            pixels
                .chunks_exact(2)
                .map(|c| u32::from(u16::from_ne_bytes([c[0], c[1]]))),
            n,
            bytes,
        )
    })
}

/// The checks every codec's frame header must pass against the DICOM attributes.
fn check_frame(
    px: &PixelFormat,
    width: usize,
    height: usize,
    components: usize,
    precision: u32,
    err: &dyn Fn(&str, String) -> Error,
) -> Result<()> {
    if components != 1 {
        return Err(err(
            "SamplesPerPixel",
            format!("the compressed frame has {components} components; a grayscale image has 1"),
        ));
    }
    if (width, height) != (px.cols, px.rows) {
        return Err(err(
            "Rows/Columns",
            format!(
                "the compressed frame is {width} x {height} (columns x rows), the DICOM \
                 attributes say {} x {}",
                px.cols, px.rows
            ),
        ));
    }
    if precision == 0 || precision > px.bits_allocated {
        return Err(err(
            "BitsAllocated",
            format!(
                "the compressed frame holds {precision}-bit samples, which do not fit \
                 BitsAllocated {}",
                px.bits_allocated
            ),
        ));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------
// JPEG-LS (ITU T.87)
// ---------------------------------------------------------------------------------

/// JPEG-LS through `pure_jpegls`, which checks the scan parameters itself (NEAR,
/// MAXVAL, thresholds, RESET; one component, no interleaving); the frame header is read
/// here first. An end marker written with a fill byte (FF FF D9, as DCMTK pads odd
/// lengths) is read as the plain EOI the decoder expects.
fn jpeg_ls(data: &[u8], px: &PixelFormat, err: &dyn Fn(&str, String) -> Error) -> Result<Vec<u8>> {
    let sof = jpeg_sof(data, |m| m == 0xF7).map_err(|m| err("PixelData", m))?;
    check_frame(
        px,
        sof.width,
        sof.height,
        sof.components,
        sof.precision,
        err,
    )?;
    let mut end = data.len();
    while end > 0 && data[end - 1] == 0 {
        end -= 1;
    }
    let data: Cow<[u8]> = if data[..end].ends_with(&[0xFF, 0xFF, 0xD9]) {
        let mut v = data[..end].to_vec();
        v.remove(end - 3);
        Cow::Owned(v)
    } else {
        Cow::Borrowed(&data[..end])
    };
    let (samples, _, _) = jpegls::decode(&data, px.cols as u32, px.rows as u32)
        .map_err(|e| err("PixelData", format!("corrupt JPEG-LS data: {e}")))?;
    let n = px.rows * px.cols;
    Ok(widen(
        samples.into_iter().map(u32::from),
        n,
        (px.bits_allocated / 8) as usize,
    ))
}

// ---------------------------------------------------------------------------------
// JPEG 2000 (ITU T.800)
// ---------------------------------------------------------------------------------

/// The codestream of a JPEG 2000 frame: the frame itself, or the contiguous codestream
/// box of a JP2 file (which some writers store, against the standard).
fn j2k_codestream(data: &[u8]) -> std::result::Result<&[u8], String> {
    if !data.starts_with(&JP2_SIGNATURE) {
        return Ok(data);
    }
    let mut pos = 0usize;
    while pos + 8 <= data.len() {
        let len = u32::from_be_bytes([data[pos], data[pos + 1], data[pos + 2], data[pos + 3]]);
        let kind = &data[pos + 4..pos + 8];
        let (head, len) = match len {
            0 => (8, data.len() - pos),
            1 => {
                let Some(l) = data.get(pos + 8..pos + 16) else {
                    break;
                };
                let l = u64::from_be_bytes(l.try_into().unwrap_or_default());
                (16, usize::try_from(l).unwrap_or(usize::MAX))
            }
            l => (8, l as usize),
        };
        if len < head || pos.saturating_add(len) > data.len() {
            break;
        }
        if kind == b"jp2c" {
            return Ok(&data[pos + head..pos + len]);
        }
        pos += len;
    }
    Err("the JP2 file holds no complete codestream box (jp2c)".into())
}

/// The image size (SIZ) marker segment, which follows SOC.
struct Siz {
    width: usize,
    height: usize,
    components: usize,
    precision: u32,
    subsampled: bool,
}

fn j2k_siz(cs: &[u8]) -> std::result::Result<Siz, String> {
    if !cs.starts_with(&[0xFF, 0x4F, 0xFF, 0x51]) {
        return Err(
            "the data is not a JPEG 2000 codestream (SOC and SIZ markers, FF 4F FF 51)".into(),
        );
    }
    let b = &cs[4..];
    let u32_at =
        |i: usize| -> Option<u32> { Some(u32::from_be_bytes(b.get(i..i + 4)?.try_into().ok()?)) };
    let short = || "the JPEG 2000 SIZ marker segment is truncated".to_string();
    let (xs, ys, xo, yo) = (
        u32_at(4).ok_or_else(short)?,
        u32_at(8).ok_or_else(short)?,
        u32_at(12).ok_or_else(short)?,
        u32_at(16).ok_or_else(short)?,
    );
    let c = b.get(36..38).ok_or_else(short)?;
    let components = u16::from_be_bytes([c[0], c[1]]) as usize;
    let first = b.get(38..41).ok_or_else(short)?;
    if xs <= xo || ys <= yo {
        return Err(format!(
            "the JPEG 2000 image area is empty (Xsiz {xs}, XOsiz {xo}, Ysiz {ys}, YOsiz {yo})"
        ));
    }
    Ok(Siz {
        width: (xs - xo) as usize,
        height: (ys - yo) as usize,
        components,
        precision: u32::from(first[0] & 0x7F) + 1,
        subsampled: first[1] != 1 || first[2] != 1,
    })
}

/// JPEG 2000 through `jpeg2k` on `openjp2`: every resolution level and quality layer,
/// samples as the codestream stores them (signed ones as two's complement).
fn jpeg_2000(
    data: &[u8],
    px: &PixelFormat,
    err: &dyn Fn(&str, String) -> Error,
) -> Result<Vec<u8>> {
    let cs = j2k_codestream(data).map_err(|m| err("PixelData", m))?;
    let siz = j2k_siz(cs).map_err(|m| err("PixelData", m))?;
    check_frame(
        px,
        siz.width,
        siz.height,
        siz.components,
        siz.precision,
        err,
    )?;
    if siz.subsampled {
        return Err(err(
            "PixelData",
            "the JPEG 2000 component is subsampled (XRsiz/YRsiz other than 1)".into(),
        ));
    }
    let image = jpeg2k::Image::from_bytes(cs)
        .map_err(|e| err("PixelData", format!("corrupt JPEG 2000 data: {e}")))?;
    let comps = image.components();
    let [c] = comps else {
        return Err(err(
            "PixelData",
            format!("decoded to {} components, expected 1", comps.len()),
        ));
    };
    let n = px.rows * px.cols;
    if (c.width() as usize, c.height() as usize) != (px.cols, px.rows) || c.data().len() != n {
        return Err(err(
            "PixelData",
            format!(
                "decoded to {} x {} samples, expected {} x {}",
                c.width(),
                c.height(),
                px.cols,
                px.rows
            ),
        ));
    }
    Ok(widen(
        c.data().iter().map(|&v| v as u32),
        n,
        (px.bits_allocated / 8) as usize,
    ))
}
