//! Soundness of an iterate: what makes a configuration of the landmarks unusable, checked at
//! every accepted L-BFGS iterate so that a fit never reports a folded or diverged model.
//!
//! An iterate is unsound ([`Unsound`]) when
//! - a figure of its evaluation is not finite;
//! - the Dice estimate leaves `[0, 1]` (it does when the model's volume turns negative);
//! - the objective exceeds [`DIVERGED`] times the magnitude of the stage's starting value;
//! - the model folds. For a medial template each boundary triangle `(b₀, b₁, b₂)` and the
//!   medial points `(m₀, m₁, m₂)` of its atoms bound a prism with spokes `s_i = b_i − m_i`.
//!   A prism is folded when its signed volume, the sum of the tetrahedra `(b₀ b₁ b₂ m₀)`,
//!   `(b₁ b₂ m₀ m₁)`, `(b₂ m₀ m₁ m₂)`, has the opposite sign of the same sum at `t = 0`: the
//!   boundary passes through the medial sheet or the sheet through the boundary. A prism that
//!   is a sliver at `t = 0` ([`SLIVER`]: long spokes over a small or skewed triangle, as at the
//!   rim of a finely sampled sheet) is not judged: the sign of its volume changes under smooth
//!   maps that fold nothing. Its corners are corners of other prisms, which are
//!   (docs/decisions/0032-fold-test-for-slivers.md).
//!   For a plain mesh, or the boundary alone ([`Guard::of_surface`]), a triangle is
//!   inverted when its normal `(p_b − p_a) × (p_c − p_a)` turns against its normal at `t = 0`
//!   (negative dot product).
//!
//! The checks cost `O(triangles)` per iterate: nothing against one evaluation.

use crate::fit::objective::Evaluation;
use crate::model::{MedialTemplate, Model};
use crate::Vec3;
use serde::{Deserialize, Serialize};

/// An objective above `DIVERGED · max(|E₀|, 1)`, `E₀` its value at the start of the stage,
/// counts as diverged.
pub const DIVERGED: f64 = 1e6;

/// Why an iterate is not sound.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Unsound {
    /// A figure that must be finite is not; names it.
    NonFinite(String),
    /// The Dice estimate left `[0, 1]`.
    DiceOutOfRange(f64),
    /// The objective rose far above the stage's start.
    Diverged {
        /// The objective at the iterate.
        total: f64,
        /// The objective at the start of the stage.
        start: f64,
    },
    /// Boundary–medial prisms turned inside out (medial templates).
    FoldedPrisms {
        /// Folded prisms.
        folded: usize,
        /// All prisms (boundary triangles).
        of: usize,
        /// The atom of the first folded prism's first corner.
        atom: usize,
        /// The centre of that prism's boundary triangle at the end of the flow, mm.
        at: [f64; 3],
    },
    /// Boundary triangles whose orientation flipped (plain meshes).
    InvertedTriangles {
        /// Inverted triangles.
        inverted: usize,
        /// All triangles.
        of: usize,
    },
    /// The objective could not be evaluated at a trial point of the line search; the
    /// engine's message.
    Evaluation(String),
}

impl std::fmt::Display for Unsound {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Unsound::NonFinite(what) => write!(f, "{what} is not finite"),
            Unsound::DiceOutOfRange(d) => {
                write!(f, "the Dice estimate {d} left [0, 1] (the model folds)")
            }
            Unsound::Diverged { total, start } => write!(
                f,
                "the objective diverged ({total:.3e}, from {start:.3e} at the start of the stage)"
            ),
            Unsound::FoldedPrisms {
                folded,
                of,
                atom,
                at,
            } => write!(
                f,
                "the model folds: {folded} of {of} boundary–medial prisms turned inside out, \
                 the first at atom {atom} near ({:.1}, {:.1}, {:.1}) mm",
                at[0], at[1], at[2]
            ),
            Unsound::InvertedTriangles { inverted, of } => write!(
                f,
                "the surface folds: {inverted} of {of} boundary triangles inverted"
            ),
            Unsound::Evaluation(why) => write!(f, "the objective failed at a trial step: {why}"),
        }
    }
}

