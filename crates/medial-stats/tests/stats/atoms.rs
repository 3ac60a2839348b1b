//! Per-atom measures on the repository's templates (cmrep's t001: one sheet with a free edge;
//! the toy: three sheets meeting at a seam), against relations that hold by construction.

use medial_core::model::Model;
use medial_core::{MedialTemplate, Vec3};
use medial_stats::{atom_values, Alignment, AtomMeasure, SheetNormals};
use nalgebra::{Rotation3, Vector3};
use std::path::Path;

fn template(name: &str) -> MedialTemplate {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../examples/{name}/template.vtk"));
    match medial_io::model::read_model(&path).unwrap() {
        Model::Medial(t) => *t,
        _ => panic!("{name}: not a medial template"),
    }
}

/// The template with every landmark mapped by `f`.
fn moved(t: &MedialTemplate, f: impl Fn(usize, Vec3) -> Vec3) -> MedialTemplate {
    let q: Vec<Vec3> = t
        .landmarks()
        .iter()
        .enumerate()
        .map(|(i, p)| f(i, *p))
        .collect();
    t.with_landmarks(&q).unwrap()
}

#[test]
fn medial_normals_are_consistent_across_each_sheet_and_none_at_seams() {
    for name in ["t001", "toy"] {
        let t = template(name);
        let normals = SheetNormals::new(&t);
        let n = normals.normals();
        let mut pairs = 0;
        for tri in t.medial_triangles() {
            for (a, b) in [(tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])] {
                if let (Some(x), Some(y)) = (n[a], n[b]) {
                    let dot: f64 = (0..3).map(|d| x[d] * y[d]).sum();
                    assert!(
                        dot > 0.0,
                        "{name}: atoms {a} and {b} face opposite ways ({dot})"
                    );
                    pairs += 1;
                }
            }
        }
        assert!(pairs > 100, "{name}: {pairs} neighbouring pairs checked");
        for (a, normal) in n.iter().enumerate() {
            let spokes = t.spokes(a).len();
            let by_seam = t
                .medial_triangles()
                .iter()
                .any(|tri| tri.contains(&a) && tri.iter().any(|&b| t.spokes(b).len() == 3));
            let expected_none = spokes == 3 || (spokes == 1 && by_seam);
            assert_eq!(
                normal.is_none(),
                expected_none,
                "{name}: atom {a} with {spokes} spokes"
            );
            if let Some(v) = *normal {
                assert!(((v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt() - 1.0).abs() < 1e-12);
            }
        }
        // A sheet atom's normal is across the sheet: its two spokes point to either side.
        for a in (0..t.medial_count()).filter(|&a| t.spokes(a).len() == 2) {
            let v = Vector3::from(n[a].unwrap());
            let m = t.medial_points()[a];
            let sides: Vec<f64> = t
                .spokes(a)
                .iter()
                .map(|&b| (t.landmarks()[b] - m).dot(&v))
                .collect();
            assert!(sides[0] * sides[1] < 0.0, "{name}: atom {a}");
        }
    }
}

#[test]
fn thickness_is_the_sum_of_the_two_sides_spokes_and_spokes_follow_the_normal() {
    let t = template("t001");
    let normals = SheetNormals::new(&t);
    let values = |m: AtomMeasure| atom_values(&t, &normals, &t, &m, Alignment::None).unwrap();
    let (thickness, pos, neg) = (
        values(AtomMeasure::Thickness),
        values(AtomMeasure::SpokePositive),
        values(AtomMeasure::SpokeNegative),
    );
    let (s1, s2, s3) = (
        values(AtomMeasure::Spoke(0)),
        values(AtomMeasure::Spoke(1)),
        values(AtomMeasure::Spoke(2)),
    );
    for a in 0..t.medial_count() {
        let m = t.medial_points()[a];
        match t.spokes(a) {
            [b] => {
                let r = (t.landmarks()[*b] - m).norm();
                assert_eq!((pos[a], neg[a], s1[a]), (r, r, r));
                assert!(s2[a].is_nan() && s3[a].is_nan());
                assert!((thickness[a] - 2.0 * r).abs() < 1e-12);
            }
            [_, _] => {
                assert!((thickness[a] - (pos[a] + neg[a])).abs() < 1e-12);
                assert!((s1[a] + s2[a] - pos[a] - neg[a]).abs() < 1e-12);
                // The + spoke is the one along the normal.
                let n = Vector3::from(normals.normals()[a].unwrap());
                let along = t
                    .spokes(a)
                    .iter()
                    .find(|&&b| (t.landmarks()[b] - m).dot(&n) > 0.0)
                    .unwrap();
                assert_eq!(pos[a], (t.landmarks()[*along] - m).norm());
            }
            _ => unreachable!("t001 has no seam"),
        }
    }
}

