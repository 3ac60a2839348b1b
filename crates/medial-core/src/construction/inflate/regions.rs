//! Gluing the corners of the two sides of every medial triangle into regions: one boundary
//! vertex per (medial vertex, region), and its spoke direction.

use super::edges::{corner_of, third, Edges, Member};
use super::geometry::SheetGeometry;
use super::{MedialSheet, LIST_MAX};
use crate::{Error, Result, Vec3};

/// The slot of corner `k` of side `s` (0: `+`, 1: `−`) of medial triangle `t`.
pub(super) fn slot(t: usize, side: usize, k: usize) -> usize {
    6 * t + 3 * side + k
}

/// Union-find over slots, with path halving; the root of a set is its smallest slot.
pub(crate) struct UnionFind(pub(super) Vec<usize>);

impl UnionFind {
    pub(crate) fn new(n: usize) -> Self {
        Self((0..n).collect())
    }

    pub(crate) fn find(&mut self, mut x: usize) -> usize {
        while self.0[x] != x {
            self.0[x] = self.0[self.0[x]];
            x = self.0[x];
        }
        x
    }

    pub(crate) fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        self.0[ra.max(rb)] = ra.min(rb);
    }
}

/// The boundary vertices: one per (medial vertex, region).
pub(super) struct Regions {
    /// The boundary vertex of every slot.
    pub(super) vertex_of_slot: Vec<usize>,
    /// The atom (medial vertex) of every boundary vertex, ascending.
    pub(super) atom: Vec<usize>,
    /// The number of regions (spokes) of every medial vertex.
    pub(super) spokes: Vec<usize>,
}

impl Regions {
    /// Glues slots across every medial edge and numbers the resulting regions by
    /// (atom, first slot).
    pub(super) fn glue(sheet: &MedialSheet, edges: &Edges) -> Self {
        let triangles = sheet.triangles();
        let mut uf = UnionFind::new(6 * triangles.len());
        for e in 0..edges.len() {
            let (a, b) = edges.ends[e];
            for (s, s2, t, t2) in facing_pairs(sheet, edges, e) {
                for v in [a, b] {
                    uf.union(
                        slot(t, s, corner_of(&triangles[t], v)),
                        slot(t2, s2, corner_of(&triangles[t2], v)),
                    );
                }
            }
        }
        let roots: Vec<usize> = (0..uf.0.len()).map(|x| uf.find(x)).collect();
        let atom_of_slot = |x: usize| triangles[x / 6][x % 3];
        // Roots are the smallest slots of their sets, so sorting them by (atom, root) orders
        // regions by atom, then first slot.
        let mut order: Vec<usize> = (0..roots.len()).filter(|&x| roots[x] == x).collect();
        order.sort_by_key(|&x| (atom_of_slot(x), x));
        let mut number = vec![0; roots.len()];
        order.iter().enumerate().for_each(|(i, &x)| number[x] = i);
        let atom: Vec<usize> = order.iter().map(|&x| atom_of_slot(x)).collect();
        let mut spokes = vec![0; sheet.points().len()];
        atom.iter().for_each(|&m| spokes[m] += 1);
        Self {
            vertex_of_slot: roots.iter().map(|&r| number[r]).collect(),
            atom,
            spokes,
        }
    }

    /// Boundary triangle `2t` is side `+` of medial triangle `t`, `2t + 1` side `−` (reversed).
    pub(super) fn boundary_triangles(&self, n_triangles: usize) -> Vec<[usize; 3]> {
        let v = |t, s, k| self.vertex_of_slot[slot(t, s, k)];
        (0..n_triangles)
            .flat_map(|t| {
                [
                    [v(t, 0, 0), v(t, 0, 1), v(t, 0, 2)],
                    [v(t, 1, 0), v(t, 1, 2), v(t, 1, 1)],
                ]
            })
            .collect()
    }

    /// The unit spoke direction of every boundary vertex: along its free edges if it has any,
    /// `−∇r ± sqrt(1 − |∇r|²)·n` inside a sheet (two regions, no crease edge), else the
    /// region's normal (the bisector at a seam).
    pub(super) fn spokes(
        &self,
        sheet: &MedialSheet,
        edges: &Edges,
        geometry: &SheetGeometry,
    ) -> Result<Vec<Vec3>> {
        let normal = self.region_normals(geometry);
        let free = self.free_edge_directions(sheet, edges);
        let has_crease = edges.has_crease(sheet.points().len());
        let mut steep = Vec::new();
        let spokes = (0..self.atom.len())
            .map(|b| {
                let m = self.atom[b];
                if free[b] != Vec3::zeros() {
                    unit(free[b], m)
                } else if self.spokes[m] == 2 && !has_crease[m] {
                    let n = unit(normal[b], m)?;
                    let g = geometry.gradient[m] - geometry.gradient[m].dot(&n) * n;
                    if g.norm() >= 1.0 {
                        steep.push((m, g.norm()));
                    }
                    Ok(-g + (1.0 - g.norm_squared()).max(0.0).sqrt() * n)
                } else {
                    unit(normal[b], m)
                }
            })
            .collect::<Result<Vec<_>>>()?;
        if steep.is_empty() {
            Ok(spokes)
        } else {
            Err(steep_radius_error(steep))
        }
    }

    /// The direction of every boundary vertex as the radius limit sees it
    /// ([`super::limit::focal_bounds`]): its spoke without the tilt by the radius gradient, i.e.
    /// along its free edges if it has any, else the region's unit normal (the bisector at a
    /// seam). It depends on the sheet's shape only, not on its radius.
    pub(super) fn fold_directions(
        &self,
        sheet: &MedialSheet,
        edges: &Edges,
        geometry: &SheetGeometry,
    ) -> Result<Vec<Vec3>> {
        let normal = self.region_normals(geometry);
        let free = self.free_edge_directions(sheet, edges);
        (0..self.atom.len())
            .map(|b| {
                let m = self.atom[b];
                if free[b] != Vec3::zeros() {
                    unit(free[b], m)
                } else {
                    unit(normal[b], m)
                }
            })
            .collect()
    }

