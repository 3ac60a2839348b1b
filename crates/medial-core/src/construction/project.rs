//! Projection of a template onto its medial constraints: the smallest move of the landmarks
//! after which the spokes are normal to the boundary and the spokes of every atom are equally
//! long (docs/method.md §9.2, §9).
//!
//! With `q⁰` the given landmarks (boundary and medial points alike, in mm) the projection
//! solves
//!
//! ```text
//! minimise ½ |q − q⁰|²   subject to   C(q) = 0
//! ```
//!
//! by Gauss–Newton steps on the linearised problem (sequential quadratic programming with the
//! identity as Hessian): at the current `q` with `c = C(q)` and `J = ∂C/∂q` (sparse, `L × 3k`),
//! the next iterate is the point nearest to `q⁰` on the linearised constraint set,
//!
//! ```text
//! q⁺ = q⁰ + Jᵀ y,   (J Jᵀ + ε D) y = J (q − q⁰) − c,
//! ```
//!
//! which from `q = q⁰` is the minimum-norm step `Δq = −Jᵀ(JJᵀ)⁻¹ c`. `D = diag(JJᵀ)` and
//! `ε` = [`DAMPING`] (a tiny Levenberg damping that keeps redundant constraints harmless). The
//! `L × L` system is solved by conjugate gradients preconditioned with `D`, using only products
//! with `J` and `Jᵀ`. A step is halved until `‖C‖₂` does not grow beyond the feasibility level
//! [`FEASIBLE`]` · h²` (`h` the diagonal of the landmarks' bounding box; `C` is in mm²).
//! Iterations stop when a step moves no landmark coordinate by more than [`STEP_TOLERANCE`]` · h`
//! at a feasible point, when no step is accepted, or after `max_iterations`. The result must
//! then meet the tolerances of [`ProjectOptions`], otherwise the projection is an error.
//!
//! **When the nearest point is out of reach.** From a template far from medial (spokes tens of
//! degrees off the boundary normal, as an inflated sheet whose triangles are small against its
//! radius gives) the linearisation can lead to a configuration that meets the constraints with
//! a spoke turned inside out, or none. Then the spokes are first *turned onto the boundary*:
//! every medial point stays, every spoke keeps its atom's mean length and turns half way
//! towards the boundary's Loop normal at its tip, repeatedly ([`TURN_ROUNDS`] at most) — a
//! fixed point of this map is medial, spokes along the normal and of one length per atom — and
//! the Gauss–Newton projection continues from there. This move is not the smallest; the
//! [`Projection`] says it was taken ([`Projection::turned_spokes`]).

use crate::mesh::Bounds;
use crate::model::constraints::MedialConstraints;
use crate::model::metrics::SpokeMetrics;
use crate::model::template::MedialTemplate;
use crate::{Error, Result, Vec3};
use sprs::CsMat;

/// Levenberg damping `ε` of `JJᵀ + ε·diag(JJᵀ)`.
pub const DAMPING: f64 = 1e-12;

/// Feasibility level: `‖C‖₂ ≤ FEASIBLE · h²` (mm², `h` the bounding-box diagonal in mm).
pub const FEASIBLE: f64 = 1e-10;

/// A step smaller than `STEP_TOLERANCE · h` in every coordinate ends the iterations.
pub const STEP_TOLERANCE: f64 = 1e-10;

/// Relative residual `‖JJᵀy − b‖ ≤ CG_TOLERANCE ‖b‖` at which conjugate gradients stop.
const CG_TOLERANCE: f64 = 1e-12;

/// Most step halvings tried before a Gauss–Newton step is given up.
const MAX_HALVINGS: usize = 30;

/// Most rounds of turning the spokes onto the boundary normal before the Gauss–Newton
/// projection continues (each round halves the angle where the normal itself moves little:
/// 200 rounds bring 45° to far below the tolerance).
pub const TURN_ROUNDS: usize = 200;

