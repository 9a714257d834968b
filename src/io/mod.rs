//! Files in and out: volume formats, images, projection stacks, meshes, and the atomic
//! writer that every output file of the crate goes through.
//!
//! - [`read_volume`] tells the format from the file's magic number or extension
//!   ([`detect_format`]) and reads NRRD (`.nrrd`, `.nhdr`; raw, gzip or ascii; [`nrrd`]),
//!   NIfTI-1 (`.nii`, `.nii.gz`; [`nifti`]), DICOM (a file, or a directory holding a
//!   series; [`dicom`]), PVM ([`pvm`]), VolPack `.den` ([`den`]), multi-page TIFF stacks
//!   ([`tiff`]), NumPy `.npy` ([`npy`]); [`raw`] reads headerless samples described by
//!   the caller. [`write_volume`] writes NRRD, NIfTI-1 or `.npy` by extension.
//! - [`write_frame`] writes an image as PNG (8- or 16-bit) or `.npy` ([`frame`]);
//!   [`projections`] reads and writes projection stacks and their geometry JSON;
//!   [`mesh`] reads clipping meshes (OBJ, PLY).
//! - [`write_atomic`] writes to a temporary file beside the target and renames it into
//!   place, so a failed or interrupted write never leaves a half-written file;
//!   [`write_text`] and every writer above go through it. [`check_output`] refuses an
//!   output that cannot be written before a long job starts.
//!
//! # From stored samples to voxels
//!
//! Files store many scalar types; a [`Volume`] holds one of four
//! ([`VoxelKind`](crate::volume::VoxelKind)). The readers share one mapping, chosen so
//! that every value arrives exactly when it can:
//!
//! | stored in the file                    | read as | exact?                          |
//! |---------------------------------------|---------|---------------------------------|
//! | unsigned 8-bit                        | `u8`    | yes                             |
//! | signed 8-bit                          | `i16`   | yes (widened)                   |
//! | unsigned 16-bit                       | `u16`   | yes                             |
//! | signed 16-bit                         | `i16`   | yes                             |
//! | 32-bit float                          | `f32`   | yes                             |
//! | 32/64-bit integers, 64-bit float      | `f32`   | rounded to the nearest `f32`    |
//!
//! Rounding to `f32` keeps 24 significant bits: integers up to 2^24 = 16 777 216 in
//! magnitude stay exact, and doubles keep about 7 significant digits; doubles beyond the
//! `f32` range (about 3.4e38) become ±infinity. Which stored types each format accepts
//! is listed in its module.
//!
//! Malformed files give [`Error::Format`] naming the file and the header field; absurd
//! sizes are refused before anything is allocated. `docs/io.md` has the full rules.

pub mod astra_geometry;
pub mod brick;
pub mod den;
pub mod dicom;
pub mod frame;
pub mod mesh;
pub mod metaimage;
pub mod nifti;
pub mod npy;
pub mod nrrd;
pub mod projections;
pub mod pvm;
pub mod raw;
pub mod rtk_geometry;
pub mod tiff;

pub use crate::source::{open, read_limited, read_text_limited};
pub use frame::{write_frame, PngOptions};

use crate::error::{Error, Result};
use crate::volume::{AnyVolume, Volume};
use glam::DMat4;
use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The volume formats voxlab reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// NRRD, attached (`.nrrd`) or detached (`.nhdr`) header.
    Nrrd,
    /// NumPy `.npy`.
    Npy,
    /// NIfTI-1, `.nii` or `.nii.gz`.
    Nifti,
    /// DICOM: one file (single- or multi-frame) or a directory holding a series.
    Dicom,
    /// Stefan Roettger's PVM (`PVM`, `PVM2`, `PVM3`; `DDS v3d` compressed).
    Pvm,
    /// VolPack's `.den` density files (Lacroute's classic volume library).
    Den,
    /// A multi-page TIFF stack (one page per slice).
    Tiff,
    /// MetaImage (`.mha`, `.mhd`), ITK's and RTK's format.
    MetaImage,
    /// Headerless raw samples, described on the command line ([`raw::RawSpec`]).
    Raw,
}

impl Format {
    /// The format's name as `voxlab info` prints it.
    pub fn name(self) -> &'static str {
        match self {
            Format::Nrrd => "NRRD",
            Format::Npy => "NumPy .npy",
            Format::Nifti => "NIfTI",
            Format::Dicom => "DICOM",
            Format::Pvm => "PVM",
            Format::Den => "VolPack .den",
            Format::Tiff => "TIFF stack",
            Format::MetaImage => "MetaImage",
            Format::Raw => "raw",
        }
    }
}

/// Fails early, before a long job, on an output `what` that cannot be written: an
/// extension not in `allowed` (lower case, without the dot), or a folder that does not
/// exist.
///
/// # Errors
/// [`Error::Invalid`] naming `what`, the path and the accepted extensions.
pub fn check_output(what: &str, path: &Path, allowed: &[&str]) -> Result<()> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    if !ext.as_deref().is_some_and(|e| allowed.contains(&e)) {
        let dotted: Vec<String> = allowed.iter().map(|e| format!(".{e}")).collect();
        let dotted: Vec<&str> = dotted.iter().map(String::as_str).collect();
        return Err(Error::invalid(
            what,
            format!(
                "{}: the extension must be {}",
                path.display(),
                crate::choice::or_list(&dotted)
            ),
        ));
    }
    let parent = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if !parent.is_dir() {
        return Err(Error::invalid(
            what,
            format!(
                "{}: folder {} does not exist",
                path.display(),
                parent.display()
            ),
        ));
    }
    if path.is_dir() {
        return Err(Error::invalid(
            what,
            format!("{} is a folder, not a file", path.display()),
        ));
    }
    probe_writable(what, parent)
}

/// [`check_output`] for a volume file: the extensions [`write_volume`] knows
/// (`.nrrd`, `.nhdr`, `.npy`, `.nii`, `.nii.gz`).
///
/// # Errors
/// As [`check_output`].
pub fn check_volume_output(what: &str, path: &Path) -> Result<()> {
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if name.ends_with(".gz") && !name.ends_with(".nii.gz") {
        return Err(Error::invalid(
            what,
            format!(
                "{}: volumes are written as .nrrd, .nhdr, .npy, .nii, .nii.gz, .mha or .mhd",
                path.display()
            ),
        ));
    }
    check_output(
        what,
        path,
        &["nrrd", "nhdr", "npy", "nii", "gz", "mha", "mhd"],
    )
}

