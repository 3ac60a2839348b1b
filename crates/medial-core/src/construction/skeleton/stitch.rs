//! Sheets built separately, stitched along the seams where they meet: the part of each sheet
//! that reaches over a seam is cut off, and the band between the cut and the seam's polyline
//! is triangulated, so that every seam edge is in exactly three triangles (one per sheet), the
//! non-manifold sheet [`inflate`](crate::construction::inflate()) takes.

use std::collections::{HashMap, HashSet};

use super::seam::Seam;
use crate::construction::inflate::MedialSheet;
use crate::{Error, Result, Vec3};

/// A sheet's vertices within this many lattice spacings of a seam are cut off: the sheet's own
/// border row along the seam (on it or just beyond, where the local fits extrapolate), so
/// that the band to the seam is about one spacing wide.
pub const CUT_SPACINGS: f64 = 0.5;

/// A sheet's vertices within this many seam radii of a seam are cut off too. Where three
/// sheets meet at 120°, the seam's spoke of radius `r` into the region between two of them
/// (along its bisector) ends `r·cos 60° = r/2` along either sheet from the seam, while a
/// sheet's spokes end over the sheet's point: the boundary folds over unless the sheet's
/// points next to the seam, after one subdivision about half way across the band, are more
/// than `r/2` from it, so the band must be wider than `r`: with 1.2 the toy's mesh folds there
/// (its subdivided band points came `0.50·r` from the seam); 1.6 leaves a margin.
pub const CUT_RADII: f64 = 1.6;

/// A stitched sheet ([`stitch()`]).
#[derive(Clone, Debug)]
pub struct Stitch {
    /// The sheets as one: the kept seams' vertices, seam after seam, then each sheet's kept
    /// vertices, sheet after sheet; its triangles keep each sheet's orientation.
    pub sheet: MedialSheet,
    /// The sheet of each of its points (`None` on a seam).
    pub sheet_of_point: Vec<Option<usize>>,
    /// The seams stitched along, in their order: those some sheet reaches.
    pub seams: Vec<Seam>,
}

/// The sheets `sheets` (each a triangulated disc, consistently oriented) stitched along the
/// seams `seams` (polylines sampled about as finely as the sheets), with `cut` (mm) the
/// distance from a seam within which a sheet's vertices are dropped.
///
/// For every sheet: the vertices within `cut` of a seam or [`CUT_RADII`] times its radius
/// there are dropped with their triangles, and any vertex the cut leaves pinched (its kept
/// triangles two fans that meet only at it) with them; its free edges form loops; the
/// longest run of consecutive loop vertices that lost a triangle and are nearest to seam `s`
/// is the cut along `s`, zipped to `s` ([`zip`]). Then the ears are dropped (`drop_ears`)
/// and the points no triangle uses (the order of the others kept).
///
/// A seam along which no sheet's cut runs has nothing to stitch: a piece of a seam found
/// apart from a longer one beside it (a ring of insertion lines broken in two), every cut
/// vertex near it being nearer the longer one. It is dropped, and the sheets are cut and
/// stitched again along the others (the last seam first when several are unreached), so that
/// no band is cut off along a seam nothing fills.
///
/// Errors: `InvalidVolume` when no sheet reaches any seam; those of [`MedialSheet::new`] (an
/// edge in more than three triangles: more than three sheets at a seam).
pub fn stitch(sheets: &[MedialSheet], seams: &[Seam], cut: f64) -> Result<Stitch> {
    let mut seams = seams.to_vec();
    loop {
        let cut_sheets: Vec<CutSheet> = (sheets.iter())
            .map(|sheet| CutSheet::new(sheet, &seams, cut))
            .collect();
        let runs: Vec<Vec<Option<Vec<usize>>>> = (cut_sheets.iter().zip(sheets))
            .map(|(c, sheet)| {
                (0..seams.len())
                    .map(|s| c.run_along(s, sheet, &seams))
                    .collect()
            })
            .collect();
        let reached = |s: usize| runs.iter().any(|r| r[s].is_some());
        match (0..seams.len()).rev().find(|&s| !reached(s)) {
            Some(_) if seams.len() == 1 => {
                return Err(Error::InvalidVolume(
                    "no medial sheet reaches the seam found: nothing to stitch along it".into(),
                ))
            }
            Some(s) => {
                seams.remove(s);
            }
            None => return stitched(sheets, seams, &cut_sheets, &runs),
        }
    }
}

