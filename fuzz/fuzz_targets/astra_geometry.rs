//! Feeds arbitrary bytes to voxlab's readers of geometry JSON — ASTRA's `proj_geom`
//! and voxlab's own (circular and per-view), told apart as `--geometry FILE` tells
//! them: each must return a geometry or an error, never panic or allocate what the
//! bytes merely promise.
#![no_main]

use libfuzzer_sys::fuzz_target;
use voxlab::io::projections::parse_geometry_bytes;

fuzz_target!(|data: &[u8]| {
    let path = std::path::Path::new("fuzz.json");
    if let Ok(g) = parse_geometry_bytes(data, path, None) {
        // A geometry read is one voxlab can build (or refuse) without panicking.
        let _ = g.into_geometry(path);
    }
});
