//! Loop tangent operators of a closed boundary mesh (docs/method.md §2.4).
//!
//! For a vertex `b` of valence `n` with one-ring `v_0 … v_{n−1}` walked counter-clockwise about
//! the outward normal from its smallest neighbour ([`crate::mesh::topology::vertex_rings`]):
//!
//! ```text
//! (W¹q)_b = Σ_j cos(2πj/n) q_{v_j},   (W²q)_b = Σ_j sin(2πj/n) q_{v_j},
//! n̂_b = (W¹q)_b × (W²q)_b / |(W¹q)_b × (W²q)_b|.
//! ```
//!
//! The two tangents span the tangent plane of the Loop limit surface at `b`; with the ring
//! counter-clockwise about the outward normal, `n̂_b` points outward. Border vertices of open
//! meshes would need Loop's border rule; medial templates are closed, so open meshes are refused.

use crate::mesh::topology::MeshDefect;
use crate::Vec3;
use sprs::{CsMat, TriMat};

/// The weights of one row of `W¹` and `W²`, in ring order.
#[derive(Clone, Copy, Debug)]
pub struct Stencil<'a> {
    /// The one-ring `v_0 … v_{n−1}`.
    pub neighbours: &'a [usize],
    /// `cos(2πj/n)`, the weights of `W¹`.
    pub w1: &'a [f64],
    /// `sin(2πj/n)`, the weights of `W²`.
    pub w2: &'a [f64],
}

/// The sparse `nb × nb` Loop tangent operators `W¹`, `W²` of a closed boundary mesh, stored
/// as their rows ([`Stencil`]).
#[derive(Clone, Debug)]
pub struct LoopTangents {
    /// Ring of vertex `b`: `neighbours[offsets[b]..offsets[b + 1]]`.
    offsets: Vec<usize>,
    neighbours: Vec<usize>,
    cos: Vec<f64>,
    sin: Vec<f64>,
}

impl LoopTangents {
    /// Builds `W¹`, `W²` from the one-rings of the vertices of a closed, consistently oriented
    /// mesh, as [`crate::mesh::topology::vertex_rings`] walks them. Refuses a vertex of valence
    /// below 3 (no tangent plane), naming it ([`MeshDefect::LowValence`]).
    pub fn new(rings: &[Vec<usize>]) -> Result<Self, MeshDefect> {
        if let Some((v, ring)) = rings.iter().enumerate().find(|(_, r)| r.len() < 3) {
            return Err(MeshDefect::LowValence {
                vertex: v,
                ring: ring.clone(),
            });
        }
        let mut offsets = Vec::with_capacity(rings.len() + 1);
        offsets.push(0);
        let (mut neighbours, mut cos, mut sin) = (Vec::new(), Vec::new(), Vec::new());
        for ring in rings {
            let n = ring.len() as f64;
            for (j, &v) in ring.iter().enumerate() {
                let angle = std::f64::consts::TAU * j as f64 / n;
                neighbours.push(v);
                cos.push(angle.cos());
                sin.push(angle.sin());
            }
            offsets.push(neighbours.len());
        }
        Ok(Self {
            offsets,
            neighbours,
            cos,
            sin,
        })
    }

    /// Number of boundary vertices `nb` (rows and columns of `W¹`, `W²`).
    pub fn len(&self) -> usize {
        self.offsets.len() - 1
    }

    /// True for an operator over no vertices (never for a valid mesh).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// `W¹` as a sparse matrix (CSR, `nb × nb`, built on each call): entry
    /// `(b, v_j) = cos(2πj/n_b)`.
    pub fn w1(&self) -> CsMat<f64> {
        self.sparse(&self.cos)
    }

    /// `W²` as a sparse matrix (CSR, `nb × nb`, built on each call): entry
    /// `(b, v_j) = sin(2πj/n_b)`.
    pub fn w2(&self) -> CsMat<f64> {
        self.sparse(&self.sin)
    }

