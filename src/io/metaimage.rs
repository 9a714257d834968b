//! MetaImage (`.mha`, `.mhd`): ITK's and RTK's own format, a text header of
//! `Key = Value` lines followed by the samples or naming the file(s) that hold them.
//!
//! Read:
//! - `ObjectType = Image`, `NDims` 2 to 10 (a 2-D image is one slice; the axes past
//!   the third number the file's 3-D volumes, its frames, read one at a time with
//!   [`ReadOptions::frame`](super::ReadOptions::frame), `--frame K`), `DimSize`,
//!   `ElementType` `MET_UCHAR`, `MET_CHAR`, `MET_USHORT`, `MET_SHORT`, `MET_UINT`,
//!   `MET_INT`, `MET_ULONG`, `MET_LONG` (4 bytes, as MetaIO defines them),
//!   `MET_ULONG_LONG`, `MET_LONG_LONG`, `MET_FLOAT`, `MET_DOUBLE` (mapped to voxel types
//!   as every reader here maps them, docs/io.md), `ElementNumberOfChannels` (samples
//!   per voxel, interleaved: above 1, each channel is a frame, numbered before the
//!   axes past the third);
//! - `ElementSpacing` (else `ElementSize`, else 1 mm), `Offset` (alias `Position`,
//!   `Origin`), `TransformMatrix` (alias `Rotation`, `Orientation`);
//! - `BinaryData` (`False`: the samples as text), `ElementByteOrderMSB` /
//!   `BinaryDataByteOrderMSB`, `CompressedData` (zlib) with `CompressedDataSize`,
//!   `HeaderSize` (bytes to skip in a data file; −1: the data ends the file);
//! - `ElementDataFile` (the last key): `LOCAL` (the data follows the header), a file
//!   beside the header, or `LIST` followed by one file per image of `NDims − 1` axes
//!   (a slice of a 3-D image, a 3-D volume of a 4-D one), or `LIST nD` with one file per
//!   image of the first `n` axes (MetaIO's convention).
//!
//! Of a 4-D (or higher) image only the chosen frame's samples are kept: its run is
//! read and the rest skipped, so the memory is one frame's, and with `LIST` only the
//! files that hold it are opened. Spacing, offset and directions are the first three
//! components of the header's (the spatial ones; a time axis has no place in a
//! voxel-to-world affine).
//!
//! Other keys (`CenterOfRotation`, `AnatomicalOrientation`, `ElementMin`, comments …)
//! are read past. **The affine is ITK's**: voxel `(i, j, k)` lies at
//! `Offset + Σ s_a · index_a · d_a`, where `s` is `ElementSpacing` and `d_a` the `a`-th
//! three numbers of `TransformMatrix` (the direction of index axis `a`). The world frame
//! is kept as written (ITK's is LPS); nothing is flipped.
//!
//! Written: `.mha` with the data after the header, `.mhd` with the data in
//! `<stem>.raw` beside it (or zlib-compressed, `<stem>.zraw`), little-endian, the
//! affine split back into spacing (the columns' lengths) and directions, every number
//! written so that it reads back exactly.

use super::{open, read_error, snippet, Endian, Samples, Stored};
use crate::error::{Error, Result};
use crate::volume::{check_dims, check_spacing, AnyVolume};
use glam::{DMat4, DVec4};
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};

/// A header larger than this is refused (real ones are under a kilobyte).
const MAX_HEADER_BYTES: u64 = 1 << 20;

/// Where the samples are.
#[derive(Clone, Debug, PartialEq)]
enum DataFile {
    Local,
    File(String),
    List(Vec<String>),
}

/// The most axes a MetaImage may have (MetaIO's limit).
const MAX_NDIMS: usize = 10;

