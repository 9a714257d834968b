//! NRRD files (`NRRD0001` to `NRRD0005`), read and written by hand; gzip via `flate2`.
//!
//! # The format
//!
//! A NRRD file starts with a text header: the magic line `NRRD000n`, then one
//! `field: value` per line (`#` starts a comment, `key:=value` lines carry free-form
//! metadata), ended by a blank line. The data follows the blank line (an *attached*
//! header, usually `.nrrd`) or lives in the file named by `data file:` (a *detached*
//! header, usually `.nhdr`; a relative name is relative to the header's directory).
//! The data's first axis is the fastest, like the crate's x.
//!
//! ```text
//! NRRD0004
//! type: short
//! dimension: 3
//! sizes: 256 256 128
//! space: left-posterior-superior
//! space directions: (0.5,0,0) (0,0.5,0) (0,0,1.2)
//! space origin: (-64,-64,0)
//! endian: little
//! encoding: gzip
//!
//! <data>
//! ```
//!
//! # What is read
//!
//! - `type`: every standard name and alias. 8-bit unsigned → u8; 8-bit signed → i16
//!   (exact); 16-bit → u16 / i16; `float` → f32; 32/64-bit integers and `double` → f32,
//!   rounded to nearest (see [`crate::io`]). `block` is refused.
//! - `encoding`: `raw`, `gzip`/`gz`, `ascii`/`text`/`txt`. `bzip2`, `hex` and `zrl`
//!   are refused (recompress with `unu save -e gzip`).
//! - `endian`: `little` or `big`; required for multi-byte types in raw or gzip data.
//! - `dimension` and `sizes`: a 3-D volume, or 2-D (read with `nz = 1`), and any
//!   number of further axes that number the file's 3-D volumes, its *frames*. An axis
//!   is spatial unless its space direction is `none`, its `kinds` entry is not a domain
//!   kind (`vector`, `RGB-color`, `list` …) or is `time`. The volume's axes are the first three spatial ones (spatial
//!   axes of size 1 are dropped from the slowest end while there are more than three;
//!   with directions, more than three spatial axes are refused); every other axis of
//!   size above 1 is a frame axis, wherever it lies (a fastest vector axis too). A file
//!   of several frames is read one at a time: [`ReadOptions::frame`](super::ReadOptions)
//!   or `--frame K`, the frame axes counted as one with the first the fastest; without
//!   a choice it is refused, naming the count. A frame that is one run of the data is
//!   read alone (the rest is skipped); frames interleaved with the volume's axes need
//!   the whole data in memory, within the voxel limit.
//! - Geometry, giving the index-to-world affine: with `space directions`, the columns
//!   of the linear part are the direction vectors; otherwise `spacings` give a diagonal
//!   (finite and positive on the spatial axes; `nan` marks non-spatial axes); otherwise
//!   1 mm. `space origin` is the translation (else 0). Spacings are ignored when space
//!   directions are given. A 2-D image's third column is the unit normal of its first
//!   two. The world frame is **the header's `space`, kept as written**: an LPS file
//!   gives LPS world coordinates and a RAS file RAS ones; nothing is flipped.
//!   Spaces with time (`RAST` …) and space dimensions other than 2 and 3 are refused.
//! - `byte skip` (−1 meaning "the data is the last bytes of the file", raw only; for
//!   gzip it counts decompressed bytes) and `line skip` (lines of the data file, before
//!   decompression).
//! - `data file`: one file. The `LIST` and printf-style multi-file forms are refused.
//! - `kinds` only marks non-spatial axes as above; key/value pairs, comments and other
//!   fields (`content`, `units`, `measurement frame`, …) are ignored. A field given
//!   twice is refused. An attached file may carry bytes after its data; data beyond what
//!   the header describes in a gzip stream or a detached raw data file is refused.
//! - A detached pair written by voxlab records the data file's size and FNV-1a hash
//!   (`voxlab_data_bytes:=`, `voxlab_data_fnv1a64:=`); a data file that does not match
//!   them (an interrupted overwrite, two writers racing) is refused. With
//!   [`ReadOptions::confine_data_files`](super::ReadOptions) the data file must lie in
//!   the header's folder.
//!
//! # What is written
//!
//! `NRRD0004`, `space dimension: 3`, `space directions` and `space origin` from the
//! affine (exactly: numbers are written in shortest round-trip form), `kinds: domain
//! domain domain`, `endian: little`, gzip (or raw) encoding, attached or detached as
//! [`NrrdWriteOptions`] say. No `space` name is written because a volume does not know
//! its frame.

use super::{open, parse_text_samples, read_error, too_short, write_atomic};
use super::{write_samples_le, Endian, Samples, Stored};
use crate::error::{Error, Result};
use crate::volume::{check_dims, check_spacing, AnyVolume, VoxelKind};
use flate2::read::MultiGzDecoder;
use flate2::write::GzEncoder;
use flate2::Compression;
use glam::{DMat3, DMat4, DVec3};
use std::io::{self, BufRead, BufReader, Read, Seek, SeekFrom, Write};
use std::path::Path;

/// How [`write_nrrd`] writes a volume.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NrrdWriteOptions {
    /// Gzip-compress the data (`encoding: gzip`); else `encoding: raw`.
    pub gzip: bool,
    /// Write the data to a separate file beside the header, named after the header
    /// with its extension replaced by `.raw.gz` (gzip) or `.raw`.
    pub detached: bool,
}

impl Default for NrrdWriteOptions {
    /// One attached, gzip-compressed file.
    fn default() -> Self {
        NrrdWriteOptions {
            gzip: true,
            detached: false,
        }
    }
}

/// A reader (or writer) that keeps the 64-bit FNV-1a hash and the count of the bytes
/// that pass through it. (Not a CRC: the CRC-32 of a gzip file, which ends in the CRC
/// of its contents, is the same for different files far too often.)
struct Digest<R> {
    inner: R,
    hash: u64,
    count: u64,
}

impl<R> Digest<R> {
    fn new(inner: R) -> Self {
        Digest {
            inner,
            hash: 0xcbf2_9ce4_8422_2325,
            count: 0,
        }
    }
    fn update(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.hash = (self.hash ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
        self.count += bytes.len() as u64;
    }
}

impl<R: Read> Read for Digest<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.update(&buf[..n]);
        Ok(n)
    }
}

