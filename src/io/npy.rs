//! NumPy `.npy` files (format versions 1.0, 2.0 and 3.0), read and written by hand.
//!
//! # The format
//!
//! ```text
//! "\x93NUMPY"  major  minor  header length   header                         data
//!  6 bytes     1 byte 1 byte u16 LE (1.0)    a Python dict literal, padded  the array's
//!                            u32 LE (2.0,    with spaces to a multiple of   bytes
//!                                    3.0)    64 and ended by '\n'
//! ```
//!
//! The header looks like `{'descr': '<f4', 'fortran_order': False, 'shape': (3, 4), }`:
//! `descr` is the dtype (byte order `<` little, `>` big, `|` not applicable, then kind
//! and size in bytes), `shape` the array's shape, and `fortran_order` the memory order:
//! `False` means C order (the last axis is fastest), `True` Fortran order (the first
//! axis is fastest). Version 3.0 only allows UTF-8 in the header.
//!
//! # Volumes
//!
//! A volume is the array `a[z, y, x]` of shape `(nz, ny, nx)`: in C order x is fastest,
//! which is the crate's memory order, so the bytes are used as they are. A 2-D array
//! `(ny, nx)` is a volume with `nz = 1`. The array is read exactly as `numpy.load`
//! would return it: **a Fortran-order array means the same `a[z, y, x]`**, only laid
//! out differently in the file, so its samples are reordered into x-fastest order
//! (which briefly needs memory for a second copy). An array indexed `a[x, y, z]` (as
//! nibabel returns them) is therefore read with x and z swapped whichever order it was
//! saved in; save `a.T` instead.
//!
//! `.npy` carries no geometry: volumes read from it have 1 mm spacing and the identity
//! affine, and [`write_npy_volume`] drops the affine.
//!
//! Volume dtypes: `u1`, `i1`, `u2`, `i2`, `f4` and `f8` in either byte order, read as
//! u8, i16 (exact), u16, i16, f32 and f32 (rounded to nearest; see [`crate::io`]).
//! Other dtypes (bool, 32/64-bit integers, complex, structured) are refused with a
//! message listing the supported ones.

use super::{open, read_samples, too_short, write_atomic, write_le, write_samples_le};
use super::{Endian, Samples, Stored};
use crate::error::{Error, Result};
use crate::volume::{check_dims, max_voxels, AnyVolume, VoxelKind};
use glam::DMat4;
use std::io::{BufReader, Read};
use std::path::Path;

/// The first six bytes of every `.npy` file.
const MAGIC: &[u8; 6] = b"\x93NUMPY";

/// The dtypes a volume can be read from, and how the error message lists them.
const VOLUME_TYPES: &[Stored] = &[
    Stored::U8,
    Stored::I8,
    Stored::U16,
    Stored::I16,
    Stored::F32,
    Stored::F64,
];
const VOLUME_TYPES_TEXT: &str = "|u1, |i1, <u2, >u2, <i2, >i2, <f4, >f4, <f8, >f8";

/// The dtypes [`read_npy_f32`] accepts.
const FLOAT_TYPES: &[Stored] = &[Stored::F32, Stored::F64];
const FLOAT_TYPES_TEXT: &str = "<f4, >f4, <f8, >f8";

/// Reads a volume from a `.npy` file: a 3-D array `(nz, ny, nx)` or a 2-D array
/// `(ny, nx)` (then `nz = 1`), with 1 mm spacing and the identity affine.
pub fn read_npy_volume(path: &Path) -> Result<AnyVolume> {
    let (file, len) = open(path)?;
    volume_from_reader(&mut BufReader::new(file), len, path)
}

/// Reads an array of any number of dimensions whose dtype is `f4` or `f8` (either
/// byte order; `f8` is rounded to f32) and returns its shape and its values in C order
/// (the last axis fastest), whatever order the file used.
pub fn read_npy_f32(path: &Path) -> Result<(Vec<usize>, Vec<f32>)> {
    let (file, len) = open(path)?;
    f32_from_reader(&mut BufReader::new(file), len, path)
}

/// Writes a volume as a little-endian C-order array of shape `(nz, ny, nx)` (dtype
/// `|u1`, `<u2`, `<i2` or `<f4`), atomically. The geometry is not stored.
pub fn write_npy_volume(path: &Path, vol: &AnyVolume) -> Result<()> {
    let [nx, ny, nz] = vol.dims();
    let descr = match vol.kind() {
        VoxelKind::U8 => "|u1",
        VoxelKind::U16 => "<u2",
        VoxelKind::I16 => "<i2",
        VoxelKind::F32 => "<f4",
    };
    let header = header_bytes(descr, &[nz, ny, nx]);
    write_atomic(path, |w| {
        w.write_all(&header)
            .and_then(|()| write_samples_le(w, vol))
            .map_err(|e| Error::io(path, e))
    })
}

