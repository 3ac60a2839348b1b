//! The sampling of the model interior: the subdivided boundary vertices as fixed combinations
//! of landmarks, and the points between a boundary point and its medial point.

use crate::mesh::subdivide::subdivide_with;
use crate::Vec3;

/// A fixed combination `Σ weight_j · q_{index_j}` of at most three landmarks, sorted by index.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Combination {
    index: [usize; 3],
    weight: [f64; 3],
    len: usize,
}

impl Combination {
    pub(super) fn single(index: usize) -> Self {
        Self {
            index: [index, 0, 0],
            weight: [1.0, 0.0, 0.0],
            len: 1,
        }
    }

    pub(super) fn terms(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        (0..self.len).map(|n| (self.index[n], self.weight[n]))
    }

    /// Merges weighted terms (equal indices added, sorted by index). The terms of every
    /// combination built here span the corners of one input triangle, so at most three remain.
    pub(super) fn from_terms(terms: impl IntoIterator<Item = (usize, f64)>) -> Self {
        let mut c = Self {
            index: [0; 3],
            weight: [0.0; 3],
            len: 0,
        };
        for (index, weight) in terms {
            match c.index[..c.len].iter().position(|&i| i == index) {
                Some(n) => c.weight[n] += weight,
                None => {
                    debug_assert!(c.len < 3, "a combination spans more than one triangle");
                    c.index[c.len] = index;
                    c.weight[c.len] = weight;
                    c.len += 1;
                }
            }
        }
        let mut order = [0, 1, 2];
        order[..c.len].sort_unstable_by_key(|&n| c.index[n]);
        Self {
            index: order.map(|n| c.index[n]),
            weight: order.map(|n| c.weight[n]),
            len: c.len,
        }
    }

    pub(super) fn midpoint(a: &Self, b: &Self) -> Self {
        Self::from_terms(a.terms().chain(b.terms()).map(|(i, w)| (i, 0.5 * w)))
    }

    /// The same weights on other landmarks (`map[index]`).
    pub(super) fn mapped(&self, map: &[usize]) -> Self {
        Self::from_terms(self.terms().map(|(i, w)| (map[i], w)))
    }

    pub(super) fn apply(&self, q: &[Vec3]) -> Vec3 {
        self.terms()
            .fold(Vec3::zeros(), |acc, (i, w)| acc + w * q[i])
    }

    /// `grad[index_j] += weight_j · g`.
    pub(super) fn scatter(&self, g: &Vec3, grad: &mut [Vec3]) {
        self.terms().for_each(|(i, w)| grad[i] += w * g);
    }
}

/// A vertex of the subdivided boundary: its boundary point and its medial point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Stencil {
    pub(super) boundary: Combination,
    pub(super) medial: Combination,
}

impl Stencil {
    /// Adds a gradient `[∂/∂b, ∂/∂m]` at this vertex to the landmark gradient `grad`.
    pub(super) fn scatter(&self, g: &[Vec3; 2], grad: &mut [Vec3]) {
        self.boundary.scatter(&g[0], grad);
        self.medial.scatter(&g[1], grad);
    }
}

/// The boundary and medial points of a subdivided boundary vertex.
#[derive(Clone, Copy, Debug)]
pub(super) struct Ends {
    pub(super) boundary: Vec3,
    pub(super) medial: Vec3,
}

impl Ends {
    /// `(1 − s) b + s m`.
    pub(super) fn at(&self, s: f64) -> Vec3 {
        (1.0 - s) * self.boundary + s * self.medial
    }
}

/// Midpoint subdivision ([`crate::mesh::subdivide`]), `levels` times, of the mesh over points
/// `0..n`. Returns each vertex as a combination of the input points, and the triangles
/// (orientation kept).
pub(super) fn subdivide(
    n: usize,
    triangles: &[[usize; 3]],
    levels: usize,
) -> (Vec<Combination>, Vec<[usize; 3]>) {
    let mut vertices: Vec<Combination> = (0..n).map(Combination::single).collect();
    let mut triangles = triangles.to_vec();
    for _ in 0..levels {
        triangles = subdivide_with(&mut vertices, &triangles, Combination::midpoint);
    }
    (vertices, triangles)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subdivision_keeps_shared_midpoints_and_weights() {
        let (v, t) = subdivide(4, &[[0, 1, 2], [0, 2, 3]], 1);
        assert_eq!(v.len(), 4 + 5);
        assert_eq!(t.len(), 8);
        let mid02 = v
            .iter()
            .position(|c| c.len == 2 && c.index[..2] == [0, 2])
            .unwrap();
        assert_eq!(t.iter().flatten().filter(|&&i| i == mid02).count(), 6);
        let (v2, _) = subdivide(3, &[[0, 1, 2]], 2);
        for c in &v2 {
            assert!((c.weight[..c.len].iter().sum::<f64>() - 1.0).abs() < 1e-15);
        }
        assert_eq!(v2.len(), 15);
    }
}
