//! Minimisation of an [`Objective`] over all momenta with L-BFGS (argmin, More–Thuente line
//! search), driven iteration by iteration so that every iteration can be reported.
//!
//! Stopping rule, checked after every iteration, first that holds:
//! - `‖∇E‖ ≤ gradient_tolerance · max(‖∇E(u₀)‖, 1e-300)` (relative gradient norm),
//! - `E_{k−1} − E_k ≤ relative_decrease · max(|E_k|, |E_{k−1}|)` (stalled decrease),
//! - `max_iterations` iterations done,
//! - the line search finds no decrease (the best point so far is kept),
//! - an iterate is unsound ([`crate::fit::guard`]) and no shorter step towards it is sound.

use crate::fit::guard::Unsound;
use crate::fit::objective::{Evaluation, Objective};
use crate::{Error, Result};
use argmin::core::{CostFunction, Gradient, IterState, Problem, Solver, State, TerminationStatus};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::quasinewton::LBFGS;
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
}

impl Default for LbfgsOptions {
    fn default() -> Self {
        Self {
            max_iterations: 1000,
            memory: 10,
            gradient_tolerance: 1e-6,
            relative_decrease: 1e-9,
        }
    }
}

/// Why the minimisation stopped.
#[derive(Clone, Debug, PartialEq)]
pub enum StopReason {
    /// The relative gradient norm criterion holds.
    GradientTolerance,
    /// The objective stopped decreasing.
    RelativeDecrease,
    /// The iteration budget is spent.
    MaxIterations,
    /// The line search found no acceptable step; the message says why.
    LineSearch(String),
    /// An iterate was unsound and no shorter step towards it was sound and lower (or the
    /// restarts ran out, or a restart made no progress). The minimum is the last sound iterate.
    Unsound(Unsound),
}

