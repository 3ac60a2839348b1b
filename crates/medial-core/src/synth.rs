//! Synthetic test cases with a known answer: a medial template built from an analytic medial
//! sheet, and a target that is the template's shape carried by a known smooth diffeomorphism.
//!
//! Shapes (all lengths in mm):
//!
//! - [`Shape::Cup`]: an LV-like cup. The medial sheet is the cap `θ ≤ θ_max` of the prolate
//!   spheroid `(a sin θ cos φ, a sin θ sin φ, −c cos θ)` (`a` = [`CUP_EQUATOR`], `c` =
//!   [`CUP_LENGTH`], `θ_max` = [`CUP_OPENING`]), open at the base (a free edge), with half
//!   thickness `r = r_apex + (r_base − r_apex + r_septum cos φ) θ/θ_max`: thin at the apex,
//!   thick at the base, thicker on one side.
//! - [`Shape::Toy`]: the paper's toy, three sheets of width [`TOY_WIDTH`] meeting at 120°
//!   along one straight seam of length [`TOY_LENGTH`] on the z axis, each curled a little
//!   (a point at distance `w` from the seam is lifted by `TOY_CURL · w²` along the sheet's
//!   in-plane normal), with half thickness `r = TOY_RADIUS (1 − 0.3 w/W)(1 − 0.2 (2z/L)²)`.
//!
//! A case is built as a template would be from a real sheet: the coarse sheet is Loop
//! subdivided once, inflated and projected onto the medial constraints
//! ([`crate::project::project`]). The target is the template boundary, midpoint subdivided
//! [`TARGET_SUBDIVISIONS`] times (so that the smooth warp bends its triangles), carried by the
//! case's [`Warp`]: a twist and a bend about the shape's long axis (z) followed by an affine map.

use crate::inflate::{inflate, MedialSheet};
use crate::project::{project, ProjectOptions, Projection};
use crate::rasterize::{grid_around, rasterize};
use crate::template::MedialTemplate;
use crate::volume::Volume;
use crate::{Error, Result, TriMesh, Vec3};
use nalgebra::{Matrix3, Matrix4, Rotation3, Unit};
use std::collections::HashMap;
use std::f64::consts::{PI, TAU};

/// Cup: equatorial semi-axis `a` of the medial spheroid, mm.
pub const CUP_EQUATOR: f64 = 20.0;
/// Cup: polar semi-axis `c` of the medial spheroid (apex at `z = −c`), mm.
pub const CUP_LENGTH: f64 = 32.0;
/// Cup: polar angle `θ_max` of the free edge (the base), radians (105°).
pub const CUP_OPENING: f64 = 105.0 * PI / 180.0;
/// Cup: rings of the coarse medial mesh (ring `i` has `6i` points).
pub const CUP_RINGS: usize = 4;
/// Cup: half thickness at the apex, mm.
pub const CUP_RADIUS_APEX: f64 = 2.0;
/// Cup: half thickness at the base, mm.
pub const CUP_RADIUS_BASE: f64 = 3.5;
/// Cup: amplitude of the `cos φ` variation of the half thickness, mm.
pub const CUP_RADIUS_SEPTUM: f64 = 0.5;

/// Toy: width `W` of each sheet (distance from the seam to its free edge), mm.
pub const TOY_WIDTH: f64 = 12.0;
/// Toy: seam length `L`, mm (the seam runs from `z = −L/2` to `L/2`).
pub const TOY_LENGTH: f64 = 24.0;
/// Toy: half thickness on the middle of the seam, mm.
pub const TOY_RADIUS: f64 = 3.5;
/// Toy: curl of the sheets, 1/mm.
pub const TOY_CURL: f64 = 0.02;
/// Toy: cells of each coarse sheet across (from the seam) and along the seam (both even).
pub const TOY_CELLS: [usize; 2] = [2, 4];

