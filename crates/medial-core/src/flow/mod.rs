//! The landmark flow (forward Euler) and its exact discrete adjoint (docs/method.md §3.3–§3.5).
//!
//! Momenta `u^n ∈ R^{k×3}`, `n = 0 … N−1`, are stored flat as `u[(n·k + i)·3 + c]`.
//!
//! - Flow: `q^{n+1}_i = q^n_i + dt Σ_j K^n_ij u^n_j`, `dt = 1/N`.
//! - Kinetic energy: `KE = (dt/2) Σ_n Σ_ij K^n_ij (u^n_i · u^n_j)`.
//! - Adjoint, from `a^N = ∂E/∂q^N`, for `n = N−1 … 0`:
//!   `a^n_i = a^{n+1}_i + ∇P^n_i − (dt/σ²) Σ_j K^n_ij [a^{n+1}_i·u^n_j + a^{n+1}_j·u^n_i + w u^n_i·u^n_j] (q^n_i − q^n_j)`,
//!   and `∂E/∂u^n_i = dt Σ_j K^n_ij (a^{n+1}_j + w u^n_j)`.
//!
//! Each step of each pass is one fused sweep over the pairs (see [`crate::flow::kernel`]): one kernel
//! evaluation per unordered pair, in parallel tiles whose partial sums are reduced in a fixed
//! order, so results are bit-identical whatever the thread count. Forward, a point carries
//! `(q, u)` and the sweep sums `K_ij u_j`; backward, it carries `(q, u, a, b = a + w u)` and the
//! sweep sums `K_ij b_j` and `K_ij s_ij (q_i − q_j)` with `s_ij = a_i·u_j + u_i·b_j`.
//!
//! With a kernel tolerance ε > 0 ([`Flow::with_kernel_tolerance`]) each sweep skips pairs
//! farther apart than `r = σ √(2 ln(1/ε))`, whose kernel value is below ε, chosen from the
//! positions `q^n` of the step: the forward and the backward pass skip the same pairs, and the
//! gradient is the exact gradient of the truncated objective (wherever no pair crosses the
//! cut). Per step and point the sums err by at most `ε Σ_j |u^n_j|` (velocity, per coordinate),
//! `ε Σ_j |b_j|` (gradient) and `ε r Σ_j |s_ij|` (adjoint update), and `KE` by at most
//! `(dt/2) ε Σ_i |u^n_i| Σ_j |u^n_j|` per step.
//!
//! The backward pass evaluates the kernel again rather than reading back values stored by the
//! forward pass: `N·k²/2` stored numbers do not stay in the CPU caches, and moving them through
//! memory was measured slower than the vectorised exponential, even for k = 100.
//!
//! [`ambient`] carries any point of space by the same rule: the fitted flow `φ₁` and its inverse.

pub mod ambient;
pub mod kernel;

use crate::flow::kernel::{F64Lanes, GaussianKernel, Layout, PairSweep, PairTerms, LANES};
use crate::{Error, Result, Vec3};

/// The step strain `dt · max_i ‖∇v^n(q^n_i)‖` ([`Flow::step_strains`]) up to which a step
/// counts as resolved: a step is one-to-one while its strain is below 1 (checked at the
/// landmarks only), half of that leaves a margin for the field between them. A fit warns past
/// it, and coarse time steps are left past it (`fit::augmented_lagrangian`).
pub const STRAIN_LIMIT: f64 = 0.5;

/// Momenta of `k` landmarks in `from` time steps (`u[(n·k + i)·3 + c]`) carried to `to` steps,
/// the control piecewise constant in time: into `to = f·from` steps each step's momenta are
/// repeated `f` times (each coarse step's velocity field held over its `f` fine steps: to first
/// order in `dt` the same trajectory and kinetic energy); into `to = from/f` steps each `f`
/// consecutive steps are averaged. Errors when neither step count divides the other or `u` is
/// not `from·k·3` numbers.
pub fn retime_momenta(u: &[f64], k: usize, from: usize, to: usize) -> Result<Vec<f64>> {
    let k3 = k * 3;
    if u.len() != from * k3 {
        return Err(Error::ShapeMismatch {
            what: "momenta (N·k·3 numbers) to retime".into(),
            expected: from * k3,
            found: u.len(),
        });
    }
    let divides = |a: usize, b: usize| a > 0 && b > 0 && b % a == 0;
    if divides(from, to) {
        let f = to / from;
        Ok(u.chunks_exact(k3.max(1))
            .flat_map(|step| std::iter::repeat(step).take(f).flatten().copied())
            .collect())
    } else if divides(to, from) {
        let f = from / to;
        let mut out = vec![0.0; to * k3];
        for (n, step) in u.chunks_exact(k3.max(1)).enumerate() {
            let target = &mut out[(n / f) * k3..(n / f + 1) * k3];
            target.iter_mut().zip(step).for_each(|(o, x)| *o += x);
        }
        out.iter_mut().for_each(|o| *o /= f as f64);
        Ok(out)
    } else {
        Err(Error::InvalidParameter(format!(
            "momenta in {from} time steps cannot be carried to {to}: one count must divide the other"
        )))
    }
}

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
}

