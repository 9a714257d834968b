//! Feeds arbitrary bytes to voxlab's reader of RTK's geometry XML (with a detector
//! grid, as `voxlab reconstruct` gives it): it must return views or an error, never
//! panic, hang or allocate what the bytes merely promise.
#![no_main]

use libfuzzer_sys::fuzz_target;
use voxlab::io::projections::{parse_geometry_bytes, DetectorGrid};

fuzz_target!(|data: &[u8]| {
    let path = std::path::Path::new("fuzz.xml");
    let grid = DetectorGrid::centred(24, 20, 4.0, 3.5);
    let _ = parse_geometry_bytes(data, path, Some(&grid));
    // Without a grid, the XML is still parsed before the refusal.
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = voxlab::io::rtk_geometry::parse_rtk_geometry(text, path);
    }
});