/// Loop subdivisions of the coarse sheet before inflation.
pub const SHEET_SUBDIVISIONS: usize = 1;
/// Midpoint subdivisions of the template boundary before it is warped into the target.
pub const TARGET_SUBDIVISIONS: usize = 2;

/// A synthetic shape.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    /// An LV-like cup: one curved sheet with a free edge and varying thickness.
    Cup,
    /// The paper's toy: three sheets meeting along one seam.
    Toy,
}

impl Shape {
    /// Every shape.
    pub const ALL: [Shape; 2] = [Shape::Cup, Shape::Toy];

    /// The name used on the command line: `"cup"` or `"toy"`.
    pub fn name(self) -> &'static str {
        match self {
            Shape::Cup => "cup",
            Shape::Toy => "toy",
        }
    }

    /// The shape called `name` (case-insensitive); `InvalidParameter` listing the names
    /// otherwise.
    pub fn from_name(name: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|s| s.name().eq_ignore_ascii_case(name))
            .ok_or_else(|| {
                let names: Vec<&str> = Self::ALL.iter().map(|s| s.name()).collect();
                Error::InvalidParameter(format!(
                    "unknown synthetic case '{name}'; the cases are: {}",
                    names.join(", ")
                ))
            })
    }

    /// The coarse medial sheet with its radius (before subdivision).
    pub fn coarse_sheet(self) -> Result<MedialSheet> {
        match self {
            Shape::Cup => cup_sheet(),
            Shape::Toy => toy_sheet(),
        }
    }

    /// The known diffeomorphism that makes the target, about the centre `centre` of the
    /// template (mm).
    pub fn warp(self, centre: Vec3) -> Warp {
        let (axis, angle_deg, scale, translation, twist_deg, bend_radius): (
            Vec3,
            f64,
            [f64; 3],
            Vec3,
            f64,
            f64,
        ) = match self {
            Shape::Cup => (
                Vec3::new(0.0, 1.0, 1.0),
                8.0,
                [1.04, 0.98, 1.06],
                Vec3::new(-2.0, 1.0, 1.5),
                15.0,
                80.0,
            ),
            Shape::Toy => (
                Vec3::new(1.0, 1.0, 0.0),
                10.0,
                [1.05, 0.97, 1.03],
                Vec3::new(1.5, -1.0, 2.0),
                20.0,
                50.0,
            ),
        };
        let length = match self {
            Shape::Cup => CUP_LENGTH * (1.0 - CUP_OPENING.cos()),
            Shape::Toy => TOY_LENGTH,
        };
        let rotation =
            Rotation3::from_axis_angle(&Unit::new_normalize(axis), angle_deg.to_radians());
        Warp {
            centre,
            twist: twist_deg.to_radians() / length,
            bend: 1.0 / bend_radius,
            linear: rotation.matrix() * Matrix3::from_diagonal(&Vec3::from(scale)),
            translation,
        }
    }

    /// Suggested voxel size of the target image, mm (about a sixth of the thinnest part).
    pub fn image_spacing_mm(self) -> f64 {
        0.5
    }
}

/// The known smooth diffeomorphism of a synthetic case,
///
/// ```text
/// φ(p) = c + t + A · B_κ(T_τ(p − c)),
/// ```
///
/// with `c` the centre, the twist `T_τ(x, y, z) = (R(τz)(x, y), z)` (`R(α)` the rotation of the
/// plane by `α`), the bend `B_κ` that rolls the z axis onto a circle of radius `ρ = 1/κ` in the
/// x–z plane,
///
/// ```text
/// B_κ(x, y, z) = (x cos θ + ρ (1 − cos θ), y, (ρ − x) sin θ),   θ = κ z,
/// ```
///
/// (arc length along the axis kept; Jacobian determinant `1 − κx`) and the affine map
/// `p ↦ A p + t`. `φ` is a diffeomorphism of the slab `κx < 1, |κz| < π` onto its image, with
/// the closed-form inverse [`Warp::inverse`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Warp {
    /// Centre `c` of the twist and bend, mm.
    pub centre: Vec3,
    /// Twist rate `τ` about the z axis, radians per mm.
    pub twist: f64,
    /// Curvature `κ` of the bent z axis, 1/mm (0: no bend).
    pub bend: f64,
    /// Linear part `A` of the affine map (invertible).
    pub linear: Matrix3<f64>,
    /// Translation `t` of the affine map, mm.
    pub translation: Vec3,
}

