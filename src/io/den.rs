//! VolPack `.den` density files (Philippe Lacroute's VolPack volume rendering library,
//! whose `denfile.c` example defines the format), read by hand.
//!
//! # The format
//!
//! A 62-byte header of 16-bit integers, then the voxels, one unsigned byte each:
//!
//! ```text
//! offset  field        type       meaning
//!  0      map_version  i16        1: the format's only version (also tells byte order)
//!  2      orig_min     3 × i16    the original data set the volume was cut from …
//!  8      orig_max     3 × i16
//! 14      orig_len     3 × i16
//! 20      extr_min     3 × i16    … the part of it that was extracted …
//! 26      extr_max     3 × i16
//! 32      extr_len     3 × i16
//! 38      map_min      3 × i16    … and this volume ("map"): min, max and length
//! 44      map_max      3 × i16        along x, y and z
//! 50      map_len      3 × i16    the dimensions (nx, ny, nz)
//! 56      map_warps    i16        how many warps were applied since extraction
//! 58      map_length   i32        number of voxels, nx · ny · nz
//! 62      data         u8 × map_length, x fastest, then y, then z
//! ```
//!
//! `denfile.c` writes the header in the writing machine's byte order and recognises a
//! byte-swapped file by its version field: bytes `01 00` mean little-endian, `00 01`
//! big-endian. Both orders are read. The voxels are bytes, so their order does not
//! matter.
//!
//! # What is read
//!
//! The dimensions are `map_len`; `map_length` must equal their product (as
//! `denfile.c` requires); the other fields describe where the volume came from and are
//! ignored. The volume is u8. **The format has no voxel spacing: volumes read from it
//! have 1 mm spacing and the identity affine.** Bytes after the voxels are ignored (as
//! `denfile.c` ignores them). Refused with [`Error::Format`] naming the field: another
//! version number, negative or zero lengths, an inconsistent `map_length`, and data
//! shorter than `map_length`.

use super::{fill, open, read_error, read_samples, too_short, truncated_header, Endian, Stored};
use crate::error::{Error, Result};
use crate::volume::{check_dims, AnyVolume};
use glam::DMat4;
use std::io::{BufReader, Read};
use std::path::Path;

/// Bytes in a `.den` header.
pub const HEADER_LEN: usize = 62;

/// Reads a VolPack `.den` file as a u8 volume with 1 mm spacing.
pub fn read_den(path: &Path) -> Result<AnyVolume> {
    let (file, len) = open(path)?;
    from_reader(&mut BufReader::new(file), len, path)
}

/// Reads a `.den` file held in memory; `path` only names the file in errors.
pub fn read_den_bytes(bytes: &[u8], path: &Path) -> Result<AnyVolume> {
    from_reader(&mut &bytes[..], bytes.len() as u64, path)
}

