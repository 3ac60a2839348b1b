//! `medial synth`: writes a self-contained synthetic case into a folder: the template, a target
//! segmentation (the template's shape carried by a known diffeomorphism, rasterized), the
//! affine part of that diffeomorphism and ready configs in the style of the paper (an SSD
//! initialisation by the affine map, then Dice with μ rising over six AL iterations).
//!
//! The template is a built-in analytic shape (`medial synth cup|toy`, this module) or any cmrep
//! template (`medial synth --from TEMPLATE.vtk`, [`from_template`]); [`CaseFiles`] (the files
//! of a case) and the engine's [`FitPlan`] (its configs: [`paper_config`], [`boundary_config`])
//! serve both.

mod from_template;

use crate::config::{Config, Source};
use crate::error::CliError;
use crate::memory;
use crate::output::{print_json, write_options, write_text, TemplateSummary};
use medial_core::fit::plan::FitPlan;
use medial_core::image::rasterize::grid_around;
use medial_core::image::volume::Volume;
use medial_core::model::template::MedialTemplate;
use medial_core::synth::{self, Shape, SyntheticCase};
use medial_core::TriMesh;
use medial_io::nifti_volume::{write_nifti, NiftiType};
use medial_io::vtk::{self, PolyData};
use nalgebra::Matrix4;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Write a synthetic case (template, target image, affine part, configs).
#[derive(clap::Args, Debug)]
pub struct SynthArgs {
    /// A built-in shape: `cup` (an LV-like curved sheet of varying thickness with a free edge)
    /// or `toy` (the paper's toy: three sheets meeting along one seam).
    #[arg(
        value_name = "SHAPE",
        required_unless_present = "from",
        conflicts_with = "from",
        value_parser = parse_shape
    )]
    pub shape: Option<Shape>,
    /// Make the case from this cmrep template instead (legacy VTK polydata with a MedialIndex
    /// point array; coordinates in mm): a twist + bend of its long principal axis, then an
    /// affine map; writes fit_boundary.toml (constrained SSD to the warped points) beside
    /// fit.toml.
    #[arg(long, value_name = "TEMPLATE.vtk")]
    pub from: Option<PathBuf>,
    /// Folder to write into (created if needed; files of the same names are replaced).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Voxel size of the target image, mm [default: 0.5].
    #[arg(long, value_name = "MM")]
    pub spacing: Option<f64>,
    /// Margin between the target and the border of its image, mm.
    #[arg(long, value_name = "MM", default_value_t = 3.0)]
    pub margin: f64,
    #[command(flatten)]
    pub warp: from_template::WarpArgs,
}

/// The built-in shape called `name` (any case); an unknown name is a command-line error (exit
/// 2) that lists the shapes.
fn parse_shape(name: &str) -> Result<Shape, String> {
    Shape::from_name(name).map_err(|_| {
        let names: Vec<&str> = Shape::ALL.iter().map(|s| s.name()).collect();
        format!(
            "the built-in shapes are {} (or give --from TEMPLATE.vtk)",
            names.join(", ")
        )
    })
}

/// The fit settings of the built-in shapes (σ about their half thickness).
fn plan(shape: Shape) -> FitPlan {
    FitPlan {
        sigma: match shape {
            Shape::Cup => 3.0,
            Shape::Toy => 2.0,
        },
        time_steps: 20,
        kinetic_weight: 0.005,
        affine_iterations: 300,
        boundary_iterations: 1000,
        dice_iterations: 150,
    }
}

/// The comment of a case's `fit.toml` ([`paper_config`]).
const PAPER_SCHEDULE_NOTE: &str = "# As in the paper: one SSD AL iteration (mu = 20) towards \
the affine initialisation, then the\n# Dice attachment with mu rising tenfold per AL iteration. \
The constraints are in relative units\n# (mu = 0.02 ... 2000: on cmrep's t001 about the \
paper's 0.001 ... 100 in mm²).\n";

/// The comment of a case's `fit_boundary.toml` ([`boundary_config`]).
const BOUNDARY_SSD_NOTE: &str = "# SSD fit of the template's boundary points to the warped \
ones (known correspondence), with\n# the medial constraints on in relative units, mu = 20, 200, \
2000, 20000.\n";

/// A case's `fit.toml`: the paper's schedule ([`FitPlan::paper_schedule`]) from the case's
/// files: SSD towards `affine.txt`, then Dice against `target.nii.gz`.
fn paper_config(plan: &FitPlan) -> Config {
    Config::of_spec(
        &plan.paper_schedule(),
        "template.vtk".into(),
        vec![
            Source::Transform("affine.txt".into()),
            Source::Image("target.nii.gz".into(), None),
        ],
    )
}

