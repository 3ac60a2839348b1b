//! What inflation refuses to return: a boundary with degenerate triangles, open, non-manifold
//! or pinched, facing inward, or intersecting itself, each said with the medial vertices near
//! the problem.

use super::geometry::{corners, is_degenerate};
use super::regions::UnionFind;
use super::LIST_MAX;
use crate::mesh::topology::{check_closed_oriented_manifold, MeshDefect};
use crate::{Error, Result, TriMesh, Vec3};

/// The sorted distinct atoms of some boundary points, as "3, 7, 12" (at most [`LIST_MAX`]).
pub(super) fn atoms_of(points: impl IntoIterator<Item = usize>, medial_index: &[usize]) -> String {
    let mut atoms: Vec<usize> = points.into_iter().map(|b| medial_index[b]).collect();
    atoms.sort_unstable();
    atoms.dedup();
    let mut list: Vec<String> = atoms.iter().take(LIST_MAX).map(usize::to_string).collect();
    if atoms.len() > LIST_MAX {
        list.push(format!("… ({} in all)", atoms.len()));
    }
    list.join(", ")
}

/// The checks before the self-intersection test: no degenerate triangle, closed, manifold,
/// outward.
pub(super) fn check_surface(mesh: &TriMesh, medial_index: &[usize]) -> Result<()> {
    check_boundary_degenerate(mesh, medial_index)?;
    check_closed_manifold(mesh, medial_index)?;
    check_outward(mesh, medial_index)
}

pub(super) fn check_boundary_degenerate(mesh: &TriMesh, medial_index: &[usize]) -> Result<()> {
    match mesh
        .triangles()
        .iter()
        .position(|tri| is_degenerate(&corners(mesh.points(), tri)))
    {
        Some(f) => Err(Error::InvalidTemplate(format!(
            "boundary triangle {f} (side {} of medial triangle {}) is degenerate, near medial \
             vertices {}",
            if f % 2 == 0 { '+' } else { '-' },
            f / 2,
            atoms_of(mesh.triangles()[f], medial_index)
        ))),
        None => Ok(()),
    }
}

/// The boundary must be a closed, consistently oriented surface whose triangles form one fan
/// around every vertex ([`check_closed_oriented_manifold`]); a defect is reported with the
/// medial vertices near it.
pub(super) fn check_closed_manifold(mesh: &TriMesh, medial_index: &[usize]) -> Result<()> {
    let edge_error = |a: usize, b: usize, triangles: &[usize]| {
        let forward = triangles
            .iter()
            .filter(|&&t| traverses(&mesh.triangles()[t], a, b))
            .count();
        Error::InvalidTemplate(format!(
            "the inflated boundary is not a closed oriented surface: its edge between boundary \
             points {a} and {b} (medial vertices {}) is in {forward} triangle(s) one way and {} \
             the other (each edge needs exactly one each way); refine the sheet there",
            atoms_of([a, b], medial_index),
            triangles.len() - forward
        ))
    };
    match check_closed_oriented_manifold(mesh) {
        Ok(_) => Ok(()),
        Err(MeshDefect::OpenEdge { a, b, triangle, .. }) => Err(edge_error(a, b, &[triangle])),
        Err(MeshDefect::InconsistentOrientation {
            a, b, triangles, ..
        }) => Err(edge_error(a, b, &triangles)),
        Err(MeshDefect::NonManifoldEdge {
            a, b, triangles, ..
        }) => Err(edge_error(a, b, &triangles)),
        Err(MeshDefect::PinchedVertex { vertex, .. }) => Err(Error::InvalidTemplate(format!(
            "boundary point {vertex} (medial vertex {}) is pinched: its triangles form more than \
             one fan",
            medial_index[vertex]
        ))),
        Err(other) => Err(other.into()),
    }
}

/// Whether triangle `tri` runs along its edge from `a` to `b`.
pub(super) fn traverses(tri: &[usize; 3], a: usize, b: usize) -> bool {
    (0..3).any(|k| tri[k] == a && tri[(k + 1) % 3] == b)
}