/// Tolerances and limits of [`project`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProjectOptions {
    /// Largest spoke–normal deviation the result may have, degrees (default 0.1°).
    pub max_spoke_normal_deg: f64,
    /// Largest spoke-length mismatch `(max − min)/mean` of an atom the result may have, a
    /// fraction (default 0.001 = 0.1 %).
    pub max_mismatch: f64,
    /// Most Gauss–Newton iterations (default 50).
    pub max_iterations: usize,
}

impl Default for ProjectOptions {
    fn default() -> Self {
        Self {
            max_spoke_normal_deg: 0.1,
            max_mismatch: 1e-3,
            max_iterations: 50,
        }
    }
}

/// How well a landmark configuration satisfies the medial constraints.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConstraintFigures {
    /// Largest spoke–normal deviation, degrees.
    pub max_spoke_normal_deg: f64,
    /// Mean spoke–normal deviation, degrees.
    pub mean_spoke_normal_deg: f64,
    /// Largest spoke-length mismatch of an atom, a fraction (× 100 for %).
    pub max_mismatch: f64,
    /// `max_l |C_l(q)|`, mm².
    pub max_abs_constraint: f64,
}

impl ConstraintFigures {
    /// The figures of `template`'s structure at landmarks `q` (`k` points).
    ///
    /// # Panics
    /// If `q.len()` is not the template's landmark count.
    pub fn of(template: &MedialTemplate, constraints: &MedialConstraints, q: &[Vec3]) -> Self {
        let metrics = SpokeMetrics::compute(template, q);
        Self {
            max_spoke_normal_deg: metrics.max_spoke_normal_deg,
            mean_spoke_normal_deg: metrics.mean_spoke_normal_deg,
            max_mismatch: metrics.max_spoke_mismatch,
            max_abs_constraint: max_abs(&constraint_values(constraints, q)),
        }
    }

    /// True when both metrics are within `options`' tolerances (false for NaN).
    pub fn meets(&self, options: &ProjectOptions) -> bool {
        self.max_spoke_normal_deg <= options.max_spoke_normal_deg
            && self.max_mismatch <= options.max_mismatch
    }
}

/// The result of [`project`].
#[derive(Clone, Debug)]
pub struct Projection {
    /// The projected template (same structure, moved landmarks).
    pub template: MedialTemplate,
    /// Gauss–Newton iterations taken.
    pub iterations: usize,
    /// Figures of the given template.
    pub before: ConstraintFigures,
    /// Figures of the projected template.
    pub after: ConstraintFigures,
    /// Largest landmark displacement `max_i |q_i − q⁰_i|`, mm.
    pub max_displacement: f64,
    /// Root-mean-square landmark displacement `sqrt(|q − q⁰|² / k)`, mm.
    pub rms_displacement: f64,
    /// Whether the spokes were turned onto the boundary first (the Gauss–Newton projection
    /// from the given landmarks missed the tolerances; see the module documentation).
    pub turned_spokes: bool,
}