impl<W: Write> Write for Digest<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.update(&buf[..n]);
        Ok(n)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

/// Reads a NRRD volume (attached or detached header); see the module docs for what is
/// accepted.
pub fn read_nrrd(path: &Path) -> Result<AnyVolume> {
    read_nrrd_with(path, &super::ReadOptions::default())
}

/// How many 3-D volumes a NRRD holds (the product of the sizes of its axes that are
/// not the volume's), from its header alone.
pub fn nrrd_frames(path: &Path) -> Result<usize> {
    let (file, _) = open(path)?;
    let fields = read_fields(&mut BufReader::new(file), path)?;
    Ok(Header::parse(&fields, path)?.frames())
}

/// [`read_nrrd`] with [`ReadOptions`](super::ReadOptions): with `confine_data_files`, a
/// detached header may only name a data file inside its own folder; `frame` chooses
/// one 3-D volume of a file with non-spatial axes.
pub fn read_nrrd_with(path: &Path, options: &super::ReadOptions) -> Result<AnyVolume> {
    let (file, len) = open(path)?;
    let mut reader = BufReader::new(file);
    let fields = read_fields(&mut reader, path)?;
    let header = Header::parse(&fields, path)?;
    let pick = header.pick(options.frame, path)?;
    let samples = match &header.data_file {
        None => read_data(&mut reader, len, path, &header, &pick)?,
        Some(name) => {
            let dir = path.parent().unwrap_or(Path::new(""));
            let data_path = dir.join(name);
            if options.confine_data_files {
                super::confine(path, dir, &data_path, name)?;
            }
            let (file, len) = super::open_data_file(path, &data_path)?;
            let mismatch = |what: String| {
                Error::format(
                    path,
                    "data file",
                    format!(
                        "{} does not belong to this header: {what}; the pair comes from \
                         different writes (an interrupted or concurrent write?)",
                        data_path.display()
                    ),
                )
            };
            let mut reader = BufReader::new(file);
            if let Some((bytes, hash)) = header.data_check {
                // Checked before the data is decoded: the size at once, then the
                // checksum in one pass over the file.
                if len != bytes {
                    return Err(mismatch(format!(
                        "it holds {len} bytes, the header was written with {bytes}"
                    )));
                }
                let mut summed = Digest::new(&mut reader);
                io::copy(&mut summed, &mut io::sink()).map_err(|e| Error::io(&data_path, e))?;
                let got = summed.hash;
                if got != hash {
                    return Err(mismatch(format!(
                        "its FNV-1a hash is {got:016x}, the header was written with {hash:016x}"
                    )));
                }
                reader
                    .seek(SeekFrom::Start(0))
                    .map_err(|e| Error::io(&data_path, e))?;
            }
            let samples = read_data(&mut reader, len, &data_path, &header, &pick)?;
            if header.data_check.is_none()
                && header.encoding == Encoding::Raw
                && header.byte_skip >= 0
            {
                let used = reader
                    .stream_position()
                    .map_err(|e| Error::io(&data_path, e))?;
                if len > used {
                    return Err(Error::format(
                        &data_path,
                        "data",
                        format!(
                            "the data file holds {len} bytes, {} more than the header's \
                             sizes, type, line skip and byte skip describe ({used})",
                            len - used
                        ),
                    ));
                }
            }
            samples
        }
    };
    samples.into_volume(header.dims, header.affine)
}

/// Where a raw-encoded NRRD (no line skip) keeps its samples, for
/// [`super::brick::read_brick`]: after its own header (plus the byte skip, or the last
/// bytes of the file for `byte skip: -1`) or in its detached data file. `None` for
/// gzip or text encodings and for a line skip. The data file's length is checked; a
/// checksum voxlab recorded is checked only by a whole read ([`read_nrrd`]).
pub(crate) fn raw_layout(path: &Path) -> Result<Option<super::RawLayout>> {
    let (file, len) = open(path)?;
    let mut reader = BufReader::new(file);
    let fields = read_fields(&mut reader, path)?;
    let h = Header::parse(&fields, path)?;
    if h.encoding != Encoding::Raw || h.line_skip != 0 || h.frames() > 1 {
        return Ok(None);
    }
    let (data, start, len) = match &h.data_file {
        None => {
            let pos = reader.stream_position().map_err(|e| Error::io(path, e))?;
            (path.to_path_buf(), pos, len)
        }
        Some(name) => {
            let data = path.parent().unwrap_or(Path::new("")).join(name);
            let (_, len) = super::open_data_file(path, &data)?;
            (data, 0, len)
        }
    };
    let expected = h.count as u64 * h.stored.size() as u64;
    let available = len.saturating_sub(start);
    let offset = if h.byte_skip == -1 {
        if available < expected {
            return Err(too_short(&data, expected, available));
        }
        len - expected
    } else {
        let skip = h.byte_skip as u64;
        if skip > available {
            return Err(past_end(&data, skip, available));
        }
        if available - skip < expected {
            return Err(too_short(&data, expected, available - skip));
        }
        start + skip
    };
    Ok(Some(super::RawLayout {
        data,
        offset,
        stored: h.stored,
        endian: h.endian,
        dims: h.dims,
        affine: h.affine,
    }))
}

/// Reads an attached-header NRRD file held in memory (`path` only names it in
/// errors). A header that names a detached data file is refused: there is no
/// directory to find it in. Used by the fuzz targets; never panics.
pub fn read_nrrd_bytes(bytes: &[u8], path: &Path) -> Result<AnyVolume> {
    read_nrrd_bytes_frame(bytes, path, None)
}

/// [`read_nrrd_bytes`] of one 3-D volume of a file that holds several.
pub fn read_nrrd_bytes_frame(bytes: &[u8], path: &Path, frame: Option<usize>) -> Result<AnyVolume> {
    let mut reader = io::Cursor::new(bytes);
    let fields = read_fields(&mut reader, path)?;
    let header = Header::parse(&fields, path)?;
    if header.data_file.is_some() {
        return Err(Error::format(
            path,
            "data file",
            "a detached header cannot be read from memory",
        ));
    }
    let pick = header.pick(frame, path)?;
    let samples = read_data(&mut reader, bytes.len() as u64, path, &header, &pick)?;
    samples.into_volume(header.dims, header.affine)
}