/// The sheets `sheets`, cut as `cut_sheets` say, zipped along the `seams` at the cuts' `runs`
/// (per sheet and seam): [`stitch()`] once every seam is reached.
fn stitched(
    sheets: &[MedialSheet],
    seams: Vec<Seam>,
    cut_sheets: &[CutSheet],
    runs: &[Vec<Option<Vec<usize>>>],
) -> Result<Stitch> {
    let mut points: Vec<Vec3> = seams.iter().flat_map(|s| s.points.clone()).collect();
    let mut radius: Vec<f64> = seams.iter().flat_map(|s| s.radius.clone()).collect();
    let mut label: Vec<Option<usize>> = vec![None; points.len()];
    let mut first = vec![0];
    for s in &seams {
        first.push(first[first.len() - 1] + s.points.len());
    }
    let mut triangles = Vec::new();
    for (k, (sheet, cut_sheet)) in sheets.iter().zip(cut_sheets).enumerate() {
        let offset = points.len();
        let global: HashMap<usize, usize> = (cut_sheet.used.iter().enumerate())
            .map(|(k, &v)| (v, offset + k))
            .collect();
        points.extend(cut_sheet.used.iter().map(|&v| sheet.points()[v]));
        radius.extend(cut_sheet.used.iter().map(|&v| sheet.radius()[v]));
        label.extend(cut_sheet.used.iter().map(|_| Some(k)));
        triangles.extend(cut_sheet.triangles.iter().map(|t| t.map(|v| global[&v])));
        for (s, seam) in seams.iter().enumerate() {
            let Some(run) = &runs[k][s] else {
                continue;
            };
            let mut run: Vec<usize> = run.iter().map(|v| global[v]).collect();
            // A seam that curves round on itself (a septum's rim) has its ends near each
            // other, and a run along it may pass from one end to the other: the run starts
            // after that step ([`wrap`]).
            let arcs: Vec<f64> = run.iter().map(|&v| seam.arc_of(&points[v])).collect();
            if let Some(k) = wrap(&arcs, seam.length()) {
                run.rotate_left(k + 1);
            }
            // The seam runs the run's way when its ends lie nearer the run's ends that way
            // than the other (a seam curved round on itself, as a ventricle's insertion
            // lines are, has ends too near each other for a direction between them to tell).
            let (start, end) = (points[run[0]], points[run[run.len() - 1]]);
            let (first_point, last_point) = (seam.points[0], seam.points[seam.points.len() - 1]);
            let mut b: Vec<usize> = (first[s]..first[s + 1]).collect();
            if (start - last_point).norm() + (end - first_point).norm()
                < (start - first_point).norm() + (end - last_point).norm()
            {
                b.reverse();
            }
            zip(&run, &b, &points, &mut triangles);
        }
    }
    drop_ears(&mut triangles);
    let (kept, triangles) = used_only(points.len(), &triangles);
    let sheet = MedialSheet::new(
        kept.iter().map(|&v| points[v]).collect(),
        triangles,
        kept.iter().map(|&v| radius[v]).collect(),
    )?;
    Ok(Stitch {
        sheet,
        sheet_of_point: kept.iter().map(|&v| label[v]).collect(),
        seams,
    })
}

