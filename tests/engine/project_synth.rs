//! Projection onto the medial constraints (the placenta inflated from cmrep's sheet, cmrep's own
//! t001 template), the synthetic cases (templates, warps, targets) and the general warp along
//! the principal axes of any template (t001).

use std::path::Path;
use std::sync::OnceLock;

use medial::construction::inflate::{inflate, MedialSheet};
use medial::construction::project::{project, ProjectOptions};
use medial::mesh::subdivide::midpoint_subdivide;
use medial::mesh::PrincipalAxes;
use medial::model::metrics::SpokeMetrics;
use medial::model::template::MedialTemplate;
use medial::synth::{target_boundary, target_image, target_surface, Shape, SyntheticCase, Warp};
use medial::{Error, TriMesh, Vec3};
use nalgebra::{Matrix3, Matrix4, Rotation3, Unit};
use proptest::prelude::*;

const CMREP: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/cmrep/");

fn placenta_template(subdivisions: usize) -> MedialTemplate {
    let path = format!("{CMREP}placenta_template_anterioralign3.vtk");
    let data = medial::io::vtk::read_polydata(Path::new(&path)).expect("placenta sheet");
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
    medial::mesh::topology::signed_volume(mesh.points(), mesh.triangles())
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
    let p = project(&template, &ProjectOptions::default()).expect("projects");
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
    let template = medial::io::cmrep::read_template(Path::new(&path)).expect("t001");
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

/// The synthetic case of `shape`, built once for all the tests that use it.
fn synthetic_case(shape: Shape) -> &'static SyntheticCase {
    static CASES: [OnceLock<SyntheticCase>; Shape::ALL.len()] =
        [const { OnceLock::new() }; Shape::ALL.len()];
    let slot = Shape::ALL
        .iter()
        .position(|&s| s == shape)
        .expect("a shape of Shape::ALL");
    CASES[slot].get_or_init(|| SyntheticCase::build(shape).expect("builds"))
}