/// Fails early on an output folder `what` that cannot be made or written: a path one
/// of whose parts is a file, or a folder (or the nearest existing parent of a folder
/// still to be made) where no file can be created.
///
/// # Errors
/// [`Error::Invalid`] naming `what` and the folder.
pub fn check_output_dir(what: &str, dir: &Path) -> Result<()> {
    let mut nearest = None;
    let mut p = Some(dir);
    while let Some(d) = p.filter(|d| !d.as_os_str().is_empty()) {
        if d.exists() {
            if !d.is_dir() {
                return Err(Error::invalid(
                    what,
                    format!("{} is a file, not a folder", d.display()),
                ));
            }
            nearest.get_or_insert(d);
        }
        p = d.parent();
    }
    probe_writable(what, nearest.unwrap_or(Path::new(".")))
}

/// Creates and removes an empty file in `dir`: the one sure test that outputs can be
/// written there (permissions, read-only mounts, `/proc`).
fn probe_writable(what: &str, dir: &Path) -> Result<()> {
    let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    let probe = dir.join(format!(".voxlab-probe-{}-{n}", std::process::id()));
    match OpenOptions::new().write(true).create_new(true).open(&probe) {
        Ok(f) => {
            drop(f);
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(Error::invalid(
            what,
            format!("cannot write into the folder {}: {e}", dir.display()),
        )),
    }
}

/// Writes `text` to `path` atomically (a temporary file renamed into place).
///
/// # Errors
/// I/O errors, naming the file.
pub fn write_text(path: &Path, text: &str) -> Result<()> {
    write_atomic(path, |w| {
        w.write_all(text.as_bytes()).map_err(|e| Error::io(path, e))
    })
}

/// Tells a file's format from its first bytes (magic numbers), falling back to its
/// extension; a directory is a DICOM series. Fails with [`Error::Io`] when the file
/// cannot be opened and [`Error::Invalid`] when neither magic nor extension is known.
pub fn detect_format(path: &Path) -> Result<Format> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if meta.is_dir() {
        return Ok(directory_format(path));
    }
    let mut head = [0u8; 352];
    let (mut file, _) = open(path)?;
    let n = fill(&mut file, &mut head).map_err(|e| Error::io(path, e))?;
    if let Some(f) = sniff(&head[..n]) {
        return Ok(f);
    }
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    Ok(match extension(path).as_deref() {
        Some("nrrd") | Some("nhdr") => Format::Nrrd,
        Some("npy") => Format::Npy,
        Some("nii") => Format::Nifti,
        Some("hdr") => Format::Nifti,
        Some("gz") if name.ends_with(".nii.gz") || name.ends_with(".hdr.gz") => Format::Nifti,
        Some("dcm") | Some("dicom") => Format::Dicom,
        Some("pvm") => Format::Pvm,
        Some("den") => Format::Den,
        Some("tif") | Some("tiff") => Format::Tiff,
        Some("mha") | Some("mhd") => Format::MetaImage,
        Some("raw") => {
            return Err(Error::invalid(
                "volume file",
                format!(
                    "{}: a raw file has no header; describe it with --raw-dims, --raw-type \
                     (and --raw-endian, --raw-spacing, --raw-offset)",
                    path.display()
                ),
            ))
        }
        _ => return Err(unsupported_extension(path)),
    })
}

/// A directory holds a DICOM series, or a stack of TIFF files: TIFF when it has
/// `.tif`/`.tiff` files and no file with the DICOM marker, else DICOM (whose reader
/// says what it found when that is not a series either).
fn directory_format(dir: &Path) -> Format {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Format::Dicom;
    };
    let mut tiffs = 0;
    for e in entries.flatten() {
        let p = e.path();
        if !p.is_file() {
            continue;
        }
        // A file named .tif that carries the DICOM marker is DICOM (the marker wins
        // over any name or other magic).
        if matches!(extension(&p).as_deref(), Some("tif") | Some("tiff")) {
            tiffs += 1;
        }
        let mut head = [0u8; 132];
        let is_dicom = File::open(&p)
            .and_then(|mut f| fill(&mut f, &mut head))
            .is_ok_and(|n| n == 132 && &head[128..] == b"DICM");
        if is_dicom {
            return Format::Dicom;
        }
    }
    if tiffs > 0 {
        Format::Tiff
    } else {
        Format::Dicom
    }
}

/// Recognises a format from the first bytes of a file (up to 352 of them).
fn sniff(head: &[u8]) -> Option<Format> {
    let starts = |m: &[u8]| head.starts_with(m);
    // `DICM` after the 128-byte preamble wins over every other magic: classic CT and MR
    // files carry a TIFF header (`II*\0`) in their preamble.
    if head.len() >= 132 && &head[128..132] == b"DICM" {
        return Some(Format::Dicom);
    }
    if starts(b"NRRD000") {
        Some(Format::Nrrd)
    } else if starts(b"\x93NUMPY") {
        Some(Format::Npy)
    } else if starts(b"PVM\n") || starts(b"PVM2\n") || starts(b"PVM3\n") || starts(b"DDS ") {
        Some(Format::Pvm)
    } else if starts(b"II*\0") || starts(b"MM\0*") || starts(b"II+\0") || starts(b"MM\0+") {
        Some(Format::Tiff)
    } else if head.len() >= 132 && &head[128..132] == b"DICM" {
        Some(Format::Dicom)
    } else if head.len() >= 348 && (&head[344..348] == b"n+1\0" || &head[344..348] == b"ni1\0") {
        Some(Format::Nifti)
    } else if head.len() >= 12
        && (head[..4] == 540i32.to_le_bytes() || head[..4] == 540i32.to_be_bytes())
        && (&head[4..8] == b"n+2\0" || &head[4..8] == b"ni2\0")
    {
        // NIfTI-2: sizeof_hdr 540 and the magic at byte 4.
        Some(Format::Nifti)
    } else if starts(b"ObjectType") {
        Some(Format::MetaImage)
    } else {
        None
    }
}

/// Reads a volume in any format voxlab knows, telling the format from the file's
/// magic number or extension ([`detect_format`]); a directory is read as a DICOM
/// series, or as a stack of TIFF files when it holds those and no DICOM file. Raw files need [`raw::read_raw`] with a [`raw::RawSpec`].
pub fn read_volume(path: &Path) -> Result<AnyVolume> {
    read_volume_with(path, &ReadOptions::default())
}

