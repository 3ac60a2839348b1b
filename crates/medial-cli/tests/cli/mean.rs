//! `medial mean` on the toy bent both ways (short SSD fits from the batch tests' base config):
//! rounds that fit from the previous round's mean, a change that shrinks, a mean halfway
//! between the two fits and nearer the unbent toy than either, whose medial constraints hold;
//! the tolerance on the change of shape (not the slide along the surface) stops the rounds; an
//! output folder of other results is refused before any work.

use crate::batch::{base_config, bent_toy, table, toy_template};
use crate::common::{f, one_line_error, run_json, s};
use medial_core::model::Model;
use medial_core::MedialTemplate;
use medial_stats::shape::procrustes;
use std::path::Path;

fn medial_model(path: &Path) -> MedialTemplate {
    match medial_io::model::read_model(path).unwrap() {
        Model::Medial(t) => *t,
        Model::Plain(_) => panic!("{}: not medial", path.display()),
    }
}

/// The RMS distance (mm) between the landmarks of `a`, placed rigidly on `b`, and `b`'s.
fn distance(a: &MedialTemplate, b: &MedialTemplate) -> f64 {
    let points =
        |m: &MedialTemplate| -> Vec<[f64; 3]> { m.landmarks().iter().map(|&p| p.into()).collect() };
    let (pa, pb) = (points(a), points(b));
    let map = procrustes(&pa, &pb, false).unwrap();
    let sum: f64 = pa
        .iter()
        .zip(&pb)
        .map(|(p, q)| {
            let m = map.apply(*p);
            (0..3).map(|d| (m[d] - q[d]).powi(2)).sum::<f64>()
        })
        .sum();
    (sum / pa.len() as f64).sqrt()
}

#[test]
fn mean_rounds_fit_from_the_last_mean_and_approach_the_unbent_toy() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (plus, minus) = (bent_toy(d, 15), bent_toy(d, -15));
    let subjects = table(d, &[("plus", &plus), ("minus", &minus)]);
    let base = base_config(d);
    let out = d.join("mean");
    let toy = toy_template();
    let summary = run_json(&[
        "mean",
        s(&toy),
        s(&subjects),
        "--out",
        s(&out),
        "--config",
        s(&base),
        "--rounds",
        "2",
        "--tolerance",
        "0",
        "-q",
    ]);
    assert_eq!(summary["converged"], false);
    let rounds = summary["rounds"].as_array().unwrap();
    assert_eq!(rounds.len(), 2);
    let csv = std::fs::read_to_string(out.join("rounds.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3, "{csv}");
    let (first, second) = (f(&rounds[0]["change_mm"]), f(&rounds[1]["change_mm"]));
    assert!(first > 0.0 && second < first / 2.0, "{first} then {second}");
    assert!(
        csv.starts_with("round,subjects,change_mm,shape_change_mm,slide_mm,"),
        "{csv}"
    );
    for r in rounds {
        // The change splits into its parts along the normals and along the surface (the
        // medial points' move is in the change only).
        let (shape, slide) = (f(&r["shape_change_mm"]), f(&r["slide_mm"]));
        assert!(shape > 0.0 && slide > 0.0 && shape.hypot(slide) <= 1.5 * f(&r["change_mm"]));
        assert_eq!(r["subjects"], 2);
        assert!(f(&r["max_spoke_normal_deg"]) <= 0.1 && f(&r["max_spoke_mismatch_pct"]) <= 0.1);
    }
    // Round 2 fitted from round 1's mean.
    let config = std::fs::read_to_string(out.join("round2/plus/config.toml")).unwrap();
    assert!(config.contains("template_1.vtk"), "{config}");
    // The mean of round 2's two fits lies halfway between them (up to its projection onto
    // the constraints, which moves it little), and nearer the unbent toy than either.
    let mean = medial_model(&out.join("mean_template.vtk"));
    assert_eq!(
        mean.landmarks(),
        medial_model(&out.join("template_2.vtk")).landmarks()
    );
    let fits = ["plus", "minus"]
        .map(|name| medial_model(&out.join(format!("round2/{name}/fitted_template.vtk"))));
    let apart = distance(&fits[0], &fits[1]);
    let toy = medial_model(&toy);
    for fit in &fits {
        let from_mean = distance(fit, &mean);
        assert!(
            (from_mean - apart / 2.0).abs() < 0.05 * apart,
            "the mean {from_mean} mm from a fit, the fits {apart} mm apart"
        );
        assert!(distance(&mean, &toy) < distance(fit, &toy));
    }

    // The rounds stop on the change of shape: a tolerance above round 1's move along the
    // normals (0.30 mm) but below its landmarks' move (0.53 mm, most of it along the surface)
    // stops after round 1, whose fits are the same bits.
    let (shape, change) = (f(&rounds[0]["shape_change_mm"]), f(&rounds[0]["change_mm"]));
    assert!(
        shape < 0.8 * change,
        "{shape} of {change} mm along the normals"
    );
    let tolerance = ((shape + change) / 2.0).to_string();
    let out = d.join("once");
    let summary = run_json(&[
        "mean",
        s(&toy_template()),
        s(&subjects),
        "--out",
        s(&out),
        "--config",
        s(&base),
        "--tolerance",
        &tolerance,
        "-q",
    ]);
    assert_eq!(summary["converged"], true);
    assert_eq!(summary["rounds"].as_array().unwrap().len(), 1);
    assert_eq!(
        summary["rounds"][0]["shape_change_mm"],
        rounds[0]["shape_change_mm"]
    );
    assert!(!out.join("round2").exists());
}

#[test]
fn mean_refuses_an_output_folder_of_other_results_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let subjects = d.join("subjects.csv");
    std::fs::write(&subjects, "subject,image\na,a.nii.gz\nb,b.nii.gz\n").unwrap();
    let fit = d.join("fit");
    std::fs::create_dir_all(&fit).unwrap();
    let summary = r#"{"version": "0", "status": "converged", "files": []}"#;
    std::fs::write(fit.join("summary.json"), summary).unwrap();
    let toy = toy_template();
    let args = ["mean", s(&toy), s(&subjects), "--out", s(&fit)];
    one_line_error(&args, 1, &["would overwrite", "another --out"]);
    // Nothing fitted or written: the fit's folder is as it was.
    assert_eq!(std::fs::read_dir(&fit).unwrap().count(), 1);
    assert_eq!(
        std::fs::read_to_string(fit.join("summary.json")).unwrap(),
        summary
    );
    // A folder whose summary.json is another analysis's (`medial pca`).
    std::fs::write(fit.join("summary.json"), r#"{"command": "pca"}"#).unwrap();
    one_line_error(&args, 1, &["the results of `medial pca`"]);
}
