//! The region a sheet's medial points cover in its chart, as a triangulated disc of grid cells,
//! and its harmonic (Tutte) map onto a [`Lattice`] hexagon: a one-to-one parametrisation of any
//! simply connected sheet, star-shaped or not (a crescent like cmrep's t001 is not).

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};

use super::lattice::Lattice;
use crate::{Error, Result, Vec3};

/// A cell holding fewer points than this fraction of the median over the cells with points is
/// empty: the ragged fringe of stray points beyond a rim is not part of the sheet.
const SPARSE_FRACTION: f64 = 0.25;

/// Relative residual at which the conjugate gradients of the harmonic map stop.
const CG_TOLERANCE: f64 = 1e-10;

/// The cells of a square grid in the chart that hold medial points (at least [`SPARSE_FRACTION`]
/// of the median count), cleaned into a
/// topological disc: closed (bridging the gaps between points and the inlets of the outline)
/// and opened by one cell (cutting one-cell spurs), its largest edge-connected piece, holes
/// filled, cells touching only at a corner joined: its outline runs along the outer side of
/// the outermost cells with points, on average half a cell beyond the outermost points. Triangulated with the cell corners as
/// vertices, two triangles a cell.
pub(super) struct Region {
    /// Chart positions of the cell corners (mm).
    corners: Vec<[f64; 2]>,
    /// The corners in space (mm): the mean medial point of the cells around them (the chart's
    /// surface where they hold none). Lengths along the outline are measured there, not in the
    /// chart, which stretches a bowl's rim.
    lifted: Vec<Vec3>,
    /// Two counter-clockwise triangles per cell (indices into `corners`).
    triangles: Vec<[usize; 3]>,
    /// The outline: the corners on it, counter-clockwise.
    outline: Vec<usize>,
    /// Positions in `outline` of the ends of the region's longest geodesic (its tips).
    tips: [usize; 2],
    /// Area on the chart's surface (mm²).
    area: f64,
    /// Length on the chart's surface of the longest geodesic between cells (mm).
    length: f64,
    /// Half the width, in corners, of the moving mean that smooths the outline before its
    /// arc length is measured (the closing's cells, at least 2).
    smoothing: usize,
}

/// A boolean grid of `dims[0] × dims[1]` cells.
#[derive(Clone, PartialEq)]
struct Cells {
    dims: [usize; 2],
    on: Vec<bool>,
}

impl Cells {
    fn get(&self, i: i64, j: i64) -> bool {
        let [nx, ny] = self.dims.map(|d| d as i64);
        (0..nx).contains(&i) && (0..ny).contains(&j) && self.on[(j * nx + i) as usize]
    }

    fn ij(&self, c: usize) -> (i64, i64) {
        ((c % self.dims[0]) as i64, (c / self.dims[0]) as i64)
    }

    /// Each cell set to `any` (dilation) or `all` (erosion) of its 3×3 neighbourhood.
    fn morph(&self, dilate: bool) -> Self {
        let on = (0..self.on.len())
            .map(|c| {
                let (i, j) = self.ij(c);
                let mut around = (0..9).map(|d| self.get(i + d % 3 - 1, j + d / 3 - 1));
                if dilate {
                    around.any(|v| v)
                } else {
                    around.all(|v| v)
                }
            })
            .collect();
        Self {
            dims: self.dims,
            on,
        }
    }

