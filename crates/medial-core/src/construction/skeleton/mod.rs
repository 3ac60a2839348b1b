//! Medial sheets from a shape: the medial points of a binary mask (the ridge of its exact
//! distance map, [`ridge`]), a chart of the sheet they form ([`chart`]), and a regularly
//! sampled triangulated sheet with a radius per vertex through them ([`disc`]) — the input
//! [`inflate`](crate::construction::inflate()) takes.
//!
//! The method, step by step:
//! 1. the exact Euclidean distance and feature transform of the mask
//!    ([`FeatureTransform`](crate::image::distance::FeatureTransform));
//! 2. medial points where the nearest boundary points of two neighbouring voxels make a wide
//!    angle (a scale-free λ-medial axis), their radius the distance to those boundary points;
//!    islands dropped, the share of the largest left out said ([`ridge::medial_pieces`]);
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
//! bowls and strips: the heart wall, placenta, leaflets, cmrep's t001). A branching shape
//! (sheets meeting at seams, found by [`branching::branching`], the paper's toy) is built sheet
//! by sheet: each sheet by steps 3–5 on its own medial points and those of its seams; each seam
//! a polyline through its points ([`seam::Seam`]), clipped to where the sheets reach along it
//! and sampled at the sheets' lattice spacing; the sheets stitched along it ([`mod@stitch`]): each
//! sheet's vertices within a band of the seam dropped, the band between the cut and the seam
//! triangulated by a zipper, so that every seam edge is in three triangles. Several sheets
//! without a seam are refused with their counts.

pub mod branching;
pub mod chart;
pub mod disc;
pub mod lattice;
pub mod region;
pub mod ridge;
pub mod seam;
pub mod stitch;

use crate::construction::inflate::MedialSheet;
use crate::image::Volume;
use crate::{Error, Result, Vec3};
use branching::{branching, Branches};
use chart::Chart;
use disc::{lattice_sheet, ChartedCloud, SheetFit};
use lattice::Lattice;
use region::Region;
use seam::Seam;
use stitch::{free_edges, stitch, Stitch, CUT_RADII, CUT_SPACINGS};

pub use ridge::{medial_pieces, medial_points, MedialPoint};

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

impl Sampling {
    /// Twice as many atoms: the count doubled, or the spacing divided by √2.
    pub fn finer(self) -> Self {
        match self {
            Self::Atoms(n) => Self::Atoms(n.saturating_mul(2)),
            Self::Spacing(s) => Self::Spacing(s / std::f64::consts::SQRT_2),
        }
    }
}

impl std::fmt::Display for Sampling {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Atoms(n) => write!(f, "{n} atoms"),
            Self::Spacing(s) => write!(f, "atoms {s} mm apart"),
        }
    }
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

/// How far the stretch of an elongated sheet's hexagon may be from `ρ·rings`, as a fraction of
/// it, to bring its count nearer the points asked for ([`lattice_of`]): its cells then are up
/// to 25 % longer or shorter along the middle row than across.
const STRETCH_SLACK: f64 = 0.25;

/// Row height of the unit triangular lattice, `√3/2`: a lattice of `V` points spaced `d`
/// covers about `V·(√3/2)·d²`.
const LATTICE_AREA: f64 = 0.866_025_403_784_438_6;

/// A sheet's lattice whose neighbouring triangles turn against each other by more than this,
/// degrees, lies over itself ([`ChartedSheet::sampled`]): between neighbours of a lattice
/// spaced finer than the sheet's radius of curvature the turn is under a radian (57°); a right
/// angle is past any bend the lattice is meant to follow.
const LATTICE_FOLD_DEG: f64 = 90.0;

/// A seam ends where the vertices of its sheets within this many lattice spacings of it end
/// along it ([`clipped`]).
const REACH_SPACINGS: f64 = 2.0;

