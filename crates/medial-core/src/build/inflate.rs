//! Templates from a medial sheet: Loop subdivision of the sheet and inflation (SPEC §9).
//!
//! A *medial sheet* is a triangle mesh of medial points `x_m` (mm) with a radius `r_m > 0` (mm)
//! per vertex. It may be non-manifold: an edge in one triangle is a *free edge*, in two an
//! ordinary interior edge, in three a *seam* where three sheets meet.
//!
//! *Inflation* turns every (triangle, side) of the sheet into one boundary triangle. Corners of
//! these triangles are glued into one boundary vertex when they belong to the same medial vertex
//! and face the same region of the object, so that a medial vertex becomes an atom with one
//! spoke on a free edge, two inside a sheet and three on a seam. The boundary vertex of an atom
//! `m` in region `R` sits at `x_m + r_m·U` where the unit spoke direction `U` is
//! - `−∇r ± sqrt(1 − |∇r|²)·n` inside a sheet (`∇r` the surface gradient of the radius, `n` the
//!   unit normal facing `R`): the exact spoke of a medial sheet whose radius is linear;
//! - the outward in-plane direction (perpendicular to the free edges, away from the sheet) at a
//!   free edge;
//! - the bisector of the region (the normalised angle-weighted normal of the sheets around it)
//!   at a seam.
//!
//! The result is an approximately medial template; projection under the constraints of §3 makes
//! it exact. Inflation refuses to return a boundary that is open, non-manifold, inward oriented
//! or self-intersecting, and says near which medial vertices the problem is.

use std::collections::{BTreeMap, HashMap};

use crate::mesh::topology::{check_closed_oriented_manifold, MeshDefect};
use crate::mesh::Bounds;
use crate::{Error, Result, TriMesh, Vec3};

/// A triangle counts as degenerate when `|e₁ × e₂| ≤ DEGENERATE · (longest edge)²`.
const DEGENERATE: f64 = 1e-12;

/// Distances to a plane below `SNAP · (diagonal of the bounding box)` count as zero in the
/// triangle–triangle intersection test.
const SNAP: f64 = 1e-10;

/// At most this many medial vertices are listed in an error message.
const LIST_MAX: usize = 12;

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

    /// The medial points (mm).
    pub fn points(&self) -> &[Vec3] {
        self.mesh.points()
    }

    /// The triangles, as corner indices into [`Self::points`].
    pub fn triangles(&self) -> &[[usize; 3]] {
        self.mesh.triangles()
    }

    /// The radius of every medial point (mm).
    pub fn radius(&self) -> &[f64] {
        &self.radius
    }
}

/// The result of [`inflate`]: a closed boundary mesh and its medial structure, ready for
/// `MedialTemplate::new(boundary, medial_index, medial_points)`.
///
/// Boundary triangle `2t` is the `+` side of medial triangle `t` (same orientation, outward along
/// its normal), `2t + 1` its `−` side (reversed). Boundary points are sorted by atom, so the
/// spokes of every atom have consecutive ascending indices and atom 0's come first; within an
/// atom, regions are in the order of their first corner `(triangle, side, corner)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Inflated {
    /// The closed, outward oriented, self-intersection free boundary mesh (mm).
    pub boundary: TriMesh,
    /// The atom (medial vertex) of every boundary point.
    pub medial_index: Vec<usize>,
    /// The medial point of every atom: atom `m` is medial vertex `m` of the sheet (mm).
    pub medial_points: Vec<Vec3>,
}

impl Inflated {
    /// Volume enclosed by the boundary (mm³), by the divergence theorem:
    /// `V = Σ_triangles p₀ · (p₁ × p₂) / 6`.
    pub fn volume(&self) -> f64 {
        signed_volumes(&self.boundary, &vec![0; self.boundary.points().len()], 1)[0]
    }
}