/// Where the run of a sheet's cut whose points lie at arc lengths `arcs` along a seam of length
/// `length` passes from one end of the seam to the other, if it does: the index of the step's
/// first point. A run along a seam advances one way; a step against that way (the sign of the
/// sum of its other steps) longer than half the seam is the run passing round a seam curved
/// round on itself. A long step the way the run goes is a coarse run's step, not a wrap: the
/// septum's cut on a 1 mm two-ventricle heart steps 6.8 mm along a 13.6 mm seam.
fn wrap(arcs: &[f64], length: f64) -> Option<usize> {
    let steps: Vec<f64> = arcs.windows(2).map(|w| w[1] - w[0]).collect();
    let (k, step) =
        (steps.iter().copied().enumerate()).max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))?;
    let rest: f64 = steps.iter().sum::<f64>() - step;
    (step.abs() > 0.5 * length && step * rest < 0.0).then_some(k)
}

/// Drops the triangles with two or three free edges (ears: inflation refuses them, their
/// sides would collapse), again until none is left: the corners of a sheet cut across where
/// the cut meets its free edge. (Dropped before zipping they would eat a narrow strip left by
/// the cut from its ends, each triangle's cut edge being free then.)
fn drop_ears(triangles: &mut Vec<[usize; 3]>) {
    loop {
        let free = free_edges(triangles);
        let before = triangles.len();
        triangles.retain(|t| {
            let on_free = (0..3).filter(|&k| free.contains(&(t[k], t[(k + 1) % 3])));
            on_free.count() < 2
        });
        if triangles.len() == before {
            return;
        }
    }
}

/// The points that `triangles` use, ascending, and the triangles renumbered into them.
fn used_only(count: usize, triangles: &[[usize; 3]]) -> (Vec<usize>, Vec<[usize; 3]>) {
    let mut used = vec![false; count];
    triangles.iter().flatten().for_each(|&v| used[v] = true);
    let kept: Vec<usize> = (0..count).filter(|&v| used[v]).collect();
    let mut number = vec![0; count];
    kept.iter().enumerate().for_each(|(k, &v)| number[v] = k);
    let triangles = triangles.iter().map(|t| t.map(|v| number[v])).collect();
    (kept, triangles)
}

/// Triangulates the band between the cut `a` (a run of a sheet's free edge, in the direction
/// its triangles run along it) and the seam polyline `b` (in the same direction along the
/// seam), advancing along whichever of the two the shorter diagonal says (the greedy
/// 'zipper'): `[a_{i+1}, a_i, b_j]` when `|a_{i+1} − b_j| ≤ |a_i − b_{j+1}|`, else
/// `[a_i, b_j, b_{j+1}]`, until both ends are reached. The new triangles run along `a` against
/// the sheet's (so the sheet's orientation is kept) and use every edge of `b` once.
pub fn zip(a: &[usize], b: &[usize], points: &[Vec3], triangles: &mut Vec<[usize; 3]>) {
    let (m, n) = (a.len(), b.len());
    let (mut i, mut j) = (0, 0);
    let d = |u: usize, v: usize| (points[u] - points[v]).norm();
    while i + 1 < m || j + 1 < n {
        let along_a = j + 1 == n || (i + 1 < m && d(a[i + 1], b[j]) <= d(a[i], b[j + 1]));
        if along_a {
            triangles.push([a[i + 1], a[i], b[j]]);
            i += 1;
        } else {
            triangles.push([a[i], b[j], b[j + 1]]);
            j += 1;
        }
    }
}

/// A sheet with its part over the seams cut off.
struct CutSheet {
    /// The triangles kept (the sheet's vertex indices).
    triangles: Vec<[usize; 3]>,
    /// The vertices they use, ascending.
    used: Vec<usize>,
    /// The free edges' loops, each in the direction its triangles run along it.
    loops: Vec<Vec<usize>>,
    /// The kept vertices that lost a triangle to the cut.
    cut: HashSet<usize>,
}