#[derive(Clone, Debug)]
struct Header {
    /// The 3-D volume's sizes: the first three axes (a 2-D image has `nz` 1).
    dims: [usize; 3],
    /// The sizes of the axes past the third, which number the file's 3-D volumes.
    extra: Vec<usize>,
    /// How many 3-D volumes the file holds (the product of `extra`).
    frames: usize,
    /// Samples in each file of a `LIST` (the first `LIST nD` axes' sizes' product).
    per_file: usize,
    /// `ElementNumberOfChannels`: samples per voxel, interleaved.
    channels: usize,
    stored: Stored,
    endian: Endian,
    binary: bool,
    compressed: bool,
    compressed_size: Option<u64>,
    header_size: i64,
    affine: DMat4,
    data: DataFile,
}

fn field(path: &Path, key: &str, why: impl Into<String>) -> Error {
    Error::format(path, key, why)
}

fn numbers(path: &Path, key: &str, text: &str, n: usize) -> Result<Vec<f64>> {
    let v: Vec<f64> = text
        .split_whitespace()
        .map(|t| t.parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| {
            field(
                path,
                key,
                format!("'{}' is not a list of numbers", snippet(text)),
            )
        })?;
    if v.len() != n {
        return Err(field(
            path,
            key,
            format!("has {} numbers, NDims needs {n}", v.len()),
        ));
    }
    if v.iter().any(|x| !x.is_finite()) {
        return Err(field(path, key, "every number must be finite"));
    }
    Ok(v)
}

fn boolean(path: &Path, key: &str, text: &str) -> Result<bool> {
    match text.to_ascii_lowercase().as_str() {
        "true" | "1" => Ok(true),
        "false" | "0" => Ok(false),
        _ => Err(field(
            path,
            key,
            format!("'{}' is not True or False", snippet(text)),
        )),
    }
}

fn element_type(path: &Path, text: &str) -> Result<Stored> {
    Ok(match text {
        "MET_UCHAR" => Stored::U8,
        "MET_CHAR" => Stored::I8,
        "MET_USHORT" => Stored::U16,
        "MET_SHORT" => Stored::I16,
        "MET_UINT" | "MET_ULONG" => Stored::U32,
        "MET_INT" | "MET_LONG" => Stored::I32,
        "MET_ULONG_LONG" => Stored::U64,
        "MET_LONG_LONG" => Stored::I64,
        "MET_FLOAT" => Stored::F32,
        "MET_DOUBLE" => Stored::F64,
        _ => {
            return Err(field(
                path,
                "ElementType",
                format!(
                    "'{}' is not a scalar type voxlab reads (MET_UCHAR, MET_CHAR, MET_USHORT, \
                     MET_SHORT, MET_UINT, MET_INT, MET_ULONG, MET_LONG, MET_ULONG_LONG, \
                     MET_LONG_LONG, MET_FLOAT, MET_DOUBLE)",
                    snippet(text)
                ),
            ))
        }
    })
}

/// A header's `(key, value)` pairs, in order.
type Fields = Vec<(String, String)>;

/// Reads the header's lines up to and including `ElementDataFile` (and, for `LIST`,
/// the file names after it); `reader` is left at the first data byte.
fn read_lines(reader: &mut dyn BufRead, path: &Path) -> Result<(Fields, Vec<String>)> {
    let mut fields = Vec::new();
    let mut read = 0u64;
    let mut line = Vec::new();
    loop {
        line.clear();
        let n = reader
            .take(MAX_HEADER_BYTES + 1 - read)
            .read_until(b'\n', &mut line)
            .map_err(|e| Error::io(path, e))?;
        read += n as u64;
        if read > MAX_HEADER_BYTES {
            return Err(field(
                path,
                "header",
                format!("no ElementDataFile within the first {MAX_HEADER_BYTES} bytes: not a MetaImage header"),
            ));
        }
        if n == 0 {
            return Err(field(
                path,
                "ElementDataFile",
                "the header ends without ElementDataFile (it must be the last key)",
            ));
        }
        let text = std::str::from_utf8(&line)
            .map_err(|_| field(path, "header", "a header line is not text"))?;
        let text = text.trim_end_matches(['\n', '\r']);
        if text.trim().is_empty() {
            continue;
        }
        let Some((k, v)) = text.split_once('=') else {
            return Err(field(
                path,
                "header",
                format!("'{}' is not a 'Key = Value' line", snippet(text)),
            ));
        };
        let (k, v) = (k.trim().to_string(), v.trim().to_string());
        let last = k == "ElementDataFile";
        fields.push((k, v.clone()));
        if last {
            let mut list = Vec::new();
            if v.split_whitespace().next() == Some("LIST") {
                for l in reader.lines() {
                    let l = l.map_err(|e| Error::io(path, e))?;
                    if !l.trim().is_empty() {
                        list.push(l.trim().to_string());
                    }
                    if list.len() > crate::volume::max_voxels() {
                        return Err(field(path, "ElementDataFile", "the file list is too long"));
                    }
                }
            }
            return Ok((fields, list));
        }
    }
}