/// Moves the landmarks of `template` as little as possible (least squares, all landmarks
/// weighted alike) so that its medial constraints hold; see the module documentation.
///
/// Errors: `InvalidParameter` for tolerances that are not positive or zero iterations;
/// `Optimisation` when the result misses the tolerances (the message gives the figures
/// reached) or the iterates become non-finite.
pub fn project(template: &MedialTemplate, options: &ProjectOptions) -> Result<Projection> {
    check_options(options)?;
    let constraints = MedialConstraints::new(template);
    let given = template.landmarks();
    let (mut points, mut iterations) = gauss_newton(&constraints, given, options);
    let mut after = ConstraintFigures::of(template, &constraints, &points);
    let mut turned_spokes = false;
    if !after.meets(options) {
        let turned = turn_spokes(template, given, &constraints, options);
        let (p, i) = gauss_newton(&constraints, &turned, options);
        let figures = ConstraintFigures::of(template, &constraints, &p);
        if figures.meets(options) {
            (points, iterations, after, turned_spokes) = (p, i, figures, true);
        }
    }
    let projected = template.with_landmarks(&points).map_err(|e| {
        Error::Optimisation(format!(
            "projection diverged after {iterations} iterations: {e}"
        ))
    })?;
    let before = ConstraintFigures::of(template, &constraints, given);
    if !after.meets(options) {
        return Err(Error::Optimisation(format!(
            "projection onto the medial constraints stopped after {iterations} iterations at \
             max spoke–normal deviation {:.4}° and spoke mismatch {:.4} % (asked: ≤ {}° and \
             ≤ {} %; before: {:.4}° and {:.4} %); the template may be too far from medial or \
             degenerate (a zero spoke, a flat boundary ring)",
            after.max_spoke_normal_deg,
            100.0 * after.max_mismatch,
            options.max_spoke_normal_deg,
            100.0 * options.max_mismatch,
            before.max_spoke_normal_deg,
            100.0 * before.max_mismatch,
        )));
    }
    let moves: Vec<f64> = points
        .iter()
        .zip(template.landmarks())
        .map(|(p, p0)| (p - p0).norm())
        .collect();
    Ok(Projection {
        template: projected,
        iterations,
        before,
        after,
        max_displacement: moves.iter().copied().fold(0.0, f64::max),
        rms_displacement: (moves.iter().map(|d| d * d).sum::<f64>() / moves.len() as f64).sqrt(),
        turned_spokes,
    })
}

/// The Gauss–Newton projection from the landmarks `start` (module documentation): the
/// landmarks reached and the iterations taken.
fn gauss_newton(
    constraints: &MedialConstraints,
    start: &[Vec3],
    options: &ProjectOptions,
) -> (Vec<Vec3>, usize) {
    let q0 = flatten(start);
    let h = bounding_diagonal(start);
    let solver = Solver {
        constraints,
        q0: &q0,
        feasible: FEASIBLE * h * h,
    };
    let (q, iterations) = solver.run(options.max_iterations, STEP_TOLERANCE * h);
    (unflatten(&q), iterations)
}

/// The spokes of `template` at landmarks `q` turned onto the boundary (module documentation):
/// medial points kept, every spoke `s_b` of atom `m` replaced by `ℓ_m · normalize(ŝ_b + n̂_b)`
/// (`ℓ_m` the atom's mean spoke length, `n̂_b` the Loop normal) until the largest spoke–normal
/// angle is a tenth of the tolerance, or after [`TURN_ROUNDS`].
fn turn_spokes(
    template: &MedialTemplate,
    q: &[Vec3],
    constraints: &MedialConstraints,
    options: &ProjectOptions,
) -> Vec<Vec3> {
    let mut q = q.to_vec();
    let atoms = template.medial_index();
    let mean_length: Vec<f64> = (0..template.medial_count())
        .map(|m| {
            let spokes = template.spokes(m);
            let centre = q[template.atom_landmark(m)];
            spokes.iter().map(|&b| (q[b] - centre).norm()).sum::<f64>() / spokes.len() as f64
        })
        .collect();
    for _ in 0..TURN_ROUNDS {
        if ConstraintFigures::of(template, constraints, &q).max_spoke_normal_deg
            <= 0.1 * options.max_spoke_normal_deg
        {
            break;
        }
        let normals = template.tangents().normals(&q);
        for (b, normal) in normals.iter().enumerate() {
            let m = atoms[b];
            let centre = q[template.atom_landmark(m)];
            let direction = ((q[b] - centre).normalize() + normal).normalize();
            if direction.iter().all(|c| c.is_finite()) {
                q[b] = centre + direction * mean_length[m];
            }
        }
    }
    q
}

