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
//! ([`crate::build::project::project`]). The target is the template boundary, midpoint subdivided
//! [`TARGET_SUBDIVISIONS`] times (so that the smooth warp bends its triangles), carried by the
//! case's [`Warp`]: a twist and a bend about the shape's long axis (z) followed by an affine map.
//!
//! Any other template becomes a case the same way: [`PrincipalAxes::of`] its points gives the
//! frame of the twist and bend (long axis z, thickness direction x), [`Warp::bending`] the warp,
//! and [`target_boundary`], [`target_surface`] and [`target_image`] the targets.
//! [`parameter_grid`] triangulates the parameter rectangle of a new analytic sheet.

use crate::build::inflate::{inflate, MedialSheet};
use crate::build::project::{project, ProjectOptions, Projection};
use crate::image::rasterize::{grid_around, rasterize};
use crate::image::volume::Volume;
use crate::mesh::subdivide::midpoint_subdivide;
use crate::mesh::Bounds;
use crate::model::template::MedialTemplate;
use crate::{Error, Result, TriMesh, Vec3};
use nalgebra::{Matrix3, Matrix4, Rotation3, Unit};
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
    /// template (mm), in the world frame (`F = I`: the shapes are built along the z axis).
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
            frame: Rotation3::identity(),
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
/// φ(p) = c + t + A · F · B_κ(T_τ(Fᵀ (p − c))),
/// ```
///
/// with `c` the centre (mm), `F` an orthonormal right-handed frame (its columns are the axes
/// `x`, `y`, `z` of the bend in world coordinates: `z` the long axis that is twisted and bent,
/// `x` the direction towards which it bends), the twist `T_τ(x, y, z) = (R(τz)(x, y), z)`
/// (`R(α)` the rotation of the plane by `α`, `τ` in rad/mm), the bend `B_κ` that rolls the z
/// axis onto a circle of radius `ρ = 1/κ` in the x–z plane,
///
/// ```text
/// B_κ(x, y, z) = (x cos θ + ρ (1 − cos θ), y, (ρ − x) sin θ),   θ = κ z,
/// ```
///
/// (arc length along the axis kept; Jacobian determinant `1 − κx`) and the affine map
/// `p ↦ A (p − c) + c + t`. The built-in shapes use `F = I`. In frame coordinates `φ` is a
/// diffeomorphism of the region `κx < 1, |κz| < π` (x, z after the twist) onto its image, with
/// the closed-form inverse [`Warp::inverse`]; [`Warp::check_invertible_on`] checks that points
/// lie in it. `det Dφ(p) = det A · (1 − κ x)` ([`Warp::jacobian_determinant`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Warp {
    /// Centre `c` of the twist and bend, mm.
    pub centre: Vec3,
    /// Frame `F` of the twist and bend: rotation whose columns are its x (bend direction),
    /// y and z (long axis) axes in world coordinates.
    pub frame: Rotation3<f64>,
    /// Twist rate `τ` about the frame's z axis, radians per mm.
    pub twist: f64,
    /// Curvature `κ` of the bent z axis, 1/mm (0: no bend; positive: towards +x).
    pub bend: f64,
    /// Linear part `A` of the affine map (invertible).
    pub linear: Matrix3<f64>,
    /// Translation `t` of the affine map, mm.
    pub translation: Vec3,
}

impl Warp {
    /// A twist and bend along the principal axes of a shape followed by the affine map
    /// `affine` (a 4×4 world matrix, last row `0 0 0 1`): centre `c` and frame `F` from
    /// `axes`, `κ = bend_deg·π/180 / L` and `τ = twist_deg·π/180 / L` with `L` the extent of
    /// the shape along its long axis (mm), so that the long axis turns by `bend_deg` degrees
    /// from end to end and its ends rotate by `twist_deg` degrees against each other. With
    /// `c` at the middle of that extent, the bend angle is `θ = κz ∈ [−bend/2, bend/2]`.
    ///
    /// Errors: `InvalidParameter` for non-finite angles, `|bend_deg| ≥ 360` (the bent axis
    /// would overlap itself), an extent `L` that is not positive, and as
    /// [`Warp::with_affine`].
    pub fn bending(
        axes: &PrincipalAxes,
        bend_deg: f64,
        twist_deg: f64,
        affine: &Matrix4<f64>,
    ) -> Result<Self> {
        if !(bend_deg.is_finite() && twist_deg.is_finite()) {
            return Err(Error::InvalidParameter(format!(
                "bend and twist angles must be finite numbers of degrees, got {bend_deg} and \
                 {twist_deg}"
            )));
        }
        if bend_deg.abs() >= 360.0 {
            return Err(Error::InvalidParameter(format!(
                "a bend of {bend_deg}° would make the bent long axis overlap itself; it must be \
                 less than 360° in magnitude"
            )));
        }
        let length = axes.extent.z;
        if !(length.is_finite() && length > 0.0) {
            return Err(Error::InvalidParameter(format!(
                "the extent of the shape along its long axis must be a positive number of mm, \
                 got {length}"
            )));
        }
        let warp = Self {
            centre: axes.centre,
            frame: axes.frame,
            twist: twist_deg.to_radians() / length,
            bend: bend_deg.to_radians() / length,
            linear: Matrix3::identity(),
            translation: Vec3::zeros(),
        };
        warp.with_affine(affine)
    }

