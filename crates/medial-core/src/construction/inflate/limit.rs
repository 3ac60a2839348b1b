//! Lowering the radius where it is too large for the sheet, so that inflation gives a valid
//! boundary (docs/decisions/0400-inflation-radius-limit.md).
//!
//! **The rule.** Seen from a spoke of atom `m` with direction `U` (without the tilt by the
//! radius gradient: the sheet's unit normal on that side, the in-plane outward direction at a
//! free edge, the bisector at a seam), every other medial point `x_j` gives the *focal bound*
//! `ρ = |d|² / (2 d·U)`, `d = x_j − x_m`, `d·U > 0`: the radius of the ball tangent to the
//! sheet at `x_m` on that side whose surface passes through `x_j`. A spoke longer than `ρ`
//! puts its tip `x_m + r·U` closer to `x_j` than to `x_m`, inside the ball of `x_j` (for equal
//! radii): the boundary of the side folds over. So `r_m ≤ c · min ρ`, with `c` = [`MARGIN`] < 1.
//! - On a smooth sheet, `ρ` over the neighbours is `1/κ` along each direction: `r·κ_max ≤ c`,
//!   the focal distance at which the two offsets of a curved sheet fold, with a margin.
//! - At a free edge, `ρ` is the radius of curvature of a concave outline, where the in-plane
//!   spokes converge.
//! - Across a seam, a spoke of sheet A at distance `L` from the seam and the point of sheet B
//!   at the same distance give `ρ = L·tan(θ/2)` (`θ` the angle between the sheets): the spoke
//!   must not cross the bisector, beyond which it meets the spokes of sheet B.
//! - Between parts of a sheet that come close (a thin gap), the same bound keeps the two
//!   boundaries apart.
//! - A seam spoke is the bisector of its wedge, not a medial spoke (its tip lies inside the
//!   true corner), so against the medial vertices it shares an edge with, it only must not
//!   pass their spokes: `r·(U·d̂) ≤ |d|`, `ρ = |d|² / (d·U)`.
//!
//! The limit is applied only to a sheet that, as given, inflates to a self-intersecting
//! boundary (a sheet that inflates validly is left as it is: the templates made from it do not
//! change). The bound depends on the sheet's shape, not on its radius, so one pass applies it. The
//! lowering is spread to the neighbours with a cosine taper (see [`lower`]) so that the
//! boundary stays smooth and the radius gradient grows by at most [`TAPER_SLOPE`]. Should the
//! boundary still intersect itself (the discrete boundary between atoms, the tilt of the spokes
//! by the radius gradient), the atoms of the intersecting triangles are shrunk by [`SHRINK`],
//! tapered the same way, at most [`SHRINK_ROUNDS`] times.

use std::collections::HashMap;
use std::f64::consts::PI;

use crate::Vec3;

/// The fraction `c` of the focal bound that a lowered radius keeps: a tip stays off the other
/// balls by a margin, so that the discrete boundary between atoms does not fold either. The
/// largest of 0.5, 0.6, …, 1.0 with which the rule alone (no shrink round) makes cmrep's
/// caudate sheet inflate at 1, 2 and 3 Loop subdivisions (the tuning case of
/// docs/decisions/0400-inflation-radius-limit.md).
pub(super) const MARGIN: f64 = 0.6;

/// The factor by which the atoms of self-intersecting triangles are shrunk in each round.
pub(super) const SHRINK: f64 = 0.8;

/// At most this many shrink rounds before inflation gives up.
pub(super) const SHRINK_ROUNDS: usize = 8;

/// The taper of a lowering adds at most this much to the radius gradient `|∇r|`.
pub(super) const TAPER_SLOPE: f64 = 0.25;

/// The taper of a lowering adds at most this much to `r·|r''|`: the envelope of the balls of
/// a flat sheet folds where `r·r''` reaches `1 − |∇r|²`.
pub(super) const TAPER_BEND: f64 = 0.25;

/// Where and by how much inflation lowered the sheet's radius.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RadiusLimit {
    /// The medial vertices whose radius was lowered, ascending (those the rule or a shrink
    /// bound, and their neighbours in the taper).
    pub vertices: Vec<usize>,
    /// The lowering of each, in % of the sheet's radius, in the order of `vertices`.
    pub reduction_pct: Vec<f64>,
    /// The medial vertices that the focal bound or a shrink bound (not only the taper),
    /// ascending.
    pub bound: Vec<usize>,
    /// Shrink rounds after a self-intersection.
    pub shrink_rounds: usize,
}