/// Writes a volume as NRRD, atomically. With `detached`, the data file is written
/// first, so a header never names a data file that is not there.
pub fn write_nrrd(path: &Path, vol: &AnyVolume, options: NrrdWriteOptions) -> Result<()> {
    let gzip = options.gzip;
    if !options.detached {
        let header = header_text(vol, gzip, None);
        return write_atomic(path, |w| {
            w.write_all(header.as_bytes())
                .and_then(|()| write_data(w, vol, gzip))
                .map_err(|e| Error::io(path, e))
        });
    }
    let data_name = detached_data_name(path, gzip)?;
    let data_path = path.with_file_name(&data_name);
    let mut check = (0u64, 0u64);
    write_atomic(&data_path, |w| {
        let mut w = Digest::new(w);
        write_data(&mut w, vol, gzip).map_err(|e| Error::io(&data_path, e))?;
        check = (w.count, w.hash);
        Ok(())
    })?;
    let mut header = header_text(vol, gzip, Some(&data_name));
    // The data file's size and hash: a reader can tell a header from the data of
    // another write (an interrupted overwrite, two writers racing).
    header.push_str(&format!(
        "voxlab_data_bytes:={}\nvoxlab_data_fnv1a64:={:016x}\n",
        check.0, check.1
    ));
    write_atomic(path, |w| {
        w.write_all(header.as_bytes())
            .map_err(|e| Error::io(path, e))
    })
}

// ---------------------------------------------------------------------------------
// Reading the header
// ---------------------------------------------------------------------------------

/// A header larger than this is refused (real ones are a few kilobytes).
const MAX_HEADER_BYTES: u64 = 16 << 20;

/// The most bytes one ascii value may take with its separators (`-1.2345678901234567e-308`
/// and white space); text beyond `sizes × this` is not read.
const MAX_TEXT_VALUE_BYTES: u64 = 64;

/// NRRD's limit on the number of axes.
const MAX_DIMENSION: usize = 16;

/// Reads the header's `field: value` lines up to the blank line (or the end of the
/// file, for a detached header), leaving `reader` at the first data byte. Field names
/// are canonical ([`canonical_name`]); comments and `key:=value` pairs are dropped.
fn read_fields(reader: &mut impl BufRead, path: &Path) -> Result<Vec<(String, String)>> {
    let not_nrrd = || {
        Error::format(
            path,
            "magic",
            "not a NRRD file: the first line must be NRRD0001 to NRRD0005",
        )
    };
    let io_error = |e| Error::io(path, e);
    match read_line(reader, 64).map_err(io_error)? {
        Line::Text(magic) if is_magic(&magic) => {}
        _ => return Err(not_nrrd()),
    }

    let mut fields: Vec<(String, String)> = Vec::new();
    let mut budget = MAX_HEADER_BYTES;
    loop {
        let line = match read_line(reader, budget).map_err(io_error)? {
            Line::Text(line) => line,
            // The end of the file also ends the header: a detached one needs no blank line.
            Line::End => break,
            Line::TooLong => {
                return Err(Error::format(
                    path,
                    "header",
                    format!("no blank line ends the header in its first {MAX_HEADER_BYTES} bytes"),
                ))
            }
        };
        budget = budget.saturating_sub(line.len() as u64 + 1);
        if line.is_empty() {
            break;
        }
        if line.starts_with('#') {
            continue;
        }
        let Some(colon) = line.find(':') else {
            return Err(Error::format(
                path,
                "header",
                format!(
                    "line '{}' is neither 'field: value' nor 'key:=value'",
                    super::snippet(&line)
                ),
            ));
        };
        if let Some(value) = line[colon + 1..].strip_prefix('=') {
            // Key/value metadata: only voxlab's own keys are kept, under a name no
            // field can have.
            let key = &line[..colon];
            if key.starts_with("voxlab_") {
                fields.push((format!("={key}"), value.trim().to_string()));
            }
            continue;
        }
        let name = canonical_name(line[..colon].trim());
        let value = line[colon + 1..].trim().to_string();
        if fields.iter().any(|(n, _)| *n == name) {
            return Err(Error::format(path, name, "the field is given twice"));
        }
        // `data file: LIST` ends the fields: the lines after it name the data files.
        let list = name == "data file" && value.split_whitespace().next() == Some("LIST");
        fields.push((name, value));
        if list {
            break;
        }
    }
    Ok(fields)
}

/// `NRRD0001` to `NRRD0005`.
fn is_magic(line: &str) -> bool {
    line.len() == 8 && line.starts_with("NRRD000") && matches!(line.as_bytes()[7], b'1'..=b'5')
}

/// Field names as this reader knows them (NRRD allows a few spellings).
fn canonical_name(name: &str) -> String {
    let name = name.to_ascii_lowercase();
    match name.as_str() {
        "datafile" => "data file".into(),
        "byteskip" => "byte skip".into(),
        "lineskip" => "line skip".into(),
        "centerings" => "centers".into(),
        _ => name,
    }
}

/// A header line, read with a length limit.
enum Line {
    /// The line without its `\n` or `\r\n`.
    Text(String),
    /// The file ended before the line started.
    End,
    /// No line end within the limit (binary junk, or a header far too large).
    TooLong,
}

/// Reads one line of at most `limit` bytes, so binary junk cannot be read as one
/// endless header line.
fn read_line(reader: &mut impl BufRead, limit: u64) -> io::Result<Line> {
    let mut buf = Vec::new();
    reader.take(limit + 1).read_until(b'\n', &mut buf)?;
    if buf.is_empty() {
        return Ok(Line::End);
    }
    if buf.len() as u64 > limit {
        return Ok(Line::TooLong);
    }
    while matches!(buf.last(), Some(b'\n' | b'\r')) {
        buf.pop();
    }
    Ok(Line::Text(String::from_utf8_lossy(&buf).into_owned()))
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Encoding {
    Raw,
    Gzip,
    Text,
}

/// What the header says, checked and reduced to what a volume needs.
#[derive(Clone, Debug)]
struct Header {
    stored: Stored,
    /// The `type` as written, for messages.
    type_name: String,
    encoding: Encoding,
    /// Little when the byte order does not matter (1-byte types, text).
    endian: Endian,
    dims: [usize; 3],
    /// Samples of one 3-D volume.
    count: usize,
    /// Samples in the data, every frame.
    total: usize,
    voxel_strides: [usize; 3],
    /// The axes past the volume's that number its frames (none for one volume).
    frame_axes: Vec<FrameAxis>,
    affine: DMat4,
    byte_skip: i64,
    line_skip: u64,
    data_file: Option<String>,
    /// The byte count and FNV-1a hash of the data file that voxlab recorded when it
    /// wrote the pair (`voxlab_data_bytes:=`, `voxlab_data_fnv1a64:=`).
    data_check: Option<(u64, u64)>,
}

/// Looks fields up and builds errors that name them.
struct Fields<'a> {
    fields: &'a [(String, String)],
    path: &'a Path,
}

