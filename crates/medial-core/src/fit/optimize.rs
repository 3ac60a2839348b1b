//! Minimisation of an [`Objective`] over all momenta with L-BFGS (argmin, More–Thuente line
//! search), driven iteration by iteration so that every iteration can be reported.
//!
//! Stopping rule, checked after every iteration, first that holds:
//! - `‖∇E‖ ≤ gradient_tolerance · max(‖∇E(u₀)‖, 1e-300)` (relative gradient norm),
//! - `E_{k−1} − E_k ≤ relative_decrease · max(|E_k|, |E_{k−1}|)` (stalled decrease),
//! - with a [`ProgressRule`], `E_{k−W} − E_k ≤ decrease · max(|E_k|, |E_{k−W}|)` (too little
//!   progress over the last `W` iterations: the budget follows the progress),
//! - `max_iterations` iterations done,
//! - the line search finds no decrease (the best point so far is kept),
//! - an iterate is unsound ([`crate::fit::guard`]) and no shorter step towards it is sound.

use crate::fit::guard::Unsound;
use crate::fit::lbfgs_vector::LbfgsVector;
use crate::fit::objective::{Evaluation, Objective};
use crate::{Error, Result};
use argmin::core::{CostFunction, Gradient, IterState, Problem, Solver, State, TerminationStatus};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::quasinewton::LBFGS;
use serde::{Deserialize, Serialize};
use std::sync::Mutex;

/// Options of [`minimize`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LbfgsOptions {
    /// Maximum number of L-BFGS iterations.
    pub max_iterations: usize,
    /// Number of correction pairs kept.
    pub memory: usize,
    /// Stop when the gradient norm falls below this fraction of its initial value.
    pub gradient_tolerance: f64,
    /// Stop when an iteration decreases the objective by less than this fraction of it.
    pub relative_decrease: f64,
    /// Stop when the last iterations together decreased it too little (none: only the
    /// other rules).
    pub progress: Option<ProgressRule>,
    /// Most restarts after an unsound iterate ([`MAX_RESTARTS`] by default); past them an
    /// unsound iterate ends the minimisation (0: the first one does, as a trial that only
    /// needs to know whether a start folds wants; [`crate::fit::trial`]).
    pub max_restarts: usize,
}

/// The progress rule of [`LbfgsOptions`]: stop at iteration `k ≥ window` when
/// `E_{k−window} − E_k ≤ decrease · max(|E_k|, |E_{k−window}|)`. With a generous
/// `max_iterations` it gives each minimisation the iterations it makes progress with: a slow
/// fit (a thin sheet) goes on, one that has settled stops.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProgressRule {
    /// `W ≥ 1`, iterations.
    pub window: usize,
    /// The least relative decrease over `W` iterations that goes on.
    pub decrease: f64,
}

impl Default for LbfgsOptions {
    fn default() -> Self {
        Self {
            max_iterations: 1000,
            memory: 10,
            gradient_tolerance: 1e-6,
            relative_decrease: 1e-9,
            progress: None,
            max_restarts: MAX_RESTARTS,
        }
    }
}

/// Why the minimisation stopped.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum StopReason {
    /// The relative gradient norm criterion holds.
    GradientTolerance,
    /// The objective stopped decreasing.
    RelativeDecrease,
    /// The objective decreased too little over the window of the [`ProgressRule`].
    Progress,
    /// The iteration budget is spent.
    MaxIterations,
    /// The line search found no acceptable step; the message says why.
    LineSearch(String),
    /// An iterate was unsound and no shorter step towards it was sound and lower (or the
    /// restarts ran out, or a restart made no progress). The minimum is the last sound iterate.
    Unsound(Unsound),
    /// Paused at a checkpoint before a stopping rule held (in the figures of a paused fit).
    Paused,
}

