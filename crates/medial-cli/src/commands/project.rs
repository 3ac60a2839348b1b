//! `medial project`: moves the landmarks of a template as little as possible (least squares)
//! so that its medial constraints hold. Prints the figures before and after as JSON.

use crate::error::CliError;
use crate::output::{model_error, print_json, write_options, TemplateSummary};
use medial_core::construction::project::{project, ConstraintFigures, ProjectOptions};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

/// Project a template onto its medial constraints.
#[derive(clap::Args, Debug)]
pub struct ProjectArgs {
    /// The template: a cmrep boundary template (legacy VTK polydata with a MedialIndex array),
    /// coordinates in mm.
    #[arg(value_name = "TEMPLATE.vtk")]
    pub template: PathBuf,
    /// The projected template to write (cmrep format, same points and triangles, moved).
    #[arg(long, value_name = "FIXED.vtk")]
    pub out: PathBuf,
    /// Largest spoke–normal deviation the result may have, degrees; the command fails if it
    /// is not reached.
    #[arg(long, value_name = "DEG", default_value_t = 0.1)]
    pub max_angle: f64,
    /// Largest spoke-length mismatch `(max − min)/mean` of an atom the result may have, in
    /// percent; the command fails if it is not reached.
    #[arg(long, value_name = "PERCENT", default_value_t = 0.1)]
    pub max_mismatch: f64,
    /// Most Gauss–Newton iterations.
    #[arg(long, value_name = "N", default_value_t = 50)]
    pub max_iterations: usize,
    /// Write binary legacy VTK instead of ASCII.
    #[arg(long)]
    pub binary: bool,
}

/// What `medial project` prints.
#[derive(Serialize)]
struct ProjectSummary {
    iterations: usize,
    seconds: f64,
    /// Largest landmark move, mm.
    max_displacement_mm: f64,
    /// Root-mean-square landmark move, mm.
    rms_displacement_mm: f64,
    /// The spokes were turned onto the boundary before the Gauss–Newton steps (the nearest
    /// medial configuration was out of its reach): the move is not the smallest.
    turned_spokes: bool,
    before: Figures,
    after: Figures,
    template: TemplateSummary,
}

/// [`ConstraintFigures`] with the mismatch in %.
#[derive(Serialize)]
struct Figures {
    max_spoke_normal_deg: f64,
    mean_spoke_normal_deg: f64,
    max_spoke_mismatch_pct: f64,
    /// `max |C|`, mm².
    max_abs_constraint: f64,
}

impl From<ConstraintFigures> for Figures {
    fn from(f: ConstraintFigures) -> Self {
        Self {
            max_spoke_normal_deg: f.max_spoke_normal_deg,
            mean_spoke_normal_deg: f.mean_spoke_normal_deg,
            max_spoke_mismatch_pct: 100.0 * f.max_mismatch,
            max_abs_constraint: f.max_abs_constraint,
        }
    }
}

/// Reads the template, projects it, writes the result and prints the figures.
pub fn run(args: &ProjectArgs) -> Result<(), CliError> {
    let options = ProjectOptions {
        max_spoke_normal_deg: args.max_angle,
        max_mismatch: args.max_mismatch / 100.0,
        max_iterations: args.max_iterations,
    };
    let template = medial_io::cmrep::read_template(&args.template)?;
    let start = Instant::now();
    let projection = project(&template, &options).map_err(|e| model_error(&args.template, e))?;
    let seconds = start.elapsed().as_secs_f64();
    medial_io::cmrep::write_template(&args.out, &projection.template, write_options(args.binary))?;
    print_json(&ProjectSummary {
        iterations: projection.iterations,
        seconds,
        max_displacement_mm: projection.max_displacement,
        rms_displacement_mm: projection.rms_displacement,
        turned_spokes: projection.turned_spokes,
        before: projection.before.into(),
        after: projection.after.into(),
        template: TemplateSummary::of(&projection.template),
    })
}
