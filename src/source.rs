//! Opening input files: regular files only, and reads bounded by what the file's kind
//! can need.
//!
//! Every reader of the crate opens its input here. A FIFO, a pipe (`<(cat x)`), a
//! socket or a device such as `/dev/zero` is refused at once with a message naming the
//! file and what it is, so nothing hangs on a FIFO without a writer and nothing reads an
//! endless stream; small files (headers, JSON, text lists, meshes) are read whole only
//! up to a limit checked against their size first ([`read_limited`]).

use crate::error::{Error, Result};
use std::fs::{File, OpenOptions};
use std::io::Read;
use std::path::Path;

/// Opens an input file for reading, with its length. Only regular files are read:
/// a FIFO, a pipe (`<(cat x)`), a socket or a device (`/dev/zero`) is refused with
/// [`Error::Invalid`] naming the file and what it is, without blocking. A FIFO is
/// opened without waiting for a writer (`O_NONBLOCK`), then checked, so that nothing
/// hangs; links are followed.
///
/// # Errors
/// [`Error::Io`] when the file cannot be opened; [`Error::Invalid`] for a file that is
/// not a regular file.
pub fn open(path: &Path) -> Result<(File, u64)> {
    let mut options = OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path).map_err(|e| Error::io(path, e))?;
    let meta = file.metadata().map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(not_regular(path, &meta));
    }
    #[cfg(unix)]
    {
        // Reads of a regular file never block, but leave the descriptor as usual.
        use std::os::unix::io::AsRawFd;
        let fd = file.as_raw_fd();
        // SAFETY: fcntl on a descriptor this function owns; failure only keeps O_NONBLOCK.
        unsafe {
            let flags = libc::fcntl(fd, libc::F_GETFL);
            if flags >= 0 {
                libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK);
            }
        }
    }
    Ok((file, meta.len()))
}

/// The error for an input that is not a regular file.
fn not_regular(path: &Path, meta: &std::fs::Metadata) -> Error {
    let t = meta.file_type();
    let what = if t.is_dir() {
        "a directory"
    } else {
        #[cfg(unix)]
        {
            use std::os::unix::fs::FileTypeExt;
            if t.is_fifo() {
                "a pipe or FIFO"
            } else if t.is_char_device() {
                "a character device"
            } else if t.is_block_device() {
                "a block device"
            } else if t.is_socket() {
                "a socket"
            } else {
                "not a regular file"
            }
        }
        #[cfg(not(unix))]
        {
            "not a regular file"
        }
    };
    Error::invalid(
        "input file",
        format!(
            "{} is {what}: voxlab reads regular files only (it needs their size); save a \
             stream to a file first",
            path.display()
        ),
    )
}

/// Reads a whole small file (a header, JSON, a text list, a mesh): a regular file of at
/// most `limit` bytes, refused before reading when it is larger ([`open`]'s rules).
/// `what` names the file's role in the error (`--tf`, `render settings JSON`).
///
/// # Errors
/// [`Error::Io`], or [`Error::TooLarge`] naming `what`, the file and the limit.
pub fn read_limited(path: &Path, what: &str, limit: u64) -> Result<Vec<u8>> {
    let (file, len) = open(path)?;
    if len > limit {
        return Err(too_big(path, what, len, limit));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    // `take` bounds the read even if the file grows while it is read.
    file.take(limit + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > limit {
        return Err(too_big(path, what, bytes.len() as u64, limit));
    }
    Ok(bytes)
}

fn too_big(path: &Path, what: &str, len: u64, limit: u64) -> Error {
    Error::too_large(
        what,
        format!(
            "{} holds {len} bytes; a file of this kind is at most {limit} bytes",
            path.display()
        ),
    )
}

/// Reads a small UTF-8 text file ([`read_limited`]), without a leading byte-order mark.
///
/// # Errors
/// As [`read_limited`]; [`Error::Format`] when the bytes are not UTF-8.
pub fn read_text_limited(path: &Path, what: &str, limit: u64) -> Result<String> {
    let bytes = read_limited(path, what, limit)?;
    let text = String::from_utf8(bytes)
        .map_err(|e| Error::format(path, what, format!("not UTF-8 text: {e}")))?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// The most bytes a JSON file of settings, transfer functions, geometry or a report may
/// have (real ones are a few kilobytes; a geometry of 100 000 views is a few MB).
pub const MAX_JSON_BYTES: u64 = 64 << 20;
