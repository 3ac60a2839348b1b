//! `medial stats` on a `medial batch` folder: a cohort made in a moment from the shipped toy
//! template (no fits: each subject's "fitted" model is the toy with every atom's spokes scaled
//! about its medial point, a little noise everywhere and a planted thickening at one end of the
//! sheet in group b), one subject whose fit failed, and a design naming them.

use crate::common::{f, medial, one_line_error, s, text};
use medial_core::model::{Model, SpokeMetrics};
use medial_core::MedialTemplate;
use medial_io::vtk::{read_polydata, PolyData};
use std::path::{Path, PathBuf};

const TOY: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../examples/toy/template.vtk"
);

/// Subjects per group.
const PER_GROUP: usize = 6;
/// The planted thickening: spokes 20 % longer.
const EFFECT: f64 = 0.2;
/// The noise: spokes scaled by up to ±4 %.
const NOISE: f64 = 0.04;

pub fn toy() -> MedialTemplate {
    match medial_io::model::read_model(Path::new(TOY)).unwrap() {
        Model::Medial(t) => *t,
        Model::Plain(_) => panic!("the toy is medial"),
    }
}

/// The atoms of the planted effect: those at the +z end of the toy's sheet.
pub fn planted(template: &MedialTemplate) -> Vec<bool> {
    template.medial_points().iter().map(|p| p.z > 6.0).collect()
}

/// A uniform number in [−1, 1) from a seed (splitmix64).
pub fn noise(seed: u64) -> f64 {
    let mut z = seed.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// The toy with atom m's spokes scaled by `scale[m]` about its medial point.
pub fn scaled(template: &MedialTemplate, scale: &[f64]) -> MedialTemplate {
    let mut q = template.landmarks().to_vec();
    for (b, &m) in template.medial_index().iter().enumerate() {
        let centre = q[template.atom_landmark(m)];
        q[b] = centre + (q[b] - centre) * scale[m];
    }
    template.with_landmarks(&q).unwrap()
}

/// Writes the cohort folder `dir/cohort` of `subjects` (name and "fitted" model: each a folder
/// with fitted_template.vtk and a config.toml naming the toy) and `gone` (its fit failed, no
/// folder); returns the folder.
pub fn write_cohort(dir: &Path, subjects: &[(String, MedialTemplate)]) -> PathBuf {
    let out = dir.join("cohort");
    let mut table = String::from("subject,status,dice\n");
    for (name, fitted) in subjects {
        let folder = out.join(name);
        std::fs::create_dir_all(&folder).unwrap();
        medial_io::cmrep::write_template(
            &folder.join("fitted_template.vtk"),
            fitted,
            medial_io::vtk::WriteOptions::default(),
        )
        .unwrap();
        std::fs::write(
            folder.join("config.toml"),
            format!("[model]\ntemplate = {TOY:?}\n"),
        )
        .unwrap();
        table.push_str(&format!("{name},budget,0.9\n"));
    }
    table.push_str("gone,failed,\n");
    std::fs::write(out.join("cohort.csv"), table).unwrap();
    out
}

/// The cohort of subjects a1…a6 and b1…b6 (b's planted atoms thickened) and `gone`; returns
/// its folder and every subject's thickness (by name).
fn cohort(dir: &Path) -> (PathBuf, Vec<(String, Vec<f64>)>) {
    let template = toy();
    let planted = planted(&template);
    let mut subjects = Vec::new();
    for (g, group) in ["a", "b"].iter().enumerate() {
        for k in 1..=PER_GROUP {
            let scale: Vec<f64> = (0..template.medial_count())
                .map(|m| {
                    let e = if g == 1 && planted[m] { EFFECT } else { 0.0 };
                    1.0 + e + NOISE * noise((g * 1000 + k * 100 + m) as u64)
                })
                .collect();
            subjects.push((format!("{group}{k}"), scaled(&template, &scale)));
        }
    }
    let thickness = subjects
        .iter()
        .map(|(name, fitted)| {
            let t = SpokeMetrics::compute(fitted, fitted.landmarks()).thickness;
            (name.clone(), t)
        })
        .collect();
    (write_cohort(dir, &subjects), thickness)
}

/// A design of the subjects `a…` (group a) and `b…` (group b), and `gone` in group `b`;
/// `labels` overrides every subject's group.
fn design(dir: &Path, name: &str, labels: impl Fn(usize, usize) -> &'static str) -> PathBuf {
    let mut csv = String::from("subject,group\n");
    for (g, group) in ["a", "b"].iter().enumerate() {
        for k in 1..=PER_GROUP {
            csv.push_str(&format!("{group}{k},{}\n", labels(g, k)));
        }
    }
    csv.push_str("gone,b\n");
    let path = dir.join(name);
    std::fs::write(&path, csv).unwrap();
    path
}

fn point_array<'a>(data: &'a PolyData, name: &str) -> &'a [f64] {
    &data
        .point_array(name)
        .unwrap_or_else(|| panic!("no array {name}"))
        .values
}

