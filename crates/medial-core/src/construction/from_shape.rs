//! A medial template from a shape (a segmentation or a closed mesh), built as the paper builds
//! one by hand, automatically (docs/method.md §9.3):
//! 1. the shape as a mask on a grid fine enough for its thinnest wall (a third of the 10th
//!    percentile of the half thicknesses found on a first, coarser grid);
//! 2. its medial points, the sheets and seams they form ([`MedialAxis`]), and its medial sheet
//!    with a radius per vertex ([`MedialAxis::sheet`]);
//! 3. one Loop subdivision, inflation and projection onto the medial constraints;
//! 4. the constrained Dice fit of that template to the mask itself (the automatic fit's plan
//!    and initial alignment, [`crate::fit::run::automatic`], with its own shorter μ schedule,
//!    [`self_fit_schedule`]), then projection again, so that the template matches its shape and
//!    its constraints hold to the projection's tolerance.
//!
//! ```no_run
//! use medial_core::construction::from_shape::{template_of_shape, Shape, TemplateOptions};
//! use medial_core::memory::MemoryLimit;
//! # fn segmentation() -> medial_core::image::Volume { unimplemented!() }
//! let shape = Shape::of_segmentation(&segmentation(), None);
//! let built = template_of_shape(&shape, &TemplateOptions::default(), MemoryLimit::none()).unwrap();
//! assert!(built.figures.verdict().is_ok());
//! ```

use crate::construction::inflate::{inflate, self_intersections, MedialSheet};
use crate::construction::project::{project, ProjectOptions};
use crate::construction::skeleton::branching::{flat_about, MIN_BALL_POINTS};
use crate::construction::skeleton::chart::ChartKind;
pub use crate::construction::skeleton::ridge::LEFT_OUT_LIMIT;
use crate::construction::skeleton::seam::Seam;
use crate::construction::skeleton::{
    medial_points, MedialAxis, MedialPoint, Sampling, ShapeSheet, Subdivided, MIN_FEATURE_ANGLE_DEG,
};
use crate::fit::augmented_lagrangian::CoarseTime;
use crate::fit::guard::Guard;
use crate::fit::optimize::ProgressRule;
use crate::fit::plan::COARSE_TIME_STEPS;
use crate::fit::run::automatic;
use crate::fit::spec::StageSpec;
use crate::fit::Target;
use crate::image::rasterize::{grid_around, grid_around_bounds, rasterize, voxel_dice};
use crate::image::Volume;
use crate::memory::{Estimate, MemoryLimit};
use crate::mesh::topology::{check_closed_oriented_manifold, check_outward};
use crate::mesh::Bounds;
use crate::model::template::MAX_SPOKES;
use crate::model::{MedialTemplate, Model, SpokeMetrics, TemplateSummary};
use crate::{Error, Result, TriMesh, Vec3};
use serde::Serialize;
use std::collections::BTreeSet;

/// Atoms of a template when neither a count nor a spacing is given.
pub const DEFAULT_ATOMS: usize = 300;
/// Most voxels of the fine grid.
pub const MAX_VOXELS: usize = 32_000_000;
/// The fine voxel is this fraction of the thin half thickness: a wall is at least six voxels
/// across, so that its two sides' ridge points are told apart.
const VOXELS_PER_RADIUS: f64 = 3.0;
/// Percentile of the half thicknesses taken as the thin wall (the thinnest few are noise of
/// the coarse grid).
const THIN_PERCENTILE: f64 = 0.10;
/// Grid margin around the shape, voxels.
pub const MARGIN_VOXELS: f64 = 3.0;
/// The Gaussian (in voxels of the segmentation) a mask is smoothed with when its sheet as given
/// gives no sound template ([`Shape::denoised`]): a segmentation's boundary is known to about a
/// voxel, and a voxel flipped alone on it (noise) is a bump of the fine grid's boundary and a
/// branch of its medial axis. At ½ voxel (the kernel sampled on the voxels: 0.79 at the centre,
/// 0.11 at either neighbour) a voxel alone (peak 0.49) is gone after the cut at ½, one alone on
/// a flat face is a smaller bump, the face stays where it was, and a wall one voxel thick stays
/// (0.84 voxel wide).
pub const NOISE_SCALE: f64 = 0.5;
/// Voxels along the longest side of a mesh's first, coarse grid.
const COARSE_VOXELS: f64 = 96.0;
/// The Dice of a template against its shape that counts as matching it.
pub const TARGET_DICE: f64 = 0.95;
/// The largest spoke–normal angle of a finished template, degrees.
pub const MAX_ANGLE_DEG: f64 = 0.1;
/// The largest spoke mismatch of a finished template, %.
pub const MAX_MISMATCH_PCT: f64 = 0.1;

/// A shape to build a template of.
#[derive(Clone, Debug)]
pub enum Shape {
    /// A binary mask on the input's grid (1 inside), and the input itself when it is a graded
    /// signed image read without a label (a level set, foreground `v > 0`): the fine grid then
    /// follows the zero crossing of its trilinear interpolant, not the whole voxels of the mask.
    Mask(Box<Volume>, Option<Box<Volume>>),
    /// A closed triangle mesh (mm).
    Mesh(TriMesh),
}

impl Shape {
    /// The shape of a segmentation: its foreground (`label`, or every voxel > 0), following the
    /// zero crossing of a graded signed image read without a label.
    pub fn of_segmentation(image: &Volume, label: Option<f64>) -> Self {
        let mask = Box::new(image.foreground(label));
        let graded = (label.is_none() && image.is_graded_signed()).then(|| Box::new(image.clone()));
        Self::Mask(mask, graded)
    }

    /// The voxel of the first, coarse grid: half the input's smallest voxel, or a
    /// [`COARSE_VOXELS`]th of a mesh's longest side.
    fn coarse_voxel(&self) -> Result<f64> {
        Ok(match self {
            Self::Mask(mask, _) => mask.spacing().min() / 2.0,
            Self::Mesh(_) => self.bounds()?.extent().max() / COARSE_VOXELS,
        })
    }

    /// The shape as a mask (1 inside) on an axis-aligned grid of voxel `h` with
    /// [`MARGIN_VOXELS`] around it: the mesh rasterized, or the mask sampled trilinearly and
    /// cut at ½. Refused past [`MAX_VOXELS`] or `memory`.
    pub fn on_grid(&self, h: f64, memory: MemoryLimit) -> Result<Volume> {
        let margin = MARGIN_VOXELS * h;
        let (dims, to_world) = match self {
            Self::Mesh(mesh) => grid_around(mesh, h, margin),
            Self::Mask(..) => grid_around_bounds(&self.bounds()?, h, margin),
        }?;
        let voxels: usize = dims.iter().product();
        if voxels > MAX_VOXELS {
            return Err(Error::InvalidParameter(format!(
                "a grid of {h:.3} mm voxels around the shape is {}×{}×{} = {voxels} voxels, \
                 more than {MAX_VOXELS}; give a larger voxel",
                dims[0], dims[1], dims[2]
            )));
        }
        memory.check(&Estimate::grid(dims), || {
            let voxels: f64 = dims.map(|n| n as f64).iter().product();
            format!(
                "a {}×{}×{} grid ({voxels:.2e} voxels)",
                dims[0], dims[1], dims[2]
            )
        })?;
        match self {
            Self::Mesh(mesh) => rasterize(mesh, dims, to_world),
            Self::Mask(mask, graded) => {
                let (image, cut) = match graded {
                    Some(graded) => (graded, 0.0),
                    None => (mask, 0.5),
                };
                image.resampled(dims, to_world).and_then(|v| {
                    let data = v.data().iter().map(|&x| f64::from(u8::from(x > cut)));
                    Volume::new(dims, data.collect(), to_world)
                })
            }
        }
    }

    /// A binary segmentation's shape with its noise taken out: the mask smoothed by a Gaussian
    /// of [`NOISE_SCALE`] of its smallest voxel, cut at ½ on the fine grid (the mask itself
    /// kept for the bounds and the Dice on its own grid). `None` for a graded image or a mesh,
    /// which carry their own sub-voxel boundary.
    pub fn denoised(&self) -> Result<Option<Self>> {
        let Self::Mask(mask, None) = self else {
            return Ok(None);
        };
        let smoothed = mask.smoothed(NOISE_SCALE * mask.spacing().min())?;
        let level = smoothed.data().iter().map(|v| v - 0.5).collect();
        let graded = Volume::new(mask.dims(), level, *mask.voxel_to_world())?;
        Ok(Some(Self::Mask(mask.clone(), Some(Box::new(graded)))))
    }

