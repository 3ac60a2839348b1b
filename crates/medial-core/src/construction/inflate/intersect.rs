//! Self-intersection test of the inflated boundary: a uniform grid as broad phase, then exact
//! triangle–triangle and segment–triangle tests (Möller's interval test, coplanar pairs in 2-D).

use std::collections::HashMap;

use super::geometry::corners;
use crate::mesh::Bounds;
use crate::{TriMesh, Vec3};

/// Halves the change `f − 1` of the atoms' `factors` at every atom of the triangles of `mesh`
/// (a template's boundary, `atom_of` its medial index) in the `crossing` pairs
/// ([`self_intersections`]): one round of the limit of a thickened wall where the sheet cannot
/// hold it (a synthetic thickening, [`crate::synth::Thickening::boundary`], and an automatic
/// fit's thickened start, [`crate::fit::initial::thickened`]).
pub fn halve_at_crossings(
    factors: &mut [f64],
    mesh: &TriMesh,
    crossing: &[(usize, usize)],
    atom_of: &[usize],
) {
    let mut atoms: Vec<usize> = (crossing.iter())
        .flat_map(|&(f, g)| [f, g])
        .flat_map(|t| mesh.triangles()[t])
        .map(|b| atom_of[b])
        .collect();
    atoms.sort_unstable();
    atoms.dedup();
    for a in atoms {
        factors[a] = 1.0 + 0.5 * (factors[a] - 1.0);
    }
}

/// How many times at most a thickened wall's change is halved at the atoms of crossing
/// triangles ([`halve_at_crossings`]): down to 1/1024 of it.
pub const LIMIT_ROUNDS: u32 = 10;

/// Distances to a plane below `SNAP · (diagonal of the bounding box)` count as zero in the
/// triangle–triangle intersection test.
pub(super) const SNAP: f64 = 1e-10;

