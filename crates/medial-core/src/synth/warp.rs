//! The known smooth diffeomorphism of a synthetic case: a twist and a bend about a long axis,
//! then an affine map, with its closed-form inverse.

use crate::mesh::PrincipalAxes;
use crate::{Error, Result, Vec3};
use nalgebra::{Matrix3, Matrix4, Rotation3};
use std::f64::consts::PI;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::Shape;
    use approx::assert_relative_eq;
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