impl Header {
    fn parse(fields: &[(String, String)], list: Vec<String>, path: &Path) -> Result<Header> {
        let get = |names: &[&str]| {
            fields
                .iter()
                .find(|(k, _)| names.contains(&k.as_str()))
                .map(|(_, v)| v.as_str())
        };
        for (i, (k, _)) in fields.iter().enumerate() {
            if fields[..i].iter().any(|(p, _)| p == k) {
                return Err(field(path, k, "is given twice"));
            }
        }
        match get(&["ObjectType"]) {
            Some("Image") => {}
            Some(o) => {
                return Err(field(
                    path,
                    "ObjectType",
                    format!("'{}' is not an image", snippet(o)),
                ))
            }
            None => {
                return Err(field(
                    path,
                    "ObjectType",
                    "missing (a MetaImage says Image)",
                ))
            }
        }
        let nd: usize = get(&["NDims"])
            .ok_or_else(|| field(path, "NDims", "missing"))?
            .parse()
            .map_err(|_| field(path, "NDims", "is not a whole number"))?;
        if !(2..=MAX_NDIMS).contains(&nd) {
            return Err(field(
                path,
                "NDims",
                format!("{nd}: needs 2 to {MAX_NDIMS}"),
            ));
        }
        let dim_text = get(&["DimSize"]).ok_or_else(|| field(path, "DimSize", "missing"))?;
        let d: Vec<usize> = dim_text
            .split_whitespace()
            .map(|t| t.parse::<usize>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| {
                field(
                    path,
                    "DimSize",
                    format!("'{}' is not a list of whole numbers", snippet(dim_text)),
                )
            })?;
        if d.len() != nd {
            return Err(field(
                path,
                "DimSize",
                format!("has {} sizes, NDims is {nd}", d.len()),
            ));
        }
        let dims = [d[0], d[1], if nd >= 3 { d[2] } else { 1 }];
        let count = check_dims(dims).map_err(|e| field(path, "DimSize", e.to_string()))?;
        let extra: Vec<usize> = d.iter().skip(3).copied().collect();
        // Every frame must be in the file, though one is read: the whole data's size
        // is checked before anything is allocated.
        let frames = extra
            .iter()
            .try_fold(1usize, |a, &e| a.checked_mul(e))
            .filter(|&f| f >= 1)
            .and_then(|f| count.checked_mul(f).filter(|&t| t <= 1 << 62).map(|_| f))
            .ok_or_else(|| {
                field(
                    path,
                    "DimSize",
                    format!("'{}': too many samples, or a size of 0", snippet(dim_text)),
                )
            })?;
        // Channels interleave (fastest) and number frames before the extra axes.
        let channels: usize = match get(&["ElementNumberOfChannels"]) {
            None => 1,
            Some(t) => t.parse().ok().filter(|&c| c >= 1).ok_or_else(|| {
                field(
                    path,
                    "ElementNumberOfChannels",
                    format!("'{}' is not a whole number ≥ 1", snippet(t)),
                )
            })?,
        };
        let frames = channels
            .checked_mul(frames)
            .filter(|&f| count.checked_mul(f).is_some_and(|t| t <= 1 << 62))
            .ok_or_else(|| field(path, "ElementNumberOfChannels", "too many samples"))?;
        let stored = element_type(
            path,
            get(&["ElementType"]).ok_or_else(|| field(path, "ElementType", "missing"))?,
        )?;
        let msb_key = ["ElementByteOrderMSB", "BinaryDataByteOrderMSB"];
        let endian = match get(&msb_key) {
            Some(v) if boolean(path, "ElementByteOrderMSB", v)? => Endian::Big,
            _ => Endian::Little,
        };
        let binary = match get(&["BinaryData"]) {
            Some(v) => boolean(path, "BinaryData", v)?,
            None => true,
        };
        let compressed = match get(&["CompressedData"]) {
            Some(v) => boolean(path, "CompressedData", v)?,
            None => false,
        };
        let compressed_size = match get(&["CompressedDataSize"]) {
            Some(v) => Some(
                v.parse::<u64>()
                    .map_err(|_| field(path, "CompressedDataSize", "is not a whole number"))?,
            ),
            None => None,
        };
        let header_size = match get(&["HeaderSize"]) {
            Some(v) => {
                let h = v
                    .parse::<i64>()
                    .map_err(|_| field(path, "HeaderSize", "is not a whole number"))?;
                if h < -1 {
                    return Err(field(path, "HeaderSize", format!("{h}: must be ≥ −1")));
                }
                h
            }
            None => 0,
        };
        // The first three components: the space of the first three axes.
        let embed = |v: &[f64]| -> [f64; 3] { [v[0], v[1], if nd >= 3 { v[2] } else { 0.0 }] };
        let spacing = match get(&["ElementSpacing"]) {
            Some(t) => numbers(path, "ElementSpacing", t, nd)?,
            None => match get(&["ElementSize"]) {
                Some(t) => numbers(path, "ElementSize", t, nd)?,
                None => vec![1.0; nd],
            },
        };
        let spacing = [
            spacing[0],
            spacing[1],
            if nd >= 3 { spacing[2] } else { 1.0 },
        ];
        check_spacing(spacing).map_err(|e| field(path, "ElementSpacing", e.to_string()))?;
        let offset = match get(&["Offset", "Position", "Origin"]) {
            Some(t) => embed(&numbers(path, "Offset", t, nd)?),
            None => [0.0; 3],
        };
        let m = match get(&["TransformMatrix", "Rotation", "Orientation"]) {
            Some(t) => numbers(path, "TransformMatrix", t, nd * nd)?,
            None => (0..nd * nd)
                .map(|i| if i % (nd + 1) == 0 { 1.0 } else { 0.0 })
                .collect(),
        };
        // Direction of index axis a: the a-th nd numbers (ITK's MetaImageIO), of which
        // the first three are the spatial ones.
        let dir = |a: usize| -> [f64; 3] {
            if a < nd {
                embed(&m[a * nd..(a + 1) * nd])
            } else {
                [0.0, 0.0, 1.0]
            }
        };
        let col = |a: usize| {
            let d = dir(a);
            DVec4::new(d[0] * spacing[a], d[1] * spacing[a], d[2] * spacing[a], 0.0)
        };
        let affine = DMat4::from_cols(
            col(0),
            col(1),
            col(2),
            DVec4::new(offset[0], offset[1], offset[2], 1.0),
        );
        if !(affine.determinant().is_finite() && affine.determinant() != 0.0) {
            return Err(field(
                path,
                "TransformMatrix",
                "the directions are degenerate (the matrix is singular)",
            ));
        }
        let data_text = get(&["ElementDataFile"]).unwrap_or("LOCAL");
        let mut per_file = count;
        let data = match data_text.split_whitespace().next() {
            Some("LOCAL") | Some("Local") | Some("local") => DataFile::Local,
            Some("LIST") => {
                // `LIST` alone: each file holds an image of NDims − 1 axes; `LIST nD`:
                // of n axes (MetaIO).
                let file_dim = match data_text.split_whitespace().nth(1) {
                    None => nd - 1,
                    Some(t) => t
                        .strip_suffix(['D', 'd'])
                        .and_then(|n| n.parse::<usize>().ok())
                        .filter(|n| (1..nd).contains(n))
                        .ok_or_else(|| {
                            field(
                                path,
                                "ElementDataFile",
                                format!(
                                    "LIST {}: the files' dimension must be 1D to {}D",
                                    snippet(t),
                                    nd - 1
                                ),
                            )
                        })?,
                };
                per_file = d[..file_dim].iter().product::<usize>() * channels;
                let files: usize = d[file_dim..].iter().product();
                if list.len() != files {
                    return Err(field(
                        path,
                        "ElementDataFile",
                        format!(
                            "LIST names {} files, DimSize needs {files} (one per {file_dim}-D \
                             image)",
                            list.len(),
                        ),
                    ));
                }
                if compressed {
                    return Err(Error::unsupported(
                        "read",
                        path.display(),
                        "compressed data in a LIST of files",
                    ));
                }
                DataFile::List(list)
            }
            Some(_) if data_text.contains('%') => {
                return Err(Error::unsupported(
                    "read",
                    path.display(),
                    format!(
                        "ElementDataFile = {}: numbered file patterns are not read; list the \
                         files with LIST",
                        snippet(data_text)
                    ),
                ))
            }
            Some(_) => DataFile::File(data_text.to_string()),
            None => return Err(field(path, "ElementDataFile", "is empty")),
        };
        if !binary && compressed {
            return Err(field(
                path,
                "CompressedData",
                "text data (BinaryData = False) cannot be compressed",
            ));
        }
        Ok(Header {
            dims,
            extra,
            frames,
            per_file,
            channels,
            stored,
            endian,
            binary,
            compressed,
            compressed_size,
            header_size,
            affine,
            data,
        })
    }

