//! Fit plans: the settings of a fit chosen from the data, for the configs `medial synth` writes
//! and for `medial fit --template T` without a config. Each rule is stated where it is made:
//! the kernel width from the template's geometry ([`Geometry::sigma`]), the time steps, the
//! kinetic weight and the iteration budgets ([`Geometry::plan`]), the μ schedules and the image
//! smoothing ([`FitPlan::automatic`]).

use crate::config::{
    AttachmentKind, Config, ConstraintUnitsConfig, FlowConfig, ModelConfig, OutputConfig,
    StageConfig,
};
use medial_core::attachment::varifold::default_width;
use medial_core::flow::kernel::GaussianKernel;
use medial_core::model::template::MedialTemplate;
use medial_core::synth::PrincipalAxes;
use medial_core::{TriMesh, Vec3};
use serde::Serialize;
use std::path::PathBuf;

/// The image smoothing of an automatic Dice stage, per mm of the smallest voxel size.
pub const IMAGE_SIGMA_PER_VOXEL: f64 = 0.4;

/// The refinement of a graded signed image in an automatic Dice stage (`image_refine`): the
/// boundary follows the zero crossing to a third of a voxel. Measured on the anterior mitral
/// leaflet (a level set in [−1, 1] at 0.8 mm voxels, a sheet one to three voxels thick): voxel
/// Dice 0.936 → 0.952 on the image's own grid with the same schedule.
pub const GRADED_IMAGE_REFINE: usize = 3;

/// What an automatic fit matches.
#[derive(Clone, Debug)]
pub enum Target {
    /// A segmentation: its file, the foreground label (every voxel > 0 without), its smallest
    /// voxel size in mm.
    Image {
        /// The file.
        path: PathBuf,
        /// The foreground label.
        label: Option<f64>,
        /// Smallest voxel size, mm.
        voxel_mm: f64,
        /// Whether it is a graded signed image (a level set, foreground `v > 0`; see
        /// [`medial_core::image::volume::Volume::is_graded_signed`]): refined by
        /// [`GRADED_IMAGE_REFINE`] without a label.
        graded_signed: bool,
    },
    /// Points in correspondence with the template's boundary points.
    Points(PathBuf),
    /// A surface without correspondence: its file, and the varifold kernel widths (mm) of the
    /// automatic fit's first two stages (see [`varifold_widths`]; the third's is
    /// [`finest_width`]).
    Surface {
        /// The file.
        path: PathBuf,
        /// Kernel width of the first stage, mm.
        width: f64,
        /// Kernel width of the second, mm.
        fine_width: f64,
    },
}

/// The fit settings of a case's configs.
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

/// AL iterations of the constrained SSD fit to the warped boundary (μ = 20 … 20000, relative
/// constraint units: on cmrep's t001 about the weight of μ = 1 … 1000 in mm²).
const BOUNDARY_AL_ITERATIONS: usize = 4;

/// AL iterations of the Dice stage (μ = 0.02, 0.2, …, 2000 in relative constraint units; on
/// cmrep's t001 about the weight of the paper's μ = 0.001 … 100 in mm², one step further than
/// the paper's 10). Measured on t001 bent by `medial synth --from`: 0.24° and 0.36 %, against 0.57° and
/// 1.59 % with the same schedule in mm² and 2.6 % when stopping at μ = 10.
const DICE_AL_ITERATIONS: usize = 6;

impl FitPlan {
    /// The paper's schedule (`fit.toml`): SSD towards the affine part `affine.txt` (μ = 20, one
    /// AL iteration), then Dice against `target.nii.gz` with the constraints in relative units
    /// and μ = 0.02, 0.2, …, 2000 ([`DICE_AL_ITERATIONS`]).
    pub fn paper_schedule(&self) -> Config {
        let affine = self.affine_stage("affine.txt".into());
        self.config(vec![affine, self.dice_stage("target.nii.gz".into())])
    }

