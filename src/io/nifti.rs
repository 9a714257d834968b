//! NIfTI-1 and NIfTI-2 files (`.nii`, `.nii.gz`, and `.hdr`/`.img` pairs), read and
//! written by hand; gzip via `flate2`.
//!
//! # The format
//!
//! A NIfTI file is a fixed binary header (348 bytes in NIfTI-1, 540 in NIfTI-2), 4 bytes
//! saying whether header extensions follow, the extensions if any, and the voxels from
//! byte `vox_offset` on. NIfTI-2 holds the same fields as NIfTI-1, widened (sizes and
//! offsets to i64, reals to f64) and reordered. The fields voxlab uses (offsets in
//! bytes, NIfTI-1 / NIfTI-2):
//!
//! ```text
//! NIfTI-1        NIfTI-2        field          use
//!   0 i32          0 i32        sizeof_hdr     348 or 540; also tells the byte order
//! 344 [4]          4 [8]        magic          "n+1\0"/"n+2\0…": one file;
//!                                              "ni1\0"/"ni2\0…": a .hdr/.img pair
//!  40 8 × i16     16 8 × i64    dim            dim[0] = number of axes (1..7),
//!                                              dim[1..] = sizes
//!  70 i16         12 i16        datatype       the stored type (codes below)
//!  72 i16         14 i16        bitpix         bits per voxel; must match datatype
//!  76 8 × f32    104 8 × f64    pixdim         pixdim[0] = qfac (±1), [1..3] = voxel size
//! 108 f32        168 i64        vox_offset     where the voxels start
//! 112 f32        176 f64        scl_slope      value = stored · slope + inter
//! 116 f32        184 f64        scl_inter      (slope 0 = no scaling)
//! 123 u8         500 i32        xyzt_units     spatial unit in bits 0..2: 1 m, 2 mm, 3 µm
//! 252 i16        344 i32        qform_code     > 0: the quaternion fields hold a geometry
//! 254 i16        348 i32        sform_code     > 0: srow_x/y/z hold a geometry
//! 256 3 × f32    352 3 × f64    quatern_b,c,d  rotation quaternion (a is implied, a ≥ 0)
//! 268 3 × f32    376 3 × f64    qoffset_x,y,z  translation
//! 280 12 × f32   400 12 × f64   srow_x,y,z     rows of the 3×4 voxel-to-world affine
//! ```
//!
//! All multi-byte fields and voxels are in the file's byte order; the voxels are x
//! fastest, like the crate's memory order, then the axes past the third (`t` fastest)
//! — a 4-D file is its 3-D volumes one after another.
//!
//! # What is read
//!
//! - Both versions and both byte orders, told by `sizeof_hdr`. Single files (`n+1`,
//!   `n+2`: data at `vox_offset`, which must be a whole number at or past the header
//!   and its 4 extension bytes: 352, 544) and pairs (`ni1`, `ni2`: the header in
//!   `X.hdr`, the voxels in `X.img` from `vox_offset` on; `X.hdr.gz` pairs with
//!   `X.img.gz`). Gzip-compressed files (`.nii.gz`) are recognised by their content.
//!   Extensions are skipped. Bytes after the voxels are ignored.
//! - `dim[0]` from 1 to 7; x, y, z from `dim[1..3]` (1 beyond `dim[0]`). The axes past
//!   the third (`dim[4..]` up to `dim[0]`: time, then vector components) count the
//!   file's 3-D volumes, its *frames*, numbered with the fourth axis fastest. voxlab
//!   volumes are scalar 3-D, so a file of several frames is read one frame at a time:
//!   [`read_nifti_frame`] (`--frame K`, `voxlab.read(path, frame=K)`) seeks to frame K
//!   and reads only its voxels; [`read_nifti`] refuses such a file with a message
//!   giving the count. [`nifti_frames`] reads the count from the header alone.
//! - `datatype`: 2 (u8) → u8, 256 (i8) → i16, 4 (i16) → i16, 512 (u16) → u16, 16 (f32)
//!   → f32, and 8 (i32), 768 (u32), 1024 (i64), 1280 (u64), 64 (f64) → f32 rounded to
//!   nearest (see [`crate::io`]). Complex, RGB, RGBA, binary and float128 data are
//!   refused naming the datatype.
//! - `scl_slope`, `scl_inter`: when the slope is finite and non-zero and the pair is not
//!   (1, 0), every value becomes `stored · slope + inter` (computed in f64) in an f32
//!   volume; a zero or non-finite slope means "no scaling", as the standard says. A
//!   valid slope with a non-finite intercept is refused.
//! - Geometry, the index-to-world affine, in the order of preference the standard
//!   gives: `sform_code > 0` → the `srow` rows; else `qform_code > 0` → the quaternion
//!   (`a = √(1 − b² − c² − d²)`, 0 when that is negative, with b, c, d then normalised),
//!   times `diag(pixdim[1], pixdim[2], qfac · pixdim[3])` (`qfac` is −1 when
//!   `pixdim[0] < 0`, else 1), plus `qoffset`: the same formula as the standard's
//!   reference library and nibabel; else (both codes 0, "method 1" of the standard)
//!   `diag(pixdim[1..3])` with the origin at voxel (0, 0, 0) (nibabel instead centres
//!   and flips x in this case). **World coordinates are NIfTI's RAS+ millimetres**
//!   (+x towards the subject's right, +y anterior, +z superior); a spatial unit of metres or micrometres is converted to millimetres,
//!   an unknown unit is taken as millimetres. A non-finite or singular result is
//!   refused naming `sform`, `qform` or `pixdim`.
//! - Analyze 7.5 (no magic) is refused with a message.
//!
//! # What is written
//!
//! [`write_nifti`] writes a single little-endian NIfTI-1 file — NIfTI-2 when an axis is
//! longer than NIfTI-1's 32767, or when asked with [`write_nifti_version`] —
//! gzip-compressed when the name ends in `.gz`: datatype 2, 512, 4 or 16 for u8, u16, i16 and f32, `vox_offset`
//! 352 (no extensions), no scaling (slope 1, intercept 0), millimetres, `sform_code` 2
//! (aligned) with the affine in `srow`, and `qform_code` 2 with the same geometry as a
//! quaternion when the affine's linear part is a rotation times positive scales
//! (possibly with one reflection, written as `qfac` −1), else `qform_code` 0. `pixdim`
//! holds the column lengths; `vox_offset` is 544 in NIfTI-2. NIfTI-1 stores the affine
//! as 32-bit floats, so **a NIfTI-1 round trip gives back the affine rounded to f32**
//! (exactly, when it is f32-representable); NIfTI-2 stores f64 and gives it back
//! exactly.