/// Runs `medial stats` on `input` with `design`, 500 permutations, clusters at t > 3 and TFCE;
/// returns the summary and stderr.
fn run_stats(
    input: &Path,
    design: &Path,
    out: &Path,
    extra: &[&str],
) -> (serde_json::Value, String) {
    let mut args = vec![
        "stats",
        s(input),
        "--design",
        s(design),
        "--contrast",
        "group[b]",
        "--out",
        s(out),
        "--permutations",
        "500",
        "--seed",
        "3",
        "--threshold",
        "3",
        "--tfce",
    ];
    args.extend(extra);
    let o = medial(&args);
    let err = text(&o.stderr);
    assert!(o.status.success(), "{args:?}: {err}");
    (serde_json::from_slice(&o.stdout).unwrap(), err)
}

#[test]
fn stats_on_a_cohort_finds_a_planted_thickening_and_nothing_in_a_null_design() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (input, thickness) = cohort(d);
    let template = toy();
    let planted = planted(&template);
    let atoms = template.medial_count();

    let groups = design(d, "groups.csv", |g, _| ["a", "b"][g]);
    let out = d.join("out");
    let (summary, err) = run_stats(&input, &groups, &out, &[]);
    assert!(
        err.contains("subject 'gone' left out: its fit failed"),
        "{err}"
    );
    assert_eq!(summary["kind"], "cohort");
    assert_eq!(summary["support"], "atoms");
    assert_eq!(summary["array"], "thickness");
    assert_eq!(summary["subjects"], 2 * PER_GROUP);
    assert_eq!(summary["left_out"][0]["subject"], "gone");
    assert_eq!(summary["elements"], atoms);
    assert_eq!(summary["template"], TOY);

    let maps = read_polydata(&out.join("stats.vtk")).unwrap();
    assert_eq!(maps.points.len(), atoms);
    for (p, m) in maps.points.iter().zip(template.medial_points()) {
        assert_eq!(p, m);
    }
    let (t, p_fwer, p_tfce, cluster, p_cluster) = (
        point_array(&maps, "t"),
        point_array(&maps, "p_fwer"),
        point_array(&maps, "p_tfce"),
        point_array(&maps, "cluster"),
        point_array(&maps, "p_cluster"),
    );
    for name in ["beta", "p", "tfce"] {
        point_array(&maps, name);
    }
    // t at every atom is the pooled two-sample t of the subjects' thickness.
    let (n, half) = (2 * PER_GROUP, PER_GROUP as f64);
    for m in 0..atoms {
        let group = |g: usize| -> Vec<f64> {
            thickness[g * PER_GROUP..(g + 1) * PER_GROUP]
                .iter()
                .map(|(_, th)| th[m])
                .collect()
        };
        let (a, b) = (group(0), group(1));
        let mean = |v: &[f64]| v.iter().sum::<f64>() / half;
        let ss = |v: &[f64]| v.iter().map(|x| (x - mean(v)).powi(2)).sum::<f64>();
        let pooled = (ss(&a) + ss(&b)) / (n - 2) as f64;
        let expected = (mean(&b) - mean(&a)) / (pooled * 2.0 / half).sqrt();
        assert!(
            (t[m] - expected).abs() <= 1e-6 * expected.abs().max(1.0),
            "atom {m}: t {} against {expected}",
            t[m]
        );
    }
    // The planted atoms: positive t, significant after FWER correction, TFCE and clusters;
    // nowhere else.
    let hits = planted.iter().filter(|&&x| x).count();
    assert!(hits >= 5 && hits < atoms / 2, "{hits} planted atoms");
    for m in 0..atoms {
        if planted[m] {
            assert!(t[m] > 5.0, "planted atom {m}: t {}", t[m]);
            assert!(p_fwer[m] <= 0.05, "planted atom {m}: p_fwer {}", p_fwer[m]);
            assert!(p_tfce[m] <= 0.05, "planted atom {m}: p_tfce {}", p_tfce[m]);
            assert!(cluster[m] > 0.0 && p_cluster[m] <= 0.05, "planted atom {m}");
        } else {
            assert!(p_fwer[m] > 0.05, "atom {m}: p_fwer {}", p_fwer[m]);
        }
    }
    let contrast = &summary["contrasts"][0];
    assert_eq!(contrast["fwer_significant_elements"], hits);
    assert!(f(&contrast["max_statistic"]) > 5.0);
    let clusters = std::fs::read_to_string(out.join("clusters.csv")).unwrap();
    assert!(clusters.lines().count() >= 2, "{clusters}");
    // The boundary of the template carries its atoms' results.
    let boundary = read_polydata(&out.join("stats_boundary.vtk")).unwrap();
    let tb = point_array(&boundary, "t");
    for (b, &m) in template.medial_index().iter().enumerate() {
        assert_eq!(tb[b].to_bits(), t[m].to_bits());
    }
    let written: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(written, summary);

    // A null design: each real group split evenly between the labels. Nothing is found.
    let null = design(d, "null.csv", |_, k| if k % 2 == 0 { "a" } else { "b" });
    let out = d.join("null");
    let (summary, _) = run_stats(&input, &null, &out, &[]);
    let contrast = &summary["contrasts"][0];
    assert!(f(&contrast["min_p_fwer"]) > 0.05, "{contrast}");
    assert!(f(&contrast["min_p_tfce"]) > 0.05, "{contrast}");
    assert_eq!(contrast["fwer_significant_elements"], 0);

    // Spoke lengths on either side: the planted effect on both.
    let out = d.join("spokes");
    let (summary, _) = run_stats(&input, &groups, &out, &["--array", "spoke_pos"]);
    assert_eq!(summary["array"], "spoke_pos");
    let t = point_array(&read_polydata(&out.join("stats.vtk")).unwrap(), "t").to_vec();
    for m in 0..atoms {
        if planted[m] && template.spokes(m).len() == 2 {
            assert!(t[m] > 5.0, "spoke_pos, atom {m}: t {}", t[m]);
        }
    }
}