    /// The constrained SSD fit to the warped boundary points (`fit_boundary.toml`): target
    /// `target_boundary.vtk` (known correspondence), constraints in relative units, μ = 20, 200,
    /// 2000, 20000 over [`BOUNDARY_AL_ITERATIONS`] AL iterations.
    pub fn boundary_ssd(&self) -> Config {
        self.config(vec![self.boundary_stage("target_boundary.vtk".into())])
    }

    /// The automatic schedule of `medial fit --template T` against `target`: [`AUTOMATIC`]'s
    /// time steps, the medial constraints on in relative units with μ rising tenfold per AL
    /// iteration, and a template already carried onto the target by the initial alignment
    /// ([`medial_core::fit::align`]), projected onto its constraints — so the first AL
    /// iteration can start at a μ that keeps it near them —
    /// - an image: Dice, the image smoothed by 0.4 × its smallest voxel size (0.2 mm at 0.5 mm
    ///   voxels);
    /// - corresponding points: SSD;
    /// - a surface: varifold, one AL iteration at μ = 200 of up to 400 L-BFGS iterations while
    ///   they make progress, then a second varifold stage at a narrower kernel
    ///   ([`varifold_widths`]) at μ = 2000 (up to 300), then a third at about the flow's σ
    ///   ([`finest_width`]) at μ = 20000 (up to 200).
    ///
    /// The kernel is truncated as [`kernel_tolerance`] decides for the template's landmarks
    /// `landmarks`.
    pub fn automatic(&self, template: PathBuf, target: &Target, landmarks: &[Vec3]) -> Config {
        let a = &AUTOMATIC;
        let sigma = (a.sigma_factor * self.sigma * 100.0).round() / 100.0;
        let stages = match target {
            Target::Image {
                path,
                label,
                voxel_mm,
                graded_signed,
            } => {
                let mut dice = constrained("dice", AttachmentKind::Dice, a.dice);
                dice.image = Some(path.clone());
                dice.label = *label;
                if *graded_signed && label.is_none() {
                    dice.image_refine = GRADED_IMAGE_REFINE;
                }
                dice.image_sigma = IMAGE_SIGMA_PER_VOXEL * voxel_mm / dice.image_refine as f64;
                vec![dice]
            }
            Target::Points(path) => {
                let mut points = constrained("boundary", AttachmentKind::Ssd, a.points);
                points.target = Some(path.clone());
                points.constraints = Some(true);
                vec![points]
            }
            Target::Surface {
                path,
                width,
                fine_width,
            } => {
                let varifold = |name, schedule, width| {
                    let mut surface = constrained(name, AttachmentKind::Varifold, schedule);
                    surface.surface = Some(path.clone());
                    surface.varifold_width = Some(width);
                    surface.constraints = Some(true);
                    surface
                };
                vec![
                    varifold("surface", a.surface, *width),
                    varifold("surface-fine", a.surface_fine, *fine_width),
                    varifold(
                        "surface-finest",
                        a.surface_finest,
                        finest_width(*fine_width, sigma),
                    ),
                ]
            }
        };
        let mut config = self.config_of(template, stages);
        config.flow.time_steps = a.time_steps;
        config.flow.sigma = sigma;
        config.flow.kernel_tolerance = kernel_tolerance(config.flow.sigma, landmarks);
        config
    }

    /// The SSD stage towards the template moved by the affine map in the file `transform`.
    fn affine_stage(&self, transform: PathBuf) -> StageConfig {
        let mut affine = StageConfig::new("affine", AttachmentKind::Ssd);
        affine.transform = Some(transform);
        affine.mu = 20.0;
        affine.al_iterations = 1;
        affine.max_iterations = self.affine_iterations;
        affine
    }

    /// The Dice stage of the paper's schedule against `image`.
    fn dice_stage(&self, image: PathBuf) -> StageConfig {
        let mut dice = constrained(
            "dice",
            AttachmentKind::Dice,
            Schedule {
                mu: 0.02,
                al_iterations: DICE_AL_ITERATIONS,
                max_iterations: self.dice_iterations,
                first: None,
                coarse: 0,
            },
        );
        dice.image = Some(image);
        dice
    }

