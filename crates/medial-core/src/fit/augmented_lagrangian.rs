//! The augmented-Lagrangian schedule of one stage (docs/method.md §5.2).
//!
//! `λ = 0`, `μ = μ₀`; for each AL iteration: minimise `E_AL` over all momenta (L-BFGS, warm
//! started), then `λ^n_l ← λ^n_l − μ C_l(q^n)` at the optimum, then `μ ← μ·μ_factor` (always,
//! or only when `max |C|` did not halve since the previous AL iteration). `μ` never exceeds
//! [`AlSchedule::mu_max`], a guard against the divergence the reference implementation shows
//! when `μ` runs away. Whether the schedule goes on past its AL iterations ([`Extend`]) is
//! judged on the constraints as a fit reports them: the largest spoke–normal angle and spoke
//! mismatch at the end of the flow against the stage's tolerance ([`Constraints::violation`]).

use crate::attachment::Attachment;
use crate::fit::guard::{self, Guard, Unsound};
use crate::fit::objective::{ConstraintSet, Evaluation, Objective, Penalty};
use crate::fit::optimize::{
    minimize, IterationReport, LbfgsOptions, Minimization, MinimizerCheckpoint, Minimum, Start,
    StopReason,
};
use crate::fit::spec::MedialTolerance;
use crate::flow::{retime_momenta, Flow, STRAIN_LIMIT};
use crate::model::metrics::SpokeMetrics;
use crate::model::MedialTemplate;
use crate::{Error, Result, Vec3};
use serde::{Deserialize, Serialize};
use std::cell::Cell;

/// When `μ` grows between AL iterations (in a config: `always`, `if_not_halved`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
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
    /// The L-BFGS budget of the first AL iteration, where the shape is matched under the
    /// weakest penalty (none: [`LbfgsOptions::max_iterations`] like the others), iterations.
    pub first_iterations: Option<usize>,
    /// Ends the schedule once an AL iteration has settled, before its last (none: every AL
    /// iteration runs); a last AL iteration that settles marks the stage settled too.
    pub settle: Option<Settle>,
    /// Coarse to fine in time (none: every AL iteration in the stage's `N` steps).
    pub coarse: Option<CoarseTime>,
    /// AL iterations past [`AlSchedule::iterations`] while the constraints are above a level
    /// and still improving (none: the schedule's iterations only).
    pub extend: Option<Extend>,
}

/// More AL iterations for a stage whose constraints end above a level: after the schedule's
/// last AL iteration, one more (μ growing as before) while the violation `v`
/// ([`Constraints::violation`], 1 at the tolerance) is above `above` and the schedule is on
/// course ([`Extend::on_course`]), at most `at_most` more. A schedule whose budget ran out
/// while the constraints still converge fast enough to meet their tolerance goes on; one that
/// stalls, or converges too slowly to meet it within the AL iterations left, ends, and is
/// reported as not meeting its tolerance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extend {
    /// The violation above which the schedule goes on, a fraction of the tolerance.
    pub above: f64,
    /// Most AL iterations added.
    pub at_most: usize,
}

impl Extend {
    /// Whether a schedule whose last AL iteration took the violation from `before` to `now`,
    /// with `left` AL iterations still allowed, is on course: the violation fell, and at the
    /// rate `ρ = now/before` kept up over the AL iterations left it would be within the
    /// tolerance, `now · ρ^left ≤ 1`. Each AL iteration multiplies the multipliers' error by
    /// about the same factor once μ is large enough (the linear rate of the method of
    /// multipliers), so the last rate is the best guess of the next; where it cannot meet the
    /// tolerance in time, more AL iterations only cost time.
    pub fn on_course(before: f64, now: f64, left: usize) -> bool {
        let rate = now / before;
        rate < 1.0 && now * rate.powi(left.min(i32::MAX as usize) as i32) <= 1.0
    }
}

