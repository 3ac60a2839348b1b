//! `medial inflate`: a cmrep medial template from a medial sheet mesh with a radius per vertex
//! (docs/method.md §9.1), optionally Loop-subdivided first. Prints a JSON summary of the template and of
//! where inflation lowered a radius too large for the sheet (`radius_limit`).

use crate::error::CliError;
use crate::output::{model_error, print_json, write_options, TemplateSummary};
use medial_core::construction::inflate::{inflate, RadiusLimit};
use medial_core::model::template::MedialTemplate;
use medial_io::sheet::read_sheet;
use serde::Serialize;
use std::path::PathBuf;

/// Most Loop subdivisions accepted (each multiplies the triangle count by 4).
const MAX_SUBDIVISIONS: usize = 5;

/// Inflate a medial sheet into a boundary medial template.
#[derive(clap::Args, Debug)]
pub struct InflateArgs {
    /// The medial sheet: legacy VTK polydata, a triangle mesh of medial points (mm), possibly
    /// non-manifold (an edge in three triangles is a seam), with a point array of radii (mm).
    #[arg(value_name = "SHEET.vtk")]
    pub sheet: PathBuf,
    /// The template to write: a cmrep boundary template (legacy VTK polydata with
    /// MedialIndex, Radius (mm), Normals, MedialPoint (mm) and Tangency point arrays).
    #[arg(long, value_name = "TEMPLATE.vtk")]
    pub out: PathBuf,
    /// Loop subdivisions of the sheet before inflation, 0 to 5 (free edges and seams are kept
    /// as creases; each level multiplies the triangles by 4).
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub subdivide: usize,
    /// Name of the sheet's radius point array (mm), matched ignoring case.
    #[arg(long, value_name = "NAME", default_value = "Radius")]
    pub radius_array: String,
    /// Write binary legacy VTK instead of ASCII.
    #[arg(long)]
    pub binary: bool,
}

/// Reads the sheet, subdivides, inflates, writes the template and prints its summary.
pub fn run(args: &InflateArgs) -> Result<(), CliError> {
    if args.subdivide > MAX_SUBDIVISIONS {
        return Err(CliError::Input(format!(
            "--subdivide {} is too many: at most {MAX_SUBDIVISIONS} (each level multiplies the \
             triangles by 4)",
            args.subdivide
        )));
    }
    let coarse = read_sheet(&args.sheet, &args.radius_array)?;
    let mut sheet = coarse.clone();
    for _ in 0..args.subdivide {
        sheet = sheet
            .loop_subdivide()
            .map_err(|e| model_error(&args.sheet, e))?;
    }
    let inflated = inflate(&sheet).map_err(|e| model_error(&args.sheet, e))?;
    let radius_limit = LimitSummary::of(&inflated.limit);
    let template = MedialTemplate::new(
        inflated.boundary,
        inflated.medial_index,
        inflated.medial_points,
    )
    .map_err(|e| model_error(&args.sheet, e))?;
    medial_io::cmrep::write_template(&args.out, &template, write_options(args.binary))?;
    let summary = InflateSummary {
        sheet_points: coarse.points().len(),
        sheet_triangles: coarse.triangles().len(),
        subdivisions: args.subdivide,
        radius_limit,
        template: TemplateSummary::of(&template),
    };
    print_json(&summary)
}

/// What `medial inflate` prints.
#[derive(Serialize)]
struct InflateSummary {
    sheet_points: usize,
    sheet_triangles: usize,
    subdivisions: usize,
    radius_limit: LimitSummary,
    template: TemplateSummary,
}

/// Where inflation lowered the (subdivided) sheet's radius, because it was too large for the
/// curvature of the sheet or for the angle between the sheets at a seam.
#[derive(Serialize)]
struct LimitSummary {
    /// How many medial vertices (of the subdivided sheet, the template's atoms) were lowered.
    vertices_lowered: usize,
    /// How many of them the focal bound (or a shrink after a self-intersection) bound; the others were
    /// lowered by the taper that keeps the radius smooth around them.
    vertices_bound: usize,
    /// The largest and the mean lowering over the lowered vertices, % of the sheet's radius.
    max_reduction_pct: f64,
    mean_reduction_pct: f64,
    /// Shrink rounds after a self-intersection (the focal bound itself takes one pass).
    shrink_rounds: usize,
    /// The lowered medial vertices (atoms), ascending, and the lowering of each (%).
    vertices: Vec<usize>,
    reduction_pct: Vec<f64>,
}

impl LimitSummary {
    fn of(limit: &RadiusLimit) -> Self {
        Self {
            vertices_lowered: limit.vertices.len(),
            vertices_bound: limit.bound.len(),
            max_reduction_pct: limit.max_pct(),
            mean_reduction_pct: limit.mean_pct(),
            shrink_rounds: limit.shrink_rounds,
            vertices: limit.vertices.clone(),
            reduction_pct: limit.reduction_pct.clone(),
        }
    }
}