/// How one sheet of a [`ShapeSheet`] was sampled.
#[derive(Clone, Debug)]
pub struct SheetLattice {
    /// The sheet as sampled on the lattice, before a branching shape's sheets are cut and
    /// stitched along their seams (for one sheet, [`ShapeSheet::sheet`]).
    pub sheet: MedialSheet,
    /// The chart the sheet was sampled in.
    pub chart: Chart,
    /// Rows of the lattice hexagon either side of its middle row ([`Lattice::new`]).
    pub rings: usize,
    /// How many edges the hexagon is stretched by along its middle row (0: a regular hexagon,
    /// a round sheet; more for a long one).
    pub stretch: usize,
}

/// The medial sheet of a [`MedialAxis`] at one sampling ([`MedialAxis::sheet`]).
#[derive(Clone, Debug)]
pub struct ShapeSheet {
    /// The sheet (coarse: Loop-subdivide it once before inflating, as the paper does); for a
    /// branching shape its sheets stitched along the seams, whose vertices come first.
    pub sheet: MedialSheet,
    /// How many of the [`MedialAxis`]'s points were kept as not on spurs (`ChartedCloud::new`),
    /// over all sheets.
    pub spur_free_points: usize,
    /// How each sheet was sampled.
    pub lattices: Vec<SheetLattice>,
    /// The sheet's points on its free edges: in order round it for a single sheet, ascending
    /// for several.
    pub border: Vec<usize>,
    /// The seams as sampled and stitched along (those some sheet reaches, [`stitch()`]): their
    /// vertices are the sheet's first, seam after seam.
    pub seams: Vec<Seam>,
    /// The sheet (`0 .. sheets`, in the order of `lattices`) of each of the sheet's points;
    /// `None` on a seam.
    pub sheet_of_point: Vec<Option<usize>>,
    /// Each sheet's local fit to its medial points, in the order of `lattices`.
    fits: Vec<SheetFit>,
}

impl ShapeSheet {
    /// The sheet after one Loop subdivision ([`MedialSheet::loop_subdivide`]), each point off
    /// the seams placed again, position and radius, by its sheet's local fit to the medial
    /// points at its place in the sheet's chart — the fit that placed the lattice's points.
    ///
    /// Loop subdivision approximates: it moves every point towards the mean of its neighbours,
    /// by about a quarter of the lattice spacing squared times the sheet's curvature. On a
    /// coarse lattice of a curved thin wall that is more than the wall's half thickness (the
    /// biv-me heart's right ventricle: half its subdivided points left the wall), so the
    /// subdivision only gives the atoms' connectivity and regular spacing, and the medial
    /// points their places. That holds in the band the stitching triangulated along each seam
    /// too (the points of the triangles with a corner on a seam, and the points subdivision
    /// puts between them): there the zipper's triangles are straight chords from the cut to
    /// the seam, across a wall that curves into its junction. The band's subdivided places are
    /// kept beside ([`Subdivided::band`]): the band's width was chosen for them
    /// ([`CUT_RADII`]), and they are where an atom goes back to where its place on the medial
    /// points makes the boundary cross itself.
    ///
    /// Errors: those of [`MedialSheet::loop_subdivide`], of the fit (a point whose chart
    /// window holds too few medial points) and of [`MedialSheet::new`] (a triangle the new
    /// places make degenerate).
    pub fn subdivided(&self) -> Result<Subdivided> {
        let subdivided = self.sheet.loop_subdivide()?;
        // The band: the points of the triangles with a corner on a seam.
        let mut off_band = self.sheet_of_point.clone();
        for t in self.sheet.triangles() {
            if t.iter().any(|&v| self.sheet_of_point[v].is_none()) {
                t.iter().for_each(|&v| off_band[v] = None);
            }
        }
        let in_band = self.sheet.subdivided_labels(&off_band);
        let labels = self.sheet.subdivided_labels(&self.sheet_of_point);
        let mut points = subdivided.points().to_vec();
        let mut radius = subdivided.radius().to_vec();
        let mut band = vec![None; points.len()];
        for (m, label) in labels.iter().enumerate() {
            if let Some(k) = *label {
                if in_band[m].is_none() {
                    band[m] = Some((points[m], radius[m]));
                }
                let (lattice, fit) = (&self.lattices[k], &self.fits[k]);
                (points[m], radius[m]) = fit.at(lattice.chart.coords(&points[m]))?;
            }
        }
        Ok(Subdivided {
            sheet: MedialSheet::new(points, subdivided.triangles().to_vec(), radius)?,
            band,
        })
    }
}