/// What the forward pass leaves for the backward pass and for reporting.
#[derive(Clone, Debug)]
pub struct Trajectory {
    /// `q^n`, `n = 0 … N`.
    positions: Vec<Vec<Vec3>>,
    kinetic: f64,
    /// The layout of each step's sweep, `n = 0 … N−1` (it depends on `q^n` only), which the
    /// backward pass and [`Flow::step_strains`] sweep in again, and the kernel's cutoff radius
    /// it was made for.
    layouts: Vec<Layout>,
    cutoff: f64,
}

impl Trajectory {
    /// Number of time points, `N + 1`.
    pub fn time_points(&self) -> usize {
        self.positions.len()
    }

    /// Landmark positions `q^n`.
    pub fn positions(&self, n: usize) -> &[Vec3] {
        &self.positions[n]
    }

    /// Landmark positions `q^N`.
    pub fn final_positions(&self) -> &[Vec3] {
        self.positions(self.positions.len() - 1)
    }

    /// The unweighted kinetic energy `KE`.
    pub fn kinetic_energy(&self) -> f64 {
        self.kinetic
    }
}

impl Flow {
    /// A flow of `landmarks` points.
    pub fn new(params: FlowParams, landmarks: usize) -> Result<Self> {
        let kernel = GaussianKernel::new(params.sigma)?;
        if params.time_steps == 0 {
            return Err(Error::InvalidParameter(
                "time_steps must be at least 1".into(),
            ));
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
        })
    }

    /// The flow with its kernel truncated at the tolerance `ε` ([`GaussianKernel::truncated`];
    /// 0: exact): pairs whose kernel value is below ε are skipped (see the module
    /// documentation for the bounds on the errors).
    pub fn with_kernel_tolerance(mut self, tolerance: f64) -> Result<Self> {
        self.kernel = self.kernel.truncated(tolerance)?;
        Ok(self)
    }

    /// The same flow in `time_steps` steps (σ, `w_kin` and the kernel tolerance kept).
    pub fn with_time_steps(&self, time_steps: usize) -> Result<Self> {
        if time_steps == 0 {
            return Err(Error::InvalidParameter(
                "time_steps must be at least 1".into(),
            ));
        }
        Ok(Self {
            steps: time_steps,
            ..self.clone()
        })
    }

    /// Momenta `u` of this flow's landmarks in `from` time steps carried to this flow's `N`
    /// steps ([`retime_momenta`]).
    pub fn retimed_momenta(&self, u: &[f64], from: usize) -> Result<Vec<f64>> {
        retime_momenta(u, self.landmarks, from, self.steps)
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

    /// Length of a momentum vector: `N·k·3`.
    pub fn momenta_len(&self) -> usize {
        self.steps * self.landmarks * 3
    }

    /// The momenta `u^n` within the flat momentum vector.
    pub(crate) fn step_controls<'u>(&self, u: &'u [f64], n: usize) -> &'u [f64] {
        let k3 = self.landmarks * 3;
        &u[n * k3..(n + 1) * k3]
    }

    /// Checks the sizes of a template and a momentum vector.
    pub fn check_sizes(&self, q0: &[Vec3], u: &[f64]) -> Result<()> {
        if q0.len() != self.landmarks {
            return Err(Error::ShapeMismatch {
                what: "landmarks".into(),
                expected: self.landmarks,
                found: q0.len(),
            });
        }
        if u.len() != self.momenta_len() {
            return Err(Error::ShapeMismatch {
                what: "momenta (N·k·3 numbers)".into(),
                expected: self.momenta_len(),
                found: u.len(),
            });
        }
        Ok(())
    }

    /// The forward pass from the template `q0` under the momenta `u`.
    pub fn shoot(&self, q0: &[Vec3], u: &[f64]) -> Result<Trajectory> {
        self.check_sizes(q0, u)?;
        // On a worker thread of the pool, each step's parallel sweep starts without handing the
        // work over to the pool and waiting for it (two thread switches per step).
        rayon::scope(|_| self.forward_steps(q0, u))
    }

    /// The strain of each step of `trajectory` (the forward pass of `u`):
    /// `dt · max_i ‖∇v^n(q^n_i)‖_F`, `n = 0 … N−1`, with `∇v^n(x) = −(1/σ²) Σ_j K(x, q^n_j)
    /// (x − q^n_j) u^nᵀ_j` the gradient of the step's velocity field at each landmark
    /// (Frobenius norm, at least the spectral one). A step `x ↦ x + dt v^n(x)` is one-to-one
    /// while `dt · sup_x ‖∇v^n(x)‖ < 1` (a contraction argument: two points that met would
    /// have moved apart by more than they were apart); the landmarks, where the momenta are,
    /// are where the field varies most. One fused sweep per step, as in the forward pass
    /// (truncated with the flow's kernel tolerance), the same bits for any thread count.
    pub fn step_strains(&self, trajectory: &Trajectory, u: &[f64]) -> Result<Vec<f64>> {
        self.check_sizes(trajectory.positions(0), u)?;
        self.check_trajectory(trajectory)?;
        let scale = self.dt() / (self.kernel.sigma() * self.kernel.sigma());
        Ok(rayon::scope(|_| {
            let mut sweep = PairSweep::new(&self.kernel, self.landmarks);
            (0..self.steps)
                .map(|n| {
                    load(
                        &mut sweep,
                        trajectory.positions(n),
                        self.step_controls(u, n),
                    );
                    sweep.run_laid_out(&StrainTerms, &trajectory.layouts[n]);
                    // The largest, NaN if any is (`f64::max` would drop it).
                    let largest = (0..self.landmarks)
                        .map(|i| sweep.sums(i).iter().map(|s| s * s).sum::<f64>().sqrt())
                        .fold(0.0, |m, x| if x.is_nan() || x > m { x } else { m });
                    scale * largest
                })
                .collect()
        }))
    }

    /// The steps of [`Flow::shoot`].
    fn forward_steps(&self, q0: &[Vec3], u: &[f64]) -> Result<Trajectory> {
        let dt = self.dt();
        let mut sweep = PairSweep::new(&self.kernel, self.landmarks);
        let mut positions = Vec::with_capacity(self.steps + 1);
        let mut layouts = Vec::with_capacity(self.steps);
        positions.push(q0.to_vec());
        let mut kinetic = 0.0;
        for n in 0..self.steps {
            let (q, un) = (&positions[n], self.step_controls(u, n));
            load(&mut sweep, q, un);
            sweep.run(&VelocityTerms);
            layouts.push(sweep.layout().clone());
            let mut step_ke = 0.0;
            let next = (q.iter().zip(un.chunks_exact(3)).enumerate())
                .map(|(i, (qi, ui))| {
                    // v_i = u_i (the pair i = j) + Σ_{j≠i} K_ij u_j.
                    let ui = Vec3::from_column_slice(ui);
                    let vi = ui + Vec3::from(sweep.sums(i));
                    step_ke += ui.dot(&vi);
                    qi + dt * vi
                })
                .collect();
            kinetic += 0.5 * dt * step_ke;
            positions.push(next);
        }
        if positions
            .last()
            .is_some_and(|q| !q.iter().all(|p| p.iter().all(|c| c.is_finite())))
        {
            return Err(Error::NonFinite(
                "the flow diverged: non-finite landmark positions".into(),
            ));
        }
        Ok(Trajectory {
            positions,
            kinetic,
            layouts,
            cutoff: self.kernel.cutoff_radius(),
        })
    }

    /// The backward pass: the gradient `∂E/∂u` (written to `grad`, length `N·k·3`) of
    /// `E = w_kin·KE + Φ(q^1, …, q^N)` given `∂Φ/∂q^N` (`terminal`) and a callback that adds
    /// `∂Φ/∂q^n` to the adjoint for `n = N−1 … 1` (called once per time point, in that order,
    /// on a thread of the rayon pool).
    pub fn backward(
        &self,
        trajectory: &Trajectory,
        u: &[f64],
        terminal: &[Vec3],
        add_state_gradient: impl FnMut(usize, &[Vec3], &mut [Vec3]) + Send,
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
        self.check_trajectory(trajectory)?;
        // On a worker thread of the pool, as in `shoot`.
        rayon::scope(|_| self.backward_steps(trajectory, u, terminal, add_state_gradient, grad));
        Ok(())
    }

    /// Refuses a trajectory that this flow's forward pass cannot have computed: another step
    /// count, landmark count or kernel cutoff.
    fn check_trajectory(&self, trajectory: &Trajectory) -> Result<()> {
        if trajectory.time_points() != self.steps + 1
            || trajectory.positions[0].len() != self.landmarks
            || trajectory.cutoff.to_bits() != self.kernel.cutoff_radius().to_bits()
        {
            return Err(Error::InvalidParameter(
                "the trajectory was not computed by this flow".into(),
            ));
        }
        Ok(())
    }

    /// The steps of [`Flow::backward`].
    fn backward_steps(
        &self,
        trajectory: &Trajectory,
        u: &[f64],
        terminal: &[Vec3],
        mut add_state_gradient: impl FnMut(usize, &[Vec3], &mut [Vec3]),
        grad: &mut [f64],
    ) {
        let k3 = self.landmarks * 3;
        let mut sweep = PairSweep::new(&self.kernel, self.landmarks);
        let mut adjoint = terminal.to_vec();
        for n in (0..self.steps).rev() {
            let q = &trajectory.positions[n];
            self.adjoint_step(
                &mut sweep,
                &trajectory.layouts[n],
                q,
                self.step_controls(u, n),
                &mut adjoint,
                &mut grad[n * k3..(n + 1) * k3],
            );
            if n > 0 {
                add_state_gradient(n, q, &mut adjoint);
            }
        }
    }

    /// One backward step at the positions `q = q^n` (laid out in `layout`, the forward step's)
    /// with the momenta `u = u^n`: from `a^{n+1}` (in `adjoint`), writes `∂E/∂u^n` to `grad`
    /// and leaves `a^n` without `∇Φ^n` in `adjoint`.
    fn adjoint_step(
        &self,
        sweep: &mut PairSweep<12, 6>,
        layout: &Layout,
        q: &[Vec3],
        u: &[f64],
        adjoint: &mut [Vec3],
        grad: &mut [f64],
    ) {
        let dt = self.dt();
        let w = self.kinetic_weight;
        let c = dt / (self.kernel.sigma() * self.kernel.sigma());
        let b = |a: &Vec3, u: &[f64]| a + w * Vec3::from_column_slice(u);
        for (i, ((qi, ui), ai)) in q.iter().zip(u.chunks_exact(3)).zip(&*adjoint).enumerate() {
            let bi = b(ai, ui);
            sweep.set_point(
                i,
                [
                    qi.x, qi.y, qi.z, ui[0], ui[1], ui[2], ai.x, ai.y, ai.z, bi.x, bi.y, bi.z,
                ],
            );
        }
        sweep.run_laid_out(&AdjointTerms, layout);
        for (i, ((gi, ui), ai)) in grad
            .chunks_exact_mut(3)
            .zip(u.chunks_exact(3))
            .zip(adjoint)
            .enumerate()
        {
            let [gx, gy, gz, rx, ry, rz] = sweep.sums(i);
            // The pair i = j adds b_i to g_i and nothing to r_i.
            let g = b(ai, ui) + Vec3::new(gx, gy, gz);
            gi.copy_from_slice((dt * g).as_slice());
            *ai -= c * Vec3::new(rx, ry, rz);
        }
    }
}