/// Writes `data` as a little-endian float32 array of the given shape in C order (the
/// last axis fastest), atomically. A scalar image is `(h, w)`, an RGBA image
/// `(h, w, 4)`. Fails with [`Error::Invalid`] when the shape does not hold exactly
/// `data.len()` values.
pub fn write_npy_f32(path: &Path, shape: &[usize], data: &[f32]) -> Result<()> {
    write_npy_array(path, "<f4", shape, data)
}

/// Writes `data` little-endian under the dtype `descr`, checking that `shape` holds
/// exactly `data.len()` values.
fn write_npy_array<T: bytemuck::Pod>(
    path: &Path,
    descr: &str,
    shape: &[usize],
    data: &[T],
) -> Result<()> {
    let n = shape.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d));
    if n != Some(data.len()) {
        return Err(Error::invalid(
            "array shape",
            format!(
                "{}: shape {shape:?} does not hold the {} values given",
                path.display(),
                data.len()
            ),
        ));
    }
    let header = header_bytes(descr, shape);
    write_atomic(path, |w| {
        w.write_all(&header)
            .and_then(|()| write_le(w, data))
            .map_err(|e| Error::io(path, e))
    })
}

/// Reads an array of any number of dimensions whose dtype is `f4` or `f8` (either
/// byte order) **without rounding**: its shape, its values in C order as f64 (an `f4`
/// file widens exactly), and whether the file stored `f8`.
pub fn read_npy_f64(path: &Path) -> Result<(Vec<usize>, Vec<f64>, bool)> {
    let (file, len) = open(path)?;
    let reader = &mut BufReader::new(file);
    let h = read_header(reader, len, path, FLOAT_TYPES, FLOAT_TYPES_TEXT)?;
    let size = h.stored.size();
    check_data(&h, len, path)?;
    let mut bytes = super::reserve::<u8>(h.count * size, path)?;
    bytes.resize(h.count * size, 0);
    reader
        .read_exact(&mut bytes)
        .map_err(|e| super::read_error(path, e))?;
    let mut values = super::reserve::<f64>(h.count, path)?;
    values.resize(h.count, 0.0);
    decode_f64(&bytes, size, h.endian == Endian::Big, &mut values);
    let values = if h.fortran_order {
        reorder(values, &h.shape)
    } else {
        values
    };
    Ok((h.shape, values, size == 8))
}

/// Whether the file (`len` bytes) holds all the data its header announces.
fn check_data(h: &Header, len: u64, path: &Path) -> Result<()> {
    let expected = h.count as u64 * h.stored.size() as u64;
    let available = len.saturating_sub(h.data_offset);
    if available < expected {
        return Err(too_short(path, expected, available));
    }
    Ok(())
}

/// Decodes `f4` or `f8` samples (`size` 4 or 8 bytes, big-endian when `big`) into `out`
/// as f64 (an `f4` widens exactly).
fn decode_f64(bytes: &[u8], size: usize, big: bool, out: &mut [f64]) {
    for (v, c) in out.iter_mut().zip(bytes.chunks_exact(size)) {
        *v = if size == 8 {
            let a: [u8; 8] = c.try_into().expect("8-byte chunk");
            if big {
                f64::from_be_bytes(a)
            } else {
                f64::from_le_bytes(a)
            }
        } else {
            let a: [u8; 4] = c.try_into().expect("4-byte chunk");
            f64::from(if big {
                f32::from_be_bytes(a)
            } else {
                f32::from_le_bytes(a)
            })
        };
    }
}

/// The header of `path`, read alone, with the data checked to be all there.
fn header_only(path: &Path, allowed: &[Stored], allowed_text: &str) -> Result<Header> {
    let (file, len) = open(path)?;
    let h = read_header(&mut BufReader::new(file), len, path, allowed, allowed_text)?;
    check_data(&h, len, path)?;
    Ok(h)
}

/// The shape of a float `.npy` file (`f4` or `f8`, either byte order) and whether it is
/// stored in Fortran order, from its header alone (the data is only checked to be
/// there, not read).
pub fn npy_float_shape(path: &Path) -> Result<(Vec<usize>, bool)> {
    let h = header_only(path, FLOAT_TYPES, FLOAT_TYPES_TEXT)?;
    Ok((h.shape, h.fortran_order))
}