/// A shape's sheet after one subdivision, its atoms on the shape's medial points
/// ([`ShapeSheet::subdivided`]).
#[derive(Clone, Debug)]
pub struct Subdivided {
    /// The subdivided sheet.
    pub sheet: MedialSheet,
    /// For each atom of a seam's band, its place and radius as subdivided (on the straight
    /// band the stitching triangulated); `None` off the bands and on the seams.
    pub band: Vec<Option<(Vec3, f64)>>,
}

impl Subdivided {
    /// `sheet` (this sheet with other radii, as inflation lowers them) with the band atoms
    /// among `atoms` put back on their subdivided places, and those atoms; a band atom already
    /// there, and an atom off the bands, is left.
    pub fn band_put_back(
        &self,
        sheet: &MedialSheet,
        atoms: impl IntoIterator<Item = usize>,
    ) -> Result<(MedialSheet, Vec<usize>)> {
        let (mut points, mut radius) = (sheet.points().to_vec(), sheet.radius().to_vec());
        let mut moved = Vec::new();
        for m in atoms {
            if let Some((p, r)) = self.band[m] {
                if points[m] != p {
                    (points[m], radius[m]) = (p, r);
                    moved.push(m);
                }
            }
        }
        let sheet = MedialSheet::new(points, sheet.triangles().to_vec(), radius)?;
        Ok((sheet, moved))
    }
}

/// The medial points of a shape with the sheets and seams they form: what every sampling of
/// its sheet starts from ([`MedialAxis::sheet`]), found once.
#[derive(Clone, Debug)]
pub struct MedialAxis {
    /// The medial points (after dropping islands).
    pub points: Vec<MedialPoint>,
    /// The share of the medial points' summed radii that the largest dropped island held
    /// ([`medial_pieces`]; 0 for points given to [`MedialAxis::of_points`]).
    pub left_out: f64,
    /// The mean voxel of the mask they were found on, mm.
    pub voxel: f64,
    /// Which sheet or seam each point is on ([`branching()`]).
    pub branches: Branches,
}

impl MedialAxis {
    /// The medial points of the shape `mask` (voxels > ½ inside, on a grid with orthogonal axes
    /// and a background border) and their branching (steps 1–2 of the module documentation).
    ///
    /// Errors: those of [`medial_pieces`].
    pub fn of_mask(mask: &Volume) -> Result<Self> {
        let (points, left_out) = medial_pieces(mask, MIN_FEATURE_ANGLE_DEG)?;
        Ok(Self {
            left_out,
            ..Self::of_points(points, mask.spacing().mean())
        })
    }

    /// The medial points `points` of a mask of mean voxel `voxel` (mm) and their branching.
    pub fn of_points(points: Vec<MedialPoint>, voxel: f64) -> Self {
        let branches = branching(&points, voxel);
        Self {
            points,
            left_out: 0.0,
            voxel,
            branches,
        }
    }