    /// The bounding box of the shape (the mask's foreground voxels, or the mesh's points).
    pub fn bounds(&self) -> Result<Bounds> {
        match self {
            Self::Mask(mask, _) => mask.support_bounds(),
            Self::Mesh(mesh) => Bounds::of(mesh.points()),
        }
        .ok_or_else(|| Error::InvalidParameter("the shape is empty".into()))
    }
}

/// How to build a template of a shape.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TemplateOptions {
    /// How densely the sheet is sampled.
    pub sampling: Sampling,
    /// Voxel size of the grid the medial sheet is found on, mm (none: a third of the thin half
    /// thickness, at most the input's half voxel).
    pub voxel: Option<f64>,
    /// Fit the projected inflation to the shape (step 4).
    pub fit: bool,
}

impl Default for TemplateOptions {
    fn default() -> Self {
        Self {
            sampling: Sampling::Atoms(DEFAULT_ATOMS),
            voxel: None,
            fit: true,
        }
    }
}

/// A template built from a shape, with what it was built from.
pub struct BuiltTemplate {
    /// The template.
    pub template: MedialTemplate,
    /// The medial sheet found, with how it was sampled.
    pub found: ShapeSheet,
    /// Its figures.
    pub figures: TemplateFigures,
    /// A fit to the shape that stopped where the model would fold: its last sound iterate was
    /// kept (the figures say whether it meets the targets).
    pub fit_stopped_early: Option<String>,
    /// The sheet of each atom (`0 .. sheets`, as in the figures' lists), `None` on a seam.
    pub atom_sheet: Vec<Option<usize>>,
}

/// The figures of a template built from a shape.
#[derive(Clone, Debug, Serialize)]
pub struct TemplateFigures {
    /// Voxel of the grid the sheet was found on, mm.
    pub voxel_mm: f64,
    /// The voxel the thinnest wall asked for, mm, when the grid had to be coarser to stay within
    /// the voxel and memory limits (none: it is the voxel used).
    pub voxel_wanted_mm: Option<f64>,
    /// Dimensions of that grid.
    pub grid_dims: [usize; 3],
    /// Medial points found (ridge voxel pairs).
    pub medial_points: usize,
    /// The share of the shape (by the medial points' summed radii) in the largest piece of its
    /// medial points that does not reach the rest and was left out of the sheet
    /// ([`MedialAxis::left_out`]); above [`LEFT_OUT_LIMIT`] the template misses a wall.
    pub medial_left_out: f64,
    /// Per sheet, the chart it was sampled in: sphere (a bowl) or plane.
    pub chart: Vec<ChartKind>,
    /// Per sheet, the rows of its lattice hexagon either side of its middle row.
    pub rings: Vec<usize>,
    /// Per sheet, how many edges its hexagon is stretched by (0: regular, a round sheet).
    pub stretch: Vec<usize>,
    /// Sheets of the medial points (stitched along the seams).
    pub sheets: usize,
    /// Seams the sheets are stitched along (those of the medial points some sheet reaches).
    pub seams: usize,
    /// Voxel Dice of the template against the shape on the fine grid.
    pub dice: f64,
    /// Voxel Dice against the input segmentation on its own grid (segmentations only).
    pub dice_input_grid: Option<f64>,
    /// Whether the figures meet the targets: Dice ≥ [`TARGET_DICE`], at most
    /// [`LEFT_OUT_LIMIT`] of the shape left out, constraints ≤
    /// [`MAX_ANGLE_DEG`] and ≤ [`MAX_MISMATCH_PCT`], closed, manifold, outward, no
    /// self-intersection.
    pub meets_targets: bool,
    /// Largest spoke–normal angle, degrees.
    pub max_spoke_normal_deg: f64,
    /// Largest spoke mismatch, %.
    pub max_spoke_mismatch_pct: f64,
    /// Atoms.
    pub atoms: usize,
    /// Atoms with 1, 2 and 3 spokes (free edge, sheet, seam).
    pub atoms_by_spokes: [usize; MAX_SPOKES],
    /// Smallest and largest local thickness (2 × mean spoke), mm.
    pub thickness_mm: [f64; 2],
    /// The boundary is a closed oriented manifold.
    pub closed_manifold: bool,
    /// The boundary is oriented outward.
    pub outward: bool,
    /// The boundary does not intersect itself.
    pub self_intersection_free: bool,
    /// Dice of the projected inflation before the fit to the shape.
    pub dice_before_fit: f64,
    /// Largest landmark move of the final projection, mm.
    pub final_projection_move_mm: f64,
    /// Where the radius was lowered because the boundary intersected itself.
    pub radius_lowered: RadiusLowered,
    /// Where the spokes of the finished template were shortened in place because its boundary
    /// still crossed itself after the refits ([`SHORTENINGS`]).
    pub spokes_shortened: SpokesShortened,
    /// The atoms of a seam's band put back on the straight band the stitching made, because
    /// their places on the medial points made the boundary intersect itself (before any
    /// radius is lowered there).
    pub band_put_back: Vec<usize>,
    /// Why the template was built again from a sheet sampled twice as finely (the sampling
    /// asked for gave a template unsound or below [`TARGET_DICE`]), which sampling was kept,
    /// and why the others were not; `None` when it was not built again.
    pub sampled_again: Option<SampledAgain>,
    /// Why the template was built from the segmentation with its noise taken out
    /// ([`Shape::denoised`]): the build from it as given gave no sound template, for this
    /// reason; `None` when it was built from the shape as given.
    pub denoised: Option<String>,
    /// The template's summary.
    pub summary: TemplateSummary,
}

/// What is wrong with a built template.
#[derive(Clone, Debug, PartialEq)]
pub enum Verdict {
    /// Its boundary is not sound: what it is (not a closed oriented manifold, not outward,
    /// self-intersecting).
    Unsound(Vec<&'static str>),
    /// Its constraints are above the targets: the largest angle (°) and mismatch (%).
    ConstraintsNotMet(f64, f64),
    /// It leaves out a wall: the share of the shape in the largest piece of medial points left
    /// out of its sheet, above [`LEFT_OUT_LIMIT`].
    WallLeftOut(f64),
}

impl std::fmt::Display for Verdict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Unsound(causes) => write!(f, "{}", causes.join(", ")),
            Self::ConstraintsNotMet(angle, mismatch) => write!(
                f,
                "constraints at {angle:.2}° and {mismatch:.2} %, above {MAX_ANGLE_DEG}° and \
                 {MAX_MISMATCH_PCT} %"
            ),
            Self::WallLeftOut(share) => write!(
                f,
                "a wall of {:.0} % of the shape left out of its sheet",
                100.0 * share
            ),
        }
    }
}

impl TemplateFigures {
    /// `Ok` for a template that can be used: a sound boundary, constraints within
    /// [`MAX_ANGLE_DEG`] and [`MAX_MISMATCH_PCT`], and no wall of the shape left out (at most
    /// [`LEFT_OUT_LIMIT`]). A Dice below [`TARGET_DICE`] is not a verdict: the template is
    /// sound and whole, the figures say how well it matches.
    pub fn verdict(&self) -> std::result::Result<(), Verdict> {
        let defects = [
            (self.closed_manifold, "not a closed oriented manifold"),
            (self.outward, "not outward"),
            (self.self_intersection_free, "self-intersecting"),
        ];
        let causes: Vec<&'static str> = (defects.iter())
            .filter(|(holds, _)| !holds)
            .map(|&(_, what)| what)
            .collect();
        if !causes.is_empty() {
            return Err(Verdict::Unsound(causes));
        }
        let (angle, mismatch) = (self.max_spoke_normal_deg, self.max_spoke_mismatch_pct);
        if !(angle <= MAX_ANGLE_DEG && mismatch <= MAX_MISMATCH_PCT) {
            return Err(Verdict::ConstraintsNotMet(angle, mismatch));
        }
        if self.medial_left_out > LEFT_OUT_LIMIT || self.medial_left_out.is_nan() {
            return Err(Verdict::WallLeftOut(self.medial_left_out));
        }
        Ok(())
    }
}