    fn n(&self) -> usize {
        self.dims.iter().product()
    }

    /// Bytes of the whole data, every frame.
    fn data_bytes(&self) -> u64 {
        (self.n() * self.frames) as u64 * self.stored.size() as u64
    }

    /// Where frame `frame` lies in the data (see [`super::choose_frame`]): the
    /// channel fastest, then the axes past the third.
    fn pick(&self, frame: Option<usize>, path: &Path) -> Result<super::FramePick> {
        let mut axes: Vec<String> = Vec::new();
        if self.channels > 1 {
            axes.push(format!("ElementNumberOfChannels {}", self.channels));
        }
        axes.extend(
            self.extra
                .iter()
                .enumerate()
                .map(|(i, e)| format!("DimSize[{}] {e}", i + 3)),
        );
        let field = if self.extra.is_empty() {
            "ElementNumberOfChannels"
        } else {
            "DimSize"
        };
        let k = super::choose_frame(path, field, self.frames, &axes.join(", "), frame)?;
        let (c, [nx, ny, _]) = (self.channels, self.dims);
        Ok(super::FramePick {
            total: self.n() * self.frames,
            dims: self.dims,
            base: (k / c) * self.n() * c + k % c,
            strides: [c, c * nx, c * nx * ny],
        })
    }
}