/// How files are read, beyond what their headers say.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReadOptions {
    /// Refuse a data file a header names outside the header's own folder (a NRRD
    /// `data file:` that is absolute or climbs with `../`, which the format allows), so
    /// that an untrusted header cannot make voxlab read any file the user can.
    pub confine_data_files: bool,
    /// Which 3-D volume to read from a file that holds several (a NIfTI `dim[4..7]`, a
    /// MetaImage of 4 dimensions or several channels, a NRRD with a non-spatial axis, a
    /// DICOM time series): its index, the extra axes counted as one. `None` refuses
    /// such a file, naming how many it holds; a file of one volume takes 0 only.
    pub frame: Option<usize>,
}

/// How many 3-D volumes a file holds, from its header: more than 1 for a NIfTI time
/// series or vector image, a 4-D or vector MetaImage, a NRRD with a non-spatial axis
/// or a DICOM time series (those are read one at a time, [`ReadOptions::frame`]); 1
/// for every other file.
///
/// # Errors
/// The header's errors.
pub fn frame_count(path: &Path) -> Result<usize> {
    match detect_format(path)? {
        Format::Nifti => nifti::nifti_frames(path),
        Format::MetaImage => metaimage::metaimage_frames(path),
        Format::Nrrd => nrrd::nrrd_frames(path),
        Format::Dicom => dicom::dicom_frames(path),
        _ => Ok(1),
    }
}

/// [`read_volume`] with [`ReadOptions`].
pub fn read_volume_with(path: &Path, options: &ReadOptions) -> Result<AnyVolume> {
    read_volume_as_with(path, detect_format(path)?, options)
}

/// Reads a volume in the given format.
pub fn read_volume_as(path: &Path, format: Format) -> Result<AnyVolume> {
    read_volume_as_with(path, format, &ReadOptions::default())
}

/// [`read_volume_as`] with [`ReadOptions`].
pub fn read_volume_as_with(
    path: &Path,
    format: Format,
    options: &ReadOptions,
) -> Result<AnyVolume> {
    if !matches!(
        format,
        Format::Nifti | Format::MetaImage | Format::Nrrd | Format::Dicom
    ) {
        // Files of one 3-D volume: frame 0 is the volume, a later one is refused.
        choose_frame(path, "frame", 1, "", options.frame)?;
    }
    match format {
        Format::Nrrd => nrrd::read_nrrd_with(path, options),
        Format::Npy => npy::read_npy_volume(path),
        Format::Nifti => nifti::read_nifti_frame(path, options.frame),
        Format::Dicom => dicom::read_dicom_frame(path, options.frame),
        Format::Pvm => pvm::read_pvm(path),
        Format::Den => den::read_den(path),
        Format::Tiff if path.is_dir() => tiff::read_tiff_dir(path),
        Format::Tiff => tiff::read_tiff(path),
        Format::MetaImage => metaimage::read_metaimage_with(path, options),
        Format::Raw => Err(Error::invalid(
            "volume file",
            format!(
                "{}: raw files need their layout (dims, type, endianness, spacing)",
                path.display()
            ),
        )),
    }
}

/// Reads a volume file held in memory, in the given format (`path` only names it in
/// errors). Formats that live in several files (DICOM series, detached NRRD headers,
/// raw) are refused. This is what the fuzz targets and the fuzz smoke test call: it
/// must return an error, never panic, whatever the bytes.
pub fn read_volume_bytes(bytes: &[u8], format: Format, path: &Path) -> Result<AnyVolume> {
    read_volume_bytes_frame(bytes, format, path, None)
}

/// [`read_volume_bytes`] of one 3-D volume of a file that holds several
/// ([`ReadOptions::frame`]); what the fuzz targets call with frame 1 too.
pub fn read_volume_bytes_frame(
    bytes: &[u8],
    format: Format,
    path: &Path,
    frame: Option<usize>,
) -> Result<AnyVolume> {
    if !matches!(format, Format::Nifti | Format::MetaImage | Format::Nrrd) {
        choose_frame(path, "frame", 1, "", frame)?;
    }
    match format {
        Format::Nrrd => nrrd::read_nrrd_bytes_frame(bytes, path, frame),
        Format::Npy => npy::read_npy_bytes(bytes, path),
        Format::Nifti => nifti::read_nifti_bytes_frame(bytes, path, frame),
        Format::Pvm => pvm::read_pvm_bytes(bytes, path),
        Format::Den => den::read_den_bytes(bytes, path),
        Format::Tiff => tiff::read_tiff_bytes(bytes, path),
        Format::MetaImage => metaimage::read_metaimage_bytes_frame(bytes, path, frame),
        other => Err(Error::invalid(
            "in-memory volume",
            format!("{} files are read from disk only", other.name()),
        )),
    }
}

/// Writes a volume, choosing the format from the extension, atomically:
/// - `.nrrd`: one file, header and gzip-compressed data;
/// - `.nhdr`: a detached header, with the gzip-compressed data in `<stem>.raw.gz`
///   beside it;
/// - `.npy`: shape `(nz, ny, nx)`, little-endian (the geometry is not stored);
/// - `.nii` / `.nii.gz`: NIfTI-1 with the affine as sform and qform;
/// - `.mha` / `.mhd`: MetaImage, the data after the header or in `<stem>.raw`.
pub fn write_volume(path: &Path, vol: &AnyVolume) -> Result<()> {
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    match extension(path).as_deref() {
        Some("nrrd") => nrrd::write_nrrd(path, vol, nrrd::NrrdWriteOptions::default()),
        Some("nhdr") => nrrd::write_nrrd(
            path,
            vol,
            nrrd::NrrdWriteOptions {
                gzip: true,
                detached: true,
            },
        ),
        Some("npy") => npy::write_npy_volume(path, vol),
        Some("nii") => nifti::write_nifti(path, vol),
        Some("gz") if name.ends_with(".nii.gz") => nifti::write_nifti(path, vol),
        Some("mha") | Some("mhd") => {
            metaimage::write_metaimage(path, vol, metaimage::MetaImageWriteOptions::default())
        }
        _ => Err(Error::invalid(
            "output volume file",
            format!(
                "{}: unsupported extension; volumes are written as .nrrd, .nhdr, .npy, .nii, .nii.gz, .mha or .mhd",
                path.display()
            ),
        )),
    }
}

/// The extension in lower case, if any.
fn extension(path: &Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
}

fn unsupported_extension(path: &Path) -> Error {
    Error::invalid(
        "volume file",
        format!(
            "{}: unknown format; voxlab reads NRRD (.nrrd, .nhdr), NumPy (.npy), NIfTI-1 \
             (.nii, .nii.gz), DICOM (a file or a directory), PVM (.pvm), VolPack (.den), \
             TIFF stacks (.tif, .tiff), MetaImage (.mha, .mhd) and raw files (with --raw-* \
             options)",
            path.display()
        ),
    )
}