/// [`read_npy_f64`] of only some lines of a C-order float array, a line being a run of
/// `shape.last()` values (line `l` holds the values `l·n … l·n + n − 1`): the array's
/// shape, the lines of `lines` in increasing order (each once) and their values, line
/// after line. Only those lines are read from the file (one positioned read per run of
/// consecutive lines) or held.
///
/// # Errors
/// As [`read_npy_f64`]; a Fortran-order file (whose lines are not contiguous); a line
/// past the array.
pub fn read_npy_f64_lines(
    path: &Path,
    lines: &[usize],
) -> Result<(Vec<usize>, Vec<usize>, Vec<f64>)> {
    let (file, len) = open(path)?;
    let mut reader = BufReader::new(file);
    let h = read_header(&mut reader, len, path, FLOAT_TYPES, FLOAT_TYPES_TEXT)?;
    if h.fortran_order {
        return Err(Error::format(
            path,
            "fortran_order",
            "a Fortran-order array cannot be read line by line: save it in C order",
        ));
    }
    let size = h.stored.size();
    check_data(&h, len, path)?;
    let n = h.shape.last().copied().unwrap_or(1).max(1);
    let total_lines = h.count / n;
    if let Some(&bad) = lines.iter().find(|&&l| l >= total_lines) {
        return Err(Error::invalid(
            format!("lines of {}", path.display()),
            format!("line {bad} is past the array's {total_lines} lines"),
        ));
    }
    let big = h.endian == Endian::Big;
    let mut wanted = lines.to_vec();
    wanted.sort_unstable();
    wanted.dedup();
    let mut values = super::reserve::<f64>(wanted.len() * n, path)?;
    values.resize(wanted.len() * n, 0.0);
    super::read_line_runs(
        reader.get_ref(),
        path,
        h.data_offset,
        n * size,
        &wanted,
        |at, bytes| {
            decode_f64(
                bytes,
                size,
                big,
                &mut values[at * n..at * n + bytes.len() / size],
            );
            Ok(())
        },
    )?;
    Ok((h.shape, wanted, values))
}

/// Where a C-order volume `.npy` file (a 2-D or 3-D array of a volume dtype) keeps its
/// samples, for [`super::brick::read_brick`]; `None` for a Fortran-order one.
pub(crate) fn raw_layout(path: &Path) -> Result<Option<super::RawLayout>> {
    let h = header_only(path, VOLUME_TYPES, VOLUME_TYPES_TEXT)?;
    if h.fortran_order {
        return Ok(None);
    }
    let dims = volume_dims(&h.shape, path)?;
    Ok(Some(super::RawLayout {
        data: path.to_path_buf(),
        offset: h.data_offset,
        stored: h.stored,
        endian: h.endian,
        dims,
        affine: DMat4::IDENTITY,
    }))
}

/// The header of a little-endian float32 C-order `.npy` array of `shape`, as
/// [`write_npy_f32`] writes it (the data follows it directly).
pub fn npy_f32_header(shape: &[usize]) -> Vec<u8> {
    header_bytes("<f4", shape)
}

/// Writes `data` as a little-endian float64 array of the given shape in C order,
/// atomically (the f64 twin of [`write_npy_f32`]).
pub fn write_npy_f64(path: &Path, shape: &[usize], data: &[f64]) -> Result<()> {
    write_npy_array(path, "<f8", shape, data)
}

// ---------------------------------------------------------------------------------
// Reading
// ---------------------------------------------------------------------------------

/// What a `.npy` header says.
#[derive(Clone, Debug, PartialEq)]
struct Header {
    stored: Stored,
    endian: Endian,
    fortran_order: bool,
    shape: Vec<usize>,
    /// How many values the shape holds (checked against [`max_voxels`]).
    count: usize,
    /// Bytes before the data: magic, version, length field and dict.
    data_offset: u64,
}

/// Reads a `.npy` volume held in memory (`path` only names it in errors). Used by the
/// fuzz targets; never panics.
pub fn read_npy_bytes(bytes: &[u8], path: &Path) -> Result<AnyVolume> {
    volume_from_reader(&mut &bytes[..], bytes.len() as u64, path)
}

/// The volume dims (x, y, z) of a 3-D `(nz, ny, nx)` or 2-D `(ny, nx)` array, no axis
/// empty (the limit on the count was checked with the header).
fn volume_dims(shape: &[usize], path: &Path) -> Result<[usize; 3]> {
    let dims = match *shape {
        [nz, ny, nx] => [nx, ny, nz],
        [ny, nx] => [nx, ny, 1],
        _ => {
            return Err(Error::format(
                path,
                "shape",
                format!(
                    "a volume needs a 2-D (ny, nx) or 3-D (nz, ny, nx) array, not shape {shape:?}"
                ),
            ))
        }
    };
    check_dims(dims).map_err(|e| Error::format(path, "shape", e.to_string()))?;
    Ok(dims)
}

