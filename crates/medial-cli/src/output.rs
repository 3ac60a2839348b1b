//! What every command shares for its results: JSON on stdout and in files, the VTK encoding,
//! the summary of a template, and engine errors about a file.

use crate::error::CliError;
use medial_core::mesh::topology::signed_volume;
use medial_core::model::template::{MedialTemplate, MAX_SPOKES};
use medial_core::model::SpokeMetrics;
use medial_io::vtk::{Encoding, WriteOptions};
use serde::Serialize;
use std::io::Write as _;
use std::path::Path;

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

/// Writes `value` as pretty JSON, atomically.
pub fn write_json(path: &Path, value: &impl Serialize) -> Result<(), CliError> {
    medial_io::atomic::write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value).map_err(std::io::Error::other)?;
        writeln!(w)
    })?;
    Ok(())
}

/// Writes `text` to `path` atomically.
pub fn write_text(path: &Path, text: &str) -> Result<(), CliError> {
    Ok(medial_io::atomic::write_atomic(path, |w| {
        w.write_all(text.as_bytes())
    })?)
}
