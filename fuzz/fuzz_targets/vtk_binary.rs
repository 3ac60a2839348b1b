//! Legacy VTK polydata (seeded with binary files), then the cmrep template built from it.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use medial_io::{cmrep, vtk};

fuzz_target!(|data: &[u8]| {
    let path = Path::new("fuzz.vtk");
    if let Ok(polydata) = vtk::parse_polydata(data, path) {
        let _ = polydata.to_trimesh(path);
        let _ = cmrep::template_from_polydata(&polydata, path);
    }
});
