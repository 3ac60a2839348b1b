//! Topology of boundary meshes: closed, manifold, consistently and outwardly oriented surfaces,
//! and the one-ring of every vertex in the order the Loop tangents need (docs/method.md §2.4).
//!
//! Conventions: a triangle `[a, b, c]` is counter-clockwise about its outward normal
//! `(p_b − p_a) × (p_c − p_a)`. In a consistently oriented closed surface every edge is used by
//! exactly two triangles, once as `a → b` and once as `b → a`.
//!
//! Every check here reports what it finds as a [`MeshDefect`], which names the triangles, edge
//! or vertex involved; callers that know more (which medial vertices a boundary point belongs
//! to) match on it and word the error themselves.

use crate::{TriMesh, Vec3};

/// What makes a triangle list fail to be a closed, consistently and outwardly oriented
/// 2-manifold. Edges are written `(a, b)` with `a < b`. The edge defects carry `problem_edges`,
/// the number of edges with a defect of any kind found by the same check (this one included).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MeshDefect {
    /// A triangle corner is not a point of the mesh.
    #[error("triangle {triangle} uses point {point} but the mesh has {points} points")]
    IndexOutOfRange {
        /// The triangle.
        triangle: usize,
        /// The corner index out of range.
        point: usize,
        /// The number of points of the mesh.
        points: usize,
    },
    /// A triangle names one point twice.
    #[error("triangle {triangle} repeats a corner: {corners:?}")]
    RepeatedCorner {
        /// The triangle.
        triangle: usize,
        /// Its corners.
        corners: [usize; 3],
    },
    /// An edge used by a single triangle: the surface has a hole.
    #[error(
        "the surface is open: edge ({a}, {b}) belongs only to triangle {triangle}, but a closed \
         surface is required{}",
        in_all(*.problem_edges)
    )]
    OpenEdge {
        /// Lower end of the edge.
        a: usize,
        /// Upper end of the edge.
        b: usize,
        /// The one triangle on it.
        triangle: usize,
        /// Edges with a defect in all.
        problem_edges: usize,
    },
    /// The two triangles of an edge traverse it in the same direction: one is flipped.
    #[error(
        "inconsistent orientation: triangles {} and {} both traverse edge ({a}, {b}) in the same \
         direction: one of them is flipped{}",
        .triangles[0],
        .triangles[1],
        in_all(*.problem_edges)
    )]
    InconsistentOrientation {
        /// Lower end of the edge.
        a: usize,
        /// Upper end of the edge.
        b: usize,
        /// The two triangles on it, ascending.
        triangles: [usize; 2],
        /// Edges with a defect in all.
        problem_edges: usize,
    },
    /// An edge shared by more than two triangles.
    #[error(
        "non-manifold edge ({a}, {b}): shared by {} triangles {triangles:?}{}",
        .triangles.len(),
        in_all(*.problem_edges)
    )]
    NonManifoldEdge {
        /// Lower end of the edge.
        a: usize,
        /// Upper end of the edge.
        b: usize,
        /// The triangles on it, ascending.
        triangles: Vec<usize>,
        /// Edges with a defect in all.
        problem_edges: usize,
    },
    /// A point that is a corner of no triangle.
    #[error("point {point} is not a corner of any triangle")]
    UnusedPoint {
        /// The point.
        point: usize,
    },
    /// Walking the triangles around `vertex`, no triangle follows the edge to `neighbour`.
    #[error(
        "vertex {vertex} lies on a border or an inconsistently oriented fan: no triangle follows \
         edge ({vertex}, {neighbour}) counter-clockwise"
    )]
    BorderVertex {
        /// The vertex.
        vertex: usize,
        /// The neighbour after which the walk stops.
        neighbour: usize,
    },
    /// Walking the triangles around `vertex`, several triangles follow the edge to `neighbour`.
    #[error(
        "vertex {vertex} is non-manifold or inconsistently oriented: several triangles follow \
         edge ({vertex}, {neighbour}) counter-clockwise"
    )]
    BranchingVertex {
        /// The vertex.
        vertex: usize,
        /// The neighbour after which the walk branches.
        neighbour: usize,
    },
    /// The neighbours of `vertex`, walked counter-clockwise, do not come back to the first.
    #[error(
        "vertex {vertex}: the triangles around it do not form a fan (its neighbours {ring:?} do \
         not close into a ring)"
    )]
    UnclosedRing {
        /// The vertex.
        vertex: usize,
        /// The neighbours walked.
        ring: Vec<usize>,
    },
    /// The triangles around `vertex` form several fans (surfaces touching at one point).
    #[error(
        "vertex {vertex} is pinched: its {triangles} triangles form more than one fan (the fan \
         through neighbour {neighbour} has only {fan} of them)"
    )]
    PinchedVertex {
        /// The vertex.
        vertex: usize,
        /// Triangles around it.
        triangles: usize,
        /// Its smallest neighbour, where the walk started.
        neighbour: usize,
        /// Triangles in the fan through that neighbour.
        fan: usize,
    },
    /// A vertex with fewer than three neighbours has no Loop tangent plane.
    #[error(
        "vertex {vertex} has valence {} (neighbours {ring:?}); Loop tangents need at least 3",
        .ring.len()
    )]
    LowValence {
        /// The vertex.
        vertex: usize,
        /// Its neighbours.
        ring: Vec<usize>,
    },
    /// The triangles are oriented inward: the signed volume is negative.
    #[error(
        "the triangle normals point inward (signed volume {volume:.6e} < 0): reverse the corner \
         order of every triangle so that they are counter-clockwise seen from outside"
    )]
    Inward {
        /// The signed volume ([`signed_volume`]), cubed coordinate unit.
        volume: f64,
    },
    /// The surface encloses no volume (or not a finite one).
    #[error(
        "the surface encloses no volume (signed volume {volume}): its points are coplanar or not \
         finite"
    )]
    NoVolume {
        /// The signed volume ([`signed_volume`]): 0 or NaN.
        volume: f64,
    },
}