impl Warp {
    /// `φ(p)`, mm.
    pub fn apply(&self, p: &Vec3) -> Vec3 {
        let bent = bend(&twist(&(p - self.centre), self.twist), self.bend);
        self.centre + self.translation + self.linear * bent
    }

    /// `φ⁻¹(p)`, or `None` when `A` is singular or `p` is the image of no point (the axis of
    /// the bend).
    pub fn inverse(&self, p: &Vec3) -> Option<Vec3> {
        let bent = self.linear.try_inverse()? * (p - self.centre - self.translation);
        let twisted = unbend(&bent, self.bend)?;
        Some(self.centre + twist(&twisted, -self.twist))
    }

    /// The affine part `p ↦ A (p − c) + c + t` as a 4×4 matrix (last row `0 0 0 1`): the warp
    /// without twist and bend, the initialisation a registration would give.
    pub fn affine(&self) -> Matrix4<f64> {
        let mut m = self.linear.to_homogeneous();
        let offset = self.centre + self.translation - self.linear * self.centre;
        m.fixed_view_mut::<3, 1>(0, 3).copy_from(&offset);
        m
    }
}

/// `T_τ`: rotation of `(x, y)` by `τ z`.
fn twist(p: &Vec3, rate: f64) -> Vec3 {
    let (s, c) = (rate * p.z).sin_cos();
    Vec3::new(c * p.x - s * p.y, s * p.x + c * p.y, p.z)
}

/// `B_κ` (see [`Warp`]), written with `sin θ / θ` and `(1 − cos θ)/θ` so that `κ → 0` is exact.
fn bend(p: &Vec3, curvature: f64) -> Vec3 {
    let theta = curvature * p.z;
    let (s, c) = theta.sin_cos();
    let (sinc, versinc) = if theta.abs() < 1e-6 {
        (1.0 - theta * theta / 6.0, theta / 2.0)
    } else {
        (s / theta, (1.0 - c) / theta)
    };
    Vec3::new(p.x * c + p.z * versinc, p.y, p.z * sinc - p.x * s)
}

/// `B_κ⁻¹`: with `ρ = 1/κ`, `(ρ − x) = sign(κ)·|(ρ − x', z')|`, `θ = atan2` of the same, `z = θ/κ`.
fn unbend(p: &Vec3, curvature: f64) -> Option<Vec3> {
    if curvature == 0.0 {
        return Some(*p);
    }
    let rho = 1.0 / curvature;
    let sign = curvature.signum();
    let (u, v) = (rho - p.x, p.z);
    let distance = u.hypot(v);
    if distance == 0.0 {
        return None;
    }
    let theta = (sign * v).atan2(sign * u);
    Some(Vec3::new(rho - sign * distance, p.y, theta / curvature))
}

/// A synthetic case: its template (with the figures of its projection) and its warp.
#[derive(Clone, Debug)]
pub struct SyntheticCase {
    /// The shape.
    pub shape: Shape,
    /// The medial sheet the template was inflated from (after [`SHEET_SUBDIVISIONS`] Loop
    /// subdivisions).
    pub sheet: MedialSheet,
    /// The projection of the inflated template; its `template` is the case's template.
    pub projection: Projection,
    /// The known diffeomorphism from template to target.
    pub warp: Warp,
}