    /// The medial sheet through the points, sampled as `sampling` says (see the module
    /// documentation).
    ///
    /// A shape of one sheet gets one lattice sheet. A branching shape (sheets meeting at seams,
    /// [`branching()`]) gets one per sheet, each on the sheet's medial points and those of the
    /// seams it reaches, and the seams as polylines ([`Seam::fit`]) sampled as finely as the
    /// sheets' lattices (their mean spacing); the sheets are stitched along them ([`stitch()`]).
    ///
    /// Errors: [`Error::Branching`] for a shape of several sheets without seams; those of
    /// [`Chart::fit`], the chart's region and its harmonic map, `lattice_sheet` (a shape that
    /// is not one simply connected sheet), [`Seam::fit`] and [`stitch()`]; `InvalidParameter`
    /// for a non-positive sampling.
    pub fn sheet(&self, sampling: Sampling) -> Result<ShapeSheet> {
        let counts = self.branches.counts;
        if counts.seams > 0 {
            return several_sheets(self, sampling);
        }
        if counts.sheets != 1 {
            return Err(Error::Branching {
                sheets: counts.sheets,
                seams: counts.seams,
            });
        }
        let charted = ChartedSheet::new(self.points.clone(), self.voxel)?;
        let first = &charted.first;
        let (rings, stretch) = lattice_of(sampling, first.area(), first.elongation())?;
        let built = charted.sampled(rings, stretch)?;
        Ok(ShapeSheet {
            sheet_of_point: vec![Some(0); built.lattice.sheet.points().len()],
            sheet: built.lattice.sheet.clone(),
            spur_free_points: built.fit.cloud().len(),
            lattices: vec![built.lattice],
            border: built.border,
            seams: Vec::new(),
            fits: vec![built.fit],
        })
    }
}

/// The medial sheet of the shape `mask`, sampled as `sampling` says: [`MedialAxis::of_mask`]
/// then [`MedialAxis::sheet`] (one call builds the axis again for each sampling; keep the
/// [`MedialAxis`] to sample it several times).
///
/// Errors: those of both.
pub fn sheet_of_mask(mask: &Volume, sampling: Sampling) -> Result<ShapeSheet> {
    MedialAxis::of_mask(mask)?.sheet(sampling)
}

/// The stitched sheet of a branching shape (see [`sheet_of_mask`]): the atoms asked for
/// shared over the sheets by area, `s = √(A/((√3/2)·n))` for `n` atoms over the sheets' total
/// area `A` less the bands of width [`CUT_RADII`]` · r̄` along each side of a seam (`r̄` its
/// mean radius), which the stitching fills with the seam's vertices (at least a quarter of
/// the area is kept). For `n` atoms the sheet is sampled again up to [`COUNT_PASSES`] times at
/// `s·√(a/n)` while its atoms after subdivision `a` are more than [`COUNT_SLACK`] off `n` (a
/// sheet's lattice has whole rings, and the cut along a seam drops a band of them), and the
/// sampling nearest `n` in ratio is kept.
fn several_sheets(axis: &MedialAxis, sampling: Sampling) -> Result<ShapeSheet> {
    let (points, branches, voxel) = (&axis.points, &axis.branches, axis.voxel);
    let of =
        |indices: &[usize]| -> Vec<MedialPoint> { indices.iter().map(|&i| points[i]).collect() };
    let counts = branches.counts;
    let seams = (0..counts.seams)
        .map(|s| Seam::fit(&of(&branches.seam_points(s)), voxel))
        .collect::<Result<Vec<_>>>()?;
    let charted = (0..counts.sheets)
        .map(|k| {
            let mut own = branches.sheet_points(k);
            for (s, on) in branches.seam_sheets.iter().enumerate() {
                if on.contains(&k) {
                    own.extend(branches.seam_points(s));
                }
            }
            ChartedSheet::new(of(&own), voxel)
        })
        .collect::<Result<Vec<_>>>()?;
    // The bands along the seams that the stitching cuts off and fills with the seam's own
    // vertices hold no lattice points.
    let bands: f64 = (seams.iter().zip(&branches.seam_sheets))
        .map(|(seam, on)| on.len() as f64 * CUT_RADII * seam.mean_radius() * seam.length())
        .sum();
    let area: f64 = charted.iter().map(|c| c.first.area()).sum();
    let mut spacing = atom_spacing(sampling, (area - bands).max(area / 4.0))?;
    let sample = |spacing: f64| Stitched::new(&charted, &seams, &branches.seam_sheets, spacing);
    let mut best = sample(spacing)?;
    if let Sampling::Atoms(n) = sampling {
        let off = |s: &Stitched| (s.atoms() as f64 / n as f64).ln().abs();
        let mut last = best.atoms();
        for _ in 1..COUNT_PASSES {
            if off(&best) <= COUNT_SLACK.ln_1p() {
                break;
            }
            spacing *= (last as f64 / n as f64).sqrt();
            let next = sample(spacing)?;
            last = next.atoms();
            if off(&next) < off(&best) {
                best = next;
            }
        }
    }
    let Stitched { stitched, built } = best;
    Ok(ShapeSheet {
        sheet_of_point: stitched.sheet_of_point,
        border: free_edge_points(&stitched.sheet),
        sheet: stitched.sheet,
        spur_free_points: built.iter().map(|b| b.fit.cloud().len()).sum(),
        lattices: built.iter().map(|b| b.lattice.clone()).collect(),
        fits: built.into_iter().map(|b| b.fit).collect(),
        seams: stitched.seams,
    })
}

