//! The medial model on the real cmrep template t001: structure, the reference spoke metrics,
//! constraint values against direct formulas, Jacobian and weighted gradient against central
//! finite differences, and invariance under similarity transforms.

use medial::model::constraints::{ConstraintUnits, MedialConstraints};
use medial::model::metrics::SpokeMetrics;
use medial::model::template::MedialTemplate;
use medial::{TriMesh, Vec3};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;

const T001: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/data/cmrep/t001_template_bcmrep.vtk"
);

fn t001() -> MedialTemplate {
    medial::io::cmrep::read_template(Path::new(T001)).expect("t001 is a valid template")
}

/// The template's landmarks moved by independent uniform offsets in `[−amplitude, amplitude]`.
fn perturbed(template: &MedialTemplate, amplitude: f64, seed: u64) -> Vec<Vec3> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    template
        .landmarks()
        .iter()
        .map(|p| p + amplitude * Vec3::from_fn(|_, _| rng.gen_range(-1.0..1.0)))
        .collect()
}

fn values(constraints: &MedialConstraints, q: &[Vec3]) -> Vec<f64> {
    let mut out = vec![f64::NAN; constraints.len()];
    constraints.evaluate(q, &mut out);
    out
}

fn max_abs(values: impl IntoIterator<Item = f64>) -> f64 {
    values.into_iter().fold(0.0, |m, v| m.max(v.abs()))
}

/// `template` with the spokes of atom `from` given to atom `into`, and the last atom renumbered
/// `from` (so that the atoms stay numbered without gaps); `from` and `into` are not the last.
fn merge_atoms(template: &MedialTemplate, from: usize, into: usize) -> MedialTemplate {
    let last = template.medial_count() - 1;
    let index = template
        .medial_index()
        .iter()
        .map(|&m| match m {
            m if m == from => into,
            m if m == last => from,
            m => m,
        })
        .collect();
    let mut medial = template.medial_points().to_vec();
    medial.swap(from, last);
    medial.pop();
    let mesh = TriMesh::new(
        template.boundary_points().to_vec(),
        template.boundary_triangles().to_vec(),
    )
    .expect("valid mesh");
    MedialTemplate::new(mesh, index, medial).expect("valid merged template")
}

#[test]
fn t001_structure() {
    let t = t001();
    assert_eq!(
        (t.boundary_count(), t.medial_count(), t.landmark_count()),
        (314, 189, 503)
    );
    assert_eq!(t.boundary_triangles().len(), 624);
    let count = |n: usize| {
        (0..t.medial_count())
            .filter(|&m| t.spokes(m).len() == n)
            .count()
    };
    assert_eq!((count(1), count(2), count(3)), (64, 125, 0));
    // Every medial triangle comes from a pair of boundary triangles (the two sides).
    assert_eq!(t.medial_triangles().len(), 312);
    let c = MedialConstraints::new(&t);
    assert_eq!(
        (c.len(), c.orthogonality_count(), c.equal_spoke_count()),
        (753, 628, 125)
    );
    assert_eq!(t.tangents().w1().shape(), (314, 314));
    assert_eq!(t.tangents().w1().nnz(), 2 * 3 * 624 / 2);
}

/// The reference figures of the data set (README): 0.07° and 0.07 %. Measured here:
/// max 0.070140°, mean 0.011918°, max mismatch 0.066982 %.
#[test]
fn t001_reference_metrics() {
    let t = t001();
    let m = SpokeMetrics::compute(&t, t.landmarks());
    assert!(
        (m.max_spoke_normal_deg - 0.070140).abs() < 5e-6,
        "{}",
        m.max_spoke_normal_deg
    );
    assert!(
        (m.mean_spoke_normal_deg - 0.011918).abs() < 5e-6,
        "{}",
        m.mean_spoke_normal_deg
    );
    assert!(
        (m.max_spoke_mismatch - 6.6982e-4).abs() < 5e-8,
        "{}",
        m.max_spoke_mismatch
    );
    assert_eq!(m.spoke_normal_deg.len(), 314);
    assert_eq!((m.mismatch.len(), m.thickness.len()), (189, 189));
    for atom in 0..t.medial_count() {
        let spokes = t.spokes(atom);
        let mean = spokes.iter().map(|&b| m.spoke_length[b]).sum::<f64>() / spokes.len() as f64;
        assert!((m.thickness[atom] - 2.0 * mean).abs() < 1e-12);
    }
    // The Loop normals point outward: within 0.07° of the file's unit outward normals.
    let data = medial::io::vtk::read_polydata(Path::new(T001)).expect("reads");
    let file = data.point_array_ci("normals").expect("t001 has normals");
    for (b, n) in t.tangents().normals(t.landmarks()).iter().enumerate() {
        let f = Vec3::from_column_slice(&file.values[3 * b..3 * b + 3]);
        assert!(
            n.dot(&f) > 0.07_f64.to_radians().cos(),
            "normal of point {b}"
        );
    }
}

