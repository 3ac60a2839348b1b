//! A seam of a branching medial axis (where three sheets meet) as a polyline with a radius per
//! vertex: the seam's medial points ordered along their principal direction, averaged in bins,
//! smoothed and resampled evenly by arc length.

use super::ridge::MedialPoint;
use super::MIN_FEATURE_ANGLE_DEG;
use crate::mesh::centroid_and_covariance;
use crate::{Error, Result, Vec3};

/// Length of the bins along the seam's principal direction, voxels.
const BIN_VOXELS: f64 = 2.0;
/// Half width, in bins, of the moving mean that smooths the binned seam.
const SMOOTHING_BINS: usize = 2;

/// A seam: a polyline of medial points (mm) with a radius per vertex (mm).
#[derive(Clone, Debug, PartialEq)]
pub struct Seam {
    /// The vertices, in order along the seam.
    pub points: Vec<Vec3>,
    /// The radius at each vertex.
    pub radius: Vec<f64>,
}

impl Seam {
    /// The seam through the medial points `points` (those of one seam) of a mask of mean
    /// voxel `voxel` (mm): with `d` the principal direction of the points and `t = (p − p̄)·d`,
    /// the mean position and radius of the points in each bin of `t` of `BIN_VOXELS` voxels
    /// (empty bins skipped), smoothed by a moving mean over `2·SMOOTHING_BINS + 1` bins (the
    /// window shifted inside at the ends) across the seam, each bin kept at its own place
    /// along `d`, and in radius (the window narrowed at the ends), then trimmed at each end while the radius
    /// changes faster along it than `|dr/ds| = cos(MIN_FEATURE_ANGLE_DEG/2)` ≈ 0.57: where the
    /// seam's line of medial points runs on into the shape's rounded end (radius falling to 0)
    /// past where the sheets' free edges, trimmed by that slope, end.
    ///
    /// Errors: `InvalidVolume` when fewer than two bins are left.
    pub fn fit(points: &[MedialPoint], voxel: f64) -> Result<Self> {
        let positions: Vec<Vec3> = points.iter().map(|p| p.position).collect();
        let (centre, covariance) = centroid_and_covariance(&positions);
        let eigen = covariance.symmetric_eigen();
        let axis = eigen.eigenvalues.imax();
        let direction: Vec3 = eigen.eigenvectors.column(axis).into_owned();
        let bin = BIN_VOXELS * voxel;
        let along: Vec<i64> = (positions.iter())
            .map(|p| ((p - centre).dot(&direction) / bin).floor() as i64)
            .collect();
        let lo = along.iter().copied().min().unwrap_or(0);
        let bins = along
            .iter()
            .map(|&a| (a - lo) as usize + 1)
            .max()
            .unwrap_or(0);
        let mut sum = vec![(Vec3::zeros(), 0.0, 0usize); bins];
        for (p, &a) in points.iter().zip(&along) {
            let s = &mut sum[(a - lo) as usize];
            s.0 += p.position;
            s.1 += p.radius;
            s.2 += 1;
        }
        let binned: Vec<(Vec3, f64)> = (sum.into_iter())
            .filter(|s| s.2 > 0)
            .map(|(p, r, n)| (p / n as f64, r / n as f64))
            .collect();
        if binned.len() < 2 {
            return Err(Error::InvalidVolume(format!(
                "the seam's {} medial points fill {} bins of {bin:.2} mm along it: too short \
                 for a seam",
                points.len(),
                binned.len()
            )));
        }
        let n = binned.len();
        let steep = (MIN_FEATURE_ANGLE_DEG / 2.0).to_radians().cos();
        let width = (2 * SMOOTHING_BINS + 1).min(n);
        let smoothed = |k: usize| {
            // Across the seam, the window about the bin shifted inside at the ends, the bin
            // keeping its place along the seam; the radius over the symmetric window, narrowed
            // at the ends (unbiased where the radius changes linearly).
            let start = k.saturating_sub(SMOOTHING_BINS).min(n - width);
            let window = &binned[start..start + width];
            let mean = window.iter().map(|b| b.0).sum::<Vec3>() / width as f64;
            let along = (binned[k].0 - mean).dot(&direction) * direction;
            let w = SMOOTHING_BINS.min(k).min(n - 1 - k);
            let radius = binned[k - w..=k + w].iter().map(|b| b.1).sum::<f64>();
            (mean + along, radius / (2 * w + 1) as f64)
        };
        let smooth: Vec<(Vec3, f64)> = (0..n).map(smoothed).collect();
        let slope = |k: usize| {
            let ((p, r), (q, s)) = (smooth[k], smooth[k + 1]);
            (s - r).abs() / (q - p).norm().max(f64::MIN_POSITIVE)
        };
        let first = (0..n - 1).find(|&k| slope(k) <= steep).unwrap_or(n - 1);
        let last = (0..n - 1)
            .rev()
            .find(|&k| slope(k) <= steep)
            .map_or(0, |k| k + 1);
        if last <= first {
            return Err(Error::InvalidVolume(format!(
                "the seam's {} medial points make no line along which the radius changes \
                 slowly enough for a medial axis",
                points.len()
            )));
        }
        let (points, radius) = smooth[first..=last].iter().copied().unzip();
        Ok(Self { points, radius })
    }