/// Builds the template of `shape` (see the module doc) within `memory`.
///
/// Where the fitted template's boundary intersects itself (triangles that the flow carried
/// across each other in a narrow wedge between sheets at a seam), the sheet is mended at the
/// atoms of the triangles involved (a seam's band put back on its straight
/// place, else the radius lowered by [`SHRINK`]) and inflated and fitted again, up to
/// [`REFITS`] times: a start that can be made sound is not a failure. The figures say which
/// atoms were put back ([`TemplateFigures::band_put_back`]) and which lowered and by how much
/// ([`RadiusLowered`]). Where it still crosses itself after the last fit, which restores the
/// thickness a mending before it took away, the spokes there are shortened in place, up to
/// [`SHORTENINGS`] times while the crossings become fewer ([`SpokesShortened`]).
///
/// A template that is still unsound (its boundary crossing itself, or a sheet that cannot be
/// inflated), or sound but below [`TARGET_DICE`] against its shape, is built again from the
/// sheet sampled twice as finely ([`Sampling::finer`]), up to [`DOUBLINGS`] times until one is
/// sound: atoms far apart for the shape's walls and junctions are a fixable start, and a
/// lattice of whole rings can give a sheet fewer atoms than asked. The first sound finer
/// template is kept when the first was unsound or it matches the shape better, else the
/// first outcome is returned; the figures' [`TemplateFigures::sampled_again`] say why it was
/// built again, which was kept and why the others were not, and an error says which finer
/// samplings were tried.
pub fn template_of_shape(
    shape: &Shape,
    options: &TemplateOptions,
    memory: MemoryLimit,
) -> Result<BuiltTemplate> {
    template_of_shape_watched(shape, options, memory, &mut |_| {})
}

/// A step of [`template_of_shape`] a caller can look at as it is taken
/// ([`template_of_shape_watched`]), whether or not a template comes of it: what the medial
/// sheet was built from, to see in a viewer why a template folds or misses a wall.
#[derive(Clone, Copy, Debug)]
pub enum BuildStep<'a> {
    /// The shape on the grid its medial sheet is found on (step 1).
    Mask(&'a Volume),
    /// The shape's medial points, with the sheets and seams they form (step 2; found once,
    /// shared by every sampling).
    MedialAxis(&'a MedialAxis),
    /// The medial sheet at one sampling (each sheet's lattice, the seams, the stitched sheet),
    /// before it is subdivided and inflated: once per sampling tried.
    Sheet(Sampling, &'a ShapeSheet),
}

/// [`template_of_shape`], calling `watch` at each [`BuildStep`] as it is taken (before the
/// steps after it, which may fail): `medial template --work` writes them.
pub fn template_of_shape_watched(
    shape: &Shape,
    options: &TemplateOptions,
    memory: MemoryLimit,
    watch: &mut dyn FnMut(BuildStep<'_>),
) -> Result<BuiltTemplate> {
    let built = built_from(shape, options, memory, watch);
    // A segmentation whose sheet gives no sound template at any sampling is built again with
    // its noise taken out: flipped voxels fold a sheet that the shape itself does not.
    let why = match &built {
        Err(Error::InvalidTemplate(e)) => e.clone(),
        Ok(b) if unsound(b) => b
            .figures
            .verdict()
            .err()
            .map(|v| v.to_string())
            .unwrap_or_default(),
        _ => return built,
    };
    let Some(denoised) = shape.denoised()? else {
        return built;
    };
    match built_from(&denoised, options, memory, watch) {
        Ok(mut again) if !unsound(&again) => {
            again.figures.denoised = Some(why);
            Ok(again)
        }
        Ok(_) | Err(Error::InvalidTemplate(_)) => match built {
            Err(_) => Err(Error::InvalidTemplate(format!(
                "{why}; built again from the segmentation smoothed by {NOISE_SCALE} voxel (its \
                 noise taken out), none was sound either"
            ))),
            ok => ok,
        },
        Err(e) => Err(e),
    }
}

/// Whether `built` is unsound (its boundary not a closed outward manifold free of
/// self-intersection): a template the finer samplings and the denoised build are for.
fn unsound(built: &BuiltTemplate) -> bool {
    matches!(built.figures.verdict(), Err(Verdict::Unsound(_)))
}

/// [`template_of_shape_watched`] of the shape as it is.
fn built_from(
    shape: &Shape,
    options: &TemplateOptions,
    memory: MemoryLimit,
    watch: &mut dyn FnMut(BuildStep<'_>),
) -> Result<BuiltTemplate> {
    shape.bounds()?;
    let (mask, voxel, wanted) = fine_mask(shape, options.voxel, memory)?;
    watch(BuildStep::Mask(&mask));
    let axis = MedialAxis::of_mask(&mask)?;
    watch(BuildStep::MedialAxis(&axis));
    let mut build = |sampling: Sampling| {
        let found = axis.sheet(sampling)?;
        watch(BuildStep::Sheet(sampling, &found));
        let options = TemplateOptions {
            sampling,
            ..*options
        };
        built_at(
            shape,
            &mask,
            (&axis, found),
            (voxel, wanted),
            &options,
            memory,
        )
    };
    let first = build(options.sampling);
    // What twice the atoms may mend, and the Dice to beat where the first template is sound.
    let (why, to_beat) = match &first {
        Ok(built) => match built.figures.verdict() {
            Err(verdict @ Verdict::Unsound(_)) => (verdict.to_string(), None),
            Ok(()) if built.figures.dice < TARGET_DICE => (
                format!(
                    "voxel Dice {:.3} against the shape, below the target {TARGET_DICE}",
                    built.figures.dice
                ),
                Some(built.figures.dice),
            ),
            _ => return first,
        },
        Err(Error::InvalidTemplate(e)) => (e.clone(), None),
        Err(_) => return first,
    };
    // Finer until one is sound: kept if it betters a sound first.
    let again = |kept: Sampling, not_kept: Vec<NotKept>| SampledAgain {
        first: options.sampling.to_string(),
        kept: kept.to_string(),
        why: why.clone(),
        not_kept,
    };
    let mut sampling = options.sampling;
    let mut not_kept = Vec::new();
    for _ in 0..DOUBLINGS {
        sampling = sampling.finer();
        let mut refused = |why: String| {
            not_kept.push(NotKept {
                sampling: sampling.to_string(),
                why,
            })
        };
        let mut built = match build(sampling) {
            Ok(built) => built,
            Err(e) => {
                refused(e.to_string());
                continue;
            }
        };
        if let Err(verdict) = built.figures.verdict() {
            refused(verdict.to_string());
            continue;
        }
        if let Some(dice) = to_beat.filter(|&dice| built.figures.dice <= dice) {
            refused(format!(
                "voxel Dice {:.3}, not above the first's {dice:.3}",
                built.figures.dice
            ));
            break;
        }
        built.figures.sampled_again = Some(again(sampling, not_kept));
        return Ok(built);
    }
    match first {
        Ok(mut built) => {
            built.figures.sampled_again = Some(again(options.sampling, not_kept));
            Ok(built)
        }
        Err(Error::InvalidTemplate(e)) => {
            let tried: Vec<&str> = not_kept.iter().map(|n| &n.sampling[..]).collect();
            Err(Error::InvalidTemplate(format!(
                "{e}; built again from {}, none was sound",
                tried.join(" and ")
            )))
        }
        Err(e) => Err(e),
    }
}

/// How many times at most a template is built again, each time from twice the atoms of the
/// last ([`template_of_shape`]): up to 4× the atoms asked for, a lattice twice as fine.
pub const DOUBLINGS: usize = 2;

/// Why a template was built again from a finer sampling of its sheet
/// ([`template_of_shape`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SampledAgain {
    /// The sampling first asked for.
    pub first: String,
    /// The sampling of the template kept.
    pub kept: String,
    /// What was wrong with the template built from the first.
    pub why: String,
    /// The finer samplings tried and not kept, in order, each with why (the first is kept
    /// when none betters it).
    pub not_kept: Vec<NotKept>,
}

/// A finer sampling tried and not kept ([`SampledAgain`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct NotKept {
    /// The sampling.
    pub sampling: String,
    /// Why its template was not kept: the build's error, what was unsound, or a Dice not
    /// above the first's.
    pub why: String,
}

/// [`template_of_shape`] at one sampling: the sheet `found` of the medial axis `axis` of `mask`
/// (the shape on the grid of voxel `voxel`, mm; `wanted` the voxel the thinnest wall asked
/// for, where coarser) at
/// `options.sampling`, subdivided, inflated, fitted to the shape (`options.fit`), projected,
/// and mended where its boundary intersects itself.
fn built_at(
    shape: &Shape,
    mask: &Volume,
    (axis, found): (&MedialAxis, ShapeSheet),
    (voxel, wanted): (f64, Option<f64>),
    options: &TemplateOptions,
    memory: MemoryLimit,
) -> Result<BuiltTemplate> {
    let subdivided = found.subdivided()?;
    let mut fine = subdivided.sheet.clone();
    let mut put_back = BTreeSet::new();
    let mut refits = 0;
    loop {
        let (initial, inflated_sheet) =
            inflated(fine, &subdivided, &mut put_back).map_err(|e| {
                let Some(fold) = Fold::of(&found.sheet, &found.sheet_of_point) else {
                    return e;
                };
                let cause = match e {
                    Error::InvalidTemplate(cause) => cause,
                    e => e.to_string(),
                };
                let why = fold.place(&found.seams, &axis.points);
                Error::InvalidTemplate(format!(
                    "the medial sheet folds by up to {:.0}° between neighbouring triangles at \
                     {} edges, the sharpest near ({:.1}, {:.1}, {:.1}) mm, {why}; a folded \
                     sheet cannot be inflated: {cause}",
                    fold.max_deg, fold.edges, fold.at.x, fold.at.y, fold.at.z
                ))
            })?;
        let dice_before_fit = voxel_dice(&initial.boundary_mesh()?, mask)?;
        let (fitted, fit_stopped_early) = if options.fit {
            fit_to_shape(&initial, mask, memory)?
        } else {
            (initial, None)
        };
        let projection = project(&fitted, &ProjectOptions::default())?;
        let template = projection.template;
        let pairs = self_intersections(&template.boundary_mesh()?);
        if pairs.is_empty() || !options.fit || refits == REFITS {
            let (template, shortened, moved) = if options.fit {
                shortened_in_place(template, pairs)?
            } else {
                (template, SpokesShortened::default(), 0.0)
            };
            let figures = figures_of(
                &template,
                (axis, &found),
                shape,
                mask,
                [
                    voxel,
                    dice_before_fit,
                    projection.max_displacement.max(moved),
                ],
            )?;
            let (placed, _) =
                subdivided.band_put_back(&subdivided.sheet, put_back.iter().copied())?;
            let figures = TemplateFigures {
                voxel_wanted_mm: wanted,
                radius_lowered: RadiusLowered::between(&placed, &inflated_sheet, refits),
                spokes_shortened: shortened,
                band_put_back: put_back.into_iter().collect(),
                ..figures
            };
            return Ok(BuiltTemplate {
                atom_sheet: found.sheet.subdivided_labels(&found.sheet_of_point),
                template,
                found,
                figures,
                fit_stopped_early,
            });
        }
        fine = mended(
            &inflated_sheet,
            &template,
            &pairs,
            &subdivided,
            &mut put_back,
        )?;
        refits += 1;
    }
}

/// How many times at most the template is inflated and fitted again with the radius lowered
/// where its fitted boundary intersects itself ([`template_of_shape`]).
pub const REFITS: usize = 3;

/// The factor the radius at an atom of intersecting boundary triangles is lowered by, each
/// time: the inflation's own (`inflate::limit`), so that the lowering is as gradual as there.
pub const SHRINK: f64 = 0.8;

/// Where the radius of the sheet was lowered before the template was inflated from it.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct RadiusLowered {
    /// The atoms (vertices of the subdivided sheet) whose radius was lowered.
    pub atoms: Vec<usize>,
    /// The least ratio of a lowered radius to the sheet's own there.
    pub least_factor: f64,
    /// How many times the template was fitted again after lowering ([`REFITS`] at most).
    pub refits: usize,
}

impl RadiusLowered {
    /// The atoms where `lowered` has a smaller radius than `sheet` (the same sheet before
    /// lowering), after `refits` fits again.
    fn between(sheet: &MedialSheet, lowered: &MedialSheet, refits: usize) -> Self {
        let ratios: Vec<(usize, f64)> = (sheet.radius().iter().zip(lowered.radius()))
            .enumerate()
            .filter(|(_, (r, l))| l < r)
            .map(|(m, (r, l))| (m, l / r))
            .collect();
        Self {
            atoms: ratios.iter().map(|&(m, _)| m).collect(),
            least_factor: ratios.iter().map(|&(_, f)| f).fold(1.0, f64::min),
            refits,
        }
    }
}

/// How many times at most the spokes of a finished template are shortened in place where its
/// boundary still crosses itself after [`REFITS`] fits again ([`template_of_shape`]): to
/// `SHRINK⁵` ≈ 0.33 of their length at most.
pub const SHORTENINGS: usize = 5;

/// Where the spokes of the finished template were shortened in place because its boundary
/// still crossed itself after [`REFITS`] fits again ([`SHORTENINGS`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SpokesShortened {
    /// The atoms whose spokes were shortened.
    pub atoms: Vec<usize>,
    /// The least ratio of a shortened spoke to its length after the fit.
    pub least_factor: f64,
}

