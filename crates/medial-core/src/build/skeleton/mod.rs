//! Medial sheets from a shape: the medial points of a binary mask (the ridge of its exact
//! distance map, [`ridge`]), a chart of the sheet they form ([`chart`]), and a regularly
//! sampled triangulated sheet with a radius per vertex through them ([`disc`]) — the input
//! [`inflate`](crate::build::inflate()) takes.
//!
//! The method, step by step:
//! 1. the exact Euclidean distance and feature transform of the mask
//!    ([`FeatureTransform`](crate::image::distance::FeatureTransform));
//! 2. medial points where the nearest boundary points of two neighbouring voxels make a wide
//!    angle (a scale-free λ-medial axis), their radius the distance to those boundary points;
//!    islands dropped ([`ridge::medial_points`]);
//! 3. a chart of the points: an azimuthal equidistant projection of a fitted sphere (bowls) or
//!    the principal plane (flat sheets) ([`chart::Chart`]);
//! 4. a disc of rings stretched to the outline of the points in the chart, each vertex placed
//!    by a robust local linear fit of position and radius ([`disc`]); its free edge lies where
//!    the wide-angle points end, short of the rim by about a radius, so that inflation (which
//!    rounds the rim by the radius) does not overshoot the shape's rim.
//!
//! A sheet is built for shapes of one sheet whose chart is one-to-one (discs and bowls: the
//! heart wall, placenta, leaflets); branching shapes (sheets meeting at seams) are not built
//! yet and are refused when their outline does not surround the chart's centre.

pub mod chart;
pub mod disc;
pub mod ridge;

use crate::build::inflate::MedialSheet;
use crate::image::Volume;
use crate::{Error, Result};
use chart::Chart;
use disc::{disc_sheet, ChartedCloud};

pub use ridge::{medial_points, MedialPoint};

/// Default angle between the feature vectors of a medial point's two neighbours, degrees: a
/// sheet with `|∇r| ≤ cos(55°) ≈ 0.57` keeps its points, the 90° corners of a cut rim do not.
pub const MIN_FEATURE_ANGLE_DEG: f64 = 110.0;

/// How densely the sheet is sampled.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Sampling {
    /// About this many atoms after one Loop subdivision of the sheet: `rings =
    /// round(√(N/12))`, since a disc of `n` rings subdivided once has `1 + 6n(2n + 1)` points.
    Atoms(usize),
    /// About this distance between neighbouring atoms after one Loop subdivision (mm): the
    /// sheet's rings are `2·spacing` apart along the mean chart radius.
    Spacing(f64),
}

/// What [`sheet_of_mask`] built.
#[derive(Clone, Debug)]
pub struct ShapeSheet {
    /// The sheet (coarse: Loop-subdivide it once before inflating, as the paper does).
    pub sheet: MedialSheet,
    /// The medial points found (after dropping islands).
    pub medial_points: Vec<MedialPoint>,
    /// How many of them were kept as not on spurs (`ChartedCloud::new`).
    pub spur_free_points: usize,
    /// The chart the sheet was sampled in.
    pub chart: Chart,
    /// Rings of the disc.
    pub rings: usize,
}

/// The medial sheet of the shape `mask` (voxels > ½ inside, on a grid with orthogonal axes and
/// a background border), sampled as `sampling` says (see the module documentation).
///
/// Errors: those of [`medial_points`], [`Chart::fit`] and `disc_sheet` (a shape that
/// is not one disc- or bowl-shaped sheet), `InvalidParameter` for a non-positive sampling.
pub fn sheet_of_mask(mask: &Volume, sampling: Sampling) -> Result<ShapeSheet> {
    let points = medial_points(mask, MIN_FEATURE_ANGLE_DEG)?;
    let positions: Vec<_> = points.iter().map(|p| p.position).collect();
    let chart = Chart::fit(&positions)?;
    let voxel = mask.spacing().mean();
    // A first outline, of every point, sets the sampling and the window; the sheet is fitted
    // to the points without spurs.
    let all = ChartedCloud::new(&points, &chart, None);
    let mean_outline = mean(&all.outline()?);
    let rings = rings_of(sampling, mean_outline)?;
    let window = (3.0 * voxel).max(0.5 * mean_outline / rings as f64);
    let cloud = ChartedCloud::new(&points, &chart, Some(window));
    let sheet = disc_sheet(&cloud, &cloud.outline()?, rings, window, voxel)?;
    Ok(ShapeSheet {
        sheet,
        spur_free_points: cloud.len(),
        medial_points: points,
        chart,
        rings,
    })
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// The rings of the disc for `sampling` on a sheet of mean chart radius `extent` mm (at least
/// 2, at most 64).
fn rings_of(sampling: Sampling, extent: f64) -> Result<usize> {
    let rings = match sampling {
        Sampling::Atoms(n) if n > 0 => (n as f64 / 12.0).sqrt(),
        Sampling::Spacing(s) if s.is_finite() && s > 0.0 => extent / (2.0 * s),
        _ => {
            return Err(Error::InvalidParameter(format!(
                "the sampling of a medial sheet must be positive, got {sampling:?}"
            )))
        }
    };
    Ok((rings.round() as usize).clamp(2, 64))
}
