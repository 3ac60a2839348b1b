//! `medial fit` without a config: settings chosen from the data, an initial similarity, the
//! resolved config written beside the results and re-run to the same bits; on the shipped toy
//! (a template and its segmentation).

use crate::common::{f, medial, run_fails, run_json as run_json_of, s, text};
use serde_json::Value;
use std::path::Path;

fn read_summary(out: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

/// `medial fit --template TEMPLATE FLAG TARGET --out OUT -q`: an automatic fit (`FLAG` one of
/// `--image`, `--target`, `--surface`).
fn automatic_fit(template: &Path, flag: &str, target: &Path, out: &Path) -> std::process::Output {
    medial(&[
        "fit",
        "--template",
        s(template),
        flag,
        s(target),
        "--out",
        s(out),
        "-q",
    ])
}

#[test]
fn an_automatic_fit_to_a_segmentation_is_medial_and_its_config_reruns_to_the_same_bits() {
    let dir = tempfile::tempdir().unwrap();
    let toy = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/toy");
    let out = dir.path().join("auto");
    let (template, image) = (toy.join("template.vtk"), toy.join("target.nii.gz"));
    let args = [
        "fit",
        "--template",
        s(&template),
        "--image",
        s(&image),
        "--out",
        s(&out),
        "-q",
    ];
    let o = medial(&args);
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("initial similarity"), "{err}");
    for file in [
        "config.toml",
        "alignment.txt",
        "aligned_template.vtk",
        "lambda.npy",
    ] {
        assert!(out.join(file).exists(), "{file}");
    }
    let summary = read_summary(&out);
    for file in ["alignment.txt", "aligned_template.vtk"] {
        let listed = summary["files"].as_array().unwrap();
        assert!(listed.iter().any(|f| f == file), "{file} not in the set");
    }
    // The alignment moved the template: where it was given is a candidate start too, and the
    // trial of the fit's first window from each chose (the one that ends lowest, not one that
    // folds), as summary.json records.
    let trials = summary["start_trials"].as_array().unwrap();
    assert!(trials.len() >= 2, "{trials:?}");
    assert!(
        trials.iter().any(|t| t["start"] == "as given"),
        "{trials:?}"
    );
    let taken: Vec<&Value> = trials.iter().filter(|t| t["taken"] == true).collect();
    assert_eq!(taken.len(), 1, "{trials:?}");
    let lowest = trials
        .iter()
        .filter_map(|t| t["objective"].as_f64())
        .fold(f64::INFINITY, f64::min);
    assert_eq!(f(&taken[0]["objective"]), lowest, "{trials:?}");
    assert!(err.contains("start chosen by a trial"), "{err}");
    let last = &summary["final"];
    println!("automatic toy fit: {summary:#}");
    // The toy's AL iterations settle (the constraints within `settle_constraint` = 1e-3, the
    // Dice no longer moving; since decision 0202's affine start in the last of the five, before
    // it earlier): the stage converged.
    let stage = &summary["stages"][0];
    assert_eq!(stage["settled"], true, "{stage}");
    assert!(f(&last["max_abs_constraint"]) <= 1e-3, "{last}");
    assert_eq!(summary["status"], "converged");
    // Coarse to fine in time: the first three AL iterations in 5 steps, the rest in 10, as
    // log.csv's time_steps column shows row by row.
    assert_eq!(stage["coarse_al_iterations"], 3, "{stage}");
    assert_eq!(stage["strained_iterations"], 0, "{stage}");
    let log = std::fs::read_to_string(out.join("log.csv")).unwrap();
    let steps: Vec<(u64, u64)> = log
        .lines()
        .skip(1)
        .map(|row| {
            let cells: Vec<&str> = row.split(',').collect();
            (
                cells[1].parse().unwrap(),
                cells.last().unwrap().parse().unwrap(),
            )
        })
        .collect();
    assert!(log.lines().next().unwrap().ends_with(",time_steps"));
    assert!(
        steps
            .iter()
            .all(|&(al, n)| n == if al < 3 { 5 } else { 10 }),
        "{steps:?}"
    );
    assert!(
        steps.iter().any(|&(al, _)| al >= 3),
        "an AL iteration in 10 steps"
    );
    assert!(f(&last["voxel_dice"]) >= 0.97, "{last}");
    assert!(f(&last["max_spoke_normal_deg"]) <= 0.5, "{last}");
    assert!(f(&last["max_spoke_mismatch_pct"]) <= 0.5, "{last}");
    // The resolved config names every setting and every file by an absolute path: run from
    // anywhere, it gives the same momenta.
    let again = dir.path().join("again");
    let config = out.join("config.toml");
    let o = medial(&["fit", s(&config), "--out", s(&again), "-q"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert_eq!(
        std::fs::read(out.join("momenta.npy")).unwrap(),
        std::fs::read(again.join("momenta.npy")).unwrap()
    );
}

#[test]
fn an_automatic_fit_needs_a_template_and_one_target() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x");
    let toy = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/toy");
    let template = toy.join("template.vtk");
    let o = run_fails(
        &["fit", "--template", s(&template), "--out", s(&out)],
        &["--image", "--target", "--surface"],
    );
    assert_eq!(o.status.code(), Some(1));
    // Two targets, or --label without an image, are wrong command lines.
    let image = toy.join("target.nii.gz");
    let points = toy.join("target_boundary.vtk");
    let both = [
        "fit",
        "--template",
        s(&template),
        "--image",
        s(&image),
        "--target",
        s(&points),
        "--out",
        s(&out),
    ];
    assert_eq!(medial(&both).status.code(), Some(2));
    let label = [
        "fit",
        "--template",
        s(&template),
        "--label",
        "1",
        "--target",
        s(&points),
        "--out",
        s(&out),
    ];
    assert_eq!(medial(&label).status.code(), Some(2));
    assert!(!out.exists(), "failures write nothing");
}

/// A target stretched unequally along the axes: the initial alignment finds the affine map,
/// applies it and projects the template back onto its constraints (the flow is left only the
/// rest), and the fit ends medial and close to the points. A stretched medial model is not
/// medial, and the correspondence is fixed: the best medial fit stays about the projection's
/// move (0.36 mm rms) away, against 1.28 mm for the best similarity.
#[test]
fn an_unequal_scaling_is_applied_and_projected_before_the_flow() {
    let dir = tempfile::tempdir().unwrap();
    let toy = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/toy");
    let stretch = dir.path().join("stretch.txt");
    std::fs::write(&stretch, "1.2 0 0 0\n0 0.9 0 0\n0 0 1 0\n0 0 0 1\n").unwrap();
    let case = dir.path().join("case");
    let o = medial(&[
        "synth",
        "--from",
        s(&toy.join("template.vtk")),
        "--bend",
        "0",
        "--twist",
        "0",
        "--affine",
        s(&stretch),
        "--out",
        s(&case),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = dir.path().join("fit");
    let o = automatic_fit(
        &case.join("template.vtk"),
        "--target",
        &case.join("target_boundary.vtk"),
        &out,
    );
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("initial affine: anisotropy 33.3 %"), "{err}");
    assert!(
        err.contains("template projected onto its constraints"),
        "{err}"
    );
    // The template the flow starts from is medial again.
    let aligned = run_json_of(&[
        "project",
        s(&out.join("aligned_template.vtk")),
        "--out",
        s(&dir.path().join("check.vtk")),
    ]);
    let before = &aligned["before"];
    assert!(f(&before["max_spoke_normal_deg"]) <= 0.1, "{aligned:#}");
    assert!(f(&before["max_spoke_mismatch_pct"]) <= 0.1, "{aligned:#}");
    let last = &read_summary(&out)["final"];
    println!("unequal scaling: {last:#}");
    assert!(f(&last["mean_distance"]) <= 0.45, "{last}");
    assert!(f(&last["max_spoke_normal_deg"]) <= 0.5, "{last}");
    assert!(f(&last["max_spoke_mismatch_pct"]) <= 0.5, "{last}");
}

/// A plain mesh (no medial structure) fits without a config too: the initial map applied
/// whole, then one unconstrained stage; an image is refused (Dice needs a medial interior).
/// The template is t001's boundary bent by `medial synth --from` (a plain mesh), the target
/// the same boundary under the affine part alone.
#[test]
fn a_plain_mesh_fits_without_a_config() {
    let dir = tempfile::tempdir().unwrap();
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let case = dir.path().join("case");
    let o = medial(&[
        "synth",
        "--from",
        s(&examples.join("t001/template.vtk")),
        "--bend",
        "0",
        "--twist",
        "0",
        "--out",
        s(&case),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let source = examples.join("t001-bent/target_boundary.vtk");
    let out = dir.path().join("fit");
    let o = automatic_fit(&source, "--target", &case.join("target_boundary.vtk"), &out);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let summary = read_summary(&out);
    let stage = &summary["stages"][0];
    println!("plain mesh: {summary:#}");
    assert_eq!(stage["constraints_met"], Value::Null, "{stage}");
    assert_eq!(summary["medial_atoms"], 0, "{summary}");
    // The SSD data term (squared distances) at the aligned start and at the end.
    let first = f(&first_logged(&out, "data"));
    let last = f(&summary["final"]["data"]);
    assert!(last < first / 10.0, "{first} → {last}");
    assert!(f(&summary["final"]["mean_distance"]) < 0.1, "{summary}");
    crate::common::one_line_error(
        &[
            "fit",
            "--template",
            s(&source),
            "--image",
            s(&examples.join("toy/target.nii.gz")),
            "--out",
            s(&dir.path().join("dice")),
        ],
        1,
        &["is a plain mesh: a Dice fit needs a medial template"],
    );
}

/// The column `name` of the first row of the fit's log (the aligned start).
fn first_logged(out: &Path, name: &str) -> Value {
    let log = std::fs::read_to_string(out.join("log.csv")).unwrap();
    let mut lines = log.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let row: Vec<&str> = lines.next().unwrap().split(',').collect();
    let column = header.iter().position(|h| *h == name).unwrap();
    Value::from(row[column].parse::<f64>().unwrap())
}

#[test]
fn an_automatic_fit_to_a_surface_narrows_its_varifold_in_three_stages() {
    // The toy against its target boundary as a surface (no correspondence used): widths a
    // tenth of the diagonal, a quarter of that, then the flow's σ.
    let dir = tempfile::tempdir().unwrap();
    let toy = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/toy");
    let out = dir.path().join("surface");
    let (template, surface) = (toy.join("template.vtk"), toy.join("target_boundary.vtk"));
    let args = [
        "fit",
        "--template",
        s(&template),
        "--surface",
        s(&surface),
        "--out",
        s(&out),
        "-q",
    ];
    let o = medial(&args);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let summary = read_summary(&out);
    let stages = summary["stages"].as_array().unwrap();
    let names: Vec<&str> = stages
        .iter()
        .map(|st| st["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["surface", "surface-fine", "surface-finest"]);
    let config: toml::Value =
        toml::from_str(&std::fs::read_to_string(out.join("config.toml")).unwrap()).unwrap();
    let widths: Vec<f64> = config["stage"]
        .as_array()
        .unwrap()
        .iter()
        .map(|st| st["varifold_width"].as_float().unwrap())
        .collect();
    let sigma = config["flow"]["sigma"].as_float().unwrap();
    assert!(widths[0] > widths[1] && widths[1] > widths[2], "{widths:?}");
    // A quarter of the first width, or more where that is under half a mean edge.
    assert!(widths[1] >= 0.25 * widths[0] * (1.0 - 1e-12), "{widths:?}");
    assert_eq!(
        widths[2],
        sigma.max(0.5 * widths[1]).min(widths[1]),
        "{widths:?} σ {sigma}"
    );
    // Each stage brings the boundary closer to the surface, and the fit stays medial.
    let distance: Vec<f64> = stages.iter().map(|st| f(&st["surface_distance"])).collect();
    assert!(distance.windows(2).all(|d| d[1] <= d[0]), "{distance:?}");
    let last = &summary["final"];
    println!("automatic toy surface fit: {distance:?}, {last:#}");
    assert!(f(&last["surface_distance"]) < 0.15, "{last}");
    assert!(f(&last["max_spoke_normal_deg"]) <= 0.5, "{last}");
    assert!(f(&last["max_spoke_mismatch_pct"]) <= 0.5, "{last}");
}

/// Recovery through the CLI: cmrep's t001 against its own segmentation with one region's wall
/// thickened 2.34 times (case 8 of `scripts/stress.py --seed 1`) folds early in the automatic
/// fit; the fit runs again with twice the time steps, and again with a wider kernel, each run's
/// image data shared with the next (read and smoothed once). `summary.json` says what was
/// retried and why, and the result is judged as any fit's: a sound fit within its tolerance
/// exits 0, one outside it exits 4 naming the constraints, never a success with a bad fit.
#[test]
fn an_automatic_fit_that_folds_runs_again_with_safer_settings_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let t001 = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/t001/template.vtk");
    let case = dir.path().join("case");
    let made = medial(&[
        "synth",
        "--from",
        s(&t001),
        "--out",
        s(&case),
        "--thicken-region",
        "2.343",
        "--region-atom",
        "141",
        "-q",
    ]);
    assert!(made.status.success(), "{}", text(&made.stderr));
    let out = dir.path().join("fit");
    let o = automatic_fit(
        &case.join("template.vtk"),
        "--image",
        &case.join("target.nii.gz"),
        &out,
    );
    let err = text(&o.stderr);
    let summary = read_summary(&out);
    let retries = summary["retries"].as_array().unwrap();
    assert!(!retries.is_empty(), "{err}");
    let first = retries[0].as_str().unwrap();
    assert!(first.contains("the model folds"), "{first}");
    assert!(first.contains("again with 20 time steps"), "{first}");
    assert_eq!(err.matches("again with").count(), retries.len(), "{err}");
    let last = &summary["stages"][0];
    let (angle, mismatch) = (
        f(&last["max_spoke_normal_deg"]),
        f(&last["max_spoke_mismatch_pct"]),
    );
    match o.status.code() {
        Some(0) => {
            assert!(angle <= 1.0 && mismatch <= 1.0, "{angle}° {mismatch} %");
            assert!(f(&last["voxel_dice"]) >= 0.93, "{last}");
        }
        Some(4) => {
            assert!(angle > 1.0 || mismatch > 1.0, "{angle}° {mismatch} %");
            assert!(err.contains("constraints are not met"), "{err}");
            assert_eq!(summary["status"], "constraints_not_met");
        }
        code => panic!("exit {code:?}: {err}"),
    }
}