    /// The constrained SSD stage to corresponding points `target`.
    fn boundary_stage(&self, target: PathBuf) -> StageConfig {
        let mut boundary = constrained(
            "boundary",
            AttachmentKind::Ssd,
            Schedule {
                mu: 20.0,
                al_iterations: BOUNDARY_AL_ITERATIONS,
                max_iterations: self.boundary_iterations,
                first: None,
                coarse: 0,
            },
        );
        boundary.target = Some(target);
        boundary.constraints = Some(true);
        boundary
    }

    /// A config of `template.vtk` with this plan's flow (σ rounded to 0.01 mm) and `stages`.
    fn config(&self, stages: Vec<StageConfig>) -> Config {
        self.config_of("template.vtk".into(), stages)
    }

    /// A config of `template` with this plan's flow (σ rounded to 0.01 mm) and `stages`.
    fn config_of(&self, template: PathBuf, stages: Vec<StageConfig>) -> Config {
        Config {
            model: ModelConfig { template },
            flow: FlowConfig {
                sigma: (self.sigma * 100.0).round() / 100.0,
                time_steps: self.time_steps,
                kinetic_weight: self.kinetic_weight,
                ..FlowConfig::default()
            },
            output: OutputConfig::default(),
            stages,
        }
    }
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
    /// The first AL iterations in [`Automatic::coarse_time_steps`] steps (0: none).
    coarse: usize,
}

/// The budget of the first AL iteration and the progress rule of a stage: an AL iteration
/// stops when its last `window` L-BFGS iterations lowered the objective by less than
/// `decrease` of it.
#[derive(Clone, Copy)]
struct FirstIteration {
    /// L-BFGS iterations of the first AL iteration (`first_iterations`).
    budget: usize,
    /// `progress_window`, iterations.
    window: usize,
    /// `progress_decrease`, a fraction of the objective.
    decrease: f64,
}