fn volume_from_reader(reader: &mut dyn Read, file_len: u64, path: &Path) -> Result<AnyVolume> {
    let header = read_header(reader, file_len, path, VOLUME_TYPES, VOLUME_TYPES_TEXT)?;
    let dims = volume_dims(&header.shape, path)?;
    let samples = read_data(reader, &header, file_len, path)?;
    samples.into_volume(dims, DMat4::IDENTITY)
}

fn f32_from_reader(
    reader: &mut dyn Read,
    file_len: u64,
    path: &Path,
) -> Result<(Vec<usize>, Vec<f32>)> {
    let header = read_header(reader, file_len, path, FLOAT_TYPES, FLOAT_TYPES_TEXT)?;
    let samples = read_data(reader, &header, file_len, path)?;
    Ok((header.shape, samples.into_f32()))
}

/// Reads the samples that follow the header, in C order.
fn read_data(reader: &mut dyn Read, h: &Header, file_len: u64, path: &Path) -> Result<Samples> {
    // `count` is at most the voxel limit (≤ 2^63 / 8), so this cannot overflow on a 64-bit machine;
    // the file length tells whether the data is all there before anything is allocated.
    let expected = h.count as u64 * h.stored.size() as u64;
    let available = file_len.saturating_sub(h.data_offset);
    if available < expected {
        return Err(too_short(path, expected, available));
    }
    let samples = read_samples(reader, h.stored, h.endian, h.count, path)?;
    Ok(if h.fortran_order {
        fortran_to_c(samples, &h.shape)
    } else {
        samples
    })
}

/// Parses the magic, version, length and dict, leaving `reader` at the first data byte.
/// `allowed` lists the dtypes the caller can use (`allowed_text` names them in errors).
fn read_header(
    reader: &mut dyn Read,
    file_len: u64,
    path: &Path,
    allowed: &[Stored],
    allowed_text: &str,
) -> Result<Header> {
    let mut start = [0u8; 8];
    let got = super::fill(reader, &mut start).map_err(|e| Error::io(path, e))?;
    if got < start.len() || &start[..6] != MAGIC {
        return Err(Error::format(
            path,
            "magic",
            "not a .npy file: it does not start with \\x93NUMPY and a version",
        ));
    }
    let (major, minor) = (start[6], start[7]);
    let len_bytes: usize = match major {
        1 => 2,
        2 | 3 => 4,
        _ => {
            return Err(Error::format(
                path,
                "version",
                format!("format version {major}.{minor} is not supported (1.0, 2.0, 3.0 are)"),
            ))
        }
    };
    let mut len_field = [0u8; 4];
    let got = super::fill(reader, &mut len_field[..len_bytes]).map_err(|e| Error::io(path, e))?;
    if got < len_bytes {
        return Err(Error::format(
            path,
            "header length",
            "the file ends inside the header length",
        ));
    }
    let header_len = u32::from_le_bytes(len_field) as u64;
    let data_offset = 8 + len_bytes as u64 + header_len;
    if data_offset > file_len {
        return Err(Error::format(
            path,
            "header length",
            format!(
                "the header claims {header_len} bytes, past the end of the {file_len}-byte file"
            ),
        ));
    }
    // Bounded by the file's length, checked just above.
    let mut raw = vec![0u8; header_len as usize];
    let got = super::fill(reader, &mut raw).map_err(|e| Error::io(path, e))?;
    if got < raw.len() {
        return Err(Error::format(
            path,
            "header",
            "the file ends inside the header",
        ));
    }
    // Versions 1.0 and 2.0 use Latin-1 (each byte is one character), 3.0 UTF-8.
    let text = if major == 3 {
        String::from_utf8(raw)
            .map_err(|_| Error::format(path, "header", "version 3.0 header is not UTF-8"))?
    } else {
        raw.iter().map(|&b| char::from(b)).collect()
    };
    let mut header = parse_dict(&text, path, allowed, allowed_text)?;
    header.data_offset = data_offset;
    Ok(header)
}