impl CutSheet {
    /// `sheet` less its vertices within `cut` of a seam and their triangles, and less the
    /// vertices that leaves pinched (two fans of kept triangles meeting only at the vertex,
    /// where a cut's two sides touch), again until none is: its free edges then form simple
    /// loops.
    fn new(sheet: &MedialSheet, seams: &[Seam], cut: f64) -> Self {
        let mut dropped: Vec<bool> = (sheet.points().iter())
            .map(|p| (seams.iter()).any(|s| s.distance(p) <= cut.max(CUT_RADII * s.radius_near(p))))
            .collect();
        let (triangles, free) = loop {
            let triangles: Vec<[usize; 3]> = (sheet.triangles().iter())
                .filter(|t| t.iter().all(|&v| !dropped[v]))
                .copied()
                .collect();
            let free = free_edges(&triangles);
            let pinched = pinched(&free);
            if pinched.is_empty() {
                break (triangles, free);
            }
            pinched.into_iter().for_each(|v| dropped[v] = true);
        };
        let kept: HashSet<[usize; 3]> = triangles.iter().copied().collect();
        let used: HashSet<usize> = triangles.iter().flatten().copied().collect();
        let cut: HashSet<usize> = (sheet.triangles().iter())
            .filter(|t| !kept.contains(*t))
            .flatten()
            .copied()
            .filter(|v| used.contains(v))
            .collect();
        let mut used: Vec<usize> = used.into_iter().collect();
        used.sort_unstable();
        Self {
            loops: loops_of(&free),
            triangles,
            used,
            cut,
        }
    }

    /// The longest run of consecutive vertices of a free-edge loop that lost a triangle to the
    /// cut and are nearer to seam `s` than to any other; `None` when no such run has two
    /// vertices (the sheet does not reach the seam).
    fn run_along(&self, s: usize, sheet: &MedialSheet, seams: &[Seam]) -> Option<Vec<usize>> {
        let nearest = |v: usize| {
            let p = &sheet.points()[v];
            (0..seams.len()).min_by(|&a, &b| seams[a].distance(p).total_cmp(&seams[b].distance(p)))
                == Some(s)
        };
        let best = (self.loops.iter())
            .filter_map(|l| longest_run(l, |v| self.cut.contains(&v) && nearest(v)))
            .max_by_key(Vec::len);
        best.filter(|run| run.len() >= 2)
    }
}

/// The free edges of `triangles` (edges in one triangle), in the direction their triangle
/// runs.
pub(super) fn free_edges(triangles: &[[usize; 3]]) -> HashSet<(usize, usize)> {
    let mut count: HashMap<(usize, usize), usize> = HashMap::new();
    for t in triangles {
        for k in 0..3 {
            let (u, v) = (t[k], t[(k + 1) % 3]);
            *count.entry((u.min(v), u.max(v))).or_default() += 1;
        }
    }
    (triangles.iter())
        .flat_map(|t| (0..3).map(move |k| (t[k], t[(k + 1) % 3])))
        .filter(|&(u, v)| count[&(u.min(v), u.max(v))] == 1)
        .collect()
}

/// The vertices that start more than one of the directed free edges `free`, ascending: where
/// two fans of triangles meet at a vertex only.
fn pinched(free: &HashSet<(usize, usize)>) -> Vec<usize> {
    let mut starts: HashMap<usize, usize> = HashMap::new();
    free.iter()
        .for_each(|&(u, _)| *starts.entry(u).or_default() += 1);
    let mut pinched: Vec<usize> = (starts.into_iter())
        .filter_map(|(v, n)| (n > 1).then_some(v))
        .collect();
    pinched.sort_unstable();
    pinched
}

/// The loops of the directed free edges `free`, none of whose vertices is [`pinched`].
fn loops_of(free: &HashSet<(usize, usize)>) -> Vec<Vec<usize>> {
    let next: HashMap<usize, usize> = free.iter().copied().collect();
    let mut starts: Vec<usize> = next.keys().copied().collect();
    starts.sort_unstable();
    let mut seen = HashSet::new();
    let mut loops = Vec::new();
    for start in starts {
        let mut l = Vec::new();
        let mut v = start;
        while seen.insert(v) {
            l.push(v);
            v = next[&v];
        }
        if !l.is_empty() {
            loops.push(l);
        }
    }
    loops
}

