//! The views of `medial stats` and `medial pca` (issue 31): stats' report.html on meshglm's
//! data (self-contained, the maps, the null distributions with critical values that are the
//! smallest significant values, the clusters table; checked by the `stats` test that runs it),
//! and pca's animated glTF per mode (its accessors checked as the Khronos validator checks
//! them: counts, `min` and `max`, indices) and its report.html (scree and scores).

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

/// The values of `accessor` (`float` or `unsigned int` components), one row per element.
fn accessor_values(
    accessor: &gltf::Accessor,
    buffers: &[gltf::buffer::Data],
) -> Result<Vec<Vec<f64>>, String> {
    use gltf::accessor::DataType;
    let index = accessor.index();
    if accessor.sparse().is_some() {
        return Err(format!("accessor {index} is sparse"));
    }
    let view = (accessor.view()).ok_or_else(|| format!("accessor {index} has no buffer view"))?;
    let data = &buffers[view.buffer().index()];
    if view.offset() + view.length() > data.len() {
        return Err(format!("buffer view {} past its buffer", view.index()));
    }
    let (component, size) = (accessor.data_type(), accessor.size());
    if !matches!(component, DataType::F32 | DataType::U32) {
        return Err(format!("accessor {index}: {component:?} components"));
    }
    // The validator's ACCESSOR_TOTAL_OFFSET_ALIGNMENT and ACCESSOR_TOO_LONG.
    if (view.offset() + accessor.offset()) % 4 != 0 {
        return Err(format!("accessor {index} not aligned to its components"));
    }
    let stride = view.stride().unwrap_or(size);
    let count = accessor.count();
    if count == 0 || accessor.offset() + stride * (count - 1) + size > view.length() {
        return Err(format!(
            "accessor {index}: {count} elements do not fit its view"
        ));
    }
    let bytes = &data[view.offset() + accessor.offset()..view.offset() + view.length()];
    Ok((0..count)
        .map(|i| {
            (0..accessor.dimensions().multiplicity())
                .map(|c| {
                    let at = i * stride + 4 * c;
                    let word: [u8; 4] = bytes[at..at + 4].try_into().unwrap();
                    match component {
                        DataType::F32 => f64::from(f32::from_le_bytes(word)),
                        _ => f64::from(u32::from_le_bytes(word)),
                    }
                })
                .collect()
        })
        .collect())
}

/// Checks every accessor of a glTF file as the Khronos validator does: its elements inside
/// its buffer view and buffer, its `min` and `max` present (required of POSITION and of
/// animation inputs; the writer gives them to all) and equal to the least and greatest value of
/// each component (ACCESSOR_MIN_MISMATCH, ACCESSOR_MAX_MISMATCH: compared as `float`), every
/// index naming a vertex of its primitive, every animation's times increasing and as many as its
/// keys. The first problem found, if any.
pub fn check_accessors(
    document: &gltf::Document,
    buffers: &[gltf::buffer::Data],
) -> Result<(), String> {
    for accessor in document.accessors() {
        let index = accessor.index();
        let values = accessor_values(&accessor, buffers)?;
        let bounds = |json: Option<gltf::json::Value>, which: &str| {
            let json = json.ok_or_else(|| format!("accessor {index} has no {which}"))?;
            let bounds: Vec<f64> = serde_json::from_value(json)
                .map_err(|e| format!("accessor {index}: {which} {e}"))?;
            (bounds.len() == values[0].len())
                .then_some(bounds)
                .ok_or_else(|| format!("accessor {index}: {which} of another length"))
        };
        let (min, max) = (
            bounds(accessor.min(), "min")?,
            bounds(accessor.max(), "max")?,
        );
        for c in 0..min.len() {
            let column = values.iter().map(|v| v[c]);
            let least = column.clone().fold(f64::INFINITY, f64::min);
            let greatest = column.fold(f64::NEG_INFINITY, f64::max);
            // The validator reads the JSON bounds as the components' type.
            if min[c] as f32 != least as f32 || max[c] as f32 != greatest as f32 {
                return Err(format!(
                    "accessor {index}, component {c}: min/max {}/{} but the data's {least}/{greatest}",
                    min[c], max[c]
                ));
            }
        }
    }
    for mesh in document.meshes() {
        for primitive in mesh.primitives() {
            let vertices = (primitive.get(&gltf::Semantic::Positions))
                .ok_or_else(|| format!("mesh {} without POSITION", mesh.index()))?
                .count();
            for (semantic, attribute) in primitive.attributes() {
                if attribute.count() != vertices {
                    return Err(format!(
                        "mesh {}: {semantic:?} of another count",
                        mesh.index()
                    ));
                }
            }
            let indices = primitive.indices().ok_or("a primitive without indices")?;
            if indices.count() % 3 != 0 {
                return Err(format!("mesh {}: indices not in triangles", mesh.index()));
            }
            let values = accessor_values(&indices, buffers)?;
            if let Some(i) = values.iter().find(|v| v[0] >= vertices as f64) {
                return Err(format!(
                    "mesh {}: index {} of {vertices} vertices",
                    mesh.index(),
                    i[0]
                ));
            }
        }
    }
    for animation in document.animations() {
        for sampler in animation.samplers() {
            let times = accessor_values(&sampler.input(), buffers)?;
            if times.windows(2).any(|w| w[1][0] <= w[0][0]) {
                return Err("animation times not increasing".into());
            }
            if sampler.output().count() != times.len() {
                return Err("an animation's keys and times differ in number".into());
            }
        }
    }
    Ok(())
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
        check_accessors(&document, &buffers).unwrap_or_else(|e| panic!("mode{mode}.glb: {e}"));
        if mode == 1 {
            refuses_broken_accessors(document.clone(), &buffers);
        }
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

/// [`check_accessors`] can fail: a POSITION accessor's `max` off by 1 mm in its last
/// component, its count twice what its view holds, its `max` left out are each refused.
fn refuses_broken_accessors(document: gltf::Document, buffers: &[gltf::buffer::Data]) {
    use gltf::json::validation::USize64;
    let position = (document
        .meshes()
        .next()
        .unwrap()
        .primitives()
        .next()
        .unwrap())
    .get(&gltf::Semantic::Positions)
    .unwrap()
    .index();
    let json = document.into_json();
    let broken = |change: &dyn Fn(&mut gltf::json::Accessor)| {
        let mut json = json.clone();
        change(&mut json.accessors[position]);
        check_accessors(&gltf::Document::from_json_without_validation(json), buffers)
            .expect_err("a broken accessor")
    };
    let e = broken(&|a| {
        let max = a.max.as_mut().unwrap();
        max[2] = serde_json::json!(max[2].as_f64().unwrap() + 1.0);
    });
    assert!(e.contains("min/max"), "{e}");
    let e = broken(&|a| a.count = USize64(a.count.0 * 2));
    assert!(e.contains("do not fit"), "{e}");
    let e = broken(&|a| a.max = None);
    assert!(e.contains("no max"), "{e}");
}
