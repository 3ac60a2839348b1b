//! Medial sheets: validation on construction and Loop subdivision with creases.

use std::collections::HashMap;

use super::edges::{edge_key, Crease, Edges};
use super::geometry::{corners, is_degenerate};
use crate::{Error, Result, TriMesh, Vec3};

/// A medial sheet: a triangle mesh, possibly non-manifold (an edge in three triangles is a seam),
/// with a radius per vertex (mm).
///
/// Validated on construction: radii finite and positive, every point in a triangle, no
/// degenerate or repeated triangle, no edge in more than three triangles.
#[derive(Clone, Debug, PartialEq)]
pub struct MedialSheet {
    mesh: TriMesh,
    radius: Vec<f64>,
}

impl MedialSheet {
    /// Builds a sheet from medial points (mm), triangles and one radius per point (mm).
    ///
    /// Refuses non-finite points or radii, radii `≤ 0`, out-of-range or repeated corners,
    /// degenerate triangles (`|e₁ × e₂| ≤ 10⁻¹² · (longest edge)²`), two triangles on the same
    /// three points, edges in more than three triangles, and points used by no triangle.
    pub fn new(points: Vec<Vec3>, triangles: Vec<[usize; 3]>, radius: Vec<f64>) -> Result<Self> {
        if radius.len() != points.len() {
            return Err(Error::ShapeMismatch {
                what: "medial sheet radii (one per point)".into(),
                expected: points.len(),
                found: radius.len(),
            });
        }
        check_radii(&radius)?;
        if triangles.is_empty() {
            return Err(Error::InvalidMesh(
                "a medial sheet needs at least one triangle".into(),
            ));
        }
        let mesh = TriMesh::new(points, triangles)?;
        check_non_degenerate(&mesh)?;
        check_all_points_used(&mesh)?;
        check_distinct_triangles(mesh.triangles())?;
        Edges::new(mesh.triangles()).check_at_most_seams()?;
        Ok(Self { mesh, radius })
    }