fn from_reader(reader: &mut dyn Read, file_len: u64, path: &Path) -> Result<AnyVolume> {
    let mut h = [0u8; HEADER_LEN];
    let got = fill(reader, &mut h).map_err(|e| read_error(path, e))?;
    if got < 2 {
        return Err(Error::format(
            path,
            "map_version",
            "the file is too short to be a VolPack .den file",
        ));
    }
    let endian = match [h[0], h[1]] {
        [1, 0] => Endian::Little,
        [0, 1] => Endian::Big,
        [a, b] => {
            return Err(Error::format(
                path,
                "map_version",
                format!("bytes {a:02x} {b:02x} are not a VolPack .den version (01 00 or 00 01)"),
            ))
        }
    };
    if got < HEADER_LEN {
        return Err(truncated_header(path, got, HEADER_LEN));
    }
    let i16_at = |off: usize| {
        let b = [h[off], h[off + 1]];
        match endian {
            Endian::Little => i16::from_le_bytes(b),
            Endian::Big => i16::from_be_bytes(b),
        }
    };
    let len = [i16_at(50), i16_at(52), i16_at(54)];
    let b = [h[58], h[59], h[60], h[61]];
    let map_length = match endian {
        Endian::Little => i32::from_le_bytes(b),
        Endian::Big => i32::from_be_bytes(b),
    };
    if let Some(axis) = len.iter().position(|&l| l < 1) {
        return Err(Error::format(
            path,
            "map_len",
            format!(
                "length {} along {} must be at least 1",
                len[axis],
                ["x", "y", "z"][axis]
            ),
        ));
    }
    let dims = len.map(|l| l as usize);
    let product = dims[0] * dims[1] * dims[2]; // at most 32767³, fits in usize
    if map_length < 0 || map_length as usize != product {
        return Err(Error::format(
            path,
            "map_length",
            format!(
                "{map_length} is not the product of the lengths {}×{}×{} = {product}",
                dims[0], dims[1], dims[2]
            ),
        ));
    }
    let n = check_dims(dims).map_err(|e| Error::format(path, "map_len", e.to_string()))?;
    let available = file_len.saturating_sub(HEADER_LEN as u64);
    if available < n as u64 {
        return Err(too_short(path, n as u64, available));
    }
    let samples = read_samples(reader, Stored::U8, endian, n, path)?;
    samples.into_volume(dims, DMat4::IDENTITY)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::VoxelKind;

    /// A `.den` file as `denfile.c` writes it, in the given byte order.
    fn den_bytes(dims: [i16; 3], data: &[u8], big: bool) -> Vec<u8> {
        let mut out = Vec::new();
        let short = |v: i16, out: &mut Vec<u8>| {
            out.extend_from_slice(&if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            })
        };
        short(1, &mut out);
        for _ in 0..3 {
            // min, max, len for orig, extr and map
            for _ in dims {
                short(0, &mut out);
            }
            for d in dims {
                short(d - 1, &mut out);
            }
            for d in dims {
                short(d, &mut out);
            }
        }
        short(0, &mut out);
        let n = dims.iter().map(|&d| d as i32).product::<i32>();
        out.extend_from_slice(&if big {
            n.to_be_bytes()
        } else {
            n.to_le_bytes()
        });
        out.extend_from_slice(data);
        out
    }

    #[test]
    fn both_byte_orders() {
        let data: Vec<u8> = (0..24).collect();
        for big in [false, true] {
            let bytes = den_bytes([4, 3, 2], &data, big);
            assert_eq!(bytes.len(), HEADER_LEN + 24);
            let v = read_den_bytes(&bytes, Path::new("t.den")).unwrap();
            assert_eq!(v.kind(), VoxelKind::U8);
            assert_eq!(v.dims(), [4, 3, 2]);
            assert_eq!(v.affine(), DMat4::IDENTITY);
            match v {
                AnyVolume::U8(v) => assert_eq!(v.data(), &data[..]),
                _ => unreachable!(),
            }
        }
    }

    #[test]
    fn bad_headers() {
        let p = Path::new("t.den");
        let good = den_bytes([4, 3, 2], &[7; 24], false);
        let field = |bytes: &[u8]| match read_den_bytes(bytes, p).unwrap_err() {
            Error::Format { field, .. } => field,
            e => panic!("{e}"),
        };
        let mut b = good.clone();
        b[0] = 2;
        assert_eq!(field(&b), "map_version");
        let mut b = good.clone();
        b[50..52].copy_from_slice(&(-4i16).to_le_bytes());
        assert_eq!(field(&b), "map_len");
        let mut b = good.clone();
        b[58..62].copy_from_slice(&25i32.to_le_bytes());
        assert_eq!(field(&b), "map_length");
        assert_eq!(field(&good[..40]), "header");
        assert_eq!(field(&good[..good.len() - 1]), "data");
        assert_eq!(field(&[]), "map_version");
    }

    #[test]
    fn every_truncation_is_an_error() {
        let good = den_bytes([4, 3, 2], &[7; 24], true);
        for n in 0..good.len() {
            assert!(read_den_bytes(&good[..n], Path::new("t.den")).is_err());
        }
    }
}