    /// Row `b` of both operators, in ring order. Panics if `b ≥ nb`.
    pub fn stencil(&self, b: usize) -> Stencil<'_> {
        let range = self.offsets[b]..self.offsets[b + 1];
        Stencil {
            neighbours: &self.neighbours[range.clone()],
            w1: &self.cos[range.clone()],
            w2: &self.sin[range],
        }
    }

    /// The tangents `((W¹q)_b, (W²q)_b)` of one vertex.
    ///
    /// # Panics
    /// If `b ≥ nb` or `q` has fewer than `nb` points.
    pub fn tangents_at(&self, q: &[Vec3], b: usize) -> (Vec3, Vec3) {
        let s = self.stencil(b);
        s.neighbours.iter().zip(s.w1).zip(s.w2).fold(
            (Vec3::zeros(), Vec3::zeros()),
            |(t1, t2), ((&v, &c), &si)| (t1 + c * q[v], t2 + si * q[v]),
        )
    }

    /// `((W¹q)_b, (W²q)_b)` for every boundary vertex `b < nb`. `q` may be longer than `nb`
    /// (all landmarks): only its first `nb` points are used.
    ///
    /// # Panics
    /// If `q` has fewer than `nb` points.
    pub fn tangents(&self, q: &[Vec3]) -> (Vec<Vec3>, Vec<Vec3>) {
        self.check_len(q);
        (0..self.len()).map(|b| self.tangents_at(q, b)).unzip()
    }

    /// Unit outward normals `normalize(W¹q × W²q)` of every boundary vertex (components are NaN
    /// where the two tangents are parallel, i.e. the ring is degenerate).
    ///
    /// # Panics
    /// If `q` has fewer than `nb` points.
    pub fn normals(&self, q: &[Vec3]) -> Vec<Vec3> {
        self.check_len(q);
        (0..self.len())
            .map(|b| {
                let (t1, t2) = self.tangents_at(q, b);
                t1.cross(&t2).normalize()
            })
            .collect()
    }

    /// The `nb × nb` CSR matrix with row `b` holding `values[offsets[b]..offsets[b+1]]` at the
    /// columns of its ring.
    fn sparse(&self, values: &[f64]) -> CsMat<f64> {
        let n = self.len();
        let mut triplets = TriMat::with_capacity((n, n), self.neighbours.len());
        for (b, w) in self.offsets.windows(2).enumerate() {
            let range = w[0]..w[1];
            for (&v, &value) in self.neighbours[range.clone()].iter().zip(&values[range]) {
                triplets.add_triplet(b, v, value);
            }
        }
        triplets.to_csr()
    }

    fn check_len(&self, q: &[Vec3]) {
        assert!(
            q.len() >= self.len(),
            "Loop tangents of {} boundary vertices need at least that many points, got {}",
            self.len(),
            q.len()
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::topology::vertex_rings;
    use crate::testing::meshes::octahedron;
    use approx::assert_relative_eq;

    #[test]
    fn octahedron_normals_are_radial() {
        let (p, t) = octahedron();
        let lt = LoopTangents::new(&vertex_rings(6, &t).unwrap()).expect("valence 4");
        for (b, n) in lt.normals(&p).iter().enumerate() {
            assert_relative_eq!(*n, p[b], epsilon = 1e-12);
        }
        // Ring of +z is (+x, +y, −x, −y): W¹ = x − (−x) = 2x, W² = 2y.
        let (t1, t2) = lt.tangents(&p);
        assert_relative_eq!(t1[4], 2.0 * Vec3::x(), epsilon = 1e-12);
        assert_relative_eq!(t2[4], 2.0 * Vec3::y(), epsilon = 1e-12);
    }

    #[test]
    fn sparse_matrices_match_stencils() {
        let (p, t) = octahedron();
        let lt = LoopTangents::new(&vertex_rings(6, &t).unwrap()).expect("valence 4");
        assert_eq!(lt.w1().shape(), (6, 6));
        let (t1, t2) = lt.tangents(&p);
        for c in 0..3 {
            let x: Vec<f64> = p.iter().map(|v| v[c]).collect();
            let y1 = &lt.w1() * &sprs::CsVec::new(6, (0..6).collect(), x.clone());
            let y2 = &lt.w2() * &sprs::CsVec::new(6, (0..6).collect(), x);
            for b in 0..6 {
                assert_relative_eq!(y1.get(b).copied().unwrap_or(0.0), t1[b][c], epsilon = 1e-12);
                assert_relative_eq!(y2.get(b).copied().unwrap_or(0.0), t2[b][c], epsilon = 1e-12);
            }
        }
    }

    #[test]
    fn low_valence_is_refused() {
        let rings = vec![vec![1, 2, 3], vec![0, 2], vec![0, 1, 3], vec![0, 1, 2]];
        let err = LoopTangents::new(&rings).expect_err("valence 2");
        assert_eq!(
            err,
            MeshDefect::LowValence {
                vertex: 1,
                ring: vec![0, 2]
            }
        );
        assert!(err.to_string().contains("vertex 1 has valence 2"), "{err}");
    }
}