impl Fields<'_> {
    fn get(&self, name: &str) -> Option<&str> {
        self.fields
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }
    fn require(&self, name: &str) -> Result<&str> {
        self.get(name)
            .ok_or_else(|| self.error(name, "the required field is missing"))
    }
    fn error(&self, name: &str, message: impl Into<String>) -> Error {
        Error::format(self.path, name, message)
    }
    /// A whitespace-separated list with one entry per axis.
    fn per_axis(&self, name: &str, dimension: usize) -> Result<Option<Vec<&str>>> {
        let Some(value) = self.get(name) else {
            return Ok(None);
        };
        let items: Vec<&str> = value.split_whitespace().collect();
        if items.len() != dimension {
            return Err(self.error(
                name,
                format!(
                    "has {} entries but the dimension is {dimension}",
                    items.len()
                ),
            ));
        }
        Ok(Some(items))
    }
}

impl Header {
    fn parse(fields: &[(String, String)], path: &Path) -> Result<Header> {
        let f = Fields { fields, path };

        let type_name = f.require("type")?.to_string();
        let stored = parse_type(&type_name).ok_or_else(|| {
            f.error(
                "type",
                format!(
                    "'{}' is not a supported NRRD type",
                    super::snippet(&type_name)
                ),
            )
        })?;

        let encoding = match f.require("encoding")?.to_ascii_lowercase().as_str() {
            "raw" => Encoding::Raw,
            "gzip" | "gz" => Encoding::Gzip,
            "ascii" | "text" | "txt" => Encoding::Text,
            "bzip2" | "bz2" => {
                return Err(f.error(
                    "encoding",
                    "bzip2 is not supported; recompress with gzip (unu save -e gzip)",
                ))
            }
            other => {
                return Err(f.error(
                    "encoding",
                    format!(
                        "'{}' is not supported (raw, gzip and ascii are)",
                        super::snippet(other)
                    ),
                ))
            }
        };

        let endian = match f.get("endian") {
            Some("little") => Endian::Little,
            Some("big") => Endian::Big,
            Some(other) => {
                return Err(f.error(
                    "endian",
                    format!("'{}' is neither little nor big", super::snippet(other)),
                ))
            }
            None if stored.size() > 1 && encoding != Encoding::Text => {
                return Err(f.error(
                    "endian",
                    "the field is required for multi-byte types in raw or gzip data",
                ))
            }
            None => Endian::Little,
        };

        let dimension: usize = f
            .require("dimension")?
            .parse()
            .ok()
            .filter(|d| (1..=MAX_DIMENSION).contains(d))
            .ok_or_else(|| {
                f.error(
                    "dimension",
                    format!("must be an integer from 1 to {MAX_DIMENSION}"),
                )
            })?;
        f.require("sizes")?;
        let sizes = f
            .per_axis("sizes", dimension)?
            .unwrap_or_default()
            .iter()
            .map(|s| {
                s.parse::<usize>().map_err(|_| {
                    f.error(
                        "sizes",
                        format!("'{}' is not a non-negative integer", super::snippet(s)),
                    )
                })
            })
            .collect::<Result<Vec<usize>>>()?;

        let Layout {
            dims,
            affine,
            voxel_strides,
            frame_axes,
        } = geometry(&f, &sizes)?;
        let count = check_dims(dims).map_err(|e| f.error("sizes", e.to_string()))?;
        // Every frame must be in the file, though one is read: the whole data's size
        // is checked before anything is allocated.
        let total = sizes
            .iter()
            .try_fold(1usize, |a, &n| a.checked_mul(n))
            .filter(|&t| t > 0 && t <= 1 << 62)
            .ok_or_else(|| f.error("sizes", "too many samples, or a size of 0"))?;

        let byte_skip: i64 = match f.get("byte skip") {
            None => 0,
            Some(s) => s.parse().ok().filter(|&b| b >= -1).ok_or_else(|| {
                f.error(
                    "byte skip",
                    format!("'{}' is not an integer ≥ -1", super::snippet(s)),
                )
            })?,
        };
        if byte_skip == -1 && encoding != Encoding::Raw {
            return Err(f.error("byte skip", "-1 is only allowed with raw encoding"));
        }
        let line_skip: u64 = match f.get("line skip") {
            None => 0,
            Some(s) => s.parse().map_err(|_| {
                f.error(
                    "line skip",
                    format!("'{}' is not a non-negative integer", super::snippet(s)),
                )
            })?,
        };

        let data_file = match f.get("data file") {
            None => None,
            Some(v) => {
                let tokens: Vec<&str> = v.split_whitespace().collect();
                let multi = tokens.first() == Some(&"LIST")
                    || (tokens.len() >= 3 && tokens[0].contains('%'));
                if multi {
                    return Err(f.error(
                        "data file",
                        "multi-file data (LIST or printf-style) is not supported; join the files into one",
                    ));
                }
                if v.is_empty() {
                    return Err(f.error("data file", "the file name is empty"));
                }
                Some(v.to_string())
            }
        };

        let data_check = match (f.get("=voxlab_data_bytes"), f.get("=voxlab_data_fnv1a64")) {
            (None, None) => None,
            (Some(b), Some(c)) => {
                let bytes = b.parse::<u64>().map_err(|_| {
                    f.error(
                        "voxlab_data_bytes",
                        format!("'{}' is not a byte count", super::snippet(b)),
                    )
                })?;
                let hash = u64::from_str_radix(c, 16).map_err(|_| {
                    f.error(
                        "voxlab_data_fnv1a64",
                        format!("'{}' is not 16 hex digits", super::snippet(c)),
                    )
                })?;
                Some((bytes, hash))
            }
            _ => {
                return Err(f.error(
                    "voxlab_data_bytes",
                    "voxlab_data_bytes and voxlab_data_fnv1a64 go together",
                ))
            }
        };
        Ok(Header {
            data_check,
            stored,
            type_name,
            encoding,
            endian,
            dims,
            count,
            total,
            voxel_strides,
            frame_axes,
            affine,
            byte_skip,
            line_skip,
            data_file,
        })
    }

