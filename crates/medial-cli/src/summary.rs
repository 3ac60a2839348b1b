//! The figures of a fit: those of one configuration ([`Figures`], as `medial eval` prints them
//! and `log.csv` rows hold them), of each stage and of the whole fit (`summary.json`).

use crate::time_points::OverTime;
use medial_core::fit::objective::Evaluation;
use medial_core::model::metrics::SpokeMetrics;
use serde::{Deserialize, Serialize};

/// The figures of a configuration, as in `summary.json` (`final` and each stage) and the
/// output of `medial eval`. Kinetic energy and data term are unweighted.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Figures {
    /// `E_AL`.
    pub total: f64,
    /// `KE`.
    pub kinetic: f64,
    /// `g(q^N)`.
    pub data: f64,
    /// Penalty `P`.
    pub penalty: f64,
    /// `max |C|` over time points 1…N (0 without constraints).
    pub max_abs_constraint: f64,
    /// Dice estimate, for Dice stages.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dice: Option<f64>,
    /// Dice stages, at the end of a stage: the voxel overlap `2|M ∩ A| / (|M| + |A|)` of the
    /// rasterized model `M` with the binary foreground `A` of the image, on the image's grid.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub voxel_dice: Option<f64>,
    /// Dice and varifold stages, at the end of a stage: the share (%) of the target outside the
    /// model and farther from it than two voxels (two of a target surface's mean edges) or the
    /// flow's σ, the larger: the part of the target the model missed (of `A`'s voxels, or of
    /// the target surface's area; above 2 % the fit misses its target: `misses_target`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub missed_pct: Option<f64>,
    /// Dice and varifold stages, at the end of a stage: the model's voxels (or boundary area)
    /// outside the target and as far from it, the part the model has and the target lacks, %
    /// of the target.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub added_pct: Option<f64>,
    /// Mean distance to the SSD targets (mm), for SSD stages.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_distance: Option<f64>,
    /// Varifold stages, at the end of a stage: the mean distance (mm) from the model's
    /// boundary points to the target surface (exact point–triangle distances).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub surface_distance: Option<f64>,
    /// Largest spoke–normal angle at the end of the flow, degrees (medial templates).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_spoke_normal_deg: Option<f64>,
    /// Mean spoke–normal angle at the end of the flow, degrees (medial templates).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_spoke_normal_deg: Option<f64>,
    /// Largest spoke-length mismatch at the end of the flow, % (medial templates).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_spoke_mismatch_pct: Option<f64>,
}

impl Figures {
    /// From an evaluation, the spoke metrics at `q^N` and the SSD mean distance.
    pub fn new(e: &Evaluation, metrics: Option<&SpokeMetrics>, mean_distance: Option<f64>) -> Self {
        Self {
            total: e.total,
            kinetic: e.kinetic,
            data: e.data,
            penalty: e.penalty,
            max_abs_constraint: e.max_abs_constraint,
            dice: e.dice,
            voxel_dice: None,
            missed_pct: None,
            added_pct: None,
            mean_distance,
            surface_distance: None,
            max_spoke_normal_deg: metrics.map(|m| m.max_spoke_normal_deg),
            mean_spoke_normal_deg: metrics.map(|m| m.mean_spoke_normal_deg),
            max_spoke_mismatch_pct: metrics.map(|m| 100.0 * m.max_spoke_mismatch),
        }
    }
}

/// One stage in `summary.json`.
#[derive(Clone, Debug, Serialize)]
pub struct StageSummary {
    /// The stage's name.
    pub name: String,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// Value + gradient evaluations.
    pub evaluations: usize,
    /// L-BFGS iterations (all AL iterations).
    pub iterations: usize,
    /// AL iterations.
    pub al_iterations: usize,
    /// μ of the last minimisation (0 without constraints); with `lambda.npy` (the last
    /// constrained stage's multipliers) `medial eval` reproduces the stage's final figures.
    pub mu: f64,
    /// Why each minimisation stopped.
    pub stop: Vec<String>,
    /// Whether the AL iterations settled (`settle_constraint`: the constraints held and the
    /// attachment no longer moved) or the last minimisation stopped on a convergence criterion
    /// (gradient, relative decrease, progress) rather than its iteration budget.
    pub converged: bool,
    /// Whether the AL iterations ended because they settled (`settle_constraint`).
    pub settled: bool,
    /// Restarts of L-BFGS from a sound iterate after an unsound one.
    pub restarts: usize,
    /// AL iterations run in `coarse_time_steps` time steps.
    pub coarse_al_iterations: usize,
    /// L-BFGS iterations of a coarse minimisation dropped because its flow strained space
    /// past 0.5 (it ran again in the flow's own steps).
    pub strained_iterations: usize,
    /// Constrained stages: whether the final max spoke–normal angle and max spoke mismatch are
    /// within the stage's `tolerance_deg` and `tolerance_pct` (for the last stage: at every
    /// time point of the fitted flow).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub constraints_met: Option<bool>,
    /// Set when the stage ended at an unsound iterate: where and why.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unsound: Option<String>,
    /// Dice and varifold stages: set when the model missed a part of its target (`missed_pct`
    /// above 2 %): how much, and the target's part farthest from the model.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub misses: Option<String>,
    /// The figures at the end of the stage.
    #[serde(flatten)]
    pub figures: Figures,
}

