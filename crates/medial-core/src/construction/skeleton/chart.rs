//! A chart of a single medial sheet: a map of its points to the plane, one-to-one for the
//! bowls (the heart wall, the cup) and the gently curved discs (placenta, leaflets) that
//! single-sheet anatomy is.

use nalgebra::{Matrix4, Vector4};

use crate::mesh::centroid_and_covariance;
use crate::mesh::Bounds;
use crate::{Error, Result, Vec3};

/// A sphere whose radius passes this many diagonals of the points is taken as a plane.
const FLAT_RADIUS: f64 = 10.0;

/// Which surface the chart projects from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ChartKind {
    /// Azimuthal equidistant projection of a sphere fitted to the sheet.
    Sphere,
    /// Orthogonal projection onto the sheet's principal plane.
    Plane,
}

/// A map from space to the plane (mm): the azimuthal equidistant projection
/// `q = R θ (t·e₁, t·e₂)/|t|` of the sphere of centre `c` and radius `R` fitted to the points
/// (`θ` the angle of `p − c` from the pole `a`, `t` its part normal to `a`), with the pole
/// towards the points' centroid (the apex of a bowl); or, for a flat sheet, the projection
/// `q = ((p − o)·e₁, (p − o)·e₂)` onto the plane of the two largest principal axes through the
/// centroid `o`. Both keep distances along the rays from the chart's centre `q = 0`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Chart {
    /// Sphere or plane.
    pub kind: ChartKind,
    /// Sphere centre `c`, or the plane's origin `o` (mm).
    pub centre: Vec3,
    /// Sphere radius `R` (mm); unused for a plane.
    pub radius: f64,
    /// Pole `a` (sphere) or normal (plane), unit.
    pub pole: Vec3,
    /// In-chart axes `e₁, e₂`, unit, normal to the pole and to each other.
    pub axes: [Vec3; 2],
}

impl Chart {
    /// The chart of `points` (see the type's documentation): the least-squares sphere
    /// `|p|² = 2 c·p + k` unless its radius passes `FLAT_RADIUS` diagonals of the points or
    /// the fit is singular, else the principal plane.
    ///
    /// Errors: `InvalidParameter` for fewer than three points or points on a line.
    pub fn fit(points: &[Vec3]) -> Result<Self> {
        let diagonal = Bounds::of(points).map_or(0.0, |b| b.diagonal());
        if points.len() < 3 || diagonal <= 0.0 {
            return Err(Error::InvalidParameter(
                "a chart needs at least three distinct medial points".into(),
            ));
        }
        let (centroid, covariance) = centroid_and_covariance(points);
        let eigen = covariance.symmetric_eigen();
        let mut order = [0, 1, 2];
        order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
        let axis = |k: usize| eigen.eigenvectors.column(order[k]).into_owned();
        if eigen.eigenvalues[order[1]] <= 1e-12 * eigen.eigenvalues[order[0]] {
            return Err(Error::InvalidParameter(
                "the medial points lie on a line: no sheet to chart".into(),
            ));
        }
        let normal = axis(0).cross(&axis(1)).normalize();
        let plane = Self {
            kind: ChartKind::Plane,
            centre: centroid,
            radius: f64::INFINITY,
            pole: normal,
            axes: [axis(0), normal.cross(&axis(0))],
        };
        Ok(match fit_sphere(points, centroid) {
            Some((centre, radius)) if radius < FLAT_RADIUS * diagonal => {
                let pole = (centroid - centre).try_normalize(1e-12).unwrap_or(normal);
                let e1 = (axis(0) - axis(0).dot(&pole) * pole)
                    .try_normalize(1e-9)
                    .unwrap_or_else(|| (axis(1) - axis(1).dot(&pole) * pole).normalize());
                Self {
                    kind: ChartKind::Sphere,
                    centre,
                    radius,
                    pole,
                    axes: [e1, pole.cross(&e1)],
                }
            }
            _ => plane,
        })
    }

