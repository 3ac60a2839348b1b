//! The structure and medial figures of a template in one record, as the template commands
//! print them.

use crate::mesh::topology::signed_volume;
use crate::model::metrics::SpokeMetrics;
use crate::model::template::{MedialTemplate, MAX_SPOKES};
use serde::Serialize;

/// The structure and medial figures of a template, as the template commands print them.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
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