#[test]
fn constraint_values_match_direct_formulas() {
    let t = t001();
    let c = MedialConstraints::new(&t);
    let q = perturbed(&t, 0.5, 1);
    let got = values(&c, &q);
    // W^γ q through the sparse matrices, one coordinate at a time.
    let nb = t.boundary_count();
    let tangent = |w: &sprs::CsMat<f64>| -> Vec<Vec3> {
        let mut out = vec![Vec3::zeros(); nb];
        for (b, row) in w.outer_iterator().enumerate() {
            for (v, &weight) in row.iter() {
                out[b] += weight * q[v];
            }
        }
        out
    };
    let (t1, t2) = (tangent(&t.tangents().w1()), tangent(&t.tangents().w2()));
    let mut expected = Vec::new();
    for b in 0..nb {
        let spoke = q[b] - q[nb + t.medial_index()[b]];
        expected.extend([spoke.dot(&t1[b]), spoke.dot(&t2[b])]);
    }
    for m in 0..t.medial_count() {
        let s = t.spokes(m);
        let r2 = |b: usize| (q[b] - q[nb + m]).norm_squared();
        expected.extend(s[1..].iter().map(|&b| r2(b) - r2(s[0])));
    }
    assert_eq!(expected.len(), got.len());
    let scale = max_abs(expected.iter().copied());
    assert!(
        scale > 1.0,
        "perturbation makes the constraints non-trivial: {scale}"
    );
    let error = max_abs(got.iter().zip(&expected).map(|(a, b)| a - b));
    assert!(error <= 1e-12 * scale, "max error {error}, scale {scale}");
}

/// Dense `L × 3k` Jacobian by central differences of step `h`.
fn finite_difference_jacobian(c: &MedialConstraints, q: &[Vec3], h: f64) -> Vec<Vec<f64>> {
    let mut columns = Vec::with_capacity(3 * q.len());
    let mut x = q.to_vec();
    for i in 0..q.len() {
        for a in 0..3 {
            x[i][a] = q[i][a] + h;
            let plus = values(c, &x);
            x[i][a] = q[i][a] - h;
            let minus = values(c, &x);
            x[i][a] = q[i][a];
            columns.push(
                plus.iter()
                    .zip(&minus)
                    .map(|(p, m)| (p - m) / (2.0 * h))
                    .collect(),
            );
        }
    }
    columns
}

fn check_jacobian(t: &MedialTemplate, seed: u64, units: ConstraintUnits) {
    let c = MedialConstraints::with_units(t, units).unwrap();
    let q = perturbed(t, 0.5, seed);
    let jac = c.jacobian(&q);
    assert_eq!(jac.shape(), (c.len(), 3 * q.len()));
    let mut dense = vec![vec![0.0; c.len()]; 3 * q.len()];
    for (row, entries) in jac.outer_iterator().enumerate() {
        for (col, &v) in entries.iter() {
            dense[col][row] += v;
        }
    }
    let fd = finite_difference_jacobian(&c, &q, 1e-3);
    let scale = max_abs(fd.iter().flatten().copied());
    let error = max_abs(
        dense
            .iter()
            .flatten()
            .zip(fd.iter().flatten())
            .map(|(a, b)| a - b),
    );
    assert!(
        error <= 1e-6 * scale,
        "Jacobian: max error {error}, scale {scale}"
    );
}

