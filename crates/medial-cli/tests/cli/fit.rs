//! End-to-end tests of `medial fit` and `medial eval` through the built binary, on cmrep's own
//! t001 medial template (k = 503), and of how bad input is refused.

use crate::common::{data, f, medial, run_fails, run_json, s, text};
use medial_io::npy::read_npy;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// A config fitting t001 to its own boundary moved by a rotation of 4° and a shift, so the
/// exact answer is known (an affine map keeps a medial model medial).
fn write_case(dir: &Path, stage_keys: &str) -> PathBuf {
    let (c, s) = (4f64.to_radians().cos(), 4f64.to_radians().sin());
    let matrix = format!("{c} {} 0 -3\n{s} {c} 0 2\n0 0 1 1\n0 0 0 1\n", -s);
    std::fs::write(dir.join("move.txt"), matrix).unwrap();
    let config = format!(
        r#"
[model]
template = "{}"
[flow]
sigma = 6.0
time_steps = 10
[[stage]]
name = "affine"
attachment = "ssd"
transform = "move.txt"
{stage_keys}
"#,
        data("cmrep/t001_template_bcmrep.vtk").display()
    );
    let path = dir.join("fit.toml");
    std::fs::write(&path, config).unwrap();
    path
}

fn fit(config: &Path, out: &Path, threads: &str) -> Value {
    let o = medial(&[
        "fit",
        s(config),
        "--out",
        s(out),
        "--threads",
        threads,
        "-q",
    ]);
    assert!(o.status.success(), "fit failed: {}", text(&o.stderr));
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

#[test]
fn fit_writes_every_output_and_matches_an_affine_target() {
    let dir = tempfile::tempdir().unwrap();
    let config = write_case(dir.path(), "constraints = false\nmax_iterations = 200");
    let out = dir.path().join("out");
    let summary = fit(&config, &out, "2");
    assert_eq!(summary["landmarks"], 503);
    assert_eq!(summary["time_steps"], 10);
    assert_eq!(summary["threads"], 2);
    let last = &summary["final"];
    for key in [
        "total",
        "kinetic",
        "data",
        "penalty",
        "max_abs_constraint",
        "max_spoke_normal_deg",
        "max_spoke_mismatch_pct",
    ] {
        assert!(last[key].is_number(), "final.{key} missing in {last}");
    }
    // The rigid move displaces points by 3.6 mm on average; the kinetic energy keeps the
    // optimum a little short of an exact match.
    let mean_distance = last["mean_distance"].as_f64().unwrap();
    assert!(
        mean_distance < 0.25,
        "mean distance to the target {mean_distance} mm"
    );
    assert!(summary["stages"][0]["evaluations"].as_u64().unwrap() > 1);

    let log = std::fs::read_to_string(out.join("log.csv")).unwrap();
    let header = log.lines().next().unwrap();
    assert_eq!(header, "stage,al_iteration,iteration,evaluations,mu,total,kinetic,data,penalty,max_abs_constraint,max_spoke_normal_deg,max_spoke_mismatch_pct,grad_norm,seconds,dice,time_steps");
    assert!(log.lines().count() > 3);

    let momenta = read_npy(&out.join("momenta.npy")).unwrap();
    assert_eq!(momenta.shape, vec![10, 503, 3]);
    for n in 0..=10 {
        let boundary =
            medial_io::vtk::read_polydata(&out.join(format!("flow/boundary_t{n:03}.vtk"))).unwrap();
        assert_eq!(boundary.points.len(), 314);
        for name in ["SpokeNormalAngle", "SpokeMismatch", "Radius", "MedialIndex"] {
            assert!(
                boundary.point_array(name).is_some(),
                "{name} missing at t{n}"
            );
        }
        let medial =
            medial_io::vtk::read_polydata(&out.join(format!("flow/medial_t{n:03}.vtk"))).unwrap();
        assert!(medial.point_array("Thickness").is_some());
    }
    check_time_points(&out, &summary);
    let fitted = medial_io::cmrep::read_template(&out.join("fitted_template.vtk")).unwrap();
    assert_eq!(fitted.landmark_count(), 503);
    let metrics = medial_core::model::metrics::SpokeMetrics::compute(&fitted, fitted.landmarks());
    let reported = last["max_spoke_normal_deg"].as_f64().unwrap();
    assert!(
        (metrics.max_spoke_normal_deg - reported).abs() < 1e-6,
        "{} vs {reported}",
        metrics.max_spoke_normal_deg
    );
}

/// `time_points.csv` has one row per time point: the template's own figures at t = 0 (0.070°,
/// 0.067 %), the final figures at t = 1, and `over_time` in summary.json is their worst over
/// time points 1 … N.
fn check_time_points(out: &Path, summary: &Value) {
    let csv = std::fs::read_to_string(out.join("time_points.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next().unwrap(),
        "time_point,t,max_spoke_normal_deg,mean_spoke_normal_deg,max_spoke_mismatch_pct,\
         max_abs_constraint_mm2,min_thickness_mm,max_thickness_mm,\
         ball_residual_sheet_mean_pct,ball_residual_sheet_max_pct,balls_poking_out_sheet,\
         ball_residual_edge_mean_pct,ball_residual_edge_max_pct,balls_poking_out_edge"
    );
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 11);
    assert!((rows[0][2] - 0.070140).abs() < 1e-5, "{:?}", rows[0]);
    assert!((rows[0][4] - 0.066982).abs() < 1e-5, "{:?}", rows[0]);
    // The template's inscribed-ball residual of its sheet atoms (README, Medial fidelity).
    assert!((rows[0][8] - 1.308).abs() < 1e-3, "{:?}", rows[0]);
    let last = &summary["final"];
    assert_eq!(rows[10][1], 1.0);
    assert!((rows[10][2] - f(&last["max_spoke_normal_deg"])).abs() < 1e-12);
    assert!((rows[10][4] - f(&last["max_spoke_mismatch_pct"])).abs() < 1e-12);
    let worst = |c: usize| rows[1..].iter().map(|r| r[c]).fold(f64::MIN, f64::max);
    let over = &summary["over_time"];
    assert_eq!(f(&over["max_spoke_normal_deg"]), worst(2));
    assert_eq!(f(&over["max_spoke_mismatch_pct"]), worst(4));
    assert_eq!(f(&over["max_abs_constraint_mm2"]), worst(5));
    let sheet_mean = f(&over["ball_fidelity"]["sheet"]["mean_residual_pct"]);
    assert!(
        (sheet_mean - worst(8)).abs() <= 1e-12 * sheet_mean,
        "{sheet_mean}"
    );
}

#[test]
fn one_or_two_threads_give_the_same_bits_and_eval_reproduces_the_fit() {
    let dir = tempfile::tempdir().unwrap();
    let config = write_case(
        dir.path(),
        // 15 iterations are far from medial; the test is about bits, so the tolerance is wide.
        "constraints = true\nmu = 1.0\nal_iterations = 2\nmax_iterations = 15\n\
         tolerance_deg = 180\ntolerance_pct = 1000",
    );
    let (one, two) = (dir.path().join("one"), dir.path().join("two"));
    let s1 = fit(&config, &one, "1");
    let s2 = fit(&config, &two, "2");
    assert_eq!(
        std::fs::read(one.join("momenta.npy")).unwrap(),
        std::fs::read(two.join("momenta.npy")).unwrap()
    );
    assert_eq!(s1["final"], s2["final"]);

    let gradient = dir.path().join("g.npy");
    let figures = run_json(&[
        "eval",
        s(&config),
        "--momenta",
        s(&one.join("momenta.npy")),
        "--gradient",
        s(&gradient),
    ]);
    // With λ = 0 and the stage's initial μ, eval gives the penalty function at the fitted
    // controls: same kinetic energy and data term as the fit's final figures.
    for key in [
        "kinetic",
        "data",
        "max_abs_constraint",
        "max_spoke_normal_deg",
    ] {
        let (a, b) = (f(&figures[key]), f(&s1["final"][key]));
        assert!(
            (a - b).abs() <= 1e-9 * b.abs().max(1.0),
            "{key}: eval {a} vs fit {b}"
        );
    }
    assert_eq!(read_npy(&gradient).unwrap().shape, vec![10, 503, 3]);
}

/// `constraint_units` is a stage key: at the template (zero controls) the relative constraints
/// are bounded by the template's own figures (sin 0.0702° for orthogonality, 0.067 % for equal
/// spokes) while the absolute ones are in mm²; an unknown unit is refused by name.
#[test]
fn constraint_units_are_a_stage_key() {
    let dir = tempfile::tempdir().unwrap();
    let zeros = dir.path().join("zeros.npy");
    medial_io::npy::write_npy(&zeros, &[10, 503, 3], &vec![0.0; 10 * 503 * 3]).unwrap();
    let eval_with = |units: &str| {
        let case = dir.path().join(units);
        std::fs::create_dir_all(&case).unwrap();
        let config = write_case(&case, &format!("constraint_units = \"{units}\""));
        run_json(&["eval", s(&config), "--momenta", s(&zeros)])
    };
    let relative = f(&eval_with("relative")["max_abs_constraint"]);
    let absolute = f(&eval_with("absolute")["max_abs_constraint"]);
    println!("max |C| at t001: relative {relative:e}, absolute {absolute:e} mm²");
    assert!(
        relative > 0.0 && relative <= 0.0702f64.to_radians().sin(),
        "{relative}"
    );
    assert!(absolute > 2.0 * relative, "{absolute} vs {relative}");
    let config = write_case(dir.path(), "constraint_units = \"relativ\"");
    assert_refused(&["fit", s(&config)], "relativ");
}

/// Runs the binary, asserts failure with a message mentioning `expected` and no panic.
fn assert_refused(args: &[&str], expected: &str) {
    let err = text(&run_fails(args, &[expected]).stderr);
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
}

#[test]
fn bad_input_is_refused_with_a_clear_message() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    assert_refused(&["fit", s(&d.join("missing.toml"))], "missing.toml");

    let config = write_case(d, "max_iterations = 5");
    let text = std::fs::read_to_string(&config).unwrap();
    let typo = d.join("typo.toml");
    std::fs::write(&typo, text.replace("sigma =", "sigam =")).unwrap();
    assert_refused(&["fit", s(&typo)], "sigam");
    // A key of the other attachment is refused, not ignored.
    let foreign = d.join("foreign.toml");
    std::fs::write(
        &foreign,
        text.replace(
            "transform = \"move.txt\"",
            "transform = \"move.txt\"\nimage = \"seg.nii.gz\"",
        ),
    )
    .unwrap();
    assert_refused(
        &["fit", s(&foreign)],
        "image does not apply to attachment = \"ssd\"",
    );

    let no_template = d.join("no_template.toml");
    std::fs::write(
        &no_template,
        text.replace("t001_template_bcmrep.vtk", "nothing_here.vtk"),
    )
    .unwrap();
    assert_refused(&["fit", s(&no_template)], "nothing_here.vtk");

    let wrong_target = d.join("wrong_target.toml");
    let hippo = data("keops/hippos_reduc_target.vtk");
    std::fs::write(
        &wrong_target,
        text.replace(
            "transform = \"move.txt\"",
            &format!("target = \"{}\"", hippo.display()),
        ),
    )
    .unwrap();
    assert_refused(&["fit", s(&wrong_target)], "662 points");

    let nan_mesh = d.join("nan.vtk");
    std::fs::write(&nan_mesh, "# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n0 0 0 1 nan 0 0 1 0\nPOLYGONS 1 4\n3 0 1 2\n").unwrap();
    let nan_config = d.join("nan.toml");
    std::fs::write(
        &nan_config,
        text.replace(
            &data("cmrep/t001_template_bcmrep.vtk").display().to_string(),
            s(&nan_mesh),
        ),
    )
    .unwrap();
    assert_refused(&["fit", s(&nan_config)], "nan.vtk");

    let quad = d.join("quad.vtk");
    std::fs::write(&quad, "# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n0 0 0 1 0 0 1 1 0 0 1 0\nPOLYGONS 1 5\n4 0 1 2 3\n").unwrap();
    let quad_config = d.join("quad.toml");
    std::fs::write(
        &quad_config,
        text.replace(
            &data("cmrep/t001_template_bcmrep.vtk").display().to_string(),
            s(&quad),
        ),
    )
    .unwrap();
    assert_refused(&["fit", s(&quad_config)], "quad.vtk");

    let bad_momenta = d.join("bad.npy");
    medial_io::npy::write_npy(&bad_momenta, &[2, 3], &[0.0; 6]).unwrap();
    assert_refused(&["eval", s(&config), "--momenta", s(&bad_momenta)], "shape");
    assert_refused(
        &[
            "eval",
            s(&config),
            "--momenta",
            s(&bad_momenta),
            "--stage",
            "nope",
        ],
        "nope",
    );
}
