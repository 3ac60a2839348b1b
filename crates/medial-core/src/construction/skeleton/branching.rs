//! How many sheets a shape's medial points form and how many seams join them: a seam is where
//! three sheets meet (the paper's toy), found as the medial points about which the cloud is not
//! flat.

use nalgebra::Matrix3;
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};

use super::ridge::MedialPoint;
use super::seam::arc_of_points;
use crate::construction::inflate::UnionFind;
use crate::Vec3;

/// Least radius of the ball about a medial point whose points decide whether it is on a seam,
/// voxels: wider than the voxel noise of the cloud.
const BALL_VOXELS: f64 = 4.0;
/// Radius of that ball in the point's own radii, where it is larger than [`BALL_VOXELS`]: a
/// medial point's scale is its radius. The sheets meeting at a seam branch from the centre of
/// the ball that touches all three boundary parts there, and within less than its radius they
/// are bent by that ball (their points' radii change as fast as their positions), so a ball
/// scaled by the voxel alone sees a thick wall's junction as a gentle fold (decision 0402).
const BALL_RADII: f64 = 1.0;
/// A point is on a seam where the smallest eigenvalue of the covariance of the points in its
/// ball is at least this fraction of their trace: about 0 on a sheet (flat on the scale of the
/// ball), 1/4 on a straight seam of three half-discs at 120°.
const SEAM_FLATNESS: f64 = 0.1;
/// Fewest points in a ball for its covariance to count.
pub(crate) const MIN_BALL_POINTS: usize = 10;
/// A piece of sheet counts when it holds at least this fraction of the medial points (smaller
/// ones are spurs of boundary bumps, cut off where they join the sheet).
const MIN_SHEET_FRACTION: f64 = 0.05;

/// The sheets and seams of a cloud of medial points ([`branching`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Branching {
    /// Sheets: pieces of the cloud off the seams, those joined across a fold (a non-flat line
    /// between two pieces only) counted once.
    pub sheets: usize,
    /// Seams: connected lines of non-flat points that three or more sheets meet.
    pub seams: usize,
    /// Medial points on seams.
    pub seam_points: usize,
}

/// Where each medial point lies ([`branching`]): on a sheet, on a seam, or on neither (a spur).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Branches {
    /// The counts.
    pub counts: Branching,
    /// The sheet (`0 .. sheets`) of every point off the seams; `None` on a seam or a spur.
    pub sheet: Vec<Option<usize>>,
    /// The seam (`0 .. seams`) of every point on one; `None` elsewhere.
    pub seam: Vec<Option<usize>>,
    /// The sheets that reach each seam (at least three), ascending.
    pub seam_sheets: Vec<Vec<usize>>,
}

impl Branches {
    /// The indices of the points of sheet `k`.
    pub fn sheet_points(&self, k: usize) -> Vec<usize> {
        (0..self.sheet.len())
            .filter(|&i| self.sheet[i] == Some(k))
            .collect()
    }

    /// The indices of the points of seam `k`.
    pub fn seam_points(&self, k: usize) -> Vec<usize> {
        (0..self.seam.len())
            .filter(|&i| self.seam[i] == Some(k))
            .collect()
    }
}

/// The [`Branches`] of the medial points `points` of a mask of mean voxel `voxel` (mm).
///
/// 1. A point is on a seam when the points within its ball (radius `b = max(4·voxel, r)`,
///    `r` the point's radius: `BALL_VOXELS`, `BALL_RADII`) are not flat: the smallest
///    eigenvalue of their covariance is at least 0.1 of the trace (`SEAM_FLATNESS`).
/// 2. The seam points form seams (joined when each lies in the other's ball) and the other
///    points, less those in the ball of a seam point, form pieces of sheet (cells of
///    1.5 voxels, as [`medial_points`](super::medial_points) joins points); pieces with fewer
///    than 5 % of the points (`MIN_SHEET_FRACTION`) are spurs and are dropped.
/// 3. A seam that at least three pieces reach (a point within twice the ball of one of its
///    points) and that is a line (its points span more than twice their mean ball) is a seam;
///    the pieces on either side of one that fewer reach are one sheet, unless that leaves
///    fewer than three sheets at a seam (`parts_a_seam`).
/// 4. The points left out of the pieces near a seam, and those of lines of non-flat points
///    that are not seams, go to the sheet of the nearest point of a piece within twice the
///    widest ball.
/// 5. A seam line that two pieces reach, curved round so that its ends are nearer each other
///    than a quarter of its length, is closed across the gap between its ends for step 2 (the
///    segment between them, sampled a voxel apart, with the balls of its ends): where the
///    sheet it encloses then parts from the sheet round it, three pieces reach it and it is a
///    seam. A ventricle's insertion lines go round the septum and fade where the RV cavity
///    tapers to its apex; whether the balls of their two ends just overlap across the gap
///    there (and part the septum from the LV free wall) depends on where the voxels fall
///    (decision 0408). The bridge only parts the pieces: the seam is its own points.
pub fn branching(points: &[MedialPoint], voxel: f64) -> Branches {
    let non_flat = NonFlat::new(points, voxel);
    let open = branches_bridged(&non_flat, voxel, &[]);
    let bridges: Vec<(Vec3, f64)> = (open.two_sided.iter())
        .flat_map(|seam| gap_bridge(points, seam, voxel))
        .collect();
    if !bridges.is_empty() {
        let closed = branches_bridged(&non_flat, voxel, &bridges);
        if closed.branches.counts.seams > open.branches.counts.seams {
            return closed.branches;
        }
    }
    open.branches
}

