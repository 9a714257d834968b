//! Feeds arbitrary bytes to voxlab's MetaImage reader (a header with LOCAL data): it
//! must return a volume or an error, never panic, hang or allocate what the bytes
//! merely promise.
#![no_main]

use libfuzzer_sys::fuzz_target;
use voxlab::io::{read_volume_bytes, Format};

fuzz_target!(|data: &[u8]| {
    let _ = read_volume_bytes(data, Format::MetaImage, std::path::Path::new("fuzz.mha"));
});
