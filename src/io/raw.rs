//! Headerless raw volumes: the samples alone, described by the user.
//!
//! Many scanners and research tools dump a volume as bare samples (`.raw`, `.img`,
//! `.vol`, `.bin`) and put the layout in a separate text file or in the user's head.
//! voxlab reads such a file from a [`RawSpec`]: dimensions, sample type, byte order,
//! spacing and the number of bytes to skip before the first sample. On the command
//! line these are `--raw-dims NX,NY,NZ --raw-type u16 --raw-endian little
//! --raw-spacing SX,SY,SZ --raw-offset BYTES`.
//!
//! The samples are x fastest (then y, then z), as everywhere in voxlab. Stored types
//! map to voxel types by the table in [`crate::io`]. A file whose first two bytes are
//! the gzip magic is decompressed first.
//!
//! Because nothing in the file can confirm the description, the one check available
//! is made strictly: the file must hold exactly `offset + nx·ny·nz·size` bytes (after
//! decompression). A wrong guess of the dimensions or the type almost always fails it,
//! and the message says how many bytes were expected and found.

use super::{read_error, read_samples, Endian, Stored};
use crate::error::{Error, Result};
use crate::volume::{check_dims, check_spacing, AnyVolume};
use glam::{DMat4, DVec4};
use std::io::{BufReader, Read};
use std::path::Path;

/// The sample types a raw file can hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RawType {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    U64,
    I64,
    F32,
    F64,
}

impl RawType {
    /// Every name [`RawType::parse`] accepts, for messages.
    pub const NAMES: &'static str = "u8, i8, u16, i16, u32, i32, u64, i64, f32, f64 \
         (or uint8, int8, uint16, int16, uint32, int32, uint64, int64, float32, float64)";

    /// Parses `u16`, `uint16`, `f32`, `float32`, `float`, `double`, ….
    pub fn parse(s: &str) -> Result<Self> {
        Ok(match s.trim().to_ascii_lowercase().as_str() {
            "u8" | "uint8" | "uchar" => RawType::U8,
            "i8" | "int8" | "char" => RawType::I8,
            "u16" | "uint16" | "ushort" => RawType::U16,
            "i16" | "int16" | "short" => RawType::I16,
            "u32" | "uint32" | "uint" => RawType::U32,
            "i32" | "int32" | "int" => RawType::I32,
            "u64" | "uint64" => RawType::U64,
            "i64" | "int64" => RawType::I64,
            "f32" | "float32" | "float" => RawType::F32,
            "f64" | "float64" | "double" => RawType::F64,
            other => {
                return Err(Error::invalid(
                    "raw sample type",
                    format!("'{other}' is not one of {}", Self::NAMES),
                ))
            }
        })
    }

    fn stored(self) -> Stored {
        match self {
            RawType::U8 => Stored::U8,
            RawType::I8 => Stored::I8,
            RawType::U16 => Stored::U16,
            RawType::I16 => Stored::I16,
            RawType::U32 => Stored::U32,
            RawType::I32 => Stored::I32,
            RawType::U64 => Stored::U64,
            RawType::I64 => Stored::I64,
            RawType::F32 => Stored::F32,
            RawType::F64 => Stored::F64,
        }
    }
}

/// How a raw file is laid out.
#[derive(Clone, Debug, PartialEq)]
pub struct RawSpec {
    /// Samples along x, y and z (x fastest).
    pub dims: [usize; 3],
    /// The stored sample type.
    pub sample: RawType,
    /// Byte order of multi-byte samples (`true` = big-endian).
    pub big_endian: bool,
    /// Voxel spacing in mm (x, y, z).
    pub spacing: [f64; 3],
    /// Bytes to skip before the first sample (a header voxlab does not read).
    pub offset: u64,
}

impl RawSpec {
    /// A little-endian spec with 1 mm voxels and no offset.
    pub fn new(dims: [usize; 3], sample: RawType) -> Self {
        RawSpec {
            dims,
            sample,
            big_endian: false,
            spacing: [1.0; 3],
            offset: 0,
        }
    }

    /// The number of data bytes the spec describes (the dims already checked).
    fn data_bytes(&self, path: &Path) -> Result<u64> {
        let n = check_dims(self.dims).map_err(|e| Error::format(path, "dims", e.to_string()))?;
        (n as u64)
            .checked_mul(self.sample.stored().size() as u64)
            .ok_or_else(|| Error::format(path, "dims", "the data size overflows"))
    }
}