/// A seam's ends are bridged ([`branching`], step 5) when they are nearer each other than this
/// fraction of its length: the seam goes round at least four fifths of the outline of the
/// sheet it encloses.
const GAP_OF_LENGTH: f64 = 0.25;

/// What [`branches_bridged`] found.
struct Bridged {
    branches: Branches,
    /// The points of each line of non-flat points that exactly two pieces reach.
    two_sided: Vec<Vec<usize>>,
}

/// Points a voxel apart, each with the ball of the seam's end it is nearer by interpolation,
/// across the gap between the ends of the seam of points `seam` of `points` (their arc
/// parameter's least and greatest), when the gap is shorter than [`GAP_OF_LENGTH`] of the
/// seam's length; none otherwise. An end's ball is the mean over the points within a bin
/// (two voxels) of it along the seam.
fn gap_bridge(points: &[MedialPoint], seam: &[usize], voxel: f64) -> Vec<(Vec3, f64)> {
    let on_seam: Vec<MedialPoint> = seam.iter().map(|&i| points[i]).collect();
    let positions: Vec<Vec3> = on_seam.iter().map(|p| p.position).collect();
    let arcs = arc_of_points(&on_seam, voxel);
    let (lo, hi) = (arcs.iter()).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &a| {
        (lo.min(a), hi.max(a))
    });
    let end = |at: f64| {
        let near: Vec<usize> = (0..seam.len())
            .filter(|&k| (arcs[k] - at).abs() <= 2.0 * voxel)
            .collect();
        let n = near.len().max(1) as f64;
        let centre = near.iter().map(|&k| positions[k]).sum::<Vec3>() / n;
        let ball = (near.iter())
            .map(|&k| ball_of(&points[seam[k]], voxel))
            .sum::<f64>()
            / n;
        (centre, ball)
    };
    let ((a, ball_a), (b, ball_b)) = (end(lo), end(hi));
    let gap = (b - a).norm();
    if gap >= GAP_OF_LENGTH * (hi - lo) {
        return Vec::new();
    }
    let steps = (gap / voxel).ceil().max(1.0) as usize;
    (0..=steps)
        .map(|k| {
            let t = k as f64 / steps as f64;
            (a + t * (b - a), ball_a + t * (ball_b - ball_a))
        })
        .collect()
}

/// The ball about a medial point whose points decide whether it is on a seam (mm).
pub(super) fn ball_of(p: &MedialPoint, voxel: f64) -> f64 {
    (BALL_VOXELS * voxel).max(BALL_RADII * p.radius)
}

/// [`branching`]'s step 1: the points about which the cloud is not flat.
struct NonFlat {
    positions: Vec<Vec3>,
    /// Each point's seam ball (mm, [`ball_of`]).
    ball: Vec<f64>,
    /// The widest ball.
    widest: f64,
    /// The points on seams, ascending.
    seam_points: Vec<usize>,
}

impl NonFlat {
    fn new(points: &[MedialPoint], voxel: f64) -> Self {
        let ball: Vec<f64> = points.iter().map(|p| ball_of(p, voxel)).collect();
        let widest = ball.iter().copied().fold(0.0, f64::max);
        let positions: Vec<Vec3> = points.iter().map(|p| p.position).collect();
        let grid = Grid::new(&positions, widest);
        let on_seam: Vec<bool> = (0..positions.len())
            .into_par_iter()
            .map(|i| {
                let near = grid.within(&positions, positions[i], ball[i]);
                near.len() >= MIN_BALL_POINTS && !flat(&positions, &near)
            })
            .collect();
        let seam_points = (0..positions.len()).filter(|&i| on_seam[i]).collect();
        Self {
            positions,
            ball,
            widest,
            seam_points,
        }
    }
}

