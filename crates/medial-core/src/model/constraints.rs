//! The medial constraints `C(q) ∈ R^L` of a template (docs/method.md §4.1–§4.2), their exact values, Jacobian
//! and weighted gradients.
//!
//! Landmarks `q` have `k = nb + nm` entries (boundary points, then medial points; atom `m` is
//! landmark `nb + m`). Constraint order:
//!
//! 1. orthogonality, `2·nb` of them: for `b = 0 … nb−1` and `γ = 1, 2`, constraint `2b + γ − 1`
//!    is `C = (q_b − q_m) · (W^γ q)_b` with `m = M[b]` (the spoke is normal to the boundary);
//! 2. equal spokes, one per extra spoke: for atoms `m` in order with spokes
//!    `B[m] = (b_0 < b_1 < …)` and `j = 1, 2, …`: `C = |q_{b_j} − q_m|² − |q_{b_0} − q_m|²`.
//!
//! Gradients: with `s = q_b − q_m`, `t_γ = (W^γ q)_b`,
//! `∂C/∂q_b = t_γ`, `∂C/∂q_m = −t_γ`, `∂C/∂q_{v_j} = W^γ_{b v_j} s` for the ring `v_j` of `b`
//! (`W^γ_{bb} = 0` on a closed mesh); for equal spokes `d_j = q_{b_j} − q_m`:
//! `∂C/∂q_{b_j} = 2 d_j`, `∂C/∂q_{b_0} = −2 d_0`, `∂C/∂q_m = 2 (d_0 − d_j)`.
//!
//! **Units** ([`ConstraintUnits`]). As docs/method.md §4.1–§4.2 writes them the constraints are in mm², so a
//! given violation means a larger angle or mismatch on a short spoke than on a long one, and μ
//! depends on the size of the template. [`ConstraintUnits::Relative`] divides every constraint
//! by a constant of the template `q⁰`: orthogonality by `|s⁰_b| |t⁰_γ|`, so that it reads
//! `cos ∠(s, t_γ)` at the template's scale (≈ the spoke–normal angle in radians); equal spokes
//! by `2 |q⁰_{b_0} − q⁰_m|²` (≈ the relative length mismatch). The feasible set is the same;
//! the penalty weighs every spoke alike and μ is dimensionless. Measured on cmrep's t001 bent
//! by a known map (SSD, 4 AL iterations × 1000): 0.14° and 0.18 % against 0.53° and 1.11 %.

use crate::model::loop_tangent::LoopTangents;
use crate::model::template::MedialTemplate;
use crate::{Error, Result, Vec3};
use sprs::{CsMat, TriMat};

/// One equal-spoke constraint `|q_spoke − q_atom|² − |q_first − q_atom|²` (landmark indices).
#[derive(Clone, Copy, Debug)]
struct EqualSpokes {
    atom: usize,
    first: usize,
    spoke: usize,
}

/// The unit of the constraint values (see the module documentation; in a config: `absolute`,
/// `relative`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConstraintUnits {
    /// docs/method.md §4 as written: mm² (the reference implementation; the paper's μ values
    /// carry over).
    #[default]
    Absolute,
    /// Divided by the template's spoke and tangent lengths: dimensionless, alike for every spoke.
    Relative,
}

/// The constraints of one template, with their stencils precomputed so that evaluation and
/// gradient accumulation allocate nothing.
#[derive(Clone, Debug)]
pub struct MedialConstraints {
    /// `k`.
    landmarks: usize,
    /// Landmark index `nb + M[b]` of the atom of every boundary point `b`.
    atom_of: Vec<usize>,
    /// `W¹`, `W²` of the boundary.
    tangents: LoopTangents,
    equal: Vec<EqualSpokes>,
    /// Per constraint, the constant factor of [`ConstraintUnits::Relative`] (empty: absolute).
    scale: Vec<f64>,
}

impl MedialConstraints {
    /// The constraints of `template` in `units`. Refuses relative units for a template with a
    /// zero spoke or a zero Loop tangent (nothing to divide by).
    pub fn with_units(template: &MedialTemplate, units: ConstraintUnits) -> Result<Self> {
        let mut constraints = Self::new(template);
        if units == ConstraintUnits::Relative {
            constraints.scale = constraints.relative_scale(template.landmarks())?;
        }
        Ok(constraints)
    }

