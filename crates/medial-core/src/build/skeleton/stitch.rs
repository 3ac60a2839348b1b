//! Sheets built separately, stitched along the seams where they meet: the part of each sheet
//! that reaches over a seam is cut off, and the band between the cut and the seam's polyline
//! is triangulated, so that every seam edge is in exactly three triangles (one per sheet), the
//! non-manifold sheet [`inflate`](crate::build::inflate()) takes.

use std::collections::{HashMap, HashSet};

use super::seam::Seam;
use crate::build::inflate::MedialSheet;
use crate::{Error, Result, Vec3};

/// A sheet's vertices within this many lattice spacings of a seam are cut off: the sheet's own
/// border row along the seam (on it or just beyond, where the local fits extrapolate), so
/// that the band to the seam is about one spacing wide.
pub const CUT_SPACINGS: f64 = 0.5;

/// A sheet's vertices within this many seam radii of a seam are cut off too. Where three
/// sheets meet at 120°, the seam's spoke of radius `r` into the region between two of them
/// (along its bisector) ends `r·cos 60° = r/2` along either sheet from the seam, while a
/// sheet's spokes end over the sheet's point: the boundary folds over unless the sheet's
/// points next to the seam, after one subdivision half way across the band, are more than
/// `r/2` from it, so the band must be wider than `r`.
pub const CUT_RADII: f64 = 1.2;

/// The sheets `sheets` (each a triangulated disc, consistently oriented) stitched along the
/// seams `seams` (polylines sampled about as finely as the sheets), with `cut` (mm) the
/// distance from a seam within which a sheet's vertices are dropped. The stitched sheet's
/// points are the seams' vertices, seam after seam, then each sheet's kept vertices, sheet
/// after sheet; its triangles keep each sheet's orientation.
///
/// For every sheet: the vertices within `cut` of a seam or [`CUT_RADII`] times its radius
/// there are dropped with their triangles, then
/// the triangles left with two or three free edges (ears, which inflation refuses); its free
/// edges form loops; the longest run of consecutive loop vertices that lost a triangle and are
/// nearest to seam `s` is the cut along `s`, zipped to `s` ([`zip`]).
///
/// Errors: `InvalidVolume` when a sheet's free edges do not form simple loops after the cut
/// (it fell apart) or a seam has no sheet along it; those of [`MedialSheet::new`] (an edge in
/// more than three triangles: more than three sheets at a seam).
pub fn stitch(sheets: &[MedialSheet], seams: &[Seam], cut: f64) -> Result<MedialSheet> {
    let mut points: Vec<Vec3> = seams.iter().flat_map(|s| s.points.clone()).collect();
    let mut radius: Vec<f64> = seams.iter().flat_map(|s| s.radius.clone()).collect();
    let mut first = vec![0];
    for s in seams {
        first.push(first[first.len() - 1] + s.points.len());
    }
    let seam_vertices: Vec<Vec<usize>> = (0..seams.len())
        .map(|s| (first[s]..first[s + 1]).collect())
        .collect();
    let mut triangles = Vec::new();
    let mut sheets_along = vec![0; seams.len()];
    for sheet in sheets {
        let cut_sheet = CutSheet::new(sheet, seams, cut)?;
        let offset = points.len();
        let global: HashMap<usize, usize> = (cut_sheet.used.iter().enumerate())
            .map(|(k, &v)| (v, offset + k))
            .collect();
        points.extend(cut_sheet.used.iter().map(|&v| sheet.points()[v]));
        radius.extend(cut_sheet.used.iter().map(|&v| sheet.radius()[v]));
        triangles.extend(cut_sheet.triangles.iter().map(|t| t.map(|v| global[&v])));
        for (s, seam) in seams.iter().enumerate() {
            let Some(run) = cut_sheet.run_along(s, sheet, seams) else {
                continue;
            };
            sheets_along[s] += 1;
            let run: Vec<usize> = run.iter().map(|v| global[v]).collect();
            let along_run = points[run[run.len() - 1]] - points[run[0]];
            let mut b = seam_vertices[s].clone();
            if along_run.dot(&(seam.points[seam.points.len() - 1] - seam.points[0])) < 0.0 {
                b.reverse();
            }
            zip(&run, &b, &points, &mut triangles);
        }
    }
    if let Some(s) = sheets_along.iter().position(|&n| n == 0) {
        return Err(Error::InvalidVolume(format!(
            "no medial sheet reaches seam {s}: nothing to stitch along it"
        )));
    }
    MedialSheet::new(points, triangles, radius)
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
    /// `sheet` less its vertices within `cut` of a seam, their triangles, and the ears left.
    ///
    /// Errors: `InvalidVolume` when the free edges left do not form simple loops.
    fn new(sheet: &MedialSheet, seams: &[Seam], cut: f64) -> Result<Self> {
        let near_seam: Vec<bool> = (sheet.points().iter())
            .map(|p| (seams.iter()).any(|s| s.distance(p) <= cut.max(CUT_RADII * s.radius_near(p))))
            .collect();
        let mut triangles: Vec<[usize; 3]> = (sheet.triangles().iter())
            .filter(|t| t.iter().all(|&v| !near_seam[v]))
            .copied()
            .collect();
        loop {
            let free = free_edges(&triangles);
            let before = triangles.len();
            triangles.retain(|t| {
                (0..3)
                    .filter(|&k| free.contains(&(t[k], t[(k + 1) % 3])))
                    .count()
                    < 2
            });
            if triangles.len() == before {
                break;
            }
        }
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
        let loops = loops_of(&free_edges(&triangles))?;
        Ok(Self {
            triangles,
            used,
            loops,
            cut,
        })
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
fn free_edges(triangles: &[[usize; 3]]) -> HashSet<(usize, usize)> {
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

/// The loops of the directed free edges `free`; `InvalidVolume` when a vertex starts two.
fn loops_of(free: &HashSet<(usize, usize)>) -> Result<Vec<Vec<usize>>> {
    let mut next: HashMap<usize, usize> = HashMap::new();
    for &(u, v) in free {
        if next.insert(u, v).is_some() {
            return Err(Error::InvalidVolume(format!(
                "a medial sheet cut at a seam is pinched at its vertex {u}: two of its free \
                 edges start there"
            )));
        }
    }
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
    Ok(loops)
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