fn check_options(options: &ProjectOptions) -> Result<()> {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !positive(options.max_spoke_normal_deg) || !positive(options.max_mismatch) {
        return Err(Error::InvalidParameter(format!(
            "projection tolerances must be positive numbers, got {}° spoke–normal deviation \
             and {} spoke mismatch",
            options.max_spoke_normal_deg, options.max_mismatch
        )));
    }
    if options.max_iterations == 0 {
        return Err(Error::InvalidParameter(
            "projection needs at least one iteration".into(),
        ));
    }
    Ok(())
}

/// The Gauss–Newton iteration towards the point of `C = 0` nearest to `q0` (flat coordinates).
struct Solver<'a> {
    constraints: &'a MedialConstraints,
    q0: &'a [f64],
    /// `‖C‖₂` below which a configuration counts as feasible, mm².
    feasible: f64,
}

impl Solver<'_> {
    /// Iterates from `q0`; returns the final flat landmarks and the number of iterations.
    fn run(&self, max_iterations: usize, step_tolerance: f64) -> (Vec<f64>, usize) {
        let mut q = self.q0.to_vec();
        let mut c = self.values(&q);
        for iteration in 1..=max_iterations {
            let Some((next, c_next)) = self.step(&q, &c) else {
                return (q, iteration - 1);
            };
            let moved = max_abs_difference(&next, &q);
            (q, c) = (next, c_next);
            if moved <= step_tolerance && norm(&c) <= self.feasible {
                return (q, iteration);
            }
        }
        (q, max_iterations)
    }

    /// One damped step from `q` (where `C = c`): the new point and its constraint values, or
    /// `None` when no fraction of the step keeps `‖C‖₂` from growing (or the step is not
    /// finite).
    fn step(&self, q: &[f64], c: &[f64]) -> Option<(Vec<f64>, Vec<f64>)> {
        let jacobian = self.constraints.jacobian(&unflatten(q));
        let offset: Vec<f64> = q.iter().zip(self.q0).map(|(a, b)| a - b).collect();
        let rhs: Vec<f64> = mul(&jacobian, &offset)
            .iter()
            .zip(c)
            .map(|(jd, c)| jd - c)
            .collect();
        let y = solve_normal_equations(&jacobian, &rhs);
        let target: Vec<f64> = mul_transpose(&jacobian, &y)
            .iter()
            .zip(self.q0)
            .map(|(d, q0)| q0 + d)
            .collect();
        let direction: Vec<f64> = target.iter().zip(q).map(|(t, q)| t - q).collect();
        if !direction.iter().all(|d| d.is_finite()) {
            return None;
        }
        let allowed = norm(c).max(self.feasible);
        let mut t = 1.0;
        for _ in 0..=MAX_HALVINGS {
            let trial: Vec<f64> = q.iter().zip(&direction).map(|(q, d)| q + t * d).collect();
            let c_trial = self.values(&trial);
            if norm(&c_trial) <= allowed {
                return Some((trial, c_trial));
            }
            t *= 0.5;
        }
        None
    }

    fn values(&self, q: &[f64]) -> Vec<f64> {
        constraint_values(self.constraints, &unflatten(q))
    }
}

