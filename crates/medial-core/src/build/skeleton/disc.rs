//! A regularly sampled, triangulated medial sheet through a cloud of medial points: a disc of
//! rings in the chart, stretched to the cloud's outline, each vertex placed by a local linear
//! fit of the points around it.

use nalgebra::{Matrix3, Vector3};
use std::collections::HashMap;
use std::f64::consts::TAU;

use super::chart::Chart;
use super::ridge::MedialPoint;
use crate::build::inflate::MedialSheet;
use crate::synth::hex_disc;
use crate::{Error, Result, Vec3};

/// Angular bins of the outline `R(φ)` of the cloud in the chart.
const OUTLINE_BINS: usize = 72;
/// The outline in a bin is this quantile of the chart radii in it (ignores stray points).
const OUTLINE_QUANTILE: f64 = 0.95;
/// Fewest points a vertex's window must hold for a linear fit.
const MIN_POINTS: usize = 8;

/// A point whose radius is below this fraction of the [`REFERENCE_QUANTILE`] of the radii
/// around it is a spur and is dropped.
const SPUR_FRACTION: f64 = 0.5;
/// The quantile of the radii in a neighbourhood that a point's radius is compared with.
const REFERENCE_QUANTILE: f64 = 0.9;

/// The medial points in chart coordinates, without spurs.
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

    /// The outline `R(φ)` of the cloud about the chart centre: [`OUTLINE_QUANTILE`] of `|q|` in
    /// each of [`OUTLINE_BINS`] angular bins, smoothed by a circular mean over three bins.
    ///
    /// Errors: `InvalidVolume` when a bin is empty (the sheet does not surround the chart's
    /// centre: it is not a disc or a bowl seen from its apex).
    pub(super) fn outline(&self) -> Result<Vec<f64>> {
        let mut bins: Vec<Vec<f64>> = vec![Vec::new(); OUTLINE_BINS];
        for q in &self.coords {
            let phi = q[1].atan2(q[0]).rem_euclid(TAU);
            let b = ((phi / TAU * OUTLINE_BINS as f64) as usize).min(OUTLINE_BINS - 1);
            bins[b].push(q[0].hypot(q[1]));
        }
        let raw = bins
            .iter_mut()
            .enumerate()
            .map(|(b, radii)| {
                if radii.is_empty() {
                    return Err(Error::InvalidVolume(format!(
                        "the medial sheet does not surround its centre (no medial points \
                         towards {:.0}° in its chart): only disc- or bowl-shaped single sheets \
                         are built",
                        (b as f64 + 0.5) * 360.0 / OUTLINE_BINS as f64
                    )));
                }
                radii.sort_by(f64::total_cmp);
                Ok(radii[((radii.len() - 1) as f64 * OUTLINE_QUANTILE) as usize])
            })
            .collect::<Result<Vec<f64>>>()?;
        let n = raw.len();
        Ok((0..n)
            .map(|b| (raw[(b + n - 1) % n] + raw[b] + raw[(b + 1) % n]) / 3.0)
            .collect())
    }
}

/// `R(φ)` interpolated linearly between bin centres.
fn outline_at(outline: &[f64], phi: f64) -> f64 {
    let n = outline.len();
    let x = phi.rem_euclid(TAU) / TAU * n as f64 - 0.5;
    let b = x.floor();
    let t = x - b;
    let b = (b as i64).rem_euclid(n as i64) as usize;
    (1.0 - t) * outline[b] + t * outline[(b + 1) % n]
}

/// The sheet: [`hex_disc`]`(rings)` with the disc point `(s, φ)` at chart position
/// `s R(φ) (cos φ, sin φ)`, its position and radius the values at that point of the weighted
/// local linear fit `v(q) ≈ v₀ + B (q − q₀)` to the medial points within `window` mm
/// (weights `exp(−|q − q₀|²/(2 (window/2)²))`, then a second pass down-weighting points off
/// the first fit by `1/(1 + (d/2h)²)`, `h` = `voxel`), which is unbiased at the rim where the
/// window is one-sided.
///
/// Errors: `InvalidVolume` when a vertex has fewer than [`MIN_POINTS`] points in its window
/// (a hole in the sheet); those of [`MedialSheet::new`].
pub(super) fn disc_sheet(
    cloud: &ChartedCloud,
    outline: &[f64],
    rings: usize,
    window: f64,
    voxel: f64,
) -> Result<MedialSheet> {
    let (params, triangles) = hex_disc(rings);
    let buckets = Buckets::new(&cloud.coords, window);
    let mut points = Vec::with_capacity(params.len());
    let mut radius = Vec::with_capacity(params.len());
    for &[s, phi] in &params {
        let r = s * outline_at(outline, phi);
        let q0 = [r * phi.cos(), r * phi.sin()];
        let near = buckets.within(&cloud.coords, q0, window);
        if near.len() < MIN_POINTS {
            return Err(Error::InvalidVolume(format!(
                "the medial sheet has a hole near chart position ({:.1}, {:.1}) mm ({} medial \
                 points within {window:.1} mm)",
                q0[0],
                q0[1],
                near.len()
            )));
        }
        let (p, rad) = local_fit(cloud, &near, q0, window, voxel)?;
        points.push(p);
        radius.push(rad);
    }
    MedialSheet::new(points, triangles, radius)
}

/// The value at `q0` of the weighted local linear fit of position and radius (see
/// [`disc_sheet`]).
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
    Ok((Vec3::new(c[0][0], c[1][0], c[2][0]), c[3][0]))
}

/// Chart points bucketed in square cells of a given size.
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
