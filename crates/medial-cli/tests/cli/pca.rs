//! `medial pca` on cohorts made from the toy template (as in `stats_cohort`): a planted
//! thickening of one end by a different amount in each subject, each subject moved rigidly, is
//! the first mode; without alignment the variances are the eigenvalues of the covariance of the
//! atoms' coordinates; the scores are a design for `medial stats`.

use crate::common::{f, medial, one_line_error, run_fails, run_json, s, text};
use crate::stats_cohort::{noise, planted, scaled, toy, write_cohort};
use crate::stats_report::check_accessors;
use medial_core::model::{Model, SpokeMetrics};
use medial_core::{MedialTemplate, Vec3};
use medial_io::vtk::read_polydata;
use nalgebra::{DMatrix, Rotation3, SymmetricEigen};
use std::path::{Path, PathBuf};

/// Subjects.
const N: usize = 10;

/// The planted amount of subject i: its planted atoms' spokes are 1 + amount times longer.
fn amount(i: usize) -> f64 {
    (i as f64 - 4.5) * 0.03
}

/// Subject i: the toy thickened at its planted end by `amount(i)`, with ±0.5 % noise on every
/// spoke, turned by `angle` × i about (1, 2, 3) and shifted.
fn subject(template: &MedialTemplate, i: usize, angle: f64) -> MedialTemplate {
    let planted = planted(template);
    let scale: Vec<f64> = (0..template.medial_count())
        .map(|m| {
            let e = if planted[m] { amount(i) } else { 0.0 };
            1.0 + e + 0.005 * noise((i * 1000 + m) as u64)
        })
        .collect();
    let thick = scaled(template, &scale);
    let r = Rotation3::new(Vec3::new(1.0, 2.0, 3.0).normalize() * angle * i as f64);
    let shift = Vec3::new(3.0, -1.0, 2.0) * (angle * i as f64);
    let q: Vec<Vec3> = thick.landmarks().iter().map(|p| r * p + shift).collect();
    thick.with_landmarks(&q).unwrap()
}

fn rows(path: &Path) -> Vec<Vec<String>> {
    let mut reader = csv::Reader::from_path(path).unwrap();
    let mut all = vec![reader.headers().unwrap().iter().map(String::from).collect()];
    for r in reader.records() {
        all.push(r.unwrap().iter().map(String::from).collect());
    }
    all
}

fn number(cell: &str) -> f64 {
    cell.parse()
        .unwrap_or_else(|_| panic!("'{cell}' is not a number"))
}

fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (ma, mb) = (mean(a), mean(b));
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let sa: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let sb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    cov / (sa * sb).sqrt()
}

/// A cohort of `N` subjects of the toy with a planted mode of amounts 0.15 ([`subject`]), and
/// `gone`; returns its folder.
fn planted_cohort(d: &Path) -> PathBuf {
    let template = toy();
    let subjects: Vec<(String, MedialTemplate)> = (0..N)
        .map(|i| (format!("s{i}"), subject(&template, i, 0.15)))
        .collect();
    write_cohort(d, &subjects)
}