/// The automatic schedules of [`FitPlan::automatic`].
struct Automatic {
    /// Time steps N.
    time_steps: usize,
    /// `coarse_time_steps` of the stages whose [`Schedule::coarse`] is not 0: their first AL
    /// iterations run in 5 steps while the flow strains space by at most 0.5 per step (see
    /// `medial_core::fit::CoarseTime`). Measured against N = 10 throughout on the resolved
    /// configs of this schedule (evaluations and figures; whole-process times in the README):
    /// - images (voxel Dice, max angle, max mismatch), 3 of the 5 AL iterations coarse:
    ///   t001-bent 427 → 384, 0.988, 0.012°, 0.015 % → 0.989, 0.013°, 0.009 %; hard 508 → 475,
    ///   0.987, 0.15°, 0.09 % → 0.989, 0.07°, 0.07 %; toy 296 → 316, 0.984, 0.05°, 0.014 % →
    ///   0.984, 0.09°, 0.02 %; cup 278 → 267, 0.981, 0.13°, 0.011 % → 0.981, 0.18°, 0.04 %; all
    ///   four settled. The anterior mitral leaflet strains space past the limit by its 10th
    ///   iteration and runs in 10 steps from its start: the same bits, 13 evaluations more.
    ///   All but the last coarse (4 of 5): t001-bent 363, hard 461 evaluations, but the toy and
    ///   the cup no longer settle (412, 344: their last AL iteration, in 10 steps, runs to its
    ///   budget).
    /// - points (mean distance), the first of 3 coarse: t001-bent 779 → 736, 0.016 → 0.015 mm;
    ///   hard 766 → 805, 0.158 → 0.157 mm, 0.034° → 0.037°; toy 418 → 378, 0.192 mm both. Two
    ///   of 3: 777, 760, 360 evaluations, but the hard case ends at 0.07°, 0.12 % and on its
    ///   budget.
    /// - surfaces: none. The first of the second stage's two AL iterations coarse: toy 829 →
    ///   878, 0.090 → 0.101 mm; cup 646 → 621, 0.216 → 0.217 mm; t001-bent 852 → 901, 0.039 →
    ///   0.035 mm; hard 897 → 918, 0.056 → 0.055 mm; the placenta 878 → 878, 0.289 → 0.241 mm,
    ///   but t001-bent, hard and the placenta then end on their budgets.
    ///
    /// Coarse in every AL iteration but a last one in 10 steps started from the coarse first
    /// one's end was measured too: the leaflet at 0.67°, 0.96 % (0.28°, 0.23 % in 10 steps).
    coarse_time_steps: usize,
    /// The kernel width, a fraction of the configs' [`Geometry::sigma`].
    sigma_factor: f64,
    /// Against an image (Dice).
    dice: Schedule,
    /// Against corresponding points (SSD): the first AL iteration up to 400 iterations under
    /// the progress rule, then 2 × 200. Up to 400 instead of 600 (toy, t001-bent, hard: mean
    /// distance, evaluations): 0.192 / 0.015 / 0.156 mm in 418 / 931 / 948 → 0.192 / 0.016 /
    /// 0.158 mm in 418 / 779 / 766.
    points: Schedule,
    /// Against a surface (varifold): one AL iteration (μ = 200) as long as it makes progress.
    /// Its shape carries the second stage, its constraints are tightened there. Measured on
    /// the toy, the cup and t001-bent against their boundaries subdivided and shuffled (mean
    /// distance after the second stage, evaluations of both): the previous 3 × 300 (μ = 200 …
    /// 20000) then 2 × 300 ended at 0.090 / 0.226 / 0.035 mm in 1,555 / 1,565 / 1,578; one AL
    /// iteration of up to 600 under 0.3 % per 40, then 300 + 150, at 0.093 / 0.216 / 0.040 mm in
    /// 1,042 / 646 / 1,070; of up to 400, then 300 + 150 (this schedule), 0.090 / 0.216 /
    /// 0.039 mm in 829 / 646 / 852; of up to 400, then 200 + 150, 0.087 / 0.216 / 0.040 mm in
    /// 767 / 646 / 793; 600, then 450 + 150: 0.112 / 0.216 / 0.029 mm in 1,204 / 646 / 1,265.
    /// On the hard case and the placenta, 300 + 150 against 200 + 150 in the second stage:
    /// 0.056 against 0.062 mm, 0.289 against 0.314 mm (the previous schedule: 0.055 mm in 1,600
    /// and 0.247 mm in 1,550 evaluations; this one 897 and 878).
    surface: Schedule,
    /// The second varifold stage, at the narrower kernel: μ = 2000, one AL iteration of up to
    /// 300 iterations under the progress rule (until this release a second, μ = 20000 and up
    /// to 150, at the same width, now the third stage's). The width (a quarter of the first stage's) was chosen with the previous schedule and an
    /// earlier flow kernel on the placenta (cmrep's sheet inflated, against its deformed
    /// template): after the first stage's 0.735 mm to the surface, a quarter of the width ended
    /// at 0.544 mm, half of it at 0.635 mm (2 × 300 from μ = 2000 each, 620 evaluations).
    surface_fine: Schedule,
    /// The third varifold stage, at about the flow's σ ([`finest_width`]): μ = 20000, one AL
    /// iteration of up to 200 iterations while the last 40 lower the objective by at least
    /// 0.1 % (at the 0.3 % of the others it stopped after about 43 evaluations: at a narrow
    /// width the data term carries a large constant part, so its relative decrease looks
    /// small). Measured on the toy, the cup, t001-bent, hard and the placenta (evaluations,
    /// mean distance to the surface), against the second stage's second AL iteration at its
    /// own width: 829 → 929, 0.090 → 0.090 mm; 646 → 784, 0.216 → 0.146 mm; 852 → 837, 0.039 →
    /// 0.038 mm; 897 → 951, 0.056 → 0.055 mm; 878 → 929, 0.289 → 0.287 mm. 150 iterations
    /// without the progress rule: the cup at 0.185 mm; the second stage kept as it was and the
    /// third after it: 752–1,058 evaluations. A third width below σ takes the toy farther
    /// (w₂/2 = 1.0 mm: 0.198 mm; 0.85 σ: 0.102 mm), above it the cup (1.15 σ: 0.190 mm); σ
    /// itself as the second width: the cup 0.174 mm, the toy 0.118 mm.
    surface_finest: Schedule,
}

