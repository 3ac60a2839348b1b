//! cmrep template files: the real t001 and placenta templates, write → read round trips in
//! every encoding and layout, and the refusal of broken files with messages that say what and
//! where.

use medial::io::cmrep::{
    read_template, template_from_polydata, template_to_polydata, write_template,
};
use medial::io::vtk::{read_polydata, Encoding, Layout, PolyData, WriteOptions};
use medial::io::Error;
use medial::model::constraints::MedialConstraints;
use medial::model::metrics::SpokeMetrics;
use medial::Vec3;
use std::path::Path;

const T001: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/data/cmrep/t001_template_bcmrep.vtk"
);
const PLACENTA: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/data/cmrep/placenta_template_anterioralign3_bcmrep.vtk"
);

fn t001_data() -> PolyData {
    read_polydata(Path::new(T001)).expect("t001 reads")
}

/// The error message of converting `data`, which must fail with the given variant.
fn refusal(data: &PolyData, model_error: bool) -> String {
    let error = template_from_polydata(data, Path::new("broken.vtk")).expect_err("must be refused");
    match (&error, model_error) {
        (Error::Model { .. }, true) | (Error::Format { .. }, false) => {}
        _ => panic!("unexpected error variant: {error:?}"),
    }
    let message = error.to_string();
    assert!(message.starts_with("broken.vtk: "), "{message}");
    message
}

fn set_point_value(data: &mut PolyData, array: &str, point: usize, value: f64) {
    let a = data
        .point_data
        .iter_mut()
        .find(|a| a.name == array)
        .expect("array exists");
    a.values[point] = value;
}

#[test]
fn t001_reads_as_the_reference_template() {
    let t = read_template(Path::new(T001)).expect("t001 reads");
    assert_eq!(
        (t.landmark_count(), t.boundary_count(), t.medial_count()),
        (503, 314, 189)
    );
    assert_eq!(MedialConstraints::new(&t).len(), 753);
    let spokes: Vec<usize> = (0..t.medial_count()).map(|m| t.spokes(m).len()).collect();
    assert_eq!(spokes.iter().filter(|&&n| n == 2).count(), 125);
    assert_eq!(spokes.iter().filter(|&&n| n == 1).count(), 64);
    // Medial point of atom m = b0 − Radius(b0)·normal(b0).
    let data = t001_data();
    let radius = data.point_array("Radius").expect("Radius");
    let normals = data.point_array("normals").expect("normals");
    for m in 0..t.medial_count() {
        let b0 = t.spokes(m)[0];
        let n = Vec3::from_column_slice(&normals.values[3 * b0..3 * b0 + 3]);
        let expected = data.points[b0] - radius.values[b0] * n;
        assert!((t.medial_points()[m] - expected).norm() < 1e-12);
    }
    let metrics = SpokeMetrics::compute(&t, t.landmarks());
    assert!((metrics.max_spoke_normal_deg - 0.070140).abs() < 5e-6);
    assert!((metrics.max_spoke_mismatch - 6.6982e-4).abs() < 5e-8);
}

#[test]
fn round_trip_in_every_encoding_and_layout() {
    let t = read_template(Path::new(T001)).expect("t001 reads");
    let metrics = SpokeMetrics::compute(&t, t.landmarks());
    let dir = tempfile::tempdir().expect("temporary directory");
    for encoding in [Encoding::Ascii, Encoding::Binary] {
        for layout in [Layout::Legacy, Layout::Offsets] {
            let path = dir.path().join(format!("t001_{encoding:?}_{layout:?}.vtk"));
            write_template(&path, &t, WriteOptions { encoding, layout }).expect("writes");
            let back = read_template(&path).expect("reads back");
            assert_eq!(back.landmarks(), t.landmarks(), "{encoding:?} {layout:?}");
            assert_eq!(back.boundary_triangles(), t.boundary_triangles());
            assert_eq!(back.medial_index(), t.medial_index());
            assert_eq!(SpokeMetrics::compute(&back, back.landmarks()), metrics);
        }
    }
}

#[test]
fn written_arrays_describe_the_model() {
    let t = read_template(Path::new(T001)).expect("t001 reads");
    let data = template_to_polydata(&t);
    let metrics = SpokeMetrics::compute(&t, t.landmarks());
    let array = |name: &str| data.point_array(name).expect("written");
    assert_eq!(array("Radius").values, metrics.spoke_length);
    let tangency = &array("Tangency").values;
    for (b, &m) in t.medial_index().iter().enumerate() {
        assert_eq!(tangency[b], t.spokes(m).len() as f64);
        assert_eq!(array("MedialIndex").values[b], m as f64);
    }
    // With MedialPoint removed, the medial points come from Radius and the (Loop) normals:
    // exact up to the spoke–normal deviation (≤ 0.0702°, i.e. ≤ 1.3e-3 × the radius).
    let mut without = data.clone();
    without.point_data.retain(|a| a.name != "MedialPoint");
    let rebuilt = template_from_polydata(&without, Path::new("rebuilt.vtk")).expect("valid");
    for m in 0..t.medial_count() {
        let b0 = t.spokes(m)[0];
        let gap = (rebuilt.medial_points()[m] - t.medial_points()[m]).norm();
        assert!(gap <= 1.3e-3 * metrics.spoke_length[b0], "atom {m}: {gap}");
    }
}