/// Signed volume `Σ p₀ · (p₁ × p₂) / 6` of every component (points relative to their mean).
pub(super) fn signed_volumes(mesh: &TriMesh, component: &[usize], n_components: usize) -> Vec<f64> {
    let p = mesh.points();
    let centre = p.iter().sum::<Vec3>() / p.len().max(1) as f64;
    let mut volume = vec![0.0; n_components];
    for tri in mesh.triangles() {
        let [a, b, c] = tri.map(|v| p[v] - centre);
        volume[component[tri[0]]] += a.dot(&b.cross(&c)) / 6.0;
    }
    volume
}

/// Every connected component must enclose a positive volume (outward orientation).
pub(super) fn check_outward(mesh: &TriMesh, medial_index: &[usize]) -> Result<()> {
    let mut uf = UnionFind::new(mesh.points().len());
    for tri in mesh.triangles() {
        uf.union(tri[0], tri[1]);
        uf.union(tri[0], tri[2]);
    }
    let roots: Vec<usize> = (0..mesh.points().len()).map(|v| uf.find(v)).collect();
    let mut ids: Vec<usize> = roots.clone();
    ids.sort_unstable();
    ids.dedup();
    let component: Vec<usize> = roots
        .iter()
        .map(|r| ids.binary_search(r).unwrap_or(0))
        .collect();
    let volume = signed_volumes(mesh, &component, ids.len());
    match volume.iter().position(|&v| v <= 0.0) {
        Some(c) => {
            Err(Error::InvalidTemplate(format!(
            "a part of the inflated boundary encloses a volume of {:.6} mm³ (it faces inward), \
             around medial vertices {}",
            volume[c],
            atoms_of((0..component.len()).filter(|&v| component[v] == c), medial_index)
        )))
        }
        None => Ok(()),
    }
}

/// The error for a boundary whose triangle pairs `pairs` (non-empty) intersect, after the
/// radius was lowered at `lowered` medial vertices by up to `max_pct` %.
pub(super) fn intersection_error(
    mesh: &TriMesh,
    medial_index: &[usize],
    pairs: &[(usize, usize)],
    lowered: usize,
    max_pct: f64,
) -> Error {
    let tri = |f: usize| mesh.triangles()[f];
    let points = pairs
        .iter()
        .flat_map(|&(f, g)| tri(f).into_iter().chain(tri(g)));
    let (f, g) = pairs.first().copied().unwrap_or_default();
    Error::InvalidTemplate(format!(
        "the inflated boundary intersects itself ({} pairs of triangles, e.g. boundary triangles \
         {f} and {g}) after lowering the radius at {lowered} medial vertices by up to \
         {max_pct:.0} %: radius too large for the curvature near medial vertices {} (or for \
         the angle between the sheets there, at a seam); lower the radius or refine the sheet",
        pairs.len(),
        atoms_of(points, medial_index)
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetrahedron(inward: bool) -> TriMesh {
        let p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
        ];
        let mut t = vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];
        if inward {
            t.iter_mut().for_each(|t| t.swap(1, 2));
        }
        TriMesh::new(p, t).unwrap()
    }

    #[test]
    fn boundary_checks() {
        let index = [0, 1, 2, 3];
        assert!(check_surface(&tetrahedron(false), &index).is_ok());
        let e = check_surface(&tetrahedron(true), &index)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("faces inward") && e.contains("medial vertices 0, 1, 2, 3"),
            "{e}"
        );
        let (p, mut t) = tetrahedron(false).into_parts();
        t.pop();
        let e = check_surface(&TriMesh::new(p.clone(), t).unwrap(), &index)
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a closed oriented surface"), "{e}");
        // Two tetrahedra glued at one vertex: closed edges, pinched vertex.
        let mut p2 = p.clone();
        p2.extend([
            Vec3::new(-1.0, 0.0, 0.0),
            Vec3::new(0.0, -1.0, 0.0),
            Vec3::new(0.0, 0.0, -1.0),
        ]);
        let mut t2 = tetrahedron(false).into_parts().1;
        t2.extend([[0, 4, 5], [0, 6, 4], [4, 6, 5], [0, 5, 6]]);
        let e = check_surface(&TriMesh::new(p2, t2).unwrap(), &[0, 1, 2, 3, 4, 5, 6])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("boundary point 0 (medial vertex 0) is pinched"),
            "{e}"
        );
    }
}