/// `template` (fitted and projected) with the spokes of the atoms of its boundary triangles in
/// the intersecting pairs `pairs` shortened by [`SHRINK`] about their medial points and the
/// template projected again, up to [`SHORTENINGS`] times while its boundary crosses itself
/// and each time at fewer pairs (a round that does not lower them, or turns a boundary–medial
/// prism inside out, is undone: triangles whose spokes point across each other cross at any
/// length); with where and by how much, and the largest landmark move of the projections
/// (mm). The
/// mendings of [`built_at`] act before a fit, which can carry the boundary back to where it
/// crossed (a wedge between sheets at a seam narrower than the shape's walls there); this one
/// acts after the last fit, so it holds, at the cost of thickness at those atoms only.
fn shortened_in_place(
    mut template: MedialTemplate,
    mut pairs: Vec<(usize, usize)>,
) -> Result<(MedialTemplate, SpokesShortened, f64)> {
    // The prisms' orientation after the fit: a round that turns one inside out is undone.
    let guard = Guard::of_template(&template);
    let mut factor = vec![1.0; template.medial_count()];
    let mut moved: f64 = 0.0;
    for _ in 0..SHORTENINGS {
        if pairs.is_empty() {
            break;
        }
        let involved = atoms_of(&template, &pairs);
        let q = spokes_scaled(&template, &involved, SHRINK);
        let projection = project(&template.with_landmarks(&q)?, &ProjectOptions::default())?;
        let crossing = self_intersections(&projection.template.boundary_mesh()?);
        // Fewer crossings, or not a crossing of spokes too long (triangles whose spokes point
        // across each other cross at any length): the round is not kept.
        if crossing.len() >= pairs.len()
            || guard.check_fold(projection.template.landmarks()).is_err()
        {
            break;
        }
        involved.iter().for_each(|&m| factor[m] *= SHRINK);
        moved = moved.max(projection.max_displacement);
        template = projection.template;
        pairs = crossing;
    }
    let atoms: Vec<usize> = (0..factor.len()).filter(|&m| factor[m] < 1.0).collect();
    let least_factor = factor.iter().copied().fold(1.0, f64::min);
    Ok((
        template,
        SpokesShortened {
            atoms,
            least_factor,
        },
        moved,
    ))
}

/// The atoms of the boundary triangles of `template` in the intersecting pairs `pairs`.
fn atoms_of(template: &MedialTemplate, pairs: &[(usize, usize)]) -> BTreeSet<usize> {
    let atoms = template.medial_index();
    (pairs.iter())
        .flat_map(|&(a, b)| [a, b])
        .flat_map(|t| template.boundary_triangles()[t].map(|v| atoms[v]))
        .collect()
}