/// The longest run of consecutive vertices of the cyclic `loop_` that satisfy `on` (the whole
/// loop when all do), in the loop's order; `None` when none does.
fn longest_run(loop_: &[usize], on: impl Fn(usize) -> bool) -> Option<Vec<usize>> {
    let n = loop_.len();
    let flags: Vec<bool> = loop_.iter().map(|&v| on(v)).collect();
    if flags.iter().all(|&f| f) {
        return Some(loop_.to_vec());
    }
    // Start just after a vertex that is off, so that no run wraps past the start.
    let start = (0..n).find(|&k| !flags[k])? + 1;
    let mut best: Vec<usize> = Vec::new();
    let mut current = Vec::new();
    for k in 0..n {
        let i = (start + k) % n;
        if flags[i] {
            current.push(loop_[i]);
            if current.len() > best.len() {
                best = current.clone();
            }
        } else {
            current.clear();
        }
    }
    (!best.is_empty()).then_some(best)
}

#[cfg(test)]
mod tests {
    use super::super::lattice::Lattice;
    use super::*;
    use crate::construction::inflate::inflate;
    use std::collections::BTreeMap;

    #[test]
    fn a_run_wraps_round_its_seam_only_against_its_own_direction() {
        // The septum's cut on a 1 mm two-ventricle shape: a long step the way the run goes.
        assert_eq!(wrap(&[13.64, 13.64, 11.61, 4.78, 1.80, 0.0], 13.64), None);
        // Runs passing round a seam curved round on itself (243 mm, as the biv-me heart's).
        let round = [150.0, 180.0, 220.0, 243.0, 5.0, 30.0, 60.0];
        assert_eq!(wrap(&round, 243.0), Some(3));
        let back: Vec<f64> = round.iter().rev().copied().collect();
        assert_eq!(wrap(&back, 243.0), Some(2));
        // Short steps, and a run of one point, do not wrap.
        assert_eq!(wrap(&[0.0, 2.0, 1.0, 3.0], 10.0), None);
        assert_eq!(wrap(&[4.0], 10.0), None);
    }

    /// Three fins at 120° about the z axis, each a lattice sheet of spacing 1 and `rings` rings
    /// reaching `over` mm across the axis (as a sheet fitted to its points and the seam's does),
    /// its triangles reversed on the second (the stitching keeps either orientation); and the
    /// seam, the z axis over the lattices' length, radius `seam_radius`.
    fn fins(rings: usize, over: f64, seam_radius: f64) -> (Vec<MedialSheet>, Seam) {
        let lattice = Lattice::new(rings, 8);
        let lo = lattice
            .points
            .iter()
            .map(|p| p[1])
            .fold(f64::INFINITY, f64::min);
        let sheets = (0..3)
            .map(|s| {
                let a = (90.0 + 120.0 * s as f64).to_radians();
                let u = Vec3::new(a.cos(), a.sin(), 0.0);
                let points: Vec<Vec3> = (lattice.points.iter())
                    .map(|p| (p[1] - lo - over) * u + Vec3::new(0.0, 0.0, p[0]))
                    .collect();
                let radius = points.iter().map(|p| 1.0 - 0.02 * p.xy().norm()).collect();
                let mut triangles = lattice.triangles.clone();
                if s == 1 {
                    triangles.iter_mut().for_each(|t| t.swap(1, 2));
                }
                MedialSheet::new(points, triangles, radius).unwrap()
            })
            .collect();
        let half = lattice.points.iter().map(|p| p[0]).fold(0.0, f64::max);
        let seam = Seam {
            points: vec![Vec3::new(0.0, 0.0, -half), Vec3::new(0.0, 0.0, half)],
            radius: vec![seam_radius; 2],
        }
        .resampled(1.0);
        (sheets, seam)
    }

    /// The undirected edges of `triangles` with how often each runs each way.
    fn directed(triangles: &[[usize; 3]]) -> BTreeMap<(usize, usize), [usize; 2]> {
        let mut count: BTreeMap<(usize, usize), [usize; 2]> = BTreeMap::new();
        for t in triangles {
            for k in 0..3 {
                let (u, v) = (t[k], t[(k + 1) % 3]);
                count.entry((u.min(v), u.max(v))).or_default()[usize::from(u > v)] += 1;
            }
        }
        count
    }

