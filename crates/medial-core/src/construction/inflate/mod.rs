//! Templates from a medial sheet: Loop subdivision of the sheet and inflation (docs/method.md §9.1).
//!
//! A *medial sheet* is a triangle mesh of medial points `x_m` (mm) with a radius `r_m > 0` (mm)
//! per vertex. It may be non-manifold: an edge in one triangle is a *free edge*, in two an
//! ordinary interior edge, in three a *seam* where three sheets meet.
//!
//! *Inflation* turns every (triangle, side) of the sheet into one boundary triangle. Corners of
//! these triangles are glued into one boundary vertex when they belong to the same medial vertex
//! and face the same region of the object, so that a medial vertex becomes an atom with one
//! spoke on a free edge, two inside a sheet and three on a seam. The boundary vertex of an atom
//! `m` in region `R` sits at `x_m + r_m·U` where the unit spoke direction `U` is
//! - `−∇r ± sqrt(1 − |∇r|²)·n` inside a sheet (`∇r` the surface gradient of the radius, `n` the
//!   unit normal facing `R`): the exact spoke of a medial sheet whose radius is linear;
//! - the outward in-plane direction (perpendicular to the free edges, away from the sheet) at a
//!   free edge;
//! - the bisector of the region (the normalised angle-weighted normal of the sheets around it)
//!   at a seam.
//!
//! The result is an approximately medial template; projection under the constraints of §3 makes
//! it exact.
//!
//! Where the radius is too large for the curvature of the sheet, or for the angle between the
//! sheets at a seam, inflation lowers it locally and smoothly (the rule and its reason are in
//! `limit` and `docs/decisions/0400-inflation-radius-limit.md`) and reports where
//! and by how much in [`Inflated::limit`]; a fit to a shape restores the thickness. Inflation
//! refuses to return a boundary that is open, non-manifold, inward oriented or, after the
//! limits, self-intersecting, and says near which medial vertices the problem is.

mod boundary;
mod edges;
mod geometry;
mod intersect;
mod limit;
mod regions;
mod sheet;

pub use intersect::{halve_at_crossings, self_intersections, LIMIT_ROUNDS};
pub use limit::RadiusLimit;
pub(crate) use regions::UnionFind;
pub use sheet::MedialSheet;

use crate::{Result, TriMesh, Vec3};
use boundary::{check_surface, intersection_error, signed_volumes};
use edges::Edges;
use geometry::SheetGeometry;
use limit::{focal_bounds, lower, MARGIN, SHRINK, SHRINK_ROUNDS};
use regions::Regions;

/// At most this many medial vertices are listed in an error message.
const LIST_MAX: usize = 12;

/// The result of [`inflate`]: a closed boundary mesh and its medial structure, ready for
/// `MedialTemplate::new(boundary, medial_index, medial_points)`.
///
/// Boundary triangle `2t` is the `+` side of medial triangle `t` (same orientation, outward along
/// its normal), `2t + 1` its `−` side (reversed). Boundary points are sorted by atom, so the
/// spokes of every atom have consecutive ascending indices and atom 0's come first; within an
/// atom, regions are in the order of their first corner `(triangle, side, corner)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Inflated {
    /// The closed, outward oriented, self-intersection free boundary mesh (mm).
    pub boundary: TriMesh,
    /// The atom (medial vertex) of every boundary point.
    pub medial_index: Vec<usize>,
    /// The medial point of every atom: atom `m` is medial vertex `m` of the sheet (mm).
    pub medial_points: Vec<Vec3>,
    /// The radius of every atom (mm): the sheet's, lowered where [`Self::limit`] says.
    pub radius: Vec<f64>,
    /// Where and by how much the sheet's radius was lowered.
    pub limit: RadiusLimit,
}

impl Inflated {
    /// Volume enclosed by the boundary (mm³), by the divergence theorem:
    /// `V = Σ_triangles p₀ · (p₁ × p₂) / 6`.
    pub fn volume(&self) -> f64 {
        signed_volumes(&self.boundary, &vec![0; self.boundary.points().len()], 1)[0]
    }
}