#[test]
fn bad_cohort_inputs_are_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (input, _) = cohort(d);
    // Subjects whose fits are all usable (no note on stderr before the error).
    let groups = d.join("groups.csv");
    std::fs::write(&groups, "subject,group\na1,a\na2,a\nb1,b\nb2,b\n").unwrap();
    let out = d.join("out");
    let run = |design: &Path, extra: &[&str], needles: &[&str]| {
        let mut args = vec![
            "stats",
            s(&input),
            "--design",
            s(design),
            "--contrast",
            "group[b]",
            "--out",
            s(&out),
        ];
        args.extend(extra);
        one_line_error(&args, 1, needles)
    };
    // A subject the cohort does not have.
    let unknown = d.join("unknown.csv");
    std::fs::write(&unknown, "subject,group\na1,a\nzz,b\nb1,b\n").unwrap();
    run(
        &unknown,
        &[],
        &["unknown.csv", "subject `zz` (row 2)", "not in the cohort"],
    );
    // A design without subject names.
    let anonymous = d.join("anonymous.csv");
    std::fs::write(&anonymous, "group\na\nb\n").unwrap();
    run(&anonymous, &[], &["anonymous.csv", "no `subject`"]);
    // An atoms.csv column of subjects without atoms.csv.
    run(&groups, &["--array", "fidelity"], &["atoms.csv"]);
    // A subject's model of another template.
    std::fs::copy(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../examples/t001/template.vtk"
        ),
        input.join("a2/fitted_template.vtk"),
    )
    .unwrap();
    run(
        &groups,
        &[],
        &["a2/fitted_template.vtk", "another template"],
    );
    // Options of a mesh input; a folder that is no cohort.
    one_line_error(
        &[
            "stats",
            s(&input),
            "--design",
            s(&groups),
            "--contrast",
            "group[b]",
            "--out",
            s(&out),
            "--cell",
        ],
        2,
        &["--cell applies to a mesh input"],
    );
    one_line_error(
        &[
            "stats",
            s(d),
            "--design",
            s(&groups),
            "--contrast",
            "group[b]",
            "--out",
            s(&out),
        ],
        1,
        &["without cohort.csv"],
    );
}

