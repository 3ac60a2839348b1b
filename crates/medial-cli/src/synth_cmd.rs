//! `medial synth`: writes a self-contained synthetic case into a folder: the template, a target
//! segmentation (the template's shape carried by a known diffeomorphism, rasterized), the
//! affine part of that diffeomorphism and a ready `fit.toml` in the style of the paper (an SSD
//! initialisation by the affine map, then Dice with μ rising from 0.001 to 10).

use crate::error::CliError;
use crate::inflate_cmd::{print_json, write_options, TemplateSummary};
use medial_core::synth::{Shape, SyntheticCase};
use medial_io::nifti_volume::{write_nifti, NiftiType};
use medial_io::vtk::{self, PolyData};
use nalgebra::Matrix4;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Write a synthetic case (template, target image, fit.toml).
#[derive(clap::Args, Debug)]
pub struct SynthArgs {
    /// The case: `cup` (an LV-like curved sheet of varying thickness with a free edge) or `toy`
    /// (the paper's toy: three sheets meeting along one seam).
    #[arg(value_name = "NAME")]
    pub name: String,
    /// Folder to write into (created if needed; files of the same names are replaced).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Voxel size of the target image, mm [default: 0.5].
    #[arg(long, value_name = "MM")]
    pub spacing: Option<f64>,
    /// Margin between the target and the border of its image, mm.
    #[arg(long, value_name = "MM", default_value_t = 3.0)]
    pub margin: f64,
}

/// The fit settings written into `fit.toml` for a case.
struct FitPlan {
    /// Kernel width σ, mm.
    sigma: f64,
    /// Time steps N.
    time_steps: usize,
    /// Weight of the kinetic energy.
    kinetic_weight: f64,
    /// Prism layers between boundary and medial sheet in the Dice estimate.
    layers: usize,
    /// L-BFGS iterations of the SSD initialisation.
    ssd_iterations: usize,
    /// L-BFGS iterations per AL iteration of the Dice stage.
    dice_iterations: usize,
}

fn plan(shape: Shape) -> FitPlan {
    match shape {
        Shape::Cup => FitPlan {
            sigma: 3.0,
            time_steps: 20,
            kinetic_weight: 0.005,
            layers: 10,
            ssd_iterations: 300,
            dice_iterations: 150,
        },
        Shape::Toy => FitPlan {
            sigma: 2.0,
            time_steps: 20,
            kinetic_weight: 0.005,
            layers: 10,
            ssd_iterations: 300,
            dice_iterations: 150,
        },
    }
}

/// What `medial synth` prints.
#[derive(Serialize)]
struct SynthSummary {
    case: &'static str,
    out: PathBuf,
    template: TemplateSummary,
    /// Landmark moves of the projection of the inflated template, mm.
    projection_max_displacement_mm: f64,
    /// Largest spoke–normal deviation of the inflated template before projection, degrees.
    inflated_max_spoke_normal_deg: f64,
    image_dims: [usize; 3],
    image_spacing_mm: f64,
    /// Foreground volume of the target image, mm³.
    target_volume_mm3: f64,
}

/// Builds the case and writes `template.vtk`, `target.nii.gz`, `target_boundary.vtk`,
/// `affine.txt` and `fit.toml` into the folder; prints a summary.
pub fn run(args: &SynthArgs) -> Result<(), CliError> {
    let shape = Shape::from_name(&args.name).map_err(|e| CliError::Input(e.to_string()))?;
    let spacing = args.spacing.unwrap_or_else(|| shape.image_spacing_mm());
    let case = SyntheticCase::build(shape)?;
    let image = case.target_image(spacing, args.margin)?;
    std::fs::create_dir_all(&args.out).map_err(|e| CliError::io(&args.out, e))?;
    let out = |name: &str| args.out.join(name);
    medial_io::cmrep::write_template(&out("template.vtk"), case.template(), write_options(false))?;
    write_nifti(&out("target.nii.gz"), &image, NiftiType::U8)?;
    let target_boundary = PolyData::from_trimesh(&case.target_boundary()?);
    vtk::write_polydata(
        &out("target_boundary.vtk"),
        &target_boundary,
        write_options(false),
    )?;
    write_text(&out("affine.txt"), &affine_text(&case.warp.affine()))?;
    write_text(&out("fit.toml"), &fit_toml(shape, &plan(shape)))?;
    print_json(&SynthSummary {
        case: shape.name(),
        out: args.out.clone(),
        template: TemplateSummary::of(case.template()),
        projection_max_displacement_mm: case.projection.max_displacement,
        inflated_max_spoke_normal_deg: case.projection.before.max_spoke_normal_deg,
        image_dims: image.dims(),
        image_spacing_mm: spacing,
        target_volume_mm3: image.integral(),
    })
}

/// A 4×4 matrix as 4 lines of 4 numbers (the format of an SSD stage's `transform`).
fn affine_text(m: &Matrix4<f64>) -> String {
    m.row_iter()
        .map(|row| {
            let cells: Vec<String> = row.iter().map(|v| format!("{v:.12}")).collect();
            cells.join(" ") + "\n"
        })
        .collect()
}

/// The case's `fit.toml`: SSD towards the affine part (μ = 1, one AL iteration), then Dice
/// with μ = 0.001, 0.01, 0.1, 1, 10.
fn fit_toml(shape: Shape, plan: &FitPlan) -> String {
    format!(
        r#"# Synthetic case '{name}', written by `medial synth {name}`.
# target.nii.gz is template.vtk carried by a known twist + bend + affine map and rasterized;
# target_boundary.vtk is the same map applied to the template's boundary points (an SSD target
# with known correspondence); affine.txt is the affine part of the map.
# As in the paper: one SSD AL iteration (mu = 1) towards the affine initialisation, then the
# Dice attachment with mu rising from 0.001 to 10 over five AL iterations.
# The Dice estimate gives the boundary samples (where the smoothed image is about 1/2) a sixth of
# the outermost prisms, which biases it low by about 1/(4·layers): 10 layers instead of the
# default 5 halve that bias. sigma is small against the wall (half thickness 2–4 mm) so that the
# flow can move medial and boundary points apart, as the constraints need.

[model]
template = "template.vtk"

[flow]
sigma = {sigma:?}          # kernel width, mm
time_steps = {steps}
kinetic_weight = {kinetic:?}

[output]
every_time_point = false

[[stage]]
name = "affine"
attachment = "ssd"
transform = "affine.txt"
mu = 1.0
al_iterations = 1
max_iterations = {ssd}

[[stage]]
name = "dice"
attachment = "dice"
image = "target.nii.gz"
layers = {layers}
mu = 0.001
mu_factor = 10.0
al_iterations = 5
max_iterations = {dice}
"#,
        name = shape.name(),
        sigma = plan.sigma,
        steps = plan.time_steps,
        kinetic = plan.kinetic_weight,
        layers = plan.layers,
        ssd = plan.ssd_iterations,
        dice = plan.dice_iterations,
    )
}

fn write_text(path: &Path, text: &str) -> Result<(), CliError> {
    Ok(medial_io::atomic::write_atomic(path, |w| {
        w.write_all(text.as_bytes())
    })?)
}