    /// `1 / (|s_b| |t_γ|)` per orthogonality constraint, `1 / (2 |s_{b_0}|²)` per equal-spoke
    /// constraint, at landmarks `q`.
    fn relative_scale(&self, q: &[Vec3]) -> Result<Vec<f64>> {
        let invert = |x: f64, what: &str, b: usize| {
            if x > 0.0 && x.is_finite() {
                Ok(1.0 / x)
            } else {
                Err(Error::InvalidTemplate(format!(
                    "relative constraint units: the {what} at boundary point {b} is {x}"
                )))
            }
        };
        let mut scale = Vec::with_capacity(self.len());
        for (b, &m) in self.atom_of.iter().enumerate() {
            let spoke = (q[b] - q[m]).norm();
            let (t1, t2) = self.tangents.tangents_at(q, b);
            for t in [t1, t2] {
                scale.push(invert(
                    spoke * t.norm(),
                    "spoke length × Loop tangent length",
                    b,
                )?);
            }
        }
        for e in &self.equal {
            let r2 = (q[e.first] - q[e.atom]).norm_squared();
            scale.push(invert(2.0 * r2, "squared spoke length", e.first)?);
        }
        Ok(scale)
    }

    /// The constraints of `template` in [`ConstraintUnits::Absolute`] (see the module
    /// documentation for their order).
    pub fn new(template: &MedialTemplate) -> Self {
        let equal = (0..template.medial_count())
            .flat_map(|m| {
                let spokes = template.spokes(m);
                let atom = template.atom_landmark(m);
                spokes[1..].iter().map(move |&spoke| EqualSpokes {
                    atom,
                    first: spokes[0],
                    spoke,
                })
            })
            .collect();
        Self {
            landmarks: template.landmark_count(),
            atom_of: template
                .medial_index()
                .iter()
                .map(|&m| template.atom_landmark(m))
                .collect(),
            tangents: template.tangents().clone(),
            equal,
            scale: Vec::new(),
        }
    }

    /// The unit of the values.
    pub fn units(&self) -> ConstraintUnits {
        if self.scale.is_empty() {
            ConstraintUnits::Absolute
        } else {
            ConstraintUnits::Relative
        }
    }

    /// Number of constraints `L = 2·nb + Σ_m (|B[m]| − 1)`.
    pub fn len(&self) -> usize {
        self.orthogonality_count() + self.equal.len()
    }

    /// True when there are no constraints (never for a valid template).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Number of orthogonality constraints `2·nb` (they come first).
    pub fn orthogonality_count(&self) -> usize {
        2 * self.atom_of.len()
    }

    /// Number of equal-spoke constraints (they follow the orthogonality constraints).
    pub fn equal_spoke_count(&self) -> usize {
        self.equal.len()
    }

    /// Number of landmarks `k` the constraints act on.
    pub fn landmark_count(&self) -> usize {
        self.landmarks
    }

    /// `C(q)` into `out` (`L` values).
    ///
    /// # Panics
    /// If `q.len() != k` or `out.len() != L`.
    pub fn evaluate(&self, q: &[Vec3], out: &mut [f64]) {
        self.check_landmarks(q);
        self.check_per_constraint(out.len(), "constraint values");
        let (ortho, equal) = out.split_at_mut(self.orthogonality_count());
        for (b, pair) in ortho.chunks_exact_mut(2).enumerate() {
            let spoke = q[b] - q[self.atom_of[b]];
            let (t1, t2) = self.tangents.tangents_at(q, b);
            pair[0] = spoke.dot(&t1);
            pair[1] = spoke.dot(&t2);
        }
        for (c, e) in equal.iter_mut().zip(&self.equal) {
            *c = (q[e.spoke] - q[e.atom]).norm_squared() - (q[e.first] - q[e.atom]).norm_squared();
        }
        for (c, s) in out.iter_mut().zip(&self.scale) {
            *c *= s;
        }
    }

    /// `grad += Σ_l w_l ∇C_l(q)` (`grad` has `k` entries, `weights` has `L`). Sequential,
    /// allocation-free, and deterministic (a fixed order of additions).
    ///
    /// # Panics
    /// If `q.len() != k`, `grad.len() != k` or `weights.len() != L`.
    pub fn accumulate_gradient(&self, q: &[Vec3], weights: &[f64], grad: &mut [Vec3]) {
        self.check_landmarks(q);
        self.check_landmarks(grad);
        self.check_per_constraint(weights.len(), "constraint weights");
        let no = self.orthogonality_count();
        let (ortho, equal) = weights.split_at(no);
        for (b, w) in ortho.chunks_exact(2).enumerate() {
            let (w0, w1) = (w[0] * self.factor(2 * b), w[1] * self.factor(2 * b + 1));
            let m = self.atom_of[b];
            let spoke = q[b] - q[m];
            let stencil = self.tangents.stencil(b);
            let mut tangent = Vec3::zeros();
            for ((&v, &c), &s) in stencil.neighbours.iter().zip(stencil.w1).zip(stencil.w2) {
                let weight = w0 * c + w1 * s;
                tangent += weight * q[v];
                grad[v] += weight * spoke;
            }
            grad[b] += tangent;
            grad[m] -= tangent;
        }
        for (l, (&w, e)) in equal.iter().zip(&self.equal).enumerate() {
            let w = w * self.factor(no + l);
            let d_spoke = (2.0 * w) * (q[e.spoke] - q[e.atom]);
            let d_first = (2.0 * w) * (q[e.first] - q[e.atom]);
            grad[e.spoke] += d_spoke;
            grad[e.first] -= d_first;
            grad[e.atom] += d_first - d_spoke;
        }
    }