    /// The same twist and bend followed by the affine map `affine` instead of the current one:
    /// with `affine = [M b; 0 1]`, `A = M` and `t = M c + b − c`, so that
    /// [`Warp::affine`] returns `affine`.
    ///
    /// Errors: `InvalidParameter` when `affine` has a non-finite entry, a last row other than
    /// `0 0 0 1`, or `det M ≤ 0` (singular, or a reflection, which no flow of space can
    /// reproduce).
    pub fn with_affine(self, affine: &Matrix4<f64>) -> Result<Self> {
        if affine.iter().any(|v| !v.is_finite()) {
            return Err(Error::InvalidParameter(format!(
                "the affine matrix has a non-finite entry: {affine}"
            )));
        }
        if affine.row(3) != nalgebra::RowVector4::new(0.0, 0.0, 0.0, 1.0) {
            return Err(Error::InvalidParameter(
                "the last row of an affine matrix must be 0 0 0 1".into(),
            ));
        }
        let linear: Matrix3<f64> = affine.fixed_view::<3, 3>(0, 0).into_owned();
        let det = linear.determinant();
        if det.is_nan() || det <= 0.0 {
            return Err(Error::InvalidParameter(format!(
                "the linear part of the affine matrix has determinant {det}; it must be \
                 positive (no reflection, not singular)"
            )));
        }
        let offset: Vec3 = affine.fixed_view::<3, 1>(0, 3).into_owned();
        Ok(Self {
            linear,
            translation: linear * self.centre + offset - self.centre,
            ..self
        })
    }

    /// `T_τ(Fᵀ (p − c))`: the point in the frame of the bend after the twist, mm (the
    /// argument of `B_κ`).
    pub fn local(&self, p: &Vec3) -> Vec3 {
        twist(
            &self.frame.inverse_transform_vector(&(p - self.centre)),
            self.twist,
        )
    }

    /// `φ(p)`, mm.
    pub fn apply(&self, p: &Vec3) -> Vec3 {
        let bent = bend(&self.local(p), self.bend);
        self.centre + self.translation + self.linear * (self.frame * bent)
    }

    /// `φ⁻¹(p)`, or `None` when `A` is singular or `p` is the image of no point (the axis of
    /// the bend).
    pub fn inverse(&self, p: &Vec3) -> Option<Vec3> {
        let bent = self.frame.inverse_transform_vector(
            &(self.linear.try_inverse()? * (p - self.centre - self.translation)),
        );
        let twisted = unbend(&bent, self.bend)?;
        Some(self.centre + self.frame * twist(&twisted, -self.twist))
    }

    /// The affine part `p ↦ A (p − c) + c + t` as a 4×4 matrix (last row `0 0 0 1`): the warp
    /// without twist and bend, the initialisation a registration would give.
    pub fn affine(&self) -> Matrix4<f64> {
        let mut m = self.linear.to_homogeneous();
        let offset = self.centre + self.translation - self.linear * self.centre;
        m.fixed_view_mut::<3, 1>(0, 3).copy_from(&offset);
        m
    }

    /// `det Dφ(p) = det A · (1 − κ x)` with `x` the first coordinate of [`Warp::local`]`(p)`
    /// (rotations and the twist keep volume): the local volume ratio of the warp at `p`.
    pub fn jacobian_determinant(&self, p: &Vec3) -> f64 {
        self.linear.determinant() * (1.0 - self.bend * self.local(p).x)
    }