/// Solves `(JJᵀ + ε·D) y = b`, `D = diag(JJᵀ)`, by conjugate gradients preconditioned with `D`
/// (rows of `J` that are zero get `D = 1`). At most `2L + 100` iterations; stops at relative
/// residual [`CG_TOLERANCE`]. The work vectors are allocated once, before the iterations.
fn solve_normal_equations(jacobian: &CsMat<f64>, b: &[f64]) -> Vec<f64> {
    let diagonal: Vec<f64> = jacobian
        .outer_iterator()
        .map(|row| row.iter().map(|(_, v)| v * v).sum::<f64>())
        .map(|d| if d > 0.0 { d } else { 1.0 })
        .collect();
    // `ap = (JJᵀ + ε·D) p`, through `jtp = Jᵀ p`.
    let mut jtp = vec![0.0; jacobian.cols()];
    let mut apply = |p: &[f64], ap: &mut [f64]| {
        mul_transpose_into(jacobian, p, &mut jtp);
        mul_into(jacobian, &jtp, ap);
        ap.iter_mut()
            .zip(p)
            .zip(&diagonal)
            .for_each(|((a, p), d)| *a += DAMPING * d * p);
    };
    let precondition = |r: &[f64], z: &mut [f64]| {
        z.iter_mut()
            .zip(r)
            .zip(&diagonal)
            .for_each(|((z, r), d)| *z = r / d);
    };
    let mut x = vec![0.0; b.len()];
    let mut r = b.to_vec();
    let mut z = vec![0.0; b.len()];
    precondition(&r, &mut z);
    let mut p = z.clone();
    let mut ap = vec![0.0; b.len()];
    let mut rz = dot(&r, &z);
    let stop = CG_TOLERANCE * norm(b);
    for _ in 0..2 * b.len() + 100 {
        if norm(&r) <= stop {
            break;
        }
        apply(&p, &mut ap);
        let curvature = dot(&p, &ap);
        if curvature <= 0.0 || !curvature.is_finite() {
            break;
        }
        let alpha = rz / curvature;
        axpy(alpha, &p, &mut x);
        axpy(-alpha, &ap, &mut r);
        precondition(&r, &mut z);
        let rz_next = dot(&r, &z);
        let beta = rz_next / rz;
        rz = rz_next;
        p.iter_mut().zip(&z).for_each(|(p, z)| *p = z + beta * *p);
    }
    x
}

/// `J x` for a CSR matrix.
fn mul(matrix: &CsMat<f64>, x: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; matrix.rows()];
    mul_into(matrix, x, &mut out);
    out
}

/// `out = J x` for a CSR matrix (`out` of length `J.rows()`).
fn mul_into(matrix: &CsMat<f64>, x: &[f64], out: &mut [f64]) {
    for (o, row) in out.iter_mut().zip(matrix.outer_iterator()) {
        *o = row.iter().map(|(col, v)| v * x[col]).sum();
    }
}

/// `Jᵀ y` for a CSR matrix.
fn mul_transpose(matrix: &CsMat<f64>, y: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; matrix.cols()];
    mul_transpose_into(matrix, y, &mut out);
    out
}

/// `out = Jᵀ y` for a CSR matrix (`out` of length `J.cols()`; a fixed order of additions:
/// deterministic).
fn mul_transpose_into(matrix: &CsMat<f64>, y: &[f64], out: &mut [f64]) {
    out.fill(0.0);
    for (row, &yr) in matrix.outer_iterator().zip(y) {
        for (col, v) in row.iter() {
            out[col] += v * yr;
        }
    }
}

fn constraint_values(constraints: &MedialConstraints, q: &[Vec3]) -> Vec<f64> {
    let mut out = vec![0.0; constraints.len()];
    constraints.evaluate(q, &mut out);
    out
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a * b).sum()
}

fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

fn axpy(alpha: f64, x: &[f64], y: &mut [f64]) {
    y.iter_mut().zip(x).for_each(|(y, x)| *y += alpha * x);
}

fn max_abs(values: &[f64]) -> f64 {
    values.iter().fold(0.0, |m, v| m.max(v.abs()))
}

fn max_abs_difference(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0, |m, (a, b)| m.max((a - b).abs()))
}

/// Diagonal of the axis-aligned bounding box of `points` (mm); 1 when it is 0 (a single point).
fn bounding_diagonal(points: &[Vec3]) -> f64 {
    match Bounds::of(points).map(|b| b.diagonal()) {
        Some(diagonal) if diagonal > 0.0 => diagonal,
        _ => 1.0,
    }
}

fn flatten(points: &[Vec3]) -> Vec<f64> {
    points.iter().flat_map(|p| [p.x, p.y, p.z]).collect()
}