fn check_gradient(t: &MedialTemplate, seed: u64, units: ConstraintUnits) {
    let c = MedialConstraints::with_units(t, units).unwrap();
    let q = perturbed(t, 0.5, seed);
    let mut rng = ChaCha8Rng::seed_from_u64(seed + 100);
    let weights: Vec<f64> = (0..c.len()).map(|_| rng.gen_range(-2.0..2.0)).collect();
    let f = |x: &[Vec3]| {
        values(&c, x)
            .iter()
            .zip(&weights)
            .map(|(v, w)| v * w)
            .sum::<f64>()
    };
    // Start from a non-zero gradient: the method adds.
    let offset = Vec3::new(1.0, -2.0, 0.5);
    let mut grad = vec![offset; q.len()];
    c.accumulate_gradient(&q, &weights, &mut grad);
    let h = 1e-3;
    let mut x = q.clone();
    let mut fd = Vec::with_capacity(3 * q.len());
    let mut analytic = Vec::with_capacity(3 * q.len());
    for i in 0..q.len() {
        for a in 0..3 {
            x[i][a] = q[i][a] + h;
            let plus = f(&x);
            x[i][a] = q[i][a] - h;
            let minus = f(&x);
            x[i][a] = q[i][a];
            fd.push((plus - minus) / (2.0 * h));
            analytic.push(grad[i][a] - offset[a]);
        }
    }
    let scale = max_abs(fd.iter().copied());
    let error = max_abs(analytic.iter().zip(&fd).map(|(a, b)| a - b));
    assert!(
        error <= 1e-6 * scale,
        "gradient: max error {error}, scale {scale}"
    );
    // Deterministic: a second accumulation gives the same bits.
    let mut again = vec![offset; q.len()];
    c.accumulate_gradient(&q, &weights, &mut again);
    assert_eq!(grad, again);
}

#[test]
fn jacobian_matches_central_differences() {
    check_jacobian(&t001(), 2, ConstraintUnits::Absolute);
    check_jacobian(&t001(), 2, ConstraintUnits::Relative);
}

#[test]
fn weighted_gradient_matches_central_differences() {
    check_gradient(&t001(), 3, ConstraintUnits::Absolute);
    check_gradient(&t001(), 3, ConstraintUnits::Relative);
}

/// Relative units divide each constraint by a constant of the template: orthogonality by
/// `|s⁰_b| |t⁰_γ|`, equal spokes by `2 |s⁰_{b_0}|²`. They are therefore dimensionless: the same
/// values for a template and configuration both scaled by λ (absolute ones scale by λ²). At
/// the template itself, the orthogonality values are the cosines of the angles between spokes
/// and Loop tangents.
#[test]
fn relative_units_are_scaled_absolute_units_and_dimensionless() {
    let t = t001();
    let absolute = MedialConstraints::new(&t);
    let relative = MedialConstraints::with_units(&t, ConstraintUnits::Relative).unwrap();
    assert_eq!(relative.units(), ConstraintUnits::Relative);
    assert_eq!(absolute.units(), ConstraintUnits::Absolute);
    let q0 = t.landmarks();
    let (a0, r0) = (values(&absolute, q0), values(&relative, q0));
    let nb = t.boundary_count();
    let tangents: Vec<Vec3> = [t.tangents().w1(), t.tangents().w2()]
        .iter()
        .flat_map(|w| {
            let mut out = vec![Vec3::zeros(); nb];
            for (b, row) in w.outer_iterator().enumerate() {
                for (v, &weight) in row.iter() {
                    out[b] += weight * q0[v];
                }
            }
            out
        })
        .collect();
    for b in 0..nb {
        let spoke = q0[b] - q0[nb + t.medial_index()[b]];
        for g in 0..2 {
            let tangent = tangents[g * nb + b];
            let cosine = spoke.dot(&tangent) / (spoke.norm() * tangent.norm());
            assert!((r0[2 * b + g] - cosine).abs() < 1e-12);
            assert!((r0[2 * b + g] * spoke.norm() * tangent.norm() - a0[2 * b + g]).abs() < 1e-12);
        }
    }
    let lambda = 3.7;
    let scaled = t
        .with_landmarks(&q0.iter().map(|p| lambda * p).collect::<Vec<_>>())
        .unwrap();
    let q = perturbed(&t, 0.5, 11);
    let q_scaled: Vec<Vec3> = q.iter().map(|p| lambda * p).collect();
    let relative_scaled =
        MedialConstraints::with_units(&scaled, ConstraintUnits::Relative).unwrap();
    let absolute_scaled = MedialConstraints::new(&scaled);
    let (r, rs) = (values(&relative, &q), values(&relative_scaled, &q_scaled));
    let (a, as_) = (values(&absolute, &q), values(&absolute_scaled, &q_scaled));
    for l in 0..r.len() {
        assert!((r[l] - rs[l]).abs() <= 1e-9 * r[l].abs().max(1e-3), "{l}");
        assert!((lambda * lambda * a[l] - as_[l]).abs() <= 1e-9 * as_[l].abs().max(1e-3));
    }
}

