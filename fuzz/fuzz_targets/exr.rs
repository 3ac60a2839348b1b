//! OpenEXR volumes.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::path::Path::new("fuzz.exr");
    let _ = medial_io::exr_volume::parse_exr_volume(data, path);
});