#[test]
fn pca_finds_a_planted_mode_and_its_scores_are_a_design() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let template = toy();
    let input = planted_cohort(d);
    let out = d.join("pca");
    let o = medial(&["pca", s(&input), "--out", s(&out), "--modes", "3"]);
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("subject 'gone' left out: its fit failed"),
        "{err}"
    );
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary["of"], "atoms");
    assert_eq!(summary["alignment"], "similarity");
    assert_eq!(summary["left_out"][0]["subject"], "gone");
    assert_eq!(summary["subjects"].as_array().unwrap().len(), N);

    // modes.csv: three modes, the first explaining nearly all the variance.
    let modes = rows(&out.join("modes.csv"));
    assert_eq!(
        modes[0],
        ["mode", "variance_mm2", "sd_mm", "explained", "cumulative"]
    );
    assert_eq!(modes.len(), 4);
    let explained = number(&modes[1][3]);
    assert!(explained > 0.95, "mode 1 explains {explained}");
    assert_eq!(f(&summary["modes"][0]["explained"]), explained);
    // scores.csv: subject, pc1..pc3; pc1 follows the planted amounts.
    let scores = rows(&out.join("scores.csv"));
    assert_eq!(scores[0], ["subject", "pc1", "pc2", "pc3"]);
    assert_eq!(scores.len(), N + 1);
    let pc1: Vec<f64> = scores[1..].iter().map(|r| number(&r[1])).collect();
    let amounts: Vec<f64> = (0..N).map(amount).collect();
    let r = correlation(&pc1, &amounts);
    assert!(r.abs() > 0.999, "pc1 against the planted amounts: r = {r}");
    // The scores' variance is the mode's.
    let variance = pc1.iter().map(|x| x * x).sum::<f64>() / (N - 1) as f64;
    assert!((variance - number(&modes[1][1])).abs() < 1e-9 * variance);

    // The series: 9 frames from −2 to +2 SD of the template's boundary and medial sheet; along
    // mode 1 the planted end's radii change, the others' barely.
    let planted = planted(&template);
    for kind in ["boundary", "medial"] {
        let series: serde_json::Value = serde_json::from_slice(
            &std::fs::read(out.join(format!("mode1_{kind}.vtk.series"))).unwrap(),
        )
        .unwrap();
        let files = series["files"].as_array().unwrap();
        assert_eq!(files.len(), 9);
        assert_eq!(f(&files[0]["time"]), -2.0);
        assert_eq!(f(&files[8]["time"]), 2.0);
        let frame =
            |k: usize| read_polydata(&out.join(files[k]["name"].as_str().unwrap())).unwrap();
        let (first, last) = (frame(0), frame(8));
        let (points, triangles) = match kind {
            "boundary" => (template.boundary_count(), template.boundary_triangles()),
            _ => (template.medial_count(), template.medial_triangles()),
        };
        assert_eq!(first.points.len(), points);
        assert_eq!(first.triangles().unwrap(), triangles);
        if kind == "medial" {
            let (r0, r8) = (
                &first.point_array("Radius").unwrap().values,
                &last.point_array("Radius").unwrap().values,
            );
            for m in 0..points {
                let change = (r8[m] / r0[m] - 1.0).abs();
                if planted[m] {
                    assert!(change > 0.1, "planted atom {m}: radius changes by {change}");
                } else {
                    assert!(change < 0.05, "atom {m}: radius changes by {change}");
                }
            }
        }
    }
    assert!(out.join("mean_boundary.vtk").is_file() && out.join("mean_medial.vtk").is_file());
    // Each mode's animation: a glTF whose accessors pass the glTF validator's checks (min and
    // max of the data among them), one frame per series file.
    for mode in 1..=3 {
        let (document, buffers, _) = gltf::import(out.join(format!("mode{mode}.glb"))).unwrap();
        check_accessors(&document, &buffers).unwrap_or_else(|e| panic!("mode{mode}.glb: {e}"));
        let frames: usize = document.meshes().map(|m| m.primitives().count()).sum();
        assert!(frames >= 9, "mode {mode}: {frames} frames");
    }

    // scores.csv as the design of `medial stats`: the thickness at the planted atoms follows pc1.
    let stats = d.join("stats");
    let summary = run_json(&[
        "stats",
        s(&input),
        "--design",
        s(&out.join("scores.csv")),
        "--contrast",
        "pc1",
        "--two-sided",
        "--out",
        s(&stats),
    ]);
    assert_eq!(summary["design_columns"][1], "pc1");
    let t = read_polydata(&stats.join("stats.vtk")).unwrap();
    let t = &t.point_array("t").unwrap().values;
    for m in (0..template.medial_count()).filter(|&m| planted[m]) {
        assert!(t[m].abs() > 10.0, "planted atom {m}: t {}", t[m]);
    }
}