/// Field `f` of the [`LANES`] points of a chunk.
#[inline(always)]
fn field<V: F64Lanes>(chunk: &[f64], f: usize) -> V {
    V::load(&chunk[LANES * f..])
}

/// Each landmark `i` into `sweep` as `(q_i, u_i)`, `u` the step's momenta (`k·3` numbers).
fn load<const C: usize>(sweep: &mut PairSweep<6, C>, q: &[Vec3], u: &[f64]) {
    for (i, (qi, ui)) in q.iter().zip(u.chunks_exact(3)).enumerate() {
        sweep.set_point(i, [qi.x, qi.y, qi.z, ui[0], ui[1], ui[2]]);
    }
}

/// Fields `f … f + 2` (a vector) of point `row`, in every lane.
#[inline(always)]
fn splat3<V: F64Lanes>(row: &[f64], f: usize) -> [V; 3] {
    [V::splat(row[f]), V::splat(row[f + 1]), V::splat(row[f + 2])]
}

/// The velocity terms `K_ij u_j`; a point carries `(q, u)`.
struct VelocityTerms;

impl PairTerms<6, 3> for VelocityTerms {
    #[inline(always)]
    fn accumulate<V: F64Lanes>(
        &self,
        row: &[f64; 6],
        chunk: &[f64],
        kernel: V,
        _d: &[V; 3],
        row_sums: &mut [V; 3],
        col_sums: &mut [f64],
    ) {
        let ui: [V; 3] = splat3(row, 3);
        for c in 0..3 {
            row_sums[c] = kernel.mul_add(field(chunk, 3 + c), row_sums[c]);
            kernel.mul_add_to(ui[c], &mut col_sums[LANES * c..]);
        }
    }
}