#[test]
fn placenta_without_radius_or_medial_points_is_refused() {
    let error = read_template(Path::new(PLACENTA)).expect_err("no medial points");
    let message = error.to_string();
    assert!(matches!(error, Error::Format { .. }), "{error:?}");
    for needle in [
        "cannot place the medial points",
        "MedialPoint",
        "Radius",
        "arrays are: MedialIndex",
    ] {
        assert!(message.contains(needle), "{message}");
    }
}

#[test]
fn broken_meshes_are_refused() {
    let mut open = t001_data();
    open.polygons.remove(0);
    let m = refusal(&open, true);
    assert!(
        m.contains("the surface is open") && m.contains("edge ("),
        "{m}"
    );

    let mut flipped = t001_data();
    flipped.polygons[10].reverse();
    let m = refusal(&flipped, true);
    assert!(
        m.contains("inconsistent orientation") && m.contains("10"),
        "{m}"
    );

    let mut inward = t001_data();
    inward.polygons.iter_mut().for_each(|p| p.reverse());
    let m = refusal(&inward, true);
    assert!(m.contains("normals point inward"), "{m}");

    let mut quad = t001_data();
    quad.polygons[3].push(7);
    let m = refusal(&quad, false);
    assert!(m.contains("polygon 3 has 4 vertices"), "{m}");
}

#[test]
fn broken_medial_indices_are_refused() {
    let mut missing = t001_data();
    missing.point_data.retain(|a| a.name != "MedialIndex");
    let m = refusal(&missing, false);
    assert!(
        m.contains("'MedialIndex'") && m.contains("arrays are: normals, Tangency, Radius"),
        "{m}"
    );

    let mut negative = t001_data();
    set_point_value(&mut negative, "MedialIndex", 5, -1.0);
    let m = refusal(&negative, false);
    assert!(m.contains("value -1 at point 5"), "{m}");

    let mut beyond = t001_data();
    set_point_value(&mut beyond, "MedialIndex", 5, 500.0);
    let m = refusal(&beyond, false);
    assert!(
        m.contains("skips atom") && m.contains("500 (at boundary point 5)"),
        "{m}"
    );
    // An atom number far beyond the points used to size a table by it (an allocation abort).
    set_point_value(&mut beyond, "MedialIndex", 5, 1e15);
    let m = refusal(&beyond, false);
    assert!(
        m.contains("skips atom") && m.contains("1000000000000000"),
        "{m}"
    );

    // Give the spokes of one sheet atom to another (4 spokes), renumber the last atom into the
    // gap, and drop Tangency (which would disagree).
    let t = read_template(Path::new(T001)).expect("t001 reads");
    let last = t.medial_count() - 1;
    let sheet: Vec<usize> = (0..last)
        .filter(|&m| t.spokes(m).len() == 2)
        .take(2)
        .collect();
    let mut four = t001_data();
    four.point_data.retain(|a| a.name != "Tangency");
    let index = four
        .point_data
        .iter_mut()
        .find(|a| a.name == "MedialIndex")
        .expect("there");
    for v in index.values.iter_mut() {
        if *v == sheet[1] as f64 {
            *v = sheet[0] as f64;
        } else if *v == last as f64 {
            *v = sheet[1] as f64;
        }
    }
    let m = refusal(&four, true);
    assert!(
        m.contains(&format!("medial atom {} has 4 spokes", sheet[0])),
        "{m}"
    );
}

#[test]
fn inconsistent_arrays_are_refused() {
    let t = read_template(Path::new(T001)).expect("t001 reads");
    let sheet = (0..t.medial_count())
        .find(|&m| t.spokes(m).len() == 2)
        .expect("a sheet atom");
    let b = t.spokes(sheet)[1];
    let mut tangency = t001_data();
    set_point_value(&mut tangency, "Tangency", b, 3.0);
    let m = refusal(&tangency, false);
    assert!(
        m.contains(&format!(
            "atom {sheet} has 3 spokes (at boundary point {b})"
        )),
        "{m}"
    );
    assert!(m.contains("MedialIndex gives it 2"), "{m}");

    let mut normal = t001_data();
    let b0 = t.spokes(sheet)[0];
    let n = normal
        .point_data
        .iter_mut()
        .find(|a| a.name == "normals")
        .expect("normals");
    n.values[3 * b0] *= 2.0;
    n.values[3 * b0 + 1] = 1.0;
    let m = refusal(&normal, false);
    assert!(
        m.contains(&format!("'normals' at point {b0}")) && m.contains("unit vectors"),
        "{m}"
    );

    let mut radius = t001_data();
    set_point_value(&mut radius, "Radius", b0, -0.5);
    let m = refusal(&radius, false);
    assert!(m.contains(&format!("value -0.5 at point {b0}")), "{m}");

    let mut not_finite = t001_data();
    set_point_value(&mut not_finite, "Radius", 7, f64::NAN);
    let m = refusal(&not_finite, false);
    assert!(
        m.contains("'Radius' has the non-finite value NaN at point 7"),
        "{m}"
    );

    let mut disagree = template_to_polydata(&t);
    let points = disagree
        .point_data
        .iter_mut()
        .find(|a| a.name == "MedialPoint")
        .expect("there");
    points.values[3 * b] += 0.5;
    let m = refusal(&disagree, false);
    assert!(
        m.contains(&format!("atom {sheet} two different medial points")),
        "{m}"
    );
    assert!(m.contains(&format!("points {b0} and {b}")), "{m}");
}