    #[test]
    fn three_fins_stitched_share_every_seam_edge_and_keep_their_orientation() {
        let (sheets, seam) = fins(3, 0.3, 1.0);
        let Stitch {
            sheet: stitched,
            sheet_of_point: label,
            ..
        } = stitch(&sheets, std::slice::from_ref(&seam), 0.5).unwrap();
        assert_eq!(label.len(), stitched.points().len());
        check_stitched(&stitched, &seam);
        // No vertex within the cut of the seam but the seam's, and the result inflates.
        for p in &stitched.points()[seam.points.len()..] {
            assert!(seam.distance(p) > CUT_RADII, "{p}");
        }
        inflate(&stitched.loop_subdivide().unwrap()).expect("an inflatable sheet");
    }

    #[test]
    fn a_narrow_strip_left_by_the_cut_is_stitched_whole() {
        // A seam of radius 2.6: the cut at 4.16 mm leaves each fin's two outer rows (4.76 and
        // 5.63 mm out), whose cut edges are free until zipped.
        let (sheets, seam) = fins(4, 1.3, 2.6);
        let Stitch {
            sheet: stitched,
            sheet_of_point: label,
            ..
        } = stitch(&sheets, std::slice::from_ref(&seam), 0.5).unwrap();
        assert_eq!(label.len(), stitched.points().len());
        check_stitched(&stitched, &seam);
        let kept: usize = (sheets.iter())
            .map(|s| {
                s.points()
                    .iter()
                    .filter(|p| seam.distance(p) > CUT_RADII * 2.6)
                    .count()
            })
            .sum();
        assert_eq!(stitched.points().len(), seam.points.len() + kept);
    }

    #[test]
    fn a_piece_of_seam_no_sheet_reaches_is_dropped_and_the_rest_stitched() {
        // A second seam just past the first's end, beyond the fins: every cut vertex is
        // nearer the first, so no sheet runs along the second (a ring of insertion lines
        // found in two pieces).
        let (sheets, seam) = fins(3, 0.3, 1.0);
        let end = seam.points[seam.points.len() - 1];
        let piece = Seam {
            points: vec![
                end + Vec3::new(0.0, 0.0, 0.5),
                end + Vec3::new(0.0, 0.0, 1.0),
            ],
            radius: vec![1.0; 2],
        };
        let stitched = stitch(&sheets, &[seam.clone(), piece.clone()], 0.5).unwrap();
        assert_eq!(stitched.seams.len(), 1);
        assert_eq!(stitched.seams[0].points, seam.points);
        check_stitched(&stitched.sheet, &seam);
        // A seam alone that no sheet reaches is an error.
        let e = stitch(&sheets, &[piece], 0.5).unwrap_err().to_string();
        assert!(e.contains("no medial sheet reaches the seam"), "{e}");
    }