/// A seam atom (3 spokes): two equal-spoke constraints, derivatives still exact.
#[test]
fn three_spoke_atom_derivatives() {
    let t = t001();
    let atoms_with = |n: usize| (0..t.medial_count() - 1).find(|&m| t.spokes(m).len() == n);
    let single = atoms_with(1).expect("a free-edge atom");
    let double = atoms_with(2).expect("a sheet atom");
    let merged = merge_atoms(&t, single, double);
    assert_eq!(merged.spokes(double).len(), 3);
    let c = MedialConstraints::new(&merged);
    assert_eq!(c.len(), 753 + 1);
    check_jacobian(&merged, 4, ConstraintUnits::Relative);
    check_gradient(&merged, 5, ConstraintUnits::Absolute);
}

/// Rotation about `axis` (any length) by `angle`, then scaling by `scale`, then translation.
fn similarity(q: &[Vec3], axis: Vec3, angle: f64, scale: f64, shift: Vec3) -> Vec<Vec3> {
    let rotation =
        nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle);
    q.iter().map(|p| scale * (rotation * p) + shift).collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// `C(sRq + t) = s² C(q)`; angles and mismatches are unchanged; lengths scale by `s`.
    #[test]
    fn similarity_invariance(
        axis in prop::array::uniform3(-1.0f64..1.0).prop_filter("non-zero axis", |a| {
            a.iter().map(|x| x * x).sum::<f64>() > 1e-2
        }),
        angle in -3.0f64..3.0,
        scale in 0.5f64..2.0,
        shift in prop::array::uniform3(-100.0f64..100.0),
        seed in 0u64..1000,
    ) {
        let t = t001();
        let c = MedialConstraints::new(&t);
        let q = perturbed(&t, 0.3, seed);
        let moved = similarity(&q, Vec3::from(axis), angle, scale, Vec3::from(shift));
        let (before, after) = (values(&c, &q), values(&c, &moved));
        let tolerance = 1e-9 * scale * scale * max_abs(before.iter().copied()).max(1.0);
        for (a, b) in after.iter().zip(&before) {
            prop_assert!((a - scale * scale * b).abs() <= tolerance, "{} vs {}", a, scale * scale * b);
        }
        let (m0, m1) = (SpokeMetrics::compute(&t, &q), SpokeMetrics::compute(&t, &moved));
        for (a, b) in m1.spoke_normal_deg.iter().zip(&m0.spoke_normal_deg) {
            prop_assert!((a - b).abs() < 1e-6, "angle {} vs {}", a, b);
        }
        for (a, b) in m1.mismatch.iter().zip(&m0.mismatch) {
            prop_assert!((a - b).abs() < 1e-9, "mismatch {} vs {}", a, b);
        }
        for (a, b) in m1.thickness.iter().zip(&m0.thickness) {
            prop_assert!((a - scale * b).abs() < 1e-9 * scale * b.max(1.0), "thickness {} vs {}", a, b);
        }
    }
}