// ---------------------------------------------------------------------------------
// Atomic writes
// ---------------------------------------------------------------------------------

/// Tells concurrent writers in one process apart (the pid tells processes apart).
static TEMP_COUNTER: AtomicUsize = AtomicUsize::new(0);

/// A temporary file that is deleted when dropped, unless it was renamed into place.
/// Dropping also happens when the writer closure panics, so even then nothing is left.
/// While it exists its name is also known to the signal handler
/// ([`remove_temp_files_on_signals`]).
struct TempFile {
    path: PathBuf,
    renamed: bool,
    slot: Option<usize>,
}

impl Drop for TempFile {
    fn drop(&mut self) {
        if !self.renamed {
            // Best effort: the file may not exist any more, and there is nobody to tell.
            let _ = std::fs::remove_file(&self.path);
        }
        if let Some(slot) = self.slot {
            signals::forget(slot);
        }
    }
}

/// Removes the temporary files of writes in progress when the process receives SIGINT,
/// SIGTERM or SIGHUP, then dies of that signal as it would have (exit status 128 + n).
/// A signal the process ignores (SIGHUP under `nohup`) stays ignored. The command line
/// calls this first thing; a library caller that handles these signals itself should
/// not. SIGKILL cannot be caught: a write killed by it leaves its
/// `.NAME.tmp-PID-N` file (never the half-written `NAME`), which is safe to delete.
pub fn remove_temp_files_on_signals() {
    signals::install();
}

/// Elsewhere than Unix the default actions stay, and an interrupted write may leave
/// its temporary file.
#[cfg(not(unix))]
mod signals {
    pub(super) fn remember(_: &std::path::Path) -> Option<usize> {
        None
    }
    pub(super) fn forget(_: usize) {}
    pub(super) fn install() {}
}

/// The signal side of [`TempFile`]: a fixed table of the temporary paths being written,
/// read by a handler that only calls `unlink` (async-signal-safe).
#[cfg(unix)]
mod signals {
    use std::ffi::CString;
    use std::path::Path;
    use std::sync::atomic::{AtomicBool, AtomicPtr, Ordering};

    const SLOTS: usize = 256;
    static PENDING: [AtomicPtr<libc::c_char>; SLOTS] =
        [const { AtomicPtr::new(std::ptr::null_mut()) }; SLOTS];
    static INSTALLED: AtomicBool = AtomicBool::new(false);

    /// Records `path`; `None` when every slot is taken (the write goes on, only
    /// without cleanup on a signal) or no handler is installed.
    pub(super) fn remember(path: &Path) -> Option<usize> {
        if !INSTALLED.load(Ordering::SeqCst) {
            return None;
        }
        use std::os::unix::ffi::OsStrExt;
        let c = CString::new(path.as_os_str().as_bytes()).ok()?.into_raw();
        for (i, slot) in PENDING.iter().enumerate() {
            if slot
                .compare_exchange(std::ptr::null_mut(), c, Ordering::SeqCst, Ordering::SeqCst)
                .is_ok()
            {
                return Some(i);
            }
        }
        // SAFETY: `c` came from `into_raw` above and was never shared.
        drop(unsafe { CString::from_raw(c) });
        None
    }

    /// Forgets a slot. The string is not freed: a handler running on another thread
    /// may be reading it (a few bytes per file written, in a process with a handler).
    pub(super) fn forget(slot: usize) {
        PENDING[slot].store(std::ptr::null_mut(), Ordering::SeqCst);
    }

    extern "C" fn on_signal(sig: libc::c_int) {
        for slot in PENDING.iter() {
            let p = slot.swap(std::ptr::null_mut(), Ordering::SeqCst);
            if !p.is_null() {
                // SAFETY: `p` is a NUL-terminated string leaked by `remember`.
                unsafe {
                    libc::unlink(p);
                }
            }
        }
        // SAFETY: restoring the default action and re-raising are async-signal-safe.
        unsafe {
            libc::signal(sig, libc::SIG_DFL);
            libc::raise(sig);
        }
    }

    pub(super) fn install() {
        if INSTALLED.swap(true, Ordering::SeqCst) {
            return;
        }
        for sig in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
            // SAFETY: a handler that only touches atomics and async-signal-safe calls.
            unsafe {
                let handler = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
                let previous = libc::signal(sig, handler);
                if previous == libc::SIG_IGN {
                    libc::signal(sig, libc::SIG_IGN);
                }
            }
        }
    }
}

/// A new temporary file beside `path` (`.NAME.tmp-PID-N`, created exclusively), known
/// to the signal handler before it exists.
fn temp_beside(path: &Path) -> Result<(TempFile, File)> {
    let name = path.file_name().ok_or_else(|| {
        Error::invalid(
            "output file",
            format!("{} does not name a file", path.display()),
        )
    })?;
    // `Path::parent` of a bare file name is "", meaning the current directory.
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        return Err(Error::io(
            path,
            io::Error::new(
                io::ErrorKind::NotFound,
                format!(
                    "cannot write: the directory {} does not exist",
                    dir.display()
                ),
            ),
        ));
    }

    let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".tmp-{}-{n}", std::process::id()));
    let tmp_path = dir.join(tmp_name);
    // Known to the signal handler before the file exists, so no window leaves it behind.
    let slot = signals::remember(&tmp_path);
    let temp = TempFile {
        path: tmp_path,
        renamed: false,
        slot,
    };

    // `create_new` never clobbers a file we did not create.
    let file = OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&temp.path)
        .map_err(|e| Error::io(path, e))?;
    Ok((temp, file))
}

/// Writes `path` atomically: `f` writes into a temporary file in the same directory
/// (named `.<name>.tmp-<pid>-<n>`), which is flushed to disk and then renamed over
/// `path`. If `f` or anything else fails, the temporary file is removed and `path` is
/// left as it was (absent, or with its old contents): a half-written file is never
/// seen under `path`.
///
/// `f` should name `path` in its own I/O errors (`Error::io(path, e)`); the temporary
/// name is an implementation detail. Fails with [`Error::Io`] naming `path` when its
/// directory does not exist.
pub fn write_atomic(path: &Path, f: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    let (mut temp, file) = temp_beside(path)?;
    let mut writer = BufWriter::new(file);
    f(&mut writer)?;
    let file = writer
        .into_inner()
        .map_err(|e| Error::io(path, e.into_error()))?;
    // The data must be on disk before the rename makes it visible under `path`.
    file.sync_all().map_err(|e| Error::io(path, e))?;
    drop(file);
    std::fs::rename(&temp.path, path).map_err(|e| Error::io(path, e))?;
    temp.renamed = true;
    Ok(())
}