use super::{fill, open, read_error, read_samples, too_short, write_atomic, write_samples_le};
use super::{truncated_header, Endian, Samples, Stored};
use crate::error::{Error, Result};
use crate::volume::{check_dims, AnyVolume, Volume, VoxelKind};
use flate2::read::MultiGzDecoder;
use flate2::write::GzEncoder;
use flate2::Compression;
use glam::{DMat3, DMat4, DQuat, DVec3, DVec4};
use std::io::{self, BufReader, Read, Write};
use std::path::{Path, PathBuf};

/// Bytes in a NIfTI-1 header.
pub const HEADER_LEN: usize = 348;

/// Where the voxels of a single file written by [`write_nifti`] start.
const WRITE_OFFSET: usize = 352;

/// The largest ratio of decompressed to compressed size deflate can reach; a gzip
/// stream shorter than its promise divided by this is certainly truncated.
const MAX_DEFLATE_RATIO: u64 = 1032;

/// Reads a NIfTI-1 or NIfTI-2 volume: `.nii`, `.nii.gz`, or the `.hdr` of a
/// `.hdr`/`.img` pair. A file of several 3-D volumes is refused (choose one with
/// [`read_nifti_frame`]).
pub fn read_nifti(path: &Path) -> Result<AnyVolume> {
    read_nifti_frame(path, None)
}

/// How many 3-D volumes a NIfTI file holds (the product of `dim[4..]`), from its
/// header alone.
pub fn nifti_frames(path: &Path) -> Result<usize> {
    let (file, len) = open(path)?;
    let (mut reader, _) = maybe_gzip(BufReader::new(file), len, path)?;
    Ok(read_header(&mut reader, path, Some(0))?.frames)
}

/// [`read_nifti`] of 3-D volume `frame` (counting the axes past the third as one, the
/// fourth fastest) of a file that holds several; `None` reads a file of one.
pub fn read_nifti_frame(path: &Path, frame: Option<usize>) -> Result<AnyVolume> {
    let (file, len) = open(path)?;
    let (mut reader, size) = maybe_gzip(BufReader::new(file), len, path)?;
    let header = read_header(&mut reader, path, frame)?;
    if header.pair {
        let img = image_path(path)?;
        let (file, len) = open(&img).map_err(|e| {
            Error::format(
                path,
                "magic",
                format!("a ni1 header needs its data file: {e}"),
            )
        })?;
        let (mut data, size) = maybe_gzip(BufReader::new(file), len, &img)?;
        read_data(&mut data, size, 0, &header, &img)
    } else {
        read_data(&mut reader, size, header.len as u64, &header, path)
    }
}

/// Reads a single-file NIfTI-1 volume held in memory, plain or gzip-compressed; `path`
/// only names the file in errors. A `ni1` header is refused (its voxels are in another
/// file).
pub fn read_nifti_bytes(bytes: &[u8], path: &Path) -> Result<AnyVolume> {
    read_nifti_bytes_frame(bytes, path, None)
}

/// [`read_nifti_bytes`] of one 3-D volume of a file that holds several
/// ([`read_nifti_frame`]).
pub fn read_nifti_bytes_frame(
    bytes: &[u8],
    path: &Path,
    frame: Option<usize>,
) -> Result<AnyVolume> {
    let (mut reader, size) = maybe_gzip(bytes, bytes.len() as u64, path)?;
    let header = read_header(&mut reader, path, frame)?;
    if header.pair {
        return Err(Error::format(
            path,
            "magic",
            "a ni1/ni2 header keeps its voxels in a separate .img file; read the .hdr file \
             by name",
        ));
    }
    read_data(&mut reader, size, header.len as u64, &header, path)
}

/// How much data a stream can hold at most.
#[derive(Clone, Copy, Debug)]
enum Size {
    /// An uncompressed stream of this many bytes.
    Exact(u64),
    /// A gzip stream of this many compressed bytes.
    Gzip(u64),
}