/// Reads the samples `pick` chooses from `reader`, which holds `pick.total` samples as
/// the header says (compressed or not, binary or text), and refuses data beyond them
/// (text data is read as far as its values can need).
fn read_body(
    reader: &mut dyn Read,
    h: &Header,
    pick: &super::FramePick,
    path: &Path,
) -> Result<Samples> {
    let n = pick.total;
    if !h.binary {
        let cap = (n as u64).saturating_mul(64).saturating_add(1 << 16);
        let mut text = String::new();
        reader
            .take(cap)
            .read_to_string(&mut text)
            .map_err(|e| read_error(path, e))?;
        return Ok(super::parse_text_samples(
            &text,
            h.stored,
            n,
            path,
            "sample of the header's ElementType",
        )?
        .pick(pick));
    }
    if h.compressed {
        let limited: Box<dyn Read> = match h.compressed_size {
            Some(s) => Box::new(reader.take(s)),
            None => Box::new(reader),
        };
        let mut z = flate2::read::ZlibDecoder::new(limited);
        let samples = super::read_picked(&mut z, h.stored, h.endian, pick, path)?;
        let mut rest = [0u8; 1];
        if super::fill(&mut z, &mut rest).map_err(|e| read_error(path, e))? > 0 {
            return Err(field(
                path,
                "data",
                "the decompressed data is longer than DimSize × ElementType describe",
            ));
        }
        return Ok(samples);
    }
    let samples = super::read_picked(reader, h.stored, h.endian, pick, path)?;
    let mut rest = [0u8; 1];
    if super::fill(reader, &mut rest).map_err(|e| read_error(path, e))? > 0 {
        return Err(field(
            path,
            "data",
            format!(
                "the data is longer than DimSize × ElementType describe ({} bytes)",
                h.data_bytes()
            ),
        ));
    }
    Ok(samples)
}

