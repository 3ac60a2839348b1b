//! The augmented-Lagrangian schedule of one stage (SPEC §3).
//!
//! `λ = 0`, `μ = μ₀`; for each AL iteration: minimise `E_AL` over all momenta (L-BFGS, warm
//! started), then `λ^n_l ← λ^n_l − μ C_l(q^n)` at the optimum, then `μ ← μ·μ_factor` (always,
//! or only when `max |C|` did not halve since the previous AL iteration). `μ` never exceeds
//! [`AlSchedule::mu_max`], a guard against the divergence the reference implementation shows
//! when `μ` runs away.

use crate::attachment::Attachment;
use crate::fit::guard::{self, Guard, Unsound};
use crate::fit::objective::{ConstraintSet, Evaluation, Objective, Penalty};
use crate::fit::optimize::{minimize, IterationReport, LbfgsOptions, Minimum, StopReason};
use crate::flow::Flow;
use crate::{Error, Result, Vec3};
use std::cell::Cell;

/// When `μ` grows between AL iterations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum MuUpdate {
    /// After every AL iteration.
    #[default]
    Always,
    /// Only when `max |C|` did not at least halve since the previous AL iteration (reference).
    IfNotHalved,
}

/// The `μ` schedule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AlSchedule {
    /// Initial penalty weight `μ₀ > 0`.
    pub mu: f64,
    /// Growth factor `≥ 1`.
    pub mu_factor: f64,
    /// Upper bound of `μ`.
    pub mu_max: f64,
    /// Number of AL iterations `≥ 1`.
    pub iterations: usize,
    /// When `μ` grows.
    pub mu_update: MuUpdate,
}

impl Default for AlSchedule {
    fn default() -> Self {
        Self {
            mu: 1.0,
            mu_factor: 10.0,
            mu_max: 1e6,
            iterations: 1,
            mu_update: MuUpdate::Always,
        }
    }
}

impl AlSchedule {
    fn check(&self) -> Result<()> {
        let ok = self.mu.is_finite()
            && self.mu > 0.0
            && self.mu_factor.is_finite()
            && self.mu_factor >= 1.0
            && self.mu_max >= self.mu
            && self.iterations >= 1;
        if ok {
            Ok(())
        } else {
            Err(Error::InvalidParameter(format!(
                "augmented Lagrangian needs mu > 0, mu_factor ≥ 1, mu_max ≥ mu and at least one iteration, got {self:?}"
            )))
        }
    }
}

/// One stage: flow, initial landmarks, attachment and its weight, optional constraints and
/// fold test.
#[derive(Clone, Copy)]
pub struct Stage<'a> {
    /// The flow.
    pub flow: &'a Flow,
    /// The landmarks at `t = 0`, `q^0` (boundary points, then medial points).
    pub initial: &'a [Vec3],
    /// `g`.
    pub attachment: &'a dyn Attachment,
    /// `w_data`.
    pub data_weight: f64,
    /// Medial constraints, or none.
    pub constraints: Option<&'a dyn ConstraintSet>,
    /// The fold test of every accepted iterate ([`Guard::new`] of the model), or none (the
    /// other checks of [`guard::check`] always apply).
    pub guard: Option<&'a Guard>,
}

/// Where an L-BFGS iteration sits in the schedule.
#[derive(Clone, Copy, Debug)]
pub struct Progress<'r> {
    /// AL iteration (0-based).
    pub al_iteration: usize,
    /// `μ` of this AL iteration (0 without constraints).
    pub mu: f64,
    /// The L-BFGS iteration.
    pub report: &'r IterationReport<'r>,
}

/// Where and why a stage ended at an unsound iterate.
#[derive(Clone, Debug, PartialEq)]
pub struct UnsoundStop {
    /// AL iteration (0-based).
    pub al_iteration: usize,
    /// The L-BFGS iteration that was refused (1-based within its minimisation).
    pub iteration: usize,
    /// Why.
    pub cause: Unsound,
}

/// The outcome of a stage.
#[derive(Clone, Debug)]
pub struct StageOutcome {
    /// Final momenta: the last sound iterate.
    pub momenta: Vec<f64>,
    /// Figures of the last minimisation at its optimum.
    pub evaluation: Evaluation,
    /// L-BFGS iterations over all AL iterations.
    pub iterations: usize,
    /// Value + gradient evaluations over all AL iterations.
    pub evaluations: usize,
    /// AL iterations done.
    pub al_iterations: usize,
    /// `μ` of the last minimisation (0 without constraints).
    pub mu: f64,
    /// The multipliers `λ` of the last minimisation, `N·L` numbers (time point after time
    /// point; empty without constraints): with [`Self::mu`] they give [`Self::evaluation`]
    /// again.
    pub lambda: Vec<f64>,
    /// Why each minimisation stopped.
    pub stops: Vec<StopReason>,
    /// Restarts after an unsound iterate, over all minimisations.
    pub restarts: usize,
    /// Set when the stage ended at an unsound iterate (after a restart): the momenta are then
    /// those of the last sound one, and the fit cannot go on.
    pub unsound: Option<UnsoundStop>,
}

