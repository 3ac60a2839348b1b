//! Small closed meshes and templates with known properties, for tests and examples.

use crate::mesh::TriMesh;
use crate::model::MedialTemplate;
use crate::Vec3;

/// The regular octahedron with corners `+x, −x, +y, −y, +z, −z` (points 0–5, unit distance from
/// the origin) and 8 triangles oriented outward: a closed manifold whose every vertex has
/// valence 4, enclosing the volume 4/3.
pub fn octahedron() -> (Vec<Vec3>, Vec<[usize; 3]>) {
    let points = vec![
        Vec3::x(),
        -Vec3::x(),
        Vec3::y(),
        -Vec3::y(),
        Vec3::z(),
        -Vec3::z(),
    ];
    let triangles = vec![
        [0, 2, 4],
        [2, 1, 4],
        [1, 3, 4],
        [3, 0, 4],
        [2, 0, 5],
        [1, 2, 5],
        [3, 1, 5],
        [0, 3, 5],
    ];
    (points, triangles)
}

/// A flat hexagonal medial sheet of radius 1 at z = 0 with a centre atom (two spokes, ±z at
/// distance `r`) and six rim atoms (one spoke each, radially outward at distance `r`).
/// Boundary: a hexagonal bipyramid, 8 points, 12 triangles. Exactly medial for any `r > 0`.
pub fn bipyramid(r: f64) -> MedialTemplate {
    let rim = |i: usize| {
        let a = std::f64::consts::TAU * i as f64 / 6.0;
        Vec3::new(a.cos(), a.sin(), 0.0)
    };
    let mut boundary = vec![Vec3::new(0.0, 0.0, r), Vec3::new(0.0, 0.0, -r)];
    boundary.extend((0..6).map(|i| rim(i) * (1.0 + r)));
    let mut triangles = Vec::new();
    for i in 0..6 {
        let (a, b) = (2 + i, 2 + (i + 1) % 6);
        triangles.push([0, a, b]);
        triangles.push([1, b, a]);
    }
    let mut medial = vec![Vec3::zeros()];
    medial.extend((0..6).map(rim));
    let index = vec![0, 0, 1, 2, 3, 4, 5, 6];
    let mesh = TriMesh::new(boundary, triangles).expect("a valid mesh");
    MedialTemplate::new(mesh, index, medial).expect("a valid template")
}