/// The landmarks of `template` with the spokes of `atoms` scaled by `factor` about their
/// medial points.
fn spokes_scaled(template: &MedialTemplate, atoms: &BTreeSet<usize>, factor: f64) -> Vec<Vec3> {
    let mut q = template.landmarks().to_vec();
    for &m in atoms {
        let centre = q[template.atom_landmark(m)];
        for &b in template.spokes(m) {
            q[b] = centre + factor * (q[b] - centre);
        }
    }
    q
}

/// `sheet` (a subdivision of `subdivided` with its radii as lowered so far) mended at the
/// atoms of the boundary triangles of `template` (inflated from it) in the intersecting pairs
/// `pairs`: the atoms of a seam's band among them put back on the straight band the
/// stitching made (their subdivided places, which the band's width was chosen for), recorded
/// in `put_back`; where none is left to put back, the radius at those atoms lowered by
/// [`SHRINK`].
fn mended(
    sheet: &MedialSheet,
    template: &MedialTemplate,
    pairs: &[(usize, usize)],
    subdivided: &Subdivided,
    put_back: &mut BTreeSet<usize>,
) -> Result<MedialSheet> {
    let involved = atoms_of(template, pairs);
    let (moved_sheet, moved) = subdivided.band_put_back(sheet, involved.iter().copied())?;
    if !moved.is_empty() {
        put_back.extend(moved);
        return Ok(moved_sheet);
    }
    let mut radius = sheet.radius().to_vec();
    for m in involved {
        radius[m] *= SHRINK;
    }
    MedialSheet::new(sheet.points().to_vec(), sheet.triangles().to_vec(), radius)
}

/// The shape on its fine grid and that grid's voxel (mm): `voxel`, or a third of the
/// [`THIN_PERCENTILE`] of the half thicknesses found on a coarse grid, at most the coarse
/// voxel, and coarsened as little as needed to stay within [`MAX_VOXELS`] and `memory`
/// ([`voxel_within`]).
fn fine_mask(
    shape: &Shape,
    voxel: Option<f64>,
    memory: MemoryLimit,
) -> Result<(Volume, f64, Option<f64>)> {
    let (voxel, wanted) = match voxel {
        Some(h) if h.is_finite() && h > 0.0 => (h, None),
        Some(h) => {
            return Err(Error::InvalidParameter(format!(
                "the voxel must be a positive number of mm, got {h}"
            )))
        }
        None => {
            let h0 = shape.coarse_voxel()?;
            let coarse = shape.on_grid(h0, memory)?;
            let points = medial_points(&coarse, MIN_FEATURE_ANGLE_DEG)?;
            let mut radii: Vec<f64> = points.iter().map(|p| p.radius).collect();
            if radii.is_empty() {
                return Err(Error::InvalidParameter(
                    "the shape has no medial point on its coarse grid".into(),
                ));
            }
            radii.sort_by(f64::total_cmp);
            let thin = radii[(THIN_PERCENTILE * (radii.len() - 1) as f64) as usize];
            let wanted = (thin / VOXELS_PER_RADIUS).min(h0);
            let voxel = voxel_within(shape, wanted, memory)?;
            (voxel, (voxel > wanted).then_some(wanted))
        }
    };
    Ok((shape.on_grid(voxel, memory)?, voxel, wanted))
}

/// The finest voxel at least `h` (mm) whose grid around `shape` holds at most [`MAX_VOXELS`]
/// and fits `memory` ([`Estimate::grid`], with room for the sheet's distance transforms: a
/// tenth of the limit): the voxel grows by the cube root of the excess, a percent more, until
/// the grid fits. A clinical segmentation at its thinnest wall's resolution asks for more
/// voxels than a machine holds; a coarser grid loses the thinnest walls' detail, not the shape.
fn voxel_within(shape: &Shape, h: f64, memory: MemoryLimit) -> Result<f64> {
    let bytes_per_voxel = Estimate::grid([1, 1, 1]).total();
    let cap = (MAX_VOXELS as f64).min(0.1 * memory.get() / bytes_per_voxel);
    let bounds = shape.bounds()?;
    let mut h = h;
    for _ in 0..64 {
        let dims = (bounds.extent() / h).map(|e| e.ceil() + 2.0 * MARGIN_VOXELS + 1.0);
        let voxels = dims.x * dims.y * dims.z;
        if voxels <= cap {
            return Ok(h);
        }
        h *= 1.01 * (voxels / cap).cbrt();
    }
    Err(Error::InvalidParameter(format!(
        "no grid of the shape fits {cap:.0} voxels"
    )))
}

/// Neighbouring triangles of a lattice sheet whose normals are more than this apart, degrees,
/// make a fold the lattice cannot follow: the medial sheet of a smooth wall turns little over
/// one lattice spacing (a few of them span a ventricle), so such an edge is a crease where sheets
/// branch and no seam was found. None of the shapes that build (the cup, t001, the anterior
/// leaflet, the toy) has one; the biv-me heart, built as one sheet, has 37 (decision 0401).
pub const SHEET_FOLD_DEG: f64 = 60.0;

/// The folds of a sheet past [`SHEET_FOLD_DEG`]: how many interior edges (in exactly two
/// triangles; a seam's edges are in three), the largest angle, the middle of its edge and its
/// length, and whether that edge is in a seam's band (one of its triangles has a corner on a
/// seam).
struct Fold {
    edges: usize,
    max_deg: f64,
    at: Vec3,
    edge_mm: f64,
    in_band: bool,
}

impl Fold {
    /// The folds of `sheet`, none when no edge passes the bound. Triangles of one edge are
    /// compared as consistently oriented (the normal of one flipped when both run the edge the
    /// same way). `sheet_of_point` is `None` at the points on a seam.
    fn of(sheet: &MedialSheet, sheet_of_point: &[Option<usize>]) -> Option<Self> {
        let (p, tris) = (sheet.points(), sheet.triangles());
        let folds = sheet.folds(SHEET_FOLD_DEG);
        let &(max_deg, [a, b], [f, g]) =
            (folds.iter()).reduce(|w, e| if e.0 > w.0 { e } else { w })?;
        let on_seam = |t: &[usize; 3]| t.iter().any(|&v| sheet_of_point[v].is_none());
        Some(Self {
            edges: folds.len(),
            max_deg,
            at: (p[a] + p[b]) / 2.0,
            edge_mm: (p[a] - p[b]).norm(),
            in_band: on_seam(&tris[f]) || on_seam(&tris[g]),
        })
    }

    /// Where the sharpest fold lies and what made it, for its error: in a seam's band, or
    /// else (inside a sheet, at its distance from the nearest of `seams`) by the shape's
    /// `medial_points` within the fold's edge (the lattice's spacing there): where they branch,
    /// a seam that was not found; where they are one sheet, the sheet's lattice laid over
    /// itself; where too few lie, a lattice laid across a gap in them.
    fn place(&self, seams: &[Seam], medial_points: &[MedialPoint]) -> String {
        if self.in_band {
            return "in the band stitched between a sheet's cut and a seam".to_string();
        }
        let edge = self.edge_mm;
        let why = match flat_about(medial_points, self.at, edge) {
            Some(false) => {
                "where the medial points branch: sheets meeting at a seam that was not found"
                    .to_string()
            }
            Some(true) => format!(
                "where the medial points are one sheet: the sheet's lattice (edges of {edge:.1} \
                 mm there) laid over itself"
            ),
            None => format!(
                "where fewer than {MIN_BALL_POINTS} medial points lie within {edge:.1} mm: the \
                 lattice laid across a gap in them"
            ),
        };
        let nearest = (seams.iter())
            .flat_map(|seam| &seam.points)
            .map(|p| (p - self.at).norm())
            .fold(f64::INFINITY, f64::min);
        if nearest.is_finite() {
            format!(
                "inside a sheet, {nearest:.0} mm from the nearest seam ({} found), {why}",
                seams.len()
            )
        } else {
            why
        }
    }
}