/// Measured on cmrep's t001 under a −35° bend, a 25° twist and an unequal scaling (1.15, 0.9,
/// 1.05) made by `medial synth --from`, after the initial affine map and projection. Against
/// the image: the schedule of the paper's configs (N = 20, μ = 0.02 …, 6 × 300) spends 1,857
/// evaluations for voxel Dice 0.986, 0.16°, 0.19 %; N = 10 with μ = 2 … 20000, 5 × 120, 636
/// evaluations for 0.975, 0.32°, 0.41 % in a fourth of the time (4 × 150: 0.978, 0.27°,
/// 0.55 %; N = 20 with 4 × 150: 0.976, 0.32°, 0.47 % at twice the cost per evaluation). A small first μ lets the first AL
/// iteration wander far from the constraints (14°, 11 %) and later ones pull it back; a template
/// projected onto them can start higher. Against the points: 4 × 1000 at N = 20 reach 0.174 mm
/// in 4,162 evaluations; μ = 200 … 20000, 3 × 300 at N = 10 0.225 mm, 0.32°, 0.46 % in 944;
/// a first AL iteration of up to 900 under a progress rule of 0.3 % per 50 iterations, then
/// 2 × 200, 0.184 mm, 0.38°, 0.47 % in 1,359 (900 + 2 × 300 without the rule: 0.186 mm in
/// 1,565; 3 × 400: 0.207 mm in 1,250; 4 × 300 with a first of 600 under 1 % per 40: 0.211 mm
/// in 1,557). The same on t001-bent takes 0.056 mm to 0.033, on the toy 0.210 mm to 0.204.
/// With the narrower kernel ([`SIGMA_FACTOR`]) a first AL iteration of up to 600 under 0.3 %
/// per 40 ends where up to 900 under 0.3 % per 50 does in fewer evaluations (hard 0.156 mm in
/// 913 against 1,037, t001-bent 0.015 in 965 against 1,252, toy 0.192 in 418 against 455).
const AUTOMATIC: Automatic = Automatic {
    time_steps: 10,
    coarse_time_steps: 5,
    sigma_factor: SIGMA_FACTOR,
    dice: Schedule {
        mu: 2.0,
        al_iterations: 5,
        max_iterations: 120,
        first: Some(FirstIteration {
            budget: 600,
            window: 40,
            decrease: 0.01,
        }),
        coarse: 3,
    },
    points: Schedule {
        mu: 200.0,
        al_iterations: 3,
        max_iterations: 200,
        first: Some(FIRST_PROGRESS),
        coarse: 1,
    },
    surface: Schedule {
        mu: 200.0,
        al_iterations: 1,
        max_iterations: 400,
        first: Some(FIRST_PROGRESS),
        coarse: 0,
    },
    surface_fine: Schedule {
        mu: 2000.0,
        al_iterations: 1,
        max_iterations: 300,
        first: Some(FirstIteration {
            budget: 300,
            ..FIRST_PROGRESS
        }),
        coarse: 0,
    },
    surface_finest: Schedule {
        mu: 20000.0,
        al_iterations: 1,
        max_iterations: 200,
        first: Some(FirstIteration {
            budget: 200,
            window: 40,
            decrease: 0.001,
        }),
        coarse: 0,
    },
};

/// The first AL iteration against points or a surface: up to 400 iterations while the last 40
/// lower the objective by at least 0.3 %.
const FIRST_PROGRESS: FirstIteration = FirstIteration {
    budget: 400,
    window: 40,
    decrease: 0.003,
};

