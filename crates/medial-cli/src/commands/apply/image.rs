//! Images carried by a fitted map: pulled back through the opposite map on an output grid, and
//! the displacement field of that pull-back as a warp.

use super::fitted::FittedMap;
use crate::error::CliError;
use medial_core::image::Volume;
use medial_core::memory::Estimate;
use medial_core::Vec3;
use medial_io::nifti_volume::{read_nifti_file, write_nifti, NiftiType};

/// How the values of an image are sampled at the pulled-back points.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    /// Nearest for integer images (label maps), linear for real ones.
    Auto,
    /// The nearest voxel: labels stay labels.
    Nearest,
    /// Trilinear.
    Linear,
}

/// The centres of the voxels of `grid` (RAS mm), `x` fastest, and the points the map (the
/// opposite of the carrying direction: `F⁻¹` to carry forward) sends them to.
pub struct PullBack {
    /// The voxel centres `y`.
    pub centres: Vec<Vec3>,
    /// Their images: where the output samples the input.
    pub sources: Vec<Vec3>,
}

impl PullBack {
    /// The pull-back on `grid` of carrying by `map` (by its inverse with `inverse`).
    pub fn on(grid: &Volume, map: &FittedMap, inverse: bool) -> Result<Self, CliError> {
        let [nx, ny, nz] = grid.dims();
        crate::memory::check(&Estimate::pull_back(nx * ny * nz), || {
            format!("a pull-back on {nx}×{ny}×{nz} voxels")
        })?;
        let centres: Vec<Vec3> = (0..nz)
            .flat_map(|k| (0..ny).flat_map(move |j| (0..nx).map(move |i| [i, j, k])))
            .map(|index| grid.voxel_centre(index))
            .collect();
        let sources = map.carry(&centres, !inverse)?;
        Ok(Self { centres, sources })
    }

    /// The displacements `d(y) = source − y`, mm.
    pub fn displacements(&self) -> Vec<Vec3> {
        self.sources
            .iter()
            .zip(&self.centres)
            .map(|(s, y)| s - y)
            .collect()
    }
}

/// Resamples the NIfTI image `input` on `grid` through `pull` and writes it to `out` in the
/// input's voxel type (linear samples of an integer image as `float32`); returns whether it was
/// sampled as labels.
pub fn resample(
    input: &std::path::Path,
    grid: &Volume,
    pull: &PullBack,
    interpolation: Interpolation,
    out: &std::path::Path,
) -> Result<bool, CliError> {
    let file = read_nifti_file(input)?;
    let nearest = match interpolation {
        Interpolation::Auto => file.labels,
        Interpolation::Nearest => true,
        Interpolation::Linear => false,
    };
    let sample = |x: &Vec3| {
        if nearest {
            file.volume.sample_nearest(x)
        } else {
            file.volume.sample(x)
        }
    };
    let values = pull.sources.iter().map(sample).collect();
    let datatype = match file.datatype {
        NiftiType::F64 => NiftiType::F64,
        _ if !nearest => NiftiType::F32,
        stored => stored,
    };
    let resampled = Volume::new(grid.dims(), values, *grid.voxel_to_world())?;
    write_nifti(out, &resampled, datatype)?;
    Ok(nearest)
}