/// How many times at most a branching shape's sheets are sampled to come near the atoms asked
/// for ([`several_sheets`]).
const COUNT_PASSES: usize = 3;

/// A branching shape's atoms within this fraction of those asked for are taken at once.
const COUNT_SLACK: f64 = 0.1;

/// The sheets of a branching shape sampled at one spacing and stitched along its seams.
struct Stitched {
    stitched: Stitch,
    built: Vec<SampledSheet>,
}

impl Stitched {
    /// Each sheet of `charted` sampled at `spacing` (mm between atoms after subdivision), the
    /// `seams` (each along the sheets `seam_sheets` says) clipped to where those reach and
    /// resampled at the lattices' mean spacing, and the sheets stitched along them.
    ///
    /// Errors: those of [`lattice_of`], [`ChartedSheet::sampled`] and [`stitch()`].
    fn new(
        charted: &[ChartedSheet],
        seams: &[Seam],
        seam_sheets: &[Vec<usize>],
        spacing: f64,
    ) -> Result<Self> {
        let built = (charted.iter())
            .map(|c| {
                let sampling = Sampling::Spacing(spacing);
                let (rings, stretch) = lattice_of(sampling, c.first.area(), c.first.elongation())?;
                c.sampled(rings, stretch)
            })
            .collect::<Result<Vec<_>>>()?;
        let lattice_spacing = built.iter().map(|b| b.spacing).sum::<f64>() / built.len() as f64;
        let sheets: Vec<MedialSheet> = built.iter().map(|b| b.lattice.sheet.clone()).collect();
        let seams: Vec<Seam> = (seams.iter().zip(seam_sheets))
            .map(|(seam, on)| {
                let along: Vec<&MedialSheet> = on.iter().map(|&k| &sheets[k]).collect();
                clipped(seam, &along, REACH_SPACINGS * lattice_spacing).resampled(lattice_spacing)
            })
            .collect();
        let stitched = stitch(&sheets, &seams, CUT_SPACINGS * lattice_spacing)?;
        Ok(Self { stitched, built })
    }

    /// The atoms after one Loop subdivision.
    fn atoms(&self) -> usize {
        self.stitched.sheet.subdivided_point_count()
    }
}

/// `seam` clipped to where the sheets `along` it reach: between the means over the sheets of
/// the least and the greatest arc length along it ([`Seam::arc_of`]) of their vertices within
/// `reach` mm of it (a sheet without any leaves the seam whole).
fn clipped(seam: &Seam, along: &[&MedialSheet], reach: f64) -> Seam {
    let ends: Vec<[f64; 2]> = (along.iter())
        .map(|sheet| {
            let arcs = (sheet.points().iter())
                .filter(|p| seam.distance(p) <= reach)
                .map(|p| seam.arc_of(p));
            arcs.fold([seam.length(), 0.0], |[lo, hi], s| [lo.min(s), hi.max(s)])
        })
        .map(|[lo, hi]| {
            if lo <= hi {
                [lo, hi]
            } else {
                [0.0, seam.length()]
            }
        })
        .collect();
    let mean = |k: usize| ends.iter().map(|e| e[k]).sum::<f64>() / ends.len() as f64;
    seam.between(mean(0), mean(1))
}

