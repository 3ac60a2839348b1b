//! Volumes in any supported format, chosen by the file name (case-insensitive): NIfTI-1
//! (`.nii`, `.nii.gz`, see [`crate::nifti_volume`]) or OpenEXR (`.exr`, see
//! [`crate::exr_volume`]). Either way the [`Volume`] holds its voxels with `x` fastest and its
//! voxel-to-world map (voxel index → RAS mm).

use std::path::Path;

use medial_core::image::volume::Volume;

use crate::exr_volume::read_exr_volume;
use crate::nifti_volume::read_nifti;
use crate::{Error, Result};

/// Reads a volume from NIfTI (`.nii`, `.nii.gz`) or OpenEXR (`.exr`), by the file name.
///
/// Errors: [`Error::Format`] for another name; else as [`read_nifti`] or [`read_exr_volume`].
pub fn read_volume(path: &Path) -> Result<Volume> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    if name.ends_with(".exr") {
        read_exr_volume(path)
    } else if name.ends_with(".nii") || name.ends_with(".nii.gz") {
        read_nifti(path)
    } else {
        Err(Error::format(
            path,
            "unknown image format: expected .nii, .nii.gz or .exr",
        ))
    }
}