/// Wraps `reader` in a gzip decoder when it starts with the gzip magic.
fn maybe_gzip<'a, R: Read + 'a>(
    mut reader: R,
    len: u64,
    path: &Path,
) -> Result<(Box<dyn Read + 'a>, Size)> {
    let mut magic = [0u8; 2];
    let got = fill(&mut reader, &mut magic).map_err(|e| read_error(path, e))?;
    let head = io::Cursor::new(magic[..got].to_vec());
    let chained = head.chain(reader);
    if got == 2 && magic == [0x1f, 0x8b] {
        Ok((Box::new(MultiGzDecoder::new(chained)), Size::Gzip(len)))
    } else {
        Ok((Box::new(chained), Size::Exact(len)))
    }
}

/// `X.hdr` → `X.img`, `X.hdr.gz` → `X.img.gz` (keeping the case of the extension).
fn image_path(path: &Path) -> Result<PathBuf> {
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    let lower = name.to_ascii_lowercase();
    let stem_len = if lower.ends_with(".hdr.gz") {
        name.len() - 7
    } else if lower.ends_with(".hdr") {
        name.len() - 4
    } else {
        return Err(Error::format(
            path,
            "magic",
            "a ni1 header (a .hdr/.img pair) must be named X.hdr or X.hdr.gz",
        ));
    };
    let ext = &name[stem_len + 1..];
    let img_ext: String = ext
        .chars()
        .zip("img".chars().chain(ext.chars().skip(3)))
        .map(|(c, r)| {
            if c.is_ascii_uppercase() {
                r.to_ascii_uppercase()
            } else {
                r
            }
        })
        .collect();
    Ok(path.with_file_name(format!("{}.{img_ext}", &name[..stem_len])))
}

/// What the header says, validated.
#[derive(Clone, Debug)]
struct Header {
    endian: Endian,
    stored: Stored,
    dims: [usize; 3],
    count: usize,
    /// 3-D volumes in the file (the product of `dim[4..]`), and the one read.
    frames: usize,
    frame: usize,
    vox_offset: u64,
    /// `(slope, inter)` when the values are scaled.
    scale: Option<(f64, f64)>,
    affine: DMat4,
    /// `ni1`/`ni2`: the voxels are in a separate `.img` file.
    pair: bool,
    /// Bytes of the header (348 for NIfTI-1, 540 for NIfTI-2).
    len: usize,
}

/// Bytes in a NIfTI-2 header.
pub const HEADER2_LEN: usize = 540;

/// The fields voxlab reads, where each version keeps them.
#[derive(Clone, Copy, Debug)]
enum Field {
    Dim(usize),
    Datatype,
    Bitpix,
    Pixdim(usize),
    VoxOffset,
    SclSlope,
    SclInter,
    QformCode,
    SformCode,
    /// quatern_b, c, d, then qoffset_x, y, z.
    Quatern(usize),
    /// srow_x[0..4], srow_y, srow_z.
    Srow(usize),
}

/// Typed access to the raw header bytes of either version.
struct Raw<'a> {
    b: &'a [u8],
    endian: Endian,
    /// 1 or 2.
    version: u8,
}