/// Reads a MetaImage; see the module docs.
pub fn read_metaimage(path: &Path) -> Result<AnyVolume> {
    read_metaimage_with(path, &super::ReadOptions::default())
}

/// How many 3-D volumes a MetaImage holds (the product of its `DimSize` past the
/// third), from its header alone.
pub fn metaimage_frames(path: &Path) -> Result<usize> {
    let (file, _) = open(path)?;
    let mut reader = BufReader::new(file);
    let (fields, list) = read_lines(&mut reader, path)?;
    Ok(Header::parse(&fields, list, path)?.frames)
}

/// [`read_metaimage`] with [`ReadOptions`](super::ReadOptions): with
/// `confine_data_files`, the data files must lie in the header's folder; `frame`
/// chooses one 3-D volume of a 4-D (or higher) image.
pub fn read_metaimage_with(path: &Path, options: &super::ReadOptions) -> Result<AnyVolume> {
    let (file, _) = open(path)?;
    let mut reader = BufReader::new(file);
    let (fields, list) = read_lines(&mut reader, path)?;
    let h = Header::parse(&fields, list, path)?;
    let dir = path.parent().unwrap_or(Path::new(""));
    let data_file = |name: &str| -> Result<(BufReader<std::fs::File>, u64, PathBuf)> {
        let data_path = dir.join(name);
        if options.confine_data_files {
            super::confine(path, dir, &data_path, name)?;
        }
        let (f, len) = super::open_data_file(path, &data_path)?;
        Ok((BufReader::new(f), len, data_path))
    };
    let pick = h.pick(options.frame, path)?;
    let samples = match &h.data {
        DataFile::Local => read_body(&mut reader, &h, &pick, path)?,
        DataFile::File(name) => {
            let (mut r, len, data_path) = data_file(name)?;
            let skip = if h.header_size == -1 {
                if h.compressed || !h.binary {
                    return Err(field(
                        path,
                        "HeaderSize",
                        "−1 (data at the end of the file) needs uncompressed binary data",
                    ));
                }
                len.checked_sub(h.data_bytes())
                    .ok_or_else(|| super::too_short(&data_path, h.data_bytes(), len))?
            } else {
                h.header_size as u64
            };
            skip_bytes(&mut r, skip, path, &data_path)?;
            read_body(&mut r, &h, &pick, &data_path)?
        }
        DataFile::List(names) => {
            // Only the files that hold the frame's samples are read: the part of one,
            // or whole ones joined and the frame picked from them.
            let per = h.per_file;
            let (lo, hi) = (pick.base, pick.index(pick.n() - 1) + 1);
            let (first, last) = (lo / per, (hi - 1) / per);
            let mut sub = pick;
            sub.base = lo - first * per;
            sub.total = (last - first + 1) * per;
            let whole = super::FramePick::whole([per, 1, 1]);
            if first < last && !sub.contiguous() {
                super::check_interleaved(&sub, path)?;
            }
            let mut all: Option<Samples> = None;
            for name in &names[first..=last] {
                let (mut r, _, data_path) = data_file(name)?;
                skip_bytes(&mut r, h.header_size.max(0) as u64, path, &data_path)?;
                let s = read_body(
                    &mut r,
                    &h,
                    if first == last { &sub } else { &whole },
                    &data_path,
                )?;
                all = Some(match all {
                    None => s,
                    Some(a) => a.append(s),
                });
            }
            let all = all.expect("at least one file (dims are checked)");
            if first == last {
                all
            } else {
                all.pick(&sub)
            }
        }
    };
    samples.into_volume(h.dims, h.affine)
}