/// The temporary file of an output that several processes write by byte ranges (a
/// distributed reconstruction): one process creates it beside `path` at its final
/// length, every process writes its ranges through [`write_part`], and the creator
/// renames it to `path` once all have written ([`SharedOutput::commit`]). Dropped
/// without a commit, it is removed, so a failed job leaves no half-written output.
pub struct SharedOutput {
    path: PathBuf,
    temp: TempFile,
}

impl SharedOutput {
    /// Creates the temporary file of `path`, `len` bytes of zeros, its name known to the
    /// signal handler ([`remove_temp_files_on_signals`]).
    ///
    /// # Errors
    /// A `path` that names no file or lies in a missing directory; I/O errors.
    pub fn create(path: &Path, len: u64) -> Result<SharedOutput> {
        let (temp, file) = temp_beside(path)?;
        file.set_len(len).map_err(|e| Error::io(path, e))?;
        Ok(SharedOutput {
            path: path.to_path_buf(),
            temp,
        })
    }

    /// Where the parts are written until the commit.
    pub fn temp_path(&self) -> &Path {
        &self.temp.path
    }

    /// Makes the written file visible under its name (after every writer is done).
    ///
    /// # Errors
    /// I/O errors.
    pub fn commit(mut self) -> Result<()> {
        let file = File::open(&self.temp.path).map_err(|e| Error::io(&self.path, e))?;
        file.sync_all().map_err(|e| Error::io(&self.path, e))?;
        drop(file);
        std::fs::rename(&self.temp.path, &self.path).map_err(|e| Error::io(&self.path, e))?;
        self.temp.renamed = true;
        Ok(())
    }
}

/// Writes `parts` (byte offset, bytes) into the existing file `temp` of the output
/// `out` (named in errors), each at its offset, and syncs it.
///
/// # Errors
/// I/O errors.
pub fn write_part(temp: &Path, out: &Path, parts: &[(u64, &[u8])]) -> Result<()> {
    use std::io::{Seek, SeekFrom};
    let mut f = OpenOptions::new()
        .write(true)
        .open(temp)
        .map_err(|e| Error::io(out, e))?;
    for (at, bytes) in parts {
        f.seek(SeekFrom::Start(*at))
            .and_then(|_| f.write_all(bytes))
            .map_err(|e| Error::io(out, e))?;
    }
    f.sync_all().map_err(|e| Error::io(out, e))
}

// ---------------------------------------------------------------------------------
// Stored sample types, shared by the readers
// ---------------------------------------------------------------------------------

/// A scalar type as stored in a file, before it is mapped to a [`VoxelKind`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Stored {
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

impl Stored {
    /// Bytes per sample in the file.
    pub(crate) fn size(self) -> usize {
        match self {
            Stored::U8 | Stored::I8 => 1,
            Stored::U16 | Stored::I16 => 2,
            Stored::U32 | Stored::I32 | Stored::F32 => 4,
            Stored::U64 | Stored::I64 | Stored::F64 => 8,
        }
    }
}

/// Where a volume file keeps its samples, uncompressed and x fastest: what
/// [`brick::read_brick`] reads a box of (each format's `raw_layout` finds it).
#[derive(Clone, Debug, PartialEq)]
pub struct RawLayout {
    /// The file holding the samples (the header's own file, or a detached data file).
    pub data: PathBuf,
    /// The byte offset of the first sample in `data`.
    pub offset: u64,
    pub(crate) stored: Stored,
    pub(crate) endian: Endian,
    /// Voxels along x, y, z.
    pub dims: [usize; 3],
    /// The voxel-index → world affine of the whole volume.
    pub affine: DMat4,
}

/// Fills `buf` from byte `offset` of `file`, without moving a shared cursor or reading
/// ahead (a positioned read: `pread` on Unix).
///
/// # Errors
/// I/O errors; the file ending before `buf` is full.
pub(crate) fn read_at(file: &File, offset: u64, buf: &mut [u8]) -> io::Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileExt;
        file.read_exact_at(buf, offset)
    }
    #[cfg(not(unix))]
    {
        use io::Seek;
        let mut f = file;
        f.seek(io::SeekFrom::Start(offset))?;
        f.read_exact(buf)
    }
}

/// Reads the lines `wanted` (increasing, each once) of a block of equal lines of
/// `line_bytes` bytes that starts at byte `offset` of `file` (`path` names it in
/// errors): one positioned read ([`read_at`]) per run of consecutive lines, each run's
/// bytes given to `take` with the index in `wanted` of its first line. The one line
/// reader of the formats read line by line ([`npy::read_npy_f64_lines`],
/// [`brick::read_lines`]).
///
/// # Errors
/// I/O errors; `take`'s.
pub(crate) fn read_line_runs(
    file: &File,
    path: &Path,
    offset: u64,
    line_bytes: usize,
    wanted: &[usize],
    mut take: impl FnMut(usize, &[u8]) -> Result<()>,
) -> Result<()> {
    let mut bytes = Vec::new();
    let mut at = 0;
    while at < wanted.len() {
        let first = wanted[at];
        let mut end = at + 1;
        while end < wanted.len() && wanted[end] == wanted[end - 1] + 1 {
            end += 1;
        }
        bytes.resize((end - at) * line_bytes, 0);
        read_at(file, offset + (first * line_bytes) as u64, &mut bytes)
            .map_err(|e| read_error(path, e))?;
        take(at, &bytes)?;
        at = end;
    }
    Ok(())
}

/// Byte order of multi-byte samples in a file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Endian {
    Little,
    Big,
}

/// Decoded voxel values, already in the voxel type their stored type maps to.
#[derive(Debug)]
pub(crate) enum Samples {
    U8(Vec<u8>),
    U16(Vec<u16>),
    I16(Vec<i16>),
    F32(Vec<f32>),
}

impl Samples {
    /// Wraps the samples in a volume (`dims` must already be checked against the
    /// number of samples, and `affine` validated, by the caller).
    pub(crate) fn into_volume(self, dims: [usize; 3], affine: DMat4) -> Result<AnyVolume> {
        Ok(match self {
            Samples::U8(v) => Volume::with_affine(dims, affine, v)?.into(),
            Samples::U16(v) => Volume::with_affine(dims, affine, v)?.into(),
            Samples::I16(v) => Volume::with_affine(dims, affine, v)?.into(),
            Samples::F32(v) => Volume::with_affine(dims, affine, v)?.into(),
        })
    }

