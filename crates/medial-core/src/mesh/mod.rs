//! Triangle meshes: the point type, [`TriMesh`], their bounding boxes ([`Bounds`]), midpoint
//! subdivision ([`subdivide`]), their topology ([`topology`]) and distances to them
//! ([`distance`]).

pub mod axes;
pub mod bounds;
pub mod distance;
pub mod section;
pub mod subdivide;
pub mod topology;

pub use axes::PrincipalAxes;
pub use bounds::Bounds;

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
    /// Builds a mesh, refusing non-finite points (`NonFinite`) and out-of-range or repeated
    /// corner indices (`Mesh`, see [`topology::check_corners`]).
    pub fn new(points: Vec<Vec3>, triangles: Vec<[usize; 3]>) -> Result<Self> {
        if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(Error::NonFinite(format!(
                "mesh point {i} is {:?}",
                points[i].as_slice()
            )));
        }
        topology::check_corners(points.len(), &triangles)?;
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

    /// The mesh with its points carried by the affine map `m` ([`carry_points`]), the same
    /// triangles.
    pub fn carried(&self, m: &nalgebra::Matrix4<f64>) -> Self {
        Self {
            points: carry_points(&self.points, m),
            triangles: self.triangles.clone(),
        }
    }
}

/// `points` carried by the affine map `m` (a 4×4 matrix of last row `0 0 0 1`, acting on
/// homogeneous coordinates): `A p + t`.
///
/// ```
/// use medial_core::mesh::carry_points;
/// use medial_core::Vec3;
/// let shift = nalgebra::Matrix4::new_translation(&Vec3::new(1.0, 2.0, 3.0));
/// assert_eq!(carry_points(&[Vec3::zeros()], &shift), [Vec3::new(1.0, 2.0, 3.0)]);
/// ```
pub fn carry_points(points: &[Vec3], m: &nalgebra::Matrix4<f64>) -> Vec<Vec3> {
    points
        .iter()
        .map(|p| m.transform_point(&(*p).into()).coords)
        .collect()
}

/// The centroid `c = Σ p / n` and the covariance `Σ (p − c)(p − c)ᵀ / n` of `points` (mm, mm²);
/// `points` must not be empty.
pub fn centroid_and_covariance(points: &[Vec3]) -> (Vec3, nalgebra::Matrix3<f64>) {
    let n = points.len() as f64;
    let centroid = points.iter().sum::<Vec3>() / n;
    let covariance = points
        .iter()
        .map(|p| (p - centroid) * (p - centroid).transpose())
        .sum::<nalgebra::Matrix3<f64>>()
        / n;
    (centroid, covariance)
}