#[test]
fn displacement_recovers_a_planted_move_along_the_normal_and_ignores_a_rigid_motion() {
    for name in ["t001", "toy"] {
        let t = template(name);
        let normals = SheetNormals::new(&t);
        let nb = t.boundary_count();
        // Each atom moved by δ(a) along its normal (seams not moved), boundary unchanged.
        let delta = |a: usize| 0.3 * ((a % 7) as f64 - 3.0);
        let planted = moved(&t, |i, p| {
            match i
                .checked_sub(nb)
                .and_then(|a| normals.normals()[a].map(|n| (a, n)))
            {
                Some((a, n)) => p + delta(a) * Vector3::from(n),
                None => p,
            }
        });
        let d = atom_values(
            &t,
            &normals,
            &planted,
            &AtomMeasure::Displacement,
            Alignment::None,
        )
        .unwrap();
        for (a, (normal, value)) in normals.normals().iter().zip(&d).enumerate() {
            match normal {
                Some(_) => assert!((value - delta(a)).abs() < 1e-12, "{name}: atom {a}"),
                None => assert!(value.is_nan()),
            }
        }
        // The template turned and shifted: no displacement once aligned, a large one without.
        let r = Rotation3::new(Vector3::new(0.3, -0.2, 0.5));
        let turned = moved(&t, |_, p| r * p + Vector3::new(10.0, -5.0, 3.0));
        let rigid = atom_values(
            &t,
            &normals,
            &turned,
            &AtomMeasure::Displacement,
            Alignment::Rigid,
        )
        .unwrap();
        assert!(
            rigid.iter().filter(|v| !v.is_nan()).all(|v| v.abs() < 1e-9),
            "{name}"
        );
        let raw = atom_values(
            &t,
            &normals,
            &turned,
            &AtomMeasure::Displacement,
            Alignment::None,
        )
        .unwrap();
        assert!(
            raw.iter().filter(|v| !v.is_nan()).any(|v| v.abs() > 1.0),
            "{name}"
        );
        // Scaled too: only a similarity alignment takes it out.
        let scaled = moved(&t, |_, p| 1.2 * (r * p));
        let similar = atom_values(
            &t,
            &normals,
            &scaled,
            &AtomMeasure::Displacement,
            Alignment::Similarity,
        )
        .unwrap();
        assert!(
            similar
                .iter()
                .filter(|v| !v.is_nan())
                .all(|v| v.abs() < 1e-9),
            "{name}"
        );
    }
}

#[test]
fn measures_are_parsed_by_name_and_other_models_refused() {
    assert_eq!(AtomMeasure::parse("thickness"), AtomMeasure::Thickness);
    assert_eq!(AtomMeasure::parse("spoke2"), AtomMeasure::Spoke(1));
    assert_eq!(
        AtomMeasure::parse("ball_residual"),
        AtomMeasure::Column("fidelity".into())
    );
    assert_eq!(
        AtomMeasure::parse("x_t1"),
        AtomMeasure::Column("x_t1".into())
    );
    let (t001, toy) = (template("t001"), template("toy"));
    let normals = SheetNormals::new(&t001);
    let e = atom_values(
        &t001,
        &normals,
        &toy,
        &AtomMeasure::Thickness,
        Alignment::None,
    )
    .unwrap_err();
    assert!(e.to_string().starts_with("atoms of a fitted model"), "{e}");
}
