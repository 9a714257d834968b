//! PVM volumes (Stefan Roettger's format of the V³ volume renderer and its `ddsbase`
//! library), plain or DDS-compressed, read by hand.
//!
//! # The format
//!
//! Like the PNM image formats, a PVM file is a short text header and then the raw
//! samples:
//!
//! ```text
//! PVM3\n                  magic: PVM, PVM2 or PVM3
//! 256 256 128\n           width height depth (x, y, z), each at least 1
//! 0.5 0.5 1.2\n           PVM2 and PVM3 only: the voxel size along x, y, z
//! 1\n                     components: bytes per voxel (1 = 8-bit, 2 = 16-bit)
//! <data>                  width·height·depth·components bytes, x fastest
//! <strings>               PVM3 only: description, courtesy, parameter and comment,
//!                         each ended by a NUL byte (possibly empty)
//! ```
//!
//! The original `PVM` version has no voxel size (1 on every axis) and may have comment
//! lines starting with `#` between the magic and the dimensions. 16-bit samples are
//! stored most significant byte first (big-endian), as `ddsbase` reads them.
//!
//! A file starting `DDS v3d\n` or `DDS v3e\n` holds a whole PVM file (header included)
//! compressed by `ddsbase`'s *differential data stream*: a bit stream read as 32-bit
//! big-endian words, most significant bit first, that starts with `skip − 1` (2 bits)
//! and `strip − 1` (16 bits) and then holds runs: a count (7 bits; 0 ends the stream),
//! a width code `w` (3 bits; the width is `w + 1` bits for `w ≥ 1`, else 0) and `count`
//! values of that width. Each value `v` adds `v − 2^(width−1)` (modulo 256) to the
//! running byte; past the first `strip` bytes it also adds the difference of the two
//! bytes `strip` and `strip + 1` places back (prediction from the previous row). The
//! decoded bytes are finally interleaved: they are `skip` streams one after the other,
//! stream `i` holding bytes `i, i + skip, i + 2·skip, …`; in `v3e` files this is done
//! per block of `skip · 2^24` bytes, in `v3d` files over the whole stream.
//!
//! # What is read
//!
//! One or two components, giving a u8 or u16 volume; other component counts (RGB,
//! vector data) are refused because voxlab volumes are scalar. The voxel size is the
//! spacing (taken as millimetres, the affine is diagonal with the origin at voxel
//! (0, 0, 0)); it must be finite and positive. The data must be complete; whatever
//! follows it (the PVM3 strings) is ignored, which is more lenient than `ddsbase`, which
//! also refuses extra bytes in PVM and PVM2 files. A decompressed stream longer than
//! twice the voxel limit (plus 1 MiB for the header and strings) is refused before it
//! is finished, so a small file cannot expand without bound.

use super::{fill, open, read_error, read_samples, too_short, Endian, Stored};
use crate::error::{Error, Result};
use crate::volume::{check_dims, max_voxels, AnyVolume};
use glam::{DMat4, DVec3};
use std::io::{BufReader, Read};
use std::path::Path;

/// The two DDS magic lines (`v3d`: interleaved over the whole stream, `v3e`: per block).
const DDS_V3D: &[u8] = b"DDS v3d\n";
const DDS_V3E: &[u8] = b"DDS v3e\n";

/// The block of `v3e` interleaving, in units of `skip` bytes.
const DDS_INTERLEAVE: usize = 1 << 24;

/// The longest header line accepted.
const MAX_LINE: usize = 256;

/// Reads a PVM file (`PVM`, `PVM2`, `PVM3`, plain or DDS-compressed) as a u8 or u16
/// volume.
pub fn read_pvm(path: &Path) -> Result<AnyVolume> {
    let (file, len) = open(path)?;
    let mut reader = BufReader::new(file);
    let mut head = [0u8; 8];
    let got = fill(&mut reader, &mut head).map_err(|e| read_error(path, e))?;
    if is_dds(&head[..got]) {
        // The whole compressed stream is needed at once; it is no larger than the file.
        let mut rest = Vec::new();
        reader
            .read_to_end(&mut rest)
            .map_err(|e| read_error(path, e))?;
        let decoded = dds_decode(&rest, head[..] == *DDS_V3E, path)?;
        return from_decoded(&decoded, path);
    }
    from_plain(&mut (&head[..got]).chain(reader), len, path)
}

