//! The intersection of a triangle mesh with a plane, as polylines (the curves a slice view draws
//! over an image).
//!
//! Each corner is classed by its signed distance `d = n · (p − o)` to the plane: on the positive
//! side where `d ≥ 0`, else on the negative side. An edge whose corners are on different sides
//! crosses the plane at `a + d_a / (d_a − d_b) (b − a)`, exactly at `a` where `d_a = 0`; a
//! triangle with two crossing edges contributes the segment between their crossings. Crossings
//! are shared by the triangles of an edge (and a corner on the plane by all its triangles), so
//! the segments join into polylines, closed where the section of a closed surface is a loop.
//! A triangle lying in the plane gives nothing.

use super::{TriMesh, Vec3};
use std::collections::HashMap;

/// A plane `n · (p − o) = 0`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    /// A point of the plane.
    pub point: Vec3,
    /// Its normal (any length but 0).
    pub normal: Vec3,
}

impl Plane {
    /// The plane through `point` normal to world axis `axis` (0 x, 1 y, 2 z).
    ///
    /// # Panics
    /// When `axis > 2`.
    pub fn axis(axis: usize, point: Vec3) -> Self {
        Self {
            point,
            normal: Vec3::ith(axis, 1.0),
        }
    }

    /// The signed distance of `p` from the plane in units of `|n|`: `n · (p − o)`.
    pub fn side(&self, p: &Vec3) -> f64 {
        self.normal.dot(&(p - self.point))
    }
}

/// Where an edge crosses the plane: a corner on it (`(i, i)`), or an edge `(i, j)`, `i < j`.
type Crossing = (usize, usize);

/// The section of `mesh` by `plane`: polylines of points on the plane, each a chain of the
/// segments of consecutive triangles; a closed loop repeats its first point at its end. A
/// branch point (a seam of three sheets) ends chains. Empty where the plane misses the mesh.
///
/// ```
/// use medial_core::mesh::section::{section, Plane};
/// use medial_core::{TriMesh, Vec3};
/// // A triangle cut by x = 1: from (1, 0, 0) to (1, 1, 0).
/// let mesh = TriMesh::new(
///     vec![Vec3::zeros(), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0)],
///     vec![[0, 1, 2]],
/// )
/// .unwrap();
/// let lines = section(&mesh, &Plane::axis(0, Vec3::new(1.0, 0.0, 0.0)));
/// assert_eq!(lines, [vec![Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.0)]]);
/// ```
pub fn section(mesh: &TriMesh, plane: &Plane) -> Vec<Vec<Vec3>> {
    let points = mesh.points();
    let d: Vec<f64> = points.iter().map(|p| plane.side(p)).collect();
    let mut at: HashMap<Crossing, Vec3> = HashMap::new();
    let mut crossing = |a: usize, b: usize| -> Crossing {
        // Oriented from the positive corner `a` to the negative one `b`.
        if d[a] == 0.0 {
            at.entry((a, a)).or_insert(points[a]);
            return (a, a);
        }
        let key = (a.min(b), a.max(b));
        at.entry(key).or_insert_with(|| {
            let t = d[a] / (d[a] - d[b]);
            points[a] + t * (points[b] - points[a])
        });
        key
    };
    let mut segments: Vec<[Crossing; 2]> = Vec::new();
    for t in mesh.triangles() {
        let positive = t.map(|i| d[i] >= 0.0);
        let mut ends = Vec::with_capacity(2);
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            match (positive[k], positive[(k + 1) % 3]) {
                (true, false) => ends.push(crossing(a, b)),
                (false, true) => ends.push(crossing(b, a)),
                _ => {}
            }
        }
        if let [p, q] = ends[..] {
            if p != q {
                segments.push([p, q]);
            }
        }
    }
    chain(&segments)
        .into_iter()
        .map(|line| line.iter().map(|c| at[c]).collect())
        .collect()
}

/// The total length of `lines` (mm).
pub fn length(lines: &[Vec<Vec3>]) -> f64 {
    lines
        .iter()
        .flat_map(|l| l.windows(2))
        .map(|w| (w[1] - w[0]).norm())
        .sum()
}

