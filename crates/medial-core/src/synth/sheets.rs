//! The analytic medial sheets of the shapes: the cup's hexagonal disc mapped onto a spheroid,
//! the toy's three parameter grids sharing their seam.

use super::shape::{
    CUP_EQUATOR, CUP_LENGTH, CUP_OPENING, CUP_RADIUS_APEX, CUP_RADIUS_BASE, CUP_RADIUS_SEPTUM,
    CUP_RINGS, TOY_CELLS, TOY_CURL, TOY_LENGTH, TOY_RADIUS, TOY_WIDTH,
};
use crate::construction::inflate::MedialSheet;
use crate::{Error, Result, Vec3};
use std::f64::consts::{PI, TAU};

/// A disc of `rings` rings around a centre point: point 0 is the centre, ring `i` has `6i`
/// points at angles `2πj/(6i)`. Returns `(radial fraction i/rings, angle)` per point and the
/// triangles, counter-clockwise in the disc's plane. Consecutive rings are zipped in angular
/// order, so every triangle has at most one edge on the outer ring.
pub(crate) fn hex_disc(rings: usize) -> (Vec<[f64; 2]>, Vec<[usize; 3]>) {
    let mut params = vec![[0.0, 0.0]];
    let mut triangles = Vec::new();
    let mut inner: Vec<usize> = vec![0];
    for i in 1..=rings {
        let n = 6 * i;
        let outer: Vec<usize> = (params.len()..params.len() + n).collect();
        params.extend((0..n).map(|j| [i as f64 / rings as f64, TAU * j as f64 / n as f64]));
        zip_rings(&inner, &outer, &mut triangles);
        inner = outer;
    }
    (params, triangles)
}

/// Triangulates the strip between ring `inner` and ring `outer` (points in angular order from
/// angle 0; a single-point inner ring is the centre), advancing along whichever ring's next
/// point comes first in angle (exact integer comparison; the outer ring on ties).
fn zip_rings(inner: &[usize], outer: &[usize], triangles: &mut Vec<[usize; 3]>) {
    let (na, nb) = (inner.len(), outer.len());
    let (mut a, mut b) = (0, 0);
    let steps = if na == 1 { nb } else { na + nb };
    for _ in 0..steps {
        let outer_first = na == 1 || (b + 1) * na <= (a + 1) * nb;
        if outer_first {
            triangles.push([inner[a % na], outer[b % nb], outer[(b + 1) % nb]]);
            b += 1;
        } else {
            triangles.push([inner[a % na], outer[b % nb], inner[(a + 1) % na]]);
            a += 1;
        }
    }
}

pub(super) fn cup_sheet() -> Result<MedialSheet> {
    let (params, triangles) = hex_disc(CUP_RINGS);
    let points = params
        .iter()
        .map(|&[s, phi]| {
            let theta = s * CUP_OPENING;
            Vec3::new(
                CUP_EQUATOR * theta.sin() * phi.cos(),
                CUP_EQUATOR * theta.sin() * phi.sin(),
                -CUP_LENGTH * theta.cos(),
            )
        })
        .collect();
    let radius = params
        .iter()
        .map(|&[s, phi]| {
            CUP_RADIUS_APEX
                + (CUP_RADIUS_BASE - CUP_RADIUS_APEX) * s
                + CUP_RADIUS_SEPTUM * s * phi.cos()
        })
        .collect();
    MedialSheet::new(points, triangles, radius)
}

/// The parameter points `(u, v)` and the triangles (indices into them) of a [`parameter_grid`].
pub type ParameterGrid = (Vec<[f64; 2]>, Vec<[usize; 3]>);