/// [`branching`]'s steps 2–4 from its step 1 `non_flat`, with `bridges` (positions and balls)
/// among the seam points when the points are parted into pieces.
fn branches_bridged(non_flat: &NonFlat, voxel: f64, bridges: &[(Vec3, f64)]) -> Bridged {
    let NonFlat {
        positions,
        ball,
        widest,
        seam_points,
    } = non_flat;
    let widest = *widest;
    let seam_positions: Vec<Vec3> = (seam_points.iter().map(|&i| positions[i]))
        .chain(bridges.iter().map(|b| b.0))
        .collect();
    let seam_ball: Vec<f64> = (seam_points.iter().map(|&i| ball[i]))
        .chain(bridges.iter().map(|b| b.1))
        .collect();
    let seam_grid = Grid::new(&seam_positions, 2.0 * widest);
    // Seam points within the smaller of their balls are one seam: a seam's points, thinned
    // where it crosses the voxels obliquely, stay one.
    let seam_piece = {
        let mut uf = UnionFind::new(seam_positions.len());
        for (k, p) in seam_positions.iter().enumerate() {
            for j in seam_grid.within(&seam_positions, *p, seam_ball[k]) {
                if (seam_positions[j] - p).norm() <= seam_ball[j] {
                    uf.union(k, j);
                }
            }
        }
        (0..seam_positions.len())
            .map(|k| uf.find(k))
            .collect::<Vec<_>>()
    };
    // The seam point whose ball holds `p`, if any.
    let near_seam = |p: Vec3, times: f64| {
        seam_grid
            .within(&seam_positions, p, times * widest)
            .into_iter()
            .find(|&s| (seam_positions[s] - p).norm() <= times * seam_ball[s])
    };
    let sheet_points: Vec<usize> = (0..positions.len())
        .into_par_iter()
        .filter(|&i| near_seam(positions[i], 1.0).is_none())
        .collect();
    let sheet_positions: Vec<Vec3> = sheet_points.iter().map(|&i| positions[i]).collect();
    let sheet_piece = pieces(&sheet_positions, 1.5 * voxel);
    let mut size: HashMap<usize, usize> = HashMap::new();
    for &p in &sheet_piece {
        *size.entry(p).or_default() += 1;
    }
    let least = MIN_SHEET_FRACTION * positions.len() as f64;
    let kept: Vec<usize> = {
        let mut kept: Vec<usize> = (size.iter())
            .filter(|&(_, &n)| n as f64 >= least)
            .map(|(&p, _)| p)
            .collect();
        kept.sort_unstable();
        kept
    };
    // Which kept pieces reach each seam.
    let mut reach: HashMap<usize, HashSet<usize>> = HashMap::new();
    let reached: Vec<Option<usize>> = (0..sheet_points.len())
        .into_par_iter()
        .map(|k| {
            if kept.binary_search(&sheet_piece[k]).is_err() {
                return None;
            }
            near_seam(sheet_positions[k], 2.0)
        })
        .collect();
    for (k, s) in reached.into_iter().enumerate() {
        if let Some(s) = s {
            reach
                .entry(seam_piece[s])
                .or_default()
                .insert(sheet_piece[k]);
        }
    }
    let slot = |p: usize| kept.binary_search(&p).expect("a kept piece");
    let mut sheets = UnionFind::new(kept.len());
    // A seam is a line: its points span more than twice their mean ball (fewer are a spot
    // where sheets touch or a bump's tip, seen as non-flat by every ball about it).
    let mut span: HashMap<usize, (Vec3, Vec3, f64, usize)> = HashMap::new();
    for (k, p) in seam_positions.iter().enumerate() {
        let e = span.entry(seam_piece[k]).or_insert((*p, *p, 0.0, 0));
        e.0 = e.0.inf(p);
        e.1 = e.1.sup(p);
        e.2 += seam_ball[k];
        e.3 += 1;
    }
    let a_line = |seam: usize| {
        let (lo, hi, balls, n) = span[&seam];
        (hi - lo).norm() > 2.0 * balls / n as f64
    };
    let mut lines: Vec<(usize, Vec<usize>)> = (reach.iter())
        .map(|(&seam, pieces)| (seam, pieces.iter().map(|&p| slot(p)).collect()))
        .collect();
    lines.sort_unstable();
    // Seams first, ascending: lines that three or more pieces reach, with those pieces.
    let (seam_numbers, at_seams): (Vec<usize>, Vec<&[usize]>) = (lines.iter())
        .filter(|(seam, pieces)| pieces.len() >= 3 && a_line(*seam))
        .map(|(seam, pieces)| (*seam, &pieces[..]))
        .unzip();
    let mut two_sided = Vec::new();
    for (seam, pieces) in &lines {
        if let [a, b] = pieces[..] {
            if !parts_a_seam(&mut sheets, a, b, &at_seams) {
                sheets.union(a, b);
            }
            if a_line(*seam) {
                two_sided.push(*seam);
            }
        }
    }
    let two_sided = (two_sided.iter())
        .map(|&s| {
            (seam_points.iter().enumerate())
                .filter(|&(k, _)| seam_piece[k] == s)
                .map(|(_, &i)| i)
                .collect()
        })
        .collect();
    let roots: Vec<usize> = (0..kept.len()).map(|k| sheets.find(k)).collect();
    let mut distinct = roots.clone();
    distinct.sort_unstable();
    distinct.dedup();
    let number = |p: usize| distinct.binary_search(&roots[slot(p)]).expect("a root");
    let seam_sheets = (seam_numbers.iter())
        .map(|s| {
            let mut on: Vec<usize> = reach[s].iter().map(|&p| number(p)).collect();
            on.sort_unstable();
            on.dedup();
            on
        })
        .collect();
    let mut sheet = vec![None; positions.len()];
    for (k, &i) in sheet_points.iter().enumerate() {
        if kept.binary_search(&sheet_piece[k]).is_ok() {
            sheet[i] = Some(number(sheet_piece[k]));
        }
    }
    let mut seam = vec![None; positions.len()];
    for (k, &i) in seam_points.iter().enumerate() {
        seam[i] = seam_numbers.binary_search(&seam_piece[k]).ok();
    }
    assign_to_nearest_sheet(positions, &mut sheet, &seam, 2.0 * widest);
    let branches = Branches {
        counts: Branching {
            sheets: distinct.len(),
            seams: seam_numbers.len(),
            seam_points: seam_points.len(),
        },
        sheet,
        seam,
        seam_sheets,
    };
    Bridged {
        branches,
        two_sided,
    }
}

