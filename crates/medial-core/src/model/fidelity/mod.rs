//! Medial fidelity, the paper's claim itself (docs/method.md §8): is every medial point still the centre
//! of a ball inscribed in the boundary, of the radius its spokes say?
//!
//! For atom `m` with medial point `x_m` and spokes `s_b = q_b − x_m`:
//!
//! ```text
//! r_m = mean_b |s_b|                       (coordinate unit, mm)
//! d_m = min_{y ∈ ∂O} |y − x_m|            (distance to the boundary surface)
//! residual_m = |d_m − r_m| / r_m           (a fraction)
//! ```
//!
//! `∂O` is a smooth surface through the boundary landmarks, the modified butterfly surface of
//! the boundary mesh ([`butterfly`]), not the boundary's chords: the chords cut into the ball
//! wherever the wall curves (on cmrep's t001 template they give 13 % mean residual over all
//! atoms, 5.8 % on sheet atoms; the butterfly surface 1.3 % on sheet atoms). `d_m` is the exact
//! distance to the nearest triangle of that surface, found with the bounding-volume hierarchy
//! of a `parry3d` triangle mesh, which also says on which side of the surface `x_m` lies (by
//! the pseudo-normal of the nearest feature).
//!
//! The surface passes through every spoke end, so `d_m` is at most the shortest spoke and the
//! residual is `(r_m − d_m) / r_m ≥ 0`: how far the boundary reaches into the ball. The ball
//! **pokes out** of the object (the paper's condition 5, which the medial constraints do not
//! enforce) when that is more than [`POKE_TOLERANCE`] of the radius, or when `x_m` lies outside
//! the object. A zero radius gives a NaN residual, which counts as poking out.
//!
//! Free-edge atoms (one spoke) are reported apart ([`FidelitySummary::edge`]): their ball is
//! the end of the wall, where a template's boundary is rounded by its own rule, and their
//! residual is large even on a template (17 % on t001). Sheet atoms (two spokes) and seam atoms
//! (three) form [`FidelitySummary::sheet`].

pub mod butterfly;

use crate::model::template::MedialTemplate;
use crate::Vec3;
use butterfly::{ButterflySurface, LEVELS};
use parry3d_f64::query::PointQueryWithLocation;
use parry3d_f64::shape::{TriMesh as ParryMesh, TriMeshFlags};
use rayon::prelude::*;

/// Residual above which a ball counts as poking out: 5 % of its radius. The medial constraints
/// at their default tolerances (1°, 1 %) leave about 1 %; the butterfly surface itself differs
/// from a finer one by well under 1 %; the shipped templates' sheet atoms have a median residual
/// of 0.1–2 %, and a fit without constraints reaches tens of per cent.
pub const POKE_TOLERANCE: f64 = 0.05;

/// The fidelity of every atom of one landmark configuration, with summaries.
#[derive(Clone, Debug, PartialEq)]
pub struct Fidelity {
    /// Per atom: `r_m`, the mean spoke length (coordinate unit).
    pub radius: Vec<f64>,
    /// Per atom: `d_m`, the distance from the medial point to the boundary surface.
    pub distance: Vec<f64>,
    /// Per atom: `|d_m − r_m| / r_m`, a fraction.
    pub residual: Vec<f64>,
    /// Per atom: whether the medial point lies inside the boundary surface.
    pub inside: Vec<bool>,
    /// Per atom: whether the ball pokes out (residual above [`POKE_TOLERANCE`] or not finite,
    /// or the medial point outside).
    pub pokes_out: Vec<bool>,
    /// Summaries of sheet and free-edge atoms.
    pub summary: FidelitySummary,
}

/// The figures of sheet atoms and of free-edge atoms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FidelitySummary {
    /// Atoms with two or three spokes (sheet interior and seams).
    pub sheet: GroupFidelity,
    /// Atoms with one spoke (free edges).
    pub edge: GroupFidelity,
}