impl Raw<'_> {
    fn bytes<const N: usize>(&self, off: usize) -> [u8; N] {
        let mut a = [0u8; N];
        a.copy_from_slice(&self.b[off..off + N]);
        if self.endian == Endian::Big {
            a.reverse();
        }
        a
    }
    /// The field's offset and its width in bytes (integers) for this version.
    fn place(&self, f: Field) -> (usize, usize) {
        match (self.version, f) {
            (1, Field::Dim(i)) => (40 + 2 * i, 2),
            (1, Field::Datatype) => (70, 2),
            (1, Field::Bitpix) => (72, 2),
            (1, Field::Pixdim(i)) => (76 + 4 * i, 4),
            (1, Field::VoxOffset) => (108, 4),
            (1, Field::SclSlope) => (112, 4),
            (1, Field::SclInter) => (116, 4),
            (1, Field::QformCode) => (252, 2),
            (1, Field::SformCode) => (254, 2),
            (1, Field::Quatern(i)) => (256 + 4 * i, 4),
            (1, Field::Srow(i)) => (280 + 4 * i, 4),
            (_, Field::Dim(i)) => (16 + 8 * i, 8),
            (_, Field::Datatype) => (12, 2),
            (_, Field::Bitpix) => (14, 2),
            (_, Field::Pixdim(i)) => (104 + 8 * i, 8),
            (_, Field::VoxOffset) => (168, 8),
            (_, Field::SclSlope) => (176, 8),
            (_, Field::SclInter) => (184, 8),
            (_, Field::QformCode) => (344, 4),
            (_, Field::SformCode) => (348, 4),
            (_, Field::Quatern(i)) => (352 + 8 * i, 8),
            (_, Field::Srow(i)) => (400 + 8 * i, 8),
        }
    }
    /// An integer field (i16 in NIfTI-1; i16, i32 or i64 in NIfTI-2), little-endian
    /// bytes after [`Raw::bytes`]'s swap.
    fn int(&self, f: Field) -> i64 {
        let (off, w) = self.place(f);
        match w {
            2 => i64::from(i16::from_le_bytes(self.bytes::<2>(off))),
            4 => i64::from(i32::from_le_bytes(self.bytes::<4>(off))),
            _ => i64::from_le_bytes(self.bytes::<8>(off)),
        }
    }
    /// A real field (f32 in NIfTI-1, f64 in NIfTI-2) as f64; `vox_offset` too (an f32
    /// in NIfTI-1, an i64 in NIfTI-2).
    fn real(&self, f: Field) -> f64 {
        let (off, w) = self.place(f);
        match (w, f) {
            (8, Field::VoxOffset) => i64::from_le_bytes(self.bytes::<8>(off)) as f64,
            (4, _) => f64::from(f32::from_le_bytes(self.bytes::<4>(off))),
            _ => f64::from_le_bytes(self.bytes::<8>(off)),
        }
    }
    /// The spatial unit's code (`xyzt_units & 7`).
    fn space_unit(&self) -> u8 {
        if self.version == 1 {
            self.b[123] & 0x07
        } else {
            (i32::from_le_bytes(self.bytes::<4>(500)) & 0x07) as u8
        }
    }
    /// The magic: whether the voxels are in a separate file (`ni1`, `ni2`).
    fn pair(&self, path: &Path) -> Result<bool> {
        let (magic, one, pair) = if self.version == 1 {
            (&self.b[344..348], &b"n+1\0"[..], &b"ni1\0"[..])
        } else {
            (
                &self.b[4..12],
                &b"n+2\0\r\n\x1a\n"[..],
                &b"ni2\0\r\n\x1a\n"[..],
            )
        };
        if magic == one {
            Ok(false)
        } else if magic == pair {
            Ok(true)
        } else {
            Err(Error::format(
                path,
                "magic",
                if self.version == 1 {
                    format!(
                        "{:?} is neither \"n+1\" nor \"ni1\": not a NIfTI-1 file (Analyze 7.5 \
                         headers without the magic are not supported)",
                        String::from_utf8_lossy(magic)
                    )
                } else {
                    format!(
                        "{:?} is neither \"n+2\" nor \"ni2\" (with \\r\\n\\x1a\\n): not a \
                         NIfTI-2 file",
                        String::from_utf8_lossy(magic)
                    )
                },
            ))
        }
    }
}

fn read_header(reader: &mut dyn Read, path: &Path, frame: Option<usize>) -> Result<Header> {
    let mut b = vec![0u8; HEADER2_LEN];
    let got = fill(reader, &mut b[..4]).map_err(|e| read_error(path, e))?;
    if got < 4 {
        return Err(Error::format(
            path,
            "sizeof_hdr",
            "the file is too short to be a NIfTI file",
        ));
    }
    let sizeof = [b[0], b[1], b[2], b[3]];
    let (endian, version, len) = match (i32::from_le_bytes(sizeof), i32::from_be_bytes(sizeof)) {
        (348, _) => (Endian::Little, 1, HEADER_LEN),
        (_, 348) => (Endian::Big, 1, HEADER_LEN),
        (540, _) => (Endian::Little, 2, HEADER2_LEN),
        (_, 540) => (Endian::Big, 2, HEADER2_LEN),
        (v, _) => {
            return Err(Error::format(
                path,
                "sizeof_hdr",
                format!(
                    "{v} is neither 348 (NIfTI-1) nor 540 (NIfTI-2) in either byte order: \
                     not a NIfTI file"
                ),
            ))
        }
    };
    let got = 4 + fill(reader, &mut b[4..len]).map_err(|e| read_error(path, e))?;
    if got < len {
        return Err(truncated_header(path, got, len));
    }
    b.truncate(len);
    parse_header(
        &Raw {
            b: &b,
            endian,
            version,
        },
        path,
        frame,
    )
}

