//! `medial check` and the inscribed-ball fidelity a fit writes: on templates, and on a short
//! fit of the shipped toy with and without the medial constraints, which must stay at least
//! ten times apart (the paper's Fig. 1 (b) against (c)).

use crate::common::{medial, one_line_error, run_json, s, text};
use serde_json::Value;
use std::path::{Path, PathBuf};

const EXAMPLES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples");

fn example(path: &str) -> PathBuf {
    Path::new(EXAMPLES).join(path)
}

/// A JSON number at a `/`-separated pointer.
fn num(v: &Value, pointer: &str) -> f64 {
    v.pointer(pointer)
        .and_then(Value::as_f64)
        .unwrap_or_else(|| panic!("{pointer} missing in {v}"))
}

#[test]
fn check_a_template_and_refuse_what_is_not_one() {
    let t001 = example("t001/template.vtk");
    let report = run_json(&["check", s(&t001)]);
    assert_eq!(report["medial"], true);
    assert_eq!(report["time_points"].as_array().unwrap().len(), 1);
    let mean = num(&report, "/judged/sheet/mean_residual_pct");
    assert!((1.25..1.4).contains(&mean), "t001 sheet mean {mean} %");
    assert_eq!(num(&report, "/judged/sheet/atoms"), 125.0);
    assert_eq!(num(&report, "/judged/edge/atoms"), 64.0);
    assert_eq!(num(&report, "/poke_tolerance_pct"), 5.0);

    let line = one_line_error(
        &["check", s(&t001), "--max-residual", "1"],
        5,
        &[
            "t001/template.vtk",
            "1.3 %",
            "threshold 1 %",
            "5 of 125 sheet balls",
        ],
    );
    assert!(
        line.contains("not the centres of inscribed balls"),
        "{line}"
    );
    one_line_error(
        &["check", s(&example("hippocampus/hippos_source.vtk"))],
        1,
        &["MedialIndex"],
    );
    one_line_error(
        &["check", s(&t001), "--max-residual", "0"],
        2,
        &["positive number of per cent"],
    );
    let empty = tempfile::tempdir().unwrap();
    one_line_error(&["check", s(empty.path())], 1, &["fitted_template.vtk"]);
}

/// The shipped toy config with a shorter Dice stage (4 AL iterations of 100), its paths made
/// absolute; `constraints = false` in every stage if `free`.
fn short_toy_config(dir: &Path, free: bool) -> PathBuf {
    let mut config = std::fs::read_to_string(example("toy/fit.toml"))
        .unwrap()
        .replace("al_iterations = 6", "al_iterations = 4")
        .replace("max_iterations = 150", "max_iterations = 100");
    for file in ["template.vtk", "affine.txt", "target.nii.gz"] {
        let path = example(&format!("toy/{file}"));
        config = config.replace(&format!("\"{file}\""), &format!("{:?}", s(&path)));
    }
    if free {
        config = config.replace("attachment = ", "constraints = false\nattachment = ");
    }
    let path = dir.join(if free {
        "free.toml"
    } else {
        "constrained.toml"
    });
    std::fs::write(&path, config).unwrap();
    path
}