/// The fold test of a model: the cells whose orientation is watched, with their orientation at
/// `t = 0`.
#[derive(Clone, Debug)]
pub struct Guard {
    cells: Cells,
}

#[derive(Clone, Debug)]
enum Cells {
    /// Medial template: per boundary triangle, the landmarks `[b₀, b₁, b₂, m₀, m₁, m₂]`, the
    /// sign of its prism's volume at `t = 0` ([`judged_sign`]: 0 for a sliver or a degenerate
    /// prism, never flagged), and the atom of `b₀`.
    Prisms(Vec<([usize; 6], f64, usize)>),
    /// Plain mesh: triangles and their normals at `t = 0`.
    Triangles(Vec<([usize; 3], Vec3)>),
}

impl Guard {
    /// The fold test of `model` at its landmarks: its prisms for a medial template, its
    /// triangles for a plain mesh.
    pub fn new(model: &Model) -> Self {
        match model {
            Model::Medial(t) => Self::of_template(t),
            Model::Plain(_) => Self::of_surface(model),
        }
    }

    /// The fold test of `model`'s boundary surface alone: its triangles must not invert. For
    /// stages whose objective does not rely on the medial points staying inside (a medial
    /// template fitted without constraints to points or a surface), where the prisms may fold
    /// as the medial axis drifts.
    pub fn of_surface(model: &Model) -> Self {
        let p = model.landmarks();
        let cells = model
            .boundary_triangles()
            .iter()
            .map(|&t| (t, normal(p, t)))
            .collect();
        Self {
            cells: Cells::Triangles(cells),
        }
    }

    /// The fold test of a medial template at its landmarks.
    pub fn of_template(template: &MedialTemplate) -> Self {
        let q = template.landmarks();
        let atom = template.medial_index();
        let prisms = template
            .boundary_triangles()
            .iter()
            .map(|&[a, b, c]| {
                let m = |v: usize| template.atom_landmark(atom[v]);
                let corners = [a, b, c, m(a), m(b), m(c)];
                (corners, judged_sign(q, &corners), atom[a])
            })
            .collect();
        Self {
            cells: Cells::Prisms(prisms),
        }
    }

    /// Checks the landmarks `q` (all `k`): `Err` with the count when the model folds.
    pub fn check_fold(&self, q: &[Vec3]) -> Result<(), Unsound> {
        match &self.cells {
            Cells::Prisms(prisms) => {
                let mut folded = prisms
                    .iter()
                    .filter(|(corners, sign, _)| prism_volume(q, corners) * sign < 0.0);
                let Some((first, _, atom)) = folded.next() else {
                    return Ok(());
                };
                let at = (q[first[0]] + q[first[1]] + q[first[2]]) / 3.0;
                Err(Unsound::FoldedPrisms {
                    folded: 1 + folded.count(),
                    of: prisms.len(),
                    atom: *atom,
                    at: [at.x, at.y, at.z],
                })
            }
            Cells::Triangles(triangles) => {
                let inverted = triangles
                    .iter()
                    .filter(|(t, n0)| normal(q, *t).dot(n0) < 0.0)
                    .count();
                match inverted {
                    0 => Ok(()),
                    inverted => Err(Unsound::InvertedTriangles {
                        inverted,
                        of: triangles.len(),
                    }),
                }
            }
        }
    }
}

/// Checks an evaluation: finite figures, the Dice estimate in `[0, 1]`, the objective below
/// [`DIVERGED`] `· max(|start|, 1)`, and, with a guard, no fold at the end of the flow.
pub fn check(guard: Option<&Guard>, e: &Evaluation, start: f64) -> Result<(), Unsound> {
    let finite = [
        (e.total, "the objective"),
        (e.kinetic, "the kinetic energy"),
        (e.data, "the data term"),
        (e.penalty, "the penalty"),
        (e.max_abs_constraint, "max |C|"),
    ];
    if let Some((_, what)) = finite.iter().find(|(v, _)| !v.is_finite()) {
        return Err(Unsound::NonFinite((*what).into()));
    }
    if e.final_positions
        .iter()
        .any(|p| !p.iter().all(|c| c.is_finite()))
    {
        return Err(Unsound::NonFinite("a landmark position".into()));
    }
    if let Some(d) = e.dice.filter(|d| !(0.0..=1.0).contains(d)) {
        return Err(Unsound::DiceOutOfRange(d));
    }
    if e.total > DIVERGED * start.abs().max(1.0) {
        return Err(Unsound::Diverged {
            total: e.total,
            start,
        });
    }
    guard.map_or(Ok(()), |g| g.check_fold(&e.final_positions))
}

