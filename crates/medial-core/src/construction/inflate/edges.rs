//! The undirected edges of a medial sheet with the triangles around each: free edges, interior
//! edges and seams, and the edge points of Loop subdivision.

use std::collections::{BTreeMap, HashMap};

use crate::{Error, Result};

/// A triangle containing an edge `(a, b)`, `a < b`, and whether it runs `a → b`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Member {
    pub(super) tri: usize,
    pub(super) forward: bool,
}

/// The undirected edges of a triangle list, each with the triangles that contain it.
pub(super) struct Edges {
    /// Edge `e` joins `ends[e] = (a, b)`, `a < b`; edges in ascending order.
    pub(super) ends: Vec<(usize, usize)>,
    /// The triangles containing edge `e`, in ascending triangle order.
    pub(super) fans: Vec<Vec<Member>>,
    /// The edge index of `(a, b)`, `a < b`.
    pub(super) index: HashMap<(usize, usize), usize>,
}

/// The key `(min, max)` of an undirected edge.
pub(super) fn edge_key(a: usize, b: usize) -> (usize, usize) {
    (a.min(b), a.max(b))
}

/// The kind of a crease edge (an edge not in exactly two triangles).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Crease {
    Free,
    Seam,
}

impl Edges {
    pub(super) fn new(triangles: &[[usize; 3]]) -> Self {
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

    pub(super) fn len(&self) -> usize {
        self.ends.len()
    }

    pub(super) fn crease(&self, e: usize) -> Option<Crease> {
        match self.fans[e].len() {
            1 => Some(Crease::Free),
            2 => None,
            _ => Some(Crease::Seam),
        }
    }

    pub(super) fn check_at_most_seams(&self) -> Result<()> {
        match (0..self.len()).find(|&e| self.fans[e].len() > 3) {
            Some(e) => {
                let tris: Vec<usize> = self.fans[e].iter().map(|m| m.tri).collect();
                Err(Error::InvalidMesh(format!(
                    "medial edge {:?} is in {n} triangles {tris:?}: {n} sheets meet along it, and \
                     at most 3 can (a seam, whose atoms have three spokes)",
                    self.ends[e],
                    n = tris.len()
                )))
            }
            None => Ok(()),
        }
    }

    /// Refuses triangles with two or more free edges: both sides of such a triangle would be
    /// glued at all three corners and collapse onto each other.
    pub(super) fn check_no_ears(&self, triangles: &[[usize; 3]]) -> Result<()> {
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
    pub(super) fn neighbours(&self, n: usize) -> Vec<Vec<usize>> {
        let mut out = vec![Vec::new(); n];
        for &(a, b) in &self.ends {
            out[a].push(b);
            out[b].push(a);
        }
        out
    }

    /// Whether every vertex has a crease edge (free edge or seam).
    pub(super) fn has_crease(&self, n: usize) -> Vec<bool> {
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
    pub(super) fn creases(&self, n: usize) -> Vec<Vec<(usize, Crease)>> {
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
    pub(super) fn edge_stencil(&self, e: usize, triangles: &[[usize; 3]]) -> Vec<(usize, f64)> {
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
pub(super) fn third(tri: &[usize; 3], a: usize, b: usize) -> usize {
    tri.iter()
        .copied()
        .find(|&v| v != a && v != b)
        .unwrap_or(tri[0])
}

/// The position (0, 1, 2) of vertex `v` in a triangle that contains it.
pub(super) fn corner_of(tri: &[usize; 3], v: usize) -> usize {
    tri.iter().position(|&c| c == v).unwrap_or(0)
}