impl StopReason {
    /// Whether the stop is a convergence criterion (gradient or decrease), not a budget, a
    /// failed line search or an unsound iterate.
    pub fn converged(&self) -> bool {
        matches!(
            self,
            StopReason::GradientTolerance | StopReason::RelativeDecrease | StopReason::Progress
        )
    }
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StopReason::GradientTolerance => write!(f, "gradient norm below tolerance"),
            StopReason::RelativeDecrease => write!(f, "relative decrease below tolerance"),
            StopReason::Progress => write!(f, "too little progress over the last iterations"),
            StopReason::MaxIterations => write!(f, "maximum number of iterations"),
            StopReason::LineSearch(why) => write!(f, "line search stopped: {why}"),
            StopReason::Unsound(why) => write!(f, "unsound iterate: {why}"),
            StopReason::Paused => write!(f, "paused at a checkpoint"),
        }
    }
}

/// What is known after an iteration (iteration 0 is the starting point).
#[derive(Clone, Copy, Debug)]
pub struct IterationReport<'a> {
    /// Iteration number.
    pub iteration: usize,
    /// Value + gradient evaluations so far.
    pub evaluations: usize,
    /// The figures at the current iterate.
    pub evaluation: &'a Evaluation,
    /// `‖∇E‖` at the current iterate.
    pub gradient_norm: f64,
    /// The current momenta.
    pub momenta: &'a [f64],
}

/// The outcome of [`minimize`].
#[derive(Clone, Debug)]
pub struct Minimum {
    /// The momenta at the last accepted sound iterate.
    pub momenta: Vec<f64>,
    /// Its figures.
    pub evaluation: Evaluation,
    /// `‖∇E‖` there.
    pub gradient_norm: f64,
    /// Iterations accepted.
    pub iterations: usize,
    /// Value + gradient evaluations done.
    pub evaluations: usize,
    /// Restarts of L-BFGS with fresh memory after an unsound iterate.
    pub restarts: usize,
    /// Why it stopped.
    pub stop: StopReason,
}

/// The last accepted sound iterate of a minimisation.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Sound {
    momenta: Vec<f64>,
    evaluation: Evaluation,
    gradient_norm: f64,
    iteration: usize,
    /// `E` at every accepted iterate `0 ..= iteration` (the progress rule).
    totals: Vec<f64>,
}

impl Sound {
    /// Whether the [`ProgressRule`] holds at the current iterate.
    fn stalled(&self, progress: Option<ProgressRule>) -> bool {
        let Some(ProgressRule { window, decrease }) = progress else {
            return false;
        };
        let Some(k) = self.iteration.checked_sub(window.max(1)) else {
            return false;
        };
        let (past, now) = (self.totals[k], self.evaluation.total);
        past - now <= decrease * past.abs().max(now.abs())
    }
}

/// Where a minimisation starts.
pub enum Start {
    /// From these momenta (iteration 0 is reported).
    Momenta(Vec<f64>),
    /// Where a paused minimisation stopped (nothing is reported again).
    Resume(Box<MinimizerCheckpoint>),
}

/// How [`minimize`] ended.
pub enum Minimization {
    /// A stopping rule holds.
    Done(Minimum),
    /// `pause` asked for a stop after an accepted iterate: everything needed to go on.
    Paused(Box<MinimizerCheckpoint>),
}

/// The momenta as L-BFGS sees them: vectors whose algebra runs on the thread pool, the same
/// bits for any thread count ([`LbfgsVector`]).
type Params = LbfgsVector;

/// The L-BFGS solver as argmin holds it: its correction pairs and its line search.
type Lbfgs = LBFGS<MoreThuenteLineSearch<Params, Params, f64>, Params, Params, f64>;

/// argmin's state of an L-BFGS run (iterate, gradient, cost, counters).
type LbfgsState = IterState<Params, Params, (), (), (), f64>;

/// A run of L-BFGS with one memory, between two iterations.
#[derive(Clone, Serialize, Deserialize)]
struct Segment {
    solver: Lbfgs,
    state: LbfgsState,
    /// `E` at the iterate before the last accepted one (the relative-decrease rule).
    previous: f64,
}

/// A minimisation paused after an accepted iterate: the iterate with its evaluation and
/// gradient (what the evaluation cache held), the counters, the restart bookkeeping and the
/// L-BFGS memory, so that [`minimize`] from [`Start::Resume`] goes on to the same bits as a run
/// that was never paused.
#[derive(Clone, Serialize, Deserialize)]
pub struct MinimizerCheckpoint {
    sound: Sound,
    /// `∇E` at the sound iterate.
    gradient: Vec<f64>,
    evaluations: usize,
    /// `‖∇E(u₀)‖` of the minimisation (the relative gradient rule).
    initial_gradient_norm: f64,
    restarts: usize,
    stalled: bool,
    /// The iteration at which the current L-BFGS segment started.
    segment_start: usize,
    segment: Segment,
}