/// Fits `config` into `out`; returns `summary.json`.
fn fit(config: &Path, out: &Path) -> Value {
    let o = medial(&["fit", s(config), "--out", s(out), "-q"]);
    assert!(o.status.success(), "fit failed: {}", text(&o.stderr));
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

/// `medial check OUT`: the report and whether it exited 0.
fn check(out: &Path) -> (Value, bool) {
    let o = medial(&["check", s(out)]);
    let report = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    (report, o.status.success())
}

#[test]
fn constrained_fit_keeps_balls_inscribed_and_an_unconstrained_fit_does_not() {
    let dir = tempfile::tempdir().unwrap();
    let template = run_json(&["check", s(&example("toy/template.vtk"))]);
    let template_mean = num(&template, "/judged/sheet/mean_residual_pct");

    let on = dir.path().join("on");
    let summary_on = fit(&short_toy_config(dir.path(), false), &on);
    let (report_on, medial_on) = check(&on);
    assert!(medial_on, "{report_on}");
    let mean_on = num(&report_on, "/judged/sheet/mean_residual_pct");
    assert!(
        mean_on < 1.5 * template_mean,
        "constrained {mean_on} % against the template's {template_mean} %"
    );
    check_outputs(&on, &summary_on, &report_on);

    let free = dir.path().join("free");
    let summary_free = fit(&short_toy_config(dir.path(), true), &free);
    let (report_free, medial_free) = check(&free);
    assert!(!medial_free, "{report_free}");
    let mean_free = num(&report_free, "/judged/sheet/mean_residual_pct");
    assert!(
        mean_free > 10.0 * mean_on,
        "without constraints {mean_free} %, with {mean_on} %"
    );
    let poking = num(&report_free, "/judged/sheet/poking_out");
    let atoms = num(&report_free, "/judged/sheet/atoms");
    assert!(
        poking >= 0.9 * atoms,
        "{poking} of {atoms} sheet balls poke out"
    );
    check_outputs(&free, &summary_free, &report_free);

    // A fit that `medial fit` did not accept fails the check whatever its balls: the sound
    // constrained fit's folder, its status changed as a fit that folded or missed its
    // tolerance would have written it.
    for (status, code) in [("unsound", 3), ("constraints_not_met", 4)] {
        let path = on.join("summary.json");
        let mut summary: Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        summary["status"] = Value::from(status);
        std::fs::write(&path, summary.to_string()).unwrap();
        let o = medial(&["check", s(&on)]);
        assert_eq!(o.status.code(), Some(code), "{status}: {}", text(&o.stderr));
        let report: Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(report["fit_status"], status);
        assert!(text(&o.stderr).contains(status), "{}", text(&o.stderr));
    }
}

/// The fit's own outputs agree with `medial check` of its folder: `over_time.ball_fidelity` in
/// summary.json, the last row of time_points.csv, and the point arrays of the last
/// flow/medial_tNNN.vtk.
fn check_outputs(out: &Path, summary: &Value, report: &Value) {
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * (1.0 + a.abs());
    for group in ["sheet", "edge"] {
        for key in ["mean_residual_pct", "max_residual_pct", "poking_out"] {
            let (a, b) = (
                num(summary, &format!("/over_time/ball_fidelity/{group}/{key}")),
                num(report, &format!("/judged/{group}/{key}")),
            );
            assert!(close(a, b), "{group}.{key}: summary {a}, check {b}");
        }
    }
    let n = summary["time_steps"].as_u64().unwrap() as usize;
    let last = &report["time_points"][n];
    assert_eq!(last["time_point"], n);

    let csv = std::fs::read_to_string(out.join("time_points.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let row: Vec<f64> = csv
        .lines()
        .last()
        .unwrap()
        .split(',')
        .map(|x| x.parse().unwrap())
        .collect();
    let column = |name: &str| row[header.iter().position(|h| *h == name).unwrap()];
    assert!(close(
        column("ball_residual_sheet_mean_pct"),
        num(last, "/sheet/mean_residual_pct")
    ));
    assert_eq!(
        column("balls_poking_out_edge"),
        num(last, "/edge/poking_out")
    );

    let medial =
        medial_io::vtk::read_polydata(&out.join(format!("flow/medial_t{n:03}.vtk"))).unwrap();
    let residual = &medial.point_array("BallResidual").unwrap().values;
    let pokes = &medial.point_array("BallPokesOut").unwrap().values;
    let max = residual.iter().fold(0.0f64, |a, &b| a.max(b));
    let expected = num(last, "/sheet/max_residual_pct").max(num(last, "/edge/max_residual_pct"));
    assert!(close(100.0 * max, expected), "{max} vs {expected} %");
    assert!(pokes.iter().all(|&p| p == 0.0 || p == 1.0));
    let poking = num(last, "/sheet/poking_out") + num(last, "/edge/poking_out");
    assert_eq!(pokes.iter().sum::<f64>(), poking);
}