    /// The angle-weighted normal of every region: `Σ α_t(m) · (±n̂_t)` over the corners glued
    /// into it, with `+n̂_t` for side `+` and `−n̂_t` for side `−`.
    pub(super) fn region_normals(&self, geometry: &SheetGeometry) -> Vec<Vec3> {
        let mut normal = vec![Vec3::zeros(); self.atom.len()];
        for (x, &b) in self.vertex_of_slot.iter().enumerate() {
            let (t, side, k) = (x / 6, (x / 3) % 2, x % 3);
            let sign = if side == 0 { 1.0 } else { -1.0 };
            normal[b] += sign * geometry.angle[t][k] * geometry.normal[t];
        }
        normal
    }

    /// The sum of the outward in-plane perpendiculars of the free edges of every region
    /// (zero for regions without free edges).
    pub(super) fn free_edge_directions(&self, sheet: &MedialSheet, edges: &Edges) -> Vec<Vec3> {
        let mut free = vec![Vec3::zeros(); self.atom.len()];
        for (e, &(a, b)) in edges.ends.iter().enumerate() {
            if let [m] = edges.fans[e].as_slice() {
                let tri = &sheet.triangles()[m.tri];
                for (v, w) in [(a, b), (b, a)] {
                    free[self.vertex_of_slot[slot(m.tri, 0, corner_of(tri, v))]] +=
                        outward_perpendicular(sheet.points(), v, w, third(tri, v, w));
                }
            }
        }
        free
    }
}

/// The error for regions whose radius gradient `|∇r| ≥ 1` (atom, |∇r|), in atom order.
pub(super) fn steep_radius_error(mut steep: Vec<(usize, f64)>) -> Error {
    steep.dedup_by_key(|s| s.0);
    let list: Vec<String> = steep
        .iter()
        .take(LIST_MAX)
        .map(|(m, g)| format!("{m} (|∇r| = {g:.3})"))
        .collect();
    Error::InvalidTemplate(format!(
        "the radius changes faster than distance along the sheet (|∇r| ≥ 1) at {} medial \
         vertices: {}; no object has such a medial sheet",
        steep.len(),
        list.join(", ")
    ))
}

/// The pairs of (side, side2, triangle, triangle2) glued across edge `e`: at a free edge the two
/// sides of its triangle; otherwise, with the triangles sorted by angle about the edge, the side
/// of each that faces the next one and the side of the next that faces back.
pub(super) fn facing_pairs(
    sheet: &MedialSheet,
    edges: &Edges,
    e: usize,
) -> Vec<(usize, usize, usize, usize)> {
    let fan = &edges.fans[e];
    if let [m] = fan.as_slice() {
        return vec![(0, 1, m.tri, m.tri)];
    }
    let order = angular_order(sheet, edges.ends[e], fan);
    // A triangle running a → b has its normal along e × (c − a): its + side faces the next
    // triangle counter-clockwise about e = b − a.
    let facing_next = |m: &Member| if m.forward { 0 } else { 1 };
    (0..order.len())
        .map(|i| {
            let (cur, next) = (&order[i], &order[(i + 1) % order.len()]);
            (facing_next(cur), 1 - facing_next(next), cur.tri, next.tri)
        })
        .collect()
}

/// The triangles of a fan sorted by the angle of their third vertex counter-clockwise about the
/// edge direction `b − a`, starting at the first triangle.
pub(super) fn angular_order(
    sheet: &MedialSheet,
    (a, b): (usize, usize),
    fan: &[Member],
) -> Vec<Member> {
    let p = sheet.points();
    let axis = (p[b] - p[a]).normalize();
    let off = |m: &Member| {
        let d = p[third(&sheet.triangles()[m.tri], a, b)] - p[a];
        d - d.dot(&axis) * axis
    };
    let u = off(&fan[0]).normalize();
    let w = axis.cross(&u);
    let angle = |m: &Member| {
        let d = off(m);
        d.dot(&w)
            .atan2(d.dot(&u))
            .rem_euclid(2.0 * std::f64::consts::PI)
    };
    let mut keyed: Vec<(f64, Member)> = fan.iter().map(|m| (angle(m), *m)).collect();
    keyed.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.tri.cmp(&y.1.tri)));
    keyed.into_iter().map(|(_, m)| m).collect()
}

/// The unit direction in the plane of triangle `(v, w, c)`, perpendicular to the free edge
/// `v–w` and pointing away from `c`.
pub(super) fn outward_perpendicular(points: &[Vec3], v: usize, w: usize, c: usize) -> Vec3 {
    let e = points[w] - points[v];
    let d = points[c] - points[v];
    -(d - d.dot(&e) / e.norm_squared() * e).normalize()
}

pub(super) fn unit(v: Vec3, atom: usize) -> Result<Vec3> {
    let n = v.norm();
    if n > 1e-12 {
        Ok(v / n)
    } else {
        Err(Error::InvalidTemplate(format!(
            "no spoke direction at medial vertex {atom}: the sheets around it cancel out"
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn union_find_roots_are_smallest() {
        let mut uf = UnionFind::new(6);
        uf.union(4, 2);
        uf.union(5, 4);
        uf.union(1, 3);
        assert_eq!(
            [uf.find(5), uf.find(4), uf.find(3), uf.find(0)],
            [2, 2, 1, 0]
        );
    }
}