impl MinimizerCheckpoint {
    /// The momenta of the last accepted iterate.
    pub fn momenta(&self) -> &[f64] {
        &self.sound.momenta
    }

    /// Its figures.
    pub fn evaluation(&self) -> &Evaluation {
        &self.sound.evaluation
    }

    /// Iterations accepted so far.
    pub fn iterations(&self) -> usize {
        self.sound.iteration
    }

    /// Value + gradient evaluations so far.
    pub fn evaluations(&self) -> usize {
        self.evaluations
    }

    /// Restarts so far.
    pub fn restarts(&self) -> usize {
        self.restarts
    }
}

/// The state of a minimisation between segments of L-BFGS.
struct Run {
    sound: Sound,
    initial_gradient_norm: f64,
    restarts: usize,
    stalled: bool,
}

/// Minimises `objective` from `start`, calling `report` after every accepted iterate (and once
/// at a fresh start, iteration 0). Every accepted iterate must pass `check`
/// ([`crate::fit::guard::check`]). One that does not is replaced by the first sound point
/// `s + 2⁻ʲ (u − s)`, `j = 1 … 20`, below the last sound iterate `s`, and L-BFGS restarts there with fresh memory; so does a line search whose
/// trial point cannot be evaluated, from the last sound iterate. The minimisation ends with
/// [`StopReason::Unsound`] at the last sound iterate when no shorter step is sound, when two
/// restarts in a row make no progress, or after [`LbfgsOptions::max_restarts`]. A start that cannot be
/// evaluated is an error; an unsound start ends at once.
///
/// After every accepted iterate at which no stopping rule holds, `pause` is asked whether to
/// stop there: if it says so, the minimisation returns [`Minimization::Paused`], and
/// [`Start::Resume`] with it continues to the very bits of a run that never paused.
pub fn minimize(
    objective: &Objective<'_>,
    start: Start,
    options: &LbfgsOptions,
    check: impl Fn(&Evaluation) -> Result<(), Unsound>,
    pause: &dyn Fn() -> bool,
    mut report: impl FnMut(&IterationReport<'_>),
) -> Result<Minimization> {
    let cached = Cached::new(objective);
    let (mut run, mut segment, mut segment_start) = match start {
        Start::Momenta(momenta) => match fresh(&cached, momenta, &check, &mut report)? {
            Ok(run) => (run, None, 0),
            Err(unsound_start) => return Ok(Minimization::Done(unsound_start)),
        },
        Start::Resume(checkpoint) => {
            let c = *checkpoint;
            check_length(objective, &c.sound.momenta)?;
            cached.restore(&c.sound, c.gradient, c.evaluations);
            let run = Run {
                sound: c.sound,
                initial_gradient_norm: c.initial_gradient_norm,
                restarts: c.restarts,
                stalled: c.stalled,
            };
            (run, Some(c.segment), c.segment_start)
        }
    };
    let stop = loop {
        let resumed = segment.take();
        if resumed.is_none() {
            segment_start = run.sound.iteration;
        }
        let grad0 = run.initial_gradient_norm;
        let end = lbfgs(
            &cached,
            &mut run.sound,
            options,
            grad0,
            resumed,
            &check,
            pause,
            &mut report,
        )?;
        match end {
            SegmentEnd::Restart(cause) => {
                let progressed = run.sound.iteration != segment_start;
                if (!progressed && run.stalled) || run.restarts >= options.max_restarts {
                    break StopReason::Unsound(cause);
                }
                run.stalled = !progressed;
                run.restarts += 1;
            }
            SegmentEnd::Stop(stop) => break stop,
            SegmentEnd::Paused(segment) => {
                let (gradient, evaluations) = cached.gradient_and_count();
                return Ok(Minimization::Paused(Box::new(MinimizerCheckpoint {
                    gradient,
                    evaluations,
                    initial_gradient_norm: run.initial_gradient_norm,
                    restarts: run.restarts,
                    stalled: run.stalled,
                    segment_start,
                    segment: *segment,
                    sound: run.sound,
                })));
            }
        }
    };
    Ok(Minimization::Done(Minimum {
        momenta: run.sound.momenta,
        evaluation: run.sound.evaluation,
        gradient_norm: run.sound.gradient_norm,
        iterations: run.sound.iteration,
        evaluations: cached.count(),
        restarts: run.restarts,
        stop,
    }))
}

/// `u` has the length of the objective's momenta.
fn check_length(objective: &Objective<'_>, u: &[f64]) -> Result<()> {
    if u.len() == objective.dimension() {
        Ok(())
    } else {
        Err(Error::ShapeMismatch {
            what: "initial momenta".into(),
            expected: objective.dimension(),
            found: u.len(),
        })
    }
}

/// Evaluates and checks the start `momenta` and reports it as iteration 0; an unsound start is
/// `Err`: the minimisation ended there.
fn fresh(
    cached: &Cached<'_, '_>,
    momenta: Vec<f64>,
    check: &impl Fn(&Evaluation) -> Result<(), Unsound>,
    report: &mut impl FnMut(&IterationReport<'_>),
) -> Result<std::result::Result<Run, Minimum>> {
    check_length(cached.objective, &momenta)?;
    cached.ensure(&momenta)?;
    let (evaluation, grad0) = cached.current();
    if let Err(cause) = check(&evaluation) {
        return Ok(Err(Minimum {
            momenta,
            evaluation,
            gradient_norm: grad0,
            iterations: 0,
            evaluations: cached.count(),
            restarts: 0,
            stop: StopReason::Unsound(cause),
        }));
    }
    report(&IterationReport {
        iteration: 0,
        evaluations: cached.count(),
        evaluation: &evaluation,
        gradient_norm: grad0,
        momenta: &momenta,
    });
    Ok(Ok(Run {
        sound: Sound {
            totals: vec![evaluation.total],
            momenta,
            evaluation,
            gradient_norm: grad0,
            iteration: 0,
        },
        initial_gradient_norm: grad0,
        restarts: 0,
        stalled: false,
    }))
}

/// How a run of L-BFGS with one memory ended.
enum SegmentEnd {
    /// A stopping rule holds.
    Stop(StopReason),
    /// An iterate was unsound: after a shorter step towards it (when one was sound and lower),
    /// L-BFGS starts again with fresh memory from `sound`.
    Restart(Unsound),
    /// `pause` asked for a stop after an accepted iterate.
    Paused(Box<Segment>),
}

/// The default of [`LbfgsOptions::max_restarts`]: most restarts of L-BFGS in one minimisation;
/// past them an unsound iterate ends it.
pub const MAX_RESTARTS: usize = 100;

/// Halvings of the step towards an unsound iterate tried before giving up on it.
const BACKOFF_HALVINGS: usize = 20;

/// L-BFGS from the sound iterate `sound`, with fresh memory (or from the paused `resumed`
/// segment), until a stopping rule holds, an iterate is unsound or `pause` asks for a stop;
/// `sound` follows every accepted sound iterate. An unsound iterate `u` is
/// replaced, when possible, by the first sound point `s + 2⁻ʲ (u − s)`, `j = 1 …`
/// [`BACKOFF_HALVINGS`], below the last sound iterate `s` (accepted and reported as the next
/// iterate) before L-BFGS restarts.
#[allow(clippy::too_many_arguments)]
fn lbfgs(
    cached: &Cached<'_, '_>,
    sound: &mut Sound,
    options: &LbfgsOptions,
    grad0: f64,
    resumed: Option<Segment>,
    check: &impl Fn(&Evaluation) -> Result<(), Unsound>,
    pause: &dyn Fn() -> bool,
    report: &mut impl FnMut(&IterationReport<'_>),
) -> Result<SegmentEnd> {
    if grad0 == 0.0 {
        return Ok(SegmentEnd::Stop(StopReason::GradientTolerance));
    }
    let unsound_trial = |e: argmin::core::Error| {
        SegmentEnd::Restart(Unsound::Evaluation(cached.error_or(e).to_string()))
    };
    let mut problem = Problem::new(cached);
    let Segment {
        mut solver,
        mut state,
        mut previous,
    } = match resumed {
        Some(segment) => segment,
        None => match start_segment(&mut problem, sound, options)? {
            Ok(segment) => segment,
            Err(e) => return Ok(unsound_trial(e)),
        },
    };
    loop {
        if sound.iteration >= options.max_iterations {
            return Ok(SegmentEnd::Stop(StopReason::MaxIterations));
        }
        if let TerminationStatus::Terminated(reason) =
            Solver::<&Cached, _>::terminate_internal(&mut solver, &state)
        {
            if !matches!(reason, argmin::core::TerminationReason::MaxItersReached) {
                return Ok(SegmentEnd::Stop(StopReason::LineSearch(reason.to_string())));
            }
        }
        state = match solver.next_iter(&mut problem, state) {
            Ok((next, _)) => next,
            Err(e) => return Ok(unsound_trial(e)),
        };
        state.update();
        if let TerminationStatus::Terminated(reason) = state.get_termination_status() {
            return Ok(SegmentEnd::Stop(StopReason::LineSearch(reason.to_string())));
        }
        state.increment_iter();
        let param = state
            .get_param()
            .ok_or_else(|| Error::Optimisation("L-BFGS lost its iterate".into()))?;
        let param = param.as_slice();
        let verdict = cached
            .ensure(param)
            .map_err(|e| Unsound::Evaluation(e.to_string()))
            .and_then(|()| check(&cached.current().0));
        if let Err(cause) = verdict {
            if back_off(cached, sound, param, check, report) {
                return Ok(SegmentEnd::Restart(cause));
            }
            return Ok(SegmentEnd::Stop(StopReason::Unsound(cause)));
        }
        let (evaluation, gradient_norm) = cached.current();
        accept(cached, sound, param, evaluation, gradient_norm, report);
        if gradient_norm <= options.gradient_tolerance * grad0 {
            return Ok(SegmentEnd::Stop(StopReason::GradientTolerance));
        }
        let total = sound.evaluation.total;
        let scale = total.abs().max(previous.abs());
        if previous - total <= options.relative_decrease * scale {
            return Ok(SegmentEnd::Stop(StopReason::RelativeDecrease));
        }
        if sound.stalled(options.progress) {
            return Ok(SegmentEnd::Stop(StopReason::Progress));
        }
        previous = total;
        if pause() {
            return Ok(SegmentEnd::Paused(Box::new(Segment {
                solver,
                state,
                previous,
            })));
        }
    }
}

/// A fresh L-BFGS solver and state at the sound iterate (`Err` from argmin when the start
/// cannot be evaluated).
fn start_segment(
    problem: &mut Problem<&Cached<'_, '_>>,
    sound: &Sound,
    options: &LbfgsOptions,
) -> Result<std::result::Result<Segment, argmin::core::Error>> {
    let mut solver = LBFGS::new(MoreThuenteLineSearch::new(), options.memory.max(1))
        .with_tolerance_grad(0.0)
        .and_then(|s| s.with_tolerance_cost(0.0))
        .map_err(|e| Error::Optimisation(e.to_string()))?;
    let state = IterState::new()
        .param(Params::from_slice(&sound.momenta))
        .max_iters((options.max_iterations - sound.iteration) as u64);
    Ok(solver.init(problem, state).map(|(mut state, _)| {
        state.update();
        Segment {
            solver,
            state,
            previous: sound.evaluation.total,
        }
    }))
}

/// Makes `u` the sound iterate and reports it.
fn accept(
    cached: &Cached<'_, '_>,
    sound: &mut Sound,
    u: &[f64],
    evaluation: Evaluation,
    gradient_norm: f64,
    report: &mut impl FnMut(&IterationReport<'_>),
) {
    sound.momenta.clear();
    sound.momenta.extend_from_slice(u);
    sound.iteration += 1;
    sound.gradient_norm = gradient_norm;
    report(&IterationReport {
        iteration: sound.iteration,
        evaluations: cached.count(),
        evaluation: &evaluation,
        gradient_norm,
        momenta: u,
    });
    sound.totals.push(evaluation.total);
    sound.evaluation = evaluation;
}

/// Tries shorter steps from the sound iterate towards the refused iterate `u`; accepts the
/// first sound one below the sound iterate's objective. Whether one was found.
fn back_off(
    cached: &Cached<'_, '_>,
    sound: &mut Sound,
    u: &[f64],
    check: &impl Fn(&Evaluation) -> Result<(), Unsound>,
    report: &mut impl FnMut(&IterationReport<'_>),
) -> bool {
    let mut t = 1.0;
    for _ in 0..BACKOFF_HALVINGS {
        t *= 0.5;
        let trial: Vec<f64> = sound
            .momenta
            .iter()
            .zip(u)
            .map(|(s, x)| s + t * (x - s))
            .collect();
        if cached.ensure(&trial).is_err() {
            continue;
        }
        let (evaluation, gradient_norm) = cached.current();
        if check(&evaluation).is_ok() && evaluation.total < sound.evaluation.total {
            accept(cached, sound, &trial, evaluation, gradient_norm, report);
            return true;
        }
    }
    false
}

/// The objective with its last value and gradient remembered: argmin asks for the cost and the
/// gradient at the same point separately, and the two come from one evaluation.
struct Cached<'o, 'a> {
    objective: &'o Objective<'a>,
    last: Mutex<Last>,
}

#[derive(Default)]
struct Last {
    momenta: Vec<f64>,
    evaluation: Evaluation,
    gradient: Vec<f64>,
    count: usize,
    failure: Option<String>,
}

impl<'o, 'a> Cached<'o, 'a> {
    fn new(objective: &'o Objective<'a>) -> Self {
        Self {
            objective,
            last: Mutex::new(Last::default()),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Last> {
        self.last
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Evaluates at `u` unless that is the remembered point.
    fn ensure(&self, u: &[f64]) -> Result<()> {
        let mut last = self.lock();
        if last.count > 0 && last.momenta == u {
            return Ok(());
        }
        let mut gradient = vec![0.0; u.len()];
        match self.objective.evaluate(u, Some(&mut gradient)) {
            Ok(evaluation) => {
                last.momenta.clear();
                last.momenta.extend_from_slice(u);
                last.evaluation = evaluation;
                last.gradient = gradient;
                last.count += 1;
                last.failure = None;
                Ok(())
            }
            Err(e) => {
                last.failure = Some(e.to_string());
                Err(e)
            }
        }
    }

    /// Remembers `sound` with its gradient after `count` evaluations, as the cache held them
    /// when a minimisation paused there.
    fn restore(&self, sound: &Sound, gradient: Vec<f64>, count: usize) {
        let mut last = self.lock();
        last.momenta.clone_from(&sound.momenta);
        last.evaluation = sound.evaluation.clone();
        last.gradient = gradient;
        last.count = count;
    }

    fn current(&self) -> (Evaluation, f64) {
        let last = self.lock();
        (
            last.evaluation.clone(),
            last.gradient.iter().map(|g| g * g).sum::<f64>().sqrt(),
        )
    }

    fn count(&self) -> usize {
        self.lock().count
    }

    /// The remembered gradient and the number of evaluations.
    fn gradient_and_count(&self) -> (Vec<f64>, usize) {
        let last = self.lock();
        (last.gradient.clone(), last.count)
    }

    /// The engine's own error if an evaluation failed, else argmin's.
    fn error_or(&self, e: argmin::core::Error) -> Error {
        let failure = self.lock().failure.take();
        Error::Optimisation(failure.unwrap_or_else(|| e.to_string()))
    }
}

impl CostFunction for &Cached<'_, '_> {
    type Param = Params;
    type Output = f64;
    fn cost(&self, u: &Params) -> std::result::Result<f64, argmin::core::Error> {
        self.ensure(u.as_slice())
            .map_err(|e| argmin::core::Error::msg(e.to_string()))?;
        Ok(self.lock().evaluation.total)
    }
}

impl Gradient for &Cached<'_, '_> {
    type Param = Params;
    type Gradient = Params;
    fn gradient(&self, u: &Params) -> std::result::Result<Params, argmin::core::Error> {
        self.ensure(u.as_slice())
            .map_err(|e| argmin::core::Error::msg(e.to_string()))?;
        Ok(Params::from_slice(&self.lock().gradient))
    }
}