    /// Checks that every point lies where the bend is a diffeomorphism: `κ x < 1` and
    /// `|κ z| < π` for `(x, y, z)` = [`Warp::local`]`(p)`.
    ///
    /// Errors: `InvalidParameter` naming the first point that does not, with `κx` or `κz`.
    pub fn check_invertible_on(&self, points: &[Vec3]) -> Result<()> {
        for (i, p) in points.iter().enumerate() {
            let local = self.local(p);
            let (across, along) = (self.bend * local.x, self.bend * local.z);
            if across >= 1.0 || along.abs() >= PI {
                return Err(Error::InvalidParameter(format!(
                    "the bend (curvature {:.4} 1/mm, radius {:.2} mm) is not invertible on the \
                     shape: at point {i} {:?}, κx = {across:.3} and κz = {along:.3} rad, but \
                     κx must be < 1 (else the inside of the bend folds) and |κz| < π; use a \
                     smaller bend angle",
                    self.bend,
                    1.0 / self.bend,
                    p.as_slice()
                )));
            }
        }
        Ok(())
    }
}

/// The principal axes of a point set, as [`Warp::bending`] uses them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrincipalAxes {
    /// Centre of the bounding box of the points in the frame, `mean + F·(lo + hi)/2`, mm.
    pub centre: Vec3,
    /// Right-handed orthonormal frame whose columns are the eigenvectors of the points'
    /// covariance: z of the largest variance (the long axis), x of the smallest (the thickness
    /// direction of a sheet), `y = z × x`. Each of x and z has its largest-magnitude
    /// component positive (a deterministic choice of sign).
    pub frame: Rotation3<f64>,
    /// Extent `hi − lo` of the points along x, y, z of the frame, mm.
    pub extent: Vec3,
    /// Standard deviations of the points along x, y, z of the frame (square roots of the
    /// covariance eigenvalues), mm.
    pub std_dev: Vec3,
}

impl PrincipalAxes {
    /// The principal axes of `points`: covariance `Σ (p − p̄)(p − p̄)ᵀ / n` about the mean `p̄`,
    /// its eigenvectors as the frame, the bounding box in that frame.
    ///
    /// Errors: `NonFinite` for a non-finite coordinate; `InvalidParameter` for no points or
    /// points without extent along their long axis (all equal).
    pub fn of(points: &[Vec3]) -> Result<Self> {
        if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(Error::NonFinite(format!(
                "point {i} is {:?}",
                points[i].as_slice()
            )));
        }
        if points.is_empty() {
            return Err(Error::InvalidParameter(
                "principal axes need at least one point".into(),
            ));
        }
        let n = points.len() as f64;
        let mean = points.iter().sum::<Vec3>() / n;
        let covariance = points
            .iter()
            .map(|p| (p - mean) * (p - mean).transpose())
            .sum::<Matrix3<f64>>()
            / n;
        let eigen = covariance.symmetric_eigen();
        let mut order = [0, 1, 2];
        order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
        let axis = |k: usize| positive_sign(eigen.eigenvectors.column(order[k]).into_owned());
        let (x, z) = (axis(0), axis(2));
        let y = z.cross(&x).normalize();
        let frame = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[y.cross(&z), y, z]));
        let local: Vec<Vec3> = points
            .iter()
            .map(|p| frame.inverse_transform_vector(&(p - mean)))
            .collect();
        let bounds = Bounds::of(&local).unwrap_or(Bounds {
            min: Vec3::zeros(),
            max: Vec3::zeros(),
        });
        let extent = bounds.extent();
        if extent.z <= 0.0 {
            return Err(Error::InvalidParameter(format!(
                "the {} points have no extent along their long axis (all equal)",
                points.len()
            )));
        }
        let variance = Vec3::from_fn(|k, _| eigen.eigenvalues[order[k]].max(0.0));
        Ok(Self {
            centre: mean + frame * bounds.centre(),
            frame,
            extent,
            std_dev: variance.map(f64::sqrt),
        })
    }
}

