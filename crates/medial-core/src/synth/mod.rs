//! Synthetic test cases with a known answer: a medial template built from an analytic medial
//! sheet, and a target that is the template's shape carried by a known smooth diffeomorphism.
//!
//! Shapes (all lengths in mm):
//!
//! - [`Shape::Cup`]: an LV-like cup. The medial sheet is the cap `θ ≤ θ_max` of the prolate
//!   spheroid `(a sin θ cos φ, a sin θ sin φ, −c cos θ)` (`a` = [`CUP_EQUATOR`], `c` =
//!   [`CUP_LENGTH`], `θ_max` = [`CUP_OPENING`]), open at the base (a free edge), with half
//!   thickness `r = r_apex + (r_base − r_apex + r_septum cos φ) θ/θ_max`: thin at the apex,
//!   thick at the base, thicker on one side.
//! - [`Shape::Toy`]: the paper's toy, three sheets of width [`TOY_WIDTH`] meeting at 120°
//!   along one straight seam of length [`TOY_LENGTH`] on the z axis, each curled a little
//!   (a point at distance `w` from the seam is lifted by `TOY_CURL · w²` along the sheet's
//!   in-plane normal), with half thickness `r = TOY_RADIUS (1 − 0.3 w/W)(1 − 0.2 (2z/L)²)`.
//!
//! A case is built as a template would be from a real sheet: the coarse sheet is Loop
//! subdivided once, inflated and projected onto the medial constraints
//! ([`crate::construction::project::project`]). The target is the template boundary, midpoint subdivided
//! [`TARGET_SUBDIVISIONS`] times (so that the smooth warp bends its triangles), carried by the
//! case's [`Warp`]: a twist and a bend about the shape's long axis (z) followed by an affine map.
//!
//! Any other template becomes a case the same way: [`PrincipalAxes::of`](crate::mesh::PrincipalAxes::of) its points gives the
//! frame of the twist and bend (long axis z, thickness direction x), [`Warp::bending`] the warp,
//! and [`target_boundary`], [`target_surface`] and [`target_image`] the targets.
//! [`parameter_grid`] triangulates the parameter rectangle of a new analytic sheet.
//!
//! [`stress`] varies a case as real data would: a [`Thickening`] of the wall (global, or a
//! regional bump of known place and size) before the warp, and a [`degrade`]d segmentation
//! (boundary voxels flipped, small holes) after it.

mod case;
mod shape;
mod sheets;
pub mod stress;
mod warp;

pub use case::{
    target_boundary, target_image, target_surface, SyntheticCase, SHEET_SUBDIVISIONS,
    TARGET_SUBDIVISIONS,
};
pub use shape::{
    Shape, CUP_EQUATOR, CUP_LENGTH, CUP_OPENING, CUP_RADIUS_APEX, CUP_RADIUS_BASE,
    CUP_RADIUS_SEPTUM, CUP_RINGS, TOY_CELLS, TOY_CURL, TOY_LENGTH, TOY_RADIUS, TOY_WIDTH,
};
pub use sheets::{parameter_grid, ParameterGrid};
pub use stress::{
    degrade, seeded_directions, Degradation, Degraded, Region, Thickened, Thickening,
};
pub use warp::Warp;