/// The suffix ` (n problem edges in all)` of an edge defect when there are several.
fn in_all(problem_edges: usize) -> String {
    if problem_edges > 1 {
        format!(" ({problem_edges} problem edges in all)")
    } else {
        String::new()
    }
}

/// Whether the two triangles of an edge must traverse it in opposite directions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Orientation {
    /// Consistently oriented: once `a → b`, once `b → a`.
    Consistent,
    /// Either way (a surface whose orientation does not matter, as for crossing parity).
    Any,
}

/// Checks that every corner of every triangle is one of `n_points` points and that no triangle
/// repeats a corner; the first offending triangle is reported.
pub fn check_corners(n_points: usize, triangles: &[[usize; 3]]) -> Result<(), MeshDefect> {
    for (t, tri) in triangles.iter().enumerate() {
        if let Some(&v) = tri.iter().find(|&&v| v >= n_points) {
            return Err(MeshDefect::IndexOutOfRange {
                triangle: t,
                point: v,
                points: n_points,
            });
        }
        if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
            return Err(MeshDefect::RepeatedCorner {
                triangle: t,
                corners: *tri,
            });
        }
    }
    Ok(())
}

/// Checks that every edge belongs to exactly two triangles, which traverse it in opposite
/// directions when `orientation` is [`Orientation::Consistent`]. The defect reported is that of
/// the smallest offending edge `(a, b)` (lexicographic, `a < b`), with the number of offending
/// edges.
pub fn check_edges(triangles: &[[usize; 3]], orientation: Orientation) -> Result<(), MeshDefect> {
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
        .filter(|uses| edge_defect(uses, orientation, 0).is_some());
    let Some(first) = problems.next() else {
        return Ok(());
    };
    let problem_edges = 1 + problems.count();
    Err(edge_defect(first, orientation, problem_edges).expect("a problem edge has a defect"))
}

