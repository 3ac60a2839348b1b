//! The triangulated parameter domain of a single sheet: a hexagon of the unit triangular
//! lattice, regular for round sheets and stretched along its middle row for long ones.

use std::collections::HashMap;

/// Row height of the unit triangular lattice, `√3/2`.
const ROW: f64 = 0.866_025_403_784_438_6;

/// A hexagon of the unit triangular lattice with `rings` rows above and below its middle row,
/// stretched by `stretch` edges along it (the top and bottom rows have `stretch + rings + 1`
/// points, the middle row `stretch + 2·rings + 1`): with `stretch = 0` the regular hexagon of
/// `1 + 3·rings·(rings + 1)` points, the hexagonal disc of `rings` rings; in general
/// `(2·rings + 1)(stretch + 1) + rings·(3·rings + 1)` points.
#[derive(Clone, Debug, PartialEq)]
pub struct Lattice {
    /// Point positions in the plane (lattice units), centred on the origin.
    pub points: Vec<[f64; 2]>,
    /// Triangles, counter-clockwise.
    pub triangles: Vec<[usize; 3]>,
    /// How many edges the hexagon is stretched by along its middle row.
    pub stretch: usize,
    /// The border points counter-clockwise from the left tip `(−stretch/2 − rings, 0)`, one
    /// lattice edge apart: the right tip is `border[stretch + 3·rings]`, half way round.
    pub border: Vec<usize>,
}

impl Lattice {
    /// The hexagon of `rings ≥ 1` rows either side, stretched by `stretch` edges.
    pub fn new(rings: usize, stretch: usize) -> Self {
        let n = rings as i64;
        let mut points = Vec::new();
        let mut index: HashMap<(i64, i64), usize> = HashMap::new();
        // Key: (2x, row).
        let row_range = |j: i64| {
            let len = stretch as i64 + 2 * n - j.abs();
            (-len, len)
        };
        for j in -n..=n {
            let (lo, hi) = row_range(j);
            for x2 in (lo..=hi).step_by(2) {
                index.insert((x2, j), points.len());
                points.push([x2 as f64 / 2.0, j as f64 * ROW]);
            }
        }
        let at = |x2: i64, j: i64| index.get(&(x2, j)).copied();
        let mut triangles = Vec::new();
        for j in -n..=n {
            let (lo, hi) = row_range(j);
            for x2 in (lo..hi).step_by(2) {
                let (a, b) = (index[&(x2, j)], index[&(x2 + 2, j)]);
                if let Some(c) = at(x2 + 1, j + 1) {
                    triangles.push([a, b, c]);
                }
                if let Some(c) = at(x2 + 1, j - 1) {
                    triangles.push([a, c, b]);
                }
            }
        }
        let first = |j: i64| index[&(row_range(j).0, j)];
        let last = |j: i64| index[&(row_range(j).1, j)];
        let mut border: Vec<usize> = (-n..=0).rev().map(first).collect();
        let (lo, hi) = row_range(-n);
        border.extend((lo + 2..=hi).step_by(2).map(|x2| index[&(x2, -n)]));
        border.extend((-n + 1..=n).map(last));
        let (lo, hi) = row_range(n);
        border.extend((lo..=hi - 2).rev().step_by(2).map(|x2| index[&(x2, n)]));
        border.extend((1..n).rev().map(first));
        Self {
            points,
            triangles,
            stretch,
            border,
        }
    }

    /// The hexagon's long sides for a region of length² / area `elongation` (the same ratio
    /// `L²/A` for the hexagon, `L` its tip-to-tip length): `stretch = ρ·rings` with `ρ ≥ 0` the
    /// root of `(ρ + 2)² = (√3/2)·elongation·(3 + 2ρ)`, 0 for regions rounder than the
    /// regular hexagon.
    pub fn stretch_ratio(elongation: f64) -> f64 {
        // ρ² + (4 − 2c)ρ + (4 − 3c) = 0 with c = (√3/2)·elongation.
        let c = ROW * elongation;
        let b = 4.0 - 2.0 * c;
        let disc = b * b - 4.0 * (4.0 - 3.0 * c);
        if disc < 0.0 {
            return 0.0;
        }
        ((-b + disc.sqrt()) / 2.0).max(0.0)
    }