/// Inflates a medial sheet into a boundary mesh with one boundary vertex per (medial vertex,
/// region); see the module documentation for the gluing rules and spoke directions, and
/// `limit` for where the radius is lowered.
///
/// Errors (`InvalidTemplate`, naming the medial vertices or triangles involved): a triangle with
/// two or three free edges (its sides would collapse), a radius gradient `|∇r| ≥ 1` inside a
/// sheet, and a boundary that is not a closed, vertex-manifold, outward oriented surface free of
/// degenerate triangles, or that still intersects itself after the radius was lowered.
pub fn inflate(sheet: &MedialSheet) -> Result<Inflated> {
    let edges = Edges::new(sheet.triangles());
    edges.check_no_ears(sheet.triangles())?;
    let regions = Regions::glue(sheet, &edges);
    let n = sheet.points().len();
    let neighbours = edges.neighbours(n);
    let longest_edge: Vec<f64> = (0..n)
        .map(|m| {
            neighbours[m]
                .iter()
                .map(|&j| (sheet.points()[j] - sheet.points()[m]).norm())
                .fold(0.0, f64::max)
        })
        .collect();
    let build = |radius: &[f64]| -> Result<(TriMesh, Vec<(usize, usize)>)> {
        let spokes = regions.spokes(sheet, &edges, &SheetGeometry::new(sheet, radius))?;
        let points = regions
            .atom
            .iter()
            .zip(&spokes)
            .map(|(&m, u)| sheet.points()[m] + radius[m] * u)
            .collect();
        let boundary = TriMesh::new(points, regions.boundary_triangles(sheet.triangles().len()))?;
        check_surface(&boundary, &regions.atom)?;
        let pairs = self_intersections(&boundary);
        Ok((boundary, pairs))
    };
    let mut radius = sheet.radius().to_vec();
    let (mut boundary, mut pairs) = build(&radius)?;
    let mut bound = vec![false; n];
    let mut shrink_rounds = 0;
    if !pairs.is_empty() {
        // The sheet as given folds: lower every radius beyond its focal bound.
        let seam: Vec<bool> = regions.spokes.iter().map(|&s| s >= 3).collect();
        let geometry = SheetGeometry::new(sheet, sheet.radius());
        let focal = focal_bounds(
            sheet.points(),
            sheet.radius(),
            &regions.atom,
            &regions.fold_directions(sheet, &edges, &geometry)?,
            &seam,
            &neighbours,
        );
        let factor: Vec<f64> = focal
            .iter()
            .zip(sheet.radius())
            .map(|(rho, r)| (MARGIN * rho / r).min(1.0))
            .collect();
        bound = factor.iter().map(|&f| f < 1.0).collect();
        lower(sheet.points(), &mut radius, &factor, &longest_edge);
        (boundary, pairs) = build(&radius)?;
    }
    while !pairs.is_empty() {
        if shrink_rounds == SHRINK_ROUNDS {
            let limit = RadiusLimit::new(sheet.radius(), &radius, &bound, shrink_rounds);
            return Err(intersection_error(
                &boundary,
                &regions.atom,
                &pairs,
                limit.vertices.len(),
                limit.max_pct(),
            ));
        }
        let mut factor = vec![1.0; n];
        for &(f, g) in &pairs {
            for b in boundary.triangles()[f]
                .into_iter()
                .chain(boundary.triangles()[g])
            {
                factor[regions.atom[b]] = SHRINK;
                bound[regions.atom[b]] = true;
            }
        }
        lower(sheet.points(), &mut radius, &factor, &longest_edge);
        shrink_rounds += 1;
        (boundary, pairs) = build(&radius)?;
    }
    let limit = RadiusLimit::new(sheet.radius(), &radius, &bound, shrink_rounds);
    Ok(Inflated {
        boundary,
        medial_index: regions.atom,
        medial_points: sheet.points().to_vec(),
        radius,
        limit,
    })
}