/// Coarse to fine in time: the first [`CoarseTime::al_iterations`] AL iterations (fewer if
/// one settles before) run the flow in [`CoarseTime::time_steps`] steps, a divisor of the
/// stage's `N`; then the momenta are carried to the `N` steps ([`retime_momenta`]), the
/// multipliers with them ([`retime_multipliers`]), and the schedule goes on in `N` steps. The
/// kernel sums and the constraints of a coarse evaluation cost `coarse/N` of a fine one (the
/// attachment the same). A coarse minimisation whose flow strains space past
/// [`STRAIN_LIMIT`] (checked every [`STRAIN_CHECK_INTERVAL`] iterations) is dropped and
/// its AL iteration runs in `N` steps from where it began.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CoarseTime {
    /// Time steps of the coarse AL iterations.
    pub time_steps: usize,
    /// AL iterations in coarse steps, at least 1 and fewer than the schedule's: the last runs
    /// in the stage's steps.
    pub al_iterations: usize,
}

/// When an AL schedule has settled: at the end of an AL iteration after the first,
/// `max |C| ≤ max_abs_constraint` and `|g_j − g_{j−1}| ≤ data_change · |g_j|` (`g_j` the
/// attachment at the end of AL iteration `j`): the constraints hold and tightening them no
/// longer moves the fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settle {
    /// The largest `|C|` that counts as met, in the constraints' unit (in relative units the
    /// angle in radians and the relative mismatch at the template's scale; decision 0035).
    pub max_abs_constraint: f64,
    /// The largest relative change of the attachment over the AL iteration.
    pub data_change: f64,
}

impl Settle {
    /// Whether `end` (after an AL iteration that began at attachment `previous_data`) settles.
    fn holds(&self, end: &Evaluation, previous_data: f64) -> bool {
        end.max_abs_constraint <= self.max_abs_constraint
            && (end.data - previous_data).abs() <= self.data_change * end.data.abs()
    }
}

impl Default for AlSchedule {
    fn default() -> Self {
        Self {
            mu: 1.0,
            mu_factor: 10.0,
            mu_max: 1e6,
            iterations: 1,
            mu_update: MuUpdate::Always,
            first_iterations: None,
            settle: None,
            coarse: None,
            extend: None,
        }
    }
}

impl AlSchedule {
    /// The flow of the coarse AL iterations of a stage in `fine`, when there are any: a
    /// coarse step count that divides `N`, below it, and at least two AL iterations.
    fn coarse_flow(&self, fine: &Flow) -> Result<Option<Flow>> {
        let Some(CoarseTime {
            time_steps: steps,
            al_iterations,
        }) = self.coarse
        else {
            return Ok(None);
        };
        let n = fine.time_steps();
        if steps == 0 || steps >= n || n % steps != 0 {
            return Err(Error::InvalidParameter(format!(
                "coarse time steps must divide the flow's {n} time steps and be below them, got {steps}"
            )));
        }
        if al_iterations == 0 || al_iterations >= self.iterations {
            return Err(Error::InvalidParameter(format!(
                "coarse AL iterations must be at least 1 and below the schedule's {}, got {al_iterations}",
                self.iterations
            )));
        }
        fine.with_time_steps(steps).map(Some)
    }

