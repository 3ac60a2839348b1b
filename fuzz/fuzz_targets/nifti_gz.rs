//! NIfTI-1 volumes (seeded with gzip-compressed `.nii.gz` files).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::path::Path::new("fuzz.nii.gz");
    let _ = medial_io::nifti_volume::parse_nifti(data.to_vec(), path);
});