/// Reads a raw volume described by `spec`.
///
/// Fails with [`Error::Format`] when the dimensions are empty or over the voxel limit
/// (`dims`), the spacing is not finite and positive (`spacing`), or the file does not
/// hold exactly `offset + nx·ny·nz·size` bytes (`data`); with [`Error::Io`] when it
/// cannot be read.
pub fn read_raw(path: &Path, spec: &RawSpec) -> Result<AnyVolume> {
    let data_bytes = spec.data_bytes(path)?;
    check_spacing(spec.spacing).map_err(|e| Error::format(path, "spacing", e.to_string()))?;
    let (mut file, _) = super::open(path)?;
    let mut magic = [0u8; 2];
    let got = super::fill(&mut file, &mut magic).map_err(|e| Error::io(path, e))?;
    let (file, len) = super::open(path)?;
    let expected = spec.offset.saturating_add(data_bytes);
    if got == 2 && magic == [0x1f, 0x8b] {
        // Compressed: the decompressed length is known only after reading it all.
        let mut reader = flate2::read::MultiGzDecoder::new(BufReader::new(file));
        skip(&mut reader, spec.offset, path)?;
        let vol = read_body(&mut reader, spec, path)?;
        let mut rest = [0u8; 1];
        let extra = super::fill(&mut reader, &mut rest).map_err(|e| read_error(path, e))?;
        if extra > 0 {
            return Err(Error::format(
                path,
                "data",
                format!(
                    "the decompressed file is longer than the {expected} bytes the \
                     description (offset + dims × sample size) needs: check --raw-dims and --raw-type"
                ),
            ));
        }
        return Ok(vol);
    }
    if len != expected {
        return Err(Error::format(
            path,
            "data",
            format!(
                "the file has {len} bytes but the description needs exactly {expected} \
                 ({} offset + {}×{}×{} samples × {} bytes): check --raw-dims, --raw-type \
                 and --raw-offset",
                spec.offset,
                spec.dims[0],
                spec.dims[1],
                spec.dims[2],
                spec.sample.stored().size()
            ),
        ));
    }
    let mut reader = BufReader::new(file);
    skip(&mut reader, spec.offset, path)?;
    read_body(&mut reader, spec, path)
}

fn skip(reader: &mut dyn Read, n: u64, path: &Path) -> Result<()> {
    let skipped = std::io::copy(&mut reader.take(n), &mut std::io::sink())
        .map_err(|e| read_error(path, e))?;
    if skipped < n {
        return Err(super::too_short(path, n, skipped));
    }
    Ok(())
}

fn read_body(reader: &mut dyn Read, spec: &RawSpec, path: &Path) -> Result<AnyVolume> {
    let n = spec.dims.iter().product();
    let endian = if spec.big_endian {
        Endian::Big
    } else {
        Endian::Little
    };
    let samples = read_samples(reader, spec.sample.stored(), endian, n, path)?;
    let [sx, sy, sz] = spec.spacing;
    let affine = DMat4::from_cols(
        DVec4::new(sx, 0.0, 0.0, 0.0),
        DVec4::new(0.0, sy, 0.0, 0.0),
        DVec4::new(0.0, 0.0, sz, 0.0),
        DVec4::W,
    );
    samples.into_volume(spec.dims, affine)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str, bytes: &[u8]) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("voxlab-raw-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    #[test]
    fn reads_big_endian_u16_with_offset_and_spacing() {
        let mut bytes = b"HDR!".to_vec();
        for v in [1u16, 2, 3, 4, 500, 6, 7, 65535] {
            bytes.extend_from_slice(&v.to_be_bytes());
        }
        let p = temp("be.raw", &bytes);
        let spec = RawSpec {
            dims: [2, 2, 2],
            sample: RawType::U16,
            big_endian: true,
            spacing: [0.5, 0.5, 2.0],
            offset: 4,
        };
        let v = read_raw(&p, &spec).unwrap();
        assert_eq!(v.dims(), [2, 2, 2]);
        assert_eq!(v.spacing(), [0.5, 0.5, 2.0]);
        assert_eq!(
            v.values_f64(),
            [1.0, 2.0, 3.0, 4.0, 500.0, 6.0, 7.0, 65535.0]
        );
    }

    #[test]
    fn size_mismatch_says_what_was_expected() {
        let p = temp("short.raw", &[0u8; 7]);
        let e = read_raw(&p, &RawSpec::new([2, 2, 2], RawType::U8)).unwrap_err();
        assert!(e.to_string().contains("has 7 bytes"), "{e}");
        assert!(e.to_string().contains("exactly 8"), "{e}");
        let p = temp("long.raw", &[0u8; 9]);
        assert!(read_raw(&p, &RawSpec::new([2, 2, 2], RawType::U8)).is_err());
    }

    #[test]
    fn absurd_dims_are_refused_before_reading() {
        let p = temp("tiny.raw", &[0u8; 8]);
        let e = read_raw(&p, &RawSpec::new([1 << 30, 1 << 30, 8], RawType::F64)).unwrap_err();
        assert!(
            matches!(e, Error::Format { ref field, .. } if field == "dims"),
            "{e}"
        );
    }

    #[test]
    fn gzip_raw() {
        use std::io::Write;
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        let vals = [1.5f32, -2.0, f32::NAN, 4.0];
        for v in vals {
            enc.write_all(&v.to_le_bytes()).unwrap();
        }
        let p = temp("f.raw.gz", &enc.finish().unwrap());
        let v = read_raw(&p, &RawSpec::new([2, 2, 1], RawType::F32)).unwrap();
        let got = v.values_f64();
        assert_eq!(got[0], 1.5);
        assert!(got[2].is_nan());
        assert!(read_raw(&p, &RawSpec::new([2, 2, 2], RawType::F32)).is_err());
        assert!(read_raw(&p, &RawSpec::new([1, 2, 1], RawType::F32)).is_err());
    }

    #[test]
    fn type_names() {
        assert_eq!(RawType::parse("uint16").unwrap(), RawType::U16);
        assert_eq!(RawType::parse("Float").unwrap(), RawType::F32);
        assert!(RawType::parse("u12")
            .unwrap_err()
            .to_string()
            .contains("u8, i8"));
    }
}
