//! Triangle meshes: the point type, [`TriMesh`], and their topology ([`topology`]).

pub mod topology;

use crate::{Error, Result};

/// A point or vector in R³ (world coordinates, usually mm).
pub type Vec3 = nalgebra::Vector3<f64>;

/// A triangle mesh: points and triangles with indices checked to be in range and distinct,
/// coordinates checked to be finite. Topology (closed, manifold, oriented) is checked by
/// [`crate::mesh::topology`] where a model needs it.
#[derive(Clone, Debug, PartialEq)]
pub struct TriMesh {
    points: Vec<Vec3>,
    triangles: Vec<[usize; 3]>,
}

impl TriMesh {
    /// Builds a mesh, refusing out-of-range or repeated corner indices and non-finite points.
    pub fn new(points: Vec<Vec3>, triangles: Vec<[usize; 3]>) -> Result<Self> {
        if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(Error::NonFinite(format!(
                "mesh point {i} is {:?}",
                points[i].as_slice()
            )));
        }
        for (t, tri) in triangles.iter().enumerate() {
            if let Some(&v) = tri.iter().find(|&&v| v >= points.len()) {
                return Err(Error::InvalidMesh(format!(
                    "triangle {t} uses point {v} but the mesh has {} points",
                    points.len()
                )));
            }
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                return Err(Error::InvalidMesh(format!(
                    "triangle {t} repeats a corner: {tri:?}"
                )));
            }
        }
        Ok(Self { points, triangles })
    }

    /// The points.
    pub fn points(&self) -> &[Vec3] {
        &self.points
    }

    /// The triangles, as corner indices into [`Self::points`].
    pub fn triangles(&self) -> &[[usize; 3]] {
        &self.triangles
    }

    /// Takes the mesh apart.
    pub fn into_parts(self) -> (Vec<Vec3>, Vec<[usize; 3]>) {
        (self.points, self.triangles)
    }
}