/// The pairs of boundary triangles `(f, g)`, `f < g`, that intersect: sharing no vertex and
/// meeting anywhere, or sharing one vertex and meeting elsewhere (the edge opposite the shared
/// vertex of one crosses the other). Broad phase: a uniform grid of cubes about the mean
/// triangle size; each candidate pair is tested once, in the cell of the lower corner of the
/// intersection of their boxes.
pub fn self_intersections(mesh: &TriMesh) -> Vec<(usize, usize)> {
    let points = mesh.points();
    let tris: Vec<[Vec3; 3]> = mesh
        .triangles()
        .iter()
        .map(|t| corners(points, t))
        .collect();
    let boxes: Vec<Bounds> = tris.iter().filter_map(|t| Bounds::of(t)).collect();
    let Some(all) = Bounds::of(points) else {
        return Vec::new();
    };
    let diagonal = all.diagonal();
    let tol = SNAP * diagonal;
    let mean_extent =
        boxes.iter().map(|b| b.extent().max()).sum::<f64>() / boxes.len().max(1) as f64;
    let cell = mean_extent.max(diagonal / 256.0).max(f64::MIN_POSITIVE);
    let cell_of = |x: &Vec3| ((x - all.min) / cell).map(|c| c.floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (f, b) in boxes.iter().enumerate() {
        let (lo, hi) = (cell_of(&b.min), cell_of(&b.max));
        for i in lo[0]..=hi[0] {
            for j in lo[1]..=hi[1] {
                for k in lo[2]..=hi[2] {
                    grid.entry([i, j, k]).or_default().push(f);
                }
            }
        }
    }
    let mut pairs = Vec::new();
    for (key, members) in &grid {
        for (x, &f) in members.iter().enumerate() {
            for &g in &members[x + 1..] {
                let corner = boxes[f].min.sup(&boxes[g].min);
                if boxes[f].overlaps(&boxes[g], tol)
                    && cell_of(&corner).as_slice() == key
                    && pair_intersects(
                        mesh.triangles()[f],
                        mesh.triangles()[g],
                        &tris[f],
                        &tris[g],
                        tol,
                    )
                {
                    pairs.push((f.min(g), f.max(g)));
                }
            }
        }
    }
    pairs.sort_unstable();
    pairs
}

pub(super) fn pair_intersects(
    fi: [usize; 3],
    gi: [usize; 3],
    f: &[Vec3; 3],
    g: &[Vec3; 3],
    tol: f64,
) -> bool {
    let shared: Vec<(usize, usize)> = (0..3)
        .flat_map(|i| (0..3).map(move |j| (i, j)))
        .filter(|&(i, j)| fi[i] == gi[j])
        .collect();
    match shared.as_slice() {
        [] => triangles_intersect(f, g, tol),
        [(i, j)] => {
            let (fa, fb) = (f[(i + 1) % 3], f[(i + 2) % 3]);
            let (ga, gb) = (g[(j + 1) % 3], g[(j + 2) % 3]);
            segment_meets_triangle(fa, fb, g, tol) || segment_meets_triangle(ga, gb, f, tol)
        }
        _ => false,
    }
}

/// Signed distances of points to the plane of a triangle, with `|d| ≤ tol` set to zero.
pub(super) fn plane_distances<const N: usize>(
    points: &[Vec3; N],
    tri: &[Vec3; 3],
    tol: f64,
) -> [f64; N] {
    let n = (tri[1] - tri[0]).cross(&(tri[2] - tri[0])).normalize();
    points.map(|p| {
        let d = n.dot(&(p - tri[0]));
        if d.abs() <= tol {
            0.0
        } else {
            d
        }
    })
}

pub(super) fn all_strictly_same_side(d: &[f64]) -> bool {
    d.iter().all(|&x| x > 0.0) || d.iter().all(|&x| x < 0.0)
}

/// Whether two triangles (closed sets) meet (Möller's interval test; coplanar pairs in 2-D).
pub(super) fn triangles_intersect(a: &[Vec3; 3], b: &[Vec3; 3], tol: f64) -> bool {
    let da = plane_distances(a, b, tol);
    if all_strictly_same_side(&da) {
        return false;
    }
    let db = plane_distances(b, a, tol);
    if all_strictly_same_side(&db) {
        return false;
    }
    let na = (a[1] - a[0]).cross(&(a[2] - a[0]));
    let nb = (b[1] - b[0]).cross(&(b[2] - b[0]));
    let dir = na.normalize().cross(&nb.normalize());
    if da.iter().all(|&d| d == 0.0) || db.iter().all(|&d| d == 0.0) || dir.norm() < 1e-12 {
        return coplanar_triangles_meet(a, b, &nb);
    }
    let (a0, a1) = plane_interval(a, &da, &dir);
    let (b0, b1) = plane_interval(b, &db, &dir);
    a0 <= b1 && b0 <= a1
}

/// The projection onto `dir` of the part of a triangle that lies in the other plane, given the
/// signed distances `d` of its corners to that plane.
pub(super) fn plane_interval(tri: &[Vec3; 3], d: &[f64; 3], dir: &Vec3) -> (f64, f64) {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    let mut add = |x: Vec3| {
        let s = dir.dot(&x);
        lo = lo.min(s);
        hi = hi.max(s);
    };
    for i in 0..3 {
        let j = (i + 1) % 3;
        if d[i] == 0.0 {
            add(tri[i]);
        }
        if d[i] * d[j] < 0.0 {
            add(tri[i] + (tri[j] - tri[i]) * (d[i] / (d[i] - d[j])));
        }
    }
    (lo, hi)
}

/// Whether a segment meets a triangle (closed sets).
pub(super) fn segment_meets_triangle(p: Vec3, q: Vec3, tri: &[Vec3; 3], tol: f64) -> bool {
    let [dp, dq] = plane_distances(&[p, q], tri, tol);
    if all_strictly_same_side(&[dp, dq]) {
        return false;
    }
    let n = (tri[1] - tri[0]).cross(&(tri[2] - tri[0]));
    let t2 = project(tri, &n);
    let [p2, q2] = project(&[p, q], &n);
    if dp == 0.0 && dq == 0.0 {
        return point_in_triangle_2d(p2, &t2)
            || (0..3).any(|i| segments_meet_2d(p2, q2, t2[i], t2[(i + 1) % 3]));
    }
    let x = if dp == 0.0 {
        p
    } else if dq == 0.0 {
        q
    } else {
        p + (q - p) * (dp / (dp - dq))
    };
    point_in_triangle_2d(project(&[x], &n)[0], &t2)
}

pub(super) type P2 = nalgebra::Vector2<f64>;

/// Projects points onto the coordinate plane most nearly perpendicular to `n`.
pub(super) fn project<const N: usize>(points: &[Vec3; N], n: &Vec3) -> [P2; N] {
    let drop = n.iamax();
    let (i, j) = ((drop + 1) % 3, (drop + 2) % 3);
    points.map(|p| P2::new(p[i], p[j]))
}

pub(super) fn coplanar_triangles_meet(a: &[Vec3; 3], b: &[Vec3; 3], n: &Vec3) -> bool {
    let (a2, b2) = (project(a, n), project(b, n));
    let edges_cross = (0..3)
        .any(|i| (0..3).any(|j| segments_meet_2d(a2[i], a2[(i + 1) % 3], b2[j], b2[(j + 1) % 3])));
    edges_cross || point_in_triangle_2d(a2[0], &b2) || point_in_triangle_2d(b2[0], &a2)
}

pub(super) fn orient_2d(a: P2, b: P2, c: P2) -> f64 {
    (b - a).perp(&(c - a))
}

pub(super) fn point_in_triangle_2d(x: P2, t: &[P2; 3]) -> bool {
    let s = [
        orient_2d(t[0], t[1], x),
        orient_2d(t[1], t[2], x),
        orient_2d(t[2], t[0], x),
    ];
    s.iter().all(|&v| v >= 0.0) || s.iter().all(|&v| v <= 0.0)
}

/// Whether two closed segments meet (collinear ones when their extents overlap).
pub(super) fn segments_meet_2d(p1: P2, p2: P2, q1: P2, q2: P2) -> bool {
    let (o1, o2) = (orient_2d(p1, p2, q1), orient_2d(p1, p2, q2));
    let (o3, o4) = (orient_2d(q1, q2, p1), orient_2d(q1, q2, p2));
    if o1 == 0.0 && o2 == 0.0 {
        let axis = (p2 - p1).iamax();
        let (a0, a1) = (p1[axis].min(p2[axis]), p1[axis].max(p2[axis]));
        let (b0, b1) = (q1[axis].min(q2[axis]), q1[axis].max(q2[axis]));
        return a0 <= b1 && b0 <= a1;
    }
    o1 * o2 <= 0.0 && o3 * o4 <= 0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64, y: f64, z: f64) -> Vec3 {
        Vec3::new(x, y, z)
    }

    #[test]
    fn triangle_pairs() {
        let tol = 1e-12;
        let a = [v(0.0, 0.0, 0.0), v(2.0, 0.0, 0.0), v(0.0, 2.0, 0.0)];
        let piercing = [v(0.5, 0.5, -1.0), v(0.5, 0.5, 1.0), v(3.0, 3.0, 0.5)];
        let above = [v(0.5, 0.5, 0.1), v(1.5, 0.5, 1.0), v(0.5, 1.5, 1.0)];
        let beside = [v(3.0, 0.0, -1.0), v(3.0, 0.0, 1.0), v(3.0, 2.0, 0.0)];
        let touching = [v(1.0, 1.0, 0.0), v(3.0, 1.0, 1.0), v(3.0, 1.0, -1.0)];
        let coplanar_overlap = [v(0.5, 0.5, 0.0), v(3.0, 0.5, 0.0), v(0.5, 3.0, 0.0)];
        let coplanar_inside = [v(0.2, 0.2, 0.0), v(0.6, 0.2, 0.0), v(0.2, 0.6, 0.0)];
        let coplanar_apart = [v(1.5, 1.5, 0.0), v(3.0, 1.5, 0.0), v(1.5, 3.0, 0.0)];
        let collinear_apart = [v(3.0, 0.0, 0.0), v(4.0, 0.0, 0.0), v(3.5, -1.0, 0.0)];
        for (b, want, what) in [
            (piercing, true, "piercing"),
            (above, false, "above"),
            (beside, false, "beside"),
            (touching, true, "touching at a point"),
            (coplanar_overlap, true, "coplanar overlap"),
            (coplanar_inside, true, "coplanar inside"),
            (coplanar_apart, false, "coplanar apart"),
            (collinear_apart, false, "collinear edges apart"),
        ] {
            assert_eq!(triangles_intersect(&a, &b, tol), want, "{what}");
            assert_eq!(triangles_intersect(&b, &a, tol), want, "{what}, swapped");
        }
    }

    #[test]
    fn triangles_sharing_a_vertex() {
        let tol = 1e-12;
        let a = [v(0.0, 0.0, 0.0), v(2.0, 0.0, 0.0), v(0.0, 2.0, 0.0)];
        // Fan neighbours in the plane and out of it do not intersect; a folded-over one does.
        let flat = [v(0.0, 0.0, 0.0), v(0.0, 2.0, 0.0), v(-2.0, 0.0, 0.0)];
        let bent = [v(0.0, 0.0, 0.0), v(-1.0, -1.0, 1.0), v(2.0, -1.0, 0.5)];
        let folded = [v(0.0, 0.0, 0.0), v(1.0, 1.0, -1.0), v(1.0, 1.0, 1.0)];
        assert!(!pair_intersects([0, 1, 2], [0, 2, 3], &a, &flat, tol));
        assert!(!pair_intersects([0, 1, 2], [0, 4, 5], &a, &bent, tol));
        assert!(pair_intersects([0, 1, 2], [0, 4, 5], &a, &folded, tol));
        assert!(
            !pair_intersects([0, 1, 2], [0, 1, 5], &a, &folded, tol),
            "edge neighbours are skipped"
        );
    }
}