/// The subdivided sheet `fine` inflated and projected onto its constraints, with the sheet
/// it was inflated from. The inflation's boundary is free of self-intersections, but the
/// projection moves spokes where sheets meet at a narrow angle at a seam (their spokes into
/// the wedge between them end close together): where the projected boundary intersects
/// itself, the sheet is mended there ([`mended`]) and inflated and projected
/// again, up to [`REFITS`] times (the fit to the shape restores the thickness; a boundary still
/// intersecting is reported by the verdict).
fn inflated(
    mut fine: MedialSheet,
    subdivided: &Subdivided,
    put_back: &mut BTreeSet<usize>,
) -> Result<(MedialTemplate, MedialSheet)> {
    for round in 0..=REFITS {
        let inflated = inflate(&fine)?;
        let template = MedialTemplate::new(
            inflated.boundary,
            inflated.medial_index,
            inflated.medial_points,
        )?;
        let projected = project(&template, &ProjectOptions::default())?.template;
        let pairs = self_intersections(&projected.boundary_mesh()?);
        if pairs.is_empty() || round == REFITS {
            return Ok((projected, fine));
        }
        fine = mended(&fine, &projected, &pairs, subdivided, put_back)?;
    }
    unreachable!("the last round returns")
}

/// First μ of the fit of a template to its own shape (relative constraint units), as the
/// automatic Dice fit's: small, so that the first AL iteration shapes the template freely.
pub const SELF_FIT_MU: f64 = 2.0;

/// L-BFGS iterations of the first AL iteration of the fit to the shape, at most: it goes on
/// while its last [`SELF_FIT_PROGRESS`] iterations lower the objective by 1 % (as the
/// automatic Dice fit's first AL iteration).
pub const SELF_FIT_FIRST_BUDGET: usize = 600;

/// The progress rule of the fit to the shape: a minimisation stops when its last 40 L-BFGS
/// iterations lowered the objective by less than 1 %.
pub const SELF_FIT_PROGRESS: ProgressRule = ProgressRule {
    window: 40,
    decrease: 0.01,
};

/// L-BFGS iterations of the second and last AL iteration of the fit to the shape (μ = 20, in
/// the plan's full time steps).
pub const SELF_FIT_LAST_ITERATIONS: usize = 60;

/// The μ schedule of the fit of a template to its own shape (`stage` is the automatic Dice
/// stage; its attachment, kernel and image smoothing stay the plan's): two AL iterations,
/// μ = [`SELF_FIT_MU`] then ten times that. The first, in [`COARSE_TIME_STEPS`] steps, runs
/// while it makes progress ([`SELF_FIT_FIRST_BUDGET`], [`SELF_FIT_PROGRESS`]): it is where the
/// Dice is won (on t001's, the caudate's and the leaflet's shapes the four later AL iterations
/// of the automatic schedule lowered the fit's Dice by 0.0006–0.003). The second
/// ([`SELF_FIT_LAST_ITERATIONS`], the plan's N) pulls the template back near its constraints,
/// max |C| about 10⁻², and makes the last iterate exact in time; no AL iterations are added
/// to tighten them further: the projection that follows the fit enforces them to 10⁻⁶°, moving
/// the landmarks by a fraction of a voxel (at most 0.09 mm, a quarter of a voxel, on the
/// shipped shapes), where a subject's fit has no projection after it and must end within its
/// tolerance by the penalty alone (decision 0501).
pub fn self_fit_schedule(stage: &mut StageSpec) {
    stage.schedule.mu = SELF_FIT_MU;
    stage.schedule.mu_factor = 10.0;
    stage.schedule.iterations = 2;
    stage.schedule.first_iterations = Some(SELF_FIT_FIRST_BUDGET);
    stage.schedule.coarse = Some(CoarseTime {
        time_steps: COARSE_TIME_STEPS,
        al_iterations: 1,
    });
    stage.schedule.extend = None;
    stage.lbfgs.max_iterations = SELF_FIT_LAST_ITERATIONS;
    stage.lbfgs.progress = Some(SELF_FIT_PROGRESS);
}

/// The fit of `template` to `mask` (as `medial fit --template --image` runs it, with the
/// schedule of [`self_fit_schedule`]); the fitted template, and why it stopped early when it
/// ended where the model would fold (its last sound iterate is kept). Constraints left above
/// their tolerance are enforced by the final projection.
fn fit_to_shape(
    template: &MedialTemplate,
    mask: &Volume,
    memory: MemoryLimit,
) -> Result<(MedialTemplate, Option<String>)> {
    let target = Target::Image {
        volume: mask.clone(),
        label: None,
    };
    let mut start = automatic(&Model::Medial(Box::new(template.clone())), &target, memory)?;
    for stage in &mut start.spec.stages {
        self_fit_schedule(stage);
    }
    let fit = start.fit(target, memory)?;
    let outcomes = fit.run(|_| {})?;
    let last = outcomes.last().expect("a fit has a stage");
    let trajectory = fit.flow().shoot(fit.model().landmarks(), &last.momenta)?;
    let started = fit.model().medial().expect("a medial template");
    let fitted = started.with_landmarks(trajectory.final_positions())?;
    let stopped = last.unsound.as_ref().map(|u| {
        format!(
            "AL iteration {}, iteration {}: {}",
            u.al_iteration + 1,
            u.iteration,
            u.cause
        )
    });
    Ok((fitted, stopped))
}

