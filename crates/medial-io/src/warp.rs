//! Displacement fields as NIfTI warps, in the convention ITK, ANTs and greedy read.
//!
//! **Convention.** A warp is a NIfTI-1 image of dimensions `[nx, ny, nz, 1, 3]` (`dim[0] = 5`;
//! the three components along the fifth dimension, each a 3-D block with `x` fastest),
//! `intent_code = 1007` (`NIFTI_INTENT_VECTOR`), `float32`, on the voxel grid of a volume (its
//! sform and qform as [`crate::nifti_volume::write_nifti`] writes them). Voxel `v` holds the
//! displacement `d(y)` in mm at its centre `y`, in **LPS** components (ITK's physical space:
//! `(−d_x, −d_y, d_z)` of the RAS displacement), which ITK-based tools read without conversion
//! for this intent. The field is a *resampling* transform, as these tools use one: the point `y`
//! of the grid's space maps to `y + d(y)` in the space an image is resampled from, so that
//! `antsApplyTransforms -r GRID -t WARP` and `greedy -r WARP` pull an image back through it, and
//! `antsApplyTransformsToPoints -t WARP` moves points from the grid's space by `y + d(y)`.
//!
//! Read back ([`read_warp`]), a warp is three [`Volume`]s of RAS components on its grid;
//! [`Warp::map`] interpolates them trilinearly (0 outside the grid, the identity there).

use std::path::Path;

use medial_core::image::volume::Volume;
use medial_core::Vec3;

use crate::nifti_volume::{decode, header_for, write_raw, NiftiType, Voxel};
use crate::{Error, Result};

/// `NIFTI_INTENT_VECTOR`.
pub const INTENT_VECTOR: i16 = 1007;

/// RAS ↔ LPS: the signs of the components (the map is its own inverse).
const LPS: [f64; 3] = [-1.0, -1.0, 1.0];

/// A displacement field read from a warp: RAS components (mm) on one grid.
#[derive(Clone, Debug)]
pub struct Warp {
    /// `d_x`, `d_y`, `d_z` (RAS, mm), each on the grid of the warp.
    pub components: [Volume; 3],
}

impl Warp {
    /// `y + d(y)`, `d` trilinear in the voxels (0 outside the grid): where the point `y` (RAS mm)
    /// maps to.
    pub fn map(&self, y: &Vec3) -> Vec3 {
        y + Vec3::from_fn(|c, _| self.components[c].sample(y))
    }
}

/// Writes the displacements `d` (RAS mm, one per voxel of `grid`, `x` fastest) as a warp on the
/// grid of `grid` (module doc for the convention).
///
/// Errors: [`Error::Format`] for a name that does not end in `.nii`/`.nii.gz`, a displacement
/// count that is not the grid's voxel count, or a displacement beyond the `float32` range;
/// [`Error::Io`] if the file cannot be written.
pub fn write_warp(path: &Path, grid: &Volume, displacements: &[Vec3]) -> Result<()> {
    let voxels = grid.data().len();
    if displacements.len() != voxels {
        return Err(Error::format(
            path,
            format!(
                "{} displacements for a grid of {voxels} voxels",
                displacements.len()
            ),
        ));
    }
    let mut header = header_for(grid, NiftiType::F32);
    header.dim = [5, 1, 1, 1, 1, 3, 1, 1];
    header.intent_code = INTENT_VECTOR;
    let values: Vec<f64> = (0..3)
        .flat_map(|c| displacements.iter().map(move |d| LPS[c] * d[c]))
        .collect();
    write_raw(path, header, grid.dims(), &values, NiftiType::F32)
}

/// Reads a warp written by [`write_warp`] or by ITK-based tools: a 5-D NIfTI-1 image
/// `[nx, ny, nz, 1, 3]` of LPS displacements (mm) with intent `NIFTI_INTENT_VECTOR`.
///
/// Errors: as [`crate::nifti_volume::read_nifti`]; [`Error::Geometry`] for other dimensions;
/// [`Error::Format`] for another intent (`1006`, `NIFTI_INTENT_DISPVECT`, whose vectors are RAS,
/// included).
pub fn read_warp(path: &Path) -> Result<Warp> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let decoded = decode(bytes, path, Voxel::Vector)?;
    if decoded.header.intent_code != INTENT_VECTOR {
        return Err(Error::format(
            path,
            format!(
                "intent_code is {}: a warp has intent_code {INTENT_VECTOR} (vectors, LPS)",
                decoded.header.intent_code
            ),
        ));
    }
    let voxels = decoded.data.len() / 3;
    let component = |c: usize| {
        let values = decoded.data[c * voxels..(c + 1) * voxels]
            .iter()
            .map(|v| LPS[c] * v)
            .collect();
        Volume::new(decoded.dims, values, decoded.voxel_to_world).map_err(|e| Error::model(path, e))
    };
    Ok(Warp {
        components: [component(0)?, component(1)?, component(2)?],
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix4;

    /// A 4×3×2 grid of 0.5 × 1 × 2 mm voxels, its axes permuted and flipped, offset.
    fn grid() -> Volume {
        let m = Matrix4::new(
            0.0, -0.5, 0.0, 10.0, //
            1.0, 0.0, 0.0, -4.0, //
            0.0, 0.0, 2.0, 3.0, //
            0.0, 0.0, 0.0, 1.0,
        );
        Volume::new([4, 3, 2], vec![0.0; 24], m).unwrap()
    }

    #[test]
    fn a_warp_reads_back_with_its_grid_and_lps_on_disk() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("warp.nii.gz");
        let grid = grid();
        let d: Vec<Vec3> = (0..24)
            .map(|i| Vec3::new(i as f64 * 0.25, -1.5, 0.125 * i as f64))
            .collect();
        write_warp(&path, &grid, &d).unwrap();
        let warp = read_warp(&path).unwrap();
        for c in &warp.components {
            assert_eq!(c.dims(), [4, 3, 2]);
            assert!((c.voxel_to_world() - grid.voxel_to_world()).amax() < 1e-6);
        }
        for (i, di) in d.iter().enumerate() {
            let y = grid.voxel_centre([i % 4, (i / 4) % 3, i / 12]);
            assert!((warp.map(&y) - (y + di)).norm() < 1e-5, "voxel {i}");
        }
        // On disk: 5-D, vector intent, the x component negated (LPS).
        let raw = crate::nifti_volume::decode(std::fs::read(&path).unwrap(), &path, Voxel::Vector)
            .unwrap();
        assert_eq!(raw.header.dim[..6], [5, 4, 3, 2, 1, 3]);
        assert_eq!(raw.header.intent_code, 1007);
        assert_eq!(raw.data[1], -0.25);
        assert_eq!(raw.data[24], 1.5);
        assert_eq!(raw.data[48 + 2], 0.25);
    }

    #[test]
    fn a_scalar_image_or_another_intent_is_not_a_warp() {
        let dir = tempfile::tempdir().unwrap();
        let scalar = dir.path().join("scalar.nii");
        crate::nifti_volume::write_nifti(&scalar, &grid(), NiftiType::F32).unwrap();
        let err = read_warp(&scalar).unwrap_err();
        assert!(err.to_string().contains("[nx, ny, nz, 1, 3]"), "{err}");
        let wrong = dir.path().join("short.nii");
        assert!(write_warp(&wrong, &grid(), &[Vec3::zeros()]).is_err());
        assert!(crate::nifti_volume::read_nifti(&dir.path().join("none.nii")).is_err());
    }
}