/// Reads a PVM file held in memory (plain or DDS-compressed); `path` only names the
/// file in errors.
pub fn read_pvm_bytes(bytes: &[u8], path: &Path) -> Result<AnyVolume> {
    if is_dds(bytes) {
        let decoded = dds_decode(&bytes[DDS_V3D.len()..], bytes.starts_with(DDS_V3E), path)?;
        return from_decoded(&decoded, path);
    }
    from_plain(&mut &bytes[..], bytes.len() as u64, path)
}

/// Reads the PVM file that DDS decompression gave, saying so in its errors.
fn from_decoded(decoded: &[u8], path: &Path) -> Result<AnyVolume> {
    from_plain(&mut &decoded[..], decoded.len() as u64, path).map_err(|e| match e {
        Error::Format {
            path,
            field,
            message,
        } => Error::Format {
            path,
            field,
            message: format!("in the DDS-decompressed data: {message}"),
        },
        other => other,
    })
}

fn is_dds(head: &[u8]) -> bool {
    head.starts_with(DDS_V3D) || head.starts_with(DDS_V3E)
}

/// Reads one header line (without its `\n`), counting the bytes consumed.
fn line(reader: &mut dyn Read, consumed: &mut u64, field: &str, path: &Path) -> Result<String> {
    let mut bytes = Vec::new();
    let mut b = [0u8; 1];
    loop {
        let got = fill(reader, &mut b).map_err(|e| read_error(path, e))?;
        if got == 0 {
            return Err(Error::format(
                path,
                field,
                "the header ends before this line is complete",
            ));
        }
        *consumed += 1;
        if b[0] == b'\n' {
            break;
        }
        if bytes.len() >= MAX_LINE {
            return Err(Error::format(
                path,
                field,
                format!("the header line is longer than {MAX_LINE} bytes"),
            ));
        }
        bytes.push(b[0]);
    }
    String::from_utf8(bytes).map_err(|_| Error::format(path, field, "the header line is not text"))
}

/// Parses exactly three numbers from a header line.
fn three<T: std::str::FromStr>(text: &str, field: &str, path: &Path) -> Result<[T; 3]> {
    let parts: Vec<&str> = text.split_ascii_whitespace().collect();
    let bad = || {
        Error::format(
            path,
            field,
            format!("'{}' is not three numbers", super::snippet(text)),
        )
    };
    if parts.len() != 3 {
        return Err(bad());
    }
    let mut out = Vec::with_capacity(3);
    for p in parts {
        out.push(p.parse::<T>().map_err(|_| bad())?);
    }
    out.try_into().map_err(|_| bad())
}

/// Reads an uncompressed PVM file from its first byte.
fn from_plain(reader: &mut dyn Read, file_len: u64, path: &Path) -> Result<AnyVolume> {
    let mut consumed = 0u64;
    let magic = line(reader, &mut consumed, "magic", path).map_err(|_| {
        Error::format(
            path,
            "magic",
            "not a PVM file: it does not start with a PVM, PVM2, PVM3 or DDS v3d/v3e line",
        )
    })?;
    let version = match magic.as_str() {
        "PVM" => 1,
        "PVM2" => 2,
        "PVM3" => 3,
        other => {
            return Err(Error::format(
                path,
                "magic",
                format!(
                    "'{}' is not PVM, PVM2 or PVM3 (nor a DDS v3d/v3e compressed file)",
                    super::snippet(other)
                ),
            ))
        }
    };
    let mut dims_line = line(reader, &mut consumed, "dimensions", path)?;
    if version == 1 {
        while dims_line.starts_with('#') {
            dims_line = line(reader, &mut consumed, "dimensions", path)?;
        }
    }
    let dims: [usize; 3] = three(&dims_line, "dimensions", path)?;
    let spacing: [f64; 3] = if version == 1 {
        [1.0; 3]
    } else {
        let s: [f64; 3] = three(&line(reader, &mut consumed, "scale", path)?, "scale", path)?;
        if !s.iter().all(|v| v.is_finite() && *v > 0.0) {
            return Err(Error::format(
                path,
                "scale",
                format!("voxel size {s:?} must be finite and positive"),
            ));
        }
        s
    };
    let comp_line = line(reader, &mut consumed, "components", path)?;
    let (stored, size) = match comp_line.trim() {
        "1" => (Stored::U8, 1u64),
        "2" => (Stored::U16, 2u64),
        other => {
            return Err(Error::format(
                path,
                "components",
                format!(
                    "{} components per voxel are not supported: voxlab volumes are scalar \
                     (1 = 8-bit or 2 = 16-bit)",
                    super::snippet(other)
                ),
            ))
        }
    };
    let n = check_dims(dims).map_err(|e| Error::format(path, "dimensions", e.to_string()))?;
    let expected = (n as u64).saturating_mul(size);
    let available = file_len.saturating_sub(consumed);
    if available < expected {
        return Err(too_short(path, expected, available));
    }
    let samples = read_samples(reader, stored, Endian::Big, n, path)?;
    samples.into_volume(dims, DMat4::from_scale(DVec3::from_array(spacing)))
}