    /// How many 3-D volumes the data holds.
    fn frames(&self) -> usize {
        self.frame_axes.iter().map(|a| a.size).product()
    }

    /// Where frame `frame` lies in the data (see [`super::choose_frame`]): its index
    /// split over the frame axes, the first fastest.
    fn pick(&self, frame: Option<usize>, path: &Path) -> Result<super::FramePick> {
        let axes = self
            .frame_axes
            .iter()
            .map(|a| match &a.kind {
                Some(k) => format!("axis {}: {} ({k})", a.axis, a.size),
                None => format!("axis {}: {}", a.axis, a.size),
            })
            .collect::<Vec<_>>()
            .join(", ");
        let mut k = super::choose_frame(path, "sizes", self.frames(), &axes, frame)?;
        let mut base = 0;
        for a in &self.frame_axes {
            base += (k % a.size) * a.stride;
            k /= a.size;
        }
        Ok(super::FramePick {
            total: self.total,
            dims: self.dims,
            base,
            strides: self.voxel_strides,
        })
    }
}

/// A NRRD type name (any standard spelling) as a stored type.
fn parse_type(name: &str) -> Option<Stored> {
    let name = name.split_whitespace().collect::<Vec<_>>().join(" ");
    Some(match name.as_str() {
        "signed char" | "int8" | "int8_t" => Stored::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => Stored::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            Stored::I16
        }
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => Stored::U16,
        "int" | "signed int" | "int32" | "int32_t" => Stored::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => Stored::U32,
        "longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t" => Stored::I64,
        "ulonglong" | "unsigned long long" | "unsigned long long int" | "uint64" | "uint64_t" => {
            Stored::U64
        }
        "float" => Stored::F32,
        "double" => Stored::F64,
        _ => return None,
    })
}

/// `kinds` entries that describe a spatial (domain) axis; every other kind, such as
/// `vector` or `RGB-color`, is a non-spatial axis.
const DOMAIN_KINDS: &[&str] = &["domain", "space", "time", "none", "???"];

/// An axis that numbers the file's 3-D volumes (frames).
#[derive(Clone, Debug, PartialEq)]
struct FrameAxis {
    axis: usize,
    size: usize,
    /// Samples between neighbours along the axis.
    stride: usize,
    /// Its `kinds` entry, if given.
    kind: Option<String>,
}

/// The volume's axes, their affine, and the axes that number frames.
struct Layout {
    dims: [usize; 3],
    affine: DMat4,
    /// Samples between neighbours along the volume's x, y and z.
    voxel_strides: [usize; 3],
    frame_axes: Vec<FrameAxis>,
}

/// Chooses the volume's axes and builds the index-to-world affine.
fn geometry(f: &Fields, sizes: &[usize]) -> Result<Layout> {
    let dimension = sizes.len();
    let space_dim = space_dimension(f)?;
    let directions = match f.get("space directions") {
        None => None,
        Some(v) => Some(parse_directions(v).map_err(|m| f.error("space directions", m))?),
    };
    let origin = match f.get("space origin") {
        None => None,
        Some(v) => Some(parse_vector(v.trim()).map_err(|m| f.error("space origin", m))?),
    };

    // The space's dimension: stated, or else the length of the vectors.
    let first_vector = directions
        .iter()
        .flatten()
        .flatten()
        .next()
        .or(origin.as_ref());
    let space_dim = match (space_dim, first_vector) {
        (Some(d), _) => Some(d),
        (None, Some(v)) if v.len() == 2 || v.len() == 3 => Some(v.len()),
        (None, Some(v)) => {
            return Err(f.error(
                "space directions",
                format!("vectors of {} components; 2 or 3 are supported", v.len()),
            ))
        }
        (None, None) => None,
    };
    let to_vec3 = |v: &[f64], field: &str| -> Result<DVec3> {
        if Some(v.len()) != space_dim {
            return Err(f.error(
                field,
                format!(
                    "a vector has {} components but the space dimension is {}",
                    v.len(),
                    space_dim.unwrap_or(0)
                ),
            ));
        }
        if !v.iter().all(|x| x.is_finite()) {
            return Err(f.error(field, "the components must be finite"));
        }
        Ok(DVec3::new(v[0], v[1], v.get(2).copied().unwrap_or(0.0)))
    };
    let directions: Option<Vec<Option<DVec3>>> = match directions {
        None => None,
        Some(d) if d.len() != dimension => {
            return Err(f.error(
                "space directions",
                format!("has {} entries but the dimension is {dimension}", d.len()),
            ))
        }
        Some(d) => Some(
            d.iter()
                .map(|v| {
                    v.as_deref()
                        .map(|v| to_vec3(v, "space directions"))
                        .transpose()
                })
                .collect::<Result<_>>()?,
        ),
    };
    let origin = match origin {
        None => DVec3::ZERO,
        Some(v) => to_vec3(&v, "space origin")?,
    };

    let spacings: Option<Vec<f64>> = match f.per_axis("spacings", dimension)? {
        None => None,
        Some(items) => Some(
            items
                .iter()
                .map(|s| {
                    s.parse::<f64>().map_err(|_| {
                        f.error(
                            "spacings",
                            format!("'{}' is not a number", super::snippet(s)),
                        )
                    })
                })
                .collect::<Result<_>>()?,
        ),
    };
    let kinds = f.per_axis("kinds", dimension)?;

    // Which axes are spatial: a `none` direction, a non-domain kind or the kind `time`
    // says no.
    let spatial = |a: usize| {
        let by_direction = directions.as_ref().is_none_or(|d| d[a].is_some());
        let by_kind = kinds.as_ref().is_none_or(|k| {
            DOMAIN_KINDS.iter().any(|d| d.eq_ignore_ascii_case(k[a]))
                && !k[a].eq_ignore_ascii_case("time")
        });
        by_direction && by_kind
    };
    // The volume's axes: the spatial ones, less those of size 1 from the slowest end
    // while there are more than three; without directions, spatial axes past the
    // third number frames like the non-spatial ones.
    let mut keep: Vec<usize> = (0..dimension).filter(|&a| spatial(a)).collect();
    while keep.len() > 3 {
        match keep.iter().rposition(|&a| sizes[a] == 1) {
            Some(p) => {
                keep.remove(p);
            }
            None => break,
        }
    }
    if keep.len() > 3 && directions.is_some() {
        return Err(f.error(
            "space directions",
            format!(
                "{} axes have directions; a volume has at most three (sizes {sizes:?})",
                keep.len()
            ),
        ));
    }
    keep.truncate(3);
    if keep.len() < 2 {
        return Err(f.error(
            "dimension",
            format!(
                "sizes {sizes:?} do not describe a 2-D or 3-D volume: {} spatial ax{}",
                keep.len(),
                if keep.len() == 1 { "is" } else { "es" }
            ),
        ));
    }
    // Every other axis of size above 1 numbers the file's frames, the first fastest.
    let mut strides = vec![1usize; dimension];
    for a in 1..dimension {
        strides[a] = strides[a - 1].saturating_mul(sizes[a - 1]);
    }
    let frame_axes: Vec<FrameAxis> = (0..dimension)
        .filter(|a| !keep.contains(a) && sizes[*a] > 1)
        .map(|a| FrameAxis {
            axis: a,
            size: sizes[a],
            stride: strides[a],
            kind: kinds.as_ref().map(|k| k[a].to_string()),
        })
        .collect();
    let mut voxel_strides = [0usize; 3];
    for (i, &a) in keep.iter().enumerate() {
        voxel_strides[i] = strides[a];
    }

    // The columns of the linear part: one world vector per kept axis.
    let mut columns: Vec<DVec3> = Vec::with_capacity(3);
    for (i, &a) in keep.iter().enumerate() {
        let column = match (&directions, &spacings) {
            // `spatial(a)` holds, so the direction is there.
            (Some(d), _) => d[a].unwrap_or(DVec3::ZERO),
            (None, Some(s)) => {
                check_spacing([s[a]; 3]).map_err(|_| {
                    f.error(
                        "spacings",
                        format!("spacing {} of axis {a} must be finite and positive", s[a]),
                    )
                })?;
                DVec3::AXES[i] * s[a]
            }
            (None, None) => DVec3::AXES[i],
        };
        columns.push(column);
    }
    if columns.len() == 2 {
        // A 2-D image: the third axis is the unit normal (1 mm) of the first two.
        columns.push(columns[0].cross(columns[1]).normalize_or_zero());
    }
    let linear = DMat3::from_cols(columns[0], columns[1], columns[2]);
    let scale = columns[0].length() * columns[1].length() * columns[2].length();
    if linear.determinant().abs() <= 1e-12 * scale || scale == 0.0 {
        return Err(f.error(
            "space directions",
            "the direction vectors are singular (zero or linearly dependent)",
        ));
    }
    let affine = DMat4::from_cols(
        linear.x_axis.extend(0.0),
        linear.y_axis.extend(0.0),
        linear.z_axis.extend(0.0),
        origin.extend(1.0),
    );

    let dims = [
        sizes[keep[0]],
        sizes[keep[1]],
        keep.get(2).map_or(1, |&a| sizes[a]),
    ];
    Ok(Layout {
        dims,
        affine,
        voxel_strides,
        frame_axes,
    })
}