    /// One level of Loop subdivision that keeps free edges and seams as creases.
    ///
    /// The new points are the old vertices (moved), in their order, followed by one point per
    /// edge in ascending `(a, b)`, `a < b`. Each triangle `(a, b, c)` becomes
    /// `(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)` in this order (orientation kept).
    ///
    /// - Edge point: `3/8 (a + b) + 1/8 (c + d)` on an edge in two triangles with opposite
    ///   vertices `c, d`; `1/2 (a + b)` on a crease (free edge or seam).
    /// - Vertex with no crease edge or one: Loop's rule `(1 − nβ) v + β Σ neighbours`,
    ///   `β = (5/8 − (3/8 + cos(2π/n)/4)²)/n`, over its `n` neighbours.
    /// - Vertex on one crease curve (two crease edges of the same kind):
    ///   `3/4 v + 1/8 (p + q)` with `p, q` its neighbours along the crease.
    /// - Corner (crease curves meet, or a free edge meets a seam): fixed.
    ///
    /// The radius is subdivided with the same weights (all positive, so radii stay positive).
    pub fn loop_subdivide(&self) -> Result<Self> {
        let edges = Edges::new(self.triangles());
        let n = self.points().len();
        let neighbours = edges.neighbours(n);
        let creases = edges.creases(n);
        let mut stencils: Vec<Vec<(usize, f64)>> = (0..n)
            .map(|v| vertex_stencil(v, &neighbours[v], &creases[v]))
            .collect();
        stencils.extend((0..edges.len()).map(|e| edges.edge_stencil(e, self.triangles())));
        let points = stencils.iter().map(|s| combine(s, self.points())).collect();
        let radius = stencils
            .iter()
            .map(|s| s.iter().map(|&(i, w)| w * self.radius[i]).sum())
            .collect();
        let mid = |a: usize, b: usize| n + edges.index[&edge_key(a, b)];
        let triangles = self
            .triangles()
            .iter()
            .flat_map(|&[a, b, c]| {
                let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
                [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
            })
            .collect();
        Self::new(points, triangles, radius)
    }

    /// The labels of the points after one Loop subdivision ([`Self::loop_subdivide`]), from
    /// `labels`, one per point (a sheet, `None` on a seam): a vertex keeps its own; an edge's
    /// new point takes its ends' label where they agree or one of them is `None` (an edge from
    /// a seam into a sheet), `None` otherwise (an edge along a seam).
    pub fn subdivided_labels(&self, labels: &[Option<usize>]) -> Vec<Option<usize>> {
        let edges = Edges::new(self.triangles());
        let mut subdivided = labels.to_vec();
        subdivided.extend(
            edges
                .ends
                .iter()
                .map(|&(a, b)| match (labels[a], labels[b]) {
                    (Some(k), Some(j)) if k == j => Some(k),
                    (Some(k), None) | (None, Some(k)) => Some(k),
                    _ => None,
                }),
        );
        subdivided
    }

    /// The medial points (mm).
    pub fn points(&self) -> &[Vec3] {
        self.mesh.points()
    }

    /// The triangles, as corner indices into [`Self::points`].
    pub fn triangles(&self) -> &[[usize; 3]] {
        self.mesh.triangles()
    }

    /// The points after one Loop subdivision (the atoms of the template inflated from it): a
    /// point per vertex and per edge.
    pub fn subdivided_point_count(&self) -> usize {
        self.points().len() + Edges::new(self.triangles()).len()
    }

    /// The radius of every medial point (mm).
    pub fn radius(&self) -> &[f64] {
        &self.radius
    }

    /// The edges in exactly two triangles (a seam's are in three) along which those turn
    /// against each other by more than `bound_deg` degrees, as `(angle in degrees, the edge's
    /// two points, its two triangles)`, in ascending order of the edge's points. The two
    /// triangles are compared as consistently oriented (the normal of one flipped when both
    /// run the edge the same way).
    pub fn folds(&self, bound_deg: f64) -> Vec<(f64, [usize; 2], [usize; 2])> {
        let (p, tris) = (self.points(), self.triangles());
        let normal = |t: &[usize; 3]| (p[t[1]] - p[t[0]]).cross(&(p[t[2]] - p[t[0]]));
        let edges = Edges::new(tris);
        (edges.ends.iter().zip(&edges.fans))
            .filter_map(|(&(a, b), fan)| {
                let [f, g] = fan[..] else {
                    return None;
                };
                let (m, n) = (normal(&tris[f.tri]), normal(&tris[g.tri]));
                let sign = if f.forward == g.forward { -1.0 } else { 1.0 };
                let cos = sign * m.dot(&n) / (m.norm() * n.norm());
                let angle = cos.clamp(-1.0, 1.0).acos().to_degrees();
                (angle > bound_deg).then_some((angle, [a, b], [f.tri, g.tri]))
            })
            .collect()
    }
}

pub(super) fn check_radii(radius: &[f64]) -> Result<()> {
    if let Some(m) = radius.iter().position(|r| !r.is_finite()) {
        return Err(Error::NonFinite(format!(
            "radius of medial point {m} is {}",
            radius[m]
        )));
    }
    if let Some(m) = radius.iter().position(|&r| r <= 0.0) {
        return Err(Error::InvalidTemplate(format!(
            "radius of medial point {m} is {} mm; radii must be positive",
            radius[m]
        )));
    }
    Ok(())
}

pub(super) fn check_non_degenerate(mesh: &TriMesh) -> Result<()> {
    for (t, tri) in mesh.triangles().iter().enumerate() {
        let p = corners(mesh.points(), tri);
        if is_degenerate(&p) {
            return Err(Error::InvalidMesh(format!(
                "medial triangle {t} {tri:?} is degenerate (its corners are collinear)"
            )));
        }
    }
    Ok(())
}

pub(super) fn check_all_points_used(mesh: &TriMesh) -> Result<()> {
    let mut used = vec![false; mesh.points().len()];
    mesh.triangles()
        .iter()
        .flatten()
        .for_each(|&v| used[v] = true);
    match used.iter().position(|u| !u) {
        Some(m) => Err(Error::InvalidMesh(format!(
            "medial point {m} is in no triangle"
        ))),
        None => Ok(()),
    }
}

pub(super) fn check_distinct_triangles(triangles: &[[usize; 3]]) -> Result<()> {
    let mut seen = HashMap::new();
    for (t, tri) in triangles.iter().enumerate() {
        let mut key = *tri;
        key.sort_unstable();
        if let Some(first) = seen.insert(key, t) {
            return Err(Error::InvalidMesh(format!(
                "medial triangles {first} and {t} both join points {key:?}"
            )));
        }
    }
    Ok(())
}

/// Loop's vertex stencil (see [`MedialSheet::loop_subdivide`]).
pub(super) fn vertex_stencil(
    v: usize,
    neighbours: &[usize],
    creases: &[(usize, Crease)],
) -> Vec<(usize, f64)> {
    match creases {
        [] | [_] => {
            let n = neighbours.len() as f64;
            let c = 0.375 + 0.25 * (2.0 * std::f64::consts::PI / n).cos();
            let beta = (0.625 - c * c) / n;
            std::iter::once((v, 1.0 - n * beta))
                .chain(neighbours.iter().map(|&u| (u, beta)))
                .collect()
        }
        [(p, kp), (q, kq)] if kp == kq => vec![(v, 0.75), (*p, 0.125), (*q, 0.125)],
        _ => vec![(v, 1.0)],
    }
}

pub(super) fn combine(stencil: &[(usize, f64)], points: &[Vec3]) -> Vec3 {
    stencil.iter().map(|&(i, w)| w * points[i]).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_subdivided_point_takes_its_edge_s_sheet_and_a_seam_edge_stays_on_the_seam() {
        // Two triangles of sheets 0 and 1 sharing the edge 0–1, which lies on a seam.
        let points = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.5, 1.0, 0.0),
            Vec3::new(0.5, -1.0, 0.5),
        ];
        let sheet = MedialSheet::new(points, vec![[0, 1, 2], [1, 0, 3]], vec![0.1; 4]).unwrap();
        let labels = sheet.subdivided_labels(&[None, None, Some(0), Some(1)]);
        let subdivided = sheet.loop_subdivide().unwrap();
        assert_eq!(labels.len(), subdivided.points().len());
        assert_eq!(&labels[..4], &[None, None, Some(0), Some(1)]);
        // Each edge's new point, found by where it lies: the middle of its ends, give or take
        // the Loop weights.
        let near = |p: Vec3| {
            (4..labels.len())
                .min_by(|&a, &b| {
                    let d = |i: usize| (subdivided.points()[i] - p).norm();
                    d(a).total_cmp(&d(b))
                })
                .unwrap()
        };
        assert_eq!(labels[near(Vec3::new(0.5, 0.0, 0.0))], None);
        assert_eq!(labels[near(Vec3::new(0.25, 0.5, 0.0))], Some(0));
        assert_eq!(labels[near(Vec3::new(0.75, -0.5, 0.25))], Some(1));
    }
}