/// The kernel width of an automatic fit against [`Geometry::sigma`] (the mean spoke length, at
/// least half the mean boundary edge): a narrower kernel lets medial and boundary points move
/// apart as the constraints need. Measured with the schedules below, σ × 1 → × 0.55:
/// - images (voxel Dice, max angle, max mismatch, evaluations): t001-bent 0.984, 0.24°, 0.42 %,
///   599 → 0.988, 0.01°, 0.01 %, 430; hard 0.973, 0.31°, 0.36 %, 624 → 0.987, 0.15°, 0.09 %,
///   494; toy 0.981, 0.18°, 0.13 %, 659 → 0.984, 0.05°, 0.01 %, 387; cup (whose σ was half
///   its 6.3 mm mean edge) 0.981, 0.32°, 0.26 %, 609 → 0.981, 0.08°, 0.004 %, 366; three
///   `medial synth --from` warps 0.977–0.990 → 0.988–0.990, ≤ 0.45° → ≤ 0.03°; the anterior
///   mitral leaflet 0.950, 0.73°, 0.19 %, 1,138 → 0.952, 0.28°, 0.20 %, 1,085;
/// - points (mean distance): hard 0.184 → 0.156 mm, 0.38° → 0.02°; t001-bent 0.033 → 0.014 mm;
///   toy 0.204 → 0.192 mm in 467 evaluations instead of 1,002; the warps 0.014–0.093 → 0.007–0.071 mm.
///
/// At × 0.75 (tried on the image and point fits of t001-bent, hard and toy) each of those lay
/// between the two.
const SIGMA_FACTOR: f64 = 0.55;

/// The kernel tolerance ε of an automatic fit that truncates its kernel: the sums then err by
/// at most 1e-10 of the sums of absolute terms (see `medial_core::flow`), far below what a fit
/// can tell.
const KERNEL_TOLERANCE: f64 = 1e-10;

/// An automatic fit truncates its kernel when at most this fraction of the template's landmark
/// pairs lie within the cutoff radius `r = σ √(2 ln(1/ε))`: the truncated sweep's cell grid
/// and chunk masks cost more than they skip when most pairs are near. Measured on image fits
/// (the automatic schedule, wall time exact / truncated, median of 3 paired runs, the leaflet
/// one run each): the toy (26 % of its 311 landmarks' pairs near) 0.91, t001-bent (16 %) 1.25,
/// the cup (8 %) 1.20, the anterior mitral leaflet (3 %, k = 1,433) 1.6; figures equal to the
/// third digit.
const TRUNCATE_AT_MOST: f64 = 0.2;

/// `[flow] kernel_tolerance` of an automatic fit with kernel width `sigma` (mm) of a template
/// with landmarks `landmarks`: [`KERNEL_TOLERANCE`] when at most [`TRUNCATE_AT_MOST`] of
/// their pairs are near, else 0 (exact).
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

/// The second varifold stage's kernel width, as a fraction of the first's (see
/// [`Automatic::surface_fine`]).
const FINE_WIDTH_FRACTION: f64 = 0.25;

/// The varifold kernel widths (mm) of an automatic fit to the surface `target`: first
/// [`default_width`] (a tenth of its bounding-box diagonal, at least two mean edges), then
/// [`FINE_WIDTH_FRACTION`] of it, at least half the longer of the mean edges of the target and
/// of the template's boundary `boundary` (a kernel much narrower than the triangles sees their
/// sampling, not the shape). On the placenta a floor of two mean edges (9.9 mm) kept the second
/// stage from helping (0.715 mm against 0.735), the quarter (3.3 mm, 0.7 mean edges) did.
pub fn varifold_widths(
    boundary: &TriMesh,
    target: &TriMesh,
) -> Result<(f64, f64), medial_core::Error> {
    let width = default_width(target)?;
    let edge = mean_edge(target).max(mean_edge(boundary));
    Ok((width, (FINE_WIDTH_FRACTION * width).max(0.5 * edge)))
}

