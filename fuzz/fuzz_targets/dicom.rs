//! Feeds arbitrary bytes to voxlab's DICOM reader (native and compressed pixel data:
//! RLE, JPEG baseline, extended and lossless, JPEG-LS, JPEG 2000): it must return a
//! volume or an error, never panic, hang or allocate what the bytes merely promise.
//! The reader works on paths (a series is a directory), so each input goes through one
//! scratch file of this process.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::PathBuf;
use std::sync::OnceLock;

fn scratch() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = std::env::temp_dir().join(format!("voxlab-fuzz-dicom-{}", std::process::id()));
        std::fs::create_dir_all(&d).expect("a scratch directory");
        d.join("input.dcm")
    })
}

fuzz_target!(|data: &[u8]| {
    let path = scratch();
    if std::fs::write(path, data).is_ok() {
        let _ = voxlab::io::dicom::read_dicom(path);
        // Multi-frame files are read one frame at a time too.
        let _ = voxlab::io::dicom::read_dicom_frame(path, Some(1));
    }
});