/// A prism whose volume at `t = 0` is below this fraction of `A·h̄` (its boundary triangle's
/// area times its mean spoke length: the volume of the right prism on that triangle) is a
/// sliver: the sign of its volume is not judged.
pub const SLIVER: f64 = 0.2;

/// The sign of the volume of the prism `c` at `t = 0`, or 0 for a [`SLIVER`] (not judged).
fn judged_sign(q: &[Vec3], c: &[usize; 6]) -> f64 {
    let area = 0.5 * normal(q, [c[0], c[1], c[2]]).norm();
    let mean_spoke = (0..3).map(|i| (q[c[i]] - q[c[i + 3]]).norm()).sum::<f64>() / 3.0;
    let volume = prism_volume(q, c);
    if volume.abs() >= SLIVER * area * mean_spoke && volume != 0.0 {
        volume.signum()
    } else {
        0.0
    }
}

/// Signed volume of a prism `[b₀, b₁, b₂, m₀, m₁, m₂]`: the sum of its three tetrahedra
/// `(b₀ b₁ b₂ m₀)`, `(b₁ b₂ m₀ m₁)`, `(b₂ m₀ m₁ m₂)`.
fn prism_volume(q: &[Vec3], c: &[usize; 6]) -> f64 {
    let vol = |a: usize, b: usize, d: usize, e: usize| {
        (q[b] - q[a]).cross(&(q[d] - q[a])).dot(&(q[e] - q[a])) / 6.0
    };
    vol(c[0], c[1], c[2], c[3]) + vol(c[1], c[2], c[3], c[4]) + vol(c[2], c[3], c[4], c[5])
}