/// Where an uncompressed binary MetaImage keeps its samples, for
/// [`super::brick::read_brick`]: after its own header (`LOCAL`) or in its one data
/// file (at `HeaderSize`, or the last bytes for −1). `None` for compressed or text
/// data and for a list of slice files. The data must fill the file exactly, as for
/// [`read_metaimage`].
pub(crate) fn raw_layout(path: &Path) -> Result<Option<super::RawLayout>> {
    use std::io::Seek;
    let (file, len) = open(path)?;
    let mut reader = BufReader::new(file);
    let (fields, list) = read_lines(&mut reader, path)?;
    let h = Header::parse(&fields, list, path)?;
    if h.compressed || !h.binary || h.frames > 1 {
        return Ok(None);
    }
    let want = h.data_bytes();
    let (data, offset, len) = match &h.data {
        DataFile::List(_) => return Ok(None),
        DataFile::Local => {
            let pos = reader.stream_position().map_err(|e| Error::io(path, e))?;
            (path.to_path_buf(), pos, len)
        }
        DataFile::File(name) => {
            let data = path.parent().unwrap_or(Path::new("")).join(name);
            let (_, len) = super::open_data_file(path, &data)?;
            let offset = if h.header_size == -1 {
                len.checked_sub(want)
                    .ok_or_else(|| super::too_short(&data, want, len))?
            } else {
                h.header_size.max(0) as u64
            };
            (data, offset, len)
        }
    };
    let available = len.saturating_sub(offset);
    if available < want {
        return Err(super::too_short(&data, want, available));
    }
    if available > want {
        return Err(field(
            &data,
            "data",
            format!("the data is longer than DimSize × ElementType describe ({want} bytes)"),
        ));
    }
    Ok(Some(super::RawLayout {
        data,
        offset,
        stored: h.stored,
        endian: h.endian,
        dims: h.dims,
        affine: h.affine,
    }))
}

/// Reads a MetaImage held in memory; its data must be `LOCAL`.
pub fn read_metaimage_bytes(bytes: &[u8], path: &Path) -> Result<AnyVolume> {
    read_metaimage_bytes_frame(bytes, path, None)
}

/// [`read_metaimage_bytes`] of one 3-D volume of a file that holds several.
pub fn read_metaimage_bytes_frame(
    bytes: &[u8],
    path: &Path,
    frame: Option<usize>,
) -> Result<AnyVolume> {
    let mut reader = std::io::Cursor::new(bytes);
    let (fields, list) = read_lines(&mut reader, path)?;
    let h = Header::parse(&fields, list, path)?;
    if h.data != DataFile::Local {
        return Err(field(
            path,
            "ElementDataFile",
            "names other files; read the header from a path",
        ));
    }
    let pick = h.pick(frame, path)?;
    read_body(&mut reader, &h, &pick, path)?.into_volume(h.dims, h.affine)
}

