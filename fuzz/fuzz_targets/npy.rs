//! NumPy `.npy` arrays.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = medial_io::npy::parse_npy(data, std::path::Path::new("fuzz.npy"));
});