    #[test]
    fn a_vertex_the_cut_leaves_pinched_is_dropped_too() {
        // A 5 × 5 grid of 1 mm squares, each split along its (i, j)–(i+1, j+1) diagonal; two
        // short seams at the centre vertex's neighbours (1, 2) and (3, 2) cut those off, which
        // leaves the centre's triangles two fans meeting only at it.
        let at = |i: usize, j: usize| 5 * j + i;
        let points: Vec<Vec3> = (0..25)
            .map(|v| Vec3::new((v % 5) as f64, (v / 5) as f64, 0.0))
            .collect();
        let triangles: Vec<[usize; 3]> = (0..4)
            .flat_map(|j| (0..4).map(move |i| (i, j)))
            .flat_map(|(i, j)| {
                let [a, b, c, d] = [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)];
                [[a, b, c], [a, c, d]]
            })
            .collect();
        let sheet = MedialSheet::new(points, triangles, vec![1.0; 25]).unwrap();
        let seam_at = |i: usize, j: usize| Seam {
            points: vec![
                Vec3::new(i as f64, j as f64, -0.1),
                Vec3::new(i as f64, j as f64, 0.1),
            ],
            radius: vec![0.1; 2],
        };
        let seams = [seam_at(1, 2), seam_at(3, 2)];
        let cut = CutSheet::new(&sheet, &seams, 0.5);
        for v in [at(1, 2), at(3, 2), at(2, 2)] {
            assert!(!cut.used.contains(&v), "vertex {v} is kept");
        }
        assert!(pinched(&free_edges(&cut.triangles)).is_empty());
        // Every kept vertex is on one loop once.
        let on_loops: usize = cut.loops.iter().map(Vec::len).sum();
        let free_vertices: HashSet<usize> = cut.loops.iter().flatten().copied().collect();
        assert_eq!(on_loops, free_vertices.len());
        assert_eq!(cut.used.len(), 25 - 3);
    }

    /// Every seam edge of `stitched` (along `seam`, its first vertices) is in exactly three
    /// triangles, every other edge in at most two, and the three sheets keep their orientation.
    fn check_stitched(stitched: &MedialSheet, seam: &Seam) {
        let seam_count = seam.points.len();
        let triangles = stitched.triangles();
        let edges = directed(triangles);
        for (&(u, v), n) in &edges {
            let on_seam = u < seam_count && v < seam_count;
            let total = n[0] + n[1];
            if on_seam {
                assert_eq!(v, u + 1, "a seam edge joins consecutive seam vertices");
                assert_eq!(total, 3, "seam edge {u}–{v}");
            } else {
                assert!(total <= 2, "edge {u}–{v} in {total} triangles");
            }
        }
        assert_eq!(
            (edges.keys())
                .filter(|(u, v)| *u < seam_count && *v < seam_count)
                .count(),
            seam_count - 1,
            "every seam edge is in the sheet"
        );
        // The pieces joined across edges of two triangles are the three sheets; within each an
        // edge runs at most once each way (orientation consistent).
        let mut pieces = crate::construction::inflate::UnionFind::new(triangles.len());
        let mut by_edge: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
        for (i, t) in triangles.iter().enumerate() {
            for k in 0..3 {
                let (u, v) = (t[k], t[(k + 1) % 3]);
                by_edge.entry((u.min(v), u.max(v))).or_default().push(i);
            }
        }
        for tris in by_edge.values() {
            if let [a, b] = tris[..] {
                pieces.union(a, b);
            }
        }
        let mut sheets_of: BTreeMap<usize, Vec<[usize; 3]>> = BTreeMap::new();
        for (i, t) in triangles.iter().enumerate() {
            sheets_of.entry(pieces.find(i)).or_default().push(*t);
        }
        assert_eq!(sheets_of.len(), 3);
        for piece in sheets_of.values() {
            assert!(directed(piece).values().all(|n| n[0] <= 1 && n[1] <= 1));
        }
    }

    #[test]
    fn the_zipper_uses_every_edge_of_both_polylines_once() {
        // A run of 4 points above a polyline of 6 along x.
        let mut points: Vec<Vec3> = (0..4).map(|i| Vec3::new(i as f64, 1.0, 0.0)).collect();
        points.extend((0..6).map(|j| Vec3::new(0.6 * j as f64, 0.0, 0.0)));
        let (a, b): (Vec<usize>, Vec<usize>) = ((0..4).collect(), (4..10).collect());
        let mut triangles = Vec::new();
        zip(&a, &b, &points, &mut triangles);
        assert_eq!(triangles.len(), 3 + 5);
        let edges = directed(&triangles);
        for w in a.windows(2) {
            assert_eq!(
                edges[&(w[0], w[1])],
                [0, 1],
                "the run is used against its direction"
            );
        }
        for w in b.windows(2) {
            assert_eq!(
                edges[&(w[0], w[1])],
                [1, 0],
                "the polyline along its direction"
            );
        }
        // Counter-clockwise seen from +z, as a sheet above the run (y > 1) whose triangles run
        // along it in +x is.
        for t in &triangles {
            let [p, q, r] = t.map(|k| points[k]);
            assert!((q - p).cross(&(r - p)).z > 0.0, "{t:?}");
        }
    }
}
