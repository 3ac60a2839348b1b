//! Medial sheets recovered from shapes with a known medial sheet: the synthetic cup, its
//! template rasterized (the template's own medial points and spokes are the truth).

use medial::build::{sheet_of_mask, Sampling};
use medial::image::rasterize::{grid_around, rasterize};
use medial::model::{MedialTemplate, SpokeMetrics};
use medial::synth::{boundary_mesh, Shape, SyntheticCase};
use medial::Vec3;

/// Voxel of the rasterized shapes, mm.
const VOXEL: f64 = 0.4;

/// The closest point of triangle `abc` to `p` and its barycentric weights (Ericson, Real-Time
/// Collision Detection, 5.1.5).
fn closest_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> (Vec3, [f64; 3]) {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, [1.0, 0.0, 0.0]);
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + v * ab, [1.0 - v, v, 0.0]);
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + w * ac, [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + w * (c - b), [0.0, 1.0 - w, w]);
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    (a + v * ab + w * ac, [1.0 - v - w, v, w])
}

/// Distance from `p` to the template's medial sheet and the radius (mean spoke) there.
fn to_sheet(template: &MedialTemplate, radius: &[f64], p: Vec3) -> (f64, f64) {
    let m = template.medial_points();
    template
        .medial_triangles()
        .iter()
        .map(|t| {
            let (q, w) = closest_on_triangle(p, m[t[0]], m[t[1]], m[t[2]]);
            let r = w[0] * radius[t[0]] + w[1] * radius[t[1]] + w[2] * radius[t[2]];
            ((p - q).norm(), r)
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .expect("a sheet has triangles")
}

/// Recovers the sheet of a synthetic shape's own template; returns per vertex inside the
/// recovered sheet (off its free edge: the rasterized rim is a polyhedral wedge whose medial
/// axis thins to its tip, not the rounded rim the spokes describe) the distance to the true
/// sheet and the radius error.
fn recovered(shape: Shape) -> Vec<(f64, f64)> {
    let case = SyntheticCase::build(shape).unwrap();
    let template = &case.projection.template;
    let boundary = boundary_mesh(template).unwrap();
    let (dims, to_world) = grid_around(&boundary, VOXEL, 3.0 * VOXEL).unwrap();
    let mask = rasterize(&boundary, dims, to_world).unwrap();
    let found = sheet_of_mask(&mask, Sampling::Atoms(300)).unwrap();
    let metrics = SpokeMetrics::compute(template, template.landmarks());
    let radius: Vec<f64> = metrics.thickness.iter().map(|t| t / 2.0).collect();
    let border: std::collections::HashSet<usize> = found.border.iter().copied().collect();
    found
        .sheet
        .points()
        .iter()
        .zip(found.sheet.radius())
        .enumerate()
        .filter(|(k, _)| !border.contains(k))
        .map(|(_, (p, r))| {
            let (d, r_true) = to_sheet(template, &radius, *p);
            (d, r - r_true)
        })
        .collect()
}

#[test]
fn the_cup_sheet_is_recovered_within_half_a_voxel_on_average_and_its_radius_within_a_voxel() {
    let errors = recovered(Shape::Cup);
    let n = errors.len() as f64;
    let mean_d = errors.iter().map(|e| e.0).sum::<f64>() / n;
    let max_d = errors.iter().map(|e| e.0).fold(0.0, f64::max);
    let mean_r = errors.iter().map(|e| e.1).sum::<f64>() / n;
    let max_r = errors.iter().map(|e| e.1.abs()).fold(0.0, f64::max);
    eprintln!("cup: distance mean {mean_d:.3} max {max_d:.3}; radius error mean {mean_r:.3} max |{max_r:.3}|");
    assert!(
        mean_d <= VOXEL / 2.0,
        "sheet {mean_d} mm from the true one on average"
    );
    assert!(max_d <= VOXEL, "sheet {max_d} mm from the true one");
    assert!(max_r <= VOXEL, "radius off by {max_r} mm");
}