    /// The mean of the radii at the vertices (mm).
    pub fn mean_radius(&self) -> f64 {
        self.radius.iter().sum::<f64>() / self.radius.len() as f64
    }

    /// The length of the polyline (mm).
    pub fn length(&self) -> f64 {
        self.arcs()[self.points.len() - 1]
    }

    /// The seam resampled at `max(1, round(L / spacing))` equal steps of arc length (`L` its
    /// length), position and radius interpolated linearly; the ends kept.
    pub fn resampled(&self, spacing: f64) -> Self {
        let arc = self.arcs();
        let length = arc[arc.len() - 1];
        let steps = ((length / spacing).round() as usize).max(1);
        let (points, radius) = (0..=steps)
            .map(|i| self.at(&arc, length * i as f64 / steps as f64))
            .unzip();
        Self { points, radius }
    }

    /// The distance from `p` to the polyline (mm).
    pub fn distance(&self, p: &Vec3) -> f64 {
        self.nearest(p).0
    }

    /// The radius at the polyline's point nearest to `p` (mm).
    pub fn radius_near(&self, p: &Vec3) -> f64 {
        self.nearest(p).2
    }

    /// The arc length along the polyline of its point nearest to `p` (mm, from its first
    /// vertex).
    pub fn arc_of(&self, p: &Vec3) -> f64 {
        self.nearest(p).1
    }

    /// The distance from `p` to the polyline, and the arc length and radius of the nearest
    /// point on it.
    fn nearest(&self, p: &Vec3) -> (f64, f64, f64) {
        let mut start = 0.0;
        let mut best = (f64::INFINITY, 0.0, 0.0);
        for (k, w) in self.points.windows(2).enumerate() {
            let (a, e) = (w[0], w[1] - w[0]);
            let t = ((p - a).dot(&e) / e.norm_squared().max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
            let d = (p - (a + t * e)).norm();
            if d < best.0 {
                let r = self.radius[k] + t * (self.radius[k + 1] - self.radius[k]);
                best = (d, start + t * e.norm(), r);
            }
            start += e.norm();
        }
        best
    }

    /// The part of the polyline between arc lengths `from < to` (mm), clamped to it, with
    /// new end vertices interpolated there.
    pub fn between(&self, from: f64, to: f64) -> Self {
        let arc = self.arcs();
        let (from, to) = (from.max(0.0), to.min(arc[arc.len() - 1]));
        let mut part = vec![self.at(&arc, from)];
        part.extend(
            (1..arc.len() - 1)
                .filter(|&k| arc[k] > from && arc[k] < to)
                .map(|k| (self.points[k], self.radius[k])),
        );
        part.push(self.at(&arc, to));
        let (points, radius) = part.into_iter().unzip();
        Self { points, radius }
    }

    /// The arc length at each vertex (mm, 0 at the first).
    fn arcs(&self) -> Vec<f64> {
        let mut arc = vec![0.0];
        for w in self.points.windows(2) {
            arc.push(arc[arc.len() - 1] + (w[1] - w[0]).norm());
        }
        arc
    }

    /// Position and radius at arc length `s` along the polyline, its vertices at arc lengths
    /// `arc`.
    fn at(&self, arc: &[f64], s: f64) -> (Vec3, f64) {
        let k = arc.partition_point(|&a| a <= s).clamp(1, arc.len() - 1) - 1;
        let f = ((s - arc[k]) / (arc[k + 1] - arc[k]).max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
        (
            self.points[k] + f * (self.points[k + 1] - self.points[k]),
            self.radius[k] + f * (self.radius[k + 1] - self.radius[k]),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_noisy_line_of_points_gives_its_line_resampled_evenly() {
        // Points along z ∈ [−10, 10] in a 0.5 mm tube about the z axis, radius 2 + z/20.
        let points: Vec<MedialPoint> = (0..400)
            .map(|i| {
                let z = -10.0 + 20.0 * i as f64 / 399.0;
                let wobble = 0.25 * ((i % 3) as f64 - 1.0);
                MedialPoint {
                    position: Vec3::new(wobble, -wobble, z),
                    radius: 2.0 + z / 20.0,
                }
            })
            .collect();
        let seam = Seam::fit(&points, 0.5).unwrap();
        assert!(seam.points.iter().all(|p| p.x.hypot(p.y) < 0.1), "{seam:?}");
        let length = seam.length();
        assert!((length - 20.0).abs() < 1.0, "{length}");
        let even = seam.resampled(2.0);
        let steps: Vec<f64> = even
            .points
            .windows(2)
            .map(|w| (w[1] - w[0]).norm())
            .collect();
        assert_eq!(steps.len(), (length / 2.0).round() as usize);
        assert!(steps
            .iter()
            .all(|s| (s - length / steps.len() as f64).abs() < 0.05));
        for (p, r) in even.points.iter().zip(&even.radius) {
            assert!((r - (2.0 + p.z / 20.0)).abs() < 0.05, "{p} {r}");
        }
        assert!((even.distance(&Vec3::new(3.0, 4.0, 0.0)) - 5.0).abs() < 0.1);
        // Points in one bin: no seam.
        let bunch = [points[0]; 5];
        assert!(Seam::fit(&bunch, 0.5).is_err());
    }
}
