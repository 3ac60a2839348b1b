//! A real heart surface of any size: the end-diastolic endocardium and epicardium of the
//! CAP left-ventricle mean shape (`shared/data/cap_lv`, 841 points each on the same 1,595
//! triangles), subdivided at edge midpoints (Loop subdivision, as the
//! core's medial sheets have it, refuses the degenerate triangles of these surfaces), and a smooth field of momenta on its points.

use medial::mesh::subdivide::midpoint_subdivide;
use medial::{TriMesh, Vec3};
use std::path::Path;

/// Points per surface in `mean_shape.csv`.
const SURFACE_POINTS: usize = 841;

/// The points of both ED surfaces after `levels` midpoint subdivisions (841 each at level 0,
/// 3,276 at level 1, 12,931 at level 2).
pub fn heart_points(levels: usize) -> Vec<Vec3> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/cap_lv");
    let read = |name: &str| std::fs::read_to_string(dir.join(name)).expect("cap_lv data");
    let numbers: Vec<f64> = (read("mean_shape.csv").lines())
        .map(|l| l.trim().parse().expect("a coordinate"))
        .collect();
    let triangles: Vec<[usize; 3]> = (read("surface_face.csv").lines())
        .map(|l| {
            let c: Vec<usize> = l
                .split(',')
                .map(|c| c.trim().parse().expect("a corner"))
                .collect();
            [c[0] - 1, c[1] - 1, c[2] - 1]
        })
        .collect();
    (0..2)
        .flat_map(|surface| {
            let points: Vec<Vec3> = (0..SURFACE_POINTS)
                .map(|i| {
                    Vec3::from_column_slice(&numbers[3 * (surface * SURFACE_POINTS + i)..][..3])
                })
                .collect();
            let mut mesh = TriMesh::new(points, triangles.clone()).expect("a surface");
            for _ in 0..levels {
                mesh = midpoint_subdivide(&mesh).expect("a subdivision");
            }
            mesh.points().to_vec()
        })
        .collect()
}

/// Smooth momenta for `steps` steps: every point pushed along a slowly varying field (mm).
pub fn smooth_momenta(q: &[Vec3], steps: usize) -> Vec<f64> {
    (0..steps)
        .flat_map(|n| {
            q.iter()
                .flat_map(move |p| [(0.1 * p.y).sin(), (0.1 * p.z + n as f64 * 0.01).cos(), 0.3])
        })
        .collect()
}