/// The space's dimension from `space` or `space dimension` (2 or 3), if given.
fn space_dimension(f: &Fields) -> Result<Option<usize>> {
    let from_name = match f.get("space") {
        None => None,
        Some(name) => match name.to_ascii_lowercase().as_str() {
            "right-anterior-superior"
            | "ras"
            | "left-anterior-superior"
            | "las"
            | "left-posterior-superior"
            | "lps"
            | "scanner-xyz"
            | "3d-right-handed"
            | "3d-left-handed" => Some(3),
            "right-anterior-superior-time"
            | "rast"
            | "left-anterior-superior-time"
            | "last"
            | "left-posterior-superior-time"
            | "lpst"
            | "scanner-xyz-time"
            | "3d-right-handed-time"
            | "3d-left-handed-time" => {
                return Err(f.error("space", "spaces with time are not supported"))
            }
            _ => {
                return Err(f.error(
                    "space",
                    format!("'{}' is not a known NRRD space", super::snippet(name)),
                ))
            }
        },
    };
    let from_dim = match f.get("space dimension") {
        None => None,
        Some(s) => Some(
            s.parse::<usize>()
                .ok()
                .filter(|d| *d == 2 || *d == 3)
                .ok_or_else(|| {
                    f.error(
                        "space dimension",
                        format!("'{}': 2 and 3 are supported", super::snippet(s)),
                    )
                })?,
        ),
    };
    match (from_name, from_dim) {
        (Some(a), Some(b)) if a != b => Err(f.error(
            "space dimension",
            format!("{b} disagrees with the space, which is {a}-dimensional"),
        )),
        (a, b) => Ok(a.or(b)),
    }
}

/// `space directions`: one `(x,y,z)` vector or `none` per axis.
fn parse_directions(value: &str) -> std::result::Result<Vec<Option<Vec<f64>>>, String> {
    let mut out = Vec::new();
    let mut rest = value.trim_start();
    while !rest.is_empty() {
        if let Some(r) = rest.strip_prefix("none") {
            out.push(None);
            rest = r.trim_start();
        } else if rest.starts_with('(') {
            let end = rest.find(')').ok_or("a '(' is not closed")?;
            out.push(Some(parse_vector(&rest[..=end])?));
            rest = rest[end + 1..].trim_start();
        } else {
            return Err(format!(
                "expected '(x,y,z)' or 'none' at '{}'",
                super::snippet(rest)
            ));
        }
    }
    Ok(out)
}

/// One vector `(a,b,c)`; white space around the numbers is allowed.
fn parse_vector(s: &str) -> std::result::Result<Vec<f64>, String> {
    let inner = s
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .ok_or_else(|| format!("'{}' is not a vector '(x,y,z)'", super::snippet(s)))?;
    inner
        .split(',')
        .map(|c| {
            c.trim()
                .parse::<f64>()
                .map_err(|_| format!("'{}' is not a number", super::snippet(c.trim())))
        })
        .collect()
}

