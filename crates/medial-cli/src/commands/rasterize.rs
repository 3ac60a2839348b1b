//! `medial rasterize`: a binary mask (1 inside, 0 outside) of a closed triangle mesh, on the
//! grid of a given image or on an axis-aligned grid around the mesh.

use crate::error::CliError;
use crate::memory;
use crate::output::{model_error, print_json};
use medial_core::image::rasterize::{grid_around, rasterize};
use medial_io::nifti_volume::{write_nifti, NiftiType};
use serde::Serialize;
use std::path::PathBuf;

/// Rasterize a closed triangle mesh into a NIfTI mask.
#[derive(clap::Args, Debug)]
#[command(group(clap::ArgGroup::new("grid").required(true).args(["like", "spacing"])))]
pub struct RasterizeArgs {
    /// The closed triangle mesh (.vtk, .obj, .gltf, .glb; a cmrep template's boundary works),
    /// in world (RAS) coordinates, mm.
    #[arg(value_name = "MESH")]
    pub mesh: PathBuf,
    /// The mask to write (.nii or .nii.gz): unsigned 8-bit, 1 at voxel centres inside the
    /// mesh, 0 outside.
    #[arg(long, value_name = "MASK.nii.gz")]
    pub out: PathBuf,
    /// Use the grid of this image (.nii, .nii.gz or .exr): its size, voxel spacing,
    /// orientation and origin.
    #[arg(long, value_name = "IMAGE")]
    pub like: Option<PathBuf>,
    /// Voxel size of an axis-aligned grid around the mesh, mm (instead of --like).
    #[arg(long, value_name = "MM")]
    pub spacing: Option<f64>,
    /// Margin between the mesh's bounding box and the border of the grid, mm (with
    /// --spacing).
    #[arg(long, value_name = "MM", default_value_t = 2.0)]
    pub margin: f64,
}

/// What `medial rasterize` prints.
#[derive(Serialize)]
struct RasterizeSummary {
    dims: [usize; 3],
    /// Voxel size along i, j, k, mm.
    spacing_mm: [f64; 3],
    inside_voxels: usize,
    /// Inside voxels × voxel volume, mm³.
    volume_mm3: f64,
}

/// Reads the mesh (and the reference image), rasterizes, writes the mask, prints a summary.
pub fn run(args: &RasterizeArgs) -> Result<(), CliError> {
    let mesh = medial_io::mesh::read_mesh(&args.mesh)?;
    let (dims, voxel_to_world) = match (&args.like, args.spacing) {
        (Some(like), _) => {
            let image = medial_io::volume::read_volume(like)?;
            (image.dims(), *image.voxel_to_world())
        }
        (None, Some(spacing)) => grid_around(&mesh, spacing, args.margin)?,
        (None, None) => {
            return Err(CliError::Input(
                "give the grid: --like IMAGE or --spacing MM [--margin MM]".into(),
            ))
        }
    };
    memory::check_grid(dims)?;
    let mask = rasterize(&mesh, dims, voxel_to_world).map_err(|e| model_error(&args.mesh, e))?;
    let inside = mask.data().iter().filter(|&&v| v > 0.0).count();
    if inside == 0 {
        // An empty mask is no picture of the mesh (issue 33): refused, nothing written.
        return Err(CliError::Input(format!(
            "{}: the mesh encloses no voxel centre of the {}×{}×{} grid: it has no volume \
             (degenerate: coincident or coplanar points) or lies outside the grid; no mask \
             written",
            args.mesh.display(),
            dims[0],
            dims[1],
            dims[2]
        )));
    }
    write_nifti(&args.out, &mask, NiftiType::U8)?;
    let spacing = mask.spacing();
    print_json(&RasterizeSummary {
        dims: mask.dims(),
        spacing_mm: [spacing.x, spacing.y, spacing.z],
        inside_voxels: inside,
        volume_mm3: inside as f64 * mask.voxel_volume(),
    })
}