    /// The Jacobian `∂C/∂q` as a CSR matrix `L × 3k`: entry `(l, 3i + c)` is `∂C_l/∂q_{i,c}`.
    ///
    /// # Panics
    /// If `q.len() != k`.
    pub fn jacobian(&self, q: &[Vec3]) -> CsMat<f64> {
        self.check_landmarks(q);
        let mut triplets = TriMat::new((self.len(), 3 * self.landmarks));
        let mut put = |row: usize, landmark: usize, d: Vec3| {
            for c in 0..3 {
                triplets.add_triplet(row, 3 * landmark + c, self.factor(row) * d[c]);
            }
        };
        for (b, &m) in self.atom_of.iter().enumerate() {
            let spoke = q[b] - q[m];
            let (t1, t2) = self.tangents.tangents_at(q, b);
            for (row, t) in [(2 * b, t1), (2 * b + 1, t2)] {
                put(row, b, t);
                put(row, m, -t);
            }
            let stencil = self.tangents.stencil(b);
            for ((&v, &c), &s) in stencil.neighbours.iter().zip(stencil.w1).zip(stencil.w2) {
                put(2 * b, v, c * spoke);
                put(2 * b + 1, v, s * spoke);
            }
        }
        for (l, e) in self.equal.iter().enumerate() {
            let row = self.orthogonality_count() + l;
            let (d_spoke, d_first) = (q[e.spoke] - q[e.atom], q[e.first] - q[e.atom]);
            put(row, e.spoke, 2.0 * d_spoke);
            put(row, e.first, -2.0 * d_first);
            put(row, e.atom, 2.0 * (d_first - d_spoke));
        }
        triplets.to_csr()
    }

    /// The factor of constraint `l` ([`ConstraintUnits::Relative`]), 1 in absolute units.
    #[inline]
    fn factor(&self, l: usize) -> f64 {
        self.scale.get(l).copied().unwrap_or(1.0)
    }

    fn check_landmarks(&self, points: &[Vec3]) {
        assert_eq!(
            points.len(),
            self.landmarks,
            "medial constraints: one entry per landmark"
        );
    }

    fn check_per_constraint(&self, n: usize, what: &str) {
        assert_eq!(n, self.len(), "{what}: one per medial constraint");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::meshes::bipyramid;
    use approx::assert_relative_eq;

    #[test]
    fn bipyramid_counts_and_values() {
        let t = bipyramid(0.5);
        let c = MedialConstraints::new(&t);
        assert_eq!(
            (c.orthogonality_count(), c.equal_spoke_count(), c.len()),
            (16, 1, 17)
        );
        let mut out = vec![f64::NAN; c.len()];
        c.evaluate(t.landmarks(), &mut out);
        // Apexes: spokes ±z, tangents in the xy plane; equal spokes of the centre atom.
        for v in [out[0], out[1], out[2], out[3], out[16]] {
            assert_relative_eq!(v, 0.0, epsilon = 1e-12);
        }
        // Move the top apex (b_0) up by 0.25: the equal-spoke constraint is 0.5² − 0.75².
        let mut q = t.landmarks().to_vec();
        q[0].z += 0.25;
        c.evaluate(&q, &mut out);
        assert_relative_eq!(out[16], 0.25 - 0.75 * 0.75, epsilon = 1e-12);
    }

    #[test]
    fn gradient_matches_jacobian_transpose() {
        let t = bipyramid(0.4);
        let c = MedialConstraints::new(&t);
        let q: Vec<Vec3> = t
            .landmarks()
            .iter()
            .enumerate()
            .map(|(i, p)| p + 0.05 * Vec3::new((i as f64).sin(), (2.0 * i as f64).cos(), 0.3))
            .collect();
        let weights: Vec<f64> = (0..c.len()).map(|l| (l as f64 * 0.7).cos()).collect();
        let mut grad = vec![Vec3::zeros(); q.len()];
        c.accumulate_gradient(&q, &weights, &mut grad);
        let jac = c.jacobian(&q);
        let mut expected = vec![0.0; 3 * q.len()];
        for (l, row) in jac.outer_iterator().enumerate() {
            for (col, &v) in row.iter() {
                expected[col] += weights[l] * v;
            }
        }
        for (i, g) in grad.iter().enumerate() {
            for a in 0..3 {
                assert_relative_eq!(g[a], expected[3 * i + a], epsilon = 1e-12);
            }
        }
    }
}
