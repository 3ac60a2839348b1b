//! Shape modes and mean templates of cohorts made from the shipped toy template: copies moved
//! rigidly (no mode, the mean boundary the toy's), a planted thickening of one end (one mode,
//! its scores the planted amounts), thickened and thinned copies (their mean the toy).

use medial_core::construction::project::ProjectOptions;
use medial_core::model::Model;
use medial_core::{MedialTemplate, Vec3};
use medial_stats::shape::procrustes;
use medial_stats::{mean_template, normal_and_tangential, shape_modes, Alignment, ShapeOf};
use nalgebra::Rotation3;
use std::path::Path;

use crate::common::noise;

fn toy() -> MedialTemplate {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/toy/template.vtk");
    match medial_io::model::read_model(&path).unwrap() {
        Model::Medial(t) => *t,
        _ => panic!("the toy is medial"),
    }
}

/// The toy with atom m's spokes scaled by `scale(m)`, then turned by `angle` about (1, 2, 3)
/// and shifted by `angle` × (10, −5, 2).
fn subject(t: &MedialTemplate, scale: impl Fn(usize) -> f64, angle: f64) -> MedialTemplate {
    let mut q = t.landmarks().to_vec();
    for (b, &m) in t.medial_index().iter().enumerate() {
        let centre = q[t.atom_landmark(m)];
        q[b] = centre + (q[b] - centre) * scale(m);
    }
    let r = Rotation3::new(Vec3::new(1.0, 2.0, 3.0).normalize() * angle);
    let shift = Vec3::new(10.0, -5.0, 2.0) * angle;
    let moved: Vec<Vec3> = q.iter().map(|p| r * p + shift).collect();
    t.with_landmarks(&moved).unwrap()
}

fn rms(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    let sum: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (0..3).map(|d| (x[d] - y[d]).powi(2)).sum::<f64>())
        .sum();
    (sum / a.len() as f64).sqrt()
}

#[test]
fn rigid_copies_have_no_mode_and_the_mean_boundary_is_the_toys() {
    let t = toy();
    let copies: Vec<MedialTemplate> = (0..4)
        .map(|k| subject(&t, |_| 1.0, 0.3 * k as f64))
        .collect();
    for alignment in [Alignment::Rigid, Alignment::Similarity] {
        let modes = shape_modes(&copies, ShapeOf::Atoms, alignment).unwrap();
        assert!(modes.pca.modes.is_empty(), "{alignment:?}");
        assert!(modes.shape_at(0, 1.0).is_err());
        let boundary = modes.boundary(&modes.gpa.mean);
        let toy: Vec<[f64; 3]> = t.boundary_points().iter().map(|&p| p.into()).collect();
        let onto = procrustes(&toy, &boundary, false).unwrap();
        let placed: Vec<[f64; 3]> = toy.iter().map(|&p| onto.apply(p)).collect();
        let e = rms(&placed, &boundary);
        assert!(
            e < 1e-9,
            "{alignment:?}: the mean boundary is off the toy's by {e} mm"
        );
    }
    // Without alignment the copies differ: the motions are modes.
    let modes = shape_modes(&copies, ShapeOf::Boundary, Alignment::None).unwrap();
    assert!(!modes.pca.modes.is_empty());
    assert!(shape_modes(&copies[..1], ShapeOf::Atoms, Alignment::Rigid).is_err());
}

#[test]
fn a_planted_thickening_is_the_first_mode() {
    let t = toy();
    let end: Vec<bool> = t.medial_points().iter().map(|p| p.z > 6.0).collect();
    let amounts: Vec<f64> = (0..10).map(|k| (k as f64 - 4.5) * 0.03).collect();
    let jitter = noise(10, t.medial_count(), 8);
    let cohort: Vec<MedialTemplate> = amounts
        .iter()
        .enumerate()
        .map(|(i, &a)| {
            let scale = |m: usize| {
                1.0 + if end[m] { a } else { 0.0 } + 0.002 * jitter[i * t.medial_count() + m]
            };
            subject(&t, scale, 0.1 * i as f64)
        })
        .collect();
    for of in [ShapeOf::Atoms, ShapeOf::Boundary] {
        let modes = shape_modes(&cohort, of, Alignment::Rigid).unwrap();
        let explained = modes.pca.explained();
        assert!(
            explained[0] > 0.95,
            "{of:?}: mode 1 explains {}",
            explained[0]
        );
        let scores: Vec<f64> = modes.pca.scores.column(0).iter().copied().collect();
        let (ms, ma) = (
            scores.iter().sum::<f64>() / 10.0,
            amounts.iter().sum::<f64>() / 10.0,
        );
        let cov: f64 = scores
            .iter()
            .zip(&amounts)
            .map(|(s, a)| (s - ms) * (a - ma))
            .sum();
        let ss: f64 = scores.iter().map(|s| (s - ms).powi(2)).sum();
        let sa: f64 = amounts.iter().map(|a| (a - ma).powi(2)).sum();
        let corr = cov / (ss * sa).sqrt();
        assert!(corr.abs() > 0.999, "{of:?}: correlation {corr}");
        // Along the mode the planted end thickens one way and the rest barely moves.
        let (minus, plus) = (
            modes.boundary(&modes.shape_at(0, -2.0).unwrap()),
            modes.boundary(&modes.shape_at(0, 2.0).unwrap()),
        );
        let spread = |points: &[[f64; 3]], planted: bool| -> f64 {
            let chosen: Vec<usize> = t
                .medial_index()
                .iter()
                .enumerate()
                .filter(|(_, &m)| end[m] == planted)
                .map(|(b, _)| b)
                .collect();
            let c = chosen.iter().fold([0.0; 3], |acc, &b| {
                [0, 1, 2].map(|d| acc[d] + points[b][d] / chosen.len() as f64)
            });
            chosen
                .iter()
                .map(|&b| (0..3).map(|d| (points[b][d] - c[d]).powi(2)).sum::<f64>())
                .sum::<f64>()
        };
        let ratio = spread(&plus, true) / spread(&minus, true);
        assert!(
            !(0.9..=1.1).contains(&ratio),
            "{of:?}: the planted end's spread changes by {ratio}"
        );
        let rest = spread(&plus, false) / spread(&minus, false);
        assert!(
            (rest - 1.0).abs() < (ratio - 1.0).abs() / 3.0,
            "{of:?}: {rest} vs {ratio}"
        );
    }
}