#[test]
fn synthetic_cases_are_medial_templates_with_the_intended_structure() {
    for shape in Shape::ALL {
        let case = synthetic_case(shape);
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
        let case = synthetic_case(shape);
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
        let case = synthetic_case(shape);
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
/// the warp overlaps the target image almost as well as the Dice estimate allows (what is left
/// is the blur of the image edge and the rasterization; the estimate samples half way between
/// layers, so it hardly depends on their number), the template itself much less.
#[test]
fn the_warped_template_matches_the_target_image() {
    use medial::attachment::dice::{DiceAttachment, DiceParams};
    for shape in Shape::ALL {
        let case = synthetic_case(shape);
        let t = case.template();
        let image = case
            .target_image(shape.image_spacing_mm(), 2.0)
            .unwrap()
            .smoothed(0.2)
            .unwrap();
        let warped: Vec<Vec3> = t.landmarks().iter().map(|p| case.warp.apply(p)).collect();
        let dice = |layers: usize, q: &[Vec3]| {
            let params = DiceParams {
                subdivision: 2,
                layers,
            };
            let d = DiceAttachment::for_template(t, image.clone(), params).unwrap();
            d.dice(q, None).unwrap().dice
        };
        let (at_target_5, at_target_10) = (dice(5, &warped), dice(10, &warped));
        let at_template = dice(10, t.landmarks());
        println!(
            "{}: Dice of the warped template {at_target_5:.4} (5 layers), {at_target_10:.4} (10 layers); of the template {at_template:.4}",
            shape.name()
        );
        assert!(
            at_target_5 > 0.94 && at_target_10 > 0.94 && at_template < 0.8,
            "{at_target_5} {at_target_10} {at_template}"
        );
        assert!(
            (at_target_10 - at_target_5).abs() < 0.015,
            "the midpoint rule across the wall barely depends on the layers"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// The general warp (any frame) and templates as synthetic cases.

fn t001() -> MedialTemplate {
    let path = format!("{CMREP}t001_template_bcmrep.vtk");
    medial::io::cmrep::read_template(Path::new(&path)).expect("t001")
}

/// A warp with every part non-trivial: tilted frame, twist, bend, affine map.
fn general_warp() -> Warp {
    Warp {
        centre: Vec3::new(10.0, -5.0, 20.0),
        frame: Rotation3::from_axis_angle(&Unit::new_normalize(Vec3::new(1.0, 2.0, -0.5)), 0.9),
        twist: 0.01,
        bend: 0.015,
        linear: Rotation3::from_axis_angle(&Vec3::y_axis(), 0.2).matrix()
            * Matrix3::from_diagonal(&Vec3::new(1.05, 0.95, 1.02)),
        translation: Vec3::new(1.0, 2.0, -1.5),
    }
}

/// The formula of the built-in shapes written out independently:
/// `c + t + A·B_κ(T_τ(p − c))` with `B_κ(x, y, z) = (x cos θ + ρ(1 − cos θ), y, (ρ − x) sin θ)`.
fn world_frame_formula(w: &Warp, p: &Vec3) -> Vec3 {
    let d = p - w.centre;
    let (s, c) = (w.twist * d.z).sin_cos();
    let (x, y, z) = (c * d.x - s * d.y, s * d.x + c * d.y, d.z);
    let rho = 1.0 / w.bend;
    let theta = w.bend * z;
    let bent = Vec3::new(
        x * theta.cos() + rho * (1.0 - theta.cos()),
        y,
        (rho - x) * theta.sin(),
    );
    w.centre + w.translation + w.linear * bent
}

#[test]
fn the_identity_frame_reproduces_the_world_frame_formula() {
    let mut warps: Vec<Warp> = Shape::ALL
        .iter()
        .map(|s| s.warp(Vec3::new(0.5, -1.0, 2.0)))
        .collect();
    warps.push(Warp {
        frame: Rotation3::identity(),
        ..general_warp()
    });
    for w in warps {
        for p in [
            Vec3::new(3.0, -4.0, 11.0),
            Vec3::new(-8.0, 6.0, -13.0),
            Vec3::new(0.1, 0.2, 0.3),
        ] {
            let expected = world_frame_formula(&w, &p);
            assert!((w.apply(&p) - expected).norm() < 1e-10, "{p:?}");
        }
    }
}

/// With a frame `F`, `A = I`, `t = 0`: `φ_F(p) = c + F·φ_I(c + Fᵀ(p − c)) − F·c`, the warp
/// conjugated by the rotation about the centre.
#[test]
fn a_frame_rotates_the_warp_about_its_centre() {
    let w = Warp {
        linear: Matrix3::identity(),
        translation: Vec3::zeros(),
        ..general_warp()
    };
    let world = Warp {
        frame: Rotation3::identity(),
        ..w
    };
    for p in [Vec3::new(3.0, -4.0, 11.0), Vec3::new(-8.0, 6.0, 33.0)] {
        let rotated_back = w.centre + w.frame.inverse_transform_vector(&(p - w.centre));
        let expected = w.centre + w.frame * (world.apply(&rotated_back) - w.centre);
        assert!((w.apply(&p) - expected).norm() < 1e-10);
    }
}

/// A straight segment along the frame's z axis through the centre is rolled onto a circle of
/// radius `ρ = 1/κ` (times the scale of `A`), keeping its length; its ends turn by `κL`.
#[test]
fn a_straight_line_along_the_long_axis_is_bent_to_curvature_kappa() {
    let scale = 1.2;
    let w = Warp {
        linear: Matrix3::identity() * scale,
        ..general_warp()
    };
    let axis = w.frame * Vec3::z();
    let samples: Vec<Vec3> = (0..=40)
        .map(|i| w.apply(&(w.centre + axis * (i as f64 - 20.0))))
        .collect();
    // Circumradius of consecutive triples: a circle of radius ρ·scale.
    let rho = scale / w.bend;
    for t in samples.windows(3).step_by(7) {
        let (a, b, c) = (
            (t[1] - t[0]).norm(),
            (t[2] - t[1]).norm(),
            (t[2] - t[0]).norm(),
        );
        let area2 = (t[1] - t[0]).cross(&(t[2] - t[0])).norm();
        let circumradius = a * b * c / (2.0 * area2);
        assert!(
            (circumradius / rho - 1.0).abs() < 1e-6,
            "{circumradius} vs {rho}"
        );
    }
    // Arc length: 40 mm scaled (polyline of 1 mm chords, chord error ~ (κh)²/24).
    let length: f64 = samples.windows(2).map(|t| (t[1] - t[0]).norm()).sum();
    assert!((length / (40.0 * scale) - 1.0).abs() < 1e-5, "{length}");
    // The tangent turns by κ·40 mm from end to end, bending towards the frame's +x axis.
    let (t0, t1) = (samples[1] - samples[0], samples[40] - samples[39]);
    let turn = t0.angle(&t1);
    assert!((turn - w.bend * 39.0).abs() < 1e-9, "{turn}");
    let bent_towards =
        w.linear.try_inverse().unwrap() * (samples[20] - (samples[0] + samples[40]) / 2.0);
    assert!(
        bent_towards.dot(&(w.frame * Vec3::x())) < 0.0,
        "ends bend towards +x, the middle stays behind"
    );
}

#[test]
fn jacobian_determinant_matches_finite_differences_in_any_frame() {
    let w = general_warp();
    let h = 1e-4;
    for p in [Vec3::new(3.0, -4.0, 11.0), Vec3::new(18.0, 0.0, 30.0)] {
        let column = |axis: usize| {
            let e = Vec3::ith(axis, h);
            (w.apply(&(p + e)) - w.apply(&(p - e))) / (2.0 * h)
        };
        let jac = Matrix3::from_columns(&[column(0), column(1), column(2)]);
        let expected = w.jacobian_determinant(&p);
        assert!(
            (jac.determinant() - expected).abs() < 1e-7 * expected.abs(),
            "{p:?}"
        );
        assert!(
            (expected - w.linear.determinant()).abs() > 1e-3,
            "the bend changes volume here"
        );
    }
}

#[test]
fn principal_axes_of_a_rotated_box_recover_its_frame() {
    let rotation = Rotation3::from_euler_angles(0.3, -0.7, 1.1);
    let centre = Vec3::new(100.0, 50.0, -20.0);
    // A box of 4 × 20 × 40 mm (x thin, z long), grid of points, shifted by its centre.
    let mut points = Vec::new();
    for i in 0..=2 {
        for j in 0..=10 {
            for k in 0..=20 {
                let local = Vec3::new(
                    2.0 * i as f64 - 2.0,
                    2.0 * j as f64 - 10.0,
                    2.0 * k as f64 - 20.0,
                );
                points.push(centre + rotation * local);
            }
        }
    }
    let axes = PrincipalAxes::of(&points).unwrap();
    let f = axes.frame.matrix();
    assert!((f.transpose() * f - Matrix3::identity()).norm() < 1e-12);
    assert!((f.determinant() - 1.0).abs() < 1e-12, "right-handed");
    for (k, expected) in [(0, Vec3::x()), (2, Vec3::z())] {
        let cos = f.column(k).dot(&(rotation * expected));
        assert!((cos.abs() - 1.0).abs() < 1e-10, "axis {k}: {cos}");
    }
    assert!(
        (axes.extent - Vec3::new(4.0, 20.0, 40.0)).norm() < 1e-9,
        "{:?}",
        axes.extent
    );
    assert!((axes.centre - centre).norm() < 1e-9);
    assert!(axes.std_dev.x < axes.std_dev.y && axes.std_dev.y < axes.std_dev.z);
    // Bad input.
    assert!(matches!(
        PrincipalAxes::of(&[]),
        Err(Error::InvalidParameter(_))
    ));
    assert!(matches!(
        PrincipalAxes::of(&[centre; 5]),
        Err(Error::InvalidParameter(_))
    ));
    assert!(matches!(
        PrincipalAxes::of(&[centre, Vec3::new(f64::NAN, 0.0, 0.0)]),
        Err(Error::NonFinite(_))
    ));
}

#[test]
fn bending_a_template_sets_angles_from_its_extent_and_keeps_the_affine_part() {
    let t = t001();
    let axes = PrincipalAxes::of(t.boundary_points()).unwrap();
    let f = axes.frame.matrix();
    assert!((f.transpose() * f - Matrix3::identity()).norm() < 1e-12);
    assert!((f.determinant() - 1.0).abs() < 1e-12);
    let affine = similarity(axes.centre, 5.0, 1.03, Vec3::new(1.0, 0.0, 0.0));
    let w = Warp::bending(&axes, 25.0, 10.0, &affine).unwrap();
    println!(
        "t001: extent {:.2?} mm, std {:.2?} mm, centre {:.2?}; κ = {:.5}/mm (ρ = {:.1} mm), τ = {:.5} rad/mm",
        axes.extent.as_slice(),
        axes.std_dev.as_slice(),
        axes.centre.as_slice(),
        w.bend,
        1.0 / w.bend,
        w.twist
    );
    assert!((w.bend * axes.extent.z - 25f64.to_radians()).abs() < 1e-12);
    assert!((w.twist * axes.extent.z - 10f64.to_radians()).abs() < 1e-12);
    assert!(
        (w.affine() - affine).norm() < 1e-12,
        "the affine part is the one given"
    );
    w.check_invertible_on(t.landmarks()).unwrap();
    // The long axis turns by the bend angle end to end: the local z of the points spans ±L/2.
    let zs: Vec<f64> = t.boundary_points().iter().map(|p| w.local(p).z).collect();
    let (lo, hi) = zs
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &z| (a.min(z), b.max(z)));
    assert!((lo + axes.extent.z / 2.0).abs() < 1e-9 && (hi - axes.extent.z / 2.0).abs() < 1e-9);
    // Refused: reflections, singular or non-affine matrices, non-finite or wrapping angles.
    let mut reflection = affine;
    reflection[(0, 0)] *= -1.0;
    let mut projective = affine;
    projective[(3, 0)] = 0.1;
    for bad in [reflection, Matrix4::zeros(), projective] {
        assert!(matches!(
            w.with_affine(&bad),
            Err(Error::InvalidParameter(_))
        ));
    }
    for (bend, twist) in [
        (f64::NAN, 0.0),
        (0.0, f64::INFINITY),
        (360.0, 0.0),
        (-400.0, 0.0),
    ] {
        assert!(matches!(
            Warp::bending(&axes, bend, twist, &affine),
            Err(Error::InvalidParameter(_))
        ));
    }
}

/// `κ x ≥ 1` somewhere: the bend folds the shape, and the targets are refused by name.
#[test]
fn a_bend_that_folds_the_shape_is_refused() {
    let t = t001();
    let axes = PrincipalAxes::of(t.boundary_points()).unwrap();
    let boundary = t.boundary_mesh().unwrap();
    // Curvature radius smaller than the half-thickness of the shape: κx > 1 on one side.
    let w = Warp {
        bend: 2.0 / axes.extent.x,
        ..Warp::bending(&axes, 0.0, 0.0, &Matrix4::identity()).unwrap()
    };
    let message = target_boundary(&boundary, &w).unwrap_err().to_string();
    assert!(
        message.contains("not invertible") && message.contains("κx"),
        "{message}"
    );
    assert!(target_surface(&boundary, &w).is_err());
}

/// Rotation by `degrees` about `(1, 1, 1)/√3` and scaling by `scale` about `centre`, then a
/// shift: a 4×4 world matrix.
fn similarity(centre: Vec3, degrees: f64, scale: f64, shift: Vec3) -> Matrix4<f64> {
    let linear = Rotation3::from_axis_angle(
        &Unit::new_normalize(Vec3::new(1.0, 1.0, 1.0)),
        degrees.to_radians(),
    )
    .matrix()
        * scale;
    let mut m = linear.to_homogeneous();
    m.fixed_view_mut::<3, 1>(0, 3)
        .copy_from(&(centre + shift - linear * centre));
    m
}

/// t001 as a synthetic case: the targets are the warped boundary, and bend and twist keep the
/// volume to within `1 − κ x̄` (x̄ the centroid's local x, about 1 % here).
#[test]
fn a_template_becomes_a_synthetic_case() {
    let t = t001();
    let boundary = t.boundary_mesh().unwrap();
    let axes = PrincipalAxes::of(boundary.points()).unwrap();
    let affine = similarity(axes.centre, 5.0, 1.03, Vec3::new(1.0, 0.0, 0.0));
    let w = Warp::bending(&axes, 25.0, 10.0, &affine).unwrap();
    let target = target_boundary(&boundary, &w).unwrap();
    assert_eq!(target.triangles(), boundary.triangles());
    for (p, q) in boundary.points().iter().zip(target.points()) {
        assert!((w.apply(p) - q).norm() < 1e-12);
        assert!((w.inverse(q).unwrap() - p).norm() < 1e-9);
    }
    let surface = target_surface(&boundary, &w).unwrap();
    let det = w.linear.determinant();
    let v0 = volume(&boundary);
    let expected = w.jacobian_determinant(&centroid(&boundary)) * v0;
    let (vs, ratio) = (volume(&surface), volume(&surface) / expected);
    println!(
        "t001 warped: volume {v0:.1} mm³ → {vs:.1} mm³ (det A = {det:.4}, ratio to det Dφ(centroid)·V {ratio:.4})"
    );
    assert!((ratio - 1.0).abs() < 0.01, "{ratio}");
    assert!((vs / (det * v0) - 1.0).abs() < 0.03, "{}", vs / (det * v0));
    let image = target_image(&target_surface(&boundary, &w).unwrap(), 0.5, 2.0).unwrap();
    let raster = image.integral();
    println!(
        "t001 target image {:?}, volume {raster:.1} mm³",
        image.dims()
    );
    assert!((raster / vs - 1.0).abs() < 0.05, "{raster} vs {vs}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn the_inverse_undoes_the_general_warp(x in -30.0..30.0f64, y in -30.0..30.0f64, z in -30.0..30.0f64) {
        let w = general_warp();
        let p = w.centre + Vec3::new(x, y, z);
        let back = w.inverse(&w.apply(&p)).expect("invertible");
        prop_assert!((back - p).norm() < 1e-9, "{p:?} → {back:?}");
    }
}