/// The third varifold stage's kernel width (mm) after a second at `fine` in a flow of kernel
/// width `sigma`: σ, at least half the second's and at most the second's (see
/// [`Automatic::surface_finest`]). The flow cannot follow a varifold much narrower than its
/// own kernel without pulling its boundary points apart; σ separates the cup, which wants
/// narrower, from the toy, which wants wider (their widths against their mean edges are
/// alike).
fn finest_width(fine: f64, sigma: f64) -> f64 {
    sigma.max(0.5 * fine).min(fine)
}

/// The largest `|C|` (relative units: about 0.06° and 0.1 %) at which an automatic stage's AL
/// iterations end early once the attachment changes by less than 0.1 % over one
/// (`settle_constraint`). Measured on the image fits (evaluations, final angle and mismatch):
/// toy 393 → 296, 0.04° / 0.007 % → 0.05° / 0.014 %; cup 358 → 278, 0.08° / 0.005 % → 0.13° /
/// 0.011 % (the angle measured at the end of the flow, the constraint at the template's
/// scale), the same voxel Dice; t001-bent, hard and the point and surface fits unchanged (their
/// constraints reach 1e-3 only in the last AL iteration, or the attachment still moves).
const SETTLE_CONSTRAINT: f64 = 1e-3;

/// A stage with the medial constraints in relative units, μ rising tenfold over the AL
/// iterations of `schedule`, ending early once they settle ([`SETTLE_CONSTRAINT`]).
fn constrained(name: &str, attachment: AttachmentKind, schedule: Schedule) -> StageConfig {
    let mut stage = StageConfig::new(name, attachment);
    stage.constraint_units = ConstraintUnitsConfig::Relative;
    stage.settle_constraint = Some(SETTLE_CONSTRAINT);
    stage.mu = schedule.mu;
    stage.mu_factor = 10.0;
    stage.al_iterations = schedule.al_iterations;
    stage.max_iterations = schedule.max_iterations;
    if schedule.coarse > 0 {
        stage.coarse_time_steps = Some(AUTOMATIC.coarse_time_steps);
        stage.coarse_al_iterations = Some(schedule.coarse);
    }
    if let Some(first) = schedule.first {
        stage.first_iterations = Some(first.budget);
        stage.progress_window = first.window;
        stage.progress_decrease = first.decrease;
    }
    stage
}

/// The comment line of `fit.toml` on its schedule.
pub const PAPER_SCHEDULE_NOTE: &str = "# As in the paper: one SSD AL iteration (mu = 20) towards \
the affine initialisation, then the\n# Dice attachment with mu rising tenfold per AL iteration. \
The constraints are in relative units\n# (mu = 0.02 ... 2000: on cmrep's t001 about the \
paper's 0.001 ... 100 in mm²).\n";

/// The comment line of `fit_boundary.toml` on its schedule.
pub const BOUNDARY_SSD_NOTE: &str = "# SSD fit of the template's boundary points to the warped \
ones (known correspondence), with\n# the medial constraints on in relative units, mu = 20, 200, \
2000, 20000.\n";

/// Geometry of the template that sets the fit's kernel width.
#[derive(Serialize)]
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

    /// `σ` = the mean spoke length (about the half thickness, as for the built-in shapes: small
    /// against the wall, so that the flow can move medial and boundary points apart as the
    /// constraints need), at least half the mean edge length (neighbouring landmarks move
    /// together), at most an eighth of the long extent (the upper bound wins), mm.
    fn sigma(&self) -> f64 {
        self.mean_spoke_mm
            .max(self.mean_edge_mm / 2.0)
            .min(self.long_extent_mm / 8.0)
    }

    /// The fit settings: `σ` from the geometry, 20 time steps, kinetic weight 0.005; L-BFGS
    /// iterations: 500 towards the affine part, 1000 per AL iteration of the boundary fit, 300
    /// per AL iteration of the Dice stage.
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
fn mean_edge(mesh: &TriMesh) -> f64 {
    let p = mesh.points();
    mean(
        mesh.triangles()
            .iter()
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .map(|(a, b)| (p[a] - p[b]).norm()),
    )
}

