//! The views of `medial stats` and `medial pca` (issue 31): stats' report.html on meshglm's
//! data (self-contained, the maps, the null distributions with critical values that are the
//! smallest significant values, the clusters table; checked by the `stats` test that runs it),
//! and pca's animated glTF per mode and its report.html (scree and scores).

use crate::common::{f, run_json, s};
use crate::stats_cohort::{toy, write_cohort};
use medial_core::{MedialTemplate, Vec3};
use medial_io::vtk::read_polydata;
use std::path::Path;

/// The report.html of `medial stats` on meshglm's data with permutations, a threshold and TFCE
/// (`stats_on_meshglm_points_writes_every_map_and_the_clusters` runs it), in `out` whose
/// summary is `summary`.
pub fn check_stats_report(out: &Path, summary: &serde_json::Value) {
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    // Self-contained: nothing loaded from elsewhere.
    for outside in ["src=\"http", "href=\"http", "<script", "<link"] {
        assert!(!html.contains(outside), "report.html has {outside}");
    }
    // The maps: t, p_fwer, p_cluster and p_tfce, each a PNG of two views.
    assert_eq!(html.matches("data:image/png;base64,").count(), 4);
    for caption in [
        "t, front",
        "p_fwer ≤ 0.05, back",
        "p_cluster ≤ 0.05",
        "p_tfce ≤ 0.05",
    ] {
        assert!(html.contains(caption), "no '{caption}'");
    }
    // The null distributions: max-t, cluster area and TFCE, each with its critical value.
    assert_eq!(html.matches("5 % critical").count(), 3);
    for title in [
        "largest t per permutation",
        "largest cluster area per permutation",
        "largest TFCE per permutation",
    ] {
        assert!(html.contains(title), "no '{title}'");
    }
    // The design: meshglm's two groups of 20, the contrast's weights.
    assert!(
        html.contains("<td class=\"key\">x1</td><td>20</td>"),
        "no n per group"
    );
    assert!(html.contains("<td>0.05</td>"));
    // The clusters table: a row per line of clusters.csv.
    let csv = std::fs::read_to_string(out.join("clusters.csv")).unwrap();
    let section = &html[html.find("<h3>Clusters</h3>").unwrap()..];
    assert_eq!(section.matches("<tr>").count(), csv.lines().count());

    // The critical value is the smallest significant value: every element at or above it has
    // p_fwer ≤ 0.05, every element below it more.
    let critical = f(&summary["contrasts"][0]["critical_statistic"]);
    let stats = read_polydata(&out.join("stats.vtk")).unwrap();
    let t = &stats.point_array("t").unwrap().values;
    let p = &stats.point_array("p_fwer").unwrap().values;
    for (t, p) in t.iter().zip(p) {
        assert_eq!(
            *t >= critical,
            *p <= 0.05,
            "t {t}, p_fwer {p}, critical {critical}"
        );
    }
}

/// The points of node `name`'s frame `k` in a glTF file.
fn frame_points(
    document: &gltf::Document,
    buffers: &[gltf::buffer::Data],
    name: &str,
    k: usize,
) -> Vec<[f32; 3]> {
    let node = document
        .nodes()
        .find(|n| n.name() == Some(name))
        .unwrap_or_else(|| panic!("no node {name}"));
    let frame = node.children().nth(k).unwrap();
    let primitive = frame.mesh().unwrap().primitives().next().unwrap();
    let reader = primitive.reader(|b| Some(&buffers[b.index()]));
    reader.read_positions().unwrap().collect()
}

#[test]
fn pca_writes_each_mode_as_an_animation_from_minus_to_plus_two_sd() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let template = toy();
    // Subjects stretched along x by different amounts: one mode.
    let subjects: Vec<(String, MedialTemplate)> = (0..6)
        .map(|i| {
            let a = 1.0 + 0.04 * (i as f64 - 2.5) + 0.003 * ((i * 7 % 5) as f64);
            let q: Vec<Vec3> = template
                .landmarks()
                .iter()
                .map(|p| Vec3::new(a * p.x, p.y + 0.01 * i as f64 * p.z, p.z))
                .collect();
            (format!("s{i}"), template.with_landmarks(&q).unwrap())
        })
        .collect();
    let input = write_cohort(d, &subjects);
    let out = d.join("pca");
    let summary = run_json(&["pca", s(&input), "--out", s(&out), "--modes", "2"]);
    for mode in 1..=2 {
        let glb = out.join(format!("mode{mode}.glb"));
        assert_eq!(
            summary["modes"][mode - 1]["animation"].as_str().unwrap(),
            s(&glb)
        );
        let (document, buffers, _) = gltf::import(&glb).expect("modeK.glb reads");
        assert_eq!(document.animations().count(), 1);
        let series: serde_json::Value = serde_json::from_slice(
            &std::fs::read(out.join(format!("mode{mode}_medial.vtk.series"))).unwrap(),
        )
        .unwrap();
        let files = series["files"].as_array().unwrap();
        // Frame k of the animation is frame k of the series: −2 SD first, +2 SD last.
        for k in [0, 4, 8] {
            for (node, kind) in [("medial", "medial"), ("boundary", "boundary")] {
                let name = files[k]["name"].as_str().unwrap().replace("medial", kind);
                let vtk = read_polydata(&out.join(name)).unwrap();
                let glb_points = frame_points(&document, &buffers, node, k);
                assert_eq!(glb_points.len(), vtk.points.len());
                for (g, v) in glb_points.iter().zip(&vtk.points) {
                    for c in 0..3 {
                        assert!((f64::from(g[c]) - v[c]).abs() < 1e-4, "{node} frame {k}");
                    }
                }
            }
        }
        assert_eq!(f(&files[0]["time"]), -2.0);
    }
    // report.html: the scree plot, the scores plot and a row of scores per subject.
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("cumulative explained variance") && html.contains("pc2 against pc1"));
    assert_eq!(html.matches("<svg").count(), 2);
    let scores = std::fs::read_to_string(out.join("scores.csv")).unwrap();
    let table = &html[html.find("<table>").unwrap()..];
    assert_eq!(table.matches("<tr>").count(), scores.lines().count());
}