/// The points of `sheet` on an edge of one triangle, ascending.
fn free_edge_points(sheet: &MedialSheet) -> Vec<usize> {
    let mut free: Vec<usize> = (free_edges(sheet.triangles()).into_iter())
        .flat_map(|(u, v)| [u, v])
        .collect();
    free.sort_unstable();
    free.dedup();
    free
}

/// The medial points of one sheet in its chart, with the region they cover there on a first
/// grid (closed by one cell), which sets the sampling.
struct ChartedSheet {
    points: Vec<MedialPoint>,
    chart: Chart,
    first: Region,
    voxel: f64,
}

/// One sheet sampled on a lattice ([`ChartedSheet::sampled`]).
struct SampledSheet {
    lattice: SheetLattice,
    /// The lattice's points on its border, in order round it.
    border: Vec<usize>,
    /// The lattice's mean spacing on the sheet (mm).
    spacing: f64,
    /// The local fit that placed the lattice's points.
    fit: SheetFit,
}

impl ChartedSheet {
    /// The chart of `points` (medial points of a mask of mean voxel `voxel`, mm) and their
    /// first region: every point, cells of [`CELL_VOXELS`], closed by one cell.
    ///
    /// Errors: those of [`Chart::fit`] and [`Region::of`].
    fn new(points: Vec<MedialPoint>, voxel: f64) -> Result<Self> {
        let positions: Vec<_> = points.iter().map(|p| p.position).collect();
        let chart = Chart::fit(&positions)?;
        let all = ChartedCloud::new(&points, &chart, None);
        let lift = |q: [f64; 2]| chart.on_surface(q);
        let first = Region::of(&usable(&chart, &all), CELL_VOXELS * voxel, 1, &lift)?;
        Ok(Self {
            points,
            chart,
            first,
            voxel,
        })
    }

