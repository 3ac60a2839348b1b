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
//! 4. the region the points cover in the chart, as a disc of grid cells ([`region`]), mapped
//!    harmonically onto a hexagon of the triangular lattice ([`lattice`]), regular for a round
//!    region and stretched for a long one (a crescent, a strip): one-to-one whatever the
//!    region's outline, star-shaped or not;
//! 5. each lattice point placed by a robust local linear fit of position and radius at its
//!    chart position ([`disc`]); the free edge lies where the wide-angle points end, short of
//!    the rim by about a radius, so that inflation (which rounds the rim by the radius) does
//!    not overshoot the shape's rim.
//!
//! A sheet is built for shapes of one simply connected sheet whose chart is one-to-one (discs,
//! bowls and strips: the heart wall, placenta, leaflets, cmrep's t001); branching shapes
//! (sheets meeting at seams, found by [`branching::branching`]) are refused with their counts.

pub mod branching;
pub mod chart;
pub mod disc;
pub mod lattice;
pub mod region;
pub mod ridge;

use crate::build::inflate::MedialSheet;
use crate::image::Volume;
use crate::{Error, Result, Vec3};
use branching::{branching, Branching};
use chart::Chart;
use disc::{lattice_sheet, ChartedCloud};
use lattice::Lattice;
use region::Region;

pub use ridge::{medial_points, MedialPoint};

/// Default angle between the feature vectors of a medial point's two neighbours, degrees: a
/// sheet with `|∇r| ≤ cos(55°) ≈ 0.57` keeps its points, the 90° corners of a cut rim do not.
pub const MIN_FEATURE_ANGLE_DEG: f64 = 110.0;

/// How densely the sheet is sampled.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Sampling {
    /// About this many atoms after one Loop subdivision of the sheet (which about quadruples
    /// a lattice's points: a regular hexagon of `n` rings has `1 + 3n(n + 1)`, subdivided
    /// `1 + 6n(2n + 1)`).
    Atoms(usize),
    /// About this distance between neighbouring atoms after one Loop subdivision (mm): the
    /// lattice's points are `2·spacing` apart on average over the sheet's area in its chart.
    Spacing(f64),
}

/// The cell of the chart's region grid ([`Region`]), in voxels: at least one medial point per
/// cell on a sheet crossing the grid (a ridge has a point per voxel column through it).
const CELL_VOXELS: f64 = 2.0;

/// The sheet is sampled where its sphere chart is at most this far from the pole, degrees:
/// beyond it the chart stretches lengths across its rays by more than `θ/sin θ` = 8.2 and
/// nears its singular antipode, where local fits in the chart mix far parts of the sheet (a
/// deep bowl's rim, seen from a sphere centred near its base). The points beyond still enter
/// the local fits.
const MAX_CHART_ANGLE_DEG: f64 = 160.0;

/// Row height of the unit triangular lattice, `√3/2`: a lattice of `V` points spaced `d`
/// covers about `V·(√3/2)·d²`.
const LATTICE_AREA: f64 = 0.866_025_403_784_438_6;

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
    /// Rows of the lattice hexagon either side of its middle row ([`Lattice::new`]).
    pub rings: usize,
    /// How many edges the hexagon is stretched by along its middle row (0: a regular hexagon,
    /// a round sheet; more for a long one).
    pub stretch: usize,
    /// The sheet's points on its free edge, in order round it.
    pub border: Vec<usize>,
    /// The sheets and seams of the medial points (one sheet, no seam: others are refused).
    pub branching: Branching,
}

/// The medial sheet of the shape `mask` (voxels > ½ inside, on a grid with orthogonal axes and
/// a background border), sampled as `sampling` says (see the module documentation).
///
/// Errors: those of [`medial_points`]; [`Error::Branching`] for a shape of several sheets or
/// with seams ([`branching()`]); those of [`Chart::fit`], the chart's region and its harmonic
/// map and `lattice_sheet` (a shape that is not one simply connected sheet);
/// `InvalidParameter` for a non-positive sampling.
pub fn sheet_of_mask(mask: &Volume, sampling: Sampling) -> Result<ShapeSheet> {
    let points = medial_points(mask, MIN_FEATURE_ANGLE_DEG)?;
    let voxel = mask.spacing().mean();
    let branching = branching(&points, voxel);
    if branching.sheets != 1 || branching.seams != 0 {
        return Err(Error::Branching {
            sheets: branching.sheets,
            seams: branching.seams,
        });
    }
    let positions: Vec<_> = points.iter().map(|p| p.position).collect();
    let chart = Chart::fit(&positions)?;
    let cell = CELL_VOXELS * voxel;
    // A first region, of every point, sets the sampling and the window; the sheet is fitted
    // to the points without spurs.
    let all = ChartedCloud::new(&points, &chart, None);
    let lift = |q: [f64; 2]| chart.on_surface(q);
    let first = Region::of(&usable(&chart, &all), cell, 1, &lift)?;
    let (rings, stretch) = lattice_of(sampling, first.area(), first.elongation())?;
    let lattice = Lattice::new(rings, stretch);
    let spacing = (first.area() / (lattice.points.len() as f64 * LATTICE_AREA)).sqrt();
    let window = (3.0 * voxel).max(0.5 * spacing);
    let cloud = ChartedCloud::new(&points, &chart, Some(window));
    let closing = (window / cell).ceil() as usize;
    let region = Region::of(&usable(&chart, &cloud), cell, closing, &lift)?;
    let in_chart = region.map_onto(&lattice)?;
    let sheet = lattice_sheet(&cloud, &lattice, &in_chart, window, voxel)?;
    Ok(ShapeSheet {
        sheet,
        spur_free_points: cloud.len(),
        medial_points: points,
        chart,
        rings,
        stretch,
        border: lattice.border,
        branching,
    })
}

/// The points of `cloud` (chart coordinates, position) within [`MAX_CHART_ANGLE_DEG`] of the
/// chart's pole.
fn usable(chart: &Chart, cloud: &ChartedCloud) -> Vec<([f64; 2], Vec3)> {
    let max = MAX_CHART_ANGLE_DEG.to_radians();
    (cloud.coords().iter().zip(cloud.points()))
        .filter(|(&q, _)| chart.angle(q) <= max)
        .map(|(&q, p)| (q, p.position))
        .collect()
}

/// The lattice hexagon (`rings` in 2 ..= 64, `stretch`) for `sampling` on a region of `area`
/// mm² and elongation `L²/A` ([`Lattice::stretch_ratio`]): about `V` points, `V` a quarter of
/// the atoms asked for (one Loop subdivision quadruples them) or `area / ((√3/2)(2s)²)` for a
/// spacing `s` after subdivision, with `V = rings²·(3 + 2ρ)` and `stretch = ρ·rings`.
fn lattice_of(sampling: Sampling, area: f64, elongation: f64) -> Result<(usize, usize)> {
    let points = match sampling {
        Sampling::Atoms(n) if n > 0 => n as f64 / 4.0,
        Sampling::Spacing(s) if s.is_finite() && s > 0.0 => area / (LATTICE_AREA * 4.0 * s * s),
        _ => {
            return Err(Error::InvalidParameter(format!(
                "the sampling of a medial sheet must be positive, got {sampling:?}"
            )))
        }
    };
    let ratio = Lattice::stretch_ratio(elongation);
    let rings = ((points / (3.0 + 2.0 * ratio)).sqrt().round() as usize).clamp(2, 64);
    let stretch = ((ratio * rings as f64).round() as usize).min(16 * rings);
    Ok((rings, stretch))
}