impl SyntheticCase {
    /// Builds `shape`: sheet, subdivision, inflation, projection (default tolerances), warp
    /// about the centre of the template's bounding box.
    ///
    /// Errors: those of [`inflate`], [`MedialTemplate::new`] and [`project`] (none for the
    /// shapes as defined; a test checks this).
    pub fn build(shape: Shape) -> Result<Self> {
        let mut sheet = shape.coarse_sheet()?;
        for _ in 0..SHEET_SUBDIVISIONS {
            sheet = sheet.loop_subdivide()?;
        }
        let inflated = inflate(&sheet)?;
        let template = MedialTemplate::new(
            inflated.boundary,
            inflated.medial_index,
            inflated.medial_points,
        )?;
        let projection = project(&template, &ProjectOptions::default())?;
        let centre = bounding_centre(projection.template.landmarks());
        Ok(Self {
            shape,
            sheet,
            warp: shape.warp(centre),
            projection,
        })
    }

    /// The template (projected onto the medial constraints).
    pub fn template(&self) -> &MedialTemplate {
        &self.projection.template
    }

    /// The template's boundary mesh.
    pub fn boundary(&self) -> Result<TriMesh> {
        let t = self.template();
        TriMesh::new(
            t.boundary_points().to_vec(),
            t.boundary_triangles().to_vec(),
        )
    }

    /// The warped template boundary, point for point (same triangles): an SSD target with
    /// known correspondence.
    pub fn target_boundary(&self) -> Result<TriMesh> {
        let (points, triangles) = self.boundary()?.into_parts();
        TriMesh::new(
            points.iter().map(|p| self.warp.apply(p)).collect(),
            triangles,
        )
    }

    /// The target surface: the template boundary midpoint subdivided [`TARGET_SUBDIVISIONS`]
    /// times, then warped.
    pub fn target_surface(&self) -> Result<TriMesh> {
        let mut mesh = self.boundary()?;
        for _ in 0..TARGET_SUBDIVISIONS {
            mesh = midpoint_subdivide(&mesh)?;
        }
        let (points, triangles) = mesh.into_parts();
        TriMesh::new(
            points.iter().map(|p| self.warp.apply(p)).collect(),
            triangles,
        )
    }

    /// The target segmentation: [`Self::target_surface`] rasterized (1 inside, 0 outside) on
    /// an axis-aligned grid of spacing `spacing_mm` around it with `margin_mm` on every side
    /// (see [`grid_around`]).
    pub fn target_image(&self, spacing_mm: f64, margin_mm: f64) -> Result<Volume> {
        let surface = self.target_surface()?;
        let (dims, voxel_to_world) = grid_around(&surface, spacing_mm, margin_mm)?;
        rasterize(&surface, dims, voxel_to_world)
    }
}

/// Splits every triangle `(a, b, c)` into `(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)`
/// with new points at edge midpoints (one per edge, numbered after the old points in order of
/// first appearance). Keeps orientation, closedness and the surface itself.
pub fn midpoint_subdivide(mesh: &TriMesh) -> Result<TriMesh> {
    let mut points = mesh.points().to_vec();
    let mut midpoints: HashMap<(usize, usize), usize> = HashMap::new();
    let mut mid = |a: usize, b: usize, points: &mut Vec<Vec3>| {
        *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
            points.push((points[a] + points[b]) / 2.0);
            points.len() - 1
        })
    };
    let mut triangles = Vec::with_capacity(4 * mesh.triangles().len());
    for &[a, b, c] in mesh.triangles() {
        let ab = mid(a, b, &mut points);
        let bc = mid(b, c, &mut points);
        let ca = mid(c, a, &mut points);
        triangles.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    TriMesh::new(points, triangles)
}