/// A case's `fit_boundary.toml`: SSD to `target_boundary.vtk` ([`FitPlan::boundary_ssd`]).
fn boundary_config(plan: &FitPlan) -> Config {
    Config::of_spec(
        &plan.boundary_ssd(),
        "template.vtk".into(),
        vec![Source::Target("target_boundary.vtk".into())],
    )
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

/// Writes the case of a built-in shape or, with `--from`, of a template.
pub fn run(args: &SynthArgs) -> Result<(), CliError> {
    match (&args.shape, &args.from) {
        (_, Some(template)) => from_template::run(args, template),
        (Some(shape), None) => run_shape(args, *shape),
        (None, None) => unreachable!("clap requires a shape or --from"),
    }
}

/// Builds the case of a built-in shape and writes `template.vtk`, `target.nii.gz`,
/// `target_boundary.vtk`, `affine.txt` and `fit.toml` into the folder; prints a summary.
fn run_shape(args: &SynthArgs, shape: Shape) -> Result<(), CliError> {
    let spacing = args.spacing.unwrap_or_else(|| shape.image_spacing_mm());
    let case = SyntheticCase::build(shape)?;
    let image = target_image(&case.target_surface()?, spacing, args.margin)?;
    let name = shape.name();
    let header = format!(
        "# Synthetic case '{name}', written by `medial synth {name}`.
# target.nii.gz is template.vtk carried by a known twist + bend + affine map and rasterized;
# target_boundary.vtk is the same map applied to the template's boundary points (an SSD target
# with known correspondence); affine.txt is the affine part of the map.
# sigma is small against the wall (half thickness 2–4 mm) so that the flow can move medial and
# boundary points apart, as the constraints need.
"
    );
    CaseFiles {
        template: case.template(),
        target_boundary: &case.target_boundary()?,
        image: &image,
        affine: case.warp.affine(),
        configs: &[(
            "fit.toml",
            paper_config(&plan(shape)).to_toml(&format!("{header}{PAPER_SCHEDULE_NOTE}"))?,
        )],
    }
    .write(&args.out)?;
    print_json(&SynthSummary {
        case: name,
        out: args.out.clone(),
        template: TemplateSummary::of(case.template()),
        projection_max_displacement_mm: case.projection.max_displacement,
        inflated_max_spoke_normal_deg: case.projection.before.max_spoke_normal_deg,
        image_dims: image.dims(),
        image_spacing_mm: spacing,
        target_volume_mm3: image.integral(),
    })
}

/// The target segmentation of a case ([`synth::target_image`]): `surface` rasterized on a grid
/// of `spacing_mm` with `margin_mm` around it; refused past the memory limit.
fn target_image(surface: &TriMesh, spacing_mm: f64, margin_mm: f64) -> Result<Volume, CliError> {
    let (dims, _) = grid_around(surface, spacing_mm, margin_mm)?;
    memory::check_grid(dims)?;
    Ok(synth::target_image(surface, spacing_mm, margin_mm)?)
}

/// The files of a synthetic case, as `medial synth` writes them.
pub struct CaseFiles<'a> {
    /// Written as `template.vtk` (cmrep template, ASCII).
    pub template: &'a MedialTemplate,
    /// Written as `target_boundary.vtk`: the warped boundary, point for point.
    pub target_boundary: &'a TriMesh,
    /// Written as `target.nii.gz` (unsigned 8-bit): the rasterized target.
    pub image: &'a Volume,
    /// Written as `affine.txt`: the affine part of the warp (world 4×4 matrix).
    pub affine: Matrix4<f64>,
    /// Configs `(file name, TOML text)`.
    pub configs: &'a [(&'a str, String)],
}

impl CaseFiles<'_> {
    /// Creates `dir` if needed and writes every file into it, each atomically (files of the
    /// same names are replaced).
    pub fn write(&self, dir: &Path) -> Result<(), CliError> {
        std::fs::create_dir_all(dir).map_err(|e| CliError::io(dir, e))?;
        let out = |name: &str| dir.join(name);
        medial_io::cmrep::write_template(
            &out("template.vtk"),
            self.template,
            write_options(false),
        )?;
        write_nifti(&out("target.nii.gz"), self.image, NiftiType::U8)?;
        vtk::write_polydata(
            &out("target_boundary.vtk"),
            &PolyData::from_trimesh(self.target_boundary),
            write_options(false),
        )?;
        medial_io::affine::write_affine(&out("affine.txt"), &self.affine)?;
        for (name, text) in self.configs {
            write_text(&out(name), text)?;
        }
        Ok(())
    }
}
