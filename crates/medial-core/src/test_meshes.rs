//! Small closed meshes shared by tests: the unit tests of this crate (declared
//! `#[cfg(test)] mod test_meshes` in `lib.rs`) and the integration tests in `tests/`, which
//! include this file with `#[path = "../src/test_meshes.rs"] mod test_meshes;`. It therefore
//! names nalgebra's `Vector3<f64>` (the crate's `Vec3`) rather than any `crate::` path.

use nalgebra::Vector3;

/// The regular octahedron with corners `+x, −x, +y, −y, +z, −z` (points 0–5, unit distance from
/// the origin) and 8 triangles oriented outward: a closed manifold whose every vertex has
/// valence 4, enclosing the volume 4/3.
pub fn octahedron() -> (Vec<Vector3<f64>>, Vec<[usize; 3]>) {
    let points = vec![
        Vector3::x(),
        -Vector3::x(),
        Vector3::y(),
        -Vector3::y(),
        Vector3::z(),
        -Vector3::z(),
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
