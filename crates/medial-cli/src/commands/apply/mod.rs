//! `medial apply`: carries points, meshes and images from the template's space to the subject's
//! by the map of a finished fit (`F = φ₁ ∘ A`: the fitted flow after the fit's initial
//! alignment `A`, if any; [`medial_core::flow::ambient`]), or back by its inverse, and writes
//! the displacement field of an image's pull-back as a NIfTI warp ([`medial_io::warp`]).
//!
//! Points and meshes move by the map itself. An image is pulled back: the output grid (the
//! input's, or `--like`'s) is sampled where the opposite map sends its voxel centres, so that
//! carrying forward samples the input at `F⁻¹(y)`.

mod carry;
mod fitted;
mod image;

use crate::error::CliError;
use crate::output::print_json;
use fitted::FittedMap;
use image::{Interpolation, PullBack};
use medial_core::Vec3;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Carry points, meshes or images by the map of a fit.
#[derive(clap::Args, Debug)]
pub struct ApplyArgs {
    /// A folder written by `medial fit` (its summary.json, config.toml, momenta.npy and
    /// fitted_template.vtk; the template its config names must be unchanged).
    #[arg(value_name = "FIT_DIR")]
    pub fit: PathBuf,
    /// What to carry, in the template's world space (with --inverse: the subject's), RAS mm:
    /// points or a mesh (.vtk, .obj, .gltf, .glb) or an image (.nii, .nii.gz).
    #[arg(value_name = "INPUT")]
    pub input: PathBuf,
    /// The result: .vtk or .obj for points and meshes (a .vtk input written as .vtk keeps its
    /// cells and arrays), .nii or .nii.gz for an image (the input's voxel type).
    #[arg(long, value_name = "OUTPUT")]
    pub out: PathBuf,
    /// Carry by the inverse map, from the subject's space to the template's.
    #[arg(long)]
    pub inverse: bool,
    /// An image whose grid (size, spacing, orientation, origin) the result is sampled on (for
    /// an image; for a mesh, the grid of --warp) [default: the input image's].
    #[arg(long, value_name = "IMAGE")]
    pub like: Option<PathBuf>,
    /// Also write the displacement field of the pull-back on the output grid as a NIfTI warp
    /// (5-D [nx,ny,nz,1,3], intent vector, LPS mm; ITK, ANTs and greedy read it): a grid point
    /// y goes to y + d(y) in the input's space. With a mesh it needs --like.
    #[arg(long, value_name = "WARP.nii.gz")]
    pub warp: Option<PathBuf>,
    /// Sampling of an image: auto is nearest for integer voxel types (label maps) and linear
    /// for real ones.
    #[arg(long, value_enum, default_value_t = Interpolation::Auto)]
    pub interpolation: Interpolation,
}

/// What `medial apply` prints.
#[derive(Serialize)]
struct ApplySummary {
    /// `forward` (template → subject) or `inverse`.
    direction: &'static str,
    /// `points` or `image`.
    input: &'static str,
    /// Points carried, or voxels of the output grid.
    points: usize,
    /// For an image: whether it was sampled as labels (nearest).
    #[serde(skip_serializing_if = "Option::is_none")]
    labels: Option<bool>,
    /// Mean and largest distance a point moved (an image: from a voxel centre to where it was
    /// sampled), mm.
    mean_displacement_mm: f64,
    max_displacement_mm: f64,
    /// Wall-clock seconds, the fit's map read and computed included.
    seconds: f64,
}

/// Whether `path` names a NIfTI image (`.nii`, `.nii.gz`, in any case).
fn is_nifti(path: &Path) -> bool {
    let name = path.to_string_lossy().to_ascii_lowercase();
    name.ends_with(".nii") || name.ends_with(".nii.gz")
}

/// Reads the fit, carries the input, writes the result (and the warp), prints a summary.
pub fn run(args: &ApplyArgs) -> Result<(), CliError> {
    let start = Instant::now();
    let image_input = is_nifti(&args.input);
    if args.warp.is_some() && !image_input && args.like.is_none() {
        return Err(CliError::Usage(
            "--warp with points or a mesh needs --like IMAGE, the grid to write the warp on".into(),
        ));
    }
    if image_input != is_nifti(&args.out) {
        return Err(CliError::Usage(format!(
            "{} and {} must both be images (.nii, .nii.gz) or both points or meshes",
            args.input.display(),
            args.out.display()
        )));
    }
    let map = FittedMap::open(&args.fit)?;
    let grid = match (&args.like, image_input) {
        (Some(like), _) => Some(medial_io::nifti_volume::read_nifti(like)?),
        (None, true) => Some(medial_io::nifti_volume::read_nifti(&args.input)?),
        (None, false) => None,
    };
    let pull = grid
        .as_ref()
        .filter(|_| image_input || args.warp.is_some())
        .map(|g| PullBack::on(g, &map, args.inverse))
        .transpose()?;
    let (input, labels, moved) = match (&pull, &grid) {
        (Some(pull), Some(grid)) if image_input => {
            let labels = image::resample(&args.input, grid, pull, args.interpolation, &args.out)?;
            ("image", Some(labels), pull.displacements())
        }
        _ => {
            let (before, after) = carry::carry_mesh(&map, &args.input, &args.out, args.inverse)?;
            let moved = after.iter().zip(&before).map(|(a, b)| a - b).collect();
            ("points", None, moved)
        }
    };
    if let (Some(path), Some(pull), Some(grid)) = (&args.warp, &pull, &grid) {
        medial_io::warp::write_warp(path, grid, &pull.displacements())?;
    }
    let lengths: Vec<f64> = moved.iter().map(Vec3::norm).collect();
    print_json(&ApplySummary {
        direction: if args.inverse { "inverse" } else { "forward" },
        input,
        points: lengths.len(),
        labels,
        mean_displacement_mm: lengths.iter().sum::<f64>() / lengths.len().max(1) as f64,
        max_displacement_mm: lengths.iter().copied().fold(0.0, f64::max),
        seconds: start.elapsed().as_secs_f64(),
    })
}
