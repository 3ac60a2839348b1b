//! Axis-aligned bounding boxes of point sets.

use crate::Vec3;

/// The axis-aligned bounding box of a set of points: per coordinate, the least (`min`) and the
/// greatest (`max`) value (same unit as the points, usually mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// The corner of least coordinates.
    pub min: Vec3,
    /// The corner of greatest coordinates.
    pub max: Vec3,
}

impl Bounds {
    /// The bounding box of `points` (`None` for no points): `min` and `max` folded component by
    /// component from the first point (`f64::min` and `f64::max`, so a NaN coordinate is passed
    /// over unless every point has one there).
    pub fn of(points: &[Vec3]) -> Option<Self> {
        let first = points.first()?;
        let (min, max) = points
            .iter()
            .fold((*first, *first), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
        Some(Self { min, max })
    }

    /// The centre `(min + max) / 2`.
    pub fn centre(&self) -> Vec3 {
        (self.min + self.max) / 2.0
    }

    /// The extent `max − min` along each axis.
    pub fn extent(&self) -> Vec3 {
        self.max - self.min
    }

    /// The box in words: `[x0, x1] × [y0, y1] × [z0, z1]`, one decimal.
    pub fn span(&self) -> String {
        let axis = |a: usize| format!("[{:.1}, {:.1}]", self.min[a], self.max[a]);
        format!("{} × {} × {}", axis(0), axis(1), axis(2))
    }

    /// The length of the diagonal, `|max − min|`.
    pub fn diagonal(&self) -> f64 {
        self.extent().norm()
    }

    /// Whether the two boxes, each grown by `tol` on every side, overlap (touching counts).
    pub fn overlaps(&self, other: &Self, tol: f64) -> bool {
        (0..3).all(|i| self.min[i] <= other.max[i] + tol && other.min[i] <= self.max[i] + tol)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_of_points() {
        assert_eq!(Bounds::of(&[]), None);
        let b = Bounds::of(&[
            Vec3::new(1.0, -2.0, 3.0),
            Vec3::new(-1.0, 4.0, 3.5),
            Vec3::new(0.0, 0.0, 5.0),
        ])
        .unwrap();
        assert_eq!(b.min, Vec3::new(-1.0, -2.0, 3.0));
        assert_eq!(b.max, Vec3::new(1.0, 4.0, 5.0));
        assert_eq!(b.centre(), Vec3::new(0.0, 1.0, 4.0));
        assert_eq!(b.extent(), Vec3::new(2.0, 6.0, 2.0));
        assert_eq!(b.diagonal(), 44.0f64.sqrt());
        let single = Bounds::of(&[Vec3::new(2.0, 2.0, 2.0)]).unwrap();
        assert_eq!(
            (single.min, single.max, single.diagonal()),
            (single.max, single.min, 0.0)
        );
        let shifted = Bounds {
            min: b.min + Vec3::new(2.5, 0.0, 0.0),
            max: b.max + Vec3::new(2.5, 0.0, 0.0),
        };
        assert!(!b.overlaps(&shifted, 0.4) && !shifted.overlaps(&b, 0.4));
        assert!(b.overlaps(&shifted, 0.5) && shifted.overlaps(&b, 0.5));
    }
}