    fn check(&self) -> Result<()> {
        let ok = self.mu.is_finite()
            && self.mu > 0.0
            && self.mu_factor.is_finite()
            && self.mu_factor >= 1.0
            && self.mu_max >= self.mu
            && self.iterations >= 1
            && self.settle.map_or(true, |s| {
                s.max_abs_constraint >= 0.0 && s.data_change >= 0.0
            })
            && self.extend.map_or(true, |e| e.above >= 0.0);
        if ok {
            Ok(())
        } else {
            Err(Error::InvalidParameter(format!(
                "augmented Lagrangian needs mu > 0, mu_factor ≥ 1, mu_max ≥ mu, at least one iteration, non-negative settling and extension levels, got {self:?}"
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
    pub constraints: Option<Constraints<'a>>,
    /// The fold test of every accepted iterate ([`Guard::new`] of the model), or none (the
    /// other checks of [`guard::check`] always apply).
    pub guard: Option<&'a Guard>,
}

/// The medial constraints of a stage and how its schedule judges them.
#[derive(Clone, Copy)]
pub struct Constraints<'a> {
    /// The constraints the penalty holds.
    pub set: &'a dyn ConstraintSet,
    /// The template whose constraints they are: its spoke figures are what a fit reports.
    pub template: &'a MedialTemplate,
    /// What counts as medial.
    pub tolerance: MedialTolerance,
}

impl Constraints<'_> {
    /// How far the template at landmarks `q` is from medial, a fraction of the tolerance: the
    /// larger of its largest spoke–normal angle and largest spoke mismatch ([`SpokeMetrics`],
    /// the figures a fit reports at the end of its flow), each over its tolerance. 1 is at the
    /// tolerance; NaN where the geometry degenerates.
    pub fn violation(&self, q: &[Vec3]) -> f64 {
        let m = SpokeMetrics::compute(self.template, q);
        let angle = m.max_spoke_normal_deg / self.tolerance.angle_deg;
        let mismatch = 100.0 * m.max_spoke_mismatch / self.tolerance.mismatch_pct;
        // `f64::max` would drop a NaN.
        if angle.is_nan() || mismatch.is_nan() {
            f64::NAN
        } else {
            angle.max(mismatch)
        }
    }
}

/// Where an L-BFGS iteration sits in the schedule.
#[derive(Clone, Copy, Debug)]
pub struct Progress<'r> {
    /// AL iteration (0-based).
    pub al_iteration: usize,
    /// `μ` of this AL iteration (0 without constraints).
    pub mu: f64,
    /// Time steps of the flow of this minimisation: the stage's `N`, or its coarse steps
    /// ([`AlSchedule::coarse`]).
    pub time_steps: usize,
    /// The L-BFGS iteration.
    pub report: &'r IterationReport<'r>,
}

/// Where and why a stage ended at an unsound iterate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UnsoundStop {
    /// AL iteration (0-based).
    pub al_iteration: usize,
    /// The L-BFGS iteration that was refused (1-based within its minimisation).
    pub iteration: usize,
    /// Why.
    pub cause: Unsound,
}

/// The outcome of a stage.
#[derive(Clone, Debug, Serialize, Deserialize)]
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
    /// Whether the schedule ended early because it settled ([`AlSchedule::settle`]).
    #[serde(default)]
    pub settled: bool,
    /// AL iterations run in coarse steps ([`AlSchedule::coarse`]).
    #[serde(default)]
    pub coarse_al_iterations: usize,
    /// L-BFGS iterations of a coarse minimisation dropped because its flow strained space past
    /// the limit (it then ran again in the stage's steps); 0 if none was.
    #[serde(default)]
    pub strained_iterations: usize,
}

impl StageOutcome {
    /// Whether the schedule settled or the last minimisation stopped on a convergence
    /// criterion.
    pub fn converged(&self) -> bool {
        self.settled || self.stops.last().is_some_and(StopReason::converged)
    }
}

/// Where a stage starts.
pub enum StageStart {
    /// From these momenta, with `λ = 0` and `μ = μ₀`.
    Momenta(Vec<f64>),
    /// Where a paused stage stopped.
    Resume(Box<StageCheckpoint>),
}

/// How [`run_stage`] ended.
pub enum StageRun {
    /// The schedule ran its course (or ended unsound).
    Done(Box<StageOutcome>),
    /// Paused after an accepted iterate: everything needed to go on.
    Paused(Box<StageCheckpoint>),
}

/// A stage paused after an accepted L-BFGS iterate: its position in the AL schedule (AL
/// iteration, `μ`, `λ`, the violation the `μ` rule compares with), the guard's reference value,
/// the figures of its finished minimisations and the paused minimisation itself.
#[derive(Clone, Serialize, Deserialize)]
pub struct StageCheckpoint {
    al_iteration: usize,
    mu: f64,
    lambda: Vec<f64>,
    previous_violation: f64,
    /// The attachment at the end of the previous AL iteration (for [`Settle`]).
    #[serde(default)]
    previous_data: f64,
    /// [`Constraints::violation`] at the end of the previous AL iteration (for [`Extend`]).
    previous_reported: f64,
    /// `E` at the start of the stage, the reference of the divergence guard.
    guard_start: Option<f64>,
    /// Set while the schedule is in its coarse AL iterations (momenta and `λ` in coarse steps).
    #[serde(default)]
    coarse: Option<CoarsePhase>,
    /// The finished minimisations of the stage (its `momenta` are not used).
    done: StageOutcome,
    minimizer: MinimizerCheckpoint,
}

