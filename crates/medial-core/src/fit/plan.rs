//! Fit plans: the settings of a fit chosen from the data (docs/method.md §8). Each rule is
//! stated where it is made, as a principle with its reason; the measurements behind the
//! constants are in the decision records under `docs/decisions/` (named at each rule).
//!
//! - the kernel width from the template's geometry ([`Geometry::sigma`]);
//! - the schedules of synthetic cases' configs ([`FitPlan::paper_schedule`],
//!   [`FitPlan::boundary_ssd`]);
//! - the automatic fit of a template to one target ([`automatic`]): the μ schedules, the time
//!   steps, the image smoothing, the varifold widths and the kernel truncation;
//! - the safer settings an automatic fit that ended unsound runs again with ([`safer`]).
//!
//! ```
//! use medial_core::fit::{plan, Target, AttachmentSpec};
//! use medial_core::model::Model;
//! use medial_core::synth::{Shape, SyntheticCase};
//! let case = SyntheticCase::build(Shape::Toy).unwrap();
//! let model = Model::Medial(Box::new(case.template().clone()));
//! let target = Target::Points(case.target_boundary().unwrap().points().to_vec());
//! let spec = plan::automatic(&model, &target).unwrap();
//! assert!(matches!(spec.stages[0].attachment, AttachmentSpec::Ssd));
//! assert_eq!(spec.flow.time_steps, 10);
//! ```

use crate::attachment::varifold::default_width;
use crate::fit::augmented_lagrangian::CoarseTime;
use crate::fit::augmented_lagrangian::{Extend, Settle};
use crate::fit::optimize::ProgressRule;
use crate::fit::prepare::Target;
use crate::fit::spec::{AttachmentSpec, DiceSpec, FitSpec, FlowSettings, StageSpec, VarifoldSpec};
use crate::flow::kernel::GaussianKernel;
use crate::mesh::PrincipalAxes;
use crate::model::template::MedialTemplate;
use crate::model::Model;
use crate::{Error, Result, TriMesh, Vec3};
use serde::Serialize;

/// The image smoothing of an automatic Dice stage, per mm of the smallest voxel size: enough
/// to give the Dice term a gradient across a voxel, small against a wall a few voxels thick.
pub const IMAGE_SIGMA_PER_VOXEL: f64 = 0.4;

/// The refinement of a graded signed image in an automatic Dice stage (`image_refine`): the
/// boundary follows the zero crossing to a third of a voxel instead of a whole one (decision
/// record: the anterior mitral leaflet, a level set one to three voxels thick).
pub const GRADED_IMAGE_REFINE: usize = 3;

/// The fit settings of a synthetic case's configs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitPlan {
    /// Kernel width σ, mm.
    pub sigma: f64,
    /// Time steps N.
    pub time_steps: usize,
    /// Weight of the kinetic energy.
    pub kinetic_weight: f64,
    /// L-BFGS iterations of the SSD stage towards the affine part.
    pub affine_iterations: usize,
    /// L-BFGS iterations per AL iteration of the constrained SSD fit to the warped boundary.
    pub boundary_iterations: usize,
    /// L-BFGS iterations per AL iteration of the Dice stage.
    pub dice_iterations: usize,
}

/// AL iterations of the constrained SSD fit to the warped boundary (μ = 20 … 20000 in relative
/// constraint units: on cmrep's t001 about the weight of μ = 1 … 1000 in mm²).
pub const BOUNDARY_AL_ITERATIONS: usize = 4;

/// AL iterations of the paper's Dice stage: μ = 0.02 … 2000 in relative units, about the
/// paper's 0.001 … 100 in mm² on cmrep's t001 and one step further, so that the constraints end
/// well inside their tolerance.
pub const DICE_AL_ITERATIONS: usize = 6;