// ---------------------------------------------------------------------------------
// Reading the data
// ---------------------------------------------------------------------------------

/// Reads the samples from `reader`, which holds the data file (`path`, `len` bytes)
/// positioned where the data part starts (after the header, or at 0 when detached).
fn read_data<R: BufRead + Seek>(
    reader: &mut R,
    len: u64,
    path: &Path,
    h: &Header,
    pick: &super::FramePick,
) -> Result<Samples> {
    for i in 0..h.line_skip {
        let n = reader.skip_until(b'\n').map_err(|e| Error::io(path, e))?;
        if n == 0 {
            return Err(Error::format(
                path,
                "line skip",
                format!("{} lines to skip, but the data ends after {i}", h.line_skip),
            ));
        }
    }
    let expected = h.total as u64 * h.stored.size() as u64;
    match h.encoding {
        Encoding::Raw => {
            let pos = reader.stream_position().map_err(|e| Error::io(path, e))?;
            let mut available = len.saturating_sub(pos);
            if h.byte_skip == -1 {
                // The data is the last `expected` bytes of the file.
                if available < expected {
                    return Err(too_short(path, expected, available));
                }
                reader
                    .seek(SeekFrom::Start(len - expected))
                    .map_err(|e| Error::io(path, e))?;
            } else {
                let skip = h.byte_skip as u64;
                if skip > available {
                    return Err(past_end(path, skip, available));
                }
                reader
                    .seek(SeekFrom::Current(skip as i64))
                    .map_err(|e| Error::io(path, e))?;
                available -= skip;
                // Checked before allocating: the file must hold all the data.
                if available < expected {
                    return Err(too_short(path, expected, available));
                }
            }
            super::read_picked(reader, h.stored, h.endian, pick, path)
        }
        Encoding::Gzip => {
            // `byte skip` counts decompressed bytes, as in teem.
            let mut gz = MultiGzDecoder::new(reader);
            skip_bytes(&mut gz, h.byte_skip as u64, path)?;
            let samples = super::read_picked(&mut gz, h.stored, h.endian, pick, path)?;
            // Decode to the end of the stream, so that its checksum is verified and a
            // truncated or corrupt tail is reported rather than silently ignored; data
            // beyond what the header describes is refused.
            let extra = io::copy(&mut gz, &mut io::sink()).map_err(|e| read_error(path, e))?;
            if extra > 0 {
                return Err(Error::format(
                    path,
                    "data",
                    format!(
                        "the gzip data holds {extra} bytes more than the header's sizes, type \
                         and byte skip describe ({})",
                        expected + h.byte_skip.max(0) as u64
                    ),
                ));
            }
            Ok(samples)
        }
        Encoding::Text => {
            skip_bytes(reader, h.byte_skip as u64, path)?;
            // At most what the values can need, however long the file: a value takes
            // at most MAX_TEXT_VALUE_BYTES with its separators.
            let limit = (h.total as u64)
                .saturating_mul(MAX_TEXT_VALUE_BYTES)
                .saturating_add(1 << 16);
            let mut bytes = Vec::new();
            reader
                .take(limit)
                .read_to_end(&mut bytes)
                .map_err(|e| Error::io(path, e))?;
            // A cut inside a UTF-8 character at the limit is not an encoding error.
            if bytes.len() as u64 == limit {
                if let Err(e) = std::str::from_utf8(&bytes) {
                    if e.error_len().is_none() {
                        bytes.truncate(e.valid_up_to());
                    }
                }
            }
            let text = String::from_utf8(bytes)
                .map_err(|_| Error::format(path, "data", "the ascii data is not text"))?;
            Ok(parse_text_samples(&text, h.stored, h.total, path, &h.type_name)?.pick(pick))
        }
    }
}

fn skip_bytes(reader: &mut impl Read, skip: u64, path: &Path) -> Result<()> {
    let skipped =
        io::copy(&mut reader.take(skip), &mut io::sink()).map_err(|e| read_error(path, e))?;
    if skipped < skip {
        return Err(past_end(path, skip, skipped));
    }
    Ok(())
}

fn past_end(path: &Path, skip: u64, available: u64) -> Error {
    Error::format(
        path,
        "byte skip",
        format!("skipping {skip} bytes goes past the end of the data ({available} bytes)"),
    )
}

// ---------------------------------------------------------------------------------
// Writing
// ---------------------------------------------------------------------------------

fn header_text(vol: &AnyVolume, gzip: bool, data_file: Option<&str>) -> String {
    let [nx, ny, nz] = vol.dims();
    let affine = vol.affine();
    let type_name = match vol.kind() {
        VoxelKind::U8 => "unsigned char",
        VoxelKind::U16 => "unsigned short",
        VoxelKind::I16 => "short",
        VoxelKind::F32 => "float",
    };
    // `{}` on f64 prints the shortest text that parses back to the same number.
    let vector = |v: DVec3| format!("({},{},{})", v.x, v.y, v.z);
    let linear = DMat3::from_mat4(affine);
    let mut h = String::new();
    h.push_str("NRRD0004\n");
    h.push_str("# Complete NRRD file format specification at:\n");
    h.push_str("# http://teem.sourceforge.net/nrrd/format.html\n");
    h.push_str("# Written by voxlab\n");
    h.push_str(&format!("type: {type_name}\n"));
    h.push_str("dimension: 3\n");
    h.push_str("space dimension: 3\n");
    h.push_str(&format!("sizes: {nx} {ny} {nz}\n"));
    h.push_str(&format!(
        "space directions: {} {} {}\n",
        vector(linear.x_axis),
        vector(linear.y_axis),
        vector(linear.z_axis)
    ));
    h.push_str("kinds: domain domain domain\n");
    h.push_str("endian: little\n");
    h.push_str(if gzip {
        "encoding: gzip\n"
    } else {
        "encoding: raw\n"
    });
    h.push_str(&format!(
        "space origin: {}\n",
        vector(affine.w_axis.truncate())
    ));
    match data_file {
        Some(name) => h.push_str(&format!("data file: {name}\n")),
        // The blank line that separates an attached header from its data.
        None => h.push('\n'),
    }
    h
}