/// The kernel width of a plain mesh (no spokes to set it): an eighth of its long principal
/// extent (the bound of [`Geometry::sigma`]; 5.5 mm for the KeOps hippocampus, whose shipped
/// config uses 5), at least half its mean edge, mm.
pub fn plain_sigma(mesh: &TriMesh, axes: &PrincipalAxes) -> f64 {
    (axes.extent.z / 8.0).max(mean_edge(mesh) / 2.0)
}

/// The kinetic weight of a plain mesh's automatic fit: the shipped hippocampus config's. With
/// no constraints to hold the wall, the kinetic energy is what keeps the flow smooth; at the
/// medial templates' 0.005 a varifold fit of the reduced KeOps hippocampus folds a triangle
/// (reported unsound at iteration 14).
const PLAIN_KINETIC_WEIGHT: f64 = 0.05;

/// L-BFGS iterations of the one unconstrained stage of an automatic fit of a plain mesh.
const PLAIN_ITERATIONS: usize = 300;

/// The automatic fit of a plain mesh `template` (no medial constraints) against `target`,
/// points (SSD) or a surface (varifold): one stage of [`PLAIN_ITERATIONS`], N =
/// [`AUTOMATIC`]'s time steps, kernel width `sigma`, w_kin [`PLAIN_KINETIC_WEIGHT`]. None for
/// an image: the Dice term needs a medial template's interior.
pub fn automatic_plain(
    template: PathBuf,
    target: &Target,
    sigma: f64,
    landmarks: &[Vec3],
) -> Option<Config> {
    let mut stage = match target {
        Target::Image { .. } => return None,
        Target::Points(path) => {
            let mut points = StageConfig::new("boundary", AttachmentKind::Ssd);
            points.target = Some(path.clone());
            points
        }
        Target::Surface { path, .. } => {
            let mut surface = StageConfig::new("surface", AttachmentKind::Varifold);
            surface.surface = Some(path.clone());
            surface
        }
    };
    stage.constraints = Some(false);
    stage.max_iterations = PLAIN_ITERATIONS;
    Some(Config {
        model: ModelConfig { template },
        flow: FlowConfig {
            sigma: (sigma * 100.0).round() / 100.0,
            time_steps: AUTOMATIC.time_steps,
            kinetic_weight: PLAIN_KINETIC_WEIGHT,
            kernel_tolerance: kernel_tolerance(sigma, landmarks),
        },
        output: OutputConfig::default(),
        stages: vec![stage],
    })
}

fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    sum / n.max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points 1 mm apart along a line.
    fn line(n: usize) -> Vec<Vec3> {
        (0..n).map(|i| Vec3::new(i as f64, 0.0, 0.0)).collect()
    }

    #[test]
    fn the_kernel_is_truncated_only_where_few_pairs_are_near() {
        // σ = 1 mm: the cutoff is 6.8 mm, so on a line of 100 the pairs up to 6 apart are near
        // (579 of 4,950, 12 %), on a line of 8 every pair.
        assert_eq!(kernel_tolerance(1.0, &line(100)), KERNEL_TOLERANCE);
        assert_eq!(kernel_tolerance(1.0, &line(8)), 0.0);
        // A width too wide for any pair to be far, and one that is not a width at all.
        assert_eq!(kernel_tolerance(100.0, &line(100)), 0.0);
        assert_eq!(kernel_tolerance(f64::NAN, &line(100)), 0.0);
    }

    #[test]
    fn the_finest_varifold_width_is_sigma_within_half_to_all_of_the_second() {
        // The cup's and the toy's (second width, σ): σ within the bounds.
        assert_eq!(finest_width(3.155, 1.74), 1.74);
        assert_eq!(finest_width(2.0, 1.5), 1.5);
        // A σ wider than the second width keeps it; a much narrower one halves it.
        assert_eq!(finest_width(1.0, 2.0), 1.0);
        assert_eq!(finest_width(4.0, 1.0), 2.0);
    }
}