/// The figures of the final template (`[voxel of its grid, Dice before the fit, last
/// projection move]`).
fn figures_of(
    template: &MedialTemplate,
    (axis, found): (&MedialAxis, &ShapeSheet),
    shape: &Shape,
    mask: &Volume,
    [voxel, dice_before_fit, moved]: [f64; 3],
) -> Result<TemplateFigures> {
    let boundary = template.boundary_mesh()?;
    let dice = voxel_dice(&boundary, mask)?;
    let dice_input_grid = match shape {
        Shape::Mask(input, _) => Some(voxel_dice(&boundary, input)?),
        Shape::Mesh(_) => None,
    };
    let metrics = SpokeMetrics::compute(template, template.landmarks());
    let summary = TemplateSummary::of(template);
    let closed_manifold = check_closed_oriented_manifold(&boundary).is_ok();
    let outward = check_outward(&boundary).is_ok();
    let self_intersection_free = self_intersections(&boundary).is_empty();
    let fold = |f: fn(f64, f64) -> f64, init| metrics.thickness.iter().copied().fold(init, f);
    let meets_targets = dice >= TARGET_DICE
        && axis.left_out <= LEFT_OUT_LIMIT
        && summary.max_spoke_normal_deg <= MAX_ANGLE_DEG
        && summary.max_spoke_mismatch_pct <= MAX_MISMATCH_PCT
        && closed_manifold
        && outward
        && self_intersection_free;
    Ok(TemplateFigures {
        voxel_mm: voxel,
        voxel_wanted_mm: None,
        grid_dims: mask.dims(),
        medial_points: axis.points.len(),
        medial_left_out: axis.left_out,
        chart: found.lattices.iter().map(|l| l.chart.kind).collect(),
        rings: found.lattices.iter().map(|l| l.rings).collect(),
        stretch: found.lattices.iter().map(|l| l.stretch).collect(),
        sheets: axis.branches.counts.sheets,
        seams: found.seams.len(),
        dice,
        dice_input_grid,
        meets_targets,
        max_spoke_normal_deg: summary.max_spoke_normal_deg,
        max_spoke_mismatch_pct: summary.max_spoke_mismatch_pct,
        atoms: summary.atoms,
        atoms_by_spokes: summary.atoms_by_spokes,
        thickness_mm: [fold(f64::min, f64::INFINITY), fold(f64::max, 0.0)],
        closed_manifold,
        outward,
        self_intersection_free,
        dice_before_fit,
        final_projection_move_mm: moved,
        radius_lowered: RadiusLowered::default(),
        spokes_shortened: SpokesShortened::default(),
        band_put_back: Vec::new(),
        sampled_again: None,
        denoised: None,
        summary,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The automatic start of the fit to the shape chooses among candidates by a trial of the
    /// plan's first window ([`crate::fit::trial`]); the fit then runs [`self_fit_schedule`]. The
    /// two must agree on that window (μ, time steps, iterations), or the trial would judge a
    /// fit that is not run.
    #[test]
    fn the_trial_of_the_start_is_the_first_window_of_the_fit_to_the_shape() {
        use crate::fit::trial::trial_spec;
        let template = crate::testing::meshes::bipyramid(0.5);
        let boundary = template.boundary_mesh().unwrap();
        let (dims, grid) = grid_around(&boundary, 0.1, 0.4).unwrap();
        let target = Target::Image {
            volume: rasterize(&boundary, dims, grid).unwrap(),
            label: None,
        };
        let plan =
            crate::fit::plan::automatic(&Model::Medial(Box::new(template)), &target).unwrap();
        let mut adjusted = plan.clone();
        for stage in &mut adjusted.stages {
            self_fit_schedule(stage);
        }
        assert_ne!(adjusted, plan);
        assert_eq!(trial_spec(&adjusted).unwrap(), trial_spec(&plan).unwrap());
    }

    /// A strip of four triangles along x, its far half turned about the y axis by `turn`
    /// degrees (a crease along x = 1), with either orientation of one of its triangles.
    fn creased(turn: f64) -> MedialSheet {
        let (c, s) = (turn.to_radians().cos(), turn.to_radians().sin());
        let points = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(1.0 + c, 0.0, s),
            Vec3::new(1.0 + c, 1.0, s),
        ];
        let triangles = vec![[0, 2, 1], [1, 2, 3], [2, 4, 3], [3, 4, 5]];
        MedialSheet::new(points, triangles, vec![0.1; 6]).unwrap()
    }

    #[test]
    fn the_fit_to_the_own_shape_has_two_al_iterations_whatever_the_automatic_schedule() {
        use crate::fit::augmented_lagrangian::Extend;
        use crate::fit::spec::{AttachmentSpec, DiceSpec, FitSpec, FlowSettings};
        let mut stage = StageSpec::new("dice", AttachmentSpec::Dice(DiceSpec::default()));
        // An automatic schedule as long as a subject's may get: 5 AL iterations of 600, three
        // coarse, extended while on course to meet the tolerance.
        stage.schedule.iterations = 5;
        stage.schedule.coarse = Some(CoarseTime {
            time_steps: 5,
            al_iterations: 3,
        });
        stage.schedule.extend = Some(Extend {
            above: crate::fit::plan::EXTEND_ABOVE,
            at_most: crate::fit::plan::EXTEND_AT_MOST,
        });
        stage.lbfgs.max_iterations = 600;
        self_fit_schedule(&mut stage);
        let s = &stage.schedule;
        assert_eq!((s.mu, s.mu_factor, s.iterations), (2.0, 10.0, 2));
        assert_eq!(s.first_iterations, Some(SELF_FIT_FIRST_BUDGET));
        assert_eq!(s.coarse.map(|c| c.al_iterations), Some(1));
        assert!(
            s.extend.is_none(),
            "the projection, not more AL iterations, ends the fit"
        );
        assert_eq!(stage.lbfgs.max_iterations, SELF_FIT_LAST_ITERATIONS);
        assert_eq!(stage.lbfgs.progress, Some(SELF_FIT_PROGRESS));
        assert!(matches!(stage.attachment, AttachmentSpec::Dice(d) if d == DiceSpec::default()));
        let spec = FitSpec {
            flow: FlowSettings {
                sigma: 1.0,
                time_steps: 10,
                ..FlowSettings::default()
            },
            stages: vec![stage],
        };
        spec.check().unwrap();
    }

    /// A segmentation with its noise taken out ([`Shape::denoised`]) on the fine grid: a voxel
    /// alone beside the shape (there as given) is gone, a wall one voxel thick stays (thinner by
    /// under a fine voxel), and a flat boundary stays where it was.
    #[test]
    fn a_lone_voxel_is_gone_and_a_one_voxel_wall_and_a_flat_boundary_stay() {
        let dims = [24, 24, 24];
        let (wall, block) = (6, 14..20);
        let lone = [12, 12, 10];
        let data = (0..dims.iter().product::<usize>())
            .map(|n| {
                let (i, j, k) = (n % 24, (n / 24) % 24, n / 576);
                let inside = (i == wall && (4..20).contains(&j) && (4..20).contains(&k))
                    || (block.contains(&i) && (4..20).contains(&j) && (4..20).contains(&k))
                    || [i, j, k] == lone;
                f64::from(u8::from(inside))
            })
            .collect();
        let mask = Volume::new(dims, data, nalgebra::Matrix4::identity()).unwrap();
        let shape = Shape::of_segmentation(&mask, None);
        let plain = shape.on_grid(0.25, MemoryLimit::none()).unwrap();
        let fine = (shape.denoised().unwrap().unwrap())
            .on_grid(0.25, MemoryLimit::none())
            .unwrap();
        assert_eq!(plain.dims(), fine.dims(), "the same grid");
        let lone = plain
            .world_to_voxel()
            .transform_point(&nalgebra::Point3::new(12.0, 12.0, 10.0));
        let [i, j, k] = [lone.x, lone.y, lone.z].map(|c| c.round() as usize);
        assert_eq!(
            plain.data()[i + plain.dims()[0] * (j + plain.dims()[1] * k)],
            1.0
        );
        let inside = |x: f64, y: f64, z: f64| {
            let v = fine
                .world_to_voxel()
                .transform_point(&nalgebra::Point3::new(x, y, z));
            let [i, j, k] = [v.x, v.y, v.z].map(|c| c.round() as usize);
            fine.data()[i + fine.dims()[0] * (j + fine.dims()[1] * k)] > 0.5
        };
        assert!(!inside(12.0, 12.0, 10.0), "the lone voxel is gone");
        // The wall (voxel 6: 5.5 to 6.5 mm) is kept 0.84 mm wide about its middle.
        assert!([5.8, 6.0, 6.2].iter().all(|&x| inside(x, 12.0, 12.0)));
        assert!(!inside(5.2, 12.0, 12.0) && !inside(6.8, 12.0, 12.0));
        // The block's flat face (at 13.5 mm) stays within a fine voxel.
        assert!(inside(13.8, 12.0, 12.0) && !inside(13.2, 12.0, 12.0));
    }

    #[test]
    fn a_crease_past_the_fold_bound_is_found_and_a_gentle_bend_is_not() {
        let one_sheet = [Some(0); 6];
        assert!(Fold::of(&creased(0.0), &one_sheet).is_none());
        assert!(Fold::of(&creased(50.0), &one_sheet).is_none());
        let fold = Fold::of(&creased(120.0), &one_sheet).expect("a fold of 120°");
        assert_eq!(fold.edges, 1);
        assert!((fold.max_deg - 120.0).abs() < 1e-9, "{}", fold.max_deg);
        assert!((fold.at - Vec3::new(1.0, 0.5, 0.0)).norm() < 1e-12);
        assert!(!fold.in_band);
        // The same crease where a triangle at it has a corner on a seam: in the band; a seam
        // corner of a triangle away from it does not make it so.
        let mut seam_at_4 = one_sheet;
        seam_at_4[4] = None;
        assert!(Fold::of(&creased(120.0), &seam_at_4).unwrap().in_band);
        let mut seam_at_0 = one_sheet;
        seam_at_0[0] = None;
        assert!(!Fold::of(&creased(120.0), &seam_at_0).unwrap().in_band);
        // The error names the place and the cause, by the medial points within the fold's
        // edge (1 mm) of it: one flat sheet of them, a plane crossed by a V of two half-planes
        // (a seam not found), too few (a gap); inside a sheet 3 mm from a seam; in the band.
        let grid = |offset: fn(f64, f64) -> Vec3| -> Vec<MedialPoint> {
            (-8..=8)
                .flat_map(|i| (-8..=8).map(move |j| (0.1 * i as f64, 0.1 * j as f64)))
                .map(|(u, v)| MedialPoint {
                    position: Vec3::new(1.0, 0.5, 0.0) + offset(u, v),
                    radius: 0.1,
                })
                .collect()
        };
        let flat = grid(|u, v| Vec3::new(u, v, 0.0));
        let mut branching = grid(|u, v| Vec3::new(u, v, 0.0));
        branching.extend(grid(|u, v| Vec3::new(0.0, v, u.abs())));
        let few = &flat[..5];
        let lattice = fold.place(&[], &flat);
        assert!(
            lattice.starts_with("where the medial points are one sheet"),
            "{lattice}"
        );
        assert!(
            lattice.contains("edges of 1.0 mm there) laid over itself"),
            "{lattice}"
        );
        let missed = fold.place(&[], &branching);
        assert!(
            missed.contains("branch: sheets meeting at a seam that was not"),
            "{missed}"
        );
        assert!(fold.place(&[], few).contains("a gap in them"));
        let seam = Seam {
            points: vec![Vec3::new(1.0, 3.5, 0.0), Vec3::new(1.0, 9.0, 0.0)],
            radius: vec![0.1; 2],
        };
        let inside = fold.place(std::slice::from_ref(&seam), &flat);
        assert!(
            inside.starts_with("inside a sheet, 3 mm from the nearest seam (1 found), where"),
            "{inside}"
        );
        let band = Fold::of(&creased(120.0), &seam_at_4).unwrap();
        assert!(band.place(&[seam], &flat).contains("in the band"));
    }

    fn figures(sound: [bool; 3], angle: f64, mismatch: f64) -> TemplateFigures {
        TemplateFigures {
            voxel_mm: 1.0,
            voxel_wanted_mm: None,
            grid_dims: [1, 1, 1],
            medial_points: 0,
            medial_left_out: 0.0,
            chart: vec![],
            rings: vec![],
            stretch: vec![],
            sheets: 1,
            seams: 0,
            dice: 0.9,
            dice_input_grid: None,
            meets_targets: false,
            max_spoke_normal_deg: angle,
            max_spoke_mismatch_pct: mismatch,
            atoms: 0,
            atoms_by_spokes: [0; MAX_SPOKES],
            thickness_mm: [0.0, 0.0],
            closed_manifold: sound[0],
            outward: sound[1],
            self_intersection_free: sound[2],
            dice_before_fit: 0.0,
            final_projection_move_mm: 0.0,
            radius_lowered: RadiusLowered::default(),
            spokes_shortened: SpokesShortened::default(),
            band_put_back: Vec::new(),
            sampled_again: None,
            denoised: None,
            summary: TemplateSummary::default(),
        }
    }

    /// The synthetic two-ventricle shape (RV free wall 4 mm) as a segmentation of 1 mm voxels,
    /// the resolution real hearts come at, sampled two ways: with the voxel centres half a
    /// voxel over, the RV free wall's medial points stop 3.2 mm short of the junction and join
    /// the rest as a wall (before: 28 % of the shape left out); a quarter voxel over in x and
    /// y, the septum's cut, two lattice points between its seams, steps more than half a seam
    /// along it and was taken for a wrap (before: the sheet folded by 174°). Decision 0407.
    #[test]
    fn a_two_ventricle_segmentation_of_1_mm_voxels_builds_with_its_two_seams() {
        use crate::construction::skeleton::branching::tests::Ventricles;
        for phase in [Vec3::repeat(0.5), Vec3::new(0.25, 0.25, 0.5)] {
            let segmentation = Ventricles::mask_sampled(1.0, Ventricles::RV[0], phase);
            let shape = Shape::of_segmentation(&segmentation, None);
            let options = TemplateOptions::default();
            let built = template_of_shape(&shape, &options, MemoryLimit::none()).unwrap();
            let f = &built.figures;
            eprintln!(
                "phase {phase:?}: {} sheets, {} seams, {:?} atoms by spokes, voxel Dice {:.4} \
                 ({:?} on 1 mm), left out {:.4}, put back {:?}, lowered {:?}",
                f.sheets,
                f.seams,
                f.atoms_by_spokes,
                f.dice,
                f.dice_input_grid,
                f.medial_left_out,
                f.band_put_back,
                f.radius_lowered
            );
            assert_eq!((f.sheets, f.seams), (3, 2), "{phase:?}");
            assert!(f.atoms_by_spokes[2] >= 4, "{:?}", f.atoms_by_spokes);
            assert_eq!(f.verdict(), Ok(()), "{phase:?}");
            assert!(f.dice >= 0.9, "{phase:?}: {}", f.dice);
        }
    }

    #[test]
    fn the_lowered_radii_are_listed_with_their_least_factor() {
        let sheet = creased(30.0);
        let mut radius = sheet.radius().to_vec();
        radius[2] *= SHRINK;
        radius[4] *= SHRINK * SHRINK;
        let lowered =
            MedialSheet::new(sheet.points().to_vec(), sheet.triangles().to_vec(), radius).unwrap();
        let found = RadiusLowered::between(&sheet, &lowered, 2);
        assert_eq!(found.atoms, vec![2, 4]);
        assert!((found.least_factor - 0.64).abs() < 1e-12, "{found:?}");
        assert_eq!(found.refits, 2);
        assert_eq!(
            RadiusLowered::between(&sheet, &sheet, 0).atoms,
            Vec::<usize>::new()
        );
    }

    /// A half cylinder of radius 3 mm inflated at radius 0.8 mm, the spokes of its three middle
    /// columns then made 5 times as long: 4 mm, past the axis of the curve, so the concave
    /// side's boundary crosses itself. Shortening in place mends it at the atoms involved
    /// only, by at most `SHRINK^SHORTENINGS`.
    #[test]
    fn spokes_too_long_for_the_curve_are_shortened_where_the_boundary_crosses_itself() {
        let (columns, rows) = (9, 5);
        let points: Vec<Vec3> = (0..rows)
            .flat_map(|j| {
                (0..columns).map(move |i| {
                    let theta = std::f64::consts::PI * i as f64 / (columns - 1) as f64;
                    Vec3::new(3.0 * theta.cos(), 3.0 * theta.sin(), j as f64)
                })
            })
            .collect();
        let at = |i: usize, j: usize| j * columns + i;
        let triangles: Vec<[usize; 3]> = (0..rows - 1)
            .flat_map(|j| {
                // Diagonals alternate, so that no corner triangle has two free edges.
                (0..columns - 1).flat_map(move |i| {
                    let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                    if (i + j) % 2 == 0 {
                        [[a, b, c], [a, c, d]]
                    } else {
                        [[a, b, d], [b, c, d]]
                    }
                })
            })
            .collect();
        let sheet = MedialSheet::new(points, triangles, vec![0.8; columns * rows]).unwrap();
        let inflated = inflate(&sheet).unwrap();
        let template = MedialTemplate::new(
            inflated.boundary,
            inflated.medial_index,
            inflated.medial_points,
        )
        .unwrap();
        assert!(self_intersections(&template.boundary_mesh().unwrap()).is_empty());
        let middle = (0..template.medial_count())
            .filter(|m| (3..=5).contains(&(m % columns)))
            .collect();
        let long = (template.with_landmarks(&spokes_scaled(&template, &middle, 5.0))).unwrap();
        let pairs = self_intersections(&long.boundary_mesh().unwrap());
        assert!(!pairs.is_empty());
        let (mended, shortened, _) = shortened_in_place(long, pairs).unwrap();
        assert!(self_intersections(&mended.boundary_mesh().unwrap()).is_empty());
        assert!(
            shortened.atoms.iter().any(|m| m % columns == 4),
            "{shortened:?}"
        );
        assert!(
            (shortened.atoms.iter()).all(|m| (2..=6).contains(&(m % columns))),
            "{shortened:?}"
        );
        let least = SHRINK.powi(SHORTENINGS as i32);
        assert!(
            shortened.least_factor >= least - 1e-12 && shortened.least_factor <= SHRINK,
            "{shortened:?}"
        );
    }

    #[test]
    fn a_broken_or_unprojected_template_is_not_a_success() {
        assert!(
            figures([true; 3], 0.05, 0.05).verdict().is_ok(),
            "a low Dice is not a verdict"
        );
        assert_eq!(
            figures([true, false, false], 0.0, 0.0).verdict(),
            Err(Verdict::Unsound(vec!["not outward", "self-intersecting"]))
        );
        for (a, m) in [(0.2, 0.0), (0.0, 0.2), (f64::NAN, 0.0)] {
            assert!(matches!(
                figures([true; 3], a, m).verdict(),
                Err(Verdict::ConstraintsNotMet(..))
            ));
        }
        let mut missing_a_wall = figures([true; 3], 0.0, 0.0);
        missing_a_wall.medial_left_out = 0.16;
        assert_eq!(missing_a_wall.verdict(), Err(Verdict::WallLeftOut(0.16)));
    }
}
