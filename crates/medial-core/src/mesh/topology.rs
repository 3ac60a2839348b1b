//! Topology of boundary meshes: closed, manifold, consistently and outwardly oriented surfaces,
//! and the one-ring of every vertex in the order the Loop tangents need (SPEC §4).
//!
//! Conventions: a triangle `[a, b, c]` is counter-clockwise about its outward normal
//! `(p_b − p_a) × (p_c − p_a)`. In a consistently oriented closed surface every edge is used by
//! exactly two triangles, once as `a → b` and once as `b → a`.

use crate::{Error, Result, TriMesh, Vec3};

/// Checks that `mesh` is a closed, consistently oriented 2-manifold whose every point is used:
///
/// * every edge belongs to exactly two triangles, which traverse it in opposite directions;
/// * the triangles around every vertex form a single closed fan (no pinched vertices);
/// * every point is a corner of some triangle.
///
/// The error (`Error::InvalidMesh`) names the first offending edge (with its triangles) or
/// vertex, and counts the offending edges. It does not check that the normals point outward:
/// see [`check_outward`].
pub fn check_closed_oriented_manifold(mesh: &TriMesh) -> Result<()> {
    check_edges(mesh.triangles())?;
    vertex_rings(mesh.points().len(), mesh.triangles()).map(|_| ())
}

/// Refuses a closed surface whose triangles are oriented inward (or that encloses no volume):
/// the signed volume ([`signed_volume`]) must be positive.
pub fn check_outward(mesh: &TriMesh) -> Result<()> {
    let volume = signed_volume(mesh.points(), mesh.triangles());
    if volume > 0.0 {
        Ok(())
    } else if volume < 0.0 {
        Err(Error::InvalidMesh(format!(
            "the triangle normals point inward (signed volume {volume:.6e} < 0): reverse the \
             corner order of every triangle so that they are counter-clockwise seen from outside"
        )))
    } else {
        Err(Error::InvalidMesh(format!(
            "the surface encloses no volume (signed volume {volume}): its points are coplanar or \
             not finite"
        )))
    }
}

/// Signed volume enclosed by a closed triangle surface (divergence theorem):
/// `V = (1/6) Σ_t p_a · (p_b × p_c)` over triangles `t = [a, b, c]`; positive when the triangles
/// are counter-clockwise seen from outside. Unit: cubed coordinate unit.
///
/// # Panics
/// If a triangle index is out of range of `points`.
pub fn signed_volume(points: &[Vec3], triangles: &[[usize; 3]]) -> f64 {
    triangles
        .iter()
        .map(|&[a, b, c]| points[a].dot(&points[b].cross(&points[c])))
        .sum::<f64>()
        / 6.0
}

/// The one-ring of every vertex of a closed, consistently oriented manifold: the neighbours
/// `v_0 … v_{n−1}` walked counter-clockwise about the outward normal (the orientation of the
/// triangles: in triangle `[v, a, b]`, `b` follows `a`), starting at the neighbour with the
/// smallest index (SPEC §4).
///
/// Errors (`Error::InvalidMesh`) name the vertex: an index out of range, a repeated corner, a
/// point used by no triangle, a vertex on a border (open mesh), a non-manifold or
/// inconsistently oriented fan, a pinched vertex (several fans).
pub fn vertex_rings(n_points: usize, triangles: &[[usize; 3]]) -> Result<Vec<Vec<usize>>> {
    let links = vertex_links(n_points, triangles)?;
    links
        .iter()
        .enumerate()
        .map(|(v, link)| ring_from_link(v, link))
        .collect()
}

/// The link edges of every vertex: for triangle `[a, b, c]`, vertex `a` gets `(b, c)`, `b` gets
/// `(c, a)` and `c` gets `(a, b)`.
fn vertex_links(n_points: usize, triangles: &[[usize; 3]]) -> Result<Vec<Vec<(usize, usize)>>> {
    let mut links = vec![Vec::new(); n_points];
    for (t, tri) in triangles.iter().enumerate() {
        if let Some(&v) = tri.iter().find(|&&v| v >= n_points) {
            return Err(Error::InvalidMesh(format!(
                "triangle {t} uses point {v} but the mesh has {n_points} points"
            )));
        }
        if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
            return Err(Error::InvalidMesh(format!(
                "triangle {t} repeats a corner: {tri:?}"
            )));
        }
        for i in 0..3 {
            links[tri[i]].push((tri[(i + 1) % 3], tri[(i + 2) % 3]));
        }
    }
    Ok(links)
}