/// Joins segments sharing an end into chains of their ends, each segment used once: chains
/// start at an end of one segment (a free end) or of three or more (a branch), then from any
/// segment left (loops, closed by repeating their start).
fn chain(segments: &[[Crossing; 2]]) -> Vec<Vec<Crossing>> {
    let mut at: HashMap<Crossing, Vec<usize>> = HashMap::new();
    for (s, ends) in segments.iter().enumerate() {
        for e in ends {
            at.entry(*e).or_default().push(s);
        }
    }
    let mut used = vec![false; segments.len()];
    let mut chains = Vec::new();
    let walk = |start: Crossing, used: &mut [bool]| -> Option<Vec<Crossing>> {
        let mut line = vec![start];
        let mut here = start;
        while let Some(&s) = at[&here].iter().find(|&&s| !used[s]) {
            used[s] = true;
            let [a, b] = segments[s];
            here = if a == here { b } else { a };
            line.push(here);
            if at[&here].len() != 2 {
                break;
            }
        }
        (line.len() > 1).then_some(line)
    };
    // Free ends and branch points first, in segment order (deterministic), then loops.
    let ends: Vec<Crossing> = segments
        .iter()
        .flatten()
        .copied()
        .filter(|e| at[e].len() != 2)
        .collect();
    for e in ends {
        while let Some(line) = walk(e, &mut used) {
            chains.push(line);
        }
    }
    for s in 0..segments.len() {
        if !used[s] {
            if let Some(line) = walk(segments[s][0], &mut used) {
                chains.push(line);
            }
        }
    }
    chains
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::meshes;

    /// The octahedron of corners ±e_x, ±e_y, ±e_z, outward ([`meshes::octahedron`]).
    fn octahedron() -> TriMesh {
        let (p, t) = meshes::octahedron();
        TriMesh::new(p, t).unwrap()
    }

    #[test]
    fn a_triangle_cut_by_hand() {
        // Corners (0,0,0), (4,0,0), (0,2,2) cut by z = 1: the edges to the third corner at
        // their middles, (0,1,1) and (2,1,1).
        let mesh = TriMesh::new(
            vec![
                Vec3::zeros(),
                Vec3::new(4.0, 0.0, 0.0),
                Vec3::new(0.0, 2.0, 2.0),
            ],
            vec![[0, 1, 2]],
        )
        .unwrap();
        let lines = section(&mesh, &Plane::axis(2, Vec3::new(0.0, 0.0, 1.0)));
        assert_eq!(lines.len(), 1);
        let mut ends = lines[0].clone();
        ends.sort_by(|a, b| a.x.total_cmp(&b.x));
        assert_eq!(ends, [Vec3::new(0.0, 1.0, 1.0), Vec3::new(2.0, 1.0, 1.0)]);
        // Missed by z = 3 and by z = −1.
        for z in [3.0, -1.0] {
            assert!(section(&mesh, &Plane::axis(2, Vec3::new(0.0, 0.0, z))).is_empty());
        }
    }

    #[test]
    fn a_closed_surface_gives_one_closed_loop() {
        // z = 0.5: the square of corners (±0.5, 0), (0, ±0.5), perimeter 4 √0.5.
        let lines = section(&octahedron(), &Plane::axis(2, Vec3::new(0.0, 0.0, 0.5)));
        assert_eq!(lines.len(), 1);
        let loop_ = &lines[0];
        assert_eq!(loop_.len(), 5);
        assert_eq!(loop_.first(), loop_.last());
        assert!((length(&lines) - 4.0 * 0.5f64.sqrt()).abs() < 1e-12);
        for p in loop_ {
            assert_eq!(p.z, 0.5);
            assert!((p.x.abs() + p.y.abs() - 0.5).abs() < 1e-12);
        }
    }

    #[test]
    fn corners_on_the_plane_are_shared() {
        // z = 0 passes through four corners: the square ±e_x, ±e_y once, perimeter 4 √2.
        let lines = section(&octahedron(), &Plane::axis(2, Vec3::zeros()));
        assert_eq!(lines.len(), 1, "{lines:?}");
        assert_eq!(lines[0].len(), 5);
        assert!((length(&lines) - 4.0 * 2f64.sqrt()).abs() < 1e-12);
        // A plane through the top corner alone touches it: no segment.
        assert!(section(&octahedron(), &Plane::axis(2, Vec3::z())).is_empty());
    }

    #[test]
    fn an_oblique_plane_and_a_branch() {
        // Three half-planes (fins) meeting along the z axis, cut by z = 0.5: three segments from
        // the axis, chained from the branch point.
        let mut p = vec![Vec3::zeros(), Vec3::z()];
        let mut t = Vec::new();
        for k in 0..3 {
            let a = 2.0 * std::f64::consts::PI * k as f64 / 3.0;
            let out = Vec3::new(a.cos(), a.sin(), 0.0);
            p.push(out);
            p.push(out + Vec3::z());
            let (i, j) = (2 + 2 * k, 3 + 2 * k);
            t.push([0, i, j]);
            t.push([0, j, 1]);
        }
        let mesh = TriMesh::new(p, t).unwrap();
        let plane = Plane {
            point: Vec3::new(0.0, 0.0, 0.5),
            normal: Vec3::new(0.0, 0.0, 2.0),
        };
        let lines = section(&mesh, &plane);
        assert_eq!(lines.len(), 3, "{lines:?}");
        assert!((length(&lines) - 3.0).abs() < 1e-12);
        for line in &lines {
            assert!(line.iter().all(|q| (q.z - 0.5).abs() < 1e-12));
        }
    }
}