    /// The edge-connected pieces of the cells equal to `value`: a label per cell (`None` for
    /// the others) and the size of each piece.
    fn pieces(&self, value: bool) -> (Vec<Option<usize>>, Vec<usize>) {
        let mut label = vec![None; self.on.len()];
        let mut sizes = Vec::new();
        for start in 0..self.on.len() {
            if self.on[start] != value || label[start].is_some() {
                continue;
            }
            let id = sizes.len();
            let mut stack = vec![start];
            label[start] = Some(id);
            let mut size = 0;
            while let Some(c) = stack.pop() {
                size += 1;
                let (i, j) = self.ij(c);
                for (di, dj) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                    let (a, b) = (i + di, j + dj);
                    let [nx, ny] = self.dims.map(|d| d as i64);
                    if !((0..nx).contains(&a) && (0..ny).contains(&b)) {
                        continue;
                    }
                    let n = (b * nx + a) as usize;
                    if self.on[n] == value && label[n].is_none() {
                        label[n] = Some(id);
                        stack.push(n);
                    }
                }
            }
            sizes.push(size);
        }
        (label, sizes)
    }

    /// Keeps the largest edge-connected piece.
    fn largest(&mut self) {
        let (label, sizes) = self.pieces(true);
        let best = (0..sizes.len()).max_by_key(|&k| (sizes[k], Reverse(k)));
        for (on, l) in self.on.iter_mut().zip(label) {
            *on = l.is_some() && l == best;
        }
    }

    /// Fills the background pieces that do not reach the grid's border, and the two empty
    /// cells of every 2×2 block whose full cells touch only at a corner, until neither is left:
    /// the outline is then one simple loop.
    fn fill(&mut self) {
        loop {
            let before = self.clone();
            let (label, _) = self.pieces(false);
            let mut outside = std::collections::HashSet::new();
            let [nx, ny] = self.dims.map(|d| d as i64);
            for (c, l) in label.iter().enumerate() {
                let (i, j) = self.ij(c);
                if i == 0 || j == 0 || i == nx - 1 || j == ny - 1 {
                    outside.extend(*l);
                }
            }
            for (on, l) in self.on.iter_mut().zip(&label) {
                *on |= l.is_some_and(|l| !outside.contains(&l));
            }
            let nx = self.dims[0];
            for c in 0..self.on.len() {
                let (i, j) = self.ij(c);
                let block = [(0, 0), (1, 0), (0, 1), (1, 1)].map(|(a, b)| self.get(i + a, j + b));
                if block == [true, false, false, true] || block == [false, true, true, false] {
                    self.on[c] = true;
                    self.on[c + 1] = true;
                    self.on[c + nx] = true;
                    self.on[c + nx + 1] = true;
                }
            }
            if *self == before {
                return;
            }
        }
    }
}