impl FitPlan {
    /// The paper's schedule: SSD towards the affine part (μ = 20, one AL iteration; the
    /// targets are the template's boundary moved by the affine map), then Dice with the
    /// constraints in relative units and μ = 0.02, 0.2, …, 2000 ([`DICE_AL_ITERATIONS`]).
    pub fn paper_schedule(&self) -> FitSpec {
        let mut affine = StageSpec::new("affine", AttachmentSpec::Ssd);
        affine.schedule.mu = 20.0;
        affine.schedule.iterations = 1;
        affine.lbfgs.max_iterations = self.affine_iterations;
        let dice = constrained(
            "dice",
            AttachmentSpec::Dice(DiceSpec::default()),
            Schedule {
                mu: 0.02,
                al_iterations: DICE_AL_ITERATIONS,
                max_iterations: self.dice_iterations,
                first: None,
                coarse: 0,
            },
        );
        self.spec(vec![affine, dice])
    }

    /// SSD to the warped boundary points (known correspondence), the constraints on in
    /// relative units, μ = 20, 200, 2000, 20000.
    pub fn boundary_ssd(&self) -> FitSpec {
        let mut boundary = constrained(
            "boundary",
            AttachmentSpec::Ssd,
            Schedule {
                mu: 20.0,
                al_iterations: BOUNDARY_AL_ITERATIONS,
                max_iterations: self.boundary_iterations,
                first: None,
                coarse: 0,
            },
        );
        boundary.constraints = Some(true);
        self.spec(vec![boundary])
    }

    fn spec(&self, stages: Vec<StageSpec>) -> FitSpec {
        FitSpec {
            flow: FlowSettings {
                sigma: round_to_hundredths(self.sigma),
                time_steps: self.time_steps,
                kinetic_weight: self.kinetic_weight,
                ..FlowSettings::default()
            },
            stages,
        }
    }
}

/// σ as configs write it: to 0.01 mm.
fn round_to_hundredths(sigma: f64) -> f64 {
    (sigma * 100.0).round() / 100.0
}

/// A μ schedule rising tenfold per AL iteration, and its L-BFGS budget.
#[derive(Clone, Copy)]
struct Schedule {
    /// First μ (relative constraint units).
    mu: f64,
    /// AL iterations.
    al_iterations: usize,
    /// L-BFGS iterations per AL iteration.
    max_iterations: usize,
    /// A longer first AL iteration that goes on while it makes progress (none:
    /// `max_iterations`, no progress rule).
    first: Option<FirstIteration>,
    /// The first AL iterations in [`COARSE_TIME_STEPS`] steps (0: none).
    coarse: usize,
}

/// The budget of the first AL iteration and the progress rule of a stage: an AL iteration
/// stops when its last `window` L-BFGS iterations lowered the objective by less than
/// `decrease` of it.
#[derive(Clone, Copy)]
struct FirstIteration {
    budget: usize,
    window: usize,
    decrease: f64,
}

/// Time steps of an automatic fit: the flow's strain per step stays below the guard's limit on
/// every measured case at 10, and each halving of N halves the cost of an evaluation.
pub const TIME_STEPS: usize = 10;

/// Coarse to fine in time: the first AL iterations of image and point fits run in 5 steps while
/// the flow strains space by at most 0.5 per step ([`CoarseTime`]); they shape the fit at half
/// the cost, the last AL iterations in [`TIME_STEPS`] make it exact. Not for surfaces (their
/// later stages are on their budgets already).
pub const COARSE_TIME_STEPS: usize = 5;

/// Against an image (Dice): μ = 2 … 20000 over 5 AL iterations, each up to 600 L-BFGS
/// iterations while it makes 1 % progress per 40; three of them coarse. A small first μ lets
/// the first AL iteration wander far from the constraints and later ones pull it back; a
/// template projected onto them can start higher. Every AL iteration runs until the progress
/// rule ends it: the multiplier update `λ ← λ − μ C` is sound only at an approximate minimiser
/// of its penalty, and a fixed budget that cuts the minimisation short (120 before, decision
/// 0034) leaves the constraints where the cut found them, whatever μ.
const DICE: Schedule = Schedule {
    mu: 2.0,
    al_iterations: 5,
    max_iterations: 600,
    first: Some(FirstIteration {
        budget: 600,
        window: 40,
        decrease: 0.01,
    }),
    coarse: 3,
};

/// Against corresponding points (SSD): μ = 200 … 20000, the first AL iteration as long as it
/// makes progress ([`FIRST_PROGRESS`]), then 2 × 200; the first coarse.
const POINTS: Schedule = Schedule {
    mu: 200.0,
    al_iterations: 3,
    max_iterations: 200,
    first: Some(FIRST_PROGRESS),
    coarse: 1,
};