    /// The number of points `V` of the hexagon of `rings` rows either side and `stretch`.
    pub fn point_count(rings: usize, stretch: usize) -> usize {
        (2 * rings + 1) * (stretch + 1) + rings * (3 * rings + 1)
    }

    /// The number of points of that hexagon after one Loop subdivision, a point per vertex and
    /// per edge: `V + E = 4V − B − 3` (a triangulated disc has `E = 3V − B − 3` edges), with
    /// `B = 6·rings + 2·stretch` points on its border.
    pub fn subdivided_count(rings: usize, stretch: usize) -> usize {
        4 * Self::point_count(rings, stretch) - 6 * rings - 2 * stretch - 3
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area(l: &Lattice, t: &[usize; 3]) -> f64 {
        let [a, b, c] = t.map(|k| l.points[k]);
        ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])) / 2.0
    }

    #[test]
    fn a_regular_hexagon_is_the_hex_disc_and_a_stretched_one_tiles_its_outline() {
        for (rings, stretch) in [(1, 0), (3, 0), (2, 5), (4, 7)] {
            let l = Lattice::new(rings, stretch);
            assert_eq!(l.points.len(), Lattice::point_count(rings, stretch));
            assert_eq!(l.border.len(), 6 * rings + 2 * stretch);
            let mut edges: Vec<(usize, usize)> = (l.triangles.iter())
                .flat_map(|t| {
                    (0..3).map(move |k| (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3])))
                })
                .collect();
            edges.sort_unstable();
            edges.dedup();
            assert_eq!(
                l.points.len() + edges.len(),
                Lattice::subdivided_count(rings, stretch)
            );
            if stretch == 0 {
                assert_eq!(l.points.len(), 1 + 3 * rings * (rings + 1));
            }
            // Unit equilateral triangles, counter-clockwise, tiling the hexagon:
            // (3n² + 2nk)·√3/2·… = (6n² + 4nk)·(√3/4).
            let unit = ROW / 2.0;
            for t in &l.triangles {
                assert!((area(&l, t) - unit).abs() < 1e-12, "{t:?}");
            }
            assert_eq!(l.triangles.len(), 6 * rings * rings + 4 * rings * stretch);
            // The border: every point on it once, one edge apart, counter-clockwise, the
            // right tip half way.
            let b = &l.border;
            assert_eq!(b.len(), 2 * stretch + 6 * rings);
            let p = |i: usize| l.points[b[i % b.len()]];
            for i in 0..b.len() {
                let (u, v) = (p(i), p(i + 1));
                assert!(((v[0] - u[0]).hypot(v[1] - u[1]) - 1.0).abs() < 1e-12);
            }
            let half = stretch + 3 * rings;
            assert!((p(0)[0] + p(half)[0]).abs() < 1e-12 && p(half)[0] > 0.0);
            assert!(
                p(1)[1] < 0.0,
                "counter-clockwise: down from the left tip first"
            );
            // No triangle has two edges on the border (as inflation requires), once there is
            // an interior.
            if rings >= 2 {
                let on: std::collections::HashSet<(usize, usize)> = (0..b.len())
                    .flat_map(|i| {
                        let (u, v) = (b[i], b[(i + 1) % b.len()]);
                        [(u, v), (v, u)]
                    })
                    .collect();
                for t in &l.triangles {
                    let edges = (0..3).filter(|&e| on.contains(&(t[e], t[(e + 1) % 3])));
                    assert!(edges.count() <= 1, "{t:?}");
                }
            }
        }
    }

    #[test]
    fn a_long_region_gets_a_stretched_hexagon_and_a_round_one_a_regular_one() {
        // A disc: L²/A = 4/π.
        assert_eq!(Lattice::stretch_ratio(4.0 / std::f64::consts::PI), 0.0);
        // The hexagon of ratio ρ has L²/A = (ρ + 2)²/((3 + 2ρ)·√3/2): recovered.
        for rho in [0.5, 2.0, 6.0] {
            let q = (rho + 2.0) * (rho + 2.0) / ((3.0 + 2.0 * rho) * ROW);
            assert!((Lattice::stretch_ratio(q) - rho).abs() < 1e-9, "{rho}");
        }
    }
}
