//! The landmark flow (forward Euler) and its exact discrete adjoint (SPEC §3).
//!
//! Controls `u^n ∈ R^{k×3}`, `n = 0 … N−1`, are stored flat as `u[(n·k + i)·3 + c]`.
//!
//! - Flow: `q^{n+1}_i = q^n_i + dt Σ_j K^n_ij u^n_j`, `dt = 1/N`.
//! - Kinetic energy: `KE = (dt/2) Σ_n Σ_ij K^n_ij (u^n_i · u^n_j)`.
//! - Adjoint, from `a^N = ∂E/∂q^N`, for `n = N−1 … 0`:
//!   `a^n_i = a^{n+1}_i + ∇P^n_i − (dt/σ²) Σ_j K^n_ij [a^{n+1}_i·u^n_j + a^{n+1}_j·u^n_i + w u^n_i·u^n_j] (q^n_i − q^n_j)`,
//!   and `∂E/∂u^n_i = dt Σ_j K^n_ij (a^{n+1}_j + w u^n_j)`.
//!
//! Each pass is row-parallel (rayon) with a fixed summation order inside a row, so results are
//! bit-identical whatever the thread count. Kernel matrices are kept from the forward pass for
//! the backward pass when they fit in [`Flow::cache_budget`]; otherwise the backward pass
//! recomputes them, still with one exponential per unordered pair.

use crate::kernel::{GaussianKernel, KernelMatrix, Soa3, ROW_CHUNK};
use crate::{Error, Result, Vec3};
use rayon::prelude::*;

/// Lanes of the explicit multi-accumulator sums (lets the compiler use SIMD registers while
/// keeping a fixed order of additions).
const LANES: usize = 4;

/// Parameters of the flow.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FlowParams {
    /// Kernel width σ, in the unit of the coordinates (mm).
    pub sigma: f64,
    /// Number of time steps `N` (`dt = 1/N`).
    pub time_steps: usize,
    /// Weight `w_kin` of the kinetic energy in the objective.
    pub kinetic_weight: f64,
}

/// A discretised flow of `k` landmarks.
#[derive(Clone, Debug)]
pub struct Flow {
    kernel: GaussianKernel,
    steps: usize,
    kinetic_weight: f64,
    landmarks: usize,
    cache_budget: usize,
}

/// What the forward pass leaves for the backward pass and for reporting.
#[derive(Clone, Debug)]
pub struct Trajectory {
    positions: Vec<Soa3>,
    kernels: Vec<KernelMatrix>,
    kinetic: f64,
}

impl Trajectory {
    /// Number of time points, `N + 1`.
    pub fn time_points(&self) -> usize {
        self.positions.len()
    }

    /// Landmark positions `q^n`.
    pub fn positions(&self, n: usize) -> Vec<Vec3> {
        self.positions[n].to_points()
    }

    /// Landmark positions `q^N`.
    pub fn final_positions(&self) -> Vec<Vec3> {
        self.positions(self.positions.len() - 1)
    }

    /// The unweighted kinetic energy `KE`.
    pub fn kinetic_energy(&self) -> f64 {
        self.kinetic
    }
}

impl Flow {
    /// Default memory allowed for keeping kernel matrices between the passes: 2 GiB.
    pub const DEFAULT_CACHE_BUDGET: usize = 2 << 30;

    /// A flow of `landmarks` points.
    pub fn new(params: FlowParams, landmarks: usize) -> Result<Self> {
        let kernel = GaussianKernel::new(params.sigma)?;
        if params.time_steps == 0 {
            return Err(Error::InvalidParameter("time_steps must be at least 1".into()));
        }
        if !(params.kinetic_weight.is_finite() && params.kinetic_weight >= 0.0) {
            return Err(Error::InvalidParameter(format!(
                "kinetic_weight must be a non-negative number, got {}",
                params.kinetic_weight
            )));
        }
        Ok(Self {
            kernel,
            steps: params.time_steps,
            kinetic_weight: params.kinetic_weight,
            landmarks,
            cache_budget: Self::DEFAULT_CACHE_BUDGET,
        })
    }

    /// Sets the memory (bytes) allowed for keeping the `N` kernel matrices between passes.
    pub fn with_cache_budget(mut self, bytes: usize) -> Self {
        self.cache_budget = bytes;
        self
    }

    /// Memory (bytes) allowed for keeping kernel matrices between passes.
    pub fn cache_budget(&self) -> usize {
        self.cache_budget
    }

    /// The kernel.
    pub fn kernel(&self) -> &GaussianKernel {
        &self.kernel
    }

    /// `N`.
    pub fn time_steps(&self) -> usize {
        self.steps
    }

    /// `dt = 1/N`.
    pub fn dt(&self) -> f64 {
        1.0 / self.steps as f64
    }