/// Interprets the header dict: `descr`, `fortran_order` and `shape` (other keys are
/// ignored).
fn parse_dict(text: &str, path: &Path, allowed: &[Stored], allowed_text: &str) -> Result<Header> {
    let bad = |field: &str, msg: String| Error::format(path, field, msg);
    let value = PyParser::parse(text).map_err(|m| bad("header", m))?;
    let Py::Dict(items) = value else {
        return Err(bad("header", "the header is not a dict".into()));
    };
    let get = |key: &str| {
        items
            .iter()
            .find(|(k, _)| matches!(k, Py::Str(s) if s == key))
            .map(|(_, v)| v)
            .ok_or_else(|| bad(key, format!("the header has no '{key}' key")))
    };

    let (stored, endian) = match get("descr")? {
        Py::Str(s) => parse_descr(s).map_err(|m| bad("descr", m))?,
        Py::List(_) => {
            return Err(bad(
                "descr",
                "structured (record) dtypes are not supported".into(),
            ))
        }
        other => return Err(bad("descr", format!("expected a string, found {other}"))),
    };
    if !allowed.contains(&stored) {
        return Err(bad(
            "descr",
            format!(
                "dtype {} is not supported here; supported are {allowed_text}",
                get("descr")?
            ),
        ));
    }

    let fortran_order = match get("fortran_order")? {
        Py::Word(w) if w == "True" => true,
        Py::Word(w) if w == "False" => false,
        other => {
            return Err(bad(
                "fortran_order",
                format!("expected True or False, found {other}"),
            ))
        }
    };

    let Py::Tuple(entries) = get("shape")? else {
        return Err(bad(
            "shape",
            format!("expected a tuple, found {}", get("shape")?),
        ));
    };
    let mut shape = Vec::with_capacity(entries.len());
    for e in entries {
        shape.push(shape_entry(e).map_err(|m| bad("shape", m))?);
    }
    let count = shape
        .iter()
        .try_fold(1usize, |acc, &d| acc.checked_mul(d))
        .filter(|&n| n <= max_voxels())
        .ok_or_else(|| {
            bad(
                "shape",
                format!(
                    "{shape:?} holds more than the limit of {} values",
                    max_voxels()
                ),
            )
        })?;

    Ok(Header {
        stored,
        endian,
        fortran_order,
        shape,
        count,
        data_offset: 0,
    })
}

/// One entry of the shape tuple: a non-negative integer (Python 2 wrote `3L`).
fn shape_entry(e: &Py) -> std::result::Result<usize, String> {
    let Py::Word(w) = e else {
        return Err(format!("entry {e} is not an integer"));
    };
    let digits = w.strip_suffix('L').unwrap_or(w);
    if let Ok(n) = digits.parse::<usize>() {
        return Ok(n);
    }
    Err(match digits.parse::<i128>() {
        Ok(n) if n < 0 => format!("entry {w} is negative"),
        Ok(_) => format!("entry {w} is too large"),
        Err(_) => format!("entry {w} is not an integer"),
    })
}

/// Parses a dtype string such as `<f4`: byte order, kind and size.
fn parse_descr(s: &str) -> std::result::Result<(Stored, Endian), String> {
    let native = if cfg!(target_endian = "little") {
        Endian::Little
    } else {
        Endian::Big
    };
    let (order, rest) = match s.chars().next() {
        Some('<') => (Some(Endian::Little), &s[1..]),
        Some('>') => (Some(Endian::Big), &s[1..]),
        Some('=') => (Some(native), &s[1..]),
        Some('|') => (None, &s[1..]),
        _ => (None, s),
    };
    let stored = match rest {
        "u1" | "B" => Stored::U8,
        "i1" | "b" => Stored::I8,
        "u2" => Stored::U16,
        "i2" => Stored::I16,
        "u4" => Stored::U32,
        "i4" => Stored::I32,
        "u8" => Stored::U64,
        "i8" => Stored::I64,
        "f4" => Stored::F32,
        "f8" => Stored::F64,
        _ => return Err(format!("dtype '{}' is not supported", super::snippet(s))),
    };
    let endian = match (order, stored.size()) {
        (_, 1) => Endian::Little, // a single byte has no order
        (Some(e), _) => e,
        (None, _) => return Err(format!("dtype '{s}' has no byte order ('<' or '>')")),
    };
    Ok((stored, endian))
}

/// Reorders values from Fortran order to C order (see [`fortran_to_c`]).
fn reorder<T: Copy>(v: Vec<T>, shape: &[usize]) -> Vec<T> {
    // In Fortran order, axis a advances by the product of the axes before it.
    let mut strides = vec![1usize; shape.len()];
    for a in 1..shape.len() {
        strides[a] = strides[a - 1] * shape[a - 1];
    }
    // Walk the array in C order with an odometer, tracking the Fortran offset.
    let mut out = Vec::with_capacity(v.len());
    let mut index = vec![0usize; shape.len()];
    let mut offset = 0usize;
    for _ in 0..v.len() {
        out.push(v[offset]);
        for a in (0..shape.len()).rev() {
            index[a] += 1;
            offset += strides[a];
            if index[a] < shape[a] {
                break;
            }
            offset -= strides[a] * shape[a];
            index[a] = 0;
        }
    }
    out
}