/// Walks the link of vertex `v` from its smallest neighbour until it closes.
fn ring_from_link(v: usize, link: &[(usize, usize)]) -> Result<Vec<usize>> {
    let Some(start) = link.iter().map(|e| e.0).min() else {
        return Err(Error::InvalidMesh(format!(
            "point {v} is not a corner of any triangle"
        )));
    };
    let mut ring = Vec::with_capacity(link.len());
    let mut current = start;
    loop {
        ring.push(current);
        let next = link_successor(v, link, current)?;
        if next == start {
            break;
        }
        if ring.len() == link.len() {
            return Err(Error::InvalidMesh(format!(
                "vertex {v}: the triangles around it do not form a fan (its neighbours {ring:?} \
                 do not close into a ring)"
            )));
        }
        current = next;
    }
    if ring.len() < link.len() {
        return Err(Error::InvalidMesh(format!(
            "vertex {v} is pinched: its {} triangles form more than one fan (the fan through \
             neighbour {start} has only {} of them)",
            link.len(),
            ring.len()
        )));
    }
    Ok(ring)
}

/// The neighbour that follows `current` counter-clockwise around `v`.
fn link_successor(v: usize, link: &[(usize, usize)], current: usize) -> Result<usize> {
    let mut followers = link.iter().filter(|e| e.0 == current).map(|e| e.1);
    match (followers.next(), followers.next()) {
        (Some(next), None) => Ok(next),
        (None, _) => Err(Error::InvalidMesh(format!(
            "vertex {v} lies on a border or an inconsistently oriented fan: no triangle \
             follows edge ({v}, {current}) counter-clockwise"
        ))),
        (Some(_), Some(_)) => Err(Error::InvalidMesh(format!(
            "vertex {v} is non-manifold or inconsistently oriented: several triangles follow \
             edge ({v}, {current}) counter-clockwise"
        ))),
    }
}

/// One directed use of an undirected edge `{lo, hi}` by triangle `triangle`.
#[derive(Clone, Copy, Debug)]
struct EdgeUse {
    lo: usize,
    hi: usize,
    /// The triangle traverses the edge as `lo → hi`.
    forward: bool,
    triangle: usize,
}

/// Every edge must be used by exactly two triangles, in opposite directions.
fn check_edges(triangles: &[[usize; 3]]) -> Result<()> {
    let mut uses: Vec<EdgeUse> = triangles
        .iter()
        .enumerate()
        .flat_map(|(t, tri)| {
            (0..3).map(move |i| {
                let (a, b) = (tri[i], tri[(i + 1) % 3]);
                EdgeUse {
                    lo: a.min(b),
                    hi: a.max(b),
                    forward: a < b,
                    triangle: t,
                }
            })
        })
        .collect();
    uses.sort_unstable_by_key(|u| (u.lo, u.hi, u.triangle));
    let mut problems = uses
        .chunk_by(|x, y| (x.lo, x.hi) == (y.lo, y.hi))
        .filter_map(edge_problem);
    let Some(first) = problems.next() else {
        return Ok(());
    };
    let more = problems.count();
    Err(Error::InvalidMesh(if more == 0 {
        first
    } else {
        format!("{first} ({} problem edges in all)", more + 1)
    }))
}

