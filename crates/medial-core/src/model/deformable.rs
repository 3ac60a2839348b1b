//! What a fit deforms: a medial template, whose landmarks are its boundary points then its
//! medial points and on which the medial constraints and spoke metrics apply, or a plain
//! triangle mesh or point set, whose points are all landmarks.

use crate::mesh::TriMesh;
use crate::model::{MedialTemplate, SpokeMetrics};
use crate::Vec3;

/// The landmark model of a fit.
#[derive(Clone, Debug)]
pub enum Model {
    /// A cmrep medial template.
    Medial(Box<MedialTemplate>),
    /// A plain triangle mesh, or a point set (no triangles): no medial constraints.
    Plain(TriMesh),
}

impl Model {
    /// The landmarks `q^0`: for a medial template the boundary points, then the medial points.
    pub fn landmarks(&self) -> &[Vec3] {
        match self {
            Model::Medial(t) => t.landmarks(),
            Model::Plain(mesh) => mesh.points(),
        }
    }

    /// Number of boundary points: the landmarks an SSD target covers (all of a plain mesh).
    pub fn boundary_count(&self) -> usize {
        match self {
            Model::Medial(t) => t.boundary_count(),
            Model::Plain(mesh) => mesh.points().len(),
        }
    }

    /// The triangles of the boundary (empty for a point set).
    pub fn boundary_triangles(&self) -> &[[usize; 3]] {
        match self {
            Model::Medial(t) => t.boundary_triangles(),
            Model::Plain(mesh) => mesh.triangles(),
        }
    }

    /// Number of medial atoms (0 for a plain mesh).
    pub fn medial_count(&self) -> usize {
        self.medial().map_or(0, MedialTemplate::medial_count)
    }

    /// The medial template, if this is one.
    pub fn medial(&self) -> Option<&MedialTemplate> {
        match self {
            Model::Medial(t) => Some(t),
            Model::Plain(_) => None,
        }
    }

    /// Spoke metrics at the landmarks `q`, for a medial template.
    pub fn metrics(&self, q: &[Vec3]) -> Option<SpokeMetrics> {
        self.medial().map(|t| SpokeMetrics::compute(t, q))
    }
}