    /// These samples followed by `more` (of the same stored type, so the same variant;
    /// else both as f32).
    pub(crate) fn append(self, more: Samples) -> Samples {
        match (self, more) {
            (Samples::U8(mut a), Samples::U8(b)) => {
                a.extend(b);
                Samples::U8(a)
            }
            (Samples::U16(mut a), Samples::U16(b)) => {
                a.extend(b);
                Samples::U16(a)
            }
            (Samples::I16(mut a), Samples::I16(b)) => {
                a.extend(b);
                Samples::I16(a)
            }
            (a, b) => {
                let mut a = a.into_f32();
                a.extend(b.into_f32());
                Samples::F32(a)
            }
        }
    }

    /// The samples of one frame ([`FramePick`]) out of these, all of the file's.
    pub(crate) fn pick(self, pick: &FramePick) -> Samples {
        fn take<T: Copy>(mut v: Vec<T>, pick: &FramePick) -> Vec<T> {
            if pick.contiguous() {
                v.truncate(pick.base + pick.n());
                v.drain(..pick.base);
                v
            } else {
                (0..pick.n()).map(|i| v[pick.index(i)]).collect()
            }
        }
        match self {
            Samples::U8(v) => Samples::U8(take(v, pick)),
            Samples::U16(v) => Samples::U16(take(v, pick)),
            Samples::I16(v) => Samples::I16(take(v, pick)),
            Samples::F32(v) => Samples::F32(take(v, pick)),
        }
    }

    /// The values as f32 (exact: u8, u16 and i16 all fit in f32).
    pub(crate) fn into_f32(self) -> Vec<f32> {
        match self {
            Samples::U8(v) => v.into_iter().map(f32::from).collect(),
            Samples::U16(v) => v.into_iter().map(f32::from).collect(),
            Samples::I16(v) => v.into_iter().map(f32::from).collect(),
            Samples::F32(v) => v,
        }
    }
}

// ---------------------------------------------------------------------------------
// Files of several 3-D volumes (frames)
// ---------------------------------------------------------------------------------

/// Which of a file's `frames` 3-D volumes to read: `frame`, or the only one. A file
/// of several without a choice, or a choice past the last, is refused naming `field`
/// and the count; `axes` describes the extra axes (`"t 5"`, `"axis 0: 3 (vector)"`).
pub(crate) fn choose_frame(
    path: &Path,
    field: &str,
    frames: usize,
    axes: &str,
    frame: Option<usize>,
) -> Result<usize> {
    match frame {
        None if frames > 1 => Err(Error::format(
            path,
            field,
            format!(
                "the file holds {frames} 3-D volumes ({axes}); choose one with --frame K \
                 (0 … {})",
                frames - 1
            ),
        )),
        None => Ok(0),
        Some(k) if k >= frames => Err(Error::format(
            path,
            field,
            format!(
                "frame {k} is past the file's {frames} 3-D volume{} (0 … {})",
                if frames == 1 { "" } else { "s" },
                frames - 1
            ),
        )),
        Some(k) => Ok(k),
    }
}

/// Where one 3-D volume's samples lie among all the samples of a file's data: voxel
/// `(x, y, z)` is sample `base + x·strides[0] + y·strides[1] + z·strides[2]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct FramePick {
    /// Samples in the file's data, every frame.
    pub total: usize,
    pub dims: [usize; 3],
    pub base: usize,
    pub strides: [usize; 3],
}

impl FramePick {
    /// The whole data as one volume.
    pub fn whole(dims: [usize; 3]) -> FramePick {
        FramePick {
            total: dims[0] * dims[1] * dims[2],
            dims,
            base: 0,
            strides: [1, dims[0], dims[0] * dims[1]],
        }
    }

    /// Samples of the volume.
    pub fn n(&self) -> usize {
        self.dims.iter().product()
    }

    /// The volume is one run of samples (its frame axes are the slowest).
    fn contiguous(&self) -> bool {
        let [nx, ny, nz] = self.dims;
        (nx == 1 || self.strides[0] == 1)
            && (ny == 1 || self.strides[1] == nx)
            && (nz == 1 || self.strides[2] == nx * ny)
    }

    fn index(&self, i: usize) -> usize {
        let [nx, ny, _] = self.dims;
        let (x, y, z) = (i % nx, (i / nx) % ny, i / (nx * ny));
        self.base + x * self.strides[0] + y * self.strides[1] + z * self.strides[2]
    }
}

/// Reads one frame's samples ([`FramePick`]) from a stream of all the frames'
/// samples, reading past the rest so that the stream ends where the data does. A
/// frame that is one run is read alone; interleaved frames (a fastest vector axis)
/// need every sample in memory, so their total must be within the voxel limit.
pub(crate) fn read_picked(
    reader: &mut dyn Read,
    stored: Stored,
    endian: Endian,
    pick: &FramePick,
    path: &Path,
) -> Result<Samples> {
    let size = stored.size() as u64;
    let total_bytes = pick.total as u64 * size;
    if pick.contiguous() {
        let n = pick.n();
        let before = pick.base as u64 * size;
        let skipped = skip_samples(reader, before, path)?;
        if skipped < before {
            return Err(too_short(path, total_bytes, skipped));
        }
        let samples = read_samples(reader, stored, endian, n, path)?;
        let after = (pick.total - pick.base - n) as u64 * size;
        let skipped = skip_samples(reader, after, path)?;
        if skipped < after {
            return Err(too_short(
                path,
                total_bytes,
                before + n as u64 * size + skipped,
            ));
        }
        return Ok(samples);
    }
    check_interleaved(pick, path)?;
    let all = read_samples(reader, stored, endian, pick.total, path)?;
    Ok(all.pick(pick))
}

/// Refuses interleaved frames whose data is larger than the voxel limit (reading one
/// needs all of it).
pub(crate) fn check_interleaved(pick: &FramePick, path: &Path) -> Result<()> {
    if pick.total > crate::volume::max_voxels() {
        return Err(Error::too_large(
            format!("data of {}", path.display()),
            format!(
                "its frames are interleaved, so reading one needs all {} samples, more than \
                 the voxel limit {} (raise it with --max-voxels)",
                pick.total,
                crate::volume::max_voxels()
            ),
        ));
    }
    Ok(())
}

fn skip_samples(reader: &mut dyn Read, bytes: u64, path: &Path) -> Result<u64> {
    io::copy(&mut reader.take(bytes), &mut io::sink()).map_err(|e| read_error(path, e))
}