    /// `w_kin`.
    pub fn kinetic_weight(&self) -> f64 {
        self.kinetic_weight
    }

    /// `k`.
    pub fn landmarks(&self) -> usize {
        self.landmarks
    }

    /// Length of a control vector: `N·k·3`.
    pub fn control_len(&self) -> usize {
        self.steps * self.landmarks * 3
    }

    fn keeps_kernels(&self) -> bool {
        KernelMatrix::bytes_for(self.landmarks).saturating_mul(self.steps) <= self.cache_budget
    }

    fn step_controls(&self, u: &[f64], n: usize) -> Soa3 {
        let k3 = self.landmarks * 3;
        Soa3::from_flat(&u[n * k3..(n + 1) * k3])
    }

    /// Checks the sizes of a template and a control vector.
    pub fn check_sizes(&self, q0: &[Vec3], u: &[f64]) -> Result<()> {
        if q0.len() != self.landmarks {
            return Err(Error::ShapeMismatch {
                what: "landmarks".into(),
                expected: self.landmarks,
                found: q0.len(),
            });
        }
        if u.len() != self.control_len() {
            return Err(Error::ShapeMismatch {
                what: "controls (N·k·3 numbers)".into(),
                expected: self.control_len(),
                found: u.len(),
            });
        }
        Ok(())
    }

    /// The forward pass from the template `q0` under the controls `u`.
    pub fn shoot(&self, q0: &[Vec3], u: &[f64]) -> Result<Trajectory> {
        self.check_sizes(q0, u)?;
        let k = self.landmarks;
        let dt = self.dt();
        let keep = self.keeps_kernels();
        let mut positions = Vec::with_capacity(self.steps + 1);
        positions.push(Soa3::from_points(q0));
        let mut kernels = Vec::with_capacity(if keep { self.steps } else { 0 });
        let mut scratch = KernelMatrix::default();
        let mut kinetic = 0.0;
        for n in 0..self.steps {
            let un = self.step_controls(u, n);
            let q = &positions[n];
            let kmat = if keep {
                kernels.push(KernelMatrix::default());
                kernels.last_mut().expect("just pushed")
            } else {
                &mut scratch
            };
            kmat.fill(&self.kernel, q);
            let v = velocity(kmat, &un);
            let mut next = q.clone();
            let mut step_ke = 0.0;
            for i in 0..k {
                let vi = v.get(i);
                step_ke += un.get(i).dot(&vi);
                next.set(i, q.get(i) + dt * vi);
            }
            kinetic += 0.5 * dt * step_ke;
            positions.push(next);
        }
        if positions.last().is_some_and(|q| !q.x.iter().chain(&q.y).chain(&q.z).all(|c| c.is_finite())) {
            return Err(Error::NonFinite("the flow diverged: non-finite landmark positions".into()));
        }
        Ok(Trajectory { positions, kernels, kinetic })
    }

    /// The backward pass: the gradient `∂E/∂u` (written to `grad`, length `N·k·3`) of
    /// `E = w_kin·KE + Φ(q^1, …, q^N)` given `∂Φ/∂q^N` (`terminal`) and a callback that adds
    /// `∂Φ/∂q^n` to the adjoint for `n = N−1 … 1` (called once per time point, in that order).
    pub fn backward(
        &self,
        trajectory: &Trajectory,
        u: &[f64],
        terminal: &[Vec3],
        mut add_state_gradient: impl FnMut(usize, &[Vec3], &mut [Vec3]),
        grad: &mut [f64],
    ) -> Result<()> {
        self.check_sizes(terminal, u)?;
        if grad.len() != u.len() {
            return Err(Error::ShapeMismatch {
                what: "gradient buffer".into(),
                expected: u.len(),
                found: grad.len(),
            });
        }
        let k3 = self.landmarks * 3;
        let mut adjoint = Soa3::from_points(terminal);
        let mut scratch = KernelMatrix::default();
        for n in (0..self.steps).rev() {
            let q = &trajectory.positions[n];
            let kmat = match trajectory.kernels.get(n) {
                Some(cached) => cached,
                None => {
                    scratch.fill(&self.kernel, q);
                    &scratch
                }
            };
            let un = self.step_controls(u, n);
            let step = self.adjoint_step(kmat, q, &un, &adjoint);
            for (g, i) in grad[n * k3..(n + 1) * k3].chunks_exact_mut(3).zip(0..) {
                g.copy_from_slice(step.grad.get(i).as_slice());
            }
            adjoint = step.adjoint;
            if n > 0 {
                let qn = q.to_points();
                let mut a = adjoint.to_points();
                add_state_gradient(n, &qn, &mut a);
                adjoint = Soa3::from_points(&a);
            }
        }
        Ok(())
    }

