//! The template a fit deforms: a cmrep medial template (boundary + medial atoms), or a plain
//! triangle mesh / point set whose points are all landmarks. Also how a configuration of its
//! landmarks is written for ParaView.

use crate::error::CliError;
use medial_core::model::constraints::MedialConstraints;
use medial_core::model::metrics::SpokeMetrics;
use medial_core::model::template::MedialTemplate;
use medial_core::Vec3;
use medial_io::vtk::{self, ArrayKind, DataArray, PolyData, ValueType};
use std::path::Path;

/// A loaded template.
pub enum Model {
    /// A medial template: constraints and spoke metrics apply.
    Medial(Box<MedialTemplate>),
    /// A plain mesh (or point set): landmarks are its points.
    Plain {
        /// Points.
        points: Vec<Vec3>,
        /// Triangles (empty for a point set).
        triangles: Vec<[usize; 3]>,
    },
}

impl Model {
    /// Reads a VTK template: with a `MedialIndex` point array it is a cmrep medial template,
    /// otherwise a plain triangle mesh or point set.
    pub fn load(path: &Path) -> Result<Self, CliError> {
        let data = vtk::read_polydata(path)?;
        if data.point_array_ci("MedialIndex").is_some() {
            let template = medial_io::cmrep::template_from_polydata(&data, path)?;
            return Ok(Model::Medial(Box::new(template)));
        }
        let triangles = data
            .triangles()
            .map_err(|m| medial_io::Error::format(path, m))?;
        let mesh = medial_core::TriMesh::new(data.points, triangles)
            .map_err(|e| medial_io::Error::model(path, e))?;
        if mesh.points().is_empty() {
            return Err(CliError::Input(format!(
                "{}: the template has no points",
                path.display()
            )));
        }
        let (points, triangles) = mesh.into_parts();
        Ok(Model::Plain { points, triangles })
    }

    /// The landmarks `q^0`: boundary points, then medial points.
    pub fn landmarks(&self) -> &[Vec3] {
        match self {
            Model::Medial(t) => t.landmarks(),
            Model::Plain { points, .. } => points,
        }
    }

    /// Number of boundary points (the landmarks an SSD target covers).
    pub fn boundary_count(&self) -> usize {
        match self {
            Model::Medial(t) => t.boundary_count(),
            Model::Plain { points, .. } => points.len(),
        }
    }

    /// Number of medial atoms (0 for a plain mesh).
    pub fn medial_count(&self) -> usize {
        match self {
            Model::Medial(t) => t.medial_count(),
            Model::Plain { .. } => 0,
        }
    }

    /// The medial template, if this is one.
    pub fn medial(&self) -> Option<&MedialTemplate> {
        match self {
            Model::Medial(t) => Some(t),
            Model::Plain { .. } => None,
        }
    }

    /// The medial constraints, for a medial template.
    pub fn constraints(&self) -> Option<MedialConstraints> {
        self.medial().map(MedialConstraints::new)
    }

    /// Spoke metrics at landmarks `q`, for a medial template.
    pub fn metrics(&self, q: &[Vec3]) -> Option<SpokeMetrics> {
        self.medial().map(|t| SpokeMetrics::compute(t, q))
    }

    /// The boundary at landmarks `q`, with `SpokeNormalAngle` (degrees), `SpokeMismatch` (%),
    /// `Radius` (spoke length) and `MedialIndex` for a medial template.
    pub fn boundary_polydata(&self, q: &[Vec3]) -> PolyData {
        let nb = self.boundary_count();
        let mut data = PolyData {
            points: q[..nb].to_vec(),
            ..PolyData::default()
        };
        match self {
            Model::Plain { triangles, .. } if triangles.is_empty() => {
                data.vertices = (0..nb).map(|i| vec![i]).collect();
            }
            Model::Plain { triangles, .. } => data.polygons = cells(triangles),
            Model::Medial(t) => {
                data.polygons = cells(t.boundary_triangles());
                let m = SpokeMetrics::compute(t, q);
                let atom = t.medial_index();
                data.point_data = vec![
                    scalars(
                        "SpokeNormalAngle",
                        m.spoke_normal_deg.clone(),
                        ValueType::Double,
                    ),
                    scalars(
                        "SpokeMismatch",
                        atom.iter().map(|&a| 100.0 * m.mismatch[a]).collect(),
                        ValueType::Double,
                    ),
                    scalars("Radius", m.spoke_length.clone(), ValueType::Double),
                    scalars(
                        "MedialIndex",
                        atom.iter().map(|&a| a as f64).collect(),
                        ValueType::Int,
                    ),
                ];
            }
        }
        data
    }

    /// The medial triangle mesh at landmarks `q` with `Thickness` (2 × mean spoke length) and
    /// `SpokeMismatch` (%), for a medial template.
    pub fn medial_polydata(&self, q: &[Vec3]) -> Option<PolyData> {
        let t = self.medial()?;
        let m = SpokeMetrics::compute(t, q);
        let nb = t.boundary_count();
        Some(PolyData {
            points: q[nb..].to_vec(),
            polygons: cells(t.medial_triangles()),
            point_data: vec![
                scalars("Thickness", m.thickness, ValueType::Double),
                scalars(
                    "SpokeMismatch",
                    m.mismatch.iter().map(|x| 100.0 * x).collect(),
                    ValueType::Double,
                ),
            ],
            ..PolyData::default()
        })
    }
}

fn cells(triangles: &[[usize; 3]]) -> Vec<Vec<usize>> {
    triangles.iter().map(|t| t.to_vec()).collect()
}

fn scalars(name: &str, values: Vec<f64>, value_type: ValueType) -> DataArray {
    DataArray {
        name: name.into(),
        components: 1,
        values,
        kind: ArrayKind::Scalars,
        value_type,
    }
}
