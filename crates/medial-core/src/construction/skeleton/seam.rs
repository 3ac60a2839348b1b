//! A seam of a branching medial axis (where three sheets meet) as a polyline with a radius per
//! vertex: the seam's medial points ordered along their principal direction, averaged in bins,
//! smoothed and resampled evenly by arc length.

use super::branching::ball_of;
use super::ridge::MedialPoint;
use super::MIN_FEATURE_ANGLE_DEG;
use crate::construction::inflate::UnionFind;
use crate::{Error, Result, Vec3};
use nalgebra::Matrix3;

/// Length of the bins along the seam's principal direction, voxels.
const BIN_VOXELS: f64 = 2.0;
/// A bin of a seam is the mean of its points whose radius is within this many voxels of its
/// largest (the voxel noise of a medial point's radius is about half a voxel).
const TOP_RADIUS_VOXELS: f64 = 0.5;
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
    /// voxel `voxel` (mm): with `t` each point's arc parameter along the seam ([`arc_of_points`]:
    /// its distance along the cloud from one end, so that a curved seam, such as the one a
    /// ventricle's insertion lines make round its apex, is followed along itself), the mean
    /// position and radius of the points in each bin of `t` of `BIN_VOXELS` voxels (empty bins
    /// skipped), smoothed by a moving mean over `2·SMOOTHING_BINS + 1` bins (the window shifted
    /// inside at the ends) across the seam, each bin kept at its own place along the seam's
    /// local direction, and in radius (the window narrowed at the ends), then trimmed at each
    /// end while the radius changes faster along it than `|dr/ds| = cos(MIN_FEATURE_ANGLE_DEG/2)`
    /// ≈ 0.57: where the seam's line of medial points runs on into the shape's rounded end
    /// (radius falling to 0) past where the sheets' free edges, trimmed by that slope, end.
    ///
    /// Errors: `InvalidVolume` when fewer than two bins are left.
    pub fn fit(points: &[MedialPoint], voxel: f64) -> Result<Self> {
        let bin = BIN_VOXELS * voxel;
        let along: Vec<i64> = (arc_of_points(points, voxel).iter())
            .map(|t| (t / bin).floor() as i64)
            .collect();
        let lo = along.iter().copied().min().unwrap_or(0);
        let bins = along
            .iter()
            .map(|&a| (a - lo) as usize + 1)
            .max()
            .unwrap_or(0);
        // The junction's ball, touching the three boundary parts the sheets part, is the
        // largest across the seam: each bin is the mean of its points within
        // `TOP_RADIUS_VOXELS` of its largest radius, not of all its points (the points off the
        // junction that see the three sheets lie further along the sheet with more points).
        let mut largest = vec![0.0_f64; bins];
        for (p, &a) in points.iter().zip(&along) {
            let l = &mut largest[(a - lo) as usize];
            *l = l.max(p.radius);
        }
        let mut sum = vec![(Vec3::zeros(), 0.0, 0usize); bins];
        for (p, &a) in points.iter().zip(&along) {
            let k = (a - lo) as usize;
            if p.radius >= largest[k] - TOP_RADIUS_VOXELS * voxel {
                let s = &mut sum[k];
                s.0 += p.position;
                s.1 += p.radius;
                s.2 += 1;
            }
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
        // The radius over the symmetric window, narrowed at the ends (unbiased where the
        // radius changes linearly).
        let radius = |k: usize| {
            let w = SMOOTHING_BINS.min(k).min(n - 1 - k);
            binned[k - w..=k + w].iter().map(|b| b.1).sum::<f64>() / (2 * w + 1) as f64
        };
        let positions: Vec<Vec3> = binned.iter().map(|b| b.0).collect();
        let smooth: Vec<(Vec3, f64)> = (smoothed_across(&positions).into_iter())
            .enumerate()
            .map(|(k, p)| (p, radius(k)))
            .collect();
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

/// How far apart two points of a seam may be to be joined along it, voxels: the first of
/// these at which every piece but the largest is a scrap ([`arc_of_points`]).
const LINKS_VOXELS: [f64; 5] = [2.0, 4.0, 8.0, 16.0, 32.0];

/// The arc parameter of each of a seam's points `points` (mm, on a mask of mean voxel
/// `voxel`): the arc length of its nearest point on the seam's spine. The spine is the
/// shortest path between the two ends of the largest piece of the graph joining points at most
/// a link apart, the ends being its point farthest from its first point and its point
/// farthest from that one; the link is the first of `LINKS_VOXELS` at which every other piece
/// is a scrap (the widest when none is): fewer points than the seam holds along one seam ball
/// (`n·b̄/L`, `b̄` the points' mean ball, `L` the spine's length), too few to be a stretch of
/// the seam to follow. Along a line of points, straight or curved, the parameter grows as the
/// arc length, where a projection onto one direction folds a curved line over itself; and a
/// seam curved round until its ends nearly meet (a ventricle's insertion lines round the
/// septum) is followed round from one end to the other, where a link wide enough to join its
/// scraps also joins its ends and the spine would be half the loop (decision 0408). A seam
/// whose points close into a loop is opened first, where its radius is least (decision 0408).
pub fn arc_of_points(points: &[MedialPoint], voxel: f64) -> Vec<f64> {
    let positions: Vec<Vec3> = points.iter().map(|p| p.position).collect();
    if positions.len() < 2 {
        return vec![0.0; positions.len()];
    }
    let spine = smoothed_spine(&spine_of(points, voxel));
    let seam = match opened(points, &spine, voxel) {
        Some(open) => smoothed_spine(&spine_of(&open, voxel)),
        None => spine,
    };
    positions.iter().map(|p| seam.arc_of(p)).collect()
}

/// The spine `spine` as a polyline (radius 0): the path zigzags through the points across the
/// seam, so it is smoothed as the bins are.
fn smoothed_spine(spine: &[Vec3]) -> Seam {
    Seam {
        radius: vec![0.0; spine.len()],
        points: smoothed_across(spine),
    }
}

/// The mean seam ball of `points` (mm, [`ball_of`]).
fn mean_ball(points: &[MedialPoint], voxel: f64) -> f64 {
    points.iter().map(|p| ball_of(p, voxel)).sum::<f64>() / points.len() as f64
}

/// How many of a seam's `n` points lie along one seam ball `ball` of a spine of length
/// `length` (mm): `n·b̄/L`, what a scrap has fewer of ([`arc_of_points`]).
fn per_ball(n: usize, ball: f64, length: f64) -> f64 {
    n as f64 * ball / length.max(ball)
}

/// A seam's points close into a loop when more than this many seam balls' worth of them
/// (`n·b̄/L` each, as for a scrap) lie further than a ball from their spine: the spine of a
/// loop runs between two of its points half way round from each other and covers half of it.
const LOOP_BALLS: f64 = 2.0;

/// Sectors about a closed seam's centre in its principal plane, of which the one of least mean
/// radius is left out to open it ([`opened`]): 15°, about two seam balls of a ventricle's
/// insertion loop (250 mm, balls of 5–6 mm).
const LOOP_SECTORS: usize = 24;

/// The seam's points `points` less the sector of [`LOOP_SECTORS`] about their centre (in
/// their principal plane) where their mean radius is least, when they close into a loop round
/// their smoothed spine `spine` ([`LOOP_BALLS`]); `None` when they do not. A seam is where three sheets
/// meet, and its ball is smallest where the junction fades: the two ventricles' insertion
/// lines meet round the RV's apex, where the RV cavity tapers to nothing and the three walls
/// become one; on a segmentation rotated against its voxels the junction is found all the
/// way round (decision 0408), and the seam, which the stitching needs with two ends, is
/// opened there.
fn opened(points: &[MedialPoint], spine: &Seam, voxel: f64) -> Option<Vec<MedialPoint>> {
    let n = points.len();
    let ball = mean_ball(points, voxel);
    let far = (points.iter())
        .filter(|p| spine.distance(&p.position) > ball)
        .count();
    if (far as f64) <= LOOP_BALLS * per_ball(n, ball, spine.length()) {
        return None;
    }
    let centre = points.iter().map(|p| p.position).sum::<Vec3>() / n as f64;
    let spread: Matrix3<f64> = (points.iter())
        .map(|p| (p.position - centre) * (p.position - centre).transpose())
        .sum();
    let eigen = spread.symmetric_eigen();
    let mut axes = [0, 1, 2];
    axes.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
    let (u, v) = (
        eigen.eigenvectors.column(axes[0]),
        eigen.eigenvectors.column(axes[1]),
    );
    let tau = std::f64::consts::TAU;
    let sector = |p: &MedialPoint| {
        let d = p.position - centre;
        let angle = d.dot(&v).atan2(d.dot(&u)).rem_euclid(tau);
        ((angle / tau * LOOP_SECTORS as f64) as usize).min(LOOP_SECTORS - 1)
    };
    let mut sums = [(0.0, 0usize); LOOP_SECTORS];
    for p in points {
        let s = &mut sums[sector(p)];
        s.0 += p.radius;
        s.1 += 1;
    }
    let weakest = (0..LOOP_SECTORS)
        .filter(|&k| sums[k].1 > 0)
        .min_by(|&a, &b| {
            let mean = |k: usize| sums[k].0 / sums[k].1 as f64;
            mean(a).total_cmp(&mean(b))
        })?;
    let open: Vec<MedialPoint> = points
        .iter()
        .filter(|p| sector(p) != weakest)
        .copied()
        .collect();
    (open.len() >= 2).then_some(open)
}

/// The spine of `points` (see [`arc_of_points`]): the shortest path between the two ends of
/// their largest piece, its points in order.
fn spine_of(points: &[MedialPoint], voxel: f64) -> Vec<Vec3> {
    let positions: Vec<Vec3> = points.iter().map(|p| p.position).collect();
    let n = positions.len();
    let ball = mean_ball(points, voxel);
    let mut spine = Vec::new();
    for link in LINKS_VOXELS.map(|l| l * voxel) {
        let neighbours = neighbours_within(&positions, link);
        let mut pieces = UnionFind::new(n);
        for (i, near) in neighbours.iter().enumerate() {
            near.iter().for_each(|&(j, _)| pieces.union(i, j));
        }
        let piece: Vec<usize> = (0..n).map(|i| pieces.find(i)).collect();
        let mut size = vec![0usize; n];
        piece.iter().for_each(|&p| size[p] += 1);
        let largest = (0..n)
            .max_by_key(|&p| (size[p], std::cmp::Reverse(p)))
            .unwrap_or(0);
        let first = piece.iter().position(|&p| p == largest).unwrap_or(0);
        let farthest = |from: &[f64]| {
            (0..n)
                .filter(|&i| from[i].is_finite())
                .max_by(|&a, &b| from[a].total_cmp(&from[b]))
                .unwrap_or(first)
        };
        let (from_first, _) = shortest_paths(&neighbours, first);
        let start = farthest(&from_first);
        let (from_start, previous) = shortest_paths(&neighbours, start);
        let mut at = farthest(&from_start);
        let length = from_start[at];
        spine = vec![positions[at]];
        while at != start {
            at = previous[at];
            spine.push(positions[at]);
        }
        let scrap = per_ball(n, ball, length);
        let scraps_only = (0..n)
            .filter(|&p| p != largest && size[p] > 0)
            .all(|p| (size[p] as f64) < scrap);
        if scraps_only {
            break;
        }
    }
    spine
}

/// The polyline `points` smoothed across itself: each vertex moved to the mean of the
/// `2·SMOOTHING_BINS + 1` vertices about it (the window shifted inside at the ends), keeping
/// its own place along the line (its direction between the neighbouring vertices), so that the
/// ends stay where they are.
fn smoothed_across(points: &[Vec3]) -> Vec<Vec3> {
    let n = points.len();
    let width = (2 * SMOOTHING_BINS + 1).min(n);
    (0..n)
        .map(|k| {
            let start = k.saturating_sub(SMOOTHING_BINS).min(n - width);
            let mean = points[start..start + width].iter().sum::<Vec3>() / width as f64;
            let direction = (points[(k + 1).min(n - 1)] - points[k.saturating_sub(1)])
                .try_normalize(f64::MIN_POSITIVE)
                .unwrap_or_else(Vec3::zeros);
            mean + (points[k] - mean).dot(&direction) * direction
        })
        .collect()
}

/// For each point, the points within `link` mm of it and their distances.
fn neighbours_within(positions: &[Vec3], link: f64) -> Vec<Vec<(usize, f64)>> {
    let key = |p: &Vec3| p.map(|c| (c / link).floor() as i64);
    let mut cells: std::collections::HashMap<[i64; 3], Vec<usize>> = Default::default();
    for (i, p) in positions.iter().enumerate() {
        let k = key(p);
        cells.entry([k.x, k.y, k.z]).or_default().push(i);
    }
    (positions.iter().enumerate())
        .map(|(i, p)| {
            let k = key(p);
            (0..27)
                .filter_map(|d| {
                    let o = [d % 3, (d / 3) % 3, d / 9].map(|o| o as i64 - 1);
                    cells.get(&[k.x + o[0], k.y + o[1], k.z + o[2]])
                })
                .flatten()
                .filter(|&&j| j != i)
                .map(|&j| (j, (positions[j] - p).norm()))
                .filter(|&(_, d)| d <= link)
                .collect()
        })
        .collect()
}

/// Dijkstra's shortest distances from `source` over `neighbours` (infinite where unreached)
/// and each point's previous point on its path.
fn shortest_paths(neighbours: &[Vec<(usize, f64)>], source: usize) -> (Vec<f64>, Vec<usize>) {
    use std::cmp::Reverse;
    let mut distance = vec![f64::INFINITY; neighbours.len()];
    let mut previous: Vec<usize> = (0..neighbours.len()).collect();
    distance[source] = 0.0;
    // Non-negative floats order as their bits.
    let mut queue = std::collections::BinaryHeap::from([(Reverse(0u64), source)]);
    while let Some((Reverse(bits), v)) = queue.pop() {
        let d = f64::from_bits(bits);
        if d > distance[v] {
            continue;
        }
        for &(w, step) in &neighbours[v] {
            if d + step < distance[w] {
                distance[w] = d + step;
                previous[w] = v;
                queue.push((Reverse(distance[w].to_bits()), w));
            }
        }
    }
    (distance, previous)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The centres of the voxels of side `v` (mm) in `|x|, |y| ≤ half·v`, `|z| ≤ 2v`.
    fn voxels(v: f64, half: i32) -> Vec<Vec3> {
        let range = |n: i32| (-n..=n).map(f64::from);
        (range(half).flat_map(|i| range(half).flat_map(move |j| range(2).map(move |k| (i, j, k)))))
            .map(|(i, j, k)| Vec3::new(i, j, k) * v)
            .collect()
    }

    #[test]
    fn a_seam_closed_into_a_loop_is_opened_where_its_radius_is_least() {
        // The voxels (0.5 mm) within 0.6 mm of a whole circle of radius 20 mm in z = 0, their
        // radius 5 mm but 2 mm from 100° to 125° (a junction fading where the walls become one).
        let (v, big) = (0.5, 20.0);
        let tau = std::f64::consts::TAU;
        let points: Vec<MedialPoint> = (voxels(v, 44).into_iter())
            .filter(|p| (p.xy().norm() - big).hypot(p.z) <= 0.6)
            .map(|p| {
                let degrees = p.y.atan2(p.x).rem_euclid(tau).to_degrees();
                let thin = (100.0..125.0).contains(&degrees);
                MedialPoint {
                    position: p,
                    radius: if thin { 2.0 } else { 5.0 },
                }
            })
            .collect();
        let arcs = arc_of_points(&points, v);
        let (lo, hi) = (arcs.iter()).fold((f64::INFINITY, 0.0_f64), |(lo, hi), &a| {
            (lo.min(a), hi.max(a))
        });
        // Followed round all but the sector left out (half the loop without opening it).
        assert!(hi - lo > 0.8 * tau * big, "{} mm", hi - lo);
        // The thin stretch is where the loop was opened: its points lie at the seam's ends.
        for (p, a) in points.iter().zip(&arcs) {
            if p.radius < 3.0 {
                assert!((a - lo).min(hi - a) < 0.2 * tau * big / 4.0, "{p:?} at {a}");
            }
        }
    }

    #[test]
    fn a_seam_curved_round_until_its_ends_nearly_meet_is_followed_round_past_its_scraps() {
        // The voxels (0.5 mm) within 0.6 mm of a circle of radius 10 mm in z = 0, less a gap
        // of 15.5° (its ends 1.5 mm apart, three voxels: a link of four voxels joins them),
        // and a scrap of three points 1.5 mm outside it, which no link of two voxels joins.
        let (v, radius, gap) = (0.5, 10.0, 15.5_f64.to_radians());
        let tau = std::f64::consts::TAU;
        let mut points: Vec<MedialPoint> = (voxels(v, 24).into_iter())
            .filter(|p| {
                let angle = p.y.atan2(p.x).rem_euclid(tau);
                let on = angle.clamp(gap / 2.0, tau - gap / 2.0);
                (p - radius * Vec3::new(on.cos(), on.sin(), 0.0)).norm() <= 0.6
            })
            .map(|position| MedialPoint {
                position,
                radius: 1.0,
            })
            .collect();
        points.extend((0..3).map(|k| MedialPoint {
            position: Vec3::new(-12.1 - 0.5 * k as f64, 0.0, 0.0),
            radius: 1.0,
        }));
        let arcs = arc_of_points(&points, v);
        let (lo, hi) = (arcs.iter()).fold((f64::INFINITY, 0.0_f64), |(lo, hi), &a| {
            (lo.min(a), hi.max(a))
        });
        let length = radius * (tau - gap);
        assert!(hi - lo > 0.9 * length, "{} of {length} mm", hi - lo);
        // The arc parameter grows with the angle round the circle, one way or the other.
        let mut by_angle: Vec<(f64, f64)> = (points.iter().zip(&arcs))
            .filter(|(p, _)| p.position.norm() < 11.0)
            .map(|(p, &a)| (p.position.y.atan2(p.position.x).rem_euclid(tau), a))
            .collect();
        by_angle.sort_by(|a, b| a.0.total_cmp(&b.0));
        let sign = (by_angle[by_angle.len() - 1].1 - by_angle[0].1).signum();
        for w in by_angle.windows(2) {
            assert!(sign * (w[1].1 - w[0].1) > -1.5, "{w:?}");
        }
    }

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
        // A half circle of radius 10 mm: followed round, not folded onto its diameter.
        let arc: Vec<MedialPoint> = (0..=300)
            .map(|i| {
                let a = std::f64::consts::PI * i as f64 / 300.0;
                MedialPoint {
                    position: Vec3::new(10.0 * a.cos(), 10.0 * a.sin(), 0.0),
                    radius: 2.0,
                }
            })
            .collect();
        let half_circle = Seam::fit(&arc, 0.5).unwrap();
        let length = half_circle.length();
        assert!(
            (length - 10.0 * std::f64::consts::PI).abs() < 1.5,
            "{length}"
        );
        assert!(half_circle
            .points
            .iter()
            .all(|p| (p.xy().norm() - 10.0).abs() < 0.3 && p.z.abs() < 1e-9));
        // Points in one bin: no seam.
        let bunch = [points[0]; 5];
        assert!(Seam::fit(&bunch, 0.5).is_err());
    }
}