impl StageCheckpoint {
    /// AL iteration in progress (0-based).
    pub fn al_iteration(&self) -> usize {
        self.al_iteration
    }

    /// Accepted L-BFGS iterations of the minimisation in progress.
    pub fn iteration(&self) -> usize {
        self.minimizer.iterations()
    }

    /// The stage as it stands: the last accepted iterate, with the multipliers and `μ` of the
    /// minimisation in progress (which give its figures again), the counters of every
    /// minimisation so far, and [`StopReason::Paused`] as the stop of the one in progress.
    /// In coarse AL iterations the momenta and `λ` are carried to the stage's steps (and then
    /// give its figures only approximately).
    pub fn partial(&self) -> StageOutcome {
        let m = &self.minimizer;
        let mut stops = self.done.stops.clone();
        stops.push(StopReason::Paused);
        let (momenta, lambda) = match &self.coarse {
            Some(p) => p.refined(m.momenta(), &self.lambda, self.lambda.len() / p.steps),
            None => (m.momenta().to_vec(), self.lambda.clone()),
        };
        StageOutcome {
            momenta,
            evaluation: m.evaluation().clone(),
            iterations: self.done.iterations + m.iterations(),
            evaluations: self.done.evaluations + m.evaluations(),
            al_iterations: self.done.al_iterations + 1,
            mu: self.mu,
            lambda,
            stops,
            restarts: self.done.restarts + m.restarts(),
            unsound: None,
            settled: false,
            coarse_al_iterations: self.done.coarse_al_iterations,
            strained_iterations: self.done.strained_iterations,
        }
    }

    /// The number of momenta of the stage's flow (`N·k·3`, also while in coarse steps).
    pub fn momenta_len(&self) -> usize {
        let len = self.minimizer.momenta().len();
        self.coarse
            .as_ref()
            .map_or(len, |p| len / p.steps * p.fine_steps)
    }
}

/// The coarse AL iterations of a stage in progress ([`AlSchedule::coarse`]): their step count,
/// the stage's, and where the coarse minimisation in progress would run again in the stage's
/// steps should its flow strain space too far.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct CoarsePhase {
    steps: usize,
    fine_steps: usize,
    /// Momenta in the stage's steps: the stage's start, or the previous coarse AL iteration's
    /// end.
    restart: Vec<f64>,
}

impl CoarsePhase {
    /// Momenta and multipliers of the coarse steps carried to the stage's (`l` constraints).
    fn refined(&self, momenta: &[f64], lambda: &[f64], l: usize) -> (Vec<f64>, Vec<f64>) {
        let k = momenta.len() / (3 * self.steps);
        let momenta = retime_momenta(momenta, k, self.steps, self.fine_steps)
            .expect("the coarse steps divide the stage's");
        let lambda = retime_multipliers(lambda, l, self.steps, self.fine_steps);
        (momenta, lambda)
    }
}

/// Multipliers of `l` constraints at the time points `1 … from` (time point after time point)
/// carried to `1 … to`, `to = f·from`: interpolated linearly in time (`λ^0` taken as `λ^1`) and
/// divided by `f`, since the penalty then sums over `f` times as many time points.
pub fn retime_multipliers(lambda: &[f64], l: usize, from: usize, to: usize) -> Vec<f64> {
    let f = to / from;
    let at = |n: usize| &lambda[(n.max(1) - 1) * l..n.max(1) * l];
    (1..=to)
        .flat_map(|m| {
            let (n, r) = (m / f, (m % f) as f64 / f as f64);
            let (a, b) = (at(n), at((n + 1).min(from)));
            (0..l).map(move |j| ((1.0 - r) * a[j] + r * b[j]) / f as f64)
        })
        .collect()
}

/// The AL schedule of a stage as it runs.
struct Schedule {
    al_iteration: usize,
    /// Set while in the coarse AL iterations.
    coarse: Option<CoarsePhase>,
    mu: f64,
    lambda: Vec<f64>,
    previous_violation: f64,
    previous_data: f64,
    previous_reported: f64,
    outcome: StageOutcome,
}

