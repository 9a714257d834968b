//! Compressed (encapsulated) DICOM pixel data: which fragments hold which frame
//! (PS3.5 A.4), and each frame decoded to the bytes an uncompressed file would hold —
//! little-endian samples of BitsAllocated bits, the stored bit pattern — so that the
//! rest of the reader (masking to BitsStored, sign extension, rescaling) is shared.
//!
//! | transfer syntax | UID | decoder |
//! |---|---|---|
//! | RLE Lossless | 1.2.840.10008.1.2.5 | here ([`rle`], PS3.5 Annex G) |
//! | JPEG Baseline (process 1), Extended (processes 2 & 4), Lossless (process 14, and its selection value 1) | …1.2.4.50, .51, .57, .70 | `jpeg-decoder` (8-bit DCT, 2–16-bit lossless); 12-bit sequential DCT here ([`jpeg12`]) |
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
    if sof.marker == 0xC1 && sof.precision == 12 {
        let samples = jpeg12::decode(data).map_err(|m| err("PixelData", m))?;
        return Ok(widen(
            samples.into_iter().map(u32::from),
            px.rows * px.cols,
            (px.bits_allocated / 8) as usize,
        ));
    }
    if !lossless && sof.precision != 8 {
        return Err(err(
            "BitsStored",
            format!(
                "{}-bit progressive JPEG is not supported (voxlab decodes 12-bit \
                 sequential DCT, JPEG Extended process 4, and 8-bit DCT through \
                 jpeg-decoder); decompress first, e.g. `dcmdjpeg in.dcm out.dcm` (DCMTK) \
                 or `gdcmconv --raw in.dcm out.dcm`",
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
// JPEG Extended, 12-bit sequential DCT (ITU T.81 Annex F)
// ---------------------------------------------------------------------------------

/// 12-bit sequential Huffman DCT (SOF1, DICOM's JPEG Extended process 4), one
/// component, decoded here because `jpeg-decoder` reads 8-bit DCT data only. The
/// inverse DCT is the exact definition (A.3.3) in f64, rounded and clamped to 0‥4095;
/// libjpeg's integer IDCT differs from it by at most 1.
mod jpeg12 {
    /// Zig-zag index → natural (row-major) index within an 8 × 8 block.
    const ZIGZAG: [usize; 64] = [
        0, 1, 8, 16, 9, 2, 3, 10, 17, 24, 32, 25, 18, 11, 4, 5, 12, 19, 26, 33, 40, 48, 41, 34, 27,
        20, 13, 6, 7, 14, 21, 28, 35, 42, 49, 56, 57, 50, 43, 36, 29, 22, 15, 23, 30, 37, 44, 51,
        58, 59, 52, 45, 38, 31, 39, 46, 53, 60, 61, 54, 47, 55, 62, 63,
    ];

    /// A Huffman table as F.2.2.3 decodes with it.
    #[derive(Clone)]
    struct Huffman {
        maxcode: [i32; 17],
        mincode: [i32; 17],
        valptr: [usize; 17],
        values: Vec<u8>,
    }

    impl Huffman {
        /// From the 16 code counts and the values of a DHT segment (Annex C).
        fn new(counts: &[u8], values: &[u8]) -> Huffman {
            let (mut maxcode, mut mincode, mut valptr) = ([-1i32; 17], [0i32; 17], [0usize; 17]);
            let (mut code, mut k) = (0i32, 0usize);
            for l in 1..=16 {
                let n = counts[l - 1] as usize;
                valptr[l] = k;
                mincode[l] = code;
                code += n as i32;
                k += n;
                maxcode[l] = if n > 0 { code - 1 } else { -1 };
                code <<= 1;
            }
            Huffman {
                maxcode,
                mincode,
                valptr,
                values: values.to_vec(),
            }
        }
    }

    /// Bits of the entropy-coded data, most significant first, stuffed zero bytes
    /// (FF 00) removed.
    struct Bits<'a> {
        data: &'a [u8],
        pos: usize,
        byte: u32,
        left: u32,
    }

    impl Bits<'_> {
        fn bit(&mut self) -> Result<u32, String> {
            if self.left == 0 {
                let b = *self
                    .data
                    .get(self.pos)
                    .ok_or("the JPEG data ends inside the scan")?;
                if b == 0xFF {
                    match self.data.get(self.pos + 1) {
                        Some(0) => self.pos += 2,
                        Some(&m) => {
                            return Err(format!(
                                "the JPEG scan ends early (marker FF{m:02X} at byte {})",
                                self.pos
                            ))
                        }
                        None => return Err("the JPEG data ends inside the scan".into()),
                    }
                } else {
                    self.pos += 1;
                }
                self.byte = u32::from(b);
                self.left = 8;
            }
            self.left -= 1;
            Ok((self.byte >> self.left) & 1)
        }

        fn bits(&mut self, n: u32) -> Result<u32, String> {
            let mut v = 0;
            for _ in 0..n {
                v = (v << 1) | self.bit()?;
            }
            Ok(v)
        }

        /// DECODE (F.2.2.3).
        fn decode(&mut self, h: &Huffman) -> Result<u8, String> {
            let mut code = self.bit()? as i32;
            for l in 1..=16 {
                if code <= h.maxcode[l] {
                    // A table with more codes than its lengths allow can put a code
                    // below its length's first one.
                    return usize::try_from(code - h.mincode[l])
                        .ok()
                        .and_then(|off| h.values.get(h.valptr[l] + off))
                        .copied()
                        .ok_or_else(|| "a Huffman code points outside its table".to_string());
                }
                code = (code << 1) | self.bit()? as i32;
            }
            Err("an invalid Huffman code in the JPEG scan".into())
        }

        /// RECEIVE and EXTEND (F.2.2.1): an `s`-bit magnitude category's value.
        fn receive_extend(&mut self, s: u32) -> Result<i32, String> {
            if s == 0 {
                return Ok(0);
            }
            if s > 16 {
                return Err(format!("a JPEG coefficient of {s} bits"));
            }
            let v = self.bits(s)? as i32;
            Ok(if v < 1 << (s - 1) {
                v - (1 << s) + 1
            } else {
                v
            })
        }
    }

    /// The samples (row-major, 0‥4095) of a 12-bit sequential JPEG stream with one
    /// component; the caller has checked its frame header against the image size.
    pub(super) fn decode(data: &[u8]) -> Result<Vec<u16>, String> {
        let mut qt: [Option<[u16; 64]>; 4] = [None; 4];
        let mut dc: [Option<Huffman>; 4] = [None, None, None, None];
        let mut ac: [Option<Huffman>; 4] = [None, None, None, None];
        let (mut width, mut height, mut tq) = (0usize, 0usize, 0usize);
        let mut restart = 0usize;
        let mut pos = 2;
        loop {
            while data.get(pos) == Some(&0xFF) && data.get(pos + 1) == Some(&0xFF) {
                pos += 1;
            }
            let (Some(&0xFF), Some(&m)) = (data.get(pos), data.get(pos + 1)) else {
                return Err(format!("a JPEG marker was expected at byte {pos}"));
            };
            let len = data
                .get(pos + 2..pos + 4)
                .map(|l| u16::from_be_bytes([l[0], l[1]]) as usize)
                .ok_or("the JPEG stream ends inside a marker segment")?;
            let body = data
                .get(pos + 4..pos + 2 + len)
                .filter(|_| len >= 2)
                .ok_or_else(|| format!("JPEG marker FF{m:02X} claims {len} bytes past the end"))?;
            let short = || format!("the JPEG marker segment FF{m:02X} is too short");
            match m {
                0xDB => {
                    let mut b = body;
                    while let Some((&pq_tq, rest)) = b.split_first() {
                        let (pq, t) = ((pq_tq >> 4) as usize, (pq_tq & 15) as usize);
                        let size = 64 * (pq + 1);
                        if pq > 1 || t > 3 || rest.len() < size {
                            return Err("a bad JPEG quantisation table (DQT)".into());
                        }
                        let mut q = [0u16; 64];
                        for (k, v) in q.iter_mut().enumerate() {
                            *v = if pq == 0 {
                                u16::from(rest[k])
                            } else {
                                u16::from_be_bytes([rest[2 * k], rest[2 * k + 1]])
                            };
                        }
                        qt[t] = Some(q);
                        b = &rest[size..];
                    }
                }
                0xC4 => {
                    let mut b = body;
                    while let Some((&tc_th, rest)) = b.split_first() {
                        let (tc, th) = (tc_th >> 4, (tc_th & 15) as usize);
                        let counts = rest.get(..16).ok_or_else(short)?;
                        let n: usize = counts.iter().map(|&c| c as usize).sum();
                        let values = rest.get(16..16 + n).ok_or_else(short)?;
                        if tc > 1 || th > 3 {
                            return Err("a bad JPEG Huffman table (DHT)".into());
                        }
                        let h = Some(Huffman::new(counts, values));
                        if tc == 0 {
                            dc[th] = h;
                        } else {
                            ac[th] = h;
                        }
                        b = &rest[16 + n..];
                    }
                }
                0xC1 => {
                    let b = body.get(..9).ok_or_else(short)?;
                    height = u16::from_be_bytes([b[1], b[2]]) as usize;
                    width = u16::from_be_bytes([b[3], b[4]]) as usize;
                    tq = (b[8] & 3) as usize;
                }
                0xDD => {
                    let b = body.get(..2).ok_or_else(short)?;
                    restart = u16::from_be_bytes([b[0], b[1]]) as usize;
                }
                0xDA => {
                    let b = body.get(..6).ok_or_else(short)?;
                    if b[0] != 1 {
                        return Err(format!("a JPEG scan of {} components", b[0]));
                    }
                    if (b[3], b[4], b[5]) != (0, 63, 0) {
                        return Err("the JPEG scan is not sequential (Ss, Se, Ah/Al)".into());
                    }
                    let (td, ta) = ((b[2] >> 4) as usize, (b[2] & 15) as usize);
                    let missing = || "the JPEG scan uses a table that was not defined".to_string();
                    let dc = dc.get(td).and_then(Option::as_ref).ok_or_else(missing)?;
                    let ac = ac.get(ta).and_then(Option::as_ref).ok_or_else(missing)?;
                    let q = qt[tq].as_ref().ok_or_else(missing)?;
                    if width == 0 || height == 0 {
                        return Err("the JPEG scan comes before its frame header".into());
                    }
                    let bits = Bits {
                        data,
                        pos: pos + 2 + len,
                        byte: 0,
                        left: 0,
                    };
                    return scan(bits, dc, ac, q, width, height, restart);
                }
                0xC0 | 0xC2..=0xCF => {
                    return Err(format!(
                        "the 12-bit JPEG decoder reads sequential Huffman (SOF1) data only, \
                         not FF{m:02X}"
                    ))
                }
                _ => {}
            }
            pos += 2 + len;
        }
    }

    fn scan(
        mut bits: Bits,
        dc: &Huffman,
        ac: &Huffman,
        q: &[u16; 64],
        width: usize,
        height: usize,
        restart: usize,
    ) -> Result<Vec<u16>, String> {
        // cos((2x + 1)uπ/16)·C(u)/2: the 1-D basis of A.3.3.
        let mut basis = [[0f64; 8]; 8];
        for (x, row) in basis.iter_mut().enumerate() {
            for (u, b) in row.iter_mut().enumerate() {
                let c = if u == 0 {
                    std::f64::consts::FRAC_1_SQRT_2
                } else {
                    1.0
                };
                *b = 0.5 * c * ((2 * x + 1) as f64 * u as f64 * std::f64::consts::PI / 16.0).cos();
            }
        }
        let (bw, bh) = (width.div_ceil(8), height.div_ceil(8));
        let mut out = vec![0u16; width * height];
        let mut pred = 0i32;
        for n in 0..bw * bh {
            if restart > 0 && n > 0 && n % restart == 0 {
                // RSTn: the bits left in the byte are padding; the prediction restarts.
                bits.left = 0;
                let p = bits.pos;
                match (bits.data.get(p), bits.data.get(p + 1)) {
                    (Some(0xFF), Some(0xD0..=0xD7)) => bits.pos += 2,
                    _ => return Err(format!("a JPEG restart marker was expected at byte {p}")),
                }
                pred = 0;
            }
            let mut coef = [0f64; 64];
            let t = u32::from(bits.decode(dc)?);
            pred = pred.saturating_add(bits.receive_extend(t)?);
            coef[0] = f64::from(pred) * f64::from(q[0]);
            let mut k = 1;
            while k < 64 {
                let rs = bits.decode(ac)?;
                let (r, s) = (usize::from(rs >> 4), u32::from(rs & 15));
                if s == 0 {
                    if r != 15 {
                        break;
                    }
                    k += 16;
                    continue;
                }
                k += r;
                if k > 63 {
                    return Err("a JPEG block has more than 64 coefficients".into());
                }
                coef[ZIGZAG[k]] = f64::from(bits.receive_extend(s)?) * f64::from(q[k]);
                k += 1;
            }
            // The separable inverse DCT: rows of the block, then columns.
            let mut tmp = [0f64; 64];
            for v in 0..8 {
                for x in 0..8 {
                    tmp[v * 8 + x] = (0..8).map(|u| basis[x][u] * coef[v * 8 + u]).sum();
                }
            }
            let (bx, by) = ((n % bw) * 8, (n / bw) * 8);
            for (y, by_y) in basis.iter().enumerate() {
                for x in 0..8 {
                    let (px, py) = (bx + x, by + y);
                    if px >= width || py >= height {
                        continue;
                    }
                    let f: f64 = (0..8).map(|v| by_y[v] * tmp[v * 8 + x]).sum();
                    out[py * width + px] = (f + 2048.0).round().clamp(0.0, 4095.0) as u16;
                }
            }
        }
        Ok(out)
    }
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
