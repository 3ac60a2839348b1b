//! `attachment = "varifold"` through the built binary: cmrep's t001 template fitted to a
//! surface without correspondence — the boundary of the shipped t001-bent case (t001 under a
//! known bend, twist and affine map), midpoint subdivided, its vertices and triangles shuffled,
//! written as OBJ. The fit must approach the surface and keep the model medial.

use crate::common::{medial, s, text};
use medial_core::mesh::subdivide::midpoint_subdivide;
use medial_core::{TriMesh, Vec3};
use std::path::Path;

/// Mean distance from each of `points` to the nearest vertex of `surface` (an upper bound of
/// the distance to the surface, close to it on a finely subdivided one), mm.
fn mean_nearest(points: &[Vec3], surface: &[Vec3]) -> f64 {
    let nearest = |p: &Vec3| {
        surface
            .iter()
            .map(|v| (v - p).norm())
            .fold(f64::INFINITY, f64::min)
    };
    points.iter().map(nearest).sum::<f64>() / points.len() as f64
}

/// `mesh` with its vertices and triangles in a scrambled order (a fixed permutation).
fn shuffled(mesh: &TriMesh) -> TriMesh {
    let n = mesh.points().len();
    let step = (1..n)
        .rev()
        .find(|s| gcd(*s, n) == 1 && *s > n / 3)
        .unwrap();
    let new_of: Vec<usize> = (0..n).map(|i| (i * step + 7) % n).collect();
    let mut points = vec![Vec3::zeros(); n];
    for (old, &new) in new_of.iter().enumerate() {
        points[new] = mesh.points()[old];
    }
    let mut triangles: Vec<[usize; 3]> = mesh
        .triangles()
        .iter()
        .map(|t| [new_of[t[1]], new_of[t[2]], new_of[t[0]]])
        .collect();
    triangles.reverse();
    TriMesh::new(points, triangles).unwrap()
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

#[test]
fn a_template_follows_a_shuffled_remeshed_surface_and_stays_medial() {
    let dir = tempfile::tempdir().unwrap();
    let case = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/t001-bent");
    let target = medial_io::mesh::read_mesh(&case.join("target_boundary.vtk")).unwrap();
    let surface = shuffled(&midpoint_subdivide(&target).unwrap());
    let obj = dir.path().join("surface.obj");
    medial_io::mesh::write_mesh(&obj, &surface).unwrap();
    let config = dir.path().join("fit.toml");
    std::fs::write(
        &config,
        format!(
            r#"
[model]
template = "{}"
[flow]
sigma = 1.41
time_steps = 20
kinetic_weight = 0.005
[[stage]]
name = "surface"
attachment = "varifold"
surface = "surface.obj"
constraint_units = "relative"
mu = 20.0
al_iterations = 2
max_iterations = 150
"#,
            case.join("template.vtk").display()
        ),
    )
    .unwrap();
    let out = dir.path().join("out");
    let o = medial(&["fit", s(&config), "--out", s(&out), "-q"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let boundary = |n: usize| {
        medial_io::vtk::read_polydata(&out.join(format!("flow/boundary_t{n:03}.vtk")))
            .unwrap()
            .points
    };
    let (before, after) = (
        mean_nearest(&boundary(0), surface.points()),
        mean_nearest(&boundary(20), surface.points()),
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    println!(
        "varifold fit: {before:.3} → {after:.3} mm, {}",
        summary["final"]
    );
    assert!(after < 0.5 * before, "{before} → {after}");
    assert_eq!(summary["stages"][0]["constraints_met"], true);
}