fn parse_header(h: &Raw, path: &Path, frame: Option<usize>) -> Result<Header> {
    let err = |field: &str, msg: String| Error::format(path, field, msg);
    let pair = h.pair(path)?;
    let dim: Vec<i64> = (0..8).map(|i| h.int(Field::Dim(i))).collect();
    let ndim = dim[0];
    if !(1..=7).contains(&ndim) {
        return Err(err("dim[0]", format!("{ndim} axes: must be from 1 to 7")));
    }
    let ndim = ndim as usize;
    let mut dims = [1usize; 3];
    let mut frames = 1usize;
    for (i, &d) in dim.iter().enumerate().take(ndim + 1).skip(1) {
        if d < 1 {
            return Err(err(
                &format!("dim[{i}]"),
                format!("{d}: sizes must be at least 1"),
            ));
        }
        let d = usize::try_from(d).unwrap_or(usize::MAX);
        if i <= 3 {
            dims[i - 1] = d;
        } else {
            frames = frames
                .checked_mul(d)
                .ok_or_else(|| err(&format!("dim[{i}]"), format!("{d}: too many volumes")))?;
        }
    }
    let count = check_dims(dims).map_err(|e| err("dim", e.to_string()))?;
    let axes = dim.get(4..=ndim).map(extra_axes).unwrap_or_default();
    let frame = super::choose_frame(path, "dim[4]", frames, &axes, frame)?;
    count
        .checked_mul(frames)
        .filter(|&n| n <= (1usize << 62))
        .ok_or_else(|| {
            err(
                "dim",
                format!("{frames} volumes of {count} voxels: too many"),
            )
        })?;

    let datatype = h.int(Field::Datatype);
    let stored = match datatype {
        2 => Stored::U8,
        256 => Stored::I8,
        4 => Stored::I16,
        512 => Stored::U16,
        8 => Stored::I32,
        768 => Stored::U32,
        1024 => Stored::I64,
        1280 => Stored::U64,
        16 => Stored::F32,
        64 => Stored::F64,
        other => {
            let name = match other {
                0 => "unknown",
                1 => "binary (1 bit)",
                32 => "complex64",
                128 => "RGB24",
                1536 => "float128",
                1792 => "complex128",
                2048 => "complex256",
                2304 => "RGBA32",
                _ => "not a NIfTI datatype",
            };
            return Err(err(
                "datatype",
                format!(
                    "{other} ({name}) is not supported; voxlab reads the scalar types \
                     u8, i8, i16, u16, i32, u32, i64, u64, f32 and f64"
                ),
            ));
        }
    };
    let bitpix = h.int(Field::Bitpix);
    if bitpix != stored.size() as i64 * 8 {
        return Err(err(
            "bitpix",
            format!(
                "{bitpix} does not match datatype {datatype} ({} bits)",
                stored.size() * 8
            ),
        ));
    }

    let header_len = h.b.len();
    let vox_offset = h.real(Field::VoxOffset);
    let min_offset = if pair { 0.0 } else { (header_len + 4) as f64 };
    if !vox_offset.is_finite() || vox_offset.fract() != 0.0 || vox_offset < min_offset {
        return Err(err(
            "vox_offset",
            format!(
                "{vox_offset} must be a whole number of bytes, at least {min_offset}{}",
                if pair { "" } else { " in a single .nii file" }
            ),
        ));
    }
    // No file holds 2^53 bytes: a larger offset is refused as such here, rather than
    // saturated to u64::MAX and printed so below.
    if vox_offset >= 9.007_199e15 {
        return Err(err(
            "vox_offset",
            format!("{vox_offset:e} bytes is past the end of any file"),
        ));
    }
    // A whole number below 2^53 converts exactly.
    let vox_offset = vox_offset as u64;

    let slope = h.real(Field::SclSlope);
    let inter = h.real(Field::SclInter);
    let scale = if slope != 0.0 && slope.is_finite() && (slope, inter) != (1.0, 0.0) {
        if !inter.is_finite() {
            return Err(err(
                "scl_inter",
                format!("{inter} is not finite while scl_slope {slope} asks for scaling"),
            ));
        }
        Some((slope, inter))
    } else {
        None
    };

    let affine = geometry(h, path)?;
    Ok(Header {
        endian: h.endian,
        stored,
        dims,
        count,
        frames,
        frame,
        vox_offset,
        scale,
        affine,
        pair,
        len: header_len,
    })
}

