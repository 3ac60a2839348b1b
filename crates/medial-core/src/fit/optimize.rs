//! Minimisation of an [`Objective`] over all momenta with L-BFGS (argmin, More–Thuente line
//! search), driven iteration by iteration so that every iteration can be reported.
//!
//! Stopping rule, checked after every iteration, first that holds:
//! - `‖∇E‖ ≤ gradient_tolerance · max(‖∇E(u₀)‖, 1e-300)` (relative gradient norm),
//! - `E_{k−1} − E_k ≤ relative_decrease · max(|E_k|, |E_{k−1}|)` (stalled decrease),
//! - `max_iterations` iterations done,
//! - the line search finds no decrease (the best point so far is kept).

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
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum StopReason {
    /// The relative gradient norm criterion holds.
    GradientTolerance,
    /// The objective stopped decreasing.
    RelativeDecrease,
    /// The iteration budget is spent.
    MaxIterations,
    /// The line search found no acceptable step; the message says why.
    LineSearch(String),
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StopReason::GradientTolerance => write!(f, "gradient norm below tolerance"),
            StopReason::RelativeDecrease => write!(f, "relative decrease below tolerance"),
            StopReason::MaxIterations => write!(f, "maximum number of iterations"),
            StopReason::LineSearch(why) => write!(f, "line search stopped: {why}"),
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
    /// The momenta at the last accepted iterate.
    pub momenta: Vec<f64>,
    /// Its figures.
    pub evaluation: Evaluation,
    /// `‖∇E‖` there.
    pub gradient_norm: f64,
    /// Iterations done.
    pub iterations: usize,
    /// Value + gradient evaluations done.
    pub evaluations: usize,
    /// Why it stopped.
    pub stop: StopReason,
}

/// Minimises `objective` from `start`, calling `report` after every iteration (and once at the
/// start, iteration 0).
pub fn minimize(
    objective: &Objective<'_>,
    start: Vec<f64>,
    options: &LbfgsOptions,
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
    let mut problem = Problem::new(&cached);
    let mut solver = LBFGS::new(MoreThuenteLineSearch::new(), options.memory.max(1))
        .with_tolerance_grad(0.0)
        .and_then(|s| s.with_tolerance_cost(0.0))
        .map_err(|e| Error::Optimisation(e.to_string()))?;
    let state = IterState::new()
        .param(start)
        .max_iters(options.max_iterations as u64);
    let (mut state, _) = solver
        .init(&mut problem, state)
        .map_err(|e| cached.error_or(e))?;
    state.update();
    let (first, grad0) = cached.current();
    report(&IterationReport {
        iteration: 0,
        evaluations: cached.count(),
        evaluation: &first,
        gradient_norm: grad0,
        momenta: state.get_param().map_or(&[], |p| p.as_slice()),
    });
    let mut iteration = 0;
    let mut previous = first.total;
    let stop = loop {
        if grad0 == 0.0 {
            break StopReason::GradientTolerance;
        }
        if iteration >= options.max_iterations {
            break StopReason::MaxIterations;
        }
        if let TerminationStatus::Terminated(reason) =
            Solver::<&Cached, _>::terminate_internal(&mut solver, &state)
        {
            if !matches!(reason, argmin::core::TerminationReason::MaxItersReached) {
                break StopReason::LineSearch(reason.to_string());
            }
        }
        let (next, _) = solver
            .next_iter(&mut problem, state)
            .map_err(|e| cached.error_or(e))?;
        state = next;
        state.update();
        if let TerminationStatus::Terminated(reason) = state.get_termination_status() {
            break StopReason::LineSearch(reason.to_string());
        }
        iteration += 1;
        state.increment_iter();
        let param = state
            .get_param()
            .ok_or_else(|| Error::Optimisation("L-BFGS lost its iterate".into()))?;
        cached.ensure(param)?;
        let (evaluation, gradient_norm) = cached.current();
        report(&IterationReport {
            iteration,
            evaluations: cached.count(),
            evaluation: &evaluation,
            gradient_norm,
            momenta: param,
        });
        if gradient_norm <= options.gradient_tolerance * grad0 {
            break StopReason::GradientTolerance;
        }
        let scale = evaluation.total.abs().max(previous.abs());
        if previous - evaluation.total <= options.relative_decrease * scale {
            break StopReason::RelativeDecrease;
        }
        previous = evaluation.total;
    };
    let momenta = state
        .take_param()
        .ok_or_else(|| Error::Optimisation("L-BFGS lost its iterate".into()))?;
    cached.ensure(&momenta)?;
    let (evaluation, gradient_norm) = cached.current();
    Ok(Minimum {
        momenta,
        evaluation,
        gradient_norm,
        iterations: iteration,
        evaluations: cached.count(),
        stop,
    })
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