    /// The chart coordinates of `p` (mm).
    pub fn coords(&self, p: &Vec3) -> [f64; 2] {
        let d = p - self.centre;
        match self.kind {
            ChartKind::Plane => [d.dot(&self.axes[0]), d.dot(&self.axes[1])],
            ChartKind::Sphere => {
                let along = d.dot(&self.pole);
                let t = d - along * self.pole;
                let theta = t.norm().atan2(along);
                if t.norm() <= 1e-12 * d.norm() {
                    return [0.0, 0.0];
                }
                let scale = self.radius * theta / t.norm();
                [scale * t.dot(&self.axes[0]), scale * t.dot(&self.axes[1])]
            }
        }
    }
}

impl Chart {
    /// The angle `θ = |q|/R` from the pole of chart coordinates `q` (radians; 0 on a plane):
    /// the chart stretches lengths across its rays by `θ/sin θ` there.
    pub fn angle(&self, q: [f64; 2]) -> f64 {
        match self.kind {
            ChartKind::Plane => 0.0,
            ChartKind::Sphere => q[0].hypot(q[1]) / self.radius,
        }
    }

    /// The point of the chart's surface (sphere or plane) at chart coordinates `q` (mm): the
    /// inverse of [`Chart::coords`] on it, `c + R (cos θ a + sin θ (q₁e₁ + q₂e₂)/|q|)` with
    /// `θ = |q|/R` for a sphere.
    pub fn on_surface(&self, q: [f64; 2]) -> Vec3 {
        let [e1, e2] = self.axes;
        match self.kind {
            ChartKind::Plane => self.centre + q[0] * e1 + q[1] * e2,
            ChartKind::Sphere => {
                let r = q[0].hypot(q[1]);
                let theta = r / self.radius;
                let along = if r > 0.0 {
                    (q[0] * e1 + q[1] * e2) / r
                } else {
                    e1
                };
                self.centre + self.radius * (theta.cos() * self.pole + theta.sin() * along)
            }
        }
    }
}

/// The least-squares sphere through `points` (centre, radius), solving the normal equations of
/// `|p − o|² = 2 c'·(p − o) + k` about `o` for `c'`, `k`; `None` when they are singular.
fn fit_sphere(points: &[Vec3], origin: Vec3) -> Option<(Vec3, f64)> {
    let mut ata = Matrix4::<f64>::zeros();
    let mut atb = Vector4::<f64>::zeros();
    for p in points {
        let d = p - origin;
        let row = Vector4::new(2.0 * d.x, 2.0 * d.y, 2.0 * d.z, 1.0);
        ata += row * row.transpose();
        atb += row * d.norm_squared();
    }
    let x = ata.lu().solve(&atb)?;
    let c = Vec3::new(x[0], x[1], x[2]);
    let r2 = x[3] + c.norm_squared();
    (r2 > 0.0 && r2.is_finite()).then(|| (origin + c, r2.sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cap_of_a_sphere_gets_the_sphere_and_keeps_arc_lengths() {
        let (c, r) = (Vec3::new(1.0, 2.0, 3.0), 10.0);
        let points: Vec<Vec3> = (0..200)
            .map(|n| {
                let (theta, phi) = (1.2 * (n % 10) as f64 / 9.0, 0.7 * (n / 10) as f64);
                c + r * Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    theta.cos(),
                )
            })
            .collect();
        let chart = Chart::fit(&points).unwrap();
        assert_eq!(chart.kind, ChartKind::Sphere);
        assert!((chart.radius - r).abs() < 1e-9 && (chart.centre - c).norm() < 1e-9);
        // Distances from the pole along a meridian are arc lengths.
        let pole_point = c + r * chart.pole;
        let q = chart.coords(&pole_point);
        assert!(q[0].hypot(q[1]) < 1e-9);
        // on_surface inverts coords on the sphere.
        for p in &points[1..] {
            assert!((chart.on_surface(chart.coords(p)) - p).norm() < 1e-9, "{p}");
        }
    }

    #[test]
    fn a_flat_disc_gets_its_plane() {
        let points: Vec<Vec3> = (0..100)
            .map(|n| Vec3::new((n % 10) as f64, (n / 10) as f64, 0.0))
            .collect();
        let chart = Chart::fit(&points).unwrap();
        assert_eq!(chart.kind, ChartKind::Plane);
        let p = Vec3::new(9.0, 9.0, 0.0);
        let q = chart.coords(&p);
        assert!((q[0].hypot(q[1]) - 4.5 * 2f64.sqrt()).abs() < 1e-9);
        assert!((chart.on_surface(q) - p).norm() < 1e-9);
    }
}
