//! A regularly sampled, triangulated medial sheet through a cloud of medial points: a
//! [`Lattice`] hexagon mapped into the chart, each vertex placed by a local linear fit of the
//! points around it.

use nalgebra::{Matrix3, Vector3};
use std::collections::HashMap;

use super::chart::Chart;
use super::lattice::Lattice;
use super::ridge::MedialPoint;
use crate::construction::inflate::MedialSheet;
use crate::{Error, Result, Vec3};

/// Fewest points a vertex's window must hold for a linear fit.
const MIN_POINTS: usize = 8;
/// A window with fewer points (at a sparse tip of the sheet) is doubled up to this many times.
const WINDOW_DOUBLINGS: u32 = 2;

/// A point whose radius is below this fraction of the [`REFERENCE_QUANTILE`] of the radii
/// around it is a spur and is dropped.
const SPUR_FRACTION: f64 = 0.5;
/// The quantile of the radii in a neighbourhood that a point's radius is compared with.
const REFERENCE_QUANTILE: f64 = 0.9;

/// The medial points in chart coordinates, without spurs.
#[derive(Clone, Debug)]
pub(super) struct ChartedCloud {
    points: Vec<MedialPoint>,
    coords: Vec<[f64; 2]>,
}

impl ChartedCloud {
    /// The points in the chart, with `window` (mm) less the spurs: points whose radius is below
    /// [`SPUR_FRACTION`] of the [`REFERENCE_QUANTILE`] of the radii within about `window` mm in
    /// the chart. A
    /// boundary crease or bump makes a branch of the medial axis that runs from the surface
    /// (radius 0) to the sheet; its part far from the sheet has small radii against the
    /// sheet's around it, while a sheet's own radius varies slowly (`|∇r| < 1`).
    pub(super) fn new(points: &[MedialPoint], chart: &Chart, window: Option<f64>) -> Self {
        let coords: Vec<[f64; 2]> = points.iter().map(|p| chart.coords(&p.position)).collect();
        let Some(window) = window else {
            return Self {
                points: points.to_vec(),
                coords,
            };
        };
        let buckets = Buckets::new(&coords, window);
        let mut reference: HashMap<[i64; 2], f64> = HashMap::new();
        for key in buckets.cells.keys() {
            let mut radii: Vec<f64> = buckets.around(*key).map(|i| points[i].radius).collect();
            radii.sort_by(f64::total_cmp);
            let r = radii[((radii.len() - 1) as f64 * REFERENCE_QUANTILE) as usize];
            reference.insert(*key, r);
        }
        let keep: Vec<usize> = (0..points.len())
            .filter(|&i| {
                points[i].radius >= SPUR_FRACTION * reference[&Buckets::key(&coords[i], window)]
            })
            .collect();
        Self {
            points: keep.iter().map(|&i| points[i]).collect(),
            coords: keep.iter().map(|&i| coords[i]).collect(),
        }
    }

    /// The medial points kept.
    pub(super) fn len(&self) -> usize {
        self.points.len()
    }

    /// The points.
    pub(super) fn points(&self) -> &[MedialPoint] {
        &self.points
    }

    /// The points' chart coordinates (mm).
    pub(super) fn coords(&self) -> &[[f64; 2]] {
        &self.coords
    }
}

/// The weighted local linear fit of position and radius to a sheet's medial points in its
/// chart: the value at a chart position `q₀` of `v(q) ≈ v₀ + B (q − q₀)` fitted to the points
/// within `window` mm (doubled up to [`WINDOW_DOUBLINGS`] times where it holds fewer than
/// [`MIN_POINTS`]; weights `exp(−|q − q₀|²/(2 (window/2)²))`, then a second pass
/// down-weighting points off the first fit by `1/(1 + (d/2h)²)`, `h` = `voxel`), which is
/// unbiased at the rim where the window is one-sided.
#[derive(Clone, Debug)]
pub(super) struct SheetFit {
    cloud: ChartedCloud,
    buckets: Buckets,
    window: f64,
    voxel: f64,
}

impl SheetFit {
    /// The fit to `cloud` with `window` (mm) on a mask of voxel `voxel` (mm).
    pub(super) fn new(cloud: ChartedCloud, window: f64, voxel: f64) -> Self {
        let widest = window * f64::from(1u32 << WINDOW_DOUBLINGS);
        let buckets = Buckets::new(&cloud.coords, widest);
        Self {
            cloud,
            buckets,
            window,
            voxel,
        }
    }

    /// The medial points fitted to (without spurs).
    pub(super) fn cloud(&self) -> &ChartedCloud {
        &self.cloud
    }

    /// Position (mm) and radius (mm) of the sheet at chart position `q0`.
    ///
    /// Errors: `InvalidVolume` when `q0` has fewer than [`MIN_POINTS`] points in its widest
    /// window (a hole in the sheet) or they lie on a line.
    pub(super) fn at(&self, q0: [f64; 2]) -> Result<(Vec3, f64)> {
        let widest = self.window * f64::from(1u32 << WINDOW_DOUBLINGS);
        let (near, window) = (0..=WINDOW_DOUBLINGS)
            .map(|d| {
                let w = self.window * f64::from(1u32 << d);
                (self.buckets.within(&self.cloud.coords, q0, w), w)
            })
            .find(|(near, w)| near.len() >= MIN_POINTS || *w >= widest)
            .expect("the widest window ends the search");
        if near.len() < MIN_POINTS {
            return Err(Error::InvalidVolume(format!(
                "the medial sheet has a hole near chart position ({:.1}, {:.1}) mm ({} medial \
                 points within {window:.1} mm)",
                q0[0],
                q0[1],
                near.len()
            )));
        }
        local_fit(&self.cloud, &near, q0, window, self.voxel)
    }
}