/// Reorders samples from Fortran order (first axis fastest) to C order (last axis
/// fastest); `shape` is the array's shape as the header states it.
fn fortran_to_c(samples: Samples, shape: &[usize]) -> Samples {
    match samples {
        Samples::U8(v) => Samples::U8(reorder(v, shape)),
        Samples::U16(v) => Samples::U16(reorder(v, shape)),
        Samples::I16(v) => Samples::I16(reorder(v, shape)),
        Samples::F32(v) => Samples::F32(reorder(v, shape)),
    }
}

// ---------------------------------------------------------------------------------
// A tiny parser for the Python literals that appear in headers
// ---------------------------------------------------------------------------------

/// A Python literal, as far as `.npy` headers need one.
#[derive(Clone, Debug, PartialEq)]
enum Py {
    Str(String),
    /// A bare word kept as written: a number, `True`, `False`, `None`.
    Word(String),
    Tuple(Vec<Py>),
    List(Vec<Py>),
    Dict(Vec<(Py, Py)>),
}

impl std::fmt::Display for Py {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let list = |f: &mut std::fmt::Formatter<'_>, items: &[Py]| -> std::fmt::Result {
            for (i, item) in items.iter().enumerate() {
                if i > 0 {
                    write!(f, ", ")?;
                }
                write!(f, "{item}")?;
            }
            Ok(())
        };
        match self {
            Py::Str(s) => write!(f, "'{}'", super::snippet(s)),
            Py::Word(w) => write!(f, "{}", super::snippet(w)),
            Py::Tuple(items) => {
                write!(f, "(")?;
                list(f, items)?;
                write!(f, ")")
            }
            Py::List(items) => {
                write!(f, "[")?;
                list(f, items)?;
                write!(f, "]")
            }
            Py::Dict(_) => write!(f, "{{…}}"),
        }
    }
}

/// Nesting deeper than this is refused (headers nest two levels; a bound keeps a
/// garbled header of a million `(` from overflowing the stack).
const MAX_DEPTH: usize = 16;

/// Recursive-descent parser over the header's bytes (all its syntax is ASCII).
struct PyParser<'a> {
    s: &'a [u8],
    pos: usize,
    depth: usize,
}

type ParseResult<T> = std::result::Result<T, String>;

impl<'a> PyParser<'a> {
    /// Parses one literal that must fill the whole text (but for white space).
    fn parse(text: &'a str) -> ParseResult<Py> {
        let mut p = PyParser {
            s: text.as_bytes(),
            pos: 0,
            depth: 0,
        };
        let v = p.value()?;
        p.skip_space();
        if p.pos < p.s.len() {
            return Err(format!("unexpected text after the dict at byte {}", p.pos));
        }
        Ok(v)
    }