/// Inflates a medial sheet into a boundary mesh with one boundary vertex per (medial vertex,
/// region); see the module documentation for the gluing rules and spoke directions.
///
/// Errors (`InvalidTemplate`, naming the medial vertices or triangles involved): a triangle with
/// two or three free edges (its sides would collapse), a radius gradient `|∇r| ≥ 1` inside a
/// sheet, and a boundary that is not a closed, vertex-manifold, outward oriented surface free of
/// degenerate triangles and self-intersections (a radius too large for the curvature).
pub fn inflate(sheet: &MedialSheet) -> Result<Inflated> {
    let edges = Edges::new(sheet.triangles());
    edges.check_no_ears(sheet.triangles())?;
    let regions = Regions::glue(sheet, &edges);
    let geometry = SheetGeometry::new(sheet);
    let spokes = regions.spokes(sheet, &edges, &geometry)?;
    let points = regions
        .atom
        .iter()
        .zip(&spokes)
        .map(|(&m, u)| sheet.points()[m] + sheet.radius()[m] * u)
        .collect();
    let boundary = TriMesh::new(points, regions.boundary_triangles(sheet.triangles().len()))?;
    check_boundary(&boundary, &regions.atom)?;
    Ok(Inflated {
        boundary,
        medial_index: regions.atom,
        medial_points: sheet.points().to_vec(),
    })
}

// ---------------------------------------------------------------------------------------------
// Sheet validation