/// Against a surface (varifold), three stages at narrowing kernel widths, each one AL iteration
/// as long as it makes progress: the wide kernel carries the shape (μ = 200), the narrower ones
/// tighten the constraints and the details (μ = 2000, 20000).
const SURFACE: Schedule = Schedule {
    mu: 200.0,
    al_iterations: 1,
    max_iterations: 400,
    first: Some(FIRST_PROGRESS),
    coarse: 0,
};

/// The second varifold stage, at [`FINE_WIDTH_FRACTION`] of the first's width.
const SURFACE_FINE: Schedule = Schedule {
    mu: 2000.0,
    al_iterations: 1,
    max_iterations: 300,
    first: Some(FirstIteration {
        budget: 300,
        ..FIRST_PROGRESS
    }),
    coarse: 0,
};

/// The third varifold stage, at about the flow's σ ([`finest_width`]); its progress rule asks
/// 0.1 % per 40 iterations, not 0.3 %: at a narrow width the data term carries a large constant
/// part, so its relative decrease looks small.
const SURFACE_FINEST: Schedule = Schedule {
    mu: 20000.0,
    al_iterations: 1,
    max_iterations: 200,
    first: Some(FirstIteration {
        budget: 200,
        window: 40,
        decrease: 0.001,
    }),
    coarse: 0,
};

/// The first AL iteration against points or a surface: up to 400 iterations while the last 40
/// lower the objective by at least 0.3 %.
const FIRST_PROGRESS: FirstIteration = FirstIteration {
    budget: 400,
    window: 40,
    decrease: 0.003,
};

/// The kernel width of an automatic fit against [`Geometry::sigma`] (the mean spoke length, at
/// least half the mean boundary edge): a kernel narrower than the wall lets medial and boundary
/// points move apart as the constraints need.
pub const SIGMA_FACTOR: f64 = 0.55;

/// The kernel tolerance ε of an automatic fit that truncates its kernel: the sums then err by
/// at most 1e-10 of the sums of absolute terms (docs/method.md §2.3), far below what a fit can
/// tell.
pub const KERNEL_TOLERANCE: f64 = 1e-10;

/// An automatic fit truncates its kernel when at most this fraction of the template's landmark
/// pairs lie within the cutoff radius `r = σ √(2 ln(1/ε))`: the truncated sweep's sort, cell
/// grid and chunk masks cost more than they skip when most pairs are near. Its fits break even
/// with the exact sweep at 40–50 % of the pairs near (decision 0014's addendum); the rule stays
/// below that, where truncation is never the slower.
pub const TRUNCATE_AT_MOST: f64 = 0.4;

/// `kernel_tolerance` of an automatic fit with kernel width `sigma` (mm) of a template with
/// landmarks `landmarks`: [`KERNEL_TOLERANCE`] when at most [`TRUNCATE_AT_MOST`] of their pairs
/// are near, else 0 (exact).
pub fn kernel_tolerance(sigma: f64, landmarks: &[Vec3]) -> f64 {
    let near = GaussianKernel::new(sigma)
        .and_then(|k| k.truncated(KERNEL_TOLERANCE))
        .map_or(1.0, |k| k.near_pair_fraction(landmarks));
    if near <= TRUNCATE_AT_MOST {
        KERNEL_TOLERANCE
    } else {
        0.0
    }
}

/// The second varifold stage's kernel width, as a fraction of the first's.
pub const FINE_WIDTH_FRACTION: f64 = 0.25;

/// The varifold kernel widths (mm) of an automatic fit to the surface `target`: first
/// [`default_width`] (a tenth of its bounding-box diagonal, at least two mean edges), then
/// [`FINE_WIDTH_FRACTION`] of it, at least half the longer of the mean edges of the target and
/// of the template's boundary `boundary` (a kernel much narrower than the triangles sees their
/// sampling, not the shape).
pub fn varifold_widths(boundary: &TriMesh, target: &TriMesh) -> Result<(f64, f64)> {
    let width = default_width(target)?;
    let edge = mean_edge(target).max(mean_edge(boundary));
    Ok((width, (FINE_WIDTH_FRACTION * width).max(0.5 * edge)))
}