/// Whether joining the pieces `a` and `b` into one sheet (`sheets`, over the slots of the
/// kept pieces) would leave fewer than three sheets at one of the seams, each given by the
/// pieces that reach it (`at_seams`). A seam is where at least three sheets meet, so a spot
/// or line of non-flat points that only two of its pieces reach does not make them one sheet:
/// it is where the seam is broken (a ventricle's insertion lines fading at the RV's apex, the
/// walls near each other across the gap), not a fold of one sheet.
fn parts_a_seam(sheets: &mut UnionFind, a: usize, b: usize, at_seams: &[&[usize]]) -> bool {
    let (ra, rb) = (sheets.find(a), sheets.find(b));
    ra != rb
        && at_seams.iter().any(|pieces| {
            let mut roots: Vec<usize> = pieces.iter().map(|&p| sheets.find(p)).collect();
            roots.sort_unstable();
            roots.dedup();
            roots.len() < 4 && roots.contains(&ra) && roots.contains(&rb)
        })
}

/// Gives every point off the seams and off the sheets (`sheet` and `seam` both `None`) the
/// sheet of the nearest point of a sheet within `reach` mm, if any.
fn assign_to_nearest_sheet(
    positions: &[Vec3],
    sheet: &mut [Option<usize>],
    seam: &[Option<usize>],
    reach: f64,
) {
    let labelled: Vec<usize> = (0..positions.len())
        .filter(|&i| sheet[i].is_some())
        .collect();
    let labelled_positions: Vec<Vec3> = labelled.iter().map(|&i| positions[i]).collect();
    let grid = Grid::new(&labelled_positions, reach);
    let nearest: Vec<(usize, Option<usize>)> = (0..positions.len())
        .into_par_iter()
        .filter(|&i| sheet[i].is_none() && seam[i].is_none())
        .map(|i| {
            let near = grid.within(&labelled_positions, positions[i], reach);
            let distance = |k: &usize| (labelled_positions[*k] - positions[i]).norm();
            let best = near
                .into_iter()
                .min_by(|a, b| distance(a).total_cmp(&distance(b)));
            (i, best.and_then(|k| sheet[labelled[k]]))
        })
        .collect();
    for (i, s) in nearest {
        sheet[i] = s;
    }
}

/// Whether the medial points `points` within `radius` (mm) of `at` are flat, one sheet as
/// [`branching`] reads a ball (the smallest eigenvalue of their covariance below
/// [`SEAM_FLATNESS`] of its trace); none when fewer than [`MIN_BALL_POINTS`] lie there.
pub(crate) fn flat_about(points: &[MedialPoint], at: Vec3, radius: f64) -> Option<bool> {
    let positions: Vec<Vec3> = (points.iter())
        .map(|p| p.position)
        .filter(|p| (p - at).norm() <= radius)
        .collect();
    let all: Vec<usize> = (0..positions.len()).collect();
    (positions.len() >= MIN_BALL_POINTS).then(|| flat(&positions, &all))
}

/// Whether the points `near` of `positions` are flat: the smallest eigenvalue of their
/// covariance below [`SEAM_FLATNESS`] of its trace.
fn flat(positions: &[Vec3], near: &[usize]) -> bool {
    let n = near.len() as f64;
    let mean = near.iter().map(|&k| positions[k]).sum::<Vec3>() / n;
    let covariance = near
        .iter()
        .map(|&k| {
            let d = positions[k] - mean;
            d * d.transpose()
        })
        .sum::<Matrix3<f64>>()
        / n;
    let eigen = covariance.symmetric_eigenvalues();
    let smallest = eigen.min();
    smallest < SEAM_FLATNESS * eigen.sum()
}