impl Region {
    /// The region of the medial points `points` (chart coordinates, position in space) on a
    /// grid of `cell` mm, closed by `closing ≥ 1` cells (see the type: inlets of the outline
    /// narrower than about `2·closing` cells are filled, so that they do not take a share of
    /// the border); area and length are measured on the chart's surface (`lift` maps chart
    /// positions onto it), the outline's arc length in space, through the mean point of the
    /// cells around each corner (the chart's surface where they hold none).
    ///
    /// Errors: `InvalidVolume` when fewer than four cells are left.
    pub(super) fn of(
        points: &[([f64; 2], Vec3)],
        cell: f64,
        closing: usize,
        lift: &dyn Fn([f64; 2]) -> Vec3,
    ) -> Result<Self> {
        if points.is_empty() {
            return Err(Error::InvalidVolume(
                "no medial points to chart: too few for a sheet".into(),
            ));
        }
        let lo = [0, 1].map(|a| points.iter().map(|q| q.0[a]).fold(f64::INFINITY, f64::min));
        let hi = [0, 1].map(|a| (points.iter().map(|q| q.0[a])).fold(f64::NEG_INFINITY, f64::max));
        // A margin of cells, so that no morphology or filling reaches the grid's border.
        let margin = closing + 3;
        let origin = lo.map(|l| l - margin as f64 * cell);
        let dims = [0, 1].map(|a| ((hi[a] - lo[a]) / cell).floor() as usize + 2 * margin + 1);
        let mut per_cell = vec![0usize; dims[0] * dims[1]];
        let mut sum = vec![Vec3::zeros(); dims[0] * dims[1]];
        for (q, p) in points {
            let [i, j] = [0, 1].map(|a| ((q[a] - origin[a]) / cell).floor() as usize);
            per_cell[j * dims[0] + i] += 1;
            sum[j * dims[0] + i] += p;
        }
        let mut held: Vec<usize> = per_cell.iter().copied().filter(|&c| c > 0).collect();
        held.sort_unstable();
        let least = ((SPARSE_FRACTION * held[held.len() / 2] as f64).ceil() as usize).max(1);
        let cells = Cells {
            dims,
            on: per_cell.iter().map(|&c| c >= least).collect(),
        };
        let mut cells = (0..2 * closing + 2).fold(cells, |cells, step| {
            // closing dilations, closing erosions, then erode and dilate (opening).
            cells.morph(step < closing || step == 2 * closing + 1)
        });
        cells.largest();
        cells.fill();
        let count = cells.on.iter().filter(|&&v| v).count();
        if count < 4 {
            return Err(Error::InvalidVolume(format!(
                "the medial points cover {count} cells of {cell:.2} mm in their chart: too few \
                 for a sheet"
            )));
        }
        let mut corner_of: HashMap<(i64, i64), usize> = HashMap::new();
        let mut corners = Vec::new();
        let mut corner = |i: i64, j: i64| {
            *corner_of.entry((i, j)).or_insert_with(|| {
                corners.push([origin[0] + i as f64 * cell, origin[1] + j as f64 * cell]);
                corners.len() - 1
            })
        };
        let mut triangles = Vec::new();
        let mut next: HashMap<usize, usize> = HashMap::new();
        let full: Vec<usize> = (0..cells.on.len()).filter(|&c| cells.on[c]).collect();
        for &c in &full {
            let (i, j) = cells.ij(c);
            let v = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)].map(|(a, b)| corner(a, b));
            triangles.extend([[v[0], v[1], v[2]], [v[0], v[2], v[3]]]);
            // Outline edges with the region on their left.
            for (side, (di, dj)) in [(0, -1), (1, 0), (0, 1), (-1, 0)].into_iter().enumerate() {
                if !cells.get(i + di, j + dj) {
                    next.insert(v[side], v[(side + 1) % 4]);
                }
            }
        }
        let outline = loop_of(&next)?;
        let held = |i: i64, j: i64| {
            let c = (j * dims[0] as i64 + i) as usize;
            (cells.get(i, j) && per_cell[c] > 0).then(|| sum[c] / per_cell[c] as f64)
        };
        let lifted: Vec<Vec3> = (corners.iter())
            .map(|&q| {
                let [i, j] = [0, 1].map(|a| ((q[a] - origin[a]) / cell).round() as i64);
                let around: Vec<Vec3> = [(i - 1, j - 1), (i, j - 1), (i - 1, j), (i, j)]
                    .into_iter()
                    .filter_map(|(a, b)| held(a, b))
                    .collect();
                if around.is_empty() {
                    lift(q)
                } else {
                    around.iter().sum::<Vec3>() / around.len() as f64
                }
            })
            .collect();
        let area: f64 = (triangles.iter())
            .map(|t| {
                let [a, b, c] = t.map(|k| lift(corners[k]));
                (b - a).cross(&(c - a)).norm() / 2.0
            })
            .sum();
        let centre = |c: usize| {
            let (i, j) = cells.ij(c);
            [
                origin[0] + (i as f64 + 0.5) * cell,
                origin[1] + (j as f64 + 0.5) * cell,
            ]
        };
        let (tip_cells, length) = longest_geodesic(&cells, &full, &|c| lift(centre(c)));
        let length = length + (area / count as f64).sqrt();
        let tips = tip_cells.map(|c| {
            let q = centre(c);
            let d = |k: &usize| {
                let p = corners[outline[*k]];
                (p[0] - q[0]).hypot(p[1] - q[1])
            };
            (0..outline.len())
                .min_by(|a, b| d(a).total_cmp(&d(b)))
                .expect("an outline has corners")
        });
        if tips[0] == tips[1] {
            return Err(Error::InvalidVolume(
                "the medial points' region in their chart has no length".into(),
            ));
        }
        Ok(Self {
            corners,
            lifted,
            triangles,
            outline,
            tips,
            area,
            length,
            smoothing: closing.max(2),
        })
    }

    /// `L²/A`: the squared length of the longest geodesic over the area (4/π for a disc).
    pub(super) fn elongation(&self) -> f64 {
        self.length * self.length / self.area
    }

    /// Area on the chart's surface (mm²).
    pub(super) fn area(&self) -> f64 {
        self.area
    }

    /// The chart positions of the points of `lattice`, through the harmonic map of the region
    /// onto it: the outline mapped onto the hexagon's border proportionally to arc length (in
    /// space), one tip to the left tip and, for a stretched hexagon, the other to the right
    /// one; every inner corner the mean of its
    /// neighbours (Tutte's embedding: one-to-one onto the convex hexagon, Floater 2003). Border
    /// points of the lattice go to the outline at the matching arc length, inner ones to the
    /// corners' barycentric combination in the triangle that holds them.
    ///
    /// Errors: `InvalidVolume` when the harmonic map does not converge.
    pub(super) fn map_onto(&self, lattice: &Lattice) -> Result<Vec<[f64; 2]>> {
        let m = self.outline.len();
        let corner = |k: usize| self.outline[(self.tips[0] + k) % m];
        let at = |k: usize| self.corners[corner(k)];
        // Arc length along the outline from the first tip, in space, of the outline smoothed by
        // a moving mean over 2·smoothing + 1 corners (the staircase of the cells and the jitter
        // of the cells' mean points would lengthen it unevenly).
        let w = self.smoothing.min((m - 1) / 2);
        let smooth = |k: usize| {
            (0..=2 * w)
                .map(|d| self.lifted[corner(k + m + d - w)])
                .sum::<Vec3>()
                / (2 * w + 1) as f64
        };
        let mut arc = vec![0.0; m + 1];
        for k in 0..m {
            arc[k + 1] = arc[k] + (smooth(k + 1) - smooth(k)).norm();
        }
        // A regular hexagon takes the outline by arc length from the first tip; a stretched
        // one has its tips at the region's.
        let total = arc[m];
        let first = if lattice.stretch == 0 {
            total / 2.0
        } else {
            arc[(self.tips[1] + m - self.tips[0]) % m]
        };
        let half = lattice.border.len() as f64 / 2.0;
        // Outline arc length s ↦ hexagon border arc (lattice edges) t, and back.
        let to_border = |s: f64| {
            if s <= first {
                half * s / first
            } else {
                half * (1.0 + (s - first) / (total - first))
            }
        };
        let to_outline = |t: f64| {
            if t <= half {
                first * t / half
            } else {
                first + (total - first) * (t / half - 1.0)
            }
        };
        let border_point = |t: f64| {
            let n = lattice.border.len();
            let k = t.floor();
            let f = t - k;
            let k = k as usize % n;
            let (p, q) = (
                lattice.points[lattice.border[k]],
                lattice.points[lattice.border[(k + 1) % n]],
            );
            [p[0] + f * (q[0] - p[0]), p[1] + f * (q[1] - p[1])]
        };
        let outline_point = |s: f64| {
            let k = arc.partition_point(|&a| a <= s).clamp(1, m) - 1;
            let f = (s - arc[k]) / (arc[k + 1] - arc[k]);
            let (p, q) = (at(k), at(k + 1));
            [p[0] + f * (q[0] - p[0]), p[1] + f * (q[1] - p[1])]
        };
        let mut fixed = vec![None; self.corners.len()];
        for (k, &s) in arc[..m].iter().enumerate() {
            fixed[self.outline[(self.tips[0] + k) % m]] = Some(border_point(to_border(s)));
        }
        let image = harmonic(&self.triangles, &fixed)?;
        let mut on_border = vec![None; lattice.points.len()];
        for (j, &b) in lattice.border.iter().enumerate() {
            on_border[b] = Some(j as f64);
        }
        Ok(lattice
            .points
            .iter()
            .zip(on_border)
            .map(|(p, border)| match border {
                Some(t) => outline_point(to_outline(t)),
                None => self.preimage(&image, *p),
            })
            .collect())
    }

    /// The chart position whose harmonic image is `p`: the barycentric combination of the
    /// corners of the image triangle that holds `p` (the one whose smallest barycentric
    /// coordinate is largest, clamped at 0 for a point just outside the image's outline).
    fn preimage(&self, image: &[[f64; 2]], p: [f64; 2]) -> [f64; 2] {
        let weights = |t: &[usize; 3]| {
            let [a, b, c] = t.map(|k| image[k]);
            let det = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            if det.abs() < 1e-300 {
                return [-f64::INFINITY; 3];
            }
            let wb = ((p[0] - a[0]) * (c[1] - a[1]) - (p[1] - a[1]) * (c[0] - a[0])) / det;
            let wc = ((b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])) / det;
            [1.0 - wb - wc, wb, wc]
        };
        let min = |w: &[f64; 3]| w[0].min(w[1]).min(w[2]);
        let (t, w) = self
            .triangles
            .iter()
            .map(|t| (t, weights(t)))
            .max_by(|a, b| min(&a.1).total_cmp(&min(&b.1)))
            .expect("a region has triangles");
        let w = w.map(|x| x.max(0.0));
        let sum = w[0] + w[1] + w[2];
        let mut q = [0.0; 2];
        for (k, wk) in t.iter().zip(w) {
            for (qa, ca) in q.iter_mut().zip(self.corners[*k]) {
                *qa += wk / sum * ca;
            }
        }
        q
    }
}