impl Schedule {
    /// The start of the schedule from `momenta` (in the stage's steps): `λ = 0` and `μ = μ₀`
    /// with constraints, no `λ` and `μ = 0` without; in the coarse steps of `coarse` when
    /// given. Returns it with the first iterate (`momenta` in the first minimisation's steps).
    fn new(
        stage: &Stage<'_>,
        schedule: &AlSchedule,
        coarse: Option<&Flow>,
        momenta: Vec<f64>,
    ) -> Result<(Self, Vec<f64>)> {
        let flow = coarse.unwrap_or(stage.flow);
        let (first, coarse) = match coarse {
            Some(c) => {
                let first = c.retimed_momenta(&momenta, stage.flow.time_steps())?;
                let phase = CoarsePhase {
                    steps: c.time_steps(),
                    fine_steps: stage.flow.time_steps(),
                    restart: momenta,
                };
                (first, Some(phase))
            }
            None => (momenta, None),
        };
        let (mu, lambda) = match stage.constraints {
            Some(c) => (schedule.mu, vec![0.0; flow.time_steps() * c.set.len()]),
            None => (0.0, Vec::new()),
        };
        let at = Self {
            al_iteration: 0,
            coarse,
            mu,
            lambda,
            previous_violation: f64::INFINITY,
            previous_data: f64::NAN,
            // Before the first AL iteration ends any violation is a decrease.
            previous_reported: f64::INFINITY,
            outcome: StageOutcome {
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
                settled: false,
                coarse_al_iterations: 0,
                strained_iterations: 0,
            },
        };
        Ok((at, first))
    }

    /// The schedule of a paused stage, checked against the stage (whose coarse flow, if any,
    /// is `coarse`).
    fn resumed(
        stage: &Stage<'_>,
        c: &StageCheckpoint,
        iterations: usize,
        coarse: Option<&Flow>,
    ) -> Result<Self> {
        let steps = c
            .coarse
            .as_ref()
            .map_or(stage.flow.time_steps(), |p| p.steps);
        let lambda_len = stage.constraints.map_or(0, |k| steps * k.set.len());
        let coarse_fits = c.coarse.as_ref().map_or(true, |p| {
            coarse.is_some_and(|f| f.time_steps() == p.steps)
                && p.fine_steps == stage.flow.time_steps()
        });
        if c.lambda.len() != lambda_len || c.al_iteration >= iterations || !coarse_fits {
            // `iterations` counts the extension's too: its last can be in progress.
            return Err(Error::InvalidParameter(format!(
                "the checkpoint does not fit the stage: AL iteration {} of {iterations}, {} \
                 multipliers for {lambda_len}, in {steps} time steps",
                c.al_iteration,
                c.lambda.len()
            )));
        }
        Ok(Self {
            al_iteration: c.al_iteration,
            coarse: c.coarse.clone(),
            mu: c.mu,
            lambda: c.lambda.clone(),
            previous_violation: c.previous_violation,
            previous_data: c.previous_data,
            previous_reported: c.previous_reported,
            outcome: c.done.clone(),
        })
    }

    /// Leaves the coarse steps in the middle of the minimisation `m`, whose flow strained
    /// space too far: `m` is dropped (its counters kept), and the AL iteration runs again in
    /// the stage's steps from where it started, momenta and `λ` carried to those steps.
    /// Returns the carried momenta.
    fn leave_coarse(&mut self, stage: &Stage<'_>, m: &MinimizerCheckpoint) -> Vec<f64> {
        let phase = self
            .coarse
            .take()
            .expect("only coarse minimisations are strained");
        self.outcome.iterations += m.iterations();
        self.outcome.evaluations += m.evaluations();
        self.outcome.restarts += m.restarts();
        self.outcome.strained_iterations += m.iterations();
        let l = lambda_count(stage);
        self.lambda = retime_multipliers(&self.lambda, l, phase.steps, phase.fine_steps);
        phase.restart
    }

    /// The checkpoint of the schedule paused in the minimisation `minimizer`.
    fn paused(self, guard_start: Option<f64>, minimizer: MinimizerCheckpoint) -> StageCheckpoint {
        StageCheckpoint {
            al_iteration: self.al_iteration,
            mu: self.mu,
            lambda: self.lambda,
            previous_violation: self.previous_violation,
            previous_data: self.previous_data,
            previous_reported: self.previous_reported,
            guard_start,
            coarse: self.coarse,
            done: self.outcome,
            minimizer,
        }
    }
}