// ---------------------------------------------------------------------------------
// DDS decompression
// ---------------------------------------------------------------------------------

/// `ddsbase`'s bit reader: 32-bit big-endian words, most significant bit first; reads
/// past the end give zeros.
struct Bits<'a> {
    data: &'a [u8],
    pos: usize,
    buffer: u32,
    bufsize: u32,
}

fn shl(v: u32, bits: u32) -> u32 {
    if bits >= 32 {
        0
    } else {
        v << bits
    }
}

fn shr(v: u32, bits: u32) -> u32 {
    if bits >= 32 {
        0
    } else {
        v >> bits
    }
}

impl Bits<'_> {
    /// Reads `bits` (at most 16) bits.
    fn read(&mut self, bits: u32) -> u32 {
        let value;
        if bits < self.bufsize {
            self.bufsize -= bits;
            value = shr(self.buffer, self.bufsize);
        } else {
            let high = shl(self.buffer, bits - self.bufsize);
            let mut word = [0u8; 4];
            if self.pos < self.data.len() {
                let end = (self.pos + 4).min(self.data.len());
                word[..end - self.pos].copy_from_slice(&self.data[self.pos..end]);
                self.pos += 4;
            }
            self.buffer = u32::from_be_bytes(word);
            self.bufsize += 32 - bits;
            value = high | shr(self.buffer, self.bufsize);
        }
        self.buffer &= shl(1, self.bufsize).wrapping_sub(1);
        value
    }
}

/// Decodes a DDS stream (the bytes after the magic line) into the PVM file it holds.
fn dds_decode(stream: &[u8], per_block: bool, path: &Path) -> Result<Vec<u8>> {
    let cap = max_voxels().saturating_mul(2).saturating_add(1 << 20);
    let mut bits = Bits {
        data: stream,
        pos: 0,
        buffer: 0,
        bufsize: 0,
    };
    let skip = bits.read(2) as usize + 1;
    let strip = bits.read(16) as usize + 1;
    let mut out: Vec<u8> = Vec::new();
    let mut act: i32 = 0;
    loop {
        let count = bits.read(7);
        if count == 0 {
            break;
        }
        let code = bits.read(3);
        let width = if code >= 1 { code + 1 } else { 0 };
        let half = (1i32 << width) / 2;
        for _ in 0..count {
            let cnt = out.len();
            let v = bits.read(width) as i32 - half;
            act += if strip == 1 || cnt <= strip {
                v
            } else {
                i32::from(out[cnt - strip]) - i32::from(out[cnt - strip - 1]) + v
            };
            act = act.rem_euclid(256);
            if out.len() >= cap {
                return Err(Error::too_large(
                    format!("DDS data of {}", path.display()),
                    format!("it decompresses to more than {cap} bytes"),
                ));
            }
            if out.len() == out.capacity() {
                out.try_reserve(out.len().max(1 << 16)).map_err(|_| {
                    Error::too_large(
                        format!("DDS data of {}", path.display()),
                        "cannot allocate memory for the decompressed data",
                    )
                })?;
            }
            out.push(act as u8);
        }
    }
    if skip <= 1 {
        return Ok(out);
    }
    let block = if per_block {
        skip * DDS_INTERLEAVE
    } else {
        out.len().max(1)
    };
    let mut result = vec![0u8; out.len()];
    for (src, dst) in out.chunks(block).zip(result.chunks_mut(block)) {
        interleave(src, dst, skip);
    }
    Ok(result)
}