/// The axes past the third, named as NIfTI names them: `t 10`, `u 3` …
fn extra_axes(dim: &[i64]) -> String {
    dim.iter()
        .zip(["t", "u", "v", "w"])
        .map(|(d, name)| format!("{name} {d}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The voxel-to-world affine in millimetres (see the module docs for the rules).
fn geometry(h: &Raw, path: &Path) -> Result<DMat4> {
    let qform_code = h.int(Field::QformCode);
    let sform_code = h.int(Field::SformCode);
    let pixdim = |i: usize| h.real(Field::Pixdim(i));
    let (affine, field) = if sform_code > 0 {
        let srow = |i: usize| h.real(Field::Srow(i));
        let row = |r: usize| {
            DVec4::new(
                srow(4 * r),
                srow(4 * r + 1),
                srow(4 * r + 2),
                srow(4 * r + 3),
            )
        };
        let (x, y, z) = (row(0), row(1), row(2));
        let m = DMat4::from_cols(
            DVec4::new(x.x, y.x, z.x, 0.0),
            DVec4::new(x.y, y.y, z.y, 0.0),
            DVec4::new(x.z, y.z, z.z, 0.0),
            DVec4::new(x.w, y.w, z.w, 1.0),
        );
        (m, "sform")
    } else if qform_code > 0 {
        let zooms = [pixdim(1), pixdim(2), pixdim(3)];
        if !zooms.iter().all(|z| z.is_finite() && *z != 0.0) {
            return Err(Error::format(
                path,
                "pixdim",
                format!("voxel size {zooms:?} must be finite and non-zero for the qform"),
            ));
        }
        let qfac = if pixdim(0) < 0.0 { -1.0 } else { 1.0 };
        let q = |i: usize| h.real(Field::Quatern(i));
        let bcd = [q(0), q(1), q(2)];
        let offset = DVec3::new(q(3), q(4), q(5));
        let rot = quaternion_matrix(bcd).ok_or_else(|| {
            Error::format(
                path,
                "qform",
                format!("quaternion (b, c, d) = {bcd:?} is not a rotation"),
            )
        })?;
        let lin = rot * DMat3::from_diagonal(DVec3::new(zooms[0], zooms[1], qfac * zooms[2]));
        (DMat4::from_mat3_translation(lin, offset), "qform")
    } else {
        let d = DVec3::new(pixdim(1), pixdim(2), pixdim(3));
        if !d.is_finite() || d.x == 0.0 || d.y == 0.0 || d.z == 0.0 {
            return Err(Error::format(
                path,
                "pixdim",
                format!("voxel size {:?} must be finite and non-zero", d.to_array()),
            ));
        }
        (DMat4::from_scale(d), "pixdim")
    };
    let unit = match h.space_unit() {
        1 => 1000.0, // metres
        3 => 0.001,  // micrometres
        _ => 1.0,    // millimetres, or unknown
    };
    let affine = DMat4::from_cols(
        affine.x_axis * unit,
        affine.y_axis * unit,
        affine.z_axis * unit,
        (affine.w_axis.truncate() * unit).extend(1.0),
    );
    let det = DMat3::from_mat4(affine).determinant();
    if !affine.is_finite() || !det.is_finite() || det.abs() < 1e-300 {
        return Err(Error::format(
            path,
            field,
            format!(
                "the voxel-to-world affine it gives is {}: {:?}",
                if affine.is_finite() {
                    "singular"
                } else {
                    "not finite"
                },
                affine.transpose().to_cols_array_2d()
            ),
        ));
    }
    Ok(affine)
}

/// The rotation of a NIfTI quaternion `(b, c, d)`, with `a ≥ 0` implied; `None` when
/// `b² + c² + d²` is clearly more than 1 or not finite.
fn quaternion_matrix([b, c, d]: [f64; 3]) -> Option<DMat3> {
    let n2 = b * b + c * c + d * d;
    if !n2.is_finite() || n2 > 1.0 + 1e-4 {
        return None;
    }
    let w2 = 1.0 - n2;
    let a = if w2 > 0.0 { w2.sqrt() } else { 0.0 };
    // Normalising makes the matrix a rotation even when |(b, c, d)| is slightly above 1.
    let q = DQuat::from_xyzw(b, c, d, a);
    let len = q.length();
    if len < 1e-12 {
        return Some(DMat3::IDENTITY);
    }
    Some(DMat3::from_quat(q / len))
}

/// Reads the voxels: skips from `pos` to `vox_offset`, checks that the stream can hold
/// them, reads and scales.
fn read_data(
    reader: &mut dyn Read,
    size: Size,
    pos: u64,
    h: &Header,
    path: &Path,
) -> Result<AnyVolume> {
    let bytes = h.count as u64 * h.stored.size() as u64;
    // Every volume of the file must be there, though one is read.
    let all = bytes.saturating_mul(h.frames as u64);
    let end = h.vox_offset.saturating_add(all);
    match size {
        Size::Exact(len) => {
            if h.vox_offset > len {
                return Err(Error::format(
                    path,
                    "vox_offset",
                    format!("{} is past the end of the file ({len} bytes)", h.vox_offset),
                ));
            }
            if len < end {
                return Err(too_short(path, all, len - h.vox_offset));
            }
        }
        Size::Gzip(len) => {
            let most = len.saturating_mul(MAX_DEFLATE_RATIO).saturating_add(1024);
            if most < end {
                return Err(Error::format(
                    path,
                    "data",
                    format!(
                        "the data is too short: {all} bytes from offset {} cannot fit in \
                         {len} bytes of gzip data",
                        h.vox_offset
                    ),
                ));
            }
        }
    }
    let skip = h
        .vox_offset
        .saturating_add(bytes * h.frame as u64)
        .saturating_sub(pos);
    let skipped =
        io::copy(&mut reader.take(skip), &mut io::sink()).map_err(|e| read_error(path, e))?;
    if skipped < skip {
        return Err(Error::format(
            path,
            "vox_offset",
            format!("{} is past the end of the data", h.vox_offset),
        ));
    }
    let samples = read_samples(reader, h.stored, h.endian, h.count, path)?;
    if let Size::Gzip(_) = size {
        // Reading to the end checks the gzip trailer (CRC and length).
        io::copy(reader, &mut io::sink()).map_err(|e| read_error(path, e))?;
    }
    match h.scale {
        None => samples.into_volume(h.dims, h.affine),
        Some((slope, inter)) => {
            let values = match samples {
                Samples::F32(v) => v,
                other => other.into_f32(),
            };
            let scaled: Vec<f32> = values
                .into_iter()
                .map(|x| (f64::from(x) * slope + inter) as f32)
                .collect();
            Ok(Volume::with_affine(h.dims, h.affine, scaled)?.into())
        }
    }
}

// ---------------------------------------------------------------------------------
// Writing
// ---------------------------------------------------------------------------------

/// Which NIfTI a writer writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NiftiVersion {
    /// NIfTI-1 (348-byte header, f32 geometry, axes of at most 32767 voxels).
    One,
    /// NIfTI-2 (540-byte header, f64 geometry, 64-bit sizes).
    Two,
}

/// Writes a volume as a little-endian NIfTI single file, gzip-compressed when the name
/// ends in `.gz`, atomically (see the module docs for the fields written): NIfTI-1, or
/// NIfTI-2 when an axis is longer than NIfTI-1 can store.
pub fn write_nifti(path: &Path, vol: &AnyVolume) -> Result<()> {
    let version = if vol.dims().iter().any(|&d| d > i16::MAX as usize) {
        NiftiVersion::Two
    } else {
        NiftiVersion::One
    };
    write_nifti_version(path, vol, version)
}

/// [`write_nifti`] in the given version.
pub fn write_nifti_version(path: &Path, vol: &AnyVolume, version: NiftiVersion) -> Result<()> {
    let header = match version {
        NiftiVersion::One => header_bytes(vol, path)?,
        NiftiVersion::Two => header2_bytes(vol),
    };
    let gzip = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"));
    write_atomic(path, |w| {
        let result = if gzip {
            let mut gz = GzEncoder::new(w, Compression::default());
            gz.write_all(&header)
                .and_then(|()| write_samples_le(&mut gz, vol))
                .and_then(|()| gz.finish().map(|_| ()))
        } else {
            w.write_all(&header).and_then(|()| write_samples_le(w, vol))
        };
        result.map_err(|e| Error::io(path, e))
    })
}

/// The geometry as NIfTI's quaternion fields: `(qfac, [b, c, d], pixdim[1..3])`, when
/// the linear part is a rotation times positive scales (with at most one reflection).
fn qform_of(affine: DMat4) -> Option<(f64, [f64; 3], [f64; 3])> {
    let m = DMat3::from_mat4(affine);
    let s = [m.x_axis.length(), m.y_axis.length(), m.z_axis.length()];
    if s.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        return None;
    }
    let mut r = DMat3::from_cols(m.x_axis / s[0], m.y_axis / s[1], m.z_axis / s[2]);
    let qfac = if r.determinant() < 0.0 { -1.0 } else { 1.0 };
    r.z_axis *= qfac;
    let err = (r.transpose() * r - DMat3::IDENTITY).to_cols_array();
    if err.iter().any(|e| e.abs() > 1e-6) {
        return None;
    }
    let mut q = DQuat::from_mat3(&r).normalize();
    if q.w < 0.0 {
        q = -q;
    }
    Some((qfac, [q.x, q.y, q.z], s))
}

/// The 352 bytes before the voxels: header and an empty extension flag.
fn header_bytes(vol: &AnyVolume, path: &Path) -> Result<Vec<u8>> {
    let dims = vol.dims();
    if let Some(&d) = dims.iter().find(|&&d| d > i16::MAX as usize) {
        return Err(Error::invalid(
            "volume for NIfTI-1",
            format!(
                "{}: an axis of {d} voxels cannot be stored (NIfTI-1 sizes are at most 32767)",
                path.display()
            ),
        ));
    }
    let (datatype, bitpix): (i16, i16) = match vol.kind() {
        VoxelKind::U8 => (2, 8),
        VoxelKind::U16 => (512, 16),
        VoxelKind::I16 => (4, 16),
        VoxelKind::F32 => (16, 32),
    };
    let affine = vol.affine();
    let mut b = vec![0u8; WRITE_OFFSET];
    let put_i16 =
        |b: &mut [u8], off: usize, v: i16| b[off..off + 2].copy_from_slice(&v.to_le_bytes());
    let put_f32 = |b: &mut [u8], off: usize, v: f64| {
        b[off..off + 4].copy_from_slice(&(v as f32).to_le_bytes())
    };
    b[0..4].copy_from_slice(&(HEADER_LEN as i32).to_le_bytes());
    b[38] = b'r'; // "regular", an Analyze field most writers set
    let dim = [
        3,
        dims[0] as i16,
        dims[1] as i16,
        dims[2] as i16,
        1,
        1,
        1,
        1,
    ];
    for (i, d) in dim.iter().enumerate() {
        put_i16(&mut b, 40 + 2 * i, *d);
    }
    put_i16(&mut b, 70, datatype);
    put_i16(&mut b, 72, bitpix);
    let qform = qform_of(affine);
    let lin = DMat3::from_mat4(affine);
    let lengths = [
        lin.x_axis.length(),
        lin.y_axis.length(),
        lin.z_axis.length(),
    ];
    let qfac = match qform {
        Some((qfac, _, _)) => qfac,
        None if lin.determinant() < 0.0 => -1.0,
        None => 1.0,
    };
    let pixdim = [qfac, lengths[0], lengths[1], lengths[2], 1.0, 1.0, 1.0, 1.0];
    for (i, p) in pixdim.iter().enumerate() {
        put_f32(&mut b, 76 + 4 * i, *p);
    }
    put_f32(&mut b, 108, WRITE_OFFSET as f64);
    put_f32(&mut b, 112, 1.0);
    put_f32(&mut b, 116, 0.0);
    b[123] = 2; // millimetres, no time unit
    let descrip = b"voxlab";
    b[148..148 + descrip.len()].copy_from_slice(descrip);
    let t = affine.w_axis;
    if let Some((_, bcd, _)) = qform {
        put_i16(&mut b, 252, 2);
        for (i, v) in bcd.iter().chain([t.x, t.y, t.z].iter()).enumerate() {
            put_f32(&mut b, 256 + 4 * i, *v);
        }
    }
    put_i16(&mut b, 254, 2);
    for r in 0..3 {
        let row = affine.row(r);
        for (c, v) in row.to_array().iter().enumerate() {
            put_f32(&mut b, 280 + 16 * r + 4 * c, *v);
        }
    }
    b[344..348].copy_from_slice(b"n+1\0");
    Ok(b)
}

/// The 544 bytes before the voxels of a NIfTI-2 single file: header and an empty
/// extension flag. The geometry is stored in f64, so it round-trips exactly.
fn header2_bytes(vol: &AnyVolume) -> Vec<u8> {
    let dims = vol.dims();
    let (datatype, bitpix): (i16, i16) = match vol.kind() {
        VoxelKind::U8 => (2, 8),
        VoxelKind::U16 => (512, 16),
        VoxelKind::I16 => (4, 16),
        VoxelKind::F32 => (16, 32),
    };
    let affine = vol.affine();
    let mut b = vec![0u8; HEADER2_LEN + 4];
    let put_f64 =
        |b: &mut [u8], off: usize, v: f64| b[off..off + 8].copy_from_slice(&v.to_le_bytes());
    b[0..4].copy_from_slice(&(HEADER2_LEN as i32).to_le_bytes());
    b[4..12].copy_from_slice(b"n+2\0\r\n\x1a\n");
    b[12..14].copy_from_slice(&datatype.to_le_bytes());
    b[14..16].copy_from_slice(&bitpix.to_le_bytes());
    let dim = [
        3,
        dims[0] as i64,
        dims[1] as i64,
        dims[2] as i64,
        1,
        1,
        1,
        1,
    ];
    for (i, d) in dim.iter().enumerate() {
        b[16 + 8 * i..24 + 8 * i].copy_from_slice(&d.to_le_bytes());
    }
    let qform = qform_of(affine);
    let lin = DMat3::from_mat4(affine);
    let qfac = match qform {
        Some((qfac, _, _)) => qfac,
        None if lin.determinant() < 0.0 => -1.0,
        None => 1.0,
    };
    let pixdim = [
        qfac,
        lin.x_axis.length(),
        lin.y_axis.length(),
        lin.z_axis.length(),
        1.0,
        1.0,
        1.0,
        1.0,
    ];
    for (i, p) in pixdim.iter().enumerate() {
        put_f64(&mut b, 104 + 8 * i, *p);
    }
    b[168..176].copy_from_slice(&((HEADER2_LEN + 4) as i64).to_le_bytes());
    put_f64(&mut b, 176, 1.0);
    put_f64(&mut b, 184, 0.0);
    let descrip = b"voxlab";
    b[240..240 + descrip.len()].copy_from_slice(descrip);
    let t = affine.w_axis;
    if let Some((_, bcd, _)) = qform {
        b[344..348].copy_from_slice(&2i32.to_le_bytes());
        for (i, v) in bcd.iter().chain([t.x, t.y, t.z].iter()).enumerate() {
            put_f64(&mut b, 352 + 8 * i, *v);
        }
    }
    b[348..352].copy_from_slice(&2i32.to_le_bytes());
    for r in 0..3 {
        for (c, v) in affine.row(r).to_array().iter().enumerate() {
            put_f64(&mut b, 400 + 32 * r + 8 * c, *v);
        }
    }
    // Millimetres, no time unit.
    b[500..504].copy_from_slice(&2i32.to_le_bytes());
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_round_trip() {
        let q = DQuat::from_axis_angle(DVec3::new(1.0, -2.0, 0.5).normalize(), 2.5);
        let lin = DMat3::from_quat(q) * DMat3::from_diagonal(DVec3::new(0.5, 2.0, -3.0));
        let affine = DMat4::from_mat3_translation(lin, DVec3::new(1.0, 2.0, 3.0));
        let (qfac, bcd, s) = qform_of(affine).unwrap();
        assert_eq!(qfac, -1.0);
        let back = quaternion_matrix(bcd).unwrap()
            * DMat3::from_diagonal(DVec3::new(s[0], s[1], qfac * s[2]));
        assert!(back.abs_diff_eq(lin, 1e-12), "{back:?} vs {lin:?}");
        // A shear has no quaternion.
        let shear = DMat4::from_cols_array(&[
            1.0, 0.0, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
        ]);
        assert!(qform_of(shear).is_none());
    }

    #[test]
    fn quaternion_edge_cases() {
        assert_eq!(quaternion_matrix([0.0; 3]), Some(DMat3::IDENTITY));
        // A 180° turn about x: b = 1, a = 0.
        let m = quaternion_matrix([1.0, 0.0, 0.0]).unwrap();
        assert!(m.abs_diff_eq(DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0)), 1e-12));
        // Slightly above 1 is normalised; far above is refused.
        assert!(quaternion_matrix([0.0, 1.00001, 0.0]).is_some());
        assert!(quaternion_matrix([0.0, 2.0, 0.0]).is_none());
        assert!(quaternion_matrix([f64::NAN, 0.0, 0.0]).is_none());
    }

    #[test]
    fn image_names() {
        assert_eq!(
            image_path(Path::new("a/x.hdr")).unwrap(),
            Path::new("a/x.img")
        );
        assert_eq!(image_path(Path::new("x.HDR")).unwrap(), Path::new("x.IMG"));
        assert_eq!(
            image_path(Path::new("x.hdr.gz")).unwrap(),
            Path::new("x.img.gz")
        );
        assert!(image_path(Path::new("x.nii")).is_err());
    }
}
