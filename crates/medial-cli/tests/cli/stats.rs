//! `medial stats` on cmrep's meshglm test data (40 subjects on a mesh of 1,586 points and
//! 3,168 triangles, meshglm's design and contrast files), and its refusals of bad input.

use crate::common::{data, f, medial, one_line_error, run_json, s, text};
use medial_io::vtk::read_polydata;
use std::path::Path;

fn meshglm(name: &str) -> String {
    s(&data("cmrep/meshglm").join(name)).to_owned()
}

#[test]
fn stats_on_meshglm_points_writes_every_map_and_the_clusters() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let summary = run_json(&[
        "stats",
        &meshglm("test_meshglm_surface.vtk"),
        "--design",
        &meshglm("test_meshglm_surface_design.txt"),
        "--contrast",
        &meshglm("test_meshglm_surface_contrast.txt"),
        "--out",
        s(&out),
        "--permutations",
        "200",
        "--seed",
        "4",
        "--threshold",
        "3",
        "--tfce",
        "--fdr",
    ]);
    let contrast = &summary["contrasts"][0];
    assert_eq!(contrast["permutations"], 201);
    assert_eq!(contrast["weights"][0][2], 0.05);
    let stats = read_polydata(&out.join("stats.vtk")).unwrap();
    assert_eq!(stats.points.len(), 1586);
    assert_eq!(stats.polygons.len(), 3168);
    let names: Vec<&str> = stats.point_data.iter().map(|a| a.name.as_str()).collect();
    for name in [
        "t",
        "beta",
        "beta_std",
        "p",
        "q",
        "p_fwer",
        "tfce",
        "p_tfce",
        "cluster",
        "p_cluster",
    ] {
        assert!(names.contains(&name), "{name} missing from {names:?}");
    }
    let array = |name: &str| {
        &stats
            .point_data
            .iter()
            .find(|a| a.name == name)
            .unwrap()
            .values
    };
    let (t, p_fwer) = (array("t"), array("p_fwer"));
    let max_t = t.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    assert_eq!(max_t, f(&contrast["max_statistic"]));
    // The element of the largest t has the smallest FWER p, at least 1/201.
    let peak = t.iter().position(|&v| v == max_t).unwrap();
    assert_eq!(p_fwer[peak], f(&contrast["min_p_fwer"]));
    assert!(p_fwer.iter().all(|&p| (1.0 / 201.0..=1.0).contains(&p)));
    // clusters.csv: one row per cluster id of the map, the peak where the map says.
    let csv = std::fs::read_to_string(out.join("clusters.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    let ids = array("cluster");
    assert_eq!(rows.len() as f64, ids.iter().copied().fold(0.0, f64::max));
    assert_eq!(rows.len() as u64, contrast["clusters"].as_u64().unwrap());
    for row in &rows {
        let (id, element): (f64, usize) = (row[0].parse().unwrap(), row[6].parse().unwrap());
        assert_eq!(ids[element], id);
        assert_eq!(row[5].parse::<f64>().unwrap(), t[element]);
        assert!(t[element] > 3.0);
    }
    assert!(contrast["significant_clusters"].as_u64().unwrap() >= 1);
    // The outlines: edges of the mesh, each with the id of a cluster of the map.
    let edges = read_polydata(&out.join("clusters_edges.vtk")).unwrap();
    assert!(!edges.lines.is_empty());
    let edge_ids = &edges
        .cell_data
        .iter()
        .find(|a| a.name == "cluster")
        .unwrap()
        .values;
    for (line, &id) in edges.lines.iter().zip(edge_ids) {
        assert!(
            line.iter().any(|&i| ids[i] == id),
            "{line:?} outlines cluster {id}"
        );
    }
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(written, summary);
    crate::stats_report::check_stats_report(&out, &summary);
}

#[test]
fn stats_on_cells_with_several_contrasts_writes_a_folder_each() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let summary = run_json(&[
        "stats",
        &meshglm("test_meshglm_surface.vtk"),
        "--cell",
        "--design",
        &meshglm("test_meshglm_surface_design.txt"),
        "--contrast",
        "effect: -1 1 0.05",
        "--contrast",
        "groups: x1; x2",
        "--out",
        s(&out),
    ]);
    assert_eq!(summary["elements"], 3168);
    assert_eq!(summary["contrasts"][1]["statistic"], "F");
    let f_test = read_polydata(&out.join("2_groups").join("stats.vtk")).unwrap();
    let beta = f_test.cell_data.iter().find(|a| a.name == "beta").unwrap();
    assert_eq!(beta.components, 2);
    assert!(f_test.cell_data.iter().any(|a| a.name == "F"));
    assert!(Path::new(&out.join("1_effect").join("stats.vtk")).exists());
}

#[test]
fn bad_stats_inputs_are_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let input = meshglm("test_meshglm_surface.vtk");
    let design = meshglm("test_meshglm_surface_design.txt");
    let base = |extra: &[&str]| -> Vec<String> {
        let mut args: Vec<String> = ["stats", &input, "--design", &design, "--out", s(&out)]
            .iter()
            .map(|a| a.to_string())
            .collect();
        args.extend(extra.iter().map(|a| a.to_string()));
        args
    };
    let check = |extra: &[&str], needles: &[&str]| {
        let args = base(extra);
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        one_line_error(&refs, 1, needles);
    };
    check(
        &["--contrast", "x1", "--array", "Z"],
        &["no point array named 'Z'", "Y"],
    );
    check(
        &["--contrast", "x4"],
        &["`x4` is not a column", "x1, x2, x3"],
    );
    check(&["--contrast", "1 0"], &["has 2 weights", "3 columns"]);
    check(&["--contrast", "x1", "--threshold=-1"], &["threshold = -1"]);
    check(
        &["--contrast", "x1", "--tfce", "--tfce-dh", "0"],
        &["tfce dh = 0"],
    );
    check(&["--contrast", "x1; x2", "--two-sided"], &["one side"]);
    check(
        &["--contrast", "x1", "--exclude", "Y"],
        &["40 components, not 1"],
    );
    let short = dir.path().join("short.txt");
    std::fs::write(&short, "1 0 0.5\n0 1 0.2\n").unwrap();
    let args = [
        "stats",
        &input,
        "--design",
        s(&short),
        "--contrast",
        "x1",
        "--out",
        s(&out),
    ];
    one_line_error(&args, 1, &["40 components", "2 subjects"]);
    let o = medial(&["stats", &input, "--design", &design, "--out", s(&out)]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
}