/// Interleaves `skip` streams stored one after the other in `src` into `dst`.
fn interleave(src: &[u8], dst: &mut [u8], skip: usize) {
    let mut s = src.iter();
    for i in 0..skip {
        for d in dst.iter_mut().skip(i).step_by(skip) {
            if let Some(&b) = s.next() {
                *d = b;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::VoxelKind;

    /// A bit writer matching [`Bits`].
    struct BitWriter {
        out: Vec<u8>,
        acc: u64,
        n: u32,
    }

    impl BitWriter {
        fn put(&mut self, value: u32, bits: u32) {
            if bits == 0 {
                return;
            }
            self.acc = (self.acc << bits) | u64::from(value & ((1u32 << bits) - 1));
            self.n += bits;
            while self.n >= 8 {
                self.n -= 8;
                self.out.push((self.acc >> self.n) as u8);
            }
        }
        fn finish(mut self) -> Vec<u8> {
            if self.n > 0 {
                let pad = 8 - self.n;
                self.put(0, pad);
            }
            self.out
        }
    }

    /// Compresses `data` as a DDS stream with the given interleaving and row prediction
    /// (every value coded with 8 bits), magic line included.
    fn dds_encode(data: &[u8], skip: usize, strip: usize, per_block: bool) -> Vec<u8> {
        // Undo the interleaving the decoder applies last.
        let block = if per_block {
            skip * DDS_INTERLEAVE
        } else {
            data.len().max(1)
        };
        let mut streams: Vec<u8> = Vec::with_capacity(data.len());
        for chunk in data.chunks(block) {
            for i in 0..skip {
                streams.extend(chunk.iter().skip(i).step_by(skip).copied());
            }
        }
        let mut w = BitWriter {
            out: Vec::new(),
            acc: 0,
            n: 0,
        };
        w.put(skip as u32 - 1, 2);
        w.put(strip as u32 - 1, 16);
        let mut act: i32 = 0;
        for (run_start, run) in streams.chunks(127).enumerate() {
            w.put(run.len() as u32, 7);
            w.put(7, 3);
            for (o, &b) in run.iter().enumerate() {
                let cnt = run_start * 127 + o;
                let predicted = if strip == 1 || cnt <= strip {
                    act
                } else {
                    act + i32::from(streams[cnt - strip]) - i32::from(streams[cnt - strip - 1])
                };
                let v = (i32::from(b) - predicted + 128).rem_euclid(256);
                w.put(v as u32, 8);
                act = i32::from(b);
            }
        }
        w.put(0, 7);
        let mut out = if per_block { DDS_V3E } else { DDS_V3D }.to_vec();
        out.extend(w.finish());
        out
    }

    fn u8_data(v: &AnyVolume) -> Vec<u8> {
        match v {
            AnyVolume::U8(v) => v.data().to_vec(),
            _ => panic!("not u8"),
        }
    }

    #[test]
    fn plain_versions() {
        let p = Path::new("t.pvm");
        let data: Vec<u8> = (0..24).collect();
        let mut f = b"PVM\n# a comment\n4 3 2\n1\n".to_vec();
        f.extend(&data);
        let v = read_pvm_bytes(&f, p).unwrap();
        assert_eq!(
            (v.kind(), v.dims(), v.spacing()),
            (VoxelKind::U8, [4, 3, 2], [1.0; 3])
        );
        assert_eq!(u8_data(&v), data);

        let mut f = b"PVM2\n4 3 2\n0.5 1 2.25\n1\n".to_vec();
        f.extend(&data);
        let v = read_pvm_bytes(&f, p).unwrap();
        assert_eq!(v.spacing(), [0.5, 1.0, 2.25]);

        let mut f = b"PVM3\n2 2 1\n1 1 1\n2\n".to_vec();
        f.extend([0x01, 0x02, 0xff, 0xfe, 0, 0, 0, 7]);
        f.extend(b"description\0courtesy\0\0\0");
        let v = read_pvm_bytes(&f, p).unwrap();
        match v {
            AnyVolume::U16(v) => assert_eq!(v.data(), &[0x0102, 0xfffe, 0, 7]),
            _ => panic!("not u16"),
        }
    }

    #[test]
    fn dds_hand_made_stream() {
        // skip 1, strip 1; a run of 3 values of width 8, a run of 2 of width 0 (repeat),
        // a run of 1 of width 2; then the end.
        let mut w = BitWriter {
            out: Vec::new(),
            acc: 0,
            n: 0,
        };
        w.put(0, 2);
        w.put(0, 16);
        w.put(3, 7);
        w.put(7, 3);
        w.put(138, 8); // 0 + 10 = 10
        w.put(138, 8); // 10 + 10 = 20
        w.put(113, 8); // 20 - 15 = 5
        w.put(2, 7);
        w.put(0, 3); // width 0: the value stays 5
        w.put(1, 7);
        w.put(1, 3); // width 2: value 0 means -2
        w.put(0, 2);
        w.put(0, 7);
        let out = dds_decode(&w.finish(), false, Path::new("t.pvm")).unwrap();
        assert_eq!(out, [10, 20, 5, 5, 5, 3]);
    }

    #[test]
    fn dds_round_trips() {
        let p = Path::new("t.pvm");
        let mut plain = b"PVM2\n5 4 3\n1 1 2\n2\n".to_vec();
        let data: Vec<u8> = (0..120u32).map(|i| (i * i * 7 % 251) as u8).collect();
        plain.extend(&data);
        let want = read_pvm_bytes(&plain, p).unwrap();
        for (skip, strip, per_block) in [(1, 1, false), (2, 10, false), (4, 7, true), (3, 1, true)]
        {
            let packed = dds_encode(&plain, skip, strip, per_block);
            assert_eq!(
                dds_decode(&packed[8..], per_block, p).unwrap(),
                plain,
                "skip {skip} strip {strip}"
            );
            assert_eq!(read_pvm_bytes(&packed, p).unwrap(), want);
        }
    }

    #[test]
    fn dds_files_by_name() {
        let dir = std::env::temp_dir().join(format!("voxlab-pvm-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut plain = b"PVM3\n3 2 1\n0.5 0.5 1\n2\n".to_vec();
        plain.extend((0..12u8).map(|i| i * 19));
        plain.extend(b"desc\0\0\0\0");
        for (i, per_block) in [false, true].into_iter().enumerate() {
            let p = dir.join(format!("c{i}.pvm"));
            std::fs::write(&p, dds_encode(&plain, 2, 3, per_block)).unwrap();
            assert_eq!(
                crate::io::read_volume(&p).unwrap(),
                read_pvm_bytes(&plain, &p).unwrap()
            );
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_files() {
        let p = Path::new("t.pvm");
        let field = |bytes: &[u8]| match read_pvm_bytes(bytes, p).unwrap_err() {
            Error::Format { field, .. } => field,
            e => panic!("{e}"),
        };
        assert_eq!(field(b"PVM4\n1 1 1\n1\n\0"), "magic");
        assert_eq!(field(b""), "magic");
        assert_eq!(field(b"PVM\n1 1\n1\n\0"), "dimensions");
        assert_eq!(field(b"PVM\n0 1 1\n1\n\0"), "dimensions");
        assert_eq!(field(b"PVM\n-1 1 1\n1\n\0"), "dimensions");
        assert_eq!(field(b"PVM2\n1 1 1\n1 0 1\n1\n\0"), "scale");
        assert_eq!(field(b"PVM2\n1 1 1\n1 nan 1\n1\n\0"), "scale");
        assert_eq!(field(b"PVM3\n1 1 1\n1 1 1\n3\n\0\0\0"), "components");
        assert_eq!(field(b"PVM3\n2 1 1\n1 1 1\n2\n\0\0\0"), "data");
        let e = read_pvm_bytes(b"PVM\n100000 100000 100000\n1\n", p).unwrap_err();
        assert!(e.to_string().contains("limit"), "{e}");
    }

    #[test]
    fn truncations_and_garbage_are_errors() {
        let p = Path::new("t.pvm");
        let mut plain = b"PVM3\n3 2 2\n1 1 1\n2\n".to_vec();
        plain.extend(0..24u8);
        let packed = dds_encode(&plain, 2, 3, false);
        for f in [&plain, &packed] {
            for n in 0..f.len() {
                let _ = read_pvm_bytes(&f[..n], p);
            }
        }
        for n in 0..plain.len() {
            assert!(read_pvm_bytes(&plain[..n], p).is_err());
        }
        let mut x: u64 = 0x9e3779b97f4a7c15;
        for len in 0..300 {
            let mut g = b"DDS v3d\n".to_vec();
            for _ in 0..len {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                g.push(x as u8);
            }
            let _ = read_pvm_bytes(&g, p);
            let _ = read_pvm_bytes(&g[8..], p);
        }
    }
}
