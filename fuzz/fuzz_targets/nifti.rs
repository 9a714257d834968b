//! Feeds arbitrary bytes to voxlab's Nifti reader: it must return a volume or an error,
//! never panic, hang or allocate what the bytes merely promise.
#![no_main]

use libfuzzer_sys::fuzz_target;
use voxlab::io::{read_volume_bytes, Format};

fuzz_target!(|data: &[u8]| {
    let path = std::path::Path::new("fuzz.nifti");
    let _ = read_volume_bytes(data, Format::Nifti, path);
    // Files of several 3-D volumes are read one frame at a time.
    let _ = voxlab::io::nifti::read_nifti_bytes_frame(data, path, Some(1));
});
