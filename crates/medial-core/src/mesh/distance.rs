//! Distances from points to a triangle surface: exact point–triangle distances through the
//! bounding-volume hierarchy of a `parry3d` triangle mesh.

use super::{TriMesh, Vec3};
use crate::{Error, Result};
use parry3d_f64::query::PointQuery;
use parry3d_f64::shape::TriMesh as ParryMesh;
use rayon::prelude::*;

/// A triangle surface prepared for distance queries.
pub struct SurfaceDistance {
    mesh: ParryMesh,
    /// The surface as given.
    surface: TriMesh,
}

impl SurfaceDistance {
    /// Prepares `surface` (any triangles: open, non-manifold or unoriented). Refuses a mesh
    /// without triangles (`InvalidMesh`).
    pub fn new(surface: &TriMesh) -> Result<Self> {
        let vertices = surface.points().iter().map(|&p| p.into()).collect();
        let triangles = surface
            .triangles()
            .iter()
            .map(|t| t.map(|i| i as u32))
            .collect();
        let mesh = ParryMesh::new(vertices, triangles)
            .map_err(|e| Error::InvalidMesh(format!("distance to a surface: {e}")))?;
        Ok(Self {
            mesh,
            surface: surface.clone(),
        })
    }

    /// The surface the distances are to.
    pub fn surface(&self) -> &TriMesh {
        &self.surface
    }

    /// `d(x, S)`: the distance (mm) from `x` to the nearest point of the surface.
    pub fn distance(&self, x: &Vec3) -> f64 {
        self.mesh.distance_to_local_point(&(*x).into(), true)
    }

    /// `Σ_i d(x_i, S) / n` over `points` (mm; NaN for none), the same bits for any number of
    /// threads (the distances are summed in order).
    pub fn mean_distance(&self, points: &[Vec3]) -> f64 {
        let distances: Vec<f64> = points.par_iter().map(|x| self.distance(x)).collect();
        distances.iter().sum::<f64>() / points.len() as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// The unit square z = 0 as two triangles.
    fn square() -> TriMesh {
        let points = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        TriMesh::new(points, vec![[0, 1, 2], [0, 2, 3]]).unwrap()
    }

    #[test]
    fn distances_to_a_square_are_exact() {
        let s = SurfaceDistance::new(&square()).unwrap();
        // Above the face, beyond an edge, beyond a corner.
        assert_relative_eq!(s.distance(&Vec3::new(0.3, 0.6, 2.0)), 2.0, epsilon = 1e-12);
        assert_relative_eq!(s.distance(&Vec3::new(1.5, 0.5, 0.0)), 0.5, epsilon = 1e-12);
        let corner = s.distance(&Vec3::new(-3.0, -4.0, 0.0));
        assert_relative_eq!(corner, 5.0, epsilon = 1e-12);
        let mean = s.mean_distance(&[Vec3::new(0.5, 0.5, 1.0), Vec3::new(0.5, 0.5, -3.0)]);
        assert_relative_eq!(mean, 2.0, epsilon = 1e-12);
    }

    #[test]
    fn a_mesh_without_triangles_is_refused() {
        let empty = TriMesh::new(vec![Vec3::zeros()], vec![]).unwrap();
        assert!(SurfaceDistance::new(&empty).is_err());
    }
}