/// The third varifold stage's kernel width (mm) after a second at `fine` in a flow of kernel
/// width `sigma`: σ, at least half the second's and at most the second's. The flow cannot
/// follow a varifold much narrower than its own kernel without pulling its boundary points
/// apart.
pub fn finest_width(fine: f64, sigma: f64) -> f64 {
    sigma.max(0.5 * fine).min(fine)
}

/// The largest `|C|` (relative units: about 0.06° and 0.1 % at the template's scale; where a
/// fit shortens spokes and tangents it reads the angle that many times too small, decision
/// 0035) at which an automatic stage's AL iterations end early once the attachment changes by
/// less than 0.1 % over one: the constraints are then well inside their tolerance and
/// tightening them no longer moves the fit.
pub const SETTLE_CONSTRAINT: f64 = 1e-3;

/// A constrained automatic stage that ends its schedule with its largest angle or mismatch
/// above this fraction of the tolerance (0.5°, 0.5 % of 1°, 1 %, as a fit reports them) goes on
/// for up to [`EXTEND_AT_MOST`] more AL iterations while it is on course to meet the tolerance
/// ([`Extend::on_course`]): the budget is there to finish the job, not to end it; a schedule
/// that stalls, or converges too slowly to finish in the AL iterations left, ends.
pub const EXTEND_ABOVE: f64 = 0.5;

/// Most AL iterations an automatic stage adds ([`EXTEND_ABOVE`]).
pub const EXTEND_AT_MOST: usize = 4;

/// The attachment's relative change over an AL iteration at most which it has settled.
pub const SETTLE_DATA_CHANGE: f64 = 1e-3;

/// A stage with the medial constraints in relative units, μ rising tenfold over the AL
/// iterations of `schedule`, ending early once they settle ([`SETTLE_CONSTRAINT`]) and going on
/// while they are on course to meet their tolerance ([`EXTEND_ABOVE`]).
fn constrained(name: &str, attachment: AttachmentSpec, schedule: Schedule) -> StageSpec {
    let mut stage = StageSpec::new(name, attachment);
    stage.schedule.settle = Some(Settle {
        max_abs_constraint: SETTLE_CONSTRAINT,
        data_change: SETTLE_DATA_CHANGE,
    });
    stage.schedule.extend = Some(Extend {
        above: EXTEND_ABOVE,
        at_most: EXTEND_AT_MOST,
    });
    stage.schedule.mu = schedule.mu;
    stage.schedule.mu_factor = 10.0;
    stage.schedule.iterations = schedule.al_iterations;
    stage.lbfgs.max_iterations = schedule.max_iterations;
    if schedule.coarse > 0 {
        stage.schedule.coarse = Some(CoarseTime {
            time_steps: COARSE_TIME_STEPS,
            al_iterations: schedule.coarse,
        });
    }
    if let Some(first) = schedule.first {
        stage.schedule.first_iterations = Some(first.budget);
        stage.lbfgs.progress = Some(ProgressRule {
            window: first.window,
            decrease: first.decrease,
        });
    }
    stage
}

/// Geometry of a medial template that sets a fit's kernel width.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Geometry {
    /// Mean spoke length `|q_b − q_M[b]|` over the boundary points (half thickness), mm.
    pub mean_spoke_mm: f64,
    /// Mean length of the boundary mesh's edges, mm.
    pub mean_edge_mm: f64,
    /// Extent along the long principal axis, mm.
    pub long_extent_mm: f64,
    /// The configs' kernel width, mm: see [`Geometry::sigma`].
    pub sigma_mm: f64,
}

impl Geometry {
    /// The geometry of `template`, whose boundary is `boundary` with principal axes `axes`.
    pub fn of(template: &MedialTemplate, boundary: &TriMesh, axes: &PrincipalAxes) -> Self {
        let q = template.landmarks();
        let atoms = template.medial_index();
        let mean_spoke_mm = mean(
            (0..template.boundary_count())
                .map(|b| (q[b] - q[template.atom_landmark(atoms[b])]).norm()),
        );
        let mut g = Self {
            mean_spoke_mm,
            mean_edge_mm: mean_edge(boundary),
            long_extent_mm: axes.extent.z,
            sigma_mm: 0.0,
        };
        g.sigma_mm = g.sigma();
        g
    }

