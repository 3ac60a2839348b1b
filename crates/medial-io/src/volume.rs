//! Volumes in any supported format, chosen by the file name (case-insensitive): NIfTI-1
//! (`.nii`, `.nii.gz`, see [`crate::nifti_volume`]) or OpenEXR (`.exr`, see
//! [`crate::exr_volume`]). Either way the [`Volume`] holds its voxels with `x` fastest and its
//! voxel-to-world map (voxel index → RAS mm).
//!
//! Every reader refuses a grid that can only give garbage world coordinates (see
//! [`check_grid`]): an empty dimension, a non-finite map, voxel sizes outside
//! [`MIN_VOXEL_SIZE_MM`] ..= [`MAX_VOXEL_SIZE_MM`], or coplanar voxel axes. A 1×1×1 volume is
//! a legal file.

use std::path::Path;

use medial_core::image::volume::Volume;
use nalgebra::Matrix4;

use crate::error::Geometry;
use crate::exr_volume::read_exr_volume;
use crate::nifti_volume::read_nifti;
use crate::{Error, Result};

/// Shortest voxel edge accepted, mm (a tenth of a micrometre: far below any imaging
/// resolution, far above the `1e-39` of a garbage header).
pub const MIN_VOXEL_SIZE_MM: f64 = 1e-4;

/// Longest voxel edge accepted, mm (10 m).
pub const MAX_VOXEL_SIZE_MM: f64 = 1e4;

/// Smallest `|det A| / (|a₁| |a₂| |a₃|)` accepted for the 3×3 part `A` of the voxel-to-world
/// map (columns `aᵢ`): the volume of a voxel relative to that of a box with the same edges, 1
/// for orthogonal axes, 0 for coplanar ones.
pub const MIN_AXIS_SINE: f64 = 1e-6;

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

/// Checks that a grid of `dims` voxels with the affine `voxel_to_world` (voxel index → RAS mm,
/// last row `0 0 0 1`) places voxels in the world: no dimension is 0, every entry is finite,
/// every voxel edge (column of the 3×3 part) is [`MIN_VOXEL_SIZE_MM`] to
/// [`MAX_VOXEL_SIZE_MM`] long and the axes are not coplanar ([`MIN_AXIS_SINE`]).
///
/// Errors: [`Error::Geometry`] naming `path` and the first problem.
pub fn check_grid(path: &Path, dims: [usize; 3], voxel_to_world: &Matrix4<f64>) -> Result<()> {
    grid_problem(dims, voxel_to_world).map_or(Ok(()), |problem| {
        Err(Error::Geometry {
            path: path.into(),
            problem,
        })
    })
}

/// The first problem of a grid (see [`check_grid`]).
fn grid_problem(dims: [usize; 3], m: &Matrix4<f64>) -> Option<Geometry> {
    if let Some(a) = dims.iter().position(|&n| n == 0) {
        return Some(Geometry::EmptyDimension {
            axis: a + 1,
            size: 0,
        });
    }
    if let Some((n, &value)) = m.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        // Column-major storage: entry n is at row n % 4, column n / 4.
        return Some(Geometry::NonFiniteMap {
            row: n % 4 + 1,
            column: n / 4 + 1,
            value,
        });
    }
    let a = m.fixed_view::<3, 3>(0, 0);
    let sizes = [0, 1, 2].map(|c| a.column(c).norm());
    if let Some(c) = (0..3).find(|&c| !(MIN_VOXEL_SIZE_MM..=MAX_VOXEL_SIZE_MM).contains(&sizes[c]))
    {
        return Some(Geometry::VoxelSize {
            axis: c + 1,
            size_mm: sizes[c],
        });
    }
    let sine = a.determinant().abs() / sizes.iter().product::<f64>();
    (sine < MIN_AXIS_SINE).then_some(Geometry::Singular { sine })
}