fn check_radii(radius: &[f64]) -> Result<()> {
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

fn check_non_degenerate(mesh: &TriMesh) -> Result<()> {
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

fn check_all_points_used(mesh: &TriMesh) -> Result<()> {
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

fn check_distinct_triangles(triangles: &[[usize; 3]]) -> Result<()> {
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

// ---------------------------------------------------------------------------------------------
// Edge topology

/// A triangle containing an edge `(a, b)`, `a < b`, and whether it runs `a → b`.
#[derive(Clone, Copy, Debug)]
struct Member {
    tri: usize,
    forward: bool,
}

/// The undirected edges of a triangle list, each with the triangles that contain it.
struct Edges {
    /// Edge `e` joins `ends[e] = (a, b)`, `a < b`; edges in ascending order.
    ends: Vec<(usize, usize)>,
    /// The triangles containing edge `e`, in ascending triangle order.
    fans: Vec<Vec<Member>>,
    /// The edge index of `(a, b)`, `a < b`.
    index: HashMap<(usize, usize), usize>,
}

/// The key `(min, max)` of an undirected edge.
fn edge_key(a: usize, b: usize) -> (usize, usize) {
    (a.min(b), a.max(b))
}

/// The kind of a crease edge (an edge not in exactly two triangles).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Crease {
    Free,
    Seam,
}

impl Edges {
    fn new(triangles: &[[usize; 3]]) -> Self {
        let mut map: BTreeMap<(usize, usize), Vec<Member>> = BTreeMap::new();
        for (t, tri) in triangles.iter().enumerate() {
            for k in 0..3 {
                let (u, v) = (tri[k], tri[(k + 1) % 3]);
                map.entry(edge_key(u, v)).or_default().push(Member {
                    tri: t,
                    forward: u < v,
                });
            }
        }
        let (ends, fans): (Vec<_>, Vec<_>) = map.into_iter().unzip();
        let index = ends.iter().enumerate().map(|(e, &key)| (key, e)).collect();
        Self { ends, fans, index }
    }

    fn len(&self) -> usize {
        self.ends.len()
    }

    fn crease(&self, e: usize) -> Option<Crease> {
        match self.fans[e].len() {
            1 => Some(Crease::Free),
            2 => None,
            _ => Some(Crease::Seam),
        }
    }

    fn check_at_most_seams(&self) -> Result<()> {
        match (0..self.len()).find(|&e| self.fans[e].len() > 3) {
            Some(e) => {
                let tris: Vec<usize> = self.fans[e].iter().map(|m| m.tri).collect();
                Err(Error::InvalidMesh(format!(
                    "medial edge {:?} is in {} triangles {tris:?}; at most 3 (a seam) are allowed",
                    self.ends[e],
                    tris.len()
                )))
            }
            None => Ok(()),
        }
    }

    /// Refuses triangles with two or more free edges: both sides of such a triangle would be
    /// glued at all three corners and collapse onto each other.
    fn check_no_ears(&self, triangles: &[[usize; 3]]) -> Result<()> {
        let mut free = vec![0usize; triangles.len()];
        for fan in self.fans.iter().filter(|f| f.len() == 1) {
            free[fan[0].tri] += 1;
        }
        match free.iter().position(|&f| f >= 2) {
            Some(t) => Err(Error::InvalidTemplate(format!(
                "medial triangle {t} {:?} has {} free edges: its two sides would collapse onto \
                 each other; split it or triangulate the corner differently",
                triangles[t], free[t]
            ))),
            None => Ok(()),
        }
    }

    /// The distinct neighbours of every vertex, ascending.
    fn neighbours(&self, n: usize) -> Vec<Vec<usize>> {
        let mut out = vec![Vec::new(); n];
        for &(a, b) in &self.ends {
            out[a].push(b);
            out[b].push(a);
        }
        out
    }

    /// Whether every vertex has a crease edge (free edge or seam).
    fn has_crease(&self, n: usize) -> Vec<bool> {
        let mut out = vec![false; n];
        for (e, &(a, b)) in self.ends.iter().enumerate() {
            if self.crease(e).is_some() {
                out[a] = true;
                out[b] = true;
            }
        }
        out
    }

    /// The crease edges of every vertex: (other end, kind).
    fn creases(&self, n: usize) -> Vec<Vec<(usize, Crease)>> {
        let mut out = vec![Vec::new(); n];
        for (e, &(a, b)) in self.ends.iter().enumerate() {
            if let Some(kind) = self.crease(e) {
                out[a].push((b, kind));
                out[b].push((a, kind));
            }
        }
        out
    }

    /// Loop's edge point: `3/8 (a + b) + 1/8 (c + d)` inside a sheet, `1/2 (a + b)` on a crease.
    fn edge_stencil(&self, e: usize, triangles: &[[usize; 3]]) -> Vec<(usize, f64)> {
        let (a, b) = self.ends[e];
        match self.fans[e].as_slice() {
            [s, t] => vec![
                (a, 0.375),
                (b, 0.375),
                (third(&triangles[s.tri], a, b), 0.125),
                (third(&triangles[t.tri], a, b), 0.125),
            ],
            _ => vec![(a, 0.5), (b, 0.5)],
        }
    }
}

/// The corner of a triangle that is neither `a` nor `b`.
fn third(tri: &[usize; 3], a: usize, b: usize) -> usize {
    tri.iter()
        .copied()
        .find(|&v| v != a && v != b)
        .unwrap_or(tri[0])
}

/// The position (0, 1, 2) of vertex `v` in a triangle that contains it.
fn corner_of(tri: &[usize; 3], v: usize) -> usize {
    tri.iter().position(|&c| c == v).unwrap_or(0)
}

/// Loop's vertex stencil (see [`MedialSheet::loop_subdivide`]).
fn vertex_stencil(
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

fn combine(stencil: &[(usize, f64)], points: &[Vec3]) -> Vec3 {
    stencil.iter().map(|&(i, w)| w * points[i]).sum()
}

// ---------------------------------------------------------------------------------------------
// Gluing corners into regions

/// The slot of corner `k` of side `s` (0: `+`, 1: `−`) of medial triangle `t`.
fn slot(t: usize, side: usize, k: usize) -> usize {
    6 * t + 3 * side + k
}

/// Union-find over slots, with path halving; the root of a set is its smallest slot.
struct UnionFind(Vec<usize>);

impl UnionFind {
    fn new(n: usize) -> Self {
        Self((0..n).collect())
    }

    fn find(&mut self, mut x: usize) -> usize {
        while self.0[x] != x {
            self.0[x] = self.0[self.0[x]];
            x = self.0[x];
        }
        x
    }

    fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        self.0[ra.max(rb)] = ra.min(rb);
    }
}

/// The boundary vertices: one per (medial vertex, region).
struct Regions {
    /// The boundary vertex of every slot.
    vertex_of_slot: Vec<usize>,
    /// The atom (medial vertex) of every boundary vertex, ascending.
    atom: Vec<usize>,
    /// The number of regions (spokes) of every medial vertex.
    spokes: Vec<usize>,
}

impl Regions {
    /// Glues slots across every medial edge and numbers the resulting regions by
    /// (atom, first slot).
    fn glue(sheet: &MedialSheet, edges: &Edges) -> Self {
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
    fn boundary_triangles(&self, n_triangles: usize) -> Vec<[usize; 3]> {
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
    fn spokes(
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

    /// The angle-weighted normal of every region: `Σ α_t(m) · (±n̂_t)` over the corners glued
    /// into it, with `+n̂_t` for side `+` and `−n̂_t` for side `−`.
    fn region_normals(&self, geometry: &SheetGeometry) -> Vec<Vec3> {
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
    fn free_edge_directions(&self, sheet: &MedialSheet, edges: &Edges) -> Vec<Vec3> {
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
fn steep_radius_error(mut steep: Vec<(usize, f64)>) -> Error {
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
fn facing_pairs(sheet: &MedialSheet, edges: &Edges, e: usize) -> Vec<(usize, usize, usize, usize)> {
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
fn angular_order(sheet: &MedialSheet, (a, b): (usize, usize), fan: &[Member]) -> Vec<Member> {
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
fn outward_perpendicular(points: &[Vec3], v: usize, w: usize, c: usize) -> Vec3 {
    let e = points[w] - points[v];
    let d = points[c] - points[v];
    -(d - d.dot(&e) / e.norm_squared() * e).normalize()
}

fn unit(v: Vec3, atom: usize) -> Result<Vec3> {
    let n = v.norm();
    if n > 1e-12 {
        Ok(v / n)
    } else {
        Err(Error::InvalidTemplate(format!(
            "no spoke direction at medial vertex {atom}: the sheets around it cancel out"
        )))
    }
}

// ---------------------------------------------------------------------------------------------
// Sheet geometry

/// Per-triangle and per-vertex geometry of a sheet.
struct SheetGeometry {
    /// Unit normal `(p₁ − p₀) × (p₂ − p₀) / |…|` of every triangle.
    normal: Vec<Vec3>,
    /// The interior angle at every corner (radians).
    angle: Vec<[f64; 3]>,
    /// The surface gradient of the radius at every vertex: the area-weighted mean of the
    /// gradients of the linear interpolant on its triangles.
    gradient: Vec<Vec3>,
}

impl SheetGeometry {
    fn new(sheet: &MedialSheet) -> Self {
        let n = sheet.points().len();
        let mut gradient = vec![Vec3::zeros(); n];
        let mut weight = vec![0.0; n];
        let mut normal = Vec::with_capacity(sheet.triangles().len());
        let mut angle = Vec::with_capacity(sheet.triangles().len());
        for tri in sheet.triangles() {
            let p = corners(sheet.points(), tri);
            let r = tri.map(|v| sheet.radius()[v]);
            let cross = (p[1] - p[0]).cross(&(p[2] - p[0]));
            let area = 0.5 * cross.norm();
            let g = triangle_gradient(&p, &r);
            for &v in tri {
                gradient[v] += area * g;
                weight[v] += area;
            }
            normal.push(cross / (2.0 * area));
            angle.push(corner_angles(&p));
        }
        gradient.iter_mut().zip(&weight).for_each(|(g, w)| *g /= *w);
        Self {
            normal,
            angle,
            gradient,
        }
    }
}

/// The gradient of the linear interpolant of values `r` on triangle `p`:
/// `∇r = Σᵢ rᵢ n̂ × (p_{i+2} − p_{i+1}) / (2A)`.
fn triangle_gradient(p: &[Vec3; 3], r: &[f64; 3]) -> Vec3 {
    let cross = (p[1] - p[0]).cross(&(p[2] - p[0]));
    let n2a = cross / cross.norm_squared(); // n̂ / (2A)
    (0..3)
        .map(|i| r[i] * n2a.cross(&(p[(i + 2) % 3] - p[(i + 1) % 3])))
        .sum()
}

fn corner_angles(p: &[Vec3; 3]) -> [f64; 3] {
    std::array::from_fn(|i| (p[(i + 1) % 3] - p[i]).angle(&(p[(i + 2) % 3] - p[i])))
}

fn corners(points: &[Vec3], tri: &[usize; 3]) -> [Vec3; 3] {
    tri.map(|v| points[v])
}

fn is_degenerate(p: &[Vec3; 3]) -> bool {
    let longest = (0..3)
        .map(|i| (p[(i + 1) % 3] - p[i]).norm_squared())
        .fold(0.0, f64::max);
    (p[1] - p[0]).cross(&(p[2] - p[0])).norm() <= DEGENERATE * longest
}

// ---------------------------------------------------------------------------------------------
// Boundary checks

/// The sorted distinct atoms of some boundary points, as "3, 7, 12" (at most [`LIST_MAX`]).
fn atoms_of(points: impl IntoIterator<Item = usize>, medial_index: &[usize]) -> String {
    let mut atoms: Vec<usize> = points.into_iter().map(|b| medial_index[b]).collect();
    atoms.sort_unstable();
    atoms.dedup();
    let mut list: Vec<String> = atoms.iter().take(LIST_MAX).map(usize::to_string).collect();
    if atoms.len() > LIST_MAX {
        list.push(format!("… ({} in all)", atoms.len()));
    }
    list.join(", ")
}

fn check_boundary(mesh: &TriMesh, medial_index: &[usize]) -> Result<()> {
    check_boundary_degenerate(mesh, medial_index)?;
    check_closed_manifold(mesh, medial_index)?;
    check_outward(mesh, medial_index)?;
    check_self_intersections(mesh, medial_index)
}

fn check_boundary_degenerate(mesh: &TriMesh, medial_index: &[usize]) -> Result<()> {
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
fn check_closed_manifold(mesh: &TriMesh, medial_index: &[usize]) -> Result<()> {
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
fn traverses(tri: &[usize; 3], a: usize, b: usize) -> bool {
    (0..3).any(|k| tri[k] == a && tri[(k + 1) % 3] == b)
}

/// Signed volume `Σ p₀ · (p₁ × p₂) / 6` of every component (points relative to their mean).
fn signed_volumes(mesh: &TriMesh, component: &[usize], n_components: usize) -> Vec<f64> {
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
fn check_outward(mesh: &TriMesh, medial_index: &[usize]) -> Result<()> {
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

fn check_self_intersections(mesh: &TriMesh, medial_index: &[usize]) -> Result<()> {
    let pairs = self_intersections(mesh);
    if pairs.is_empty() {
        return Ok(());
    }
    let tri = |f: usize| mesh.triangles()[f];
    let points = pairs
        .iter()
        .flat_map(|&(f, g)| tri(f).into_iter().chain(tri(g)));
    Err(Error::InvalidTemplate(format!(
        "the inflated boundary intersects itself ({} pairs of triangles, e.g. boundary triangles \
         {} and {}): radius too large for the curvature near medial vertices {} (or for the \
         angle between the sheets there, at a seam); lower the radius or refine the sheet",
        pairs.len(),
        pairs[0].0,
        pairs[0].1,
        atoms_of(points, medial_index)
    )))
}

// ---------------------------------------------------------------------------------------------
// Self-intersection test

/// The pairs of boundary triangles `(f, g)`, `f < g`, that intersect: sharing no vertex and
/// meeting anywhere, or sharing one vertex and meeting elsewhere (the edge opposite the shared
/// vertex of one crosses the other). Broad phase: a uniform grid of cubes about the mean
/// triangle size; each candidate pair is tested once, in the cell of the lower corner of the
/// intersection of their boxes.
fn self_intersections(mesh: &TriMesh) -> Vec<(usize, usize)> {
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

fn pair_intersects(fi: [usize; 3], gi: [usize; 3], f: &[Vec3; 3], g: &[Vec3; 3], tol: f64) -> bool {
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
fn plane_distances<const N: usize>(points: &[Vec3; N], tri: &[Vec3; 3], tol: f64) -> [f64; N] {
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

fn all_strictly_same_side(d: &[f64]) -> bool {
    d.iter().all(|&x| x > 0.0) || d.iter().all(|&x| x < 0.0)
}

/// Whether two triangles (closed sets) meet (Möller's interval test; coplanar pairs in 2-D).
fn triangles_intersect(a: &[Vec3; 3], b: &[Vec3; 3], tol: f64) -> bool {
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
fn plane_interval(tri: &[Vec3; 3], d: &[f64; 3], dir: &Vec3) -> (f64, f64) {
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
fn segment_meets_triangle(p: Vec3, q: Vec3, tri: &[Vec3; 3], tol: f64) -> bool {
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

type P2 = nalgebra::Vector2<f64>;

/// Projects points onto the coordinate plane most nearly perpendicular to `n`.
fn project<const N: usize>(points: &[Vec3; N], n: &Vec3) -> [P2; N] {
    let drop = n.iamax();
    let (i, j) = ((drop + 1) % 3, (drop + 2) % 3);
    points.map(|p| P2::new(p[i], p[j]))
}

fn coplanar_triangles_meet(a: &[Vec3; 3], b: &[Vec3; 3], n: &Vec3) -> bool {
    let (a2, b2) = (project(a, n), project(b, n));
    let edges_cross = (0..3)
        .any(|i| (0..3).any(|j| segments_meet_2d(a2[i], a2[(i + 1) % 3], b2[j], b2[(j + 1) % 3])));
    edges_cross || point_in_triangle_2d(a2[0], &b2) || point_in_triangle_2d(b2[0], &a2)
}

fn orient_2d(a: P2, b: P2, c: P2) -> f64 {
    (b - a).perp(&(c - a))
}

fn point_in_triangle_2d(x: P2, t: &[P2; 3]) -> bool {
    let s = [
        orient_2d(t[0], t[1], x),
        orient_2d(t[1], t[2], x),
        orient_2d(t[2], t[0], x),
    ];
    s.iter().all(|&v| v >= 0.0) || s.iter().all(|&v| v <= 0.0)
}

/// Whether two closed segments meet (collinear ones when their extents overlap).
fn segments_meet_2d(p1: P2, p2: P2, q1: P2, q2: P2) -> bool {
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
    fn triangle_gradient_matches_finite_differences() {
        let p = [v(0.3, -0.2, 0.1), v(2.1, 0.4, -0.5), v(0.7, 1.9, 0.8)];
        let r = [1.2, 0.7, 2.3];
        let g = triangle_gradient(&p, &r);
        // The linear interpolant at barycentric coordinates (1 − s − t, s, t).
        let point = |s: f64, t: f64| p[0] + s * (p[1] - p[0]) + t * (p[2] - p[0]);
        let value = |s: f64, t: f64| r[0] + s * (r[1] - r[0]) + t * (r[2] - r[0]);
        let h = 1e-6;
        for (ds, dt) in [(1.0, 0.0), (0.0, 1.0), (0.6, -0.3)] {
            let fd =
                (value(0.3 + h * ds, 0.3 + h * dt) - value(0.3 - h * ds, 0.3 - h * dt)) / (2.0 * h);
            let step =
                (point(0.3 + h * ds, 0.3 + h * dt) - point(0.3 - h * ds, 0.3 - h * dt)) / (2.0 * h);
            assert!(
                (g.dot(&step) - fd).abs() < 1e-8,
                "direction ({ds}, {dt}): {} vs {fd}",
                g.dot(&step)
            );
        }
        let n = (p[1] - p[0]).cross(&(p[2] - p[0]));
        assert!(
            g.dot(&n).abs() < 1e-12 * n.norm(),
            "the gradient lies in the plane"
        );
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

    fn tetrahedron(inward: bool) -> TriMesh {
        let p = vec![
            v(0.0, 0.0, 0.0),
            v(1.0, 0.0, 0.0),
            v(0.0, 1.0, 0.0),
            v(0.0, 0.0, 1.0),
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
        assert!(check_boundary(&tetrahedron(false), &index).is_ok());
        let e = check_boundary(&tetrahedron(true), &index)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("faces inward") && e.contains("medial vertices 0, 1, 2, 3"),
            "{e}"
        );
        let (p, mut t) = tetrahedron(false).into_parts();
        t.pop();
        let e = check_boundary(&TriMesh::new(p.clone(), t).unwrap(), &index)
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a closed oriented surface"), "{e}");
        // Two tetrahedra glued at one vertex: closed edges, pinched vertex.
        let mut p2 = p.clone();
        p2.extend([v(-1.0, 0.0, 0.0), v(0.0, -1.0, 0.0), v(0.0, 0.0, -1.0)]);
        let mut t2 = tetrahedron(false).into_parts().1;
        t2.extend([[0, 4, 5], [0, 6, 4], [4, 6, 5], [0, 5, 6]]);
        let e = check_boundary(&TriMesh::new(p2, t2).unwrap(), &[0, 1, 2, 3, 4, 5, 6])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("boundary point 0 (medial vertex 0) is pinched"),
            "{e}"
        );
    }

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