    /// `σ` = the mean spoke length (about the half thickness: small against the wall, so that
    /// the flow can move medial and boundary points apart as the constraints need), at least
    /// half the mean edge length (neighbouring landmarks move together), at most an eighth of
    /// the long extent (the upper bound wins), mm.
    pub fn sigma(&self) -> f64 {
        self.mean_spoke_mm
            .max(self.mean_edge_mm / 2.0)
            .min(self.long_extent_mm / 8.0)
    }

    /// Voxels for rasterizing a surface to align to: half the mean spoke, so that the wall is a
    /// few voxels thick, and at most 256 along the long extent, mm.
    pub fn alignment_spacing(&self) -> f64 {
        (self.mean_spoke_mm / 2.0).max(self.long_extent_mm / 256.0)
    }

    /// The synthetic cases' fit settings: `σ` from the geometry, 20 time steps, kinetic weight
    /// 0.005; L-BFGS iterations: 500 towards the affine part, 1000 per AL iteration of the
    /// boundary fit, 300 per AL iteration of the Dice stage.
    pub fn plan(&self) -> FitPlan {
        FitPlan {
            sigma: self.sigma_mm,
            time_steps: 20,
            kinetic_weight: 0.005,
            affine_iterations: 500,
            boundary_iterations: 1000,
            dice_iterations: 300,
        }
    }
}

/// Mean length of the edges of `mesh`'s triangles (each counted once per triangle), mm.
pub fn mean_edge(mesh: &TriMesh) -> f64 {
    let p = mesh.points();
    mean(
        mesh.triangles()
            .iter()
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .map(|(a, b)| (p[a] - p[b]).norm()),
    )
}

/// The kernel width of a plain mesh (no spokes to set it): an eighth of its long principal
/// extent (the bound of [`Geometry::sigma`]), at least half its mean edge, mm.
pub fn plain_sigma(mesh: &TriMesh, axes: &PrincipalAxes) -> f64 {
    (axes.extent.z / 8.0).max(mean_edge(mesh) / 2.0)
}

/// The kinetic weight of a plain mesh's automatic fit: with no constraints to hold the wall,
/// the kinetic energy is what keeps the flow smooth (at the medial templates' 0.005 a varifold
/// fit of the reduced KeOps hippocampus folds a triangle).
pub const PLAIN_KINETIC_WEIGHT: f64 = 0.05;

/// L-BFGS iterations of the one unconstrained stage of an automatic fit of a plain mesh.
pub const PLAIN_ITERATIONS: usize = 300;

/// The automatic fit of `model` (before its initial alignment) to `target`:
///
/// - a medial template: the kernel width a [`SIGMA_FACTOR`] of [`Geometry::sigma`], N =
///   [`TIME_STEPS`], constrained stages: one Dice stage against an image (smoothed by
///   [`IMAGE_SIGMA_PER_VOXEL`] of its smallest voxel, a graded signed image refined by
///   [`GRADED_IMAGE_REFINE`]), one SSD stage against points, three varifold stages against a
///   surface ([`varifold_widths`], [`finest_width`]);
/// - a plain mesh: one unconstrained stage of [`PLAIN_ITERATIONS`] against points or a surface
///   at kernel width [`plain_sigma`]; an image is refused (the Dice term samples a medial
///   template's interior).
///
/// The kernel is truncated when few landmark pairs of the model as given are near
/// ([`kernel_tolerance`]); [`crate::fit::run::automatic`] decides again at the start it takes.
pub fn automatic(model: &Model, target: &Target) -> Result<FitSpec> {
    match model {
        Model::Medial(template) => automatic_medial(template, target),
        Model::Plain(mesh) => automatic_plain(mesh, target),
    }
}