/// Checks that `mesh` is a closed, consistently oriented 2-manifold whose every point is used,
/// and returns the one-ring of every vertex ([`vertex_rings`]):
///
/// * every edge belongs to exactly two triangles, which traverse it in opposite directions
///   ([`check_edges`]);
/// * the triangles around every vertex form a single closed fan (no pinched vertices);
/// * every point is a corner of some triangle.
///
/// The defect names the first offending edge (with its triangles, and the number of offending
/// edges) or vertex. The normals need not point outward: see [`check_outward`].
pub fn check_closed_oriented_manifold(mesh: &TriMesh) -> Result<Vec<Vec<usize>>, MeshDefect> {
    check_edges(mesh.triangles(), Orientation::Consistent)?;
    vertex_rings(mesh.points().len(), mesh.triangles())
}

/// Refuses a closed surface whose triangles are oriented inward (or that encloses no volume):
/// the signed volume ([`signed_volume`]) must be positive.
pub fn check_outward(mesh: &TriMesh) -> Result<(), MeshDefect> {
    let volume = signed_volume(mesh.points(), mesh.triangles());
    if volume > 0.0 {
        Ok(())
    } else if volume < 0.0 {
        Err(MeshDefect::Inward { volume })
    } else {
        Err(MeshDefect::NoVolume { volume })
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
/// smallest index (docs/method.md §2.4).
///
/// Defects name the vertex: an index out of range, a repeated corner ([`check_corners`]), a
/// point used by no triangle, a vertex on a border (open mesh), a non-manifold or
/// inconsistently oriented fan, a pinched vertex (several fans).
pub fn vertex_rings(
    n_points: usize,
    triangles: &[[usize; 3]],
) -> Result<Vec<Vec<usize>>, MeshDefect> {
    check_corners(n_points, triangles)?;
    let mut links = vec![Vec::new(); n_points];
    for tri in triangles {
        for i in 0..3 {
            links[tri[i]].push((tri[(i + 1) % 3], tri[(i + 2) % 3]));
        }
    }
    links
        .iter()
        .enumerate()
        .map(|(v, link)| ring_from_link(v, link))
        .collect()
}

/// Walks the link of vertex `v` (for triangle `[v, a, b]`, the link edge `(a, b)`) from its
/// smallest neighbour until it closes.
fn ring_from_link(v: usize, link: &[(usize, usize)]) -> Result<Vec<usize>, MeshDefect> {
    let Some(start) = link.iter().map(|e| e.0).min() else {
        return Err(MeshDefect::UnusedPoint { point: v });
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
            return Err(MeshDefect::UnclosedRing { vertex: v, ring });
        }
        current = next;
    }
    if ring.len() < link.len() {
        return Err(MeshDefect::PinchedVertex {
            vertex: v,
            triangles: link.len(),
            neighbour: start,
            fan: ring.len(),
        });
    }
    Ok(ring)
}

/// The neighbour that follows `current` counter-clockwise around `v`.
fn link_successor(v: usize, link: &[(usize, usize)], current: usize) -> Result<usize, MeshDefect> {
    let mut followers = link.iter().filter(|e| e.0 == current).map(|e| e.1);
    match (followers.next(), followers.next()) {
        (Some(next), None) => Ok(next),
        (None, _) => Err(MeshDefect::BorderVertex {
            vertex: v,
            neighbour: current,
        }),
        (Some(_), Some(_)) => Err(MeshDefect::BranchingVertex {
            vertex: v,
            neighbour: current,
        }),
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

/// What is wrong with one edge, given all its uses (ascending triangles), if anything.
fn edge_defect(
    uses: &[EdgeUse],
    orientation: Orientation,
    problem_edges: usize,
) -> Option<MeshDefect> {
    let (a, b) = (uses[0].lo, uses[0].hi);
    match uses {
        [only] => Some(MeshDefect::OpenEdge {
            a,
            b,
            triangle: only.triangle,
            problem_edges,
        }),
        [x, y] if orientation == Orientation::Consistent && x.forward == y.forward => {
            Some(MeshDefect::InconsistentOrientation {
                a,
                b,
                triangles: [x.triangle, y.triangle],
                problem_edges,
            })
        }
        [_, _] => None,
        _ => Some(MeshDefect::NonManifoldEdge {
            a,
            b,
            triangles: uses.iter().map(|u| u.triangle).collect(),
            problem_edges,
        }),
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

    fn defect<T: std::fmt::Debug>(result: Result<T, MeshDefect>) -> MeshDefect {
        result.expect_err("must be refused")
    }

    #[test]
    fn octahedron_is_closed_outward_with_ccw_rings() {
        let mesh = octahedron();
        let rings = check_closed_oriented_manifold(&mesh).expect("closed");
        assert_eq!(rings, vertex_rings(6, mesh.triangles()).expect("rings"));
        check_outward(&mesh).expect("outward");
        approx::assert_relative_eq!(signed_volume(mesh.points(), mesh.triangles()), 4.0 / 3.0);
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
    fn corners_out_of_range_or_repeated_are_refused() {
        let d = defect(check_corners(6, &[[0, 1, 2], [0, 6, 1]]));
        assert_eq!(
            d,
            MeshDefect::IndexOutOfRange {
                triangle: 1,
                point: 6,
                points: 6
            }
        );
        assert_eq!(
            d.to_string(),
            "triangle 1 uses point 6 but the mesh has 6 points"
        );
        let d = defect(vertex_rings(6, &[[0, 1, 2], [3, 4, 3]]));
        assert_eq!(
            d,
            MeshDefect::RepeatedCorner {
                triangle: 1,
                corners: [3, 4, 3]
            }
        );
        let e = TriMesh::new(vec![Vec3::zeros(); 3], vec![[0, 1, 1]]).unwrap_err();
        assert!(matches!(
            e,
            crate::Error::Mesh(MeshDefect::RepeatedCorner { triangle: 0, .. })
        ));
        assert_eq!(
            e.to_string(),
            "invalid mesh: triangle 0 repeats a corner: [0, 1, 1]"
        );
    }

    #[test]
    fn open_mesh_is_refused_naming_the_edge() {
        let (points, mut triangles) = octahedron().into_parts();
        triangles.remove(3);
        let mesh = TriMesh::new(points, triangles).expect("indices valid");
        let d = defect(check_closed_oriented_manifold(&mesh));
        // Triangle [3, 0, 4] removed: edges (0, 3), (0, 4), (3, 4) are open.
        assert_eq!(
            d,
            MeshDefect::OpenEdge {
                a: 0,
                b: 3,
                triangle: 6,
                problem_edges: 3
            }
        );
        let m = d.to_string();
        assert!(m.contains("open") && m.contains("edge (0, 3)"), "{m}");
        assert!(
            m.contains("triangle 6") && m.contains("3 problem edges in all"),
            "{m}"
        );
        // Orientation does not change which edges are open.
        assert_eq!(defect(check_edges(mesh.triangles(), Orientation::Any)), d);
    }

    #[test]
    fn flipped_triangle_is_refused_unless_orientation_does_not_matter() {
        let (points, mut triangles) = octahedron().into_parts();
        triangles[2] = [1, 4, 3];
        let mesh = TriMesh::new(points, triangles).expect("indices valid");
        let d = defect(check_closed_oriented_manifold(&mesh));
        assert_eq!(
            d,
            MeshDefect::InconsistentOrientation {
                a: 1,
                b: 3,
                triangles: [2, 6],
                problem_edges: 3
            }
        );
        let m = d.to_string();
        assert!(
            m.contains("inconsistent orientation") && m.contains("triangles 2 and 6"),
            "{m}"
        );
        assert!(m.contains("3 problem edges in all"), "{m}");
        check_edges(mesh.triangles(), Orientation::Any).expect("closed when orientation is free");
    }

    #[test]
    fn inward_and_flat_meshes_are_refused() {
        let (points, triangles) = octahedron().into_parts();
        let flipped = triangles.iter().map(|&[a, b, c]| [a, c, b]).collect();
        let mesh = TriMesh::new(points.clone(), flipped).expect("indices valid");
        check_closed_oriented_manifold(&mesh).expect("still closed and consistent");
        let d = defect(check_outward(&mesh));
        assert!(
            matches!(d, MeshDefect::Inward { volume } if volume < 0.0),
            "{d:?}"
        );
        assert!(d.to_string().contains("point inward"), "{d}");
        let flat: Vec<Vec3> = points.iter().map(|p| Vec3::new(p.x, p.y, 0.0)).collect();
        let mesh = TriMesh::new(flat, triangles).expect("indices valid");
        let d = defect(check_outward(&mesh));
        assert_eq!(d, MeshDefect::NoVolume { volume: 0.0 });
        assert!(d.to_string().contains("encloses no volume"), "{d}");
    }

    #[test]
    fn unused_point_and_pinched_vertex_are_refused() {
        let (mut points, triangles) = octahedron().into_parts();
        points.push(Vec3::new(5.0, 5.0, 5.0));
        let mesh = TriMesh::new(points.clone(), triangles.clone()).expect("indices valid");
        let d = defect(check_closed_oriented_manifold(&mesh));
        assert_eq!(d, MeshDefect::UnusedPoint { point: 6 });
        assert!(d.to_string().contains("point 6 is not a corner"), "{d}");

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
        let d = defect(check_closed_oriented_manifold(&mesh));
        assert_eq!(
            d,
            MeshDefect::PinchedVertex {
                vertex: 0,
                triangles: 8,
                neighbour: 2,
                fan: 4
            }
        );
        assert!(d.to_string().contains("vertex 0 is pinched"), "{d}");
    }

    #[test]
    fn non_manifold_edge_is_refused() {
        let (mut points, mut triangles) = octahedron().into_parts();
        points.push(Vec3::new(0.5, 0.5, 2.0));
        triangles.push([0, 2, 6]);
        let mesh = TriMesh::new(points, triangles).expect("indices valid");
        let d = defect(check_closed_oriented_manifold(&mesh));
        assert!(
            matches!(&d, MeshDefect::NonManifoldEdge { a: 0, b: 2, triangles, .. }
                if triangles == &[0, 4, 8]),
            "{d:?}"
        );
        assert!(d.to_string().contains("non-manifold edge (0, 2)"), "{d}");
        // The two new edges are open, whatever the orientation rule.
        let d = defect(check_edges(mesh.triangles(), Orientation::Any));
        assert!(
            matches!(
                d,
                MeshDefect::NonManifoldEdge {
                    problem_edges: 3,
                    ..
                }
            ),
            "{d:?}"
        );
    }

    #[test]
    fn border_and_branching_fans_are_refused_by_the_ring_walk() {
        let (_, mut triangles) = crate::testing::meshes::octahedron();
        triangles.pop();
        // Vertex 0 loses triangle [0, 3, 5]: its walk from 2 stops at 5 … reaches the border.
        let d = defect(vertex_rings(6, &triangles));
        assert!(matches!(d, MeshDefect::BorderVertex { .. }), "{d:?}");
        assert!(d.to_string().contains("border"), "{d}");
        let (_, mut triangles) = crate::testing::meshes::octahedron();
        triangles.push([0, 2, 3]);
        let d = defect(vertex_rings(6, &triangles));
        assert!(
            matches!(
                d,
                MeshDefect::BranchingVertex {
                    vertex: 0,
                    neighbour: 2
                }
            ),
            "{d:?}"
        );
        // Around vertex 0, the walk 1 → 2 → 3 → 2 … never comes back to 1.
        let d = defect(vertex_rings(4, &[[0, 1, 2], [0, 2, 3], [0, 3, 2]]));
        assert_eq!(
            d,
            MeshDefect::UnclosedRing {
                vertex: 0,
                ring: vec![1, 2, 3]
            }
        );
        assert!(d.to_string().contains("do not form a fan"), "{d}");
    }
}
