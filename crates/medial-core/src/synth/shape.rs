//! The synthetic shapes, their dimensions, and the known warp of each.

use super::sheets::{cup_sheet, toy_sheet};
use super::Warp;
use crate::construction::inflate::MedialSheet;
use crate::{Error, Result, Vec3};
use nalgebra::{Matrix3, Rotation3, Unit};
use std::f64::consts::PI;

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_names_are_listed() {
        for s in Shape::ALL {
            assert_eq!(Shape::from_name(s.name()).unwrap(), s);
        }
        assert_eq!(Shape::from_name("TOY").unwrap(), Shape::Toy);
        let m = Shape::from_name("mug").unwrap_err().to_string();
        assert!(m.contains("'mug'") && m.contains("cup, toy"), "{m}");
    }
}