#[test]
fn the_mean_template_of_thickened_and_thinned_copies_is_the_toy() {
    let t = toy();
    let options = ProjectOptions::default();
    // Without alignment: the average of spokes 10 % longer and 10 % shorter is the toy.
    let pair = [subject(&t, |_| 1.1, 0.0), subject(&t, |_| 0.9, 0.0)];
    let mean = mean_template(&pair, &t, Alignment::None, &options).unwrap();
    assert!(mean.change < 1e-9, "moved {} mm from the toy", mean.change);
    assert!(mean.after.max_spoke_normal_deg <= 0.1 && mean.after.max_mismatch <= 1e-3);
    // Copies of the thickened toy moved rigidly: GPA brings them together, the mean is placed
    // on the toy and its landmarks are the thickened toy's.
    let copies: Vec<MedialTemplate> = (0..3)
        .map(|k| subject(&t, |_| 1.1, 0.4 * k as f64))
        .collect();
    let mean = mean_template(&copies, &t, Alignment::Rigid, &options).unwrap();
    let thick = subject(&t, |_| 1.1, 0.0);
    let as_points =
        |m: &MedialTemplate| -> Vec<[f64; 3]> { m.landmarks().iter().map(|&p| p.into()).collect() };
    let onto = procrustes(&as_points(&thick), &as_points(&mean.template), false).unwrap();
    let placed: Vec<[f64; 3]> = as_points(&thick).iter().map(|&p| onto.apply(p)).collect();
    let e = rms(&placed, &as_points(&mean.template));
    assert!(
        e < 1e-6 + mean.projection_rms,
        "{e} mm off the thickened toy"
    );
    assert!(
        mean.change > 0.1,
        "the thickening is a change: {}",
        mean.change
    );
    assert!(mean_template(&copies[..1], &t, Alignment::Rigid, &options).is_err());
}

#[test]
fn a_round_s_shape_change_is_the_move_along_the_normals_and_its_slide_the_rest() {
    let t = toy();
    let q = t.landmarks();
    let normals = t.tangents().normals(q);
    // A unit vector across each normal, from the axis it is least aligned with.
    let across: Vec<medial_core::Vec3> = (normals.iter())
        .map(|n| {
            let axis = medial_core::Vec3::ith(n.iamin(), 1.0);
            n.cross(&axis).normalize()
        })
        .collect();
    let moved = |a: f64, b: f64| -> Vec<medial_core::Vec3> {
        (0..q.len())
            .map(|k| match k < t.boundary_count() {
                true => q[k] + a * normals[k] + b * across[k],
                false => q[k],
            })
            .collect()
    };
    for (a, b) in [(0.3, 0.0), (0.0, 0.2), (0.3, 0.4), (-0.1, 0.0)] {
        let (normal, slide) = normal_and_tangential(&t, &moved(a, b));
        assert!((normal - f64::abs(a)).abs() < 1e-12, "{a} {b}: {normal}");
        assert!((slide - b).abs() < 1e-12, "{a} {b}: {slide}");
    }
    // The mean of copies thickened by 10 % and thinned by 10 % is the toy: no change at all.
    let options = ProjectOptions::default();
    let pair = [subject(&t, |_| 1.1, 0.0), subject(&t, |_| 0.9, 0.0)];
    let mean = mean_template(&pair, &t, Alignment::None, &options).unwrap();
    assert!(mean.shape_change < 1e-9 && mean.slide < 1e-9, "{mean:?}");
}
