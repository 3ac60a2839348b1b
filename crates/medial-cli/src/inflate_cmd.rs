//! `medial inflate`: a cmrep medial template from a medial sheet mesh with a radius per vertex
//! (SPEC §9), optionally Loop-subdivided first. Prints a JSON summary of the template.

use crate::error::CliError;
use medial_core::build::inflate::{inflate, MedialSheet};
use medial_core::mesh::topology::signed_volume;
use medial_core::model::metrics::SpokeMetrics;
use medial_core::model::template::{MedialTemplate, MAX_SPOKES};
use medial_io::vtk::{self, Encoding, WriteOptions};
use serde::Serialize;
use std::io::Write as _;
use std::path::{Path, PathBuf};

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
    template: TemplateSummary,
}

/// The structure and medial figures of a template, as the template commands print them.
#[derive(Clone, Debug, Serialize)]
pub struct TemplateSummary {
    /// Boundary points `nb`.
    pub boundary_points: usize,
    /// Boundary triangles.
    pub boundary_triangles: usize,
    /// Medial atoms `nm`.
    pub atoms: usize,
    /// Atoms with 1, 2 and 3 spokes (free edge, sheet, seam).
    pub atoms_by_spokes: [usize; MAX_SPOKES],
    /// Landmarks `k = nb + nm`.
    pub landmarks: usize,
    /// Volume enclosed by the boundary, mm³.
    pub volume_mm3: f64,
    /// Largest spoke–normal deviation, degrees.
    pub max_spoke_normal_deg: f64,
    /// Mean spoke–normal deviation, degrees.
    pub mean_spoke_normal_deg: f64,
    /// Largest spoke-length mismatch of an atom, %.
    pub max_spoke_mismatch_pct: f64,
}

impl TemplateSummary {
    /// The summary of `template` at its landmarks.
    pub fn of(template: &MedialTemplate) -> Self {
        let metrics = SpokeMetrics::compute(template, template.landmarks());
        let mut atoms_by_spokes = [0; MAX_SPOKES];
        for m in 0..template.medial_count() {
            atoms_by_spokes[template.spokes(m).len() - 1] += 1;
        }
        let volume_mm3 = signed_volume(template.boundary_points(), template.boundary_triangles());
        Self {
            boundary_points: template.boundary_count(),
            boundary_triangles: template.boundary_triangles().len(),
            atoms: template.medial_count(),
            atoms_by_spokes,
            landmarks: template.landmark_count(),
            volume_mm3,
            max_spoke_normal_deg: metrics.max_spoke_normal_deg,
            mean_spoke_normal_deg: metrics.mean_spoke_normal_deg,
            max_spoke_mismatch_pct: 100.0 * metrics.max_spoke_mismatch,
        }
    }
}

/// A medial sheet from VTK polydata: its points, its triangles and the radius array `name`.
fn read_sheet(path: &Path, name: &str) -> Result<MedialSheet, CliError> {
    let data = vtk::read_polydata(path)?;
    let triangles = data
        .triangles()
        .map_err(|m| medial_io::Error::format(path, m))?;
    let radius = data.point_array_ci(name).ok_or_else(|| {
        let names: Vec<&str> = data.point_data.iter().map(|a| a.name.as_str()).collect();
        medial_io::Error::format(
            path,
            format!(
                "no point array '{name}' (the radius of each medial point, mm); the file has: \
                 [{}]; choose one with --radius-array",
                names.join(", ")
            ),
        )
    })?;
    if radius.components != 1 {
        return Err(medial_io::Error::format(
            path,
            format!(
                "point array '{}' has {} components; a radius has 1",
                radius.name, radius.components
            ),
        )
        .into());
    }
    MedialSheet::new(data.points.clone(), triangles, radius.values.clone())
        .map_err(|e| model_error(path, e))
}

/// An engine error about the contents of `path`.
pub fn model_error(path: &Path, e: medial_core::Error) -> CliError {
    medial_io::Error::model(path, e).into()
}

/// ASCII or binary legacy VTK.
pub fn write_options(binary: bool) -> WriteOptions {
    WriteOptions {
        encoding: if binary {
            Encoding::Binary
        } else {
            Encoding::Ascii
        },
        ..WriteOptions::default()
    }
}

/// Prints `value` as pretty JSON on stdout. A closed pipe (`medial … | head`) is not an error;
/// any other write failure is.
pub fn print_json(value: &impl Serialize) -> Result<(), CliError> {
    let text = serde_json::to_string_pretty(value).expect("summaries serialise");
    match writeln!(std::io::stdout(), "{text}") {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(CliError::io(Path::new("<stdout>"), e))
        }
        _ => Ok(()),
    }
}