    fn skip_space(&mut self) {
        while self.pos < self.s.len() && self.s[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
    }

    fn peek(&self) -> Option<u8> {
        self.s.get(self.pos).copied()
    }

    fn value(&mut self) -> ParseResult<Py> {
        self.skip_space();
        match self.peek() {
            None => Err("the header ends in the middle of the dict".into()),
            Some(q @ (b'\'' | b'"')) => self.string(q),
            Some(b'(') => Ok(Py::Tuple(self.sequence(b')')?)),
            Some(b'[') => Ok(Py::List(self.sequence(b']')?)),
            Some(b'{') => self.dict(),
            Some(c) if is_word_byte(c) => {
                let start = self.pos;
                while self.peek().is_some_and(is_word_byte) {
                    self.pos += 1;
                }
                Ok(Py::Word(self.text(start, self.pos)))
            }
            Some(c) => Err(format!(
                "unexpected character {:?} at byte {}",
                char::from(c),
                self.pos
            )),
        }
    }

    fn text(&self, start: usize, end: usize) -> String {
        String::from_utf8_lossy(&self.s[start..end]).into_owned()
    }

    /// A quoted string; a backslash takes the next byte literally.
    fn string(&mut self, quote: u8) -> ParseResult<Py> {
        let start = self.pos;
        self.pos += 1;
        let mut bytes = Vec::new();
        loop {
            match self.peek() {
                None => return Err(format!("the string starting at byte {start} is not closed")),
                Some(b'\\') => {
                    self.pos += 1;
                    if let Some(c) = self.peek() {
                        bytes.push(c);
                        self.pos += 1;
                    }
                }
                Some(c) if c == quote => {
                    self.pos += 1;
                    return Ok(Py::Str(String::from_utf8_lossy(&bytes).into_owned()));
                }
                Some(c) => {
                    bytes.push(c);
                    self.pos += 1;
                }
            }
        }
    }

    fn enter(&mut self) -> ParseResult<()> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(format!("nesting deeper than {MAX_DEPTH} levels"));
        }
        self.pos += 1; // the opening bracket
        Ok(())
    }

    /// After an item: a comma, or the closing bracket (left for the caller).
    fn separator(&mut self, close: u8) -> ParseResult<()> {
        self.skip_space();
        match self.peek() {
            Some(b',') => {
                self.pos += 1;
                Ok(())
            }
            Some(c) if c == close => Ok(()),
            _ => Err(format!(
                "expected ',' or '{}' at byte {}",
                char::from(close),
                self.pos
            )),
        }
    }

    /// Items up to `close`, with an optional trailing comma.
    fn sequence(&mut self, close: u8) -> ParseResult<Vec<Py>> {
        self.enter()?;
        let mut items = Vec::new();
        loop {
            self.skip_space();
            if self.peek() == Some(close) {
                self.pos += 1;
                self.depth -= 1;
                return Ok(items);
            }
            items.push(self.value()?);
            self.separator(close)?;
        }
    }

    fn dict(&mut self) -> ParseResult<Py> {
        self.enter()?;
        let mut items = Vec::new();
        loop {
            self.skip_space();
            if self.peek() == Some(b'}') {
                self.pos += 1;
                self.depth -= 1;
                return Ok(Py::Dict(items));
            }
            let key = self.value()?;
            self.skip_space();
            if self.peek() != Some(b':') {
                return Err(format!("expected ':' after a key at byte {}", self.pos));
            }
            self.pos += 1;
            let value = self.value()?;
            items.push((key, value));
            self.separator(b'}')?;
        }
    }
}

fn is_word_byte(c: u8) -> bool {
    c.is_ascii_alphanumeric() || matches!(c, b'.' | b'+' | b'-' | b'_')
}

// ---------------------------------------------------------------------------------
// Writing
// ---------------------------------------------------------------------------------