impl StageOutcome {
    /// Whether the last minimisation stopped on a convergence criterion.
    pub fn converged(&self) -> bool {
        self.stops.last().is_some_and(StopReason::converged)
    }
}

/// Runs a stage from the momenta `start`: one minimisation without constraints, the AL
/// schedule with them. Every accepted iterate is checked ([`guard::check`] against the
/// objective at the stage's start); after a minimisation that needed a restart, `μ` grows by
/// `√mu_factor` only. A minimisation that ends unsound ends the stage ([`StageOutcome::unsound`]).
pub fn run_stage(
    stage: &Stage<'_>,
    schedule: &AlSchedule,
    options: &LbfgsOptions,
    start: Vec<f64>,
    mut progress: impl FnMut(&Progress<'_>),
) -> Result<StageOutcome> {
    let stage_start = Cell::new(None);
    let check = |e: &Evaluation| {
        let start = stage_start.get().unwrap_or(e.total);
        stage_start.set(Some(start));
        guard::check(stage.guard, e, start)
    };
    let Some(constraints) = stage.constraints else {
        let objective = Objective::new(
            stage.flow,
            stage.initial,
            stage.attachment,
            stage.data_weight,
        );
        let min = minimize(&objective, start, options, check, |r| {
            progress(&Progress {
                al_iteration: 0,
                mu: 0.0,
                report: r,
            })
        })?;
        return Ok(StageOutcome {
            unsound: unsound_stop(0, &min),
            momenta: min.momenta,
            evaluation: min.evaluation,
            iterations: min.iterations,
            evaluations: min.evaluations,
            al_iterations: 1,
            mu: 0.0,
            lambda: Vec::new(),
            restarts: min.restarts,
            stops: vec![min.stop],
        });
    };
    schedule.check()?;
    let mut lambda = vec![0.0; stage.flow.time_steps() * constraints.len()];
    let mut mu = schedule.mu;
    let mut momenta = start;
    let mut outcome = StageOutcome {
        momenta: Vec::new(),
        evaluation: Evaluation::default(),
        iterations: 0,
        evaluations: 0,
        al_iterations: 0,
        mu,
        lambda: Vec::new(),
        stops: Vec::new(),
        restarts: 0,
        unsound: None,
    };
    let mut previous_violation = f64::INFINITY;
    for al_iteration in 0..schedule.iterations {
        let objective = Objective::new(
            stage.flow,
            stage.initial,
            stage.attachment,
            stage.data_weight,
        )
        .with_penalty(Penalty {
            constraints,
            mu,
            lambda: &lambda,
        })?;
        let min = minimize(&objective, momenta, options, check, |r| {
            progress(&Progress {
                al_iteration,
                mu,
                report: r,
            })
        })?;
        outcome.iterations += min.iterations;
        outcome.evaluations += min.evaluations;
        outcome.al_iterations += 1;
        outcome.restarts += min.restarts;
        outcome.evaluation = min.evaluation.clone();
        outcome.mu = mu;
        outcome.lambda.clone_from(&lambda);
        outcome.unsound = unsound_stop(al_iteration, &min);
        outcome.stops.push(min.stop);
        momenta = min.momenta;
        if outcome.unsound.is_some() {
            break;
        }
        let values = objective.constraint_values(&momenta)?;
        lambda
            .iter_mut()
            .zip(&values)
            .for_each(|(lam, c)| *lam -= mu * c);
        let violation = outcome.evaluation.max_abs_constraint;
        let grow = match schedule.mu_update {
            MuUpdate::Always => true,
            MuUpdate::IfNotHalved => violation > 0.5 * previous_violation,
        };
        previous_violation = violation;
        if grow {
            let factor = match min.restarts {
                0 => schedule.mu_factor,
                _ => schedule.mu_factor.sqrt(),
            };
            mu = (mu * factor).min(schedule.mu_max);
        }
    }
    outcome.momenta = momenta;
    Ok(outcome)
}

/// The unsound stop of a minimisation of AL iteration `al_iteration`, if it ended so.
fn unsound_stop(al_iteration: usize, min: &Minimum) -> Option<UnsoundStop> {
    match &min.stop {
        StopReason::Unsound(cause) => Some(UnsoundStop {
            al_iteration,
            iteration: min.iterations + 1,
            cause: cause.clone(),
        }),
        _ => None,
    }
}