impl RadiusLimit {
    /// Compares the radii used with the sheet's; `bound` flags the atoms bound directly.
    pub(super) fn new(sheet: &[f64], used: &[f64], bound: &[bool], shrink_rounds: usize) -> Self {
        let (vertices, reduction_pct) = sheet
            .iter()
            .zip(used)
            .enumerate()
            .filter(|(_, (r, u))| u < r)
            .map(|(m, (r, u))| (m, 100.0 * (r - u) / r))
            .unzip();
        Self {
            vertices,
            reduction_pct,
            bound: (0..bound.len()).filter(|&m| bound[m]).collect(),
            shrink_rounds,
        }
    }

    /// The largest lowering (% of the sheet's radius), 0 when none.
    pub fn max_pct(&self) -> f64 {
        self.reduction_pct.iter().copied().fold(0.0, f64::max)
    }

    /// The mean lowering over the lowered vertices (%), 0 when none.
    pub fn mean_pct(&self) -> f64 {
        match self.reduction_pct.len() {
            0 => 0.0,
            n => self.reduction_pct.iter().sum::<f64>() / n as f64,
        }
    }
}

/// A uniform grid of medial points for range queries.
pub(super) struct Grid<'a> {
    points: &'a [Vec3],
    cell: f64,
    cells: HashMap<[i64; 3], Vec<usize>>,
}

impl<'a> Grid<'a> {
    pub(super) fn new(points: &'a [Vec3], cell: f64) -> Self {
        let cell = cell.max(f64::MIN_POSITIVE);
        let mut cells: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for (i, p) in points.iter().enumerate() {
            cells.entry(key(p, cell)).or_default().push(i);
        }
        Self {
            points,
            cell,
            cells,
        }
    }

    /// Calls `visit(j, |x_j − centre|)` for every point within `reach` of `centre`.
    pub(super) fn within(&self, centre: &Vec3, reach: f64, mut visit: impl FnMut(usize, f64)) {
        let k = (reach / self.cell).ceil() as i64;
        let c = key(centre, self.cell);
        for i in -k..=k {
            for j in -k..=k {
                for l in -k..=k {
                    let Some(members) = self.cells.get(&[c[0] + i, c[1] + j, c[2] + l]) else {
                        continue;
                    };
                    for &x in members {
                        let s = (self.points[x] - centre).norm();
                        if s < reach {
                            visit(x, s);
                        }
                    }
                }
            }
        }
    }
}

fn key(p: &Vec3, cell: f64) -> [i64; 3] {
    [0, 1, 2].map(|i| (p[i] / cell).floor() as i64)
}

/// The focal bound `min ρ` of every atom (infinite where nothing bounds it), from the fold
/// direction `U_b` of every boundary vertex `b` of atom `atom[b]`; `seam` flags the atoms with
/// three spokes or more and `neighbours` lists the medial vertices joined to each by an edge.
/// Only medial points within `2 r_m` of `x_m` are visited: farther ones give `ρ > r_m`.
pub(super) fn focal_bounds(
    points: &[Vec3],
    radius: &[f64],
    atom: &[usize],
    directions: &[Vec3],
    seam: &[bool],
    neighbours: &[Vec<usize>],
) -> Vec<f64> {
    let r_max = radius.iter().copied().fold(0.0, f64::max);
    let grid = Grid::new(points, 2.0 * r_max);
    let mut bound = vec![f64::INFINITY; points.len()];
    for (&m, u) in atom.iter().zip(directions) {
        grid.within(&points[m], 2.0 * radius[m], |j, _| {
            let d = points[j] - points[m];
            let du = d.dot(u);
            if j == m || du <= 0.0 {
                return;
            }
            let rho = if seam[m] && neighbours[m].contains(&j) {
                d.norm_squared() / du
            } else {
                d.norm_squared() / (2.0 * du)
            };
            bound[m] = bound[m].min(rho);
        });
    }
    bound
}

