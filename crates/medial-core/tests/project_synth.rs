//! Projection onto the medial constraints (the placenta inflated from cmrep's sheet, cmrep's own
//! t001 template) and the synthetic cases (templates, warps, targets).

use std::path::Path;

use medial_core::inflate::{inflate, MedialSheet};
use medial_core::metrics::SpokeMetrics;
use medial_core::project::{project, ProjectOptions};
use medial_core::synth::{midpoint_subdivide, Shape, SyntheticCase};
use medial_core::template::MedialTemplate;
use medial_core::{Error, TriMesh, Vec3};
use proptest::prelude::*;

const CMREP: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data/cmrep/");

fn placenta_template(subdivisions: usize) -> MedialTemplate {
    let path = format!("{CMREP}placenta_template_anterioralign3.vtk");
    let data = medial_io::vtk::read_polydata(Path::new(&path)).expect("placenta sheet");
    let radius = data.point_array("Radius").expect("Radius").values.clone();
    let mut sheet = MedialSheet::new(data.points.clone(), data.triangles().unwrap(), radius)
        .expect("placenta sheet is valid");
    for _ in 0..subdivisions {
        sheet = sheet.loop_subdivide().expect("subdivides");
    }
    let inflated = inflate(&sheet).expect("inflates");
    MedialTemplate::new(
        inflated.boundary,
        inflated.medial_index,
        inflated.medial_points,
    )
    .expect("a valid template")
}

/// Atoms with 1, 2, 3 spokes.
fn spoke_histogram(t: &MedialTemplate) -> [usize; 3] {
    let mut h = [0; 3];
    (0..t.medial_count()).for_each(|m| h[t.spokes(m).len() - 1] += 1);
    h
}

fn volume(mesh: &TriMesh) -> f64 {
    let p = mesh.points();
    mesh.triangles()
        .iter()
        .map(|t| p[t[0]].dot(&p[t[1]].cross(&p[t[2]])) / 6.0)
        .sum()
}

/// Centroid of the solid bounded by `mesh` (divergence theorem over tetrahedra to the origin).
fn centroid(mesh: &TriMesh) -> Vec3 {
    let p = mesh.points();
    let weighted: Vec3 = mesh
        .triangles()
        .iter()
        .map(|t| p[t[0]].dot(&p[t[1]].cross(&p[t[2]])) / 6.0 * (p[t[0]] + p[t[1]] + p[t[2]]) / 4.0)
        .sum();
    weighted / volume(mesh)
}

#[test]
fn placenta_inflated_once_projects_onto_the_constraints() {
    let template = placenta_template(1);
    assert_eq!(template.boundary_count(), 818);
    assert_eq!(spoke_histogram(&template), [48, 385, 0]);
    let start = std::time::Instant::now();
    let p = project(&template, &ProjectOptions::default()).expect("projects");
    println!(
        "placenta: k = {}, before {:.3}° / {:.3} %, after {:.2e}° / {:.2e} % (max |C| {:.1e} mm²) in {} \
         iterations, {:.2} s; moves max {:.3} mm, rms {:.3} mm",
        template.landmark_count(),
        p.before.max_spoke_normal_deg,
        100.0 * p.before.max_mismatch,
        p.after.max_spoke_normal_deg,
        100.0 * p.after.max_mismatch,
        p.after.max_abs_constraint,
        p.iterations,
        start.elapsed().as_secs_f64(),
        p.max_displacement,
        p.rms_displacement
    );
    assert!(
        p.before.max_spoke_normal_deg > 1.0,
        "inflation is only approximately medial"
    );
    assert!(
        p.after.max_spoke_normal_deg < 1e-3 && p.after.max_mismatch < 1e-5,
        "{:?}",
        p.after
    );
    // Independent check with the metrics module and the stored structure.
    let metrics = SpokeMetrics::compute(&p.template, p.template.landmarks());
    assert!(metrics.max_spoke_normal_deg <= 0.1 && metrics.max_spoke_mismatch <= 1e-3);
    assert_eq!(
        p.template.boundary_triangles(),
        template.boundary_triangles()
    );
    assert_eq!(p.template.medial_index(), template.medial_index());
    // Small moves against radii of 3–5 mm; the boundary keeps its volume within 2 %.
    assert!(
        p.max_displacement < 1.5 && p.rms_displacement < 0.3,
        "{} {}",
        p.max_displacement,
        p.rms_displacement
    );
    let mesh = |t: &MedialTemplate| {
        TriMesh::new(
            t.boundary_points().to_vec(),
            t.boundary_triangles().to_vec(),
        )
        .unwrap()
    };
    let (v0, v1) = (volume(&mesh(&template)), volume(&mesh(&p.template)));
    assert!((v1 - v0).abs() < 0.02 * v0, "{v0} → {v1}");
}