/// The closed loop of the outline edges `next` (start corner → end corner).
///
/// Errors: `InvalidVolume` when they form more than one loop (not a disc).
fn loop_of(next: &HashMap<usize, usize>) -> Result<Vec<usize>> {
    let start = *next.keys().min().expect("a region has an outline");
    let mut outline = vec![start];
    let mut v = next[&start];
    while v != start && outline.len() <= next.len() {
        outline.push(v);
        v = next[&v];
    }
    if outline.len() != next.len() {
        return Err(Error::InvalidVolume(
            "the medial points' region in their chart is not a disc (its outline is not one \
             loop)"
                .into(),
        ));
    }
    Ok(outline)
}

/// The steps of the 16-neighbourhood (cell units): lengths along them overestimate Euclidean
/// ones by at most 2.7 % (8.2 % with the 8-neighbourhood).
const STEPS: [(i64, i64); 16] = [
    (1, 0),
    (-1, 0),
    (0, 1),
    (0, -1),
    (1, 1),
    (1, -1),
    (-1, 1),
    (-1, -1),
    (2, 1),
    (2, -1),
    (-2, 1),
    (-2, -1),
    (1, 2),
    (1, -2),
    (-1, 2),
    (-1, -2),
];

/// The two cells of `full` farthest apart along paths inside the region (two sweeps of
/// Dijkstra over the 16-neighbourhood [`STEPS`], each step as long as the distance between the
/// `lifted` cell centres), and that distance (mm, between the end cells' centres).
fn longest_geodesic(
    cells: &Cells,
    full: &[usize],
    lifted: &dyn Fn(usize) -> Vec3,
) -> ([usize; 2], f64) {
    let sweep = |from: usize| -> (usize, f64) {
        let mut dist = vec![f64::INFINITY; cells.on.len()];
        let mut heap = BinaryHeap::new();
        dist[from] = 0.0;
        heap.push((Reverse(0), from));
        // Integer distances in µm, so that the heap orders exactly.
        let key = |d: f64| Reverse((d * 1000.0).round() as u64);
        while let Some((k, c)) = heap.pop() {
            if k != key(dist[c]) {
                continue;
            }
            let d = dist[c];
            let here = lifted(c);
            let (i, j) = cells.ij(c);
            for (di, dj) in STEPS {
                // A step passes the cells it straddles: (1, 2) passes (0, 1) and (1, 1).
                let via = [(di / 2, dj / 2), (di.signum(), dj.signum())];
                if !cells.get(i + di, j + dj) || via.iter().any(|&(a, b)| !cells.get(i + a, j + b))
                {
                    continue;
                }
                let n = ((j + dj) * cells.dims[0] as i64 + i + di) as usize;
                let nd = d + (lifted(n) - here).norm();
                if nd < dist[n] - 1e-6 {
                    dist[n] = nd;
                    heap.push((key(nd), n));
                }
            }
        }
        let far = (full.iter().copied())
            .max_by(|&a, &b| dist[a].total_cmp(&dist[b]).then(b.cmp(&a)))
            .expect("a region has cells");
        (far, dist[far])
    };
    let (a, _) = sweep(full[0]);
    let (b, d) = sweep(a);
    ([a, b], d)
}

