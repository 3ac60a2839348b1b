//! Midpoint subdivision of triangle meshes.
//!
//! Every triangle `(a, b, c)` becomes `(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)`,
//! with one new vertex per edge at its midpoint. The new vertices are numbered after the old
//! ones in the order their edges are first met (triangle by triangle, edges `ab`, `bc`, `ca`),
//! so the result is deterministic. Orientation, closedness and the surface itself are kept.

use std::collections::HashMap;

use crate::{Result, TriMesh, Vec3};

/// One level of midpoint subdivision of `triangles` over `vertices`: appends the vertex of
/// every edge `(a, b)`, `midpoint(&vertices[a], &vertices[b])` (with `a`, `b` in the order of
/// the first triangle that has the edge), to `vertices` and returns the finer triangles (see
/// the module documentation). `vertices` may be points, or anything that can be halved, such
/// as the weights of each vertex on the vertices of a coarser mesh.
///
/// # Panics
/// If a triangle index is out of range of `vertices`.
pub fn subdivide_with<T>(
    vertices: &mut Vec<T>,
    triangles: &[[usize; 3]],
    mut midpoint: impl FnMut(&T, &T) -> T,
) -> Vec<[usize; 3]> {
    let mut midpoints: HashMap<(usize, usize), usize> = HashMap::new();
    let mut mid = |a: usize, b: usize, vertices: &mut Vec<T>| {
        *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
            let m = midpoint(&vertices[a], &vertices[b]);
            vertices.push(m);
            vertices.len() - 1
        })
    };
    let mut finer = Vec::with_capacity(4 * triangles.len());
    for &[a, b, c] in triangles {
        let ab = mid(a, b, vertices);
        let bc = mid(b, c, vertices);
        let ca = mid(c, a, vertices);
        finer.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    finer
}

/// One level of midpoint subdivision of `mesh`, new points at `(p_a + p_b) / 2`.
///
/// Errors: none for a valid mesh (the result is checked as [`TriMesh::new`] does).
pub fn midpoint_subdivide(mesh: &TriMesh) -> Result<TriMesh> {
    let mut points = mesh.points().to_vec();
    let triangles = subdivide_with(&mut points, mesh.triangles(), |a: &Vec3, b: &Vec3| {
        (a + b) / 2.0
    });
    TriMesh::new(points, triangles)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::topology::{check_closed_oriented_manifold, signed_volume};
    use crate::testing::meshes::octahedron;

    /// A vertex as weights on the vertices of the coarsest mesh.
    type Weights = Vec<(usize, f64)>;

    fn halved(a: &Weights, b: &Weights) -> Weights {
        a.iter().chain(b).map(|&(i, w)| (i, 0.5 * w)).collect()
    }

    #[test]
    fn weights_reproduce_the_subdivided_points() {
        let (points, triangles) = octahedron();
        let mut mesh = TriMesh::new(points.clone(), triangles.clone()).unwrap();
        let mut weights: Vec<Weights> = (0..points.len()).map(|i| vec![(i, 1.0)]).collect();
        let mut tris = triangles;
        for level in 1..=2 {
            mesh = midpoint_subdivide(&mesh).unwrap();
            tris = subdivide_with(&mut weights, &tris, halved);
            assert_eq!(mesh.triangles(), tris.as_slice());
            assert_eq!(mesh.points().len(), weights.len());
            for (p, w) in mesh.points().iter().zip(&weights) {
                let combined: Vec3 = w.iter().map(|&(i, w)| w * points[i]).sum();
                approx::assert_relative_eq!(*p, combined, epsilon = 1e-14);
                approx::assert_relative_eq!(w.iter().map(|t| t.1).sum::<f64>(), 1.0);
            }
            // Octahedron: 6 + 12 points, then 18 + 48; every face split in four.
            assert_eq!(
                (mesh.points().len(), mesh.triangles().len()),
                [(18, 32), (66, 128)][level - 1]
            );
            check_closed_oriented_manifold(&mesh).expect("still closed and oriented");
        }
        // The surface is kept: the flat faces do not move, so neither does the volume.
        approx::assert_relative_eq!(
            signed_volume(mesh.points(), mesh.triangles()),
            4.0 / 3.0,
            epsilon = 1e-14
        );
    }

    #[test]
    fn shared_edges_get_one_midpoint_numbered_in_order() {
        let mut v: Vec<Vec3> = vec![Vec3::zeros(), Vec3::x(), Vec3::y(), Vec3::z()];
        let t = subdivide_with(&mut v, &[[0, 1, 2], [0, 2, 3]], |a, b| (a + b) / 2.0);
        // Edges met: 01, 12, 20, then 23, 30 (20 again: shared).
        assert_eq!(v.len(), 4 + 5);
        assert_eq!(
            v[4..],
            [
                Vec3::x() / 2.0,
                (Vec3::x() + Vec3::y()) / 2.0,
                Vec3::y() / 2.0,
                (Vec3::y() + Vec3::z()) / 2.0,
                Vec3::z() / 2.0
            ]
        );
        assert_eq!(t[..4], [[0, 4, 6], [4, 1, 5], [6, 5, 2], [4, 5, 6]]);
        assert_eq!(t.iter().flatten().filter(|&&i| i == 6).count(), 6);
    }
}