/// Lowers every radius `r_j` with `factor[j] < 1` to `factor[j]·r_j`, and its neighbours within
/// `D_j` of it by the fraction `a·w(s / D_j)`, `a = 1 − factor[j]`, `w(x) = (1 + cos πx) / 2`.
/// The lowered radius `r(1 − a·w)` has slope at most `π a r / (2 D)` and `r·|r''|` at most
/// `π² a r² / (2 D²)`, so `D_j = max(π a r_j / (2 TAPER_SLOPE), π r_j √(a / (2 TAPER_BEND)),
/// 2 h_j)` keeps them below [`TAPER_SLOPE`] and [`TAPER_BEND`] (`h_j` the longest sheet edge at
/// `j`: the taper reaches at least the second ring of neighbours). Where tapers overlap, the
/// largest lowering wins, so every bound still holds.
pub(super) fn lower(points: &[Vec3], radius: &mut [f64], factor: &[f64], longest_edge: &[f64]) {
    let lowered: Vec<usize> = (0..factor.len()).filter(|&j| factor[j] < 1.0).collect();
    if lowered.is_empty() {
        return;
    }
    let fraction = |j: usize| 1.0 - factor[j].max(0.0);
    let reach: Vec<f64> = lowered
        .iter()
        .map(|&j| {
            let (a, r) = (fraction(j), radius[j]);
            (PI * a * r / (2.0 * TAPER_SLOPE))
                .max(PI * r * (a / (2.0 * TAPER_BEND)).sqrt())
                .max(2.0 * longest_edge[j])
        })
        .collect();
    let grid = Grid::new(points, reach.iter().copied().fold(0.0, f64::max));
    let mut keep = vec![1.0_f64; points.len()];
    for (&j, &reach) in lowered.iter().zip(&reach) {
        let a = fraction(j);
        grid.within(&points[j], reach, |m, s| {
            let w = 0.5 * (1.0 + (PI * s / reach).cos());
            keep[m] = keep[m].min(1.0 - a * w);
        });
    }
    radius.iter_mut().zip(&keep).for_each(|(r, k)| *r *= k);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_focal_bound_on_a_circle_is_its_radius() {
        // Medial points on a circle of radius 1 (a cylinder's section), spokes toward the
        // centre: every other point of the circle lies on the ball of radius 1 tangent there.
        let n = 24;
        let points: Vec<Vec3> = (0..n)
            .map(|k| {
                let a = 2.0 * PI * k as f64 / n as f64;
                Vec3::new(a.cos(), a.sin(), 0.0)
            })
            .collect();
        let inward: Vec<Vec3> = points.iter().map(|p| -p).collect();
        let atom: Vec<usize> = (0..n).collect();
        let neighbours: Vec<Vec<usize>> =
            (0..n).map(|k| vec![(k + 1) % n, (k + n - 1) % n]).collect();
        let bounds = |r: f64, dirs: &[Vec3], seam: bool| {
            focal_bounds(
                &points,
                &vec![r; n],
                &atom,
                dirs,
                &vec![seam; n],
                &neighbours,
            )
        };
        assert!(bounds(1.5, &inward, false)
            .iter()
            .all(|&b| (b - 1.0).abs() < 1e-9));
        // A short radius does not look far enough to see a bound of 1 (the neighbours are
        // 0.26 apart) …
        assert!(bounds(0.1, &inward, false).iter().all(|&b| b.is_infinite()));
        // … the convex side is never bound …
        assert!(bounds(1.5, &points, false).iter().all(|&b| b.is_infinite()));
        // … and a seam spoke only must not pass its neighbours' spokes: twice the bound, where
        // only the neighbours are in reach.
        assert!(bounds(0.2, &inward, false)
            .iter()
            .all(|&b| (b - 1.0).abs() < 1e-9));
        let seam = bounds(0.2, &inward, true);
        assert!(seam.iter().all(|&b| (b - 2.0).abs() < 1e-9), "{seam:?}");
    }

    #[test]
    fn the_taper_keeps_the_bound_and_its_slope() {
        // Halving a radius of 2 reaches π · 0.5 · 2 / (2 · 0.25) = 2π along a line of points.
        let points: Vec<Vec3> = (0..201)
            .map(|k| Vec3::new(0.1 * k as f64, 0.0, 0.0))
            .collect();
        let mut radius = vec![2.0; 201];
        let mut factor = vec![1.0; 201];
        factor[100] = 0.5;
        lower(&points, &mut radius, &factor, &[0.1; 201]);
        assert!((radius[100] - 1.0).abs() < 1e-12);
        assert!(
            radius[38] < 2.0 && radius[162] < 2.0,
            "the taper reaches 2π"
        );
        assert_eq!((radius[0], radius[37], radius[163]), (2.0, 2.0, 2.0));
        let slope = radius
            .windows(2)
            .map(|w| (w[1] - w[0]).abs() / 0.1)
            .fold(0.0, f64::max);
        assert!(slope <= TAPER_SLOPE + 1e-9, "slope {slope}");
        let bend = radius
            .windows(3)
            .map(|w| w[1] * (w[0] - 2.0 * w[1] + w[2]).abs() / 0.01)
            .fold(0.0, f64::max);
        assert!(bend <= TAPER_BEND + 1e-3, "r·|r''| {bend}");
        assert!(radius.iter().all(|&r| (1.0..=2.0).contains(&r)));
    }
}
