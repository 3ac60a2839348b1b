//! Per-triangle and per-vertex geometry of a medial sheet: normals, corner angles, the surface
//! gradient of the radius, degenerate triangles.

use super::MedialSheet;
use crate::Vec3;

/// A triangle counts as degenerate when `|e₁ × e₂| ≤ DEGENERATE · (longest edge)²`.
pub(super) const DEGENERATE: f64 = 1e-12;

/// Per-triangle and per-vertex geometry of a sheet.
pub(super) struct SheetGeometry {
    /// Unit normal `(p₁ − p₀) × (p₂ − p₀) / |…|` of every triangle.
    pub(super) normal: Vec<Vec3>,
    /// The interior angle at every corner (radians).
    pub(super) angle: Vec<[f64; 3]>,
    /// The surface gradient of the radius at every vertex: the area-weighted mean of the
    /// gradients of the linear interpolant on its triangles.
    pub(super) gradient: Vec<Vec3>,
}

impl SheetGeometry {
    /// The geometry of `sheet` with the radii `radius` (one per point) in place of its own.
    pub(super) fn new(sheet: &MedialSheet, radius: &[f64]) -> Self {
        let n = sheet.points().len();
        let mut gradient = vec![Vec3::zeros(); n];
        let mut weight = vec![0.0; n];
        let mut normal = Vec::with_capacity(sheet.triangles().len());
        let mut angle = Vec::with_capacity(sheet.triangles().len());
        for tri in sheet.triangles() {
            let p = corners(sheet.points(), tri);
            let r = tri.map(|v| radius[v]);
            let cross = (p[1] - p[0]).cross(&(p[2] - p[0]));
            let area = 0.5 * cross.norm();
            let g = triangle_gradient(&p, &r);
            for &v in tri {
                gradient[v] += area * g;
                weight[v] += area;
            }
            normal.push(cross / (2.0 * area));
            angle.push(corner_angles(&p));
        }
        gradient.iter_mut().zip(&weight).for_each(|(g, w)| *g /= *w);
        Self {
            normal,
            angle,
            gradient,
        }
    }
}

/// The gradient of the linear interpolant of values `r` on triangle `p`:
/// `∇r = Σᵢ rᵢ n̂ × (p_{i+2} − p_{i+1}) / (2A)`.
pub(super) fn triangle_gradient(p: &[Vec3; 3], r: &[f64; 3]) -> Vec3 {
    let cross = (p[1] - p[0]).cross(&(p[2] - p[0]));
    let n2a = cross / cross.norm_squared(); // n̂ / (2A)
    (0..3)
        .map(|i| r[i] * n2a.cross(&(p[(i + 2) % 3] - p[(i + 1) % 3])))
        .sum()
}

pub(super) fn corner_angles(p: &[Vec3; 3]) -> [f64; 3] {
    std::array::from_fn(|i| (p[(i + 1) % 3] - p[i]).angle(&(p[(i + 2) % 3] - p[i])))
}

pub(super) fn corners(points: &[Vec3], tri: &[usize; 3]) -> [Vec3; 3] {
    tri.map(|v| points[v])
}

pub(super) fn is_degenerate(p: &[Vec3; 3]) -> bool {
    let longest = (0..3)
        .map(|i| (p[(i + 1) % 3] - p[i]).norm_squared())
        .fold(0.0, f64::max);
    (p[1] - p[0]).cross(&(p[2] - p[0])).norm() <= DEGENERATE * longest
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangle_gradient_matches_finite_differences() {
        let p = [
            Vec3::new(0.3, -0.2, 0.1),
            Vec3::new(2.1, 0.4, -0.5),
            Vec3::new(0.7, 1.9, 0.8),
        ];
        let r = [1.2, 0.7, 2.3];
        let g = triangle_gradient(&p, &r);
        // The linear interpolant at barycentric coordinates (1 − s − t, s, t).
        let point = |s: f64, t: f64| p[0] + s * (p[1] - p[0]) + t * (p[2] - p[0]);
        let value = |s: f64, t: f64| r[0] + s * (r[1] - r[0]) + t * (r[2] - r[0]);
        let h = 1e-6;
        for (ds, dt) in [(1.0, 0.0), (0.0, 1.0), (0.6, -0.3)] {
            let fd =
                (value(0.3 + h * ds, 0.3 + h * dt) - value(0.3 - h * ds, 0.3 - h * dt)) / (2.0 * h);
            let step =
                (point(0.3 + h * ds, 0.3 + h * dt) - point(0.3 - h * ds, 0.3 - h * dt)) / (2.0 * h);
            assert!(
                (g.dot(&step) - fd).abs() < 1e-8,
                "direction ({ds}, {dt}): {} vs {fd}",
                g.dot(&step)
            );
        }
        let n = (p[1] - p[0]).cross(&(p[2] - p[0]));
        assert!(
            g.dot(&n).abs() < 1e-12 * n.norm(),
            "the gradient lies in the plane"
        );
    }
}