/// Tutte's embedding: the corners with a `fixed` position keep it, every other one is the mean
/// of its neighbours along the edges of `triangles` (the Laplace equation, solved by conjugate
/// gradients).
///
/// Errors: `InvalidVolume` when the gradients do not converge.
fn harmonic(triangles: &[[usize; 3]], fixed: &[Option<[f64; 2]>]) -> Result<Vec<[f64; 2]>> {
    let n = fixed.len();
    let mut neighbours: Vec<Vec<usize>> = vec![Vec::new(); n];
    for t in triangles {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            neighbours[a].push(b);
            neighbours[b].push(a);
        }
    }
    for list in &mut neighbours {
        list.sort_unstable();
        list.dedup();
    }
    let free: Vec<usize> = (0..n).filter(|&v| fixed[v].is_none()).collect();
    let mut slot = vec![usize::MAX; n];
    for (k, &v) in free.iter().enumerate() {
        slot[v] = k;
    }
    let mut out: Vec<[f64; 2]> = fixed.iter().map(|f| f.unwrap_or([0.0; 2])).collect();
    for axis in 0..2 {
        // A x = b: deg(v)·x_v − Σ_{free u ~ v} x_u = Σ_{fixed u ~ v} p_u.
        let apply = |x: &[f64]| -> Vec<f64> {
            free.iter()
                .map(|&v| {
                    let mut y = neighbours[v].len() as f64 * x[slot[v]];
                    for &u in &neighbours[v] {
                        if slot[u] != usize::MAX {
                            y -= x[slot[u]];
                        }
                    }
                    y
                })
                .collect()
        };
        let b: Vec<f64> = free
            .iter()
            .map(|&v| {
                (neighbours[v].iter())
                    .filter_map(|&u| fixed[u].map(|p| p[axis]))
                    .sum()
            })
            .collect();
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let mut x = vec![0.0; free.len()];
        let mut r = b.clone();
        let mut p = r.clone();
        let mut rr = dot(&r, &r);
        let stop = CG_TOLERANCE * CG_TOLERANCE * dot(&b, &b).max(1e-300);
        let mut iterations = 0;
        while rr > stop {
            if iterations > 10 * free.len() + 100 {
                return Err(Error::InvalidVolume(
                    "the harmonic map of the medial sheet's chart did not converge".into(),
                ));
            }
            let ap = apply(&p);
            let alpha = rr / dot(&p, &ap);
            for k in 0..x.len() {
                x[k] += alpha * p[k];
                r[k] -= alpha * ap[k];
            }
            let next = dot(&r, &r);
            for k in 0..p.len() {
                p[k] = r[k] + next / rr * p[k];
            }
            rr = next;
            iterations += 1;
        }
        for (k, &v) in free.iter().enumerate() {
            out[v][axis] = x[k];
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points filling the crescent between two circles (mm): not star-shaped about any point.
    fn crescent() -> Vec<[f64; 2]> {
        let mut points = Vec::new();
        for a in 0..400 {
            for r in 0..12 {
                let phi = 0.1 + 4.5 * a as f64 / 399.0;
                let rad = 14.0 + 6.0 * r as f64 / 11.0;
                points.push([rad * phi.cos(), rad * phi.sin()]);
            }
        }
        points
    }

    fn signed_area(p: [[f64; 2]; 3]) -> f64 {
        let [a, b, c] = p;
        ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])) / 2.0
    }

    #[test]
    fn a_crescent_maps_one_to_one_onto_a_stretched_hexagon() {
        let points = crescent();
        let flat = |q: [f64; 2]| Vec3::new(q[0], q[1], 0.0);
        let points: Vec<_> = points.iter().map(|&q| (q, flat(q))).collect();
        let region = Region::of(&points, 1.0, 1, &flat).unwrap();
        // Length between the inner arc (14 mm × 4.5 rad = 63 mm) and the outer one (90 mm).
        assert!((60.0..90.0).contains(&region.length), "{}", region.length);
        let area = 0.5 * 4.5 * (20.0f64.powi(2) - 14.0f64.powi(2));
        assert!(
            (region.area() / area - 1.0).abs() < 0.25,
            "{}",
            region.area()
        );
        let rho = Lattice::stretch_ratio(region.elongation());
        assert!(rho > 3.0, "{rho}");
        let lattice = Lattice::new(3, (rho * 3.0).round() as usize);
        let chart = region.map_onto(&lattice).unwrap();
        // Every lattice triangle keeps its orientation in the chart: no fold.
        for t in &lattice.triangles {
            let a = signed_area(t.map(|k| chart[k]));
            assert!(a > 0.0, "{t:?} folds ({a} mm²)");
        }
        // Every point lies in the crescent (within a cell of it).
        for q in &chart {
            let (r, phi) = (
                q[0].hypot(q[1]),
                q[1].atan2(q[0]).rem_euclid(std::f64::consts::TAU),
            );
            assert!(
                (12.5..21.5).contains(&r) && (0.0..4.8).contains(&phi),
                "{q:?}"
            );
        }
    }

    #[test]
    fn a_disc_maps_onto_a_regular_hexagon() {
        // A 0.3 mm grid of points within 10 mm of the origin.
        let points: Vec<[f64; 2]> = (0..70 * 70)
            .map(|k| [0.3 * (k % 70) as f64 - 10.35, 0.3 * (k / 70) as f64 - 10.35])
            .filter(|q| q[0].hypot(q[1]) <= 10.0)
            .collect();
        let flat = |q: [f64; 2]| Vec3::new(q[0], q[1], 0.0);
        let points: Vec<_> = points.iter().map(|&q| (q, flat(q))).collect();
        let region = Region::of(&points, 1.0, 1, &flat).unwrap();
        assert_eq!(Lattice::stretch_ratio(region.elongation()), 0.0);
        let lattice = Lattice::new(4, 0);
        let chart = region.map_onto(&lattice).unwrap();
        // The centre goes near the centre; the border onto the outline, within a cell of the
        // points' (radius 10) on the staircase of cells.
        assert!(chart[lattice.points.len() / 2][0].hypot(chart[lattice.points.len() / 2][1]) < 1.5);
        for &b in &lattice.border {
            let r = chart[b][0].hypot(chart[b][1]);
            assert!((9.0..11.5).contains(&r), "{r}");
        }
    }
}