/// The figures of a group of atoms. The mean and maximum are NaN if a residual is, and for a
/// group without atoms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroupFidelity {
    /// Number of atoms in the group.
    pub atoms: usize,
    /// Mean residual, a fraction.
    pub mean_residual: f64,
    /// Largest residual, a fraction.
    pub max_residual: f64,
    /// Atoms whose ball pokes out.
    pub poking_out: usize,
}

/// Measures the fidelity of a template's structure at any landmark positions; the butterfly
/// surface's weights are built once.
#[derive(Clone, Debug)]
pub struct BallFidelity {
    surface: ButterflySurface,
    /// Landmark count `k` of the template.
    landmarks: usize,
    /// Per atom: its spokes (boundary point indices) and its landmark index.
    atoms: Vec<(Vec<usize>, usize)>,
}

impl BallFidelity {
    /// Prepares the measurement for `template`'s structure.
    pub fn new(template: &MedialTemplate) -> Self {
        let surface = ButterflySurface::new(
            template.boundary_count(),
            template.boundary_triangles(),
            LEVELS,
        )
        .expect("a template's boundary is closed and oriented, and so are its subdivisions");
        let atoms = (0..template.medial_count())
            .map(|m| (template.spokes(m).to_vec(), template.atom_landmark(m)))
            .collect();
        Self {
            surface,
            landmarks: template.landmark_count(),
            atoms,
        }
    }

    /// The fidelity at landmarks `q` (boundary points, then medial points). Landmarks that are
    /// not all finite are reported, not refused: every distance is NaN and every medial point
    /// counts as outside.
    ///
    /// # Panics
    /// If `q.len()` differs from the template's landmark count.
    pub fn measure(&self, q: &[Vec3]) -> Fidelity {
        assert_eq!(
            q.len(),
            self.landmarks,
            "medial fidelity: one point per landmark"
        );
        let finite = q.iter().all(|p| p.iter().all(|c| c.is_finite()));
        let mesh = finite.then(|| self.parry_mesh(q));
        let radius: Vec<f64> = self
            .atoms
            .iter()
            .map(|(spokes, m)| mean_spoke(spokes, *m, q))
            .collect();
        let (distance, inside): (Vec<f64>, Vec<bool>) = self
            .atoms
            .par_iter()
            .map(|(_, m)| match &mesh {
                Some(mesh) => nearest(mesh, &q[*m]),
                None => (f64::NAN, false),
            })
            .unzip();
        let residual: Vec<f64> = distance
            .iter()
            .zip(&radius)
            .map(|(d, r)| (d - r).abs() / r)
            .collect();
        let pokes_out: Vec<bool> = residual
            .iter()
            .zip(&inside)
            .map(|(&res, &inside)| !inside || res.is_nan() || res > POKE_TOLERANCE)
            .collect();
        let group = |edge: bool| {
            let members = self
                .atoms
                .iter()
                .enumerate()
                .filter(|(_, (s, _))| (s.len() == 1) == edge);
            GroupFidelity::of(members.map(|(m, _)| (residual[m], pokes_out[m])))
        };
        let summary = FidelitySummary {
            sheet: group(false),
            edge: group(true),
        };
        Fidelity {
            radius,
            distance,
            residual,
            inside,
            pokes_out,
            summary,
        }
    }

    /// The butterfly surface at `q` as a `parry3d` mesh with pseudo-normals (for the side).
    fn parry_mesh(&self, q: &[Vec3]) -> ParryMesh {
        let vertices = self
            .surface
            .vertices(q)
            .into_iter()
            .map(Into::into)
            .collect();
        let triangles = self
            .surface
            .triangles()
            .iter()
            .map(|t| t.map(|i| i as u32))
            .collect();
        ParryMesh::with_flags(vertices, triangles, TriMeshFlags::ORIENTED)
            .expect("a closed boundary has triangles")
    }
}