    /// The sheet on the hexagon of `rings` and `stretch`: the first region sets the lattice's
    /// spacing `s` and the fits' window (`max(3 voxels, s/2)`); the sheet is fitted to the
    /// points without spurs, on the region of those closed by the window.
    ///
    /// Where that sheet lies over itself (neighbouring triangles turned by more than
    /// [`LATTICE_FOLD_DEG`]), it is sampled again on the region closed by `s`, which fills the
    /// inlets of the outline up to about `2s` wide, and the one that folds less is kept: a
    /// lattice cannot follow an inlet that narrow (it needs a row of points along each side
    /// and one between), and the harmonic map crowds the rows either side of it against each
    /// other until they fold at its tip (the biv-me heart's RV free wall, open between its
    /// insertion lines where the valves are; decision 0413). Filled, the inlet is spanned by
    /// the lattice, placed by fits that reach across it.
    ///
    /// Errors: those of [`Region::of`], [`Region::map_onto`] and `lattice_sheet`.
    fn sampled(&self, rings: usize, stretch: usize) -> Result<SampledSheet> {
        let (chart, voxel) = (&self.chart, self.voxel);
        let cell = CELL_VOXELS * voxel;
        let lattice = Lattice::new(rings, stretch);
        let spacing = (self.first.area() / (lattice.points.len() as f64 * LATTICE_AREA)).sqrt();
        let window = (3.0 * voxel).max(0.5 * spacing);
        let cloud = ChartedCloud::new(&self.points, chart, Some(window));
        let lift = |q: [f64; 2]| chart.on_surface(q);
        let charted = usable(chart, &cloud);
        let fit = SheetFit::new(cloud, window, voxel);
        let sheet_closed_by = |closing: f64| -> Result<MedialSheet> {
            let closing = (closing / cell).ceil() as usize;
            let in_chart = Region::of(&charted, cell, closing, &lift)?.map_onto(&lattice)?;
            lattice_sheet(&fit, &lattice, &in_chart)
        };
        let sharpest = |sheet: &MedialSheet| {
            (sheet.folds(LATTICE_FOLD_DEG).iter()).fold(0.0, |w: f64, f| w.max(f.0))
        };
        let mut sheet = sheet_closed_by(window)?;
        let folded = sharpest(&sheet);
        if folded > 0.0 {
            match sheet_closed_by(spacing) {
                Ok(closed) if sharpest(&closed) < folded => sheet = closed,
                _ => {}
            }
        }
        Ok(SampledSheet {
            lattice: SheetLattice {
                sheet,
                chart: *chart,
                rings,
                stretch,
            },
            border: lattice.border,
            spacing,
            fit,
        })
    }
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
/// mm² and elongation `L²/A` ([`Lattice::stretch_ratio`] `ρ`): for `n` atoms, the hexagon
/// whose atoms after one Loop subdivision ([`Lattice::subdivided_count`]) are nearest `n` in
/// ratio; for a spacing `s` after subdivision, the one whose `V` points
/// ([`Lattice::point_count`]) are nearest `area / ((√3/2)(2s)²)`. Taken
/// over the whole rings either side of `√(V/(3 + 2ρ))` (`V ≈ rings²·(3 + 2ρ)`) and, for an
/// elongated region (`ρ > 0`), the stretches within [`STRETCH_SLACK`] of `ρ·rings` (at least
/// one edge either way): rounding the rings alone would take 2.6 rings to 3, 1.6 times the
/// points asked for. A round region keeps a regular hexagon.
fn lattice_of(sampling: Sampling, area: f64, elongation: f64) -> Result<(usize, usize)> {
    let points = match sampling {
        Sampling::Atoms(n) if n > 0 => n as f64 / 4.0,
        Sampling::Spacing(s) if s.is_finite() && s > 0.0 => area / (LATTICE_AREA * 4.0 * s * s),
        _ => return Err(non_positive(sampling)),
    };
    let ratio = Lattice::stretch_ratio(elongation);
    let rings = (points / (3.0 + 2.0 * ratio)).sqrt();
    let candidates = [rings.floor() as usize, rings.ceil() as usize]
        .map(|r| r.clamp(2, 64))
        .into_iter()
        .flat_map(|r| {
            let aimed = ratio * r as f64;
            let slack = if ratio > 0.0 {
                (STRETCH_SLACK * aimed).max(1.0)
            } else {
                0.0
            };
            let (lo, hi) = ((aimed - slack).ceil().max(0.0), (aimed + slack).floor());
            (lo as usize..=(hi as usize).max(lo as usize)).map(move |s| (r, s.min(16 * r)))
        });
    let off = |&(r, s): &(usize, usize)| {
        let (count, aim) = match sampling {
            Sampling::Atoms(n) => (Lattice::subdivided_count(r, s), n as f64),
            _ => (Lattice::point_count(r, s), points),
        };
        (count as f64 / aim).ln().abs()
    };
    Ok(candidates
        .min_by(|a, b| off(a).total_cmp(&off(b)))
        .expect("two candidate ring counts"))
}

/// The distance between atoms (mm) for `sampling` over sheets of total area `area` (mm²):
/// `√(A/((√3/2)·n))` for `n` atoms (a lattice of `n/4` points spaced `2s` covers `A`).
fn atom_spacing(sampling: Sampling, area: f64) -> Result<f64> {
    match sampling {
        Sampling::Atoms(n) if n > 0 => Ok((area / (LATTICE_AREA * n as f64)).sqrt()),
        Sampling::Spacing(s) if s.is_finite() && s > 0.0 => Ok(s),
        _ => Err(non_positive(sampling)),
    }
}

/// The error for a sampling that is not positive.
fn non_positive(sampling: Sampling) -> Error {
    Error::InvalidParameter(format!(
        "the sampling of a medial sheet must be positive, got {sampling:?}"
    ))
}