#[test]
fn cmrep_template_is_already_medial_and_barely_moves() {
    let path = format!("{CMREP}t001_template_bcmrep.vtk");
    let template = medial_io::cmrep::read_template(Path::new(&path)).expect("t001");
    let p = project(&template, &ProjectOptions::default()).expect("projects");
    println!(
        "t001: before {:.3}°, {:.3} %; moves max {:.4} mm, {} iterations",
        p.before.max_spoke_normal_deg,
        100.0 * p.before.max_mismatch,
        p.max_displacement,
        p.iterations
    );
    assert!(p.before.max_spoke_normal_deg < 0.1);
    assert!(p.after.max_spoke_normal_deg < 1e-4 && p.after.max_mismatch < 1e-6);
    assert!(p.max_displacement < 0.05, "{}", p.max_displacement);
}

#[test]
fn unreachable_tolerances_are_an_error_with_figures() {
    let template = placenta_template(0);
    let options = ProjectOptions {
        max_iterations: 1,
        max_spoke_normal_deg: 1e-9,
        max_mismatch: 1e-12,
    };
    match project(&template, &options) {
        Err(Error::Optimisation(m)) => {
            assert!(
                m.contains("after 1 iterations") && m.contains("asked"),
                "{m}"
            )
        }
        other => panic!("expected an optimisation error, got {other:?}"),
    }
}

#[test]
fn synthetic_cases_are_medial_templates_with_the_intended_structure() {
    for shape in Shape::ALL {
        let case = SyntheticCase::build(shape).expect("builds");
        let t = case.template();
        let h = spoke_histogram(t);
        let p = &case.projection;
        println!(
            "{}: {} boundary points, {} atoms {h:?}, k = {}; inflated {:.2}° / {:.2} %, projected {:.1e}° / {:.1e} %, moves max {:.3} mm",
            shape.name(),
            t.boundary_count(),
            t.medial_count(),
            t.landmark_count(),
            p.before.max_spoke_normal_deg,
            100.0 * p.before.max_mismatch,
            p.after.max_spoke_normal_deg,
            100.0 * p.after.max_mismatch,
            p.max_displacement
        );
        assert!(p.after.max_spoke_normal_deg <= 0.1 && p.after.max_mismatch <= 1e-3);
        assert!(
            (200..=800).contains(&t.landmark_count()),
            "k = {}",
            t.landmark_count()
        );
        match shape {
            // One sheet with a free edge: 1- and 2-spoke atoms.
            Shape::Cup => assert!(h[0] == 48 && h[1] > 0 && h[2] == 0, "{h:?}"),
            // Three sheets of 4 × 8 cells after one subdivision: 45 free-edge atoms and the two
            // ends of the seam (where it meets the free edges) have one spoke, the 7 other seam
            // atoms three, the 3 × 3 × 7 interior sheet atoms two.
            Shape::Toy => assert_eq!(h, [47, 63, 7]),
        }
        // Thickness: the cup's half thickness lies in 2 … 4 mm, the toy's in 1.96 … 3.5 mm.
        let metrics = SpokeMetrics::compute(t, t.landmarks());
        let (lo, hi) = metrics
            .thickness
            .iter()
            .fold((f64::MAX, 0.0f64), |(lo, hi), &x| (lo.min(x), hi.max(x)));
        let expected = match shape {
            Shape::Cup => (4.0, 8.0),
            Shape::Toy => (3.92, 7.0),
        };
        assert!(
            lo > 0.9 * expected.0 && hi < 1.1 * expected.1,
            "{}: thickness {lo} … {hi}",
            shape.name()
        );
    }
}