    /// One fused backward step over all rows: gradient of step `n` and the adjoint `a^n`
    /// (before adding `∇P^n`).
    fn adjoint_step(&self, kmat: &KernelMatrix, q: &Soa3, u: &Soa3, a: &Soa3) -> AdjointStep {
        let k = self.landmarks;
        let dt = self.dt();
        let w = self.kinetic_weight;
        let c = dt / (self.kernel.sigma() * self.kernel.sigma());
        let mut grad = Soa3::zeros(k);
        let mut next = Soa3::zeros(k);
        let rows: Vec<(Vec3, Vec3)> = (0..k)
            .into_par_iter()
            .with_min_len(ROW_CHUNK)
            .map(|i| {
                let (g, r) = adjoint_row(kmat.row(i), i, q, u, a, w);
                (dt * g, a.get(i) - c * r)
            })
            .collect();
        for (i, (g, an)) in rows.into_iter().enumerate() {
            grad.set(i, g);
            next.set(i, an);
        }
        AdjointStep { grad, adjoint: next }
    }
}

struct AdjointStep {
    grad: Soa3,
    adjoint: Soa3,
}

/// `v_i = Σ_j K_ij u_j` for every row, in parallel.
fn velocity(kmat: &KernelMatrix, u: &Soa3) -> Soa3 {
    let k = u.len();
    let rows: Vec<Vec3> =
        (0..k).into_par_iter().with_min_len(ROW_CHUNK).map(|i| velocity_row(kmat.row(i), u)).collect();
    Soa3::from_points(&rows)
}

/// `Σ_j K_ij u_j` for one row, with `LANES` independent accumulators per coordinate.
#[inline]
fn velocity_row(row: &[f64], u: &Soa3) -> Vec3 {
    let mut acc = [[0.0f64; LANES]; 3];
    let n = row.len() / LANES * LANES;
    for (((kc, xc), yc), zc) in row[..n]
        .chunks_exact(LANES)
        .zip(u.x[..n].chunks_exact(LANES))
        .zip(u.y[..n].chunks_exact(LANES))
        .zip(u.z[..n].chunks_exact(LANES))
    {
        for l in 0..LANES {
            acc[0][l] += kc[l] * xc[l];
            acc[1][l] += kc[l] * yc[l];
            acc[2][l] += kc[l] * zc[l];
        }
    }
    let mut v = Vec3::new(lane_sum(&acc[0]), lane_sum(&acc[1]), lane_sum(&acc[2]));
    for j in n..row.len() {
        v += row[j] * u.get(j);
    }
    v
}

/// For row `i`: `(Σ_j K_ij (a_j + w u_j), Σ_j K_ij s_ij (q_i − q_j))` with
/// `s_ij = a_i·u_j + a_j·u_i + w u_i·u_j`.
#[inline]
fn adjoint_row(row: &[f64], i: usize, q: &Soa3, u: &Soa3, a: &Soa3, w: f64) -> (Vec3, Vec3) {
    let (qi, ui, ai) = (q.get(i), u.get(i), a.get(i));
    // g: 3 sums, r: 3 sums, each in LANES accumulators. Differences q_i − q_j are formed per
    // pair (not q_i Σ K s − Σ K s q_j) to avoid cancellation far from the origin.
    let mut acc = [[0.0f64; LANES]; 6];
    let pair = |j: usize, acc: &mut [[f64; LANES]; 6], l: usize| {
        let kij = row[j];
        let (ux, uy, uz) = (u.x[j], u.y[j], u.z[j]);
        let (ax, ay, az) = (a.x[j], a.y[j], a.z[j]);
        acc[0][l] += kij * (ax + w * ux);
        acc[1][l] += kij * (ay + w * uy);
        acc[2][l] += kij * (az + w * uz);
        let s = ai.x * ux + ai.y * uy + ai.z * uz + ax * ui.x + ay * ui.y + az * ui.z
            + w * (ui.x * ux + ui.y * uy + ui.z * uz);
        let ks = kij * s;
        acc[3][l] += ks * (qi.x - q.x[j]);
        acc[4][l] += ks * (qi.y - q.y[j]);
        acc[5][l] += ks * (qi.z - q.z[j]);
    };
    let n = row.len() / LANES * LANES;
    for base in (0..n).step_by(LANES) {
        for l in 0..LANES {
            pair(base + l, &mut acc, l);
        }
    }
    for j in n..row.len() {
        pair(j, &mut acc, 0);
    }
    let sum = |c: usize| lane_sum(&acc[c]);
    let g = Vec3::new(sum(0), sum(1), sum(2));
    let r = Vec3::new(sum(3), sum(4), sum(5));
    (g, r)
}

/// Sum of lanes in a fixed order.
#[inline]
fn lane_sum(lanes: &[f64; LANES]) -> f64 {
    (lanes[0] + lanes[1]) + (lanes[2] + lanes[3])
}