fn automatic_medial(template: &MedialTemplate, target: &Target) -> Result<FitSpec> {
    let boundary = template.boundary_mesh()?;
    let axes = PrincipalAxes::of(boundary.points())?;
    let plan = Geometry::of(template, &boundary, &axes).plan();
    let sigma = round_to_hundredths(SIGMA_FACTOR * plan.sigma);
    let stages = match target {
        Target::Image { volume, label } => {
            let mut dice = DiceSpec::default();
            if volume.is_graded_signed() && label.is_none() {
                dice.image_refine = GRADED_IMAGE_REFINE;
            }
            let voxel_mm = volume.spacing().min();
            dice.image_sigma = IMAGE_SIGMA_PER_VOXEL * voxel_mm / dice.image_refine as f64;
            vec![constrained("dice", AttachmentSpec::Dice(dice), DICE)]
        }
        Target::Points(_) => {
            let mut points = constrained("boundary", AttachmentSpec::Ssd, POINTS);
            points.constraints = Some(true);
            vec![points]
        }
        Target::Surface(mesh) => {
            let (width, fine_width) = varifold_widths(&boundary, mesh)?;
            let varifold = |name, schedule, width| {
                let spec = VarifoldSpec {
                    width: Some(width),
                    ..VarifoldSpec::default()
                };
                let mut surface = constrained(name, AttachmentSpec::Varifold(spec), schedule);
                surface.constraints = Some(true);
                surface
            };
            vec![
                varifold("surface", SURFACE, width),
                varifold("surface-fine", SURFACE_FINE, fine_width),
                varifold(
                    "surface-finest",
                    SURFACE_FINEST,
                    finest_width(fine_width, sigma),
                ),
            ]
        }
    };
    let mut spec = plan.spec(stages);
    spec.flow.time_steps = TIME_STEPS;
    spec.flow.sigma = sigma;
    spec.flow.kernel_tolerance = kernel_tolerance(sigma, template.landmarks());
    Ok(spec)
}

fn automatic_plain(mesh: &TriMesh, target: &Target) -> Result<FitSpec> {
    let axes = PrincipalAxes::of(mesh.points())?;
    let sigma = plain_sigma(mesh, &axes);
    let mut stage = match target {
        Target::Image { .. } => return Err(Error::NeedsMedial("a Dice fit")),
        Target::Points(_) => StageSpec::new("boundary", AttachmentSpec::Ssd),
        Target::Surface(_) => {
            StageSpec::new("surface", AttachmentSpec::Varifold(VarifoldSpec::default()))
        }
    };
    stage.constraints = Some(false);
    stage.lbfgs.max_iterations = PLAIN_ITERATIONS;
    Ok(FitSpec {
        flow: FlowSettings {
            sigma: round_to_hundredths(sigma),
            time_steps: TIME_STEPS,
            kinetic_weight: PLAIN_KINETIC_WEIGHT,
            kernel_tolerance: kernel_tolerance(sigma, mesh.points()),
        },
        stages: vec![stage],
    })
}

fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    sum / n.max(1) as f64
}

/// How many times an automatic fit that ended unsound is run again, from its start, with
/// [`safer`] settings before it is reported unsound.
pub const RETRIES: usize = 2;

/// The kernel width of the second retry against the plan's.
pub const RETRY_SIGMA_FACTOR: f64 = 1.5;

/// Settings to run an automatic fit again with after it ended unsound ([`safer`]), and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Safer {
    /// The fit to run instead.
    pub spec: FitSpec,
    /// What changed and why, one line.
    pub why: String,
}