/// A fixed-size number that can be decoded from bytes in either order.
trait FromBytes: Copy {
    const SIZE: usize;
    /// `bytes` has exactly `SIZE` bytes.
    fn from_bytes(bytes: &[u8], endian: Endian) -> Self;
}

macro_rules! from_bytes {
    ($($t:ty),*) => {$(
        impl FromBytes for $t {
            const SIZE: usize = std::mem::size_of::<$t>();
            #[inline(always)]
            fn from_bytes(bytes: &[u8], endian: Endian) -> Self {
                let mut a = [0u8; std::mem::size_of::<$t>()];
                a.copy_from_slice(bytes);
                match endian {
                    Endian::Little => <$t>::from_le_bytes(a),
                    Endian::Big => <$t>::from_be_bytes(a),
                }
            }
        }
    )*};
}
from_bytes!(u8, i8, u16, i16, u32, i32, u64, i64, f32, f64);

/// Bytes decoded per step while reading (a multiple of every sample size).
const CHUNK_BYTES: usize = 1 << 20;

/// Reads `n` binary samples of type `stored` from `reader`.
///
/// Fails with [`Error::Format`] (field `data`) when the stream ends early, saying how
/// many bytes were expected and found, or when a decoder (gzip) reports corrupt data.
/// `path` names the file in errors. Bytes after the `n` samples are not read.
pub(crate) fn read_samples(
    reader: &mut dyn Read,
    stored: Stored,
    endian: Endian,
    n: usize,
    path: &Path,
) -> Result<Samples> {
    // The conversions below are the table in the module docs.
    Ok(match stored {
        Stored::U8 => Samples::U8(read_vec(reader, n, endian, path, |x: u8| x)?),
        Stored::I8 => Samples::I16(read_vec(reader, n, endian, path, |x: i8| i16::from(x))?),
        Stored::U16 => Samples::U16(read_vec(reader, n, endian, path, |x: u16| x)?),
        Stored::I16 => Samples::I16(read_vec(reader, n, endian, path, |x: i16| x)?),
        Stored::U32 => Samples::F32(read_vec(reader, n, endian, path, |x: u32| x as f32)?),
        Stored::I32 => Samples::F32(read_vec(reader, n, endian, path, |x: i32| x as f32)?),
        Stored::U64 => Samples::F32(read_vec(reader, n, endian, path, |x: u64| x as f32)?),
        Stored::I64 => Samples::F32(read_vec(reader, n, endian, path, |x: i64| x as f32)?),
        Stored::F32 => Samples::F32(read_vec(reader, n, endian, path, |x: f32| x)?),
        Stored::F64 => Samples::F32(read_vec(reader, n, endian, path, |x: f64| x as f32)?),
    })
}

/// The error for a fixed-size binary header that the file ends inside: `got` of the
/// `len` header bytes were read.
pub(crate) fn truncated_header(path: &Path, got: usize, len: usize) -> Error {
    Error::format(
        path,
        "header",
        format!("the header is truncated: {got} of {len} bytes"),
    )
}

/// Refuses a data file `name` (at `data`) that a header names outside the header's
/// folder `dir` (after following links and `..`): `--confine-data-files`.
pub(crate) fn confine(header: &Path, dir: &Path, data: &Path, name: &str) -> Result<()> {
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let outside = || {
        Error::format(
            header,
            "data file",
            format!(
                "'{}' lies outside the header's folder {}; data files are confined to it \
                 (--confine-data-files)",
                snippet(name),
                dir.display()
            ),
        )
    };
    let base = std::fs::canonicalize(dir).map_err(|e| Error::io(dir, e))?;
    match std::fs::canonicalize(data) {
        Ok(real) if real.starts_with(&base) => Ok(()),
        Ok(_) => Err(outside()),
        // A file that does not exist is reported by the reader; one reached by a
        // path that leaves the folder is refused either way.
        Err(_) if Path::new(name).is_absolute() || name.split(['/', '\\']).any(|c| c == "..") => {
            Err(outside())
        }
        Err(_) => Ok(()),
    }
}

/// Opens a data file a header names; a failure is the header's error (field `data
/// file`), saying why.
pub(crate) fn open_data_file(header: &Path, data: &Path) -> Result<(File, u64)> {
    open(data).map_err(|e| {
        let why = match e {
            Error::Io { source, .. } => source.to_string(),
            Error::Invalid { message, .. } => message,
            other => other.to_string(),
        };
        Error::format(
            header,
            "data file",
            format!("cannot open {}: {why}", data.display()),
        )
    })
}

/// Reserves room for `n` values, reporting an allocation failure as an error instead
/// of aborting the process.
pub(crate) fn reserve<T>(n: usize, path: &Path) -> Result<Vec<T>> {
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| {
        Error::too_large(
            format!("data of {}", path.display()),
            format!("cannot allocate memory for {n} values"),
        )
    })?;
    Ok(v)
}

fn read_vec<S: FromBytes, T>(
    reader: &mut dyn Read,
    n: usize,
    endian: Endian,
    path: &Path,
    convert: impl Fn(S) -> T,
) -> Result<Vec<T>> {
    let total = n
        .checked_mul(S::SIZE)
        .ok_or_else(|| Error::format(path, "data", format!("{n} samples do not fit in memory")))?;
    let mut out = reserve(n, path)?;
    let mut buf = vec![0u8; CHUNK_BYTES.min(total)];
    let mut done = 0;
    while done < total {
        // Both `total - done` and the buffer length are multiples of `S::SIZE`.
        let want = (total - done).min(buf.len());
        let got = fill(reader, &mut buf[..want]).map_err(|e| read_error(path, e))?;
        if got < want {
            return Err(too_short(path, total as u64, (done + got) as u64));
        }
        out.extend(
            buf[..want]
                .chunks_exact(S::SIZE)
                .map(|c| convert(S::from_bytes(c, endian))),
        );
        done += want;
    }
    Ok(out)
}

/// Reads until `buf` is full or the stream ends; returns how many bytes were read.
fn fill(reader: &mut dyn Read, buf: &mut [u8]) -> io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match reader.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(k) => got += k,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

/// The error for data that ends before the header's promise is kept.
pub(crate) fn too_short(path: &Path, expected: u64, found: u64) -> Error {
    Error::format(
        path,
        "data",
        format!("the data is too short: expected {expected} bytes, found {found}"),
    )
}

/// Classifies a read error: decoders (gzip) report corrupt input as `InvalidInput` or
/// `InvalidData`, which is a format problem; anything else is the file system's.
pub(crate) fn read_error(path: &Path, e: io::Error) -> Error {
    match e.kind() {
        io::ErrorKind::InvalidInput | io::ErrorKind::InvalidData | io::ErrorKind::UnexpectedEof => {
            Error::format(
                path,
                "data",
                format!("the data cannot be decoded (corrupt or truncated): {e}"),
            )
        }
        _ => Error::io(path, e),
    }
}