/// The velocity-gradient terms `K_ij (q_i − q_j)_a u_{j,b}` (sum `3a + b`; `∇v(q_i)_{ab} =
/// −S_{3a+b}(i)/σ²`); a point carries `(q, u)`.
struct StrainTerms;

impl PairTerms<6, 9> for StrainTerms {
    #[inline(always)]
    fn accumulate<V: F64Lanes>(
        &self,
        row: &[f64; 6],
        chunk: &[f64],
        kernel: V,
        d: &[V; 3],
        row_sums: &mut [V; 9],
        col_sums: &mut [f64],
    ) {
        let ui: [V; 3] = splat3(row, 3);
        for (a, &da) in d.iter().enumerate() {
            // K_ij (q_i − q_j)_a; for the pair seen from j, (q_j − q_i)_a = −d_a.
            let kd = kernel * da;
            for (b, &uib) in ui.iter().enumerate() {
                let c = 3 * a + b;
                row_sums[c] = kd.mul_add(field(chunk, 3 + b), row_sums[c]);
                kd.neg_mul_add_to(uib, &mut col_sums[LANES * c..]);
            }
        }
    }
}

/// The adjoint terms `K_ij b_j` (gradient) and `K_ij s_ij (q_i − q_j)` (adjoint update) with
/// `b = a + w u` and `s_ij = a_i·u_j + a_j·u_i + w u_i·u_j = a_i·u_j + u_i·b_j` (symmetric);
/// a point carries `(q, u, a, b)`.
struct AdjointTerms;