/// The triangulated parameter rectangle of a medial sheet: `(nu+1) × (nv+1)` parameter points
/// `(u, v) = (i/nu, j/nv)` in `[0, 1]²` (point `j(nu+1) + i`) and `2 nu nv` triangles, each
/// cell split along the diagonal through its corner with even `i + j`, counter-clockwise in
/// `(u, v)`. With `nu`, `nv` even no triangle has two edges on the border of the grid, as
/// [`inflate`](crate::construction::inflate()) requires. Mapping the parameters to points and radii
/// gives a [`MedialSheet`] (the toy's sheets are three such grids sharing the column `u = 0`).
///
/// Errors: `InvalidParameter` if `nu` or `nv` is 0.
pub fn parameter_grid(nu: usize, nv: usize) -> Result<ParameterGrid> {
    if nu == 0 || nv == 0 {
        return Err(Error::InvalidParameter(format!(
            "a parameter grid needs at least one cell each way, got {nu} × {nv}"
        )));
    }
    let id = |i: usize, j: usize| j * (nu + 1) + i;
    let params = (0..=nv)
        .flat_map(|j| (0..=nu).map(move |i| [i as f64 / nu as f64, j as f64 / nv as f64]))
        .collect();
    let mut triangles = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            if (i + j) % 2 == 0 {
                triangles.extend([[a, b, c], [a, c, d]]);
            } else {
                triangles.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    Ok((params, triangles))
}

/// Half thickness of the toy at distance fraction `u` from the seam and height fraction `v`.
fn toy_radius(u: f64, v: f64) -> f64 {
    let z = 2.0 * v - 1.0;
    TOY_RADIUS * (1.0 - 0.3 * u) * (1.0 - 0.2 * z * z)
}

pub(super) fn toy_sheet() -> Result<MedialSheet> {
    let [nw, nz] = TOY_CELLS;
    let (params, cells) = parameter_grid(nw, nz)?;
    // The seam: grid column u = 0, shared by the three sheets (points 0 ..= nz).
    let mut points: Vec<Vec3> = (0..=nz)
        .map(|j| Vec3::new(0.0, 0.0, TOY_LENGTH * (j as f64 / nz as f64 - 0.5)))
        .collect();
    let mut radius: Vec<f64> = (0..=nz)
        .map(|j| toy_radius(0.0, j as f64 / nz as f64))
        .collect();
    let mut triangles = Vec::new();
    for s in 0..3 {
        let angle = PI / 2.0 + TAU * s as f64 / 3.0;
        let along = Vec3::new(angle.cos(), angle.sin(), 0.0);
        let normal = Vec3::new(-angle.sin(), angle.cos(), 0.0);
        let global: Vec<usize> = params
            .iter()
            .enumerate()
            .map(|(k, &[u, v])| {
                if k % (nw + 1) == 0 {
                    return k / (nw + 1);
                }
                let w = TOY_WIDTH * u;
                let z = TOY_LENGTH * (v - 0.5);
                points.push(w * along + TOY_CURL * w * w * normal + Vec3::new(0.0, 0.0, z));
                radius.push(toy_radius(u, v));
                points.len() - 1
            })
            .collect();
        triangles.extend(cells.iter().map(|t| t.map(|v| global[v])));
    }
    MedialSheet::new(points, triangles, radius)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    #[test]
    fn hex_disc_is_a_disc() {
        let (params, triangles) = hex_disc(3);
        assert_eq!(params.len(), 1 + 6 + 12 + 18);
        assert_eq!(triangles.len(), 6 * 9);
        // Counter-clockwise in the plane.
        let xy = |k: usize| {
            let [s, a] = params[k];
            nalgebra::Vector2::new(s * a.cos(), s * a.sin())
        };
        for t in &triangles {
            let (e1, e2) = (xy(t[1]) - xy(t[0]), xy(t[2]) - xy(t[0]));
            assert!(e1.perp(&e2) > 1e-3, "{t:?}");
        }
    }

    #[test]
    fn parameter_grid_tiles_the_unit_square_counter_clockwise() {
        let (params, triangles) = parameter_grid(4, 2).unwrap();
        assert_eq!((params.len(), triangles.len()), (5 * 3, 2 * 4 * 2));
        assert_eq!((params[6], params[14]), ([0.25, 0.5], [1.0, 1.0]));
        let area = |t: &[usize; 3]| {
            let [a, b, c] = t.map(|k| nalgebra::Vector2::from(params[k]));
            (b - a).perp(&(c - a)) / 2.0
        };
        assert!(triangles.iter().all(|t| area(t) > 0.0));
        assert_relative_eq!(
            triangles.iter().map(area).sum::<f64>(),
            1.0,
            epsilon = 1e-12
        );
        let m = parameter_grid(3, 0).unwrap_err().to_string();
        assert!(m.contains("3 × 0"), "{m}");
    }
}