/// Parses `n` samples written as text, separated by white space or commas.
/// Integers must be integers within the stored type's range; floats may be `nan` or
/// `inf`. Fails with [`Error::Format`] (field `data`) naming the first bad value.
pub(crate) fn parse_text_samples(
    text: &str,
    stored: Stored,
    n: usize,
    path: &Path,
    type_name: &str,
) -> Result<Samples> {
    let mut tokens = text
        .split(|c: char| c.is_ascii_whitespace() || c == ',')
        .filter(|t| !t.is_empty());
    let mut next = |convert: &mut dyn FnMut(&str) -> bool| -> Result<()> {
        for i in 0..n {
            let tok = tokens.next().ok_or_else(|| {
                Error::format(
                    path,
                    "data",
                    format!("the text data is too short: expected {n} values, found {i}"),
                )
            })?;
            if !convert(tok) {
                return Err(Error::format(
                    path,
                    "data",
                    format!("value #{i} '{}' is not a valid {type_name}", snippet(tok)),
                ));
            }
        }
        Ok(())
    };
    // Each value takes at least two characters (digit and separator), which bounds
    // the allocation by the size of the text rather than by the header's promise.
    let cap = n.min(text.len() / 2 + 1);
    macro_rules! parse {
        ($variant:ident, $s:ty, $convert:expr) => {{
            let mut v = reserve(cap, path)?;
            next(&mut |tok| match tok.parse::<$s>() {
                Ok(x) => {
                    v.push($convert(x));
                    true
                }
                Err(_) => false,
            })?;
            Samples::$variant(v)
        }};
    }
    Ok(match stored {
        Stored::U8 => parse!(U8, u8, |x| x),
        Stored::I8 => parse!(I16, i8, i16::from),
        Stored::U16 => parse!(U16, u16, |x| x),
        Stored::I16 => parse!(I16, i16, |x| x),
        Stored::U32 => parse!(F32, u32, |x| x as f32),
        Stored::I32 => parse!(F32, i32, |x| x as f32),
        Stored::U64 => parse!(F32, u64, |x| x as f32),
        Stored::I64 => parse!(F32, i64, |x| x as f32),
        Stored::F32 => parse!(F32, f32, |x| x),
        Stored::F64 => parse!(F32, f64, |x| x as f32),
    })
}

/// At most the first 40 characters of `s`, for quoting file contents in messages, with
/// control characters escaped ([`crate::error::escape_controls`]).
pub(crate) fn snippet(s: &str) -> String {
    let head: String = s.chars().take(40).collect();
    let cut = head.len() < s.len();
    let mut out = crate::error::escape_controls(&head).into_owned();
    if cut {
        out.push('…');
    }
    out
}

// ---------------------------------------------------------------------------------
// Writing samples
// ---------------------------------------------------------------------------------

/// Writes the volume's voxels, x fastest, little-endian.
pub(crate) fn write_samples_le(w: &mut dyn Write, vol: &AnyVolume) -> io::Result<()> {
    crate::with_volume!(vol, v => write_le(w, v.data()))
}

/// Writes values little-endian, whatever the machine's byte order.
pub(crate) fn write_le<T: bytemuck::Pod>(w: &mut dyn Write, data: &[T]) -> io::Result<()> {
    let size = std::mem::size_of::<T>();
    for chunk in data.chunks(CHUNK_BYTES / size.max(1)) {
        let bytes: &[u8] = bytemuck::cast_slice(chunk);
        if cfg!(target_endian = "little") || size == 1 {
            w.write_all(bytes)?;
        } else {
            let mut swapped = bytes.to_vec();
            swapped.chunks_exact_mut(size).for_each(|s| s.reverse());
            w.write_all(&swapped)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("voxlab-io-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn atomic_write_replaces_and_cleans_up() {
        let dir = temp_dir("atomic");
        let p = dir.join("out.bin");
        write_atomic(&p, |w| w.write_all(b"one").map_err(|e| Error::io(&p, e))).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"one");
        // A failing writer leaves the old contents and no temporary file.
        let r = write_atomic(&p, |w| {
            w.write_all(b"half").map_err(|e| Error::io(&p, e))?;
            Err(Error::invalid("test", "fails on purpose"))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read(&p).unwrap(), b"one");
        assert_eq!(entries(&dir), vec!["out.bin"]);
        // A panicking writer too.
        let r = std::panic::catch_unwind(|| {
            let _ = write_atomic(&p, |_| panic!("on purpose"));
        });
        assert!(r.is_err());
        assert_eq!(entries(&dir), vec!["out.bin"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn atomic_write_refuses_missing_directory() {
        let p = std::env::temp_dir().join("voxlab-no-such-dir-xyz/out.bin");
        let e = write_atomic(&p, |_| Ok(())).unwrap_err();
        assert!(matches!(e, Error::Io { .. }), "{e}");
        assert!(e.to_string().contains("voxlab-no-such-dir-xyz"), "{e}");
    }

    #[test]
    fn text_samples() {
        let p = Path::new("t.nrrd");
        let s = parse_text_samples("1, 2\n-3 4", Stored::I8, 4, p, "int8").unwrap();
        assert!(matches!(s, Samples::I16(v) if v == [1, 2, -3, 4]));
        let e = parse_text_samples("1 2 300", Stored::U8, 3, p, "uchar").unwrap_err();
        assert!(e.to_string().contains("'300'"), "{e}");
        let e = parse_text_samples("1 2", Stored::F32, 3, p, "float").unwrap_err();
        assert!(e.to_string().contains("expected 3 values, found 2"), "{e}");
    }

    #[test]
    fn binary_samples_both_orders() {
        let p = Path::new("t.raw");
        let bytes = [0x01u8, 0x02, 0xff, 0xfe];
        let le = read_samples(&mut &bytes[..], Stored::I16, Endian::Little, 2, p).unwrap();
        assert!(matches!(le, Samples::I16(v) if v == [0x0201, -257]));
        let be = read_samples(&mut &bytes[..], Stored::U16, Endian::Big, 2, p).unwrap();
        assert!(matches!(be, Samples::U16(v) if v == [0x0102, 0xfffe]));
        let e = read_samples(&mut &bytes[..], Stored::F32, Endian::Big, 2, p).unwrap_err();
        assert!(e.to_string().contains("expected 8 bytes, found 4"), "{e}");
    }
}
