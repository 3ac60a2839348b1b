//! Wavefront OBJ meshes.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = medial_io::mesh::parse_obj(data, std::path::Path::new("fuzz.obj"));
});