impl StopReason {
    /// Whether the stop is a convergence criterion (gradient or decrease), not a budget, a
    /// failed line search or an unsound iterate.
    pub fn converged(&self) -> bool {
        matches!(
            self,
            StopReason::GradientTolerance | StopReason::RelativeDecrease
        )
    }
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StopReason::GradientTolerance => write!(f, "gradient norm below tolerance"),
            StopReason::RelativeDecrease => write!(f, "relative decrease below tolerance"),
            StopReason::MaxIterations => write!(f, "maximum number of iterations"),
            StopReason::LineSearch(why) => write!(f, "line search stopped: {why}"),
            StopReason::Unsound(why) => write!(f, "unsound iterate: {why}"),
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
struct Sound {
    momenta: Vec<f64>,
    evaluation: Evaluation,
    gradient_norm: f64,
    iteration: usize,
}

/// Minimises `objective` from `start`, calling `report` after every accepted iterate (and once
/// at the start, iteration 0). Every accepted iterate must pass `check`
/// ([`crate::fit::guard::check`]). One that does not is replaced by the first sound point
/// `s + 2⁻ʲ (u − s)`, `j = 1 … 20`, below the last sound iterate `s`, and L-BFGS restarts there with fresh memory; so does a line search whose
/// trial point cannot be evaluated, from the last sound iterate. The minimisation ends with
/// [`StopReason::Unsound`] at the last sound iterate when no shorter step is sound, when two
/// restarts in a row make no progress, or after [`MAX_RESTARTS`]. A start that cannot be
/// evaluated is an error; an unsound start ends at once.
pub fn minimize(
    objective: &Objective<'_>,
    start: Vec<f64>,
    options: &LbfgsOptions,
    check: impl Fn(&Evaluation) -> Result<(), Unsound>,
    mut report: impl FnMut(&IterationReport<'_>),
) -> Result<Minimum> {
    if start.len() != objective.dimension() {
        return Err(Error::ShapeMismatch {
            what: "initial momenta".into(),
            expected: objective.dimension(),
            found: start.len(),
        });
    }
    let cached = Cached::new(objective);
    cached.ensure(&start)?;
    let (evaluation, grad0) = cached.current();
    let mut sound = Sound {
        momenta: start,
        evaluation,
        gradient_norm: grad0,
        iteration: 0,
    };
    let (mut restarts, mut stalled) = (0, false);
    let stop = match check(&sound.evaluation) {
        Err(cause) => StopReason::Unsound(cause),
        Ok(()) => {
            report(&IterationReport {
                iteration: 0,
                evaluations: cached.count(),
                evaluation: &sound.evaluation,
                gradient_norm: grad0,
                momenta: &sound.momenta,
            });
            loop {
                let before = sound.iteration;
                match lbfgs(&cached, &mut sound, options, grad0, &check, &mut report)? {
                    Segment::Restart(cause) => {
                        let stuck = sound.iteration == before && stalled;
                        if stuck || restarts == MAX_RESTARTS {
                            break StopReason::Unsound(cause);
                        }
                        stalled = sound.iteration == before;
                        restarts += 1;
                    }
                    Segment::Stop(stop) => break stop,
                }
            }
        }
    };
    Ok(Minimum {
        momenta: sound.momenta,
        evaluation: sound.evaluation,
        gradient_norm: sound.gradient_norm,
        iterations: sound.iteration,
        evaluations: cached.count(),
        restarts,
        stop,
    })
}

/// How a run of L-BFGS with one memory ended.
enum Segment {
    /// A stopping rule holds.
    Stop(StopReason),
    /// An iterate was unsound: after a shorter step towards it (when one was sound and lower),
    /// L-BFGS starts again with fresh memory from `sound`.
    Restart(Unsound),
}

/// Most restarts of L-BFGS in one minimisation; past them an unsound iterate ends it.
pub const MAX_RESTARTS: usize = 100;

/// Halvings of the step towards an unsound iterate tried before giving up on it.
const BACKOFF_HALVINGS: usize = 20;

/// L-BFGS from the sound iterate `sound`, with fresh memory, until a stopping rule holds or an
/// iterate is unsound; `sound` follows every accepted sound iterate. An unsound iterate `u` is
/// replaced, when possible, by the first sound point `s + 2⁻ʲ (u − s)`, `j = 1 …`
/// [`BACKOFF_HALVINGS`], below the last sound iterate `s` (accepted and reported as the next
/// iterate) before L-BFGS restarts.
fn lbfgs(
    cached: &Cached<'_, '_>,
    sound: &mut Sound,
    options: &LbfgsOptions,
    grad0: f64,
    check: &impl Fn(&Evaluation) -> Result<(), Unsound>,
    report: &mut impl FnMut(&IterationReport<'_>),
) -> Result<Segment> {
    if grad0 == 0.0 {
        return Ok(Segment::Stop(StopReason::GradientTolerance));
    }
    let unsound_trial = |e: argmin::core::Error| {
        Segment::Restart(Unsound::Evaluation(cached.error_or(e).to_string()))
    };
    let mut problem = Problem::new(cached);
    let mut solver = LBFGS::new(MoreThuenteLineSearch::new(), options.memory.max(1))
        .with_tolerance_grad(0.0)
        .and_then(|s| s.with_tolerance_cost(0.0))
        .map_err(|e| Error::Optimisation(e.to_string()))?;
    let state = IterState::new()
        .param(sound.momenta.clone())
        .max_iters((options.max_iterations - sound.iteration) as u64);
    let mut state = match solver.init(&mut problem, state) {
        Ok((state, _)) => state,
        Err(e) => return Ok(unsound_trial(e)),
    };
    state.update();
    let mut previous = sound.evaluation.total;
    loop {
        if sound.iteration >= options.max_iterations {
            return Ok(Segment::Stop(StopReason::MaxIterations));
        }
        if let TerminationStatus::Terminated(reason) =
            Solver::<&Cached, _>::terminate_internal(&mut solver, &state)
        {
            if !matches!(reason, argmin::core::TerminationReason::MaxItersReached) {
                return Ok(Segment::Stop(StopReason::LineSearch(reason.to_string())));
            }
        }
        state = match solver.next_iter(&mut problem, state) {
            Ok((next, _)) => next,
            Err(e) => return Ok(unsound_trial(e)),
        };
        state.update();
        if let TerminationStatus::Terminated(reason) = state.get_termination_status() {
            return Ok(Segment::Stop(StopReason::LineSearch(reason.to_string())));
        }
        state.increment_iter();
        let param = state
            .get_param()
            .ok_or_else(|| Error::Optimisation("L-BFGS lost its iterate".into()))?;
        let verdict = cached
            .ensure(param)
            .map_err(|e| Unsound::Evaluation(e.to_string()))
            .and_then(|()| check(&cached.current().0));
        if let Err(cause) = verdict {
            if back_off(cached, sound, param, check, report) {
                return Ok(Segment::Restart(cause));
            }
            return Ok(Segment::Stop(StopReason::Unsound(cause)));
        }
        let (evaluation, gradient_norm) = cached.current();
        accept(cached, sound, param, evaluation, gradient_norm, report);
        if gradient_norm <= options.gradient_tolerance * grad0 {
            return Ok(Segment::Stop(StopReason::GradientTolerance));
        }
        let total = sound.evaluation.total;
        let scale = total.abs().max(previous.abs());
        if previous - total <= options.relative_decrease * scale {
            return Ok(Segment::Stop(StopReason::RelativeDecrease));
        }
        previous = total;
    }
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
                Ok(())
            }
            Err(e) => {
                last.failure = Some(e.to_string());
                Err(e)
            }
        }
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

    /// The engine's own error if an evaluation failed, else argmin's.
    fn error_or(&self, e: argmin::core::Error) -> Error {
        let failure = self.lock().failure.take();
        Error::Optimisation(failure.unwrap_or_else(|| e.to_string()))
    }
}

impl CostFunction for &Cached<'_, '_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, u: &Vec<f64>) -> std::result::Result<f64, argmin::core::Error> {
        self.ensure(u)
            .map_err(|e| argmin::core::Error::msg(e.to_string()))?;
        Ok(self.lock().evaluation.total)
    }
}

impl Gradient for &Cached<'_, '_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;
    fn gradient(&self, u: &Vec<f64>) -> std::result::Result<Vec<f64>, argmin::core::Error> {
        self.ensure(u)
            .map_err(|e| argmin::core::Error::msg(e.to_string()))?;
        Ok(self.lock().gradient.clone())
    }
}
