//! Feeds arbitrary bytes to voxlab's Nrrd reader: it must return a volume or an error,
//! never panic, hang or allocate what the bytes merely promise.
#![no_main]

use libfuzzer_sys::fuzz_target;
use voxlab::io::{read_volume_bytes, read_volume_bytes_frame, Format};

fuzz_target!(|data: &[u8]| {
    let path = std::path::Path::new("fuzz.nrrd");
    let _ = read_volume_bytes(data, Format::Nrrd, path);
    // Files of several 3-D volumes are read one frame at a time.
    let _ = read_volume_bytes_frame(data, Format::Nrrd, path, Some(1));
});