/// `v` or `−v`, whichever has its largest-magnitude component positive.
fn positive_sign(v: Vec3) -> Vec3 {
    if v[v.iamax()] < 0.0 {
        -v
    } else {
        v
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

/// The SSD target with known correspondence: `boundary` with every point carried by `warp`
/// (same triangles, same order), mm.
///
/// Errors: as [`Warp::check_invertible_on`] when the warp folds the boundary.
pub fn target_boundary(boundary: &TriMesh, warp: &Warp) -> Result<TriMesh> {
    warp.check_invertible_on(boundary.points())?;
    TriMesh::new(
        boundary.points().iter().map(|p| warp.apply(p)).collect(),
        boundary.triangles().to_vec(),
    )
}

/// The target surface: `boundary` midpoint subdivided [`TARGET_SUBDIVISIONS`] times (so that
/// the smooth warp bends its triangles), then carried by `warp` point by point, mm.
///
/// Errors: as [`target_boundary`].
pub fn target_surface(boundary: &TriMesh, warp: &Warp) -> Result<TriMesh> {
    let mut mesh = boundary.clone();
    for _ in 0..TARGET_SUBDIVISIONS {
        mesh = midpoint_subdivide(&mesh)?;
    }
    target_boundary(&mesh, warp)
}

/// The target segmentation: the closed `surface` (a [`target_surface`]) rasterized (1 inside,
/// 0 outside) on an axis-aligned grid of spacing `spacing_mm` around it with `margin_mm` on
/// every side (see [`grid_around`]).
///
/// Errors: as [`grid_around`] and [`rasterize`] (an open surface).
pub fn target_image(surface: &TriMesh, spacing_mm: f64, margin_mm: f64) -> Result<Volume> {
    let (dims, voxel_to_world) = grid_around(surface, spacing_mm, margin_mm)?;
    rasterize(surface, dims, voxel_to_world)
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
        let centre =
            Bounds::of(projection.template.landmarks()).map_or(Vec3::zeros(), |b| b.centre());
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
        boundary_mesh(self.template())
    }

    /// [`target_boundary`] of the template: the warped boundary, point for point.
    pub fn target_boundary(&self) -> Result<TriMesh> {
        target_boundary(&self.boundary()?, &self.warp)
    }

    /// [`target_surface`] of the template: its boundary subdivided, then warped.
    pub fn target_surface(&self) -> Result<TriMesh> {
        target_surface(&self.boundary()?, &self.warp)
    }

    /// [`target_image`] of the template: the target surface rasterized with voxels of
    /// `spacing_mm` and `margin_mm` around it.
    pub fn target_image(&self, spacing_mm: f64, margin_mm: f64) -> Result<Volume> {
        target_image(&self.target_surface()?, spacing_mm, margin_mm)
    }
}

/// The boundary mesh of `template` (its boundary points and triangles).
pub fn boundary_mesh(template: &MedialTemplate) -> Result<TriMesh> {
    TriMesh::new(
        template.boundary_points().to_vec(),
        template.boundary_triangles().to_vec(),
    )
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

/// The parameter points `(u, v)` and the triangles (indices into them) of a [`parameter_grid`].
pub type ParameterGrid = (Vec<[f64; 2]>, Vec<[usize; 3]>);

/// The triangulated parameter rectangle of a medial sheet: `(nu+1) × (nv+1)` parameter points
/// `(u, v) = (i/nu, j/nv)` in `[0, 1]²` (point `j(nu+1) + i`) and `2 nu nv` triangles, each
/// cell split along the diagonal through its corner with even `i + j`, counter-clockwise in
/// `(u, v)`. With `nu`, `nv` even no triangle has two edges on the border of the grid, as
/// [`inflate`] requires. Mapping the parameters to points and radii gives a [`MedialSheet`]
/// (the toy's sheets are three such grids sharing the column `u = 0`).
///
/// Errors: `InvalidParameter` if `nu` or `nv` is 0.
pub fn parameter_grid(nu: usize, nv: usize) -> Result<ParameterGrid> {
    if nu == 0 || nv == 0 {
        return Err(Error::InvalidParameter(format!(
            "a parameter grid needs at least one cell each way, got {nu} × {nv}"
        )));
    }
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
    Ok((params, triangles))
}

/// Half thickness of the toy at distance fraction `u` from the seam and height fraction `v`.
fn toy_radius(u: f64, v: f64) -> f64 {
    let z = 2.0 * v - 1.0;
    TOY_RADIUS * (1.0 - 0.3 * u) * (1.0 - 0.2 * z * z)
}

fn toy_sheet() -> Result<MedialSheet> {
    let [nw, nz] = TOY_CELLS;
    let (params, cells) = parameter_grid(nw, nz)?;
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
    fn parameter_grid_tiles_the_unit_square_counter_clockwise() {
        let (params, triangles) = parameter_grid(4, 2).unwrap();
        assert_eq!((params.len(), triangles.len()), (5 * 3, 2 * 4 * 2));
        assert_eq!((params[6], params[14]), ([0.25, 0.5], [1.0, 1.0]));
        let area = |t: &[usize; 3]| {
            let [a, b, c] = t.map(|k| nalgebra::Vector2::from(params[k]));
            (b - a).perp(&(c - a)) / 2.0
        };
        assert!(triangles.iter().all(|t| area(t) > 0.0));
        assert_relative_eq!(
            triangles.iter().map(area).sum::<f64>(),
            1.0,
            epsilon = 1e-12
        );
        let m = parameter_grid(3, 0).unwrap_err().to_string();
        assert!(m.contains("3 × 0"), "{m}");
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