#[test]
fn without_alignment_the_variances_are_the_covariance_eigenvalues() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let template = toy();
    let subjects: Vec<(String, MedialTemplate)> = (0..N)
        .map(|i| (format!("s{i}"), subject(&template, i, 0.0)))
        .collect();
    let input = write_cohort(d, &subjects);
    let out = d.join("pca");
    run_json(&[
        "pca",
        s(&input),
        "--out",
        s(&out),
        "--align",
        "none",
        "--modes",
        "4",
    ]);
    // Independent: the models read back, their medial points and radii (half the thickness)
    // as rows, the covariance matrix and its symmetric eigendecomposition.
    let data: Vec<Vec<f64>> = subjects
        .iter()
        .map(|(name, _)| {
            let path = input.join(name).join("fitted_template.vtk");
            let Model::Medial(fitted) = medial_io::model::read_model(&path).unwrap() else {
                panic!("not medial")
            };
            let radii = SpokeMetrics::compute(&fitted, fitted.landmarks()).thickness;
            fitted
                .medial_points()
                .iter()
                .flat_map(|p| [p.x, p.y, p.z])
                .chain(radii.iter().map(|t| t / 2.0))
                .collect()
        })
        .collect();
    let p = data[0].len();
    let x = DMatrix::from_fn(N, p, |i, j| data[i][j]);
    let mean = x.row_mean();
    let centred = DMatrix::from_fn(N, p, |i, j| x[(i, j)] - mean[j]);
    let covariance = centred.transpose() * &centred / (N - 1) as f64;
    let trace = covariance.trace();
    let mut eigen: Vec<f64> = SymmetricEigen::new(covariance)
        .eigenvalues
        .iter()
        .copied()
        .collect();
    eigen.sort_by(|a, b| b.total_cmp(a));
    let modes = rows(&out.join("modes.csv"));
    assert_eq!(modes.len(), 5);
    for (k, row) in modes[1..].iter().enumerate() {
        let (variance, explained) = (number(&row[1]), number(&row[3]));
        assert!(
            (variance - eigen[k]).abs() < 1e-9 * eigen[0],
            "mode {}: {variance} against {}",
            k + 1,
            eigen[k]
        );
        assert!(
            (explained - eigen[k] / trace).abs() < 1e-9,
            "mode {}",
            k + 1
        );
    }
}

#[test]
fn bad_pca_inputs_are_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let template = toy();
    let out = d.join("out");
    // One usable subject (and `gone`, noted first): no modes.
    let input = write_cohort(d, &[("s0".into(), subject(&template, 0, 0.0))]);
    let o = run_fails(
        &["pca", s(&input), "--out", s(&out)],
        &["at least 2 fitted models, found 1"],
    );
    assert_eq!(o.status.code(), Some(1));
    let err = text(&o.stderr);
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 2, "{err}");
    assert!(lines[0].starts_with("subject 'gone' left out") && lines[1].starts_with("error: "));
    one_line_error(
        &["pca", s(&input), "--out", s(&out), "--of", "spokes"],
        2,
        &["expected atoms or boundary"],
    );
    one_line_error(
        &["pca", s(&input), "--out", s(&out), "--modes", "0"],
        2,
        &["--modes 0"],
    );
    one_line_error(&["pca", s(d), "--out", s(&out)], 1, &["cohort.csv"]);
    one_line_error(
        &["pca", s(&input), "--out", s(&out), "--subjects", "s0,zz"],
        1,
        &["--subjects: no subject 'zz'"],
    );
    // A subject's fitted model whose bytes differ from the digest its fit recorded.
    std::fs::write(
        input.join("s0").join("summary.json"),
        r#"{"sha256": {"fitted_template.vtk": "00"}}"#,
    )
    .unwrap();
    let line = one_line_error(
        &["pca", s(&input), "--out", s(&out), "--subjects", "s0"],
        1,
        &["fitted_template.vtk", "SHA-256"],
    );
    assert!(line.contains("s0"), "{line}");
    // An output folder of another command's results (a fit's) is refused before any work and
    // kept as it was; so is a batch folder.
    let fit = d.join("fit");
    std::fs::create_dir_all(&fit).unwrap();
    let summary = r#"{"version": "0", "status": "converged", "files": []}"#;
    std::fs::write(fit.join("summary.json"), summary).unwrap();
    one_line_error(
        &["pca", s(&input), "--out", s(&fit)],
        1,
        &["would overwrite", "another --out"],
    );
    assert_eq!(
        std::fs::read_to_string(fit.join("summary.json")).unwrap(),
        summary
    );
    assert_eq!(std::fs::read_dir(&fit).unwrap().count(), 1);
    one_line_error(
        &["pca", s(&input), "--out", s(&input)],
        1,
        &["cohort.csv", "would overwrite"],
    );
}

#[test]
fn pca_takes_the_subjects_it_is_given() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = planted_cohort(d);
    let out = d.join("pca");
    let summary = run_json(&[
        "pca",
        s(&input),
        "--out",
        s(&out),
        "--subjects",
        "s0,s2,s3,gone",
    ]);
    assert_eq!(summary["subjects"], serde_json::json!(["s0", "s2", "s3"]));
    assert_eq!(summary["left_out"][0]["subject"], "gone");
    let scores = std::fs::read_to_string(out.join("scores.csv")).unwrap();
    assert_eq!(scores.lines().count(), 1 + 3, "{scores}");
}