/// Runs a stage from `start`: one minimisation without constraints, the AL schedule with them.
/// Every accepted iterate is checked ([`guard::check`] against the objective at the stage's
/// start); after a minimisation that needed a restart, `μ` grows by `√mu_factor` only. A
/// minimisation that ends unsound ends the stage ([`StageOutcome::unsound`]). `pause` is asked
/// after every accepted iterate whether to stop there ([`StageRun::Paused`]); the stage resumed
/// from that checkpoint ends with the very bits of a stage that never paused.
pub fn run_stage(
    stage: &Stage<'_>,
    schedule: &AlSchedule,
    options: &LbfgsOptions,
    start: StageStart,
    pause: &dyn Fn() -> bool,
    mut progress: impl FnMut(&Progress<'_>),
) -> Result<StageRun> {
    let (al_iterations, coarse) = match stage.constraints {
        Some(_) => {
            schedule.check()?;
            let extra = schedule.extend.map_or(0, |e| e.at_most);
            (
                schedule.iterations + extra,
                schedule.coarse_flow(stage.flow)?,
            )
        }
        None => (1, None),
    };
    let (mut at, guard_start, mut minimizer_start) = match start {
        StageStart::Momenta(momenta) => {
            let (at, first) = Schedule::new(stage, schedule, coarse.as_ref(), momenta)?;
            (at, None, Start::Momenta(first))
        }
        StageStart::Resume(c) => (
            Schedule::resumed(stage, &c, al_iterations, coarse.as_ref())?,
            c.guard_start,
            Start::Resume(Box::new(c.minimizer)),
        ),
    };
    let stage_start = Cell::new(guard_start);
    let check = |e: &Evaluation| {
        let start = stage_start.get().unwrap_or(e.total);
        stage_start.set(Some(start));
        guard::check(stage.guard, e, start)
    };
    loop {
        let (al_iteration, mu) = (at.al_iteration, at.mu);
        let flow = match (&at.coarse, &coarse) {
            (Some(_), Some(c)) => c,
            _ => stage.flow,
        };
        let objective = objective_of(stage, flow, mu, &at.lambda)?;
        let strained = Cell::new(false);
        let in_coarse = at.coarse.is_some();
        let report = |r: &IterationReport<'_>| {
            if in_coarse && r.iteration > 0 && r.iteration % STRAIN_CHECK_INTERVAL == 0 {
                strained.set(too_strained(flow, stage.initial, r.momenta));
            }
            progress(&Progress {
                al_iteration,
                mu,
                time_steps: flow.time_steps(),
                report: r,
            })
        };
        let options = match (al_iteration, schedule.first_iterations) {
            (0, Some(max_iterations)) => LbfgsOptions {
                max_iterations,
                ..*options
            },
            _ => *options,
        };
        let pause_or_strained = || strained.get() || pause();
        let min = match minimize(
            &objective,
            minimizer_start,
            &options,
            check,
            &pause_or_strained,
            report,
        )? {
            Minimization::Done(min) => min,
            Minimization::Paused(m) if strained.get() => {
                minimizer_start = Start::Momenta(at.leave_coarse(stage, &m));
                continue;
            }
            Minimization::Paused(m) => {
                return Ok(StageRun::Paused(Box::new(at.paused(stage_start.get(), *m))))
            }
        };
        let outcome = &mut at.outcome;
        outcome.iterations += min.iterations;
        outcome.evaluations += min.evaluations;
        outcome.al_iterations += 1;
        outcome.coarse_al_iterations += usize::from(at.coarse.is_some());
        outcome.restarts += min.restarts;
        outcome.evaluation = min.evaluation.clone();
        outcome.mu = mu;
        outcome.lambda.clone_from(&at.lambda);
        outcome.unsound = unsound_stop(al_iteration, &min);
        outcome.stops.push(min.stop);
        outcome.settled = al_iteration > 0
            && outcome.unsound.is_none()
            && (schedule.settle).is_some_and(|s| s.holds(&outcome.evaluation, at.previous_data));
        at.previous_data = outcome.evaluation.data;
        let coarse_settled = at.coarse.is_some() && outcome.settled;
        let violation = outcome.evaluation.max_abs_constraint;
        let scheduled = match stage.constraints {
            Some(_) => schedule.iterations,
            None => 1,
        };
        let reported = match (stage.constraints, schedule.extend) {
            (Some(c), Some(_)) => c.violation(&outcome.evaluation.final_positions),
            _ => f64::NAN,
        };
        let left = al_iterations - (al_iteration + 1);
        let extended = al_iteration + 1 >= scheduled
            && left > 0
            && schedule.extend.is_some_and(|e| {
                reported > e.above && Extend::on_course(at.previous_reported, reported, left)
            });
        at.previous_reported = reported;
        if outcome.unsound.is_some()
            || (outcome.settled && !coarse_settled)
            || (al_iteration + 1 >= scheduled && !extended)
        {
            at.outcome.momenta = min.momenta;
            if let Some(phase) = &at.coarse {
                // An unsound stop in coarse steps: its last sound iterate in the stage's steps.
                let (momenta, lambda) = (&at.outcome.momenta, &at.outcome.lambda);
                (at.outcome.momenta, at.outcome.lambda) =
                    phase.refined(momenta, lambda, lambda_count(stage));
            }
            return Ok(StageRun::Done(Box::new(at.outcome)));
        }
        let values = objective.constraint_values(&min.momenta)?;
        at.lambda
            .iter_mut()
            .zip(&values)
            .for_each(|(lam, c)| *lam -= mu * c);
        let grow = match schedule.mu_update {
            MuUpdate::Always => true,
            MuUpdate::IfNotHalved => violation > 0.5 * at.previous_violation,
        };
        at.previous_violation = violation;
        if grow {
            let factor = match min.restarts {
                0 => schedule.mu_factor,
                _ => schedule.mu_factor.sqrt(),
            };
            at.mu = (mu * factor).min(schedule.mu_max);
        }
        at.al_iteration += 1;
        let mut momenta = min.momenta;
        let leave =
            coarse_settled || Some(at.al_iteration) == schedule.coarse.map(|c| c.al_iterations);
        if let Some(phase) = &mut at.coarse {
            let (fine, fine_lambda) = phase.refined(&momenta, &at.lambda, lambda_count(stage));
            match leave {
                true => (momenta, at.lambda) = (fine, fine_lambda),
                false => phase.restart = fine,
            }
        }
        if leave {
            at.coarse = None;
        }
        minimizer_start = Start::Momenta(momenta);
    }
}

