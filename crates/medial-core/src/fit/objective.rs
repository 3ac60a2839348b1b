//! The objective of one stage (docs/method.md §3.5):
//! `E_AL = w_kin·KE + w_data·g(q^N) + Σ_{n=1..N} Σ_l [ (μ/2) C_l(q^n)² − λ^n_l C_l(q^n) ]`,
//! its exact gradient with respect to every momentum `u^n` (one forward and one fused backward
//! pass), and the figures reported for it.

use crate::attachment::Attachment;
use crate::flow::{Flow, Trajectory};
use crate::{Error, Result, Vec3};
use serde::{Deserialize, Serialize};

/// A set of equality constraints `C(q) = 0` on the landmark configuration.
pub trait ConstraintSet: Sync {
    /// Number of constraints `L`.
    fn len(&self) -> usize;
    /// No constraints.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// `C(q)` into `out` (length `L`).
    fn evaluate(&self, q: &[Vec3], out: &mut [f64]);
    /// `grad += Σ_l weights_l ∇C_l(q)`.
    fn accumulate_gradient(&self, q: &[Vec3], weights: &[f64], grad: &mut [Vec3]);
}

impl ConstraintSet for crate::model::constraints::MedialConstraints {
    fn len(&self) -> usize {
        self.len()
    }
    fn evaluate(&self, q: &[Vec3], out: &mut [f64]) {
        self.evaluate(q, out)
    }
    fn accumulate_gradient(&self, q: &[Vec3], weights: &[f64], grad: &mut [Vec3]) {
        self.accumulate_gradient(q, weights, grad)
    }
}

/// The augmented-Lagrangian penalty: constraints, `μ`, and multipliers `λ^n_l` stored
/// time point after time point (`lambda[(n−1)·L + l]`, `n = 1 … N`).
#[derive(Clone, Copy)]
pub struct Penalty<'a> {
    /// The constraints.
    pub constraints: &'a dyn ConstraintSet,
    /// Penalty weight `μ`.
    pub mu: f64,
    /// Multipliers, `N·L` numbers.
    pub lambda: &'a [f64],
}

/// The figures of one evaluation. `kinetic` and `data` are unweighted.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    /// `E_AL`.
    pub total: f64,
    /// `KE` (unweighted).
    pub kinetic: f64,
    /// `g(q^N)` (unweighted).
    pub data: f64,
    /// The penalty term `P`.
    pub penalty: f64,
    /// `max_{n,l} |C_l(q^n)|` over `n = 1 … N`.
    pub max_abs_constraint: f64,
    /// The Dice coefficient when the attachment estimates one.
    pub dice: Option<f64>,
    /// The landmarks at the end of the flow, `q^N`.
    pub final_positions: Vec<Vec3>,
}

/// One stage's objective over the momenta `u` (flat, `N·k·3`).
pub struct Objective<'a> {
    flow: &'a Flow,
    initial: &'a [Vec3],
    attachment: &'a dyn Attachment,
    data_weight: f64,
    penalty: Option<Penalty<'a>>,
}

impl<'a> Objective<'a> {
    /// `w_kin·KE + w_data·g`, without constraints.
    pub fn new(
        flow: &'a Flow,
        initial: &'a [Vec3],
        attachment: &'a dyn Attachment,
        data_weight: f64,
    ) -> Self {
        Self {
            flow,
            initial,
            attachment,
            data_weight,
            penalty: None,
        }
    }

    /// Adds the augmented-Lagrangian penalty.
    pub fn with_penalty(mut self, penalty: Penalty<'a>) -> Result<Self> {
        let expected = self.flow.time_steps() * penalty.constraints.len();
        if penalty.lambda.len() != expected {
            return Err(Error::ShapeMismatch {
                what: "multipliers (N·L)".into(),
                expected,
                found: penalty.lambda.len(),
            });
        }
        self.penalty = Some(penalty);
        Ok(self)
    }

    /// The flow.
    pub fn flow(&self) -> &Flow {
        self.flow
    }