#[test]
fn targets_are_the_warped_shapes() {
    for shape in Shape::ALL {
        let case = SyntheticCase::build(shape).expect("builds");
        let boundary = case.boundary().unwrap();
        let target = case.target_surface().unwrap();
        // Midpoint subdivision keeps the surface: same volume before the warp.
        let fine = midpoint_subdivide(&midpoint_subdivide(&boundary).unwrap()).unwrap();
        assert!((volume(&fine) - volume(&boundary)).abs() < 1e-9 * volume(&boundary));
        // The warp scales volumes by det A (1 − κx), x after the twist (det T = 1): the
        // target volume is about det A (1 − κ x̄) V with x̄ at the template's centroid.
        let det = case.warp.linear.determinant();
        let local = centroid(&boundary) - case.warp.centre;
        let (s, c) = (case.warp.twist * local.z).sin_cos();
        let expected =
            det * (1.0 - case.warp.bend * (c * local.x - s * local.y)) * volume(&boundary);
        let ratio = volume(&target) / expected;
        assert!(
            (ratio - 1.0).abs() < 0.01,
            "{}: volume ratio {ratio}",
            shape.name()
        );
        // Its rasterization holds the target volume to within a few percent.
        let spacing = shape.image_spacing_mm();
        let image = case.target_image(spacing, 2.0).unwrap();
        let raster = image.integral();
        println!(
            "{}: target image {:?} voxels of {spacing} mm, volume {raster:.0} mm³ vs mesh {:.0} mm³",
            shape.name(),
            image.dims(),
            volume(&target)
        );
        assert!((raster / volume(&target) - 1.0).abs() < 0.03);
        // The target boundary is the warp of each template point.
        let points = case.target_boundary().unwrap();
        for (p, q) in boundary.points().iter().zip(points.points()) {
            assert!((case.warp.apply(p) - q).norm() < 1e-12);
        }
    }
}

/// Central finite differences of the warp: its Jacobian determinant stays positive and close
/// to det A over the template.
#[test]
fn warps_are_orientation_preserving_on_the_templates() {
    for shape in Shape::ALL {
        let case = SyntheticCase::build(shape).expect("builds");
        let det_a = case.warp.linear.determinant();
        let h = 1e-4;
        for p in case.template().landmarks() {
            let column = |axis: usize| {
                let mut e = Vec3::zeros();
                e[axis] = h;
                (case.warp.apply(&(p + e)) - case.warp.apply(&(p - e))) / (2.0 * h)
            };
            let jac = nalgebra::Matrix3::from_columns(&[column(0), column(1), column(2)]);
            let ratio = jac.determinant() / det_a;
            // det B = 1 − κx with |κx| ≤ 0.4 on these shapes; det T = 1.
            let x = case.warp.centre;
            let bent_x = {
                let local = p - x;
                let (s, c) = (case.warp.twist * local.z).sin_cos();
                c * local.x - s * local.y
            };
            assert!(
                (ratio - (1.0 - case.warp.bend * bent_x)).abs() < 1e-6,
                "{}: {ratio} at {p:?}",
                shape.name()
            );
            assert!(ratio > 0.5);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn the_inverse_undoes_the_warp(x in -30.0..30.0f64, y in -30.0..30.0f64, z in -30.0..30.0f64) {
        for shape in Shape::ALL {
            let warp = shape.warp(Vec3::new(0.5, -1.0, 2.0));
            let p = Vec3::new(x, y, z);
            let back = warp.inverse(&warp.apply(&p)).expect("invertible");
            prop_assert!((back - p).norm() < 1e-9, "{p:?} → {back:?}");
        }
    }
}

/// The target is reachable: the template with every landmark (boundary and medial) carried by
/// the warp overlaps the target image almost as well as the Dice estimate allows (it counts
/// the boundary samples, where the image is ½, with a sixth of the outermost prisms: a bias of
/// about `1/(4·layers)`), the template itself much less.
#[test]
fn the_warped_template_matches_the_target_image() {
    use medial_core::attachment::dice::{DiceAttachment, DiceParams};
    for shape in Shape::ALL {
        let case = SyntheticCase::build(shape).expect("builds");
        let t = case.template();
        let image = case
            .target_image(shape.image_spacing_mm(), 2.0)
            .unwrap()
            .smoothed(0.2)
            .unwrap();
        let medial_of: Vec<usize> = t
            .medial_index()
            .iter()
            .map(|&m| t.atom_landmark(m))
            .collect();
        let warped: Vec<Vec3> = t.landmarks().iter().map(|p| case.warp.apply(p)).collect();
        let dice = |layers: usize, q: &[Vec3]| {
            let params = DiceParams {
                subdivision: 2,
                layers,
            };
            let d = DiceAttachment::new(
                t.boundary_triangles(),
                &medial_of,
                t.landmark_count(),
                image.clone(),
                params,
            )
            .unwrap();
            d.evaluate(q, None).unwrap().dice
        };
        let (at_target_5, at_target_10) = (dice(5, &warped), dice(10, &warped));
        let at_template = dice(10, t.landmarks());
        println!(
            "{}: Dice of the warped template {at_target_5:.4} (5 layers), {at_target_10:.4} (10 layers); of the template {at_template:.4}",
            shape.name()
        );
        assert!(
            at_target_5 > 0.92 && at_target_10 > 0.935 && at_template < 0.8,
            "{at_target_5} {at_target_10} {at_template}"
        );
        assert!(at_target_10 > at_target_5 + 0.008, "more layers, less bias");
    }
}
