//! glTF 2.0 meshes (seeded with JSON `.gltf` files, buffers embedded as data URIs). External
//! buffers are looked up beside a file in a folder that does not exist.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::path::Path::new("/nonexistent-medial-fuzz/fuzz.gltf");
    let _ = medial_io::mesh::parse_gltf(data, path);
});