    /// The landmarks at `t = 0`, `q^0`.
    pub fn initial(&self) -> &[Vec3] {
        self.initial
    }

    /// Number of unknowns `N·k·3`.
    pub fn dimension(&self) -> usize {
        self.flow.momenta_len()
    }

    /// The value and, if `grad` is given, the exact gradient `∂E_AL/∂u`.
    pub fn evaluate(&self, u: &[f64], grad: Option<&mut [f64]>) -> Result<Evaluation> {
        let trajectory = self.flow.shoot(self.initial, u)?;
        let k = self.initial.len();
        let q_final = trajectory.final_positions();
        let mut terminal = vec![Vec3::zeros(); k];
        let data = self
            .attachment
            .evaluate(q_final, grad.is_some().then_some(&mut terminal[..]))?;
        terminal.iter_mut().for_each(|g| *g *= self.data_weight);
        let constraint_values = self.constraint_values_of(&trajectory);
        let (penalty, max_abs_constraint) = self.penalty_value(&constraint_values);
        let total = self.flow.kinetic_weight() * trajectory.kinetic_energy()
            + self.data_weight * data.value
            + penalty;
        if !total.is_finite() {
            return Err(Error::NonFinite(format!("objective is {total}")));
        }
        if let Some(grad) = grad {
            let weights = self.penalty_weights(&constraint_values);
            let n_steps = self.flow.time_steps();
            self.add_penalty_gradient(n_steps, q_final, &weights, &mut terminal);
            self.flow.backward(
                &trajectory,
                u,
                &terminal,
                |n, q, a| self.add_penalty_gradient(n, q, &weights, a),
                grad,
            )?;
        }
        Ok(Evaluation {
            total,
            kinetic: trajectory.kinetic_energy(),
            data: data.value,
            penalty,
            max_abs_constraint,
            dice: data.dice,
            final_positions: q_final.to_vec(),
        })
    }

    /// Constraint values at time points `1 … N` under the momenta `u` (`N·L` numbers), for
    /// the multiplier update; empty without a penalty.
    pub fn constraint_values(&self, u: &[f64]) -> Result<Vec<f64>> {
        Ok(self.constraint_values_of(&self.flow.shoot(self.initial, u)?))
    }

    fn constraint_values_of(&self, trajectory: &Trajectory) -> Vec<f64> {
        let Some(p) = &self.penalty else {
            return Vec::new();
        };
        let l = p.constraints.len();
        let mut values = vec![0.0; self.flow.time_steps() * l];
        for (n, out) in (1..).zip(values.chunks_exact_mut(l.max(1))) {
            p.constraints.evaluate(trajectory.positions(n), out);
        }
        values
    }

    /// `(P, max |C|)`.
    fn penalty_value(&self, values: &[f64]) -> (f64, f64) {
        let Some(p) = &self.penalty else {
            return (0.0, 0.0);
        };
        let value = values
            .iter()
            .zip(p.lambda)
            .map(|(c, lam)| 0.5 * p.mu * c * c - lam * c)
            .sum();
        (value, values.iter().fold(0.0f64, |m, c| m.max(c.abs())))
    }

    /// `∂P/∂C^n_l = μ C^n_l − λ^n_l` for every time point and constraint (empty without a
    /// penalty).
    fn penalty_weights(&self, values: &[f64]) -> Vec<f64> {
        let Some(p) = &self.penalty else {
            return Vec::new();
        };
        values
            .iter()
            .zip(p.lambda)
            .map(|(c, lam)| p.mu * c - lam)
            .collect()
    }

    /// `a += Σ_l (μ C^n_l − λ^n_l) ∇C_l(q^n)`, with the weights of [`Self::penalty_weights`].
    fn add_penalty_gradient(&self, n: usize, q: &[Vec3], weights: &[f64], a: &mut [Vec3]) {
        let Some(p) = &self.penalty else { return };
        let l = p.constraints.len();
        p.constraints
            .accumulate_gradient(q, &weights[(n - 1) * l..n * l], a);
    }
}
