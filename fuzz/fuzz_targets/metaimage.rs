//! Feeds arbitrary bytes to voxlab's MetaImage reader (a header with LOCAL data): it
//! must return a volume or an error, never panic, hang or allocate what the bytes
//! merely promise.
#![no_main]

use libfuzzer_sys::fuzz_target;
use voxlab::io::{read_volume_bytes, read_volume_bytes_frame, Format};

fuzz_target!(|data: &[u8]| {
    let path = std::path::Path::new("fuzz.mha");
    let _ = read_volume_bytes(data, Format::MetaImage, path);
    // Files of several 3-D volumes are read one frame at a time.
    let _ = read_volume_bytes_frame(data, Format::MetaImage, path, Some(1));
});