/// A label per point: the pieces of `positions` joined where their cells of size `cell` touch
/// (26-neighbourhood).
fn pieces(positions: &[Vec3], cell: f64) -> Vec<usize> {
    let key = |p: &Vec3| p.map(|c| (c / cell).floor() as i64);
    let mut cells: HashMap<[i64; 3], usize> = HashMap::new();
    let cell_of: Vec<usize> = (positions.iter())
        .map(|p| {
            let k = key(p);
            let next = cells.len();
            *cells.entry([k.x, k.y, k.z]).or_insert(next)
        })
        .collect();
    let mut uf = UnionFind::new(cells.len());
    for (k, &c) in &cells {
        for d in 0..27 {
            let o = [d % 3, (d / 3) % 3, d / 9].map(|o| o as i64 - 1);
            if let Some(&other) = cells.get(&[k[0] + o[0], k[1] + o[1], k[2] + o[2]]) {
                uf.union(c, other);
            }
        }
    }
    cell_of.iter().map(|&c| uf.find(c)).collect()
}

/// Points bucketed in cubic cells of a given size.
struct Grid {
    cell: f64,
    cells: HashMap<[i64; 3], Vec<usize>>,
}

impl Grid {
    fn new(positions: &[Vec3], cell: f64) -> Self {
        let mut cells: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for (i, p) in positions.iter().enumerate() {
            cells.entry(Self::key(p, cell)).or_default().push(i);
        }
        Self { cell, cells }
    }

    fn key(p: &Vec3, cell: f64) -> [i64; 3] {
        [p.x, p.y, p.z].map(|c| (c / cell).floor() as i64)
    }