/// Centre of the axis-aligned bounding box of `points` (the origin for none).
fn bounding_centre(points: &[Vec3]) -> Vec3 {
    let Some(first) = points.first() else {
        return Vec3::zeros();
    };
    let (lo, hi) = points
        .iter()
        .fold((*first, *first), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
    (lo + hi) / 2.0
}

// ---------------------------------------------------------------------------------------------
// The cup

/// A disc of `rings` rings around a centre point: point 0 is the centre, ring `i` has `6i`
/// points at angles `2πj/(6i)`. Returns `(radial fraction i/rings, angle)` per point and the
/// triangles, counter-clockwise in the disc's plane. Consecutive rings are zipped in angular
/// order, so every triangle has at most one edge on the outer ring.
fn hex_disc(rings: usize) -> (Vec<[f64; 2]>, Vec<[usize; 3]>) {
    let mut params = vec![[0.0, 0.0]];
    let mut triangles = Vec::new();
    let mut inner: Vec<usize> = vec![0];
    for i in 1..=rings {
        let n = 6 * i;
        let outer: Vec<usize> = (params.len()..params.len() + n).collect();
        params.extend((0..n).map(|j| [i as f64 / rings as f64, TAU * j as f64 / n as f64]));
        zip_rings(&inner, &outer, &mut triangles);
        inner = outer;
    }
    (params, triangles)
}

/// Triangulates the strip between ring `inner` and ring `outer` (points in angular order from
/// angle 0; a single-point inner ring is the centre), advancing along whichever ring's next
/// point comes first in angle (exact integer comparison; the outer ring on ties).
fn zip_rings(inner: &[usize], outer: &[usize], triangles: &mut Vec<[usize; 3]>) {
    let (na, nb) = (inner.len(), outer.len());
    let (mut a, mut b) = (0, 0);
    let steps = if na == 1 { nb } else { na + nb };
    for _ in 0..steps {
        let outer_first = na == 1 || (b + 1) * na <= (a + 1) * nb;
        if outer_first {
            triangles.push([inner[a % na], outer[b % nb], outer[(b + 1) % nb]]);
            b += 1;
        } else {
            triangles.push([inner[a % na], outer[b % nb], inner[(a + 1) % na]]);
            a += 1;
        }
    }
}

fn cup_sheet() -> Result<MedialSheet> {
    let (params, triangles) = hex_disc(CUP_RINGS);
    let points = params
        .iter()
        .map(|&[s, phi]| {
            let theta = s * CUP_OPENING;
            Vec3::new(
                CUP_EQUATOR * theta.sin() * phi.cos(),
                CUP_EQUATOR * theta.sin() * phi.sin(),
                -CUP_LENGTH * theta.cos(),
            )
        })
        .collect();
    let radius = params
        .iter()
        .map(|&[s, phi]| {
            CUP_RADIUS_APEX
                + (CUP_RADIUS_BASE - CUP_RADIUS_APEX) * s
                + CUP_RADIUS_SEPTUM * s * phi.cos()
        })
        .collect();
    MedialSheet::new(points, triangles, radius)
}

// ---------------------------------------------------------------------------------------------
// The toy

/// A grid of `(nu+1) × (nv+1)` points `(i/nu, j/nv)` (point `j(nu+1) + i`), each cell split
/// along the diagonal through its corner with even `i + j`, counter-clockwise in `(u, v)`.
/// With `nu`, `nv` even no triangle has two edges on the border of the grid.
fn grid(nu: usize, nv: usize) -> (Vec<[f64; 2]>, Vec<[usize; 3]>) {
    let id = |i: usize, j: usize| j * (nu + 1) + i;
    let params = (0..=nv)
        .flat_map(|j| (0..=nu).map(move |i| [i as f64 / nu as f64, j as f64 / nv as f64]))
        .collect();
    let mut triangles = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            if (i + j) % 2 == 0 {
                triangles.extend([[a, b, c], [a, c, d]]);
            } else {
                triangles.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    (params, triangles)
}

/// Half thickness of the toy at distance fraction `u` from the seam and height fraction `v`.
fn toy_radius(u: f64, v: f64) -> f64 {
    let z = 2.0 * v - 1.0;
    TOY_RADIUS * (1.0 - 0.3 * u) * (1.0 - 0.2 * z * z)
}

fn toy_sheet() -> Result<MedialSheet> {
    let [nw, nz] = TOY_CELLS;
    let (params, cells) = grid(nw, nz);
    // The seam: grid column u = 0, shared by the three sheets (points 0 ..= nz).
    let mut points: Vec<Vec3> = (0..=nz)
        .map(|j| Vec3::new(0.0, 0.0, TOY_LENGTH * (j as f64 / nz as f64 - 0.5)))
        .collect();
    let mut radius: Vec<f64> = (0..=nz)
        .map(|j| toy_radius(0.0, j as f64 / nz as f64))
        .collect();
    let mut triangles = Vec::new();
    for s in 0..3 {
        let angle = PI / 2.0 + TAU * s as f64 / 3.0;
        let along = Vec3::new(angle.cos(), angle.sin(), 0.0);
        let normal = Vec3::new(-angle.sin(), angle.cos(), 0.0);
        let global: Vec<usize> = params
            .iter()
            .enumerate()
            .map(|(k, &[u, v])| {
                if k % (nw + 1) == 0 {
                    return k / (nw + 1);
                }
                let w = TOY_WIDTH * u;
                let z = TOY_LENGTH * (v - 0.5);
                points.push(w * along + TOY_CURL * w * w * normal + Vec3::new(0.0, 0.0, z));
                radius.push(toy_radius(u, v));
                points.len() - 1
            })
            .collect();
        triangles.extend(cells.iter().map(|t| t.map(|v| global[v])));
    }
    MedialSheet::new(points, triangles, radius)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn names_round_trip_and_unknown_names_are_listed() {
        for s in Shape::ALL {
            assert_eq!(Shape::from_name(s.name()).unwrap(), s);
        }
        assert_eq!(Shape::from_name("TOY").unwrap(), Shape::Toy);
        let m = Shape::from_name("mug").unwrap_err().to_string();
        assert!(m.contains("'mug'") && m.contains("cup, toy"), "{m}");
    }

    #[test]
    fn hex_disc_is_a_disc() {
        let (params, triangles) = hex_disc(3);
        assert_eq!(params.len(), 1 + 6 + 12 + 18);
        assert_eq!(triangles.len(), 6 * 9);
        // Counter-clockwise in the plane.
        let xy = |k: usize| {
            let [s, a] = params[k];
            nalgebra::Vector2::new(s * a.cos(), s * a.sin())
        };
        for t in &triangles {
            let (e1, e2) = (xy(t[1]) - xy(t[0]), xy(t[2]) - xy(t[0]));
            assert!(e1.perp(&e2) > 1e-3, "{t:?}");
        }
    }

    #[test]
    fn bend_and_twist_are_inverted_exactly() {
        let warp = Shape::Toy.warp(Vec3::new(1.0, -2.0, 3.0));
        for p in [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(10.0, -7.0, 12.0),
            Vec3::new(-14.0, 3.0, -11.0),
        ] {
            let back = warp.inverse(&warp.apply(&p)).expect("invertible");
            assert_relative_eq!(back, p, epsilon = 1e-10);
        }
        let straight = Warp {
            bend: 0.0,
            twist: 0.0,
            ..warp
        };
        let p = Vec3::new(3.0, 4.0, 5.0);
        let affine = straight.affine() * p.push(1.0);
        assert_relative_eq!(affine.xyz(), straight.apply(&p), epsilon = 1e-12);
        // The bend keeps arc length along the axis and its small-angle branch is continuous.
        let on_axis = bend(&Vec3::new(0.0, 0.0, 10.0), 0.02);
        assert_relative_eq!(
            on_axis,
            Vec3::new(50.0 * (1.0 - 0.2f64.cos()), 0.0, 50.0 * 0.2f64.sin()),
            epsilon = 1e-12
        );
        let tiny = bend(&Vec3::new(1.0, 2.0, 3.0), 1e-9);
        assert_relative_eq!(tiny, Vec3::new(1.0, 2.0, 3.0), epsilon = 1e-8);
    }
}