/// The sheet on `lattice`: each lattice point at its chart position `chart[k]` (the harmonic
/// map of [`Region::map_onto`](super::region::Region::map_onto)), its position and radius
/// those of `fit` there ([`SheetFit::at`]).
///
/// Errors: those of [`SheetFit::at`] and [`MedialSheet::new`].
pub(super) fn lattice_sheet(
    fit: &SheetFit,
    lattice: &Lattice,
    chart: &[[f64; 2]],
) -> Result<MedialSheet> {
    let (points, radius) = (chart.iter())
        .map(|&q0| fit.at(q0))
        .collect::<Result<(Vec<_>, Vec<_>)>>()?;
    MedialSheet::new(points, lattice.triangles.clone(), radius)
}

/// The value at `q0` of the weighted local linear fit of position and radius (see
/// [`SheetFit`]).
fn local_fit(
    cloud: &ChartedCloud,
    near: &[usize],
    q0: [f64; 2],
    window: f64,
    voxel: f64,
) -> Result<(Vec3, f64)> {
    let sigma = window / 2.0;
    let offset =
        |i: usize| Vector3::new(1.0, cloud.coords[i][0] - q0[0], cloud.coords[i][1] - q0[1]);
    let base: Vec<f64> = near
        .iter()
        .map(|&i| {
            let d = offset(i);
            (-(d[1] * d[1] + d[2] * d[2]) / (2.0 * sigma * sigma)).exp()
        })
        .collect();
    let solve = |weights: &[f64]| -> Option<[Vector3<f64>; 4]> {
        let mut a = Matrix3::zeros();
        let mut b = [Vector3::zeros(); 4];
        for (&i, &w) in near.iter().zip(weights) {
            let x = offset(i);
            a += w * x * x.transpose();
            let p = cloud.points[i].position;
            for (k, v) in [p.x, p.y, p.z, cloud.points[i].radius]
                .into_iter()
                .enumerate()
            {
                b[k] += w * v * x;
            }
        }
        let lu = a.lu();
        Some([
            lu.solve(&b[0])?,
            lu.solve(&b[1])?,
            lu.solve(&b[2])?,
            lu.solve(&b[3])?,
        ])
    };
    let first = solve(&base).ok_or_else(|| {
        Error::InvalidVolume(format!(
            "the medial points near chart position ({:.1}, {:.1}) mm lie on a line",
            q0[0], q0[1]
        ))
    })?;
    let predict = |c: &[Vector3<f64>; 4], i: usize| {
        let x = offset(i);
        Vec3::new(c[0].dot(&x), c[1].dot(&x), c[2].dot(&x))
    };
    let robust: Vec<f64> = near
        .iter()
        .zip(&base)
        .map(|(&i, &w)| {
            let d = (cloud.points[i].position - predict(&first, i)).norm() / (2.0 * voxel);
            w / (1.0 + d * d)
        })
        .collect();
    let c = solve(&robust).unwrap_or(first);
    // A radius is positive, and a one-sided window at a steep rim can extrapolate it past 0:
    // the fit is kept no lower than the least radius it was fitted to.
    let least = (near.iter().map(|&i| cloud.points[i].radius)).fold(f64::INFINITY, f64::min);
    Ok((Vec3::new(c[0][0], c[1][0], c[2][0]), c[3][0].max(least)))
}

/// Chart points bucketed in square cells of a given size.
#[derive(Clone, Debug)]
struct Buckets {
    cell: f64,
    cells: HashMap<[i64; 2], Vec<usize>>,
}

impl Buckets {
    fn new(coords: &[[f64; 2]], cell: f64) -> Self {
        let mut cells: HashMap<[i64; 2], Vec<usize>> = HashMap::new();
        for (i, q) in coords.iter().enumerate() {
            cells.entry(Self::key(q, cell)).or_default().push(i);
        }
        Self { cell, cells }
    }

    fn key(q: &[f64; 2], cell: f64) -> [i64; 2] {
        [(q[0] / cell).floor() as i64, (q[1] / cell).floor() as i64]
    }

    /// The points in cell `k` and the eight around it.
    fn around(&self, k: [i64; 2]) -> impl Iterator<Item = usize> + '_ {
        (0..9)
            .filter_map(move |d| self.cells.get(&[k[0] + d % 3 - 1, k[1] + d / 3 - 1]))
            .flatten()
            .copied()
    }

    /// The points within `radius ≤ cell` of `q0`, ascending.
    fn within(&self, coords: &[[f64; 2]], q0: [f64; 2], radius: f64) -> Vec<usize> {
        let mut found: Vec<usize> = self
            .around(Self::key(&q0, self.cell))
            .filter(|&i| (coords[i][0] - q0[0]).hypot(coords[i][1] - q0[1]) <= radius)
            .collect();
        found.sort_unstable();
        found
    }
}