/// `<stem>.raw.gz` (or `.raw`) beside the header.
fn detached_data_name(path: &Path, gzip: bool) -> Result<String> {
    let stem = path
        .file_stem()
        .and_then(|s| s.to_str())
        .filter(|s| !s.is_empty() && !s.starts_with(char::is_whitespace))
        .ok_or_else(|| {
            Error::invalid(
                "output file",
                format!(
                    "{}: a detached NRRD needs a UTF-8 file name to name its data file",
                    path.display()
                ),
            )
        })?;
    Ok(format!("{stem}.raw{}", if gzip { ".gz" } else { "" }))
}

fn write_data(w: &mut dyn Write, vol: &AnyVolume, gzip: bool) -> io::Result<()> {
    if gzip {
        let mut gz = GzEncoder::new(w, Compression::default());
        write_samples_le(&mut gz, vol)?;
        gz.finish()?;
        Ok(())
    } else {
        write_samples_le(w, vol)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fields(text: &str) -> Vec<(String, String)> {
        read_fields(&mut text.as_bytes(), Path::new("t.nrrd")).unwrap()
    }

    fn header(text: &str) -> Result<Header> {
        Header::parse(&fields(text), Path::new("t.nrrd"))
    }

    #[test]
    fn fields_and_comments() {
        let f = fields("NRRD0005\n# c\ntype: float\nfoo:=bar: baz\nDataFile: x.raw\n\njunk");
        assert_eq!(
            f,
            vec![
                ("type".to_string(), "float".to_string()),
                ("data file".to_string(), "x.raw".to_string())
            ]
        );
        let e = read_fields(&mut &b"NRRD0006\n"[..], Path::new("t")).unwrap_err();
        assert!(e.to_string().contains("magic"), "{e}");
        let e = read_fields(&mut &b"NRRD0004\ntype: a\ntype: b\n"[..], Path::new("t")).unwrap_err();
        assert!(e.to_string().contains("twice"), "{e}");
    }

    #[test]
    fn types_and_aliases() {
        assert_eq!(parse_type("unsigned  char"), Some(Stored::U8));
        assert_eq!(parse_type("signed char"), Some(Stored::I8));
        assert_eq!(parse_type("unsigned long long int"), Some(Stored::U64));
        assert_eq!(parse_type("uint16_t"), Some(Stored::U16));
        assert_eq!(parse_type("double"), Some(Stored::F64));
        assert_eq!(parse_type("block"), None);
    }

    #[test]
    fn axes_of_size_one_are_dropped() {
        let base = "NRRD0004\ntype: float\nencoding: raw\nendian: little\n";
        // A 4-D file with a singleton time axis at the end.
        let h = header(&format!("{base}dimension: 4\nsizes: 4 5 6 1\n")).unwrap();
        assert_eq!(h.dims, [4, 5, 6]);
        // A singleton vector axis in front, marked by `none`.
        let h = header(&format!(
            "{base}dimension: 4\nsizes: 1 4 5 6\nspace directions: none (2,0,0) (0,3,0) (0,0,4)\n"
        ))
        .unwrap();
        assert_eq!(h.dims, [4, 5, 6]);
        assert_eq!(h.affine, DMat4::from_scale(DVec3::new(2.0, 3.0, 4.0)));
        // A 2-D image: nz = 1, third column the unit normal.
        let h = header(&format!(
            "{base}dimension: 2\nsizes: 4 5\nspacings: 0.5 2\n"
        ))
        .unwrap();
        assert_eq!(h.dims, [4, 5, 1]);
        assert_eq!(h.affine, DMat4::from_scale(DVec3::new(0.5, 2.0, 1.0)));
        // An RGB axis numbers frames: three 2-D images, the colour fastest.
        let h = header(&format!(
            "{base}dimension: 3\nsizes: 3 4 5\nkinds: RGB-color domain domain\n"
        ))
        .unwrap();
        assert_eq!(
            (h.dims, h.frames(), h.voxel_strides),
            ([4, 5, 1], 3, [3, 12, 0])
        );
        let p = Path::new("rgb.nrrd");
        let e = h.pick(None, p).unwrap_err().to_string();
        assert!(
            e.contains("sizes") && e.contains("--frame") && e.contains("RGB-color"),
            "{e}"
        );
        assert_eq!(h.pick(Some(2), p).unwrap().base, 2);
        assert!(h.pick(Some(3), p).is_err());
        // Without directions or kinds, axes past the third number frames.
        let h = header(&format!("{base}dimension: 4\nsizes: 2 4 5 6\n")).unwrap();
        assert_eq!((h.dims, h.frames()), ([2, 4, 5], 6));
        assert_eq!(h.pick(Some(4), p).unwrap().base, 4 * 40);
        // A time axis between space axes, by kinds: frames with a stride.
        let h = header(&format!(
            "{base}dimension: 4\nsizes: 4 3 5 6\nkinds: space time space space\n"
        ))
        .unwrap();
        assert_eq!(
            (h.dims, h.frames(), h.voxel_strides),
            ([4, 5, 6], 3, [1, 12, 60])
        );
        assert_eq!(h.pick(Some(1), p).unwrap().base, 4);
        // Two frame axes: the first is the fastest.
        let h = header(&format!(
            "{base}dimension: 5\nsizes: 2 4 5 6 3\nspace directions: none (1,0,0) (0,1,0) (0,0,1) none\n"
        ))
        .unwrap();
        assert_eq!(h.frames(), 6);
        assert_eq!(h.pick(Some(3), p).unwrap().base, 1 + 240);
        // Four spatial directions are not a volume.
        let e = header(&format!(
            "{base}dimension: 4\nsizes: 2 4 5 6\nspace directions: (1,0,0) (0,1,0) (0,0,1) (1,1,1)\n"
        ))
        .unwrap_err();
        assert!(e.to_string().contains("space directions"), "{e}");
        // A size of 0 anywhere is refused.
        let e = header(&format!("{base}dimension: 4\nsizes: 2 4 5 0\n")).unwrap_err();
        assert!(e.to_string().contains("sizes"), "{e}");
    }

    #[test]
    fn directions_parse() {
        let d = parse_directions("none ( 1, 0,0) (0,1.5,0)").unwrap();
        assert_eq!(
            d,
            vec![None, Some(vec![1.0, 0.0, 0.0]), Some(vec![0.0, 1.5, 0.0])]
        );
        assert!(parse_directions("(1,0,0").is_err());
        assert!(parse_directions("(1,x,0)").is_err());
        assert!(parse_directions("[1,0,0]").is_err());
    }
}