fn unflatten(q: &[f64]) -> Vec<Vec3> {
    q.chunks_exact(3)
        .map(|c| Vec3::new(c[0], c[1], c[2]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::meshes::bipyramid;
    use approx::assert_relative_eq;
    use nalgebra::DMatrix;

    /// A sparse matrix with rows of very different scales and a redundant row.
    fn test_matrix() -> CsMat<f64> {
        let mut t = sprs::TriMat::new((4, 7));
        for (r, c, v) in [
            (0, 0, 2.0),
            (0, 3, -1.0),
            (1, 1, 1e-3),
            (1, 6, 3e-3),
            (2, 2, 50.0),
            (2, 4, 10.0),
            (2, 5, -20.0),
            (3, 0, 1.0),
            (3, 5, 0.5),
        ] {
            t.add_triplet(r, c, v);
        }
        t.to_csr()
    }

    #[test]
    fn conjugate_gradients_match_a_dense_solve() {
        let j = test_matrix();
        let dense = DMatrix::from_fn(4, 7, |r, c| *j.get(r, c).unwrap_or(&0.0));
        let b = [1.0, -2.0, 0.5, 3.0];
        let y = solve_normal_equations(&j, &b);
        let mut jjt = &dense * dense.transpose();
        for i in 0..4 {
            jjt[(i, i)] *= 1.0 + DAMPING;
        }
        let expected = jjt
            .lu()
            .solve(&nalgebra::DVector::from_row_slice(&b))
            .unwrap();
        for i in 0..4 {
            assert_relative_eq!(y[i], expected[i], max_relative = 1e-8);
        }
        let x = [0.3, -1.0, 2.0, 0.1, 0.0, 4.0, -0.5];
        let jx = mul(&j, &x);
        let jty = mul_transpose(&j, &b);
        let dense_jx = &dense * nalgebra::DVector::from_row_slice(&x);
        let dense_jty = dense.transpose() * nalgebra::DVector::from_row_slice(&b);
        for i in 0..4 {
            assert_relative_eq!(jx[i], dense_jx[i], epsilon = 1e-12);
        }
        for i in 0..7 {
            assert_relative_eq!(jty[i], dense_jty[i], epsilon = 1e-12);
        }
    }

    #[test]
    fn a_perturbed_bipyramid_is_projected_back_with_small_moves() {
        let t = bipyramid(0.5);
        let mut q = t.landmarks().to_vec();
        q[0] += Vec3::new(0.03, -0.02, 0.04); // top apex: tilted and longer spoke
        q[9] += Vec3::new(0.0, 0.02, 0.01); // a rim atom
        let perturbed = t.with_landmarks(&q).unwrap();
        let p = project(&perturbed, &ProjectOptions::default()).expect("projects");
        assert!(p.before.max_spoke_normal_deg > 1.0 && p.before.max_mismatch > 0.05);
        assert!(p.after.max_spoke_normal_deg < 1e-6, "{:?}", p.after);
        assert!(p.after.max_mismatch < 1e-9 && p.after.max_abs_constraint < 1e-12);
        // The template itself is feasible, so the nearest feasible point is at most as far
        // as the perturbation (0.0583 mm in all).
        let total = p.rms_displacement * (q.len() as f64).sqrt();
        assert!(total <= 0.0584, "{total}");
        assert!(p.iterations <= 20, "{}", p.iterations);
    }

    #[test]
    fn a_satisfied_template_does_not_move() {
        let t = bipyramid(0.5);
        let p = project(&t, &ProjectOptions::default()).expect("projects");
        assert!(p.max_displacement < 1e-12, "{}", p.max_displacement);
    }

    #[test]
    fn bad_options_are_refused() {
        let t = bipyramid(0.5);
        let bad = ProjectOptions {
            max_mismatch: 0.0,
            ..ProjectOptions::default()
        };
        let m = project(&t, &bad).unwrap_err().to_string();
        assert!(m.contains("tolerances must be positive"), "{m}");
        let none = ProjectOptions {
            max_iterations: 0,
            ..ProjectOptions::default()
        };
        assert!(project(&t, &none).is_err());
    }
}