/// The `retry`-th (from 1, at most [`RETRIES`]) safer version of the automatic fit `spec` of a
/// model with landmarks `landmarks`, after it ended unsound:
///
/// 1. twice the time steps, and no coarse steps: a fold early in a fit is most often one step
///    of the flow moving points too far for its time discretisation (`dt·|∇v|` large), which
///    halving `dt` undoes;
/// 2. then also the kernel [`RETRY_SIGMA_FACTOR`] times wider (its truncation chosen again): a
///    smoother flow cannot fold a prism much smaller than its kernel.
///
/// `None` past the last retry. Each retry costs a fit; the first that ends sound is the result.
pub fn safer(spec: &FitSpec, landmarks: &[Vec3], retry: usize) -> Option<Safer> {
    let mut safer = spec.clone();
    let steps = |safer: &mut FitSpec| {
        safer.flow.time_steps *= 2;
        for stage in &mut safer.stages {
            stage.schedule.coarse = None;
        }
    };
    let why = match retry {
        1 => {
            steps(&mut safer);
            format!(
                "again with {} time steps throughout (was {}): a fold early in a fit is most \
                 often a step too bold for the time discretisation",
                safer.flow.time_steps, spec.flow.time_steps
            )
        }
        2 => {
            steps(&mut safer);
            safer.flow.sigma = round_to_hundredths(RETRY_SIGMA_FACTOR * spec.flow.sigma);
            safer.flow.kernel_tolerance = kernel_tolerance(safer.flow.sigma, landmarks);
            format!(
                "again with {} time steps and σ = {} mm (was {} mm): a smoother flow cannot fold \
                 a prism much smaller than its kernel",
                safer.flow.time_steps, safer.flow.sigma, spec.flow.sigma
            )
        }
        _ => return None,
    };
    Some(Safer { spec: safer, why })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_retry_doubles_the_steps_then_widens_the_kernel_then_gives_up() {
        let mut spec = FitSpec {
            flow: FlowSettings {
                sigma: 1.0,
                time_steps: 10,
                ..FlowSettings::default()
            },
            stages: Vec::new(),
        };
        let mut stage = StageSpec::new("dice", AttachmentSpec::Ssd);
        stage.schedule.coarse = Some(CoarseTime {
            time_steps: 5,
            al_iterations: 3,
        });
        spec.stages.push(stage);
        let landmarks = line(100);
        let first = safer(&spec, &landmarks, 1).unwrap().spec;
        assert_eq!((first.flow.time_steps, first.flow.sigma), (20, 1.0));
        assert!(first.stages[0].schedule.coarse.is_none());
        let second = safer(&spec, &landmarks, 2).unwrap().spec;
        assert_eq!((second.flow.time_steps, second.flow.sigma), (20, 1.5));
        assert_eq!(
            second.flow.kernel_tolerance,
            kernel_tolerance(1.5, &landmarks)
        );
        assert!(safer(&spec, &landmarks, RETRIES + 1).is_none());
    }

    /// Decision 0034: no AL iteration of the automatic Dice stage is cut before its progress
    /// rule ends it, the later ones no shorter than the first.
    #[test]
    fn every_dice_al_iteration_runs_until_its_progress_rule_ends_it() {
        let stage = constrained("dice", AttachmentSpec::Ssd, DICE);
        let first = stage.schedule.first_iterations.expect("a first budget");
        assert!(stage.lbfgs.progress.is_some());
        assert!(stage.lbfgs.max_iterations >= first);
    }

    fn line(n: usize) -> Vec<Vec3> {
        (0..n).map(|i| Vec3::new(i as f64, 0.0, 0.0)).collect()
    }

    #[test]
    fn the_kernel_is_truncated_only_where_few_pairs_are_near() {
        assert_eq!(kernel_tolerance(1.0, &line(100)), KERNEL_TOLERANCE);
        // 159 of 435 pairs (37 %) within the cutoff: truncated (decision 0014's addendum).
        assert_eq!(kernel_tolerance(1.0, &line(30)), KERNEL_TOLERANCE);
        assert_eq!(kernel_tolerance(1.0, &line(8)), 0.0);
        assert_eq!(kernel_tolerance(100.0, &line(100)), 0.0);
        assert_eq!(kernel_tolerance(f64::NAN, &line(100)), 0.0);
    }

    #[test]
    fn the_finest_varifold_width_is_sigma_within_half_to_all_of_the_second() {
        assert_eq!(finest_width(3.155, 1.74), 1.74);
        assert_eq!(finest_width(2.0, 1.5), 1.5);
        assert_eq!(finest_width(1.0, 2.0), 1.0);
        assert_eq!(finest_width(4.0, 1.0), 2.0);
    }

    #[test]
    fn every_plan_passes_its_own_checks() {
        let plan = FitPlan {
            sigma: 2.345,
            time_steps: 20,
            kinetic_weight: 0.005,
            affine_iterations: 500,
            boundary_iterations: 1000,
            dice_iterations: 300,
        };
        for spec in [plan.paper_schedule(), plan.boundary_ssd()] {
            spec.check().unwrap();
            assert_eq!(spec.flow.sigma, 2.35);
        }
    }
}