/// How a fit ended, best first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Every stage ran; the last one converged and met its constraint tolerances.
    Converged,
    /// Every stage ran and the constraints are met, but the last minimisation stopped on its
    /// iteration budget (more iterations may improve the fit).
    Budget,
    /// Every stage ran, but the medial constraints are above their tolerance at the end
    /// (exit code 4).
    ConstraintsNotMet,
    /// Every stage ran, but the last one's model missed a part of its target: more than 2 % of
    /// an image's foreground (or of a surface's area) lies farther from the model than two
    /// voxels (two mean edges) or the flow's σ (exit code 6).
    MissesTarget,
    /// A stage ended at an unsound iterate (folded, diverged, not finite); the results are
    /// those of the last sound iterate and later stages did not run (exit code 3).
    Unsound,
    /// SIGINT or SIGTERM stopped the fit after an accepted iterate: the results are those of
    /// that iterate, the stage in progress is partial and `checkpoint.bin` resumes the fit
    /// (`--resume`; exit code 130 or 143).
    Interrupted,
}

/// `summary.json`.
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    /// `medial` version.
    pub version: &'static str,
    /// How the fit ended.
    pub status: Status,
    /// `k`.
    pub landmarks: usize,
    /// Boundary points.
    pub boundary_points: usize,
    /// Medial atoms.
    pub medial_atoms: usize,
    /// Medial constraints per time point (0 for a plain mesh).
    pub constraints_per_time_point: usize,
    /// `N`.
    pub time_steps: usize,
    /// Kernel width σ.
    pub sigma: f64,
    /// Worker threads.
    pub threads: usize,
    /// Wall-clock seconds of all stages.
    pub seconds: f64,
    /// Value + gradient evaluations of all stages.
    pub evaluations: usize,
    /// Figures at the end.
    #[serde(rename = "final")]
    pub final_figures: Figures,
    /// Medial templates: the worst spoke figures over time points 1 … N (`time_points.csv`
    /// holds them per time point).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub over_time: Option<OverTime>,
    /// The strain of each step of the fitted flow, `dt · max_i ‖∇v^n(q^n_i)‖_F`, `n = 0 … N−1`
    /// (`medial_core::flow::Flow::step_strains`): a step is one-to-one while its strain is
    /// below 1, and a fit warns past `medial_core::flow::STRAIN_LIMIT` (0.5).
    pub step_strains: Vec<f64>,
    /// Each stage.
    pub stages: Vec<StageSummary>,
    /// An automatic fit: what its initial alignment did, one line per step (scale, thickness,
    /// anisotropy, overlap before and after, the projection's moves, a fallback and its reason).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub alignment: Vec<String>,
    /// An automatic fit that had more than one candidate start: what a short trial of the fit
    /// reached from each, and which was taken (`medial_core::fit::trial`); empty when there was
    /// one.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub start_trials: Vec<medial_core::fit::trial::StartTrial>,
    /// An automatic fit that ended unsound and ran again with safer settings: one line per
    /// run before this one (why it ended, what changed); empty when it ran once.
    pub retries: Vec<String>,
    /// The other files of this set of results (paths relative to the folder, sorted): all in
    /// place once `summary.json` is ([`crate::results`]).
    pub files: Vec<String>,
    /// The SHA-256 of each of [`Summary::files`] (lowercase hex), by path: commands that read
    /// the set refuse a file that differs ([`crate::results::verify`]).
    pub sha256: std::collections::BTreeMap<String, String>,
}