    /// The points within `radius` of `q`, ascending: those of the cells the ball's bounding
    /// box meets (for `radius ≤ cell` at most 8, often 1, where the 27 cells around `q` would
    /// hold up to 27 cells of points to test).
    fn within(&self, positions: &[Vec3], q: Vec3, radius: f64) -> Vec<usize> {
        let lo = Self::key(&(q - Vec3::repeat(radius)), self.cell);
        let hi = Self::key(&(q + Vec3::repeat(radius)), self.cell);
        let mut found = Vec::new();
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    let Some(cell) = self.cells.get(&[x, y, z]) else {
                        continue;
                    };
                    found.extend(
                        (cell.iter().copied()).filter(|&i| (positions[i] - q).norm() <= radius),
                    );
                }
            }
        }
        found.sort_unstable();
        found
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::construction::skeleton::ridge::LEFT_OUT_LIMIT;
    use crate::construction::skeleton::seam::Seam;
    use crate::construction::skeleton::{medial_pieces, medial_points, MIN_FEATURE_ANGLE_DEG};
    use crate::image::Volume;
    use nalgebra::{Matrix4, Vector4};

    /// A T of two walls of half thickness `h` (mm) on a grid of voxel `v`: the bar
    /// `|y| ≤ h, |x| ≤ 18` and the stem `|x| ≤ h, 0 ≤ y ≤ 18`, both `|z| ≤ 14` (a ventricle's
    /// wall running on through an insertion, the other wall branching off it).
    fn t_walls(h: f64, v: f64) -> Volume {
        let lo = Vec3::new(-20.0, -h - 2.0, -16.0);
        mask(lo, Vec3::new(40.0, 22.0 + h, 32.0), v, |p| {
            let bar = p.y.abs() <= h && p.x.abs() <= 18.0;
            let stem = p.x.abs() <= h && p.y >= 0.0 && p.y <= 18.0;
            (bar || stem) && p.z.abs() <= 14.0
        })
    }

    /// The mask (1 where `inside`) on the grid of voxel `v` whose first voxel centre is at
    /// `lo`, spanning `size` (mm).
    fn mask(lo: Vec3, size: Vec3, v: f64, inside: impl Fn(Vec3) -> bool) -> Volume {
        let dims = [0, 1, 2].map(|d| (size[d] / v) as usize);
        let mut m = Matrix4::new_scaling(v);
        m[(3, 3)] = 1.0;
        m.fixed_view_mut::<3, 1>(0, 3).copy_from(&lo);
        let [nx, ny, _] = dims;
        let data = (0..dims.iter().product())
            .map(|i| {
                let ijk = [i % nx, (i / nx) % ny, i / (nx * ny)].map(|c| c as f64);
                let p = m * Vector4::new(ijk[0], ijk[1], ijk[2], 1.0);
                f64::from(u8::from(inside(p.xyz())))
            })
            .collect();
        Volume::new(dims, data, m).unwrap()
    }

    /// Two ventricles in cross-section, extruded along z (`|z| ≤ 12`): the LV wall between
    /// circles of radii 12 and 20 about 0, the RV wall between circles of radii 16 and 20 about
    /// (16, 0), outside the LV's outer circle (walls 8 and 4 mm thick meeting at two
    /// insertions). With an RV wall of 1 or 2 mm (outer radius 17 or 18), or at 0.25 mm voxels,
    /// the RV's sheet is not kept: its medial points are cut off from the LV's where the RV wall
    /// widens into the LV's (decision 0402).
    pub(crate) struct Ventricles;

    impl Ventricles {
        const LV: [f64; 2] = [12.0, 20.0];
        pub(crate) const RV: [f64; 2] = [16.0, 20.0];
        const RV_CENTRE: [f64; 2] = [16.0, 0.0];

        fn rv(p: [f64; 2]) -> f64 {
            (p[0] - Self::RV_CENTRE[0]).hypot(p[1] - Self::RV_CENTRE[1])
        }

        fn inside(p: [f64; 2]) -> bool {
            Self::inside_with(p, Self::RV[0])
        }

        /// [`Ventricles::inside`] with the RV cavity of radius `rv_cavity` (its free wall
        /// `RV[1] − rv_cavity` thick).
        fn inside_with(p: [f64; 2], rv_cavity: f64) -> bool {
            let (lv, rv) = (p[0].hypot(p[1]), Self::rv(p));
            let wall = lv <= Self::LV[1] || rv <= Self::RV[1];
            let cavity = lv < Self::LV[0] || (rv < rv_cavity && lv > Self::LV[1]);
            wall && !cavity
        }

        /// The distance from `p` (in the wall) to the arc of the circle of `radius` about
        /// `centre` where `on` holds: to the circle where its nearest point there is on the arc,
        /// else to the nearer of the arc's ends (`ends`).
        fn to_arc(
            p: [f64; 2],
            centre: [f64; 2],
            radius: f64,
            on: impl Fn([f64; 2]) -> bool,
            ends: &[[f64; 2]],
        ) -> f64 {
            let d = [p[0] - centre[0], p[1] - centre[1]];
            let r = d[0].hypot(d[1]);
            let q = [centre[0] + radius * d[0] / r, centre[1] + radius * d[1] / r];
            if on(q) {
                return (r - radius).abs();
            }
            (ends.iter())
                .map(|e| (p[0] - e[0]).hypot(p[1] - e[1]))
                .fold(f64::INFINITY, f64::min)
        }

        /// The points where the circles of radius `r1` about 0 and `r2` about the RV's centre
        /// cross.
        fn crossings(r1: f64, r2: f64) -> [[f64; 2]; 2] {
            let c = Self::RV_CENTRE[0];
            let x = (r1 * r1 - r2 * r2 + c * c) / (2.0 * c);
            let y = (r1 * r1 - x * x).sqrt();
            [[x, y], [x, -y]]
        }

        /// The distances from `p` to the LV cavity, the RV cavity and the outside.
        fn distances(p: [f64; 2]) -> [f64; 3] {
            let [a, r] = Self::LV;
            let [b, big] = Self::RV;
            let cavity_ends = Self::crossings(r, b);
            let outer_ends = Self::crossings(r, big);
            let lv_cavity = p[0].hypot(p[1]) - a;
            let rv_cavity = Self::to_arc(
                p,
                Self::RV_CENTRE,
                b,
                |q| q[0].hypot(q[1]) >= r,
                &cavity_ends,
            )
            .min(Self::to_arc(
                p,
                [0.0, 0.0],
                r,
                |q| Self::rv(q) <= b,
                &cavity_ends,
            ));
            let outside = Self::to_arc(p, [0.0, 0.0], r, |q| Self::rv(q) >= big, &outer_ends).min(
                Self::to_arc(
                    p,
                    Self::RV_CENTRE,
                    big,
                    |q| q[0].hypot(q[1]) >= r,
                    &outer_ends,
                ),
            );
            [lv_cavity, rv_cavity, outside]
        }

        /// The upper insertion's junction: the point of the wall equidistant from the two
        /// cavities and the outside (searched on a 0.01 mm grid; the lower one is its mirror).
        fn junction() -> [f64; 2] {
            let mut best = ([0.0, 0.0], f64::INFINITY);
            for i in 0..=2000 {
                for j in 0..=1500 {
                    let p = [0.01 * i as f64, 5.0 + 0.01 * j as f64];
                    if !Self::inside(p) {
                        continue;
                    }
                    let [d1, d2, d3] = Self::distances(p);
                    let spread = d1.max(d2).max(d3) - d1.min(d2).min(d3);
                    if spread < best.1 {
                        best = (p, spread);
                    }
                }
            }
            assert!(best.1 < 0.02, "no junction: {best:?}");
            best.0
        }

        /// The shape on a grid of voxel `v`.
        fn mask(v: f64) -> Volume {
            Self::mask_with(v, Self::RV[0])
        }

        /// The shape with the RV cavity of radius `rv_cavity` on a grid of voxel `v`.
        pub(crate) fn mask_with(v: f64, rv_cavity: f64) -> Volume {
            Self::mask_sampled(v, rv_cavity, Vec3::zeros())
        }

        /// [`Ventricles::mask_with`] with the voxel centres moved by `phase` voxels.
        pub(crate) fn mask_sampled(v: f64, rv_cavity: f64, phase: Vec3) -> Volume {
            let lo = Vec3::new(-23.0, -23.0, -14.0) + v * phase;
            mask(lo, Vec3::new(60.0, 46.0, 28.0), v, |p| {
                Self::inside_with([p.x, p.y], rv_cavity) && p.z.abs() <= 12.0
            })
        }
    }

    #[test]
    fn two_ventricles_have_three_sheets_and_two_seams_at_their_insertions() {
        let v = 0.5;
        let truth = Ventricles::junction();
        let points = medial_points(&Ventricles::mask(v), MIN_FEATURE_ANGLE_DEG).unwrap();
        let branches = branching(&points, v);
        let counts = branches.counts;
        assert_eq!((counts.sheets, counts.seams), (3, 2), "{counts:?}");
        for k in 0..2 {
            let on_seam: Vec<MedialPoint> = (branches.seam_points(k).iter())
                .map(|&i| points[i])
                .collect();
            let seam = Seam::fit(&on_seam, v).unwrap();
            let middle: Vec<&Vec3> = seam.points.iter().filter(|p| p.z.abs() < 4.0).collect();
            assert!(middle.len() > 3, "{seam:?}");
            for p in middle {
                let off = (p.x - truth[0]).hypot(p.y.abs() - truth[1]);
                assert!(
                    off <= v,
                    "a seam vertex at {:?}, {off} mm from {truth:?}",
                    (p.x, p.y, p.z)
                );
            }
        }
    }

    /// Whether a wall is kept does not depend on the voxel: the 4 mm RV wall's medial points
    /// leave a gap of about a millimetre short of the insertions (where the radius grows fast),
    /// which a join of 1.5 voxels bridged at 0.5 mm and not at 0.35 or 0.25 mm (30.6 % of the
    /// shape left out); pieces within the smaller radius of each other are one.
    #[test]
    fn two_ventricles_keep_their_three_sheets_and_two_seams_on_finer_grids() {
        for v in [0.35, 0.25] {
            let (points, left_out) =
                medial_pieces(&Ventricles::mask(v), MIN_FEATURE_ANGLE_DEG).unwrap();
            assert!(left_out < 0.01 * LEFT_OUT_LIMIT, "{v} mm: {left_out}");
            let counts = branching(&points, v).counts;
            assert_eq!((counts.sheets, counts.seams), (3, 2), "{v} mm: {counts:?}");
        }
    }

    /// An RV free wall of 1.5 mm (three 0.5 mm voxels) tapers into the septum where its two
    /// sides stop facing each other: its medial points stop short of the rest, by less than the
    /// junction's radius, and join it as a wall (decision 0407). A wall apart from the rest by
    /// more than its radii (a plate beside the LV) is left out, and the share says so.
    #[test]
    fn a_thin_wall_joins_the_rest_across_its_taper_and_a_wall_apart_is_reported_left_out() {
        let v = 0.5;
        let share = |shape: &Volume| medial_pieces(shape, MIN_FEATURE_ANGLE_DEG).unwrap().1;
        for rv_cavity in [Ventricles::RV[0], Ventricles::RV[1] - 1.5] {
            let left_out = share(&Ventricles::mask_with(v, rv_cavity));
            assert!(left_out <= 0.01 * LEFT_OUT_LIMIT, "{rv_cavity}: {left_out}");
        }
        // The LV wall and a plate 4 mm thick, 9 mm beyond it (radii 4 and 2 mm).
        let lo = Vec3::new(-23.0, -23.0, -14.0);
        let apart = mask(lo, Vec3::new(60.0, 46.0, 28.0), v, |p| {
            let ring = (Ventricles::LV[0]..=Ventricles::LV[1]).contains(&p.x.hypot(p.y));
            let plate = (29.0..=33.0).contains(&p.x) && p.y.abs() <= 15.0;
            (ring || plate) && p.z.abs() <= 12.0
        });
        let left_out = share(&apart);
        assert!(left_out > LEFT_OUT_LIMIT, "{left_out}");
    }

    /// The 1.5 mm RV free wall joined across its taper: the points bridging the gap make its
    /// junctions with the LV seams (decision 0407; joined without them, the walls touch and no
    /// seam is found).
    #[test]
    fn a_thin_wall_joined_across_its_taper_meets_the_rest_at_two_seams() {
        let v = 0.5;
        let shape = Ventricles::mask_with(v, Ventricles::RV[1] - 1.5);
        let points = medial_points(&shape, MIN_FEATURE_ANGLE_DEG).unwrap();
        let counts = branching(&points, v).counts;
        assert_eq!((counts.sheets, counts.seams), (3, 2), "{counts:?}");
    }

    #[test]
    fn the_seam_of_a_t_of_thick_walls_lies_at_its_junction_within_a_voxel() {
        // The ball tangent to the bar's far face (y = −h) and to the two inner corners
        // (±h, h) of the T is centred at (0, h/4) with radius 5h/4: the junction of the
        // three sheets, not where the walls' mid-planes cross (y = 0). The sheets end about a
        // radius short of the flat ends (|z| ≤ 14): the seam is checked where it is straight.
        // Walls 16 voxels thick, as the heart's at its insertions: a ball of a few voxels
        // sees only a gentle fold there.
        let (h, v) = (4.0, 0.5);
        let points = medial_points(&t_walls(h, v), MIN_FEATURE_ANGLE_DEG).unwrap();
        let branches = branching(&points, v);
        let counts = branches.counts;
        assert_eq!((counts.sheets, counts.seams), (3, 1), "{counts:?}");
        let on_seam: Vec<MedialPoint> = (branches.seam_points(0).iter())
            .map(|&i| points[i])
            .collect();
        let seam = Seam::fit(&on_seam, v).unwrap();
        // The mask's faces lie half a voxel beyond the last voxel centres inside.
        let junction = (h + v / 2.0) / 4.0;
        let middle: Vec<&Vec3> = seam.points.iter().filter(|p| p.z.abs() < 5.0).collect();
        assert!(middle.len() > 5, "{seam:?}");
        for p in middle {
            let at = (p.x, p.y, p.z);
            assert!(
                p.x.abs() <= v && (p.y - junction).abs() <= v,
                "a seam vertex at {at:?}"
            );
        }
    }

    /// Points on a 0.5 mm grid of the half-planes `{w·u + z·e_z : 0 ≤ w ≤ 12, |z| ≤ 8}` for
    /// the directions `u` at the given angles (degrees).
    fn fins(angles: &[f64]) -> Vec<MedialPoint> {
        let mut points = Vec::new();
        for &a in angles {
            let u = Vec3::new(a.to_radians().cos(), a.to_radians().sin(), 0.0);
            for i in 0..=24 {
                for j in -16..=16 {
                    let p = 0.5 * i as f64 * u + Vec3::new(0.0, 0.0, 0.5 * j as f64);
                    if i > 0 || a == angles[0] {
                        points.push(MedialPoint {
                            position: p,
                            radius: 1.0,
                        });
                    }
                }
            }
        }
        points
    }

    #[test]
    fn three_fins_meet_at_one_seam_and_a_folded_sheet_is_one_sheet() {
        let points = fins(&[90.0, 210.0, 330.0]);
        let branches = branching(&points, 0.5);
        let toy = branches.counts;
        assert_eq!((toy.sheets, toy.seams), (3, 1), "{toy:?}");
        assert!(toy.seam_points > 0);
        assert_eq!(branches.seam_sheets, vec![vec![0, 1, 2]]);
        // Each fin is one sheet, the seam's points lie about the axis, and every point is on
        // one or the other.
        let mut fin_of_sheet = HashMap::new();
        for (p, (sheet, seam)) in points.iter().zip(branches.sheet.iter().zip(&branches.seam)) {
            let w = p.position.xy().norm();
            match (sheet, seam) {
                (Some(k), None) if w > 0.0 => {
                    let a = p.position.y.atan2(p.position.x).to_degrees().round() as i64;
                    assert_eq!(*fin_of_sheet.entry(*k).or_insert(a), a, "{p:?}");
                }
                (None, Some(0)) => assert!(w <= 2.0, "a seam point {w} mm off the axis"),
                other => panic!("{p:?} is {other:?}"),
            }
        }
        assert_eq!(fin_of_sheet.len(), 3);
        // A plate from the far edge of the first fin to that of the second (30° to each):
        // the two folds there are reached by two pieces each, but joining both would leave
        // the seam two sheets; the plate joins one of them.
        let a = Vec3::new(0.0, 12.0, 0.0);
        let b = 12.0 * Vec3::new(210f64.to_radians().cos(), 210f64.to_radians().sin(), 0.0);
        let mut closed = points.clone();
        for i in 1..41 {
            for j in -16..=16 {
                closed.push(MedialPoint {
                    position: a + (i as f64 / 41.0) * (b - a) + Vec3::new(0.0, 0.0, 0.5 * j as f64),
                    radius: 1.0,
                });
            }
        }
        let closed = branching(&closed, 0.5);
        assert_eq!(
            (closed.counts.sheets, closed.counts.seams),
            (3, 1),
            "{:?}",
            closed.counts
        );
        assert_eq!(closed.seam_sheets, vec![vec![0, 1, 2]]);
        // Two fins at 120°: one sheet folded along a line, not a seam.
        let fold = branching(&fins(&[90.0, 210.0]), 0.5).counts;
        assert_eq!((fold.sheets, fold.seams), (1, 0), "{fold:?}");
        // A flat sheet: no seam points at all.
        let flat = branching(&fins(&[0.0, 180.0]), 0.5).counts;
        assert_eq!((flat.sheets, flat.seams, flat.seam_points), (1, 0, 0));
    }
}