impl GroupFidelity {
    /// The figures of `(residual, pokes out)` pairs.
    fn of(members: impl Iterator<Item = (f64, bool)>) -> Self {
        let (mut atoms, mut sum, mut max, mut poking_out) = (0, 0.0, f64::NEG_INFINITY, 0);
        for (residual, pokes) in members {
            atoms += 1;
            sum += residual;
            max = if residual.is_nan() || max.is_nan() {
                f64::NAN
            } else {
                max.max(residual)
            };
            poking_out += usize::from(pokes);
        }
        let empty = |x: f64| if atoms == 0 { f64::NAN } else { x };
        Self {
            atoms,
            mean_residual: empty(sum / atoms as f64),
            max_residual: empty(max),
            poking_out,
        }
    }
}

/// `r_m`: the mean length of the spokes from landmark `atom` to the boundary points `spokes`.
fn mean_spoke(spokes: &[usize], atom: usize, q: &[Vec3]) -> f64 {
    spokes.iter().map(|&b| (q[b] - q[atom]).norm()).sum::<f64>() / spokes.len() as f64
}

/// The distance from `x` to the nearest point of `mesh`, and whether `x` is inside it.
fn nearest(mesh: &ParryMesh, x: &Vec3) -> (f64, bool) {
    let point = (*x).into();
    let (projection, _) = mesh.project_local_point_and_get_location(&point, false);
    ((projection.point - point).norm(), projection.is_inside)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::construction::inflate::{inflate, MedialSheet};
    use crate::synth::parameter_grid;
    use approx::assert_relative_eq;
    use nalgebra::{Rotation3, Unit};
    use proptest::prelude::*;

    /// Half thickness of the slab, mm.
    const R: f64 = 0.5;
    /// Cells of the slab's medial grid each way (1 mm cells).
    const CELLS: usize = 8;

    /// A flat slab: the medial sheet a square grid of 8 × 8 mm at z = 0 with radius [`R`],
    /// inflated. Sheet atoms have spokes ±[`R`] z; the boundary is flat (z = ±R) except near
    /// the rim, so a sheet atom far from it has an inscribed ball of radius exactly R.
    fn slab() -> MedialTemplate {
        let (params, triangles) = parameter_grid(CELLS, CELLS).unwrap();
        let points = params
            .iter()
            .map(|&[u, v]| Vec3::new(u, v, 0.0) * CELLS as f64)
            .collect();
        let sheet = MedialSheet::new(points, triangles, vec![R; params.len()]).unwrap();
        let inflated = inflate(&sheet).unwrap();
        MedialTemplate::new(
            inflated.boundary,
            inflated.medial_index,
            inflated.medial_points,
        )
        .unwrap()
    }

    /// The atom at the centre of the slab, (4, 4, 0).
    fn centre_atom() -> usize {
        CELLS / 2 * (CELLS + 1) + CELLS / 2
    }

    #[test]
    fn slab_has_exact_balls_and_a_moved_medial_point_pokes_out_by_its_offset() {
        let t = slab();
        let meter = BallFidelity::new(&t);
        let m = centre_atom();
        assert_eq!(t.medial_points()[m], Vec3::new(4.0, 4.0, 0.0));
        assert_eq!(t.spokes(m).len(), 2);
        let f = meter.measure(t.landmarks());
        assert_relative_eq!(f.radius[m], R, epsilon = 1e-14);
        assert_relative_eq!(f.distance[m], R, epsilon = 1e-12);
        assert!(f.residual[m] < 1e-12 && f.inside[m] && !f.pokes_out[m]);
        assert_eq!(
            f.summary.sheet.atoms + f.summary.edge.atoms,
            t.medial_count()
        );
        assert_eq!(f.summary.edge.atoms, 4 * CELLS);
        // Up by δ: spokes R − δ and R + δ (mean R), the top face at R − δ: residual δ / R.
        for (delta, pokes) in [(0.01, false), (0.2 * R, true)] {
            let mut q = t.landmarks().to_vec();
            q[t.atom_landmark(m)].z += delta;
            let f = meter.measure(&q);
            assert_relative_eq!(f.radius[m], R, epsilon = 1e-14);
            assert_relative_eq!(f.residual[m], delta / R, epsilon = 1e-12);
            assert_eq!(f.pokes_out[m], pokes, "δ = {delta}");
            assert!(f.inside[m]);
        }
        // Out of the slab: outside, and poking out.
        let mut q = t.landmarks().to_vec();
        q[t.atom_landmark(m)].z += 3.0 * R;
        let f = meter.measure(&q);
        assert!(!f.inside[m] && f.pokes_out[m]);
        assert_relative_eq!(f.distance[m], 2.0 * R, epsilon = 1e-12);
        let before = meter.measure(t.landmarks()).summary.sheet.poking_out;
        assert_eq!(f.summary.sheet.poking_out, before + 1);
    }

    #[test]
    fn summaries_are_means_and_maxima_and_non_finite_landmarks_are_reported() {
        let g = GroupFidelity::of([(0.1, false), (0.3, true)].into_iter());
        assert_eq!(g.atoms, 2);
        assert_relative_eq!(g.mean_residual, 0.2);
        assert_eq!((g.max_residual, g.poking_out), (0.3, 1));
        let g = GroupFidelity::of([(f64::NAN, true), (0.3, true)].into_iter());
        assert!(g.mean_residual.is_nan() && g.max_residual.is_nan());
        let g = GroupFidelity::of(std::iter::empty());
        assert!(g.atoms == 0 && g.mean_residual.is_nan());
        let t = slab();
        let meter = BallFidelity::new(&t);
        let mut q = t.landmarks().to_vec();
        q[3].x = f64::INFINITY;
        let f = meter.measure(&q);
        assert!(f.distance.iter().all(|d| d.is_nan()) && f.pokes_out.iter().all(|&p| p));
        assert!(f.summary.sheet.mean_residual.is_nan());
        assert_eq!(f.summary.sheet.poking_out, f.summary.sheet.atoms);
    }

    /// The slab with every medial point moved by a fixed pseudo-random offset of up to 0.3 R,
    /// so that the residuals are neither zero nor alike.
    fn perturbed(t: &MedialTemplate) -> Vec<Vec3> {
        let mut q = t.landmarks().to_vec();
        for (i, p) in q[t.boundary_count()..].iter_mut().enumerate() {
            let a = i as f64;
            *p += 0.3 * R * Vec3::new((1.3 * a).sin(), (2.1 * a).cos(), (0.7 * a).sin())
                / 3f64.sqrt();
        }
        q
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(16))]

        /// Residuals are fractions of the radius: a rigid motion and a scaling change none.
        #[test]
        fn residuals_are_invariant_under_rigid_motion_and_scaling(
            axis in prop::array::uniform3(-1.0f64..1.0),
            angle in -3.1f64..3.1,
            shift in prop::array::uniform3(-50.0f64..50.0),
            log_scale in -3.0f64..3.0,
        ) {
            prop_assume!(Vec3::from(axis).norm() > 0.1);
            let t = slab();
            let meter = BallFidelity::new(&t);
            let q = perturbed(&t);
            let rotation = Rotation3::from_axis_angle(&Unit::new_normalize(Vec3::from(axis)), angle);
            let scale = log_scale.exp();
            let moved: Vec<Vec3> = q.iter().map(|p| scale * (rotation * p) + Vec3::from(shift)).collect();
            let (a, b) = (meter.measure(&q), meter.measure(&moved));
            for m in 0..t.medial_count() {
                prop_assert!((a.residual[m] - b.residual[m]).abs() < 1e-9, "atom {m}: {} vs {}", a.residual[m], b.residual[m]);
                prop_assert!((a.distance[m] * scale - b.distance[m]).abs() < 1e-9 * scale);
                prop_assert_eq!(a.inside[m], b.inside[m]);
                if (a.residual[m] - POKE_TOLERANCE).abs() > 1e-9 {
                    prop_assert_eq!(a.pokes_out[m], b.pokes_out[m]);
                }
            }
        }
    }
}