/// What is wrong with one edge, given all its uses, if anything.
fn edge_problem(uses: &[EdgeUse]) -> Option<String> {
    let (lo, hi) = (uses[0].lo, uses[0].hi);
    let triangles: Vec<usize> = uses.iter().map(|u| u.triangle).collect();
    match uses {
        [only] => Some(format!(
            "the surface is open: edge ({lo}, {hi}) belongs only to triangle {}, but a closed \
             surface is required",
            only.triangle
        )),
        [a, b] if a.forward == b.forward => Some(format!(
            "inconsistent orientation: triangles {} and {} both traverse edge ({lo}, {hi}) in \
             the same direction: one of them is flipped",
            a.triangle, b.triangle
        )),
        [_, _] => None,
        _ => Some(format!(
            "non-manifold edge ({lo}, {hi}): shared by {} triangles {triangles:?}",
            uses.len()
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The regular octahedron of [`crate::testing::meshes::octahedron`], outward oriented.
    fn octahedron() -> TriMesh {
        let (points, triangles) = crate::testing::meshes::octahedron();
        TriMesh::new(points, triangles).expect("valid octahedron")
    }

    fn message(result: Result<()>) -> String {
        match result {
            Err(Error::InvalidMesh(m)) => m,
            other => panic!("expected InvalidMesh, got {other:?}"),
        }
    }

    #[test]
    fn octahedron_is_closed_outward_with_ccw_rings() {
        let mesh = octahedron();
        check_closed_oriented_manifold(&mesh).expect("closed");
        check_outward(&mesh).expect("outward");
        approx::assert_relative_eq!(signed_volume(mesh.points(), mesh.triangles()), 4.0 / 3.0);
        let rings = vertex_rings(6, mesh.triangles()).expect("rings");
        // Around +z (vertex 4) seen from outside (from +z): +x, +y, −x, −y is counter-clockwise.
        assert_eq!(rings[4], vec![0, 2, 1, 3]);
        // Around +x (vertex 0), outward normal +x: smallest neighbour 2 (+y), then +z (4), …
        assert_eq!(rings[0], vec![2, 4, 3, 5]);
        for (v, ring) in rings.iter().enumerate() {
            let p = mesh.points()[v];
            let (a, b) = (mesh.points()[ring[0]] - p, mesh.points()[ring[1]] - p);
            assert!(
                a.cross(&b).dot(&p) > 0.0,
                "ring of {v} is not counter-clockwise"
            );
            assert_eq!(ring[0], *ring.iter().min().expect("non-empty"));
        }
    }

    #[test]
    fn open_mesh_is_refused_naming_the_edge() {
        let (points, mut triangles) = octahedron().into_parts();
        triangles.remove(3);
        let mesh = TriMesh::new(points, triangles).expect("indices valid");
        let m = message(check_closed_oriented_manifold(&mesh));
        assert!(m.contains("open") && m.contains("edge (0, 3)"), "{m}");
        assert!(
            m.contains("triangle 6") && m.contains("3 problem edges in all"),
            "{m}"
        );
    }

    #[test]
    fn flipped_triangle_is_refused() {
        let (points, mut triangles) = octahedron().into_parts();
        triangles[2] = [1, 4, 3];
        let mesh = TriMesh::new(points, triangles).expect("indices valid");
        let m = message(check_closed_oriented_manifold(&mesh));
        assert!(
            m.contains("inconsistent orientation") && m.contains("triangles"),
            "{m}"
        );
        assert!(m.contains("3 problem edges in all"), "{m}");
    }

    #[test]
    fn inward_mesh_is_refused() {
        let (points, triangles) = octahedron().into_parts();
        let flipped = triangles.iter().map(|&[a, b, c]| [a, c, b]).collect();
        let mesh = TriMesh::new(points, flipped).expect("indices valid");
        check_closed_oriented_manifold(&mesh).expect("still closed and consistent");
        let m = message(check_outward(&mesh));
        assert!(m.contains("point inward"), "{m}");
    }

    #[test]
    fn unused_point_and_pinched_vertex_are_refused() {
        let (mut points, triangles) = octahedron().into_parts();
        points.push(Vec3::new(5.0, 5.0, 5.0));
        let mesh = TriMesh::new(points.clone(), triangles.clone()).expect("indices valid");
        let m = message(check_closed_oriented_manifold(&mesh));
        assert!(m.contains("point 6 is not a corner"), "{m}");

        // Two octahedra glued at one vertex: the −x corner (1) of the second, shifted by +2 in
        // x, is the +x corner (0) of the first.
        let second = |v: usize| match v {
            1 => 0,
            0 => 6,
            _ => v + 5,
        };
        let mut points: Vec<Vec3> = octahedron().points().to_vec();
        let shift = Vec3::new(2.0, 0.0, 0.0);
        points.extend([0, 2, 3, 4, 5].map(|v| octahedron().points()[v] + shift));
        let mut triangles = octahedron().triangles().to_vec();
        triangles.extend(octahedron().triangles().iter().map(|t| t.map(second)));
        let mesh = TriMesh::new(points, triangles).expect("indices valid");
        check_outward(&mesh).expect("outward");
        let m = message(check_closed_oriented_manifold(&mesh));
        assert!(m.contains("vertex 0 is pinched"), "{m}");
    }

    #[test]
    fn non_manifold_edge_is_refused() {
        let (mut points, mut triangles) = octahedron().into_parts();
        points.push(Vec3::new(0.5, 0.5, 2.0));
        triangles.push([0, 2, 6]);
        let mesh = TriMesh::new(points, triangles).expect("indices valid");
        let m = message(check_closed_oriented_manifold(&mesh));
        assert!(m.contains("non-manifold edge (0, 2)"), "{m}");
    }
}