/// `(p_b − p_a) × (p_c − p_a)` of triangle `[a, b, c]`.
fn normal(p: &[Vec3], [a, b, c]: [usize; 3]) -> Vec3 {
    (p[b] - p[a]).cross(&(p[c] - p[a]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::meshes::{bipyramid, octahedron};
    use crate::{MedialTemplate, TriMesh};

    fn evaluation(q: &[Vec3]) -> Evaluation {
        Evaluation {
            total: 1.0,
            final_positions: q.to_vec(),
            ..Evaluation::default()
        }
    }

    #[test]
    fn a_medial_template_is_sound_until_a_spoke_crosses_its_sheet() {
        let t = bipyramid(0.5);
        let guard = Guard::of_template(&t);
        let mut q = t.landmarks().to_vec();
        assert_eq!(check(Some(&guard), &evaluation(&q), 1.0), Ok(()));
        // Scaling and rotating keep every prism's orientation.
        let r = nalgebra::Rotation3::from_euler_angles(0.3, -0.2, 1.0);
        let moved: Vec<Vec3> = q.iter().map(|p| r * p * 2.5).collect();
        assert_eq!(guard.check_fold(&moved), Ok(()));
        // The top apex pushed through the medial sheet: its six prisms turn inside out, the
        // first (triangle 0, of atom 0) centred at the mean of the apex and two rim points.
        q[0].z = -0.2;
        let Err(Unsound::FoldedPrisms {
            folded,
            of,
            atom,
            at,
        }) = guard.check_fold(&q)
        else {
            panic!("the pushed apex must fold the model");
        };
        assert_eq!((folded, of, atom), (6, 12, 0));
        let expected = (q[0] + q[2] + q[3]) / 3.0;
        assert!((Vec3::from(at) - expected).norm() < 1e-12);
        let message = guard.check_fold(&q).unwrap_err().to_string();
        assert!(
            message.contains("at atom 0 near (0.8, 0.4, -0.1) mm"),
            "{message}"
        );
    }

    /// A sliver prism: a medial triangle 0.05 wide under spokes 2 long, its top boundary
    /// triangle nearly edge-on to them. Its tip swinging 0.1 across (a smooth map need not be
    /// affine over the spokes' length) flips the prism's volume but folds nothing; the
    /// well-shaped neighbour pushed through the sheet is caught.
    #[test]
    fn a_sliver_is_not_judged_by_its_volume_and_a_real_fold_still_is() {
        let medial = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.5, 0.05, 0.0),
            Vec3::new(0.5, -1.0, 0.0),
        ];
        let mut boundary: Vec<Vec3> = medial.iter().map(|m| m + Vec3::z() * 2.0).collect();
        boundary[2].z = 3.0;
        boundary.extend(medial.iter().map(|m| m - Vec3::z() * 2.0));
        let triangles = vec![
            [0, 1, 2],
            [0, 3, 1],
            [4, 6, 5],
            [4, 5, 7],
            [1, 3, 7],
            [1, 7, 5],
            [3, 0, 4],
            [3, 4, 7],
            [0, 2, 6],
            [0, 6, 4],
            [2, 1, 5],
            [2, 5, 6],
        ];
        let mesh = TriMesh::new(boundary, triangles).unwrap();
        let template = MedialTemplate::new(mesh, vec![0, 1, 2, 3, 0, 1, 2, 3], medial).unwrap();
        let guard = Guard::of_template(&template);
        let Cells::Prisms(prisms) = &guard.cells else {
            panic!("a medial template has prisms");
        };
        assert_eq!(prisms[0].1, 0.0, "the sliver is not judged");
        assert_eq!(prisms[1].1, -1.0, "the neighbour is");
        // The sliver's tip swung across: its volume flips, nothing folds.
        let mut q = template.landmarks().to_vec();
        q[2].y = -0.05;
        let volume = |q: &[Vec3]| prism_volume(q, &prisms[0].0);
        assert!(volume(template.landmarks()) * volume(&q) < 0.0);
        assert_eq!(guard.check_fold(&q), Ok(()));
        // The neighbour's top pushed through the sheet: it folds.
        for b in [0, 1, 3] {
            q[b].z = -1.0;
        }
        let verdict = guard.check_fold(&q);
        assert!(
            matches!(verdict, Err(Unsound::FoldedPrisms { atom: 0, .. })),
            "{verdict:?}"
        );
    }

    #[test]
    fn a_plain_mesh_is_inverted_when_a_vertex_passes_through_the_opposite_side() {
        let (points, triangles) = octahedron();
        let mesh = TriMesh::new(points.clone(), triangles).unwrap();
        let guard = Guard::new(&Model::Plain(mesh));
        assert_eq!(guard.check_fold(&points), Ok(()));
        let mut q = points;
        q[4].z = -1.5; // the +z apex pushed through to the far side: its four triangles flip.
        assert_eq!(
            guard.check_fold(&q),
            Err(Unsound::InvertedTriangles { inverted: 4, of: 8 })
        );
    }

    #[test]
    fn non_finite_figures_dice_out_of_range_and_divergence_are_unsound() {
        let q = vec![Vec3::zeros()];
        let mut e = evaluation(&q);
        e.penalty = f64::NAN;
        assert_eq!(
            check(None, &e, 1.0),
            Err(Unsound::NonFinite("the penalty".into()))
        );
        let mut e = evaluation(&q);
        e.dice = Some(5.8);
        assert_eq!(check(None, &e, 1.0), Err(Unsound::DiceOutOfRange(5.8)));
        let mut e = evaluation(&q);
        e.total = 2e7;
        assert!(matches!(
            check(None, &e, 10.0),
            Err(Unsound::Diverged { .. })
        ));
        e.total = 9e6;
        assert_eq!(check(None, &e, 10.0), Ok(()));
        let mut e = evaluation(&[Vec3::new(f64::INFINITY, 0.0, 0.0)]);
        e.dice = Some(0.5);
        assert_eq!(
            check(None, &e, 1.0),
            Err(Unsound::NonFinite("a landmark position".into()))
        );
    }
}
