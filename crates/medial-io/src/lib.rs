//! # medial-io
//!
//! File formats of `medial`: legacy VTK polydata (ASCII and binary, 3.0/4.x and 5.1 layouts),
//! cmrep medial templates, NumPy `.npy` arrays, NIfTI and OpenEXR volumes, OBJ and glTF meshes.
//! Everything is written to a temporary file first and renamed into place, so that a failure
//! never leaves a half-written result.

pub mod atomic;
pub mod cmrep;
pub mod error;
pub mod exr_volume;
pub mod mesh;
pub mod model;
pub mod nifti_volume;
pub mod npy;
pub mod sheet;
pub mod vtk;

pub use error::{Error, Result};