impl PairTerms<12, 6> for AdjointTerms {
    #[inline(always)]
    fn accumulate<V: F64Lanes>(
        &self,
        row: &[f64; 12],
        chunk: &[f64],
        kernel: V,
        d: &[V; 3],
        row_sums: &mut [V; 6],
        col_sums: &mut [f64],
    ) {
        let (ui, ai, bi): ([V; 3], [V; 3], [V; 3]) =
            (splat3(row, 3), splat3(row, 6), splat3(row, 9));
        let uj: [V; 3] = [field(chunk, 3), field(chunk, 4), field(chunk, 5)];
        let bj: [V; 3] = [field(chunk, 9), field(chunk, 10), field(chunk, 11)];
        let a_dot_u = ai[2].mul_add(uj[2], ai[1].mul_add(uj[1], ai[0] * uj[0]));
        let s = ui[2].mul_add(bj[2], ui[1].mul_add(bj[1], ui[0].mul_add(bj[0], a_dot_u)));
        let ks = kernel * s;
        for c in 0..3 {
            row_sums[c] = kernel.mul_add(bj[c], row_sums[c]);
            kernel.mul_add_to(bi[c], &mut col_sums[LANES * c..]);
            row_sums[3 + c] = ks.mul_add(d[c], row_sums[3 + c]);
            ks.neg_mul_add_to(d[c], &mut col_sums[LANES * (3 + c)..]);
        }
    }
}