/// How often the coarse flow's step strain is checked, L-BFGS iterations.
pub const STRAIN_CHECK_INTERVAL: usize = 10;

/// Whether the flow under `u` from `q0` strains space past [`STRAIN_LIMIT`] in a step, where
/// coarse steps are left. Two fine steps of one coarse step's momenta differ from it by about
/// `dt²/4 · ∇v·v`, a fraction `strain/4` of the step, and the differences add up over the
/// steps. The anterior mitral leaflet, at σ = 0.37 mm, passes 0.5 at N = 5 within 10
/// iterations (1.01 at the end), and carried to N = 10 then violates its constraints at the new
/// time points by 13°; the automatic t001-sized fits stay at 0.17–0.47.
fn too_strained(flow: &Flow, q0: &[Vec3], u: &[f64]) -> bool {
    let strains = flow.shoot(q0, u).and_then(|t| flow.step_strains(&t, u));
    // A NaN strain counts as past the limit.
    strains.map_or(true, |s| s.iter().any(|x| x.is_nan() || *x > STRAIN_LIMIT))
}

/// The number of constraints of `stage` (0 without).
fn lambda_count(stage: &Stage<'_>) -> usize {
    stage.constraints.map_or(0, |c| c.set.len())
}

/// The objective of `stage` in `flow` (the stage's, or its coarse one) with the penalty `(μ, λ)`
/// when it has constraints.
fn objective_of<'a>(
    stage: &Stage<'a>,
    flow: &'a Flow,
    mu: f64,
    lambda: &'a [f64],
) -> Result<Objective<'a>> {
    let objective = Objective::new(flow, stage.initial, stage.attachment, stage.data_weight);
    match stage.constraints {
        Some(c) => objective.with_penalty(Penalty {
            constraints: c.set,
            mu,
            lambda,
        }),
        None => Ok(objective),
    }
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
