//! `medial inflate` of cmrep's real sheets subdivided once: their radius is too large for the
//! curvature of the subdivided sheet, so inflation lowers it locally and says where in its JSON
//! output (docs/decisions/0400-inflation-radius-limit.md).

use crate::common::{data, f, run_json, s};

/// Inflates `sheet` with `--subdivide 1`; checks the template's topology and the report of the
/// lowered radii; returns the JSON output.
fn inflate_subdivided(sheet: &str) -> serde_json::Value {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("template.vtk");
    let sheet = data(sheet);
    let report = run_json(&["inflate", s(&sheet), "--out", s(&out), "--subdivide", "1"]);
    let limit = &report["radius_limit"];
    let lowered = limit["vertices_lowered"].as_u64().expect("a count") as usize;
    let vertices = limit["vertices"].as_array().expect("the lowered vertices");
    let pct = limit["reduction_pct"].as_array().expect("their reductions");
    let atoms = report["template"]["atoms"].as_u64().expect("atoms") as usize;
    assert!(lowered > 0 && lowered < atoms, "{limit}");
    assert_eq!((vertices.len(), pct.len()), (lowered, lowered));
    assert!(vertices
        .iter()
        .all(|v| (v.as_u64().unwrap() as usize) < atoms));
    let (max, mean) = (
        f(&limit["max_reduction_pct"]),
        f(&limit["mean_reduction_pct"]),
    );
    assert!(0.0 < mean && mean <= max && max < 100.0, "{limit}");
    let bound = limit["vertices_bound"].as_u64().expect("a count") as usize;
    assert!(0 < bound && bound <= lowered, "{limit}");
    // The template reads back and meets `medial check`.
    let check = run_json(&["check", s(&out)]);
    assert!(check["judged"].is_object(), "{check}");
    println!(
        "{}: {lowered} of {atoms} atoms lowered ({bound} bound), max {max:.1} %, mean \
         {mean:.1} %; check {}",
        sheet.display(),
        check["judged"]
    );
    report
}

#[test]
fn caudate_subdivided_inflates_with_its_radius_limited() {
    let report = inflate_subdivided("cmrep/real/caudate_pde_model.vtk");
    assert_eq!(report["template"]["atoms"].as_u64(), Some(1177));
}

#[test]
fn hippocampus_t002_subdivided_inflates_with_its_radius_limited() {
    let report = inflate_subdivided("cmrep/real/t002_hipp-prob_template.vtk");
    assert_eq!(report["template"]["atoms"].as_u64(), Some(3289));
}

#[test]
fn a_sheet_that_inflates_as_given_keeps_its_radius() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("template.vtk");
    let sheet = data("cmrep/placenta_template_anterioralign3.vtk");
    let report = run_json(&["inflate", s(&sheet), "--out", s(&out), "--subdivide", "1"]);
    assert_eq!(report["radius_limit"]["vertices_lowered"].as_u64(), Some(0));
    assert_eq!(f(&report["radius_limit"]["max_reduction_pct"]), 0.0);
}