/// Skips the `HeaderSize` bytes of `data`, a data file `header` names.
fn skip_bytes(reader: &mut dyn Read, n: u64, header: &Path, data: &Path) -> Result<()> {
    let skipped = std::io::copy(&mut reader.take(n), &mut std::io::sink())
        .map_err(|e| read_error(data, e))?;
    if skipped < n {
        return Err(field(
            header,
            "HeaderSize",
            format!(
                "skips {n} bytes, but {} holds only {skipped}",
                data.display()
            ),
        ));
    }
    Ok(())
}

/// How [`write_metaimage`] writes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MetaImageWriteOptions {
    /// zlib-compress the data (`CompressedData = True`).
    pub compress: bool,
}

/// A number as MetaImage text that parses back to the same `f64`.
fn num(x: f64) -> String {
    let x = if x == 0.0 { 0.0 } else { x };
    format!("{x}")
}

/// Writes `vol` as `.mha` (data after the header) or `.mhd` (data in `<stem>.raw`, or
/// `<stem>.zraw` compressed), atomically.
///
/// # Errors
/// An extension other than `.mha`/`.mhd`; the files' write errors.
pub fn write_metaimage(path: &Path, vol: &AnyVolume, options: MetaImageWriteOptions) -> Result<()> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    let detached = match ext.as_deref() {
        Some("mha") => false,
        Some("mhd") => true,
        _ => {
            return Err(Error::invalid(
                "MetaImage file",
                format!("{}: use .mha or .mhd", path.display()),
            ))
        }
    };
    let a = vol.affine();
    let cols = [a.x_axis, a.y_axis, a.z_axis].map(|c| c.truncate());
    let spacing = cols.map(|c| c.length());
    let dirs: Vec<String> = (0..3)
        .flat_map(|i| (cols[i] / spacing[i]).to_array())
        .map(num)
        .collect();
    let t = a.w_axis;
    let element = match vol {
        AnyVolume::U8(_) => "MET_UCHAR",
        AnyVolume::U16(_) => "MET_USHORT",
        AnyVolume::I16(_) => "MET_SHORT",
        AnyVolume::F32(_) => "MET_FLOAT",
    };
    let mut raw = Vec::new();
    super::write_samples_le(&mut raw, vol).map_err(|e| Error::io(path, e))?;
    let data = if options.compress {
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&raw).map_err(|e| Error::io(path, e))?;
        z.finish().map_err(|e| Error::io(path, e))?
    } else {
        raw
    };
    let d = vol.dims();
    let data_name = if detached {
        let stem = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("volume");
        Some(format!(
            "{stem}.{}",
            if options.compress { "zraw" } else { "raw" }
        ))
    } else {
        None
    };
    let mut header = format!(
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n\
         CompressedData = {}\n",
        if options.compress { "True" } else { "False" }
    );
    if options.compress {
        header.push_str(&format!("CompressedDataSize = {}\n", data.len()));
    }
    header.push_str(&format!(
        "TransformMatrix = {}\nOffset = {} {} {}\nCenterOfRotation = 0 0 0\n\
         ElementSpacing = {} {} {}\nDimSize = {} {} {}\nElementType = {element}\n\
         ElementDataFile = {}\n",
        dirs.join(" "),
        num(t.x),
        num(t.y),
        num(t.z),
        num(spacing[0]),
        num(spacing[1]),
        num(spacing[2]),
        d[0],
        d[1],
        d[2],
        data_name.as_deref().unwrap_or("LOCAL"),
    ));
    match data_name {
        None => super::write_atomic(path, |w| {
            w.write_all(header.as_bytes())
                .and_then(|()| w.write_all(&data))
                .map_err(|e| Error::io(path, e))
        }),
        Some(name) => {
            let data_path = path.with_file_name(&name);
            super::write_atomic(&data_path, |w| {
                w.write_all(&data).map_err(|e| Error::io(&data_path, e))
            })?;
            super::write_atomic(path, |w| {
                w.write_all(header.as_bytes())
                    .map_err(|e| Error::io(path, e))
            })
        }
    }
}