/// The bytes before the data: magic, version, header length and the padded dict.
fn header_bytes(descr: &str, shape: &[usize]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    // A Python 1-tuple needs its trailing comma.
    let shape = if dims.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    // The whole prefix is padded to a multiple of 64 bytes, ending with '\n'.
    let padded = |prefix: usize| (prefix + dict.len() + 1).div_ceil(64) * 64;
    // Version 1.0 has a 2-byte length field; only an enormous shape needs 2.0.
    let (major, len_bytes) = if padded(10) - 10 <= u16::MAX as usize {
        (1u8, 2)
    } else {
        (2u8, 4)
    };
    let prefix = 8 + len_bytes;
    let total = padded(prefix);
    let header_len = (total - prefix) as u32;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[major, 0]);
    out.extend_from_slice(&header_len.to_le_bytes()[..len_bytes]);
    out.extend_from_slice(dict.as_bytes());
    out.resize(total - 1, b' ');
    out.push(b'\n');
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_f32(bytes: &[u8]) -> Result<(Vec<usize>, Vec<f32>)> {
        f32_from_reader(&mut &bytes[..], bytes.len() as u64, Path::new("t.npy"))
    }

    fn parse_volume(bytes: &[u8]) -> Result<AnyVolume> {
        volume_from_reader(&mut &bytes[..], bytes.len() as u64, Path::new("t.npy"))
    }

    fn file(descr: &str, shape: &[usize], data: &[u8]) -> Vec<u8> {
        let mut b = header_bytes(descr, shape);
        b.extend_from_slice(data);
        b
    }

    #[test]
    fn header_is_aligned_and_parses_back() {
        for shape in [&[][..], &[5], &[2, 3], &[4, 5, 6]] {
            let h = header_bytes("<f4", shape);
            assert_eq!(h.len() % 64, 0);
            assert_eq!(*h.last().unwrap(), b'\n');
            let data = vec![0u8; 4 * shape.iter().product::<usize>()];
            let (s, v) = parse_f32(&file("<f4", shape, &data)).unwrap();
            assert_eq!(s, shape);
            assert_eq!(v.len(), data.len() / 4);
        }
    }

    #[test]
    fn literal_parser() {
        let v = PyParser::parse("{'a': (1, 2,), \"b\": [True], 'c': (3L,)}  \n").unwrap();
        let Py::Dict(items) = v else { panic!() };
        assert_eq!(items.len(), 3);
        assert_eq!(
            items[0].1,
            Py::Tuple(vec![Py::Word("1".into()), Py::Word("2".into())])
        );
        for bad in [
            "{",
            "{'a' 1}",
            "{'a': (1 2)}",
            "{'a': 1} x",
            "'abc",
            "{'a': @}",
        ] {
            assert!(PyParser::parse(bad).is_err(), "{bad}");
        }
        let deep = "(".repeat(100_000);
        assert!(PyParser::parse(&deep).unwrap_err().contains("nesting"));
    }

    #[test]
    fn dtypes() {
        assert_eq!(parse_descr("|u1").unwrap(), (Stored::U8, Endian::Little));
        assert_eq!(parse_descr(">i2").unwrap(), (Stored::I16, Endian::Big));
        assert_eq!(parse_descr("<f8").unwrap(), (Stored::F64, Endian::Little));
        assert!(parse_descr("|f4").is_err());
        assert!(parse_descr("<c8").is_err());
        let e = parse_volume(&file("<i4", &[1, 1, 1], &[0; 4])).unwrap_err();
        assert!(e.to_string().contains("<f4"), "{e}");
    }

    #[test]
    fn fortran_order_matches_numpy_load() {
        // a[z, y, x] = 100 z + 10 y + x with shape (2, 2, 3), stored first-axis-fastest.
        let shape = [2usize, 2, 3];
        let mut data = Vec::new();
        for x in 0..3 {
            for y in 0..2 {
                for z in 0..2 {
                    data.extend_from_slice(&((100 * z + 10 * y + x) as f32).to_le_bytes());
                }
            }
        }
        let text = "{'descr': '<f4', 'fortran_order': True, 'shape': (2, 2, 3), }";
        let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
        bytes.extend_from_slice(&(text.len() as u16).to_le_bytes());
        bytes.extend_from_slice(text.as_bytes());
        bytes.extend_from_slice(&data);
        let (s, v) = parse_f32(&bytes).unwrap();
        assert_eq!(s, shape);
        let want: Vec<f32> = (0..12)
            .map(|i| (100 * (i / 6) + 10 * (i / 3 % 2) + i % 3) as f32)
            .collect();
        assert_eq!(v, want);
        let vol = parse_volume(&bytes).unwrap();
        assert_eq!(vol.dims(), [3, 2, 2]);
        assert_eq!(vol.values_f64()[5], 12.0);
    }

    #[test]
    fn bad_shapes_are_format_errors() {
        let cases = [
            ("(-1, 2)", "negative"),
            ("(2.5, 2)", "not an integer"),
            ("(99999999999999999999999, 2)", "too large"),
            ("(4294967296, 4294967296, 4)", "limit"),
            ("(65536, 65536, 2)", "limit"),
            ("[2, 2]", "tuple"),
        ];
        for (shape, words) in cases {
            let text = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}}}");
            let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
            bytes.extend_from_slice(&(text.len() as u16).to_le_bytes());
            bytes.extend_from_slice(text.as_bytes());
            let e = parse_f32(&bytes).unwrap_err();
            assert!(
                matches!(&e, Error::Format { field, message, .. } if field == "shape" && message.contains(words)),
                "{shape}: {e}"
            );
        }
    }

    /// A small deterministic generator (xorshift), so failures reproduce.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }
    }

    #[test]
    fn garbage_and_truncations_give_errors_not_panics() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        // Random bytes, with and without a valid magic in front.
        for len in 0..300 {
            let mut bytes: Vec<u8> = (0..len).map(|_| rng.next() as u8).collect();
            assert!(parse_volume(&bytes).is_err());
            if len > 10 {
                bytes[..8].copy_from_slice(b"\x93NUMPY\x01\x00");
                let _ = parse_volume(&bytes);
                let _ = parse_f32(&bytes);
            }
        }
        // Every truncation of valid files fails.
        let data: Vec<u8> = (0..2 * 3 * 4 * 2).map(|i| i as u8).collect();
        for valid in [file("<i2", &[2, 3, 4], &data), file(">f4", &[3, 4], &data)] {
            assert!(parse_volume(&valid).is_ok());
            for cut in 0..valid.len() {
                assert!(parse_volume(&valid[..cut]).is_err(), "cut at {cut}");
            }
            // Garbled bytes anywhere: any result but a panic.
            for _ in 0..2000 {
                let mut b = valid.clone();
                for _ in 0..1 + rng.next() % 4 {
                    let i = (rng.next() as usize) % b.len();
                    b[i] = rng.next() as u8;
                }
                let _ = parse_volume(&b);
                let _ = parse_f32(&b);
            }
        }
    }
}