#[test]
fn a_design_whose_subjects_all_failed_has_nothing_to_test() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (input, _) = cohort(d);
    let only = d.join("only.csv");
    std::fs::write(&only, "subject,group\ngone,b\n").unwrap();
    one_line_error(
        &[
            "stats",
            s(&input),
            "--design",
            s(&only),
            "--contrast",
            "group",
            "--out",
            s(&d.join("out")),
        ],
        1,
        &["only.csv", "none of its subjects has data to test"],
    );
}

/// The arguments as `&str`s.
fn args(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

#[test]
fn stats_refuses_a_damaged_subject_file_and_an_output_folder_of_other_results() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (input, _) = cohort(d);
    // Subjects whose fits are all usable (no note on stderr before the error).
    let groups = d.join("groups.csv");
    std::fs::write(
        &groups,
        "subject,group\na1,a\na2,a\na3,a\nb1,b\nb2,b\nb3,b\n",
    )
    .unwrap();
    let stats = |out: &Path| {
        vec![
            "stats".to_owned(),
            s(&input).to_owned(),
            "--design".to_owned(),
            s(&groups).to_owned(),
            "--contrast".to_owned(),
            "group[b]".to_owned(),
            "--permutations".to_owned(),
            "50".to_owned(),
            "--out".to_owned(),
            s(out).to_owned(),
        ]
    };
    // A subject's fitted model whose bytes differ from the digest its fit recorded.
    let marker = input.join("a1").join("summary.json");
    std::fs::write(&marker, r#"{"sha256": {"fitted_template.vtk": "00"}}"#).unwrap();
    let line = one_line_error(
        &args(&stats(&d.join("st"))),
        1,
        &["fitted_template.vtk", "SHA-256"],
    );
    assert!(line.contains("a1"), "{line}");
    // Likewise its atoms.csv, for a measure read from it.
    let atoms = input.join("a1").join("atoms.csv");
    std::fs::write(&atoms, "atom,fidelity\n0,1\n").unwrap();
    std::fs::write(&marker, r#"{"sha256": {"atoms.csv": "00"}}"#).unwrap();
    let mut column = stats(&d.join("st"));
    column.extend(["--array".to_owned(), "fidelity".to_owned()]);
    let line = one_line_error(&args(&column), 1, &["atoms.csv", "SHA-256"]);
    assert!(line.contains("a1"), "{line}");
    std::fs::remove_file(&atoms).unwrap();
    std::fs::remove_file(&marker).unwrap();
    // A fit's folder and a batch folder are not overwritten; the fit's summary stays.
    let fit = d.join("fit");
    std::fs::create_dir_all(&fit).unwrap();
    let summary = r#"{"version": "0", "status": "converged", "files": []}"#;
    std::fs::write(fit.join("summary.json"), summary).unwrap();
    one_line_error(
        &args(&stats(&fit)),
        1,
        &["would overwrite", "another --out"],
    );
    assert_eq!(
        std::fs::read_to_string(fit.join("summary.json")).unwrap(),
        summary
    );
    one_line_error(&args(&stats(&input)), 1, &["cohort.csv", "would overwrite"]);
    // Its own folder is written over.
    for _ in 0..2 {
        let o = medial(&args(&stats(&d.join("st"))));
        assert!(o.status.success(), "{}", text(&o.stderr));
    }
    let written: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("st").join("summary.json")).unwrap()).unwrap();
    assert_eq!(written["command"], "stats");
}
