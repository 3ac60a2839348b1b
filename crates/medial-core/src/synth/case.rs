//! A synthetic case built as a template would be from a real sheet, and its targets.

use super::{Shape, Warp};
use crate::construction::inflate::{inflate, MedialSheet};
use crate::construction::project::{project, ProjectOptions, Projection};
use crate::image::rasterize::{grid_around, rasterize};
use crate::image::volume::Volume;
use crate::mesh::subdivide::midpoint_subdivide;
use crate::mesh::Bounds;
use crate::model::template::MedialTemplate;
use crate::{Result, TriMesh, Vec3};

/// Loop subdivisions of the coarse sheet before inflation.
pub const SHEET_SUBDIVISIONS: usize = 1;
/// Midpoint subdivisions of the template boundary before it is warped into the target.
pub const TARGET_SUBDIVISIONS: usize = 2;

/// The SSD target with known correspondence: `boundary` with every point carried by `warp`
/// (same triangles, same order), mm.
///
/// Errors: as [`Warp::check_invertible_on`] when the warp folds the boundary.
pub fn target_boundary(boundary: &TriMesh, warp: &Warp) -> Result<TriMesh> {
    warp.check_invertible_on(boundary.points())?;
    TriMesh::new(
        boundary.points().iter().map(|p| warp.apply(p)).collect(),
        boundary.triangles().to_vec(),
    )
}

/// The target surface: `boundary` midpoint subdivided [`TARGET_SUBDIVISIONS`] times (so that
/// the smooth warp bends its triangles), then carried by `warp` point by point, mm.
///
/// Errors: as [`target_boundary`].
pub fn target_surface(boundary: &TriMesh, warp: &Warp) -> Result<TriMesh> {
    let mut mesh = boundary.clone();
    for _ in 0..TARGET_SUBDIVISIONS {
        mesh = midpoint_subdivide(&mesh)?;
    }
    target_boundary(&mesh, warp)
}

/// The target segmentation: the closed `surface` (a [`target_surface`]) rasterized (1 inside,
/// 0 outside) on an axis-aligned grid of spacing `spacing_mm` around it with `margin_mm` on
/// every side (see [`grid_around`]).
///
/// Errors: as [`grid_around`] and [`rasterize`] (an open surface).
pub fn target_image(surface: &TriMesh, spacing_mm: f64, margin_mm: f64) -> Result<Volume> {
    let (dims, voxel_to_world) = grid_around(surface, spacing_mm, margin_mm)?;
    rasterize(surface, dims, voxel_to_world)
}

/// A synthetic case: its template (with the figures of its projection) and its warp.
#[derive(Clone, Debug)]
pub struct SyntheticCase {
    /// The shape.
    pub shape: Shape,
    /// The medial sheet the template was inflated from (after [`SHEET_SUBDIVISIONS`] Loop
    /// subdivisions).
    pub sheet: MedialSheet,
    /// The projection of the inflated template; its `template` is the case's template.
    pub projection: Projection,
    /// The known diffeomorphism from template to target.
    pub warp: Warp,
}

impl SyntheticCase {
    /// Builds `shape`: sheet, subdivision, inflation, projection (default tolerances), warp
    /// about the centre of the template's bounding box.
    ///
    /// Errors: those of [`inflate`], [`MedialTemplate::new`] and [`project`] (none for the
    /// shapes as defined; a test checks this).
    pub fn build(shape: Shape) -> Result<Self> {
        let mut sheet = shape.coarse_sheet()?;
        for _ in 0..SHEET_SUBDIVISIONS {
            sheet = sheet.loop_subdivide()?;
        }
        let inflated = inflate(&sheet)?;
        let template = MedialTemplate::new(
            inflated.boundary,
            inflated.medial_index,
            inflated.medial_points,
        )?;
        let projection = project(&template, &ProjectOptions::default())?;
        let centre =
            Bounds::of(projection.template.landmarks()).map_or(Vec3::zeros(), |b| b.centre());
        Ok(Self {
            shape,
            sheet,
            warp: shape.warp(centre),
            projection,
        })
    }

    /// The template (projected onto the medial constraints).
    pub fn template(&self) -> &MedialTemplate {
        &self.projection.template
    }

    /// The template's boundary mesh.
    pub fn boundary(&self) -> Result<TriMesh> {
        self.template().boundary_mesh()
    }

    /// [`target_boundary`] of the template: the warped boundary, point for point.
    pub fn target_boundary(&self) -> Result<TriMesh> {
        target_boundary(&self.boundary()?, &self.warp)
    }

    /// [`target_surface`] of the template: its boundary subdivided, then warped.
    pub fn target_surface(&self) -> Result<TriMesh> {
        target_surface(&self.boundary()?, &self.warp)
    }

    /// [`target_image`] of the template: the target surface rasterized with voxels of
    /// `spacing_mm` and `margin_mm` around it.
    pub fn target_image(&self, spacing_mm: f64, margin_mm: f64) -> Result<Volume> {
        target_image(&self.target_surface()?, spacing_mm, margin_mm)
    }
}
