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
use fitted::{FittedMap, TemplateSpace};
use image::{ControlGrid, Interpolation};
use medial_core::image::Volume;
use medial_core::Vec3;
use medial_io::nifti_volume::{read_nifti_file, write_nifti, NiftiType};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The default largest distance between an image's grid pull-back and the exact map, voxels.
pub const DEFAULT_TOLERANCE_VOXELS: f64 = 0.01;

/// Carry points, meshes or images by the map of a fit.
#[derive(clap::Args, Debug)]
pub struct ApplyArgs {
    /// A folder written by `medial fit` (its summary.json, config.toml, momenta.npy and
    /// fitted_template.vtk; the template its config names must be unchanged).
    #[arg(value_name = "FIT_DIR")]
    pub fit: PathBuf,
    /// What to carry, in the template's world space (see --template-space; with --inverse: the
    /// subject's), RAS mm: points or a mesh (.vtk, .obj, .gltf, .glb) or an image (.nii,
    /// .nii.gz).
    #[arg(value_name = "INPUT")]
    pub input: PathBuf,
    /// The result: .vtk or .obj for points and meshes (a .vtk input written as .vtk keeps its
    /// cells and arrays), .nii or .nii.gz for an image (the input's voxel type).
    #[arg(long, value_name = "OUTPUT")]
    pub out: PathBuf,
    /// Carry by the inverse map, from the subject's space to the template's.
    #[arg(long)]
    pub inverse: bool,
    /// The template side's space: `given`, the template the fit was given (an automatic fit's
    /// map then includes its initial alignment and the projection after it), or `aligned`, the
    /// fit's aligned_template.vtk (the flow alone). The same for a fit with a config.
    #[arg(long, value_enum, default_value_t = TemplateSpace::Given)]
    pub template_space: TemplateSpace,
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
    /// Map every voxel of an image (or warp) by the whole flow instead of interpolating a
    /// control grid (slow: for checking).
    #[arg(long)]
    pub exact: bool,
    /// The largest distance between where a voxel samples the input and where the exact map
    /// would, in voxels of the output grid (its smallest spacing).
    #[arg(long, value_name = "VOXELS", default_value_t = DEFAULT_TOLERANCE_VOXELS)]
    pub tolerance: f64,
}

/// What `medial apply` prints.
#[derive(Serialize)]
struct ApplySummary {
    /// `forward` (template → subject) or `inverse`.
    direction: &'static str,
    /// `given` or `aligned`: the template side's space.
    template_space: &'static str,
    /// `points` or `image`.
    input: &'static str,
    /// Points carried (points and meshes).
    #[serde(skip_serializing_if = "Option::is_none")]
    points: Option<usize>,
    /// Voxels of the output grid (images, warps).
    #[serde(skip_serializing_if = "Option::is_none")]
    voxels: Option<usize>,
    /// For an image: whether it was sampled as labels (nearest).
    #[serde(skip_serializing_if = "Option::is_none")]
    labels: Option<bool>,
    /// Mean and largest distance a point moved (an image: from a voxel centre to where it was
    /// sampled), mm.
    mean_displacement_mm: f64,
    max_displacement_mm: f64,
    /// How an image's or warp's pull-back was computed (absent with --exact).
    #[serde(skip_serializing_if = "Option::is_none")]
    control_grid: Option<ControlGrid>,
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
    if !(args.tolerance.is_finite() && args.tolerance > 0.0) {
        return Err(CliError::Usage(format!(
            "--tolerance must be a positive number of voxels, got {}",
            args.tolerance
        )));
    }
    let map = FittedMap::open(&args.fit, args.template_space)?;
    let file = image_input
        .then(|| read_nifti_file(&args.input))
        .transpose()?;
    let grid = match (&args.like, &file) {
        (Some(like), _) => Some(medial_io::nifti_volume::read_nifti(like)?),
        (None, Some(file)) => Some(file.volume.clone()),
        (None, None) => None,
    };
    let nearest = file.as_ref().map(|f| match args.interpolation {
        Interpolation::Auto => f.labels,
        Interpolation::Nearest => true,
        Interpolation::Linear => false,
    });
    let sample = |x: &Vec3| match (&file, nearest) {
        (Some(f), Some(true)) => f.volume.sample_nearest(x),
        (Some(f), _) => f.volume.sample(x),
        (None, _) => 0.0,
    };
    let pulled = match &grid {
        Some(g) if image_input || args.warp.is_some() => Some(image::pull_back(
            g,
            &map,
            args.inverse,
            args.exact,
            args.tolerance,
            image_input.then_some(&sample as &(dyn Fn(&Vec3) -> f64 + Sync)),
            args.warp.is_some(),
        )?),
        _ => None,
    };
    let (input, labels, points, voxels, mean, max) = match (&pulled, &grid, &file) {
        (Some(pulled), Some(grid), Some(file)) => {
            let values = pulled.values.clone().unwrap_or_default();
            let datatype = match file.datatype {
                NiftiType::F64 => NiftiType::F64,
                _ if nearest != Some(true) => NiftiType::F32,
                stored => stored,
            };
            let resampled = Volume::new(grid.dims(), values, *grid.voxel_to_world())?;
            write_nifti(&args.out, &resampled, datatype)?;
            let p = pulled;
            ("image", nearest, None, Some(p.voxels), p.mean_mm, p.max_mm)
        }
        _ => {
            let (before, after) = carry::carry_mesh(&map, &args.input, &args.out, args.inverse)?;
            let lengths: Vec<f64> = after
                .iter()
                .zip(&before)
                .map(|(a, b)| (a - b).norm())
                .collect();
            let mean = lengths.iter().sum::<f64>() / lengths.len().max(1) as f64;
            let max = lengths.iter().copied().fold(0.0, f64::max);
            ("points", None, Some(lengths.len()), None, mean, max)
        }
    };
    if let (Some(path), Some(pulled), Some(grid)) = (&args.warp, &pulled, &grid) {
        let d = pulled.displacements.as_deref().unwrap_or_default();
        medial_io::warp::write_warp(path, grid, d)?;
    }
    print_json(&ApplySummary {
        direction: if args.inverse { "inverse" } else { "forward" },
        template_space: match args.template_space {
            TemplateSpace::Given => "given",
            TemplateSpace::Aligned => "aligned",
        },
        input,
        points,
        voxels: voxels.or(pulled.as_ref().map(|p| p.voxels)),
        labels,
        mean_displacement_mm: mean,
        max_displacement_mm: max,
        control_grid: pulled.and_then(|p| p.grid),
        seconds: start.elapsed().as_secs_f64(),
    })
}
