//! The flow of space by a fitted flow: any point moves with the velocity field of the landmarks,
//! by the fit's own rule (docs/method.md §3.6), so that meshes, point sets and images can be carried from the
//! template's space to the subject's and back.
//!
//! With the landmark positions `q^n` of the fit's trajectory and its momenta `u^n`, the velocity
//! at time step `n` is `v^n(x) = Σ_j K(x, q^n_j) u^n_j`, `K(x, y) = exp(−|x − y|² / (2σ²))`,
//! summed over all `k` landmarks (the kernel and momenta of [`Flow`]; `dt = 1/N`).
//!
//! - **Forward** `φ₁`: `x^0 = x`, `x^{n+1} = x^n + dt v^n(x^n)` for `n = 0 … N−1` — the forward
//!   Euler rule of the landmarks. At a landmark `x = q^0_i` it *is* the landmark flow, the same
//!   terms summed in another order: the template's points come out at the fit's `q^N` to
//!   round-off.
//! - **Inverse** `φ₁⁻¹`: the same steps undone, `n = N−1 … 0`: `x^n` solves
//!   `x^n + dt v^n(x^n) = x^{n+1}`, by the fixed-point iteration `x ← x^{n+1} − dt v^n(x)` from
//!   `x^{n+1} − dt v^n(x^{n+1})`. It contracts by about `dt·|∇v^n|` per iteration, below 1 for
//!   the small steps of a fitted flow; it stops when an iteration moves the point by at most
//!   [`INVERSE_TOLERANCE`]`·σ`, and a step that has not converged after [`INVERSE_ITERATIONS`]
//!   is an error ([`Error::NotInvertible`]). `φ₁⁻¹(φ₁(x)) = x` to that tolerance.
//!
//! Points are mapped in parallel, each by the same operations whatever the thread count: the
//! results are bit-identical for any number of threads (see [`crate::flow::kernel`]).
//!
//! **Truncated, in blocks** ([`AmbientFlow::map_truncated`]): many points close together (a
//! mesh of many vertices, the nodes of a control grid) can skip, step by step, the landmarks
//! farther than a cutoff radius `r = σ √(2 ln(1/ε))` from every point of their block, whose
//! kernel values are below ε. Each velocity then errs by at most `ε U^n`, `U^n = Σ_j |u^n_j|`,
//! and the map by at most [`AmbientFlow::truncation_bound`]`(ε)`. [`grid`] carries whole images
//! this way, through a control grid.

pub mod grid;

use crate::flow::kernel::{map_points, F64Lanes, GaussianKernel, PointMap, Sources};
use crate::flow::{Flow, Trajectory};
use crate::{Error, Result, Vec3};
use rayon::prelude::*;

/// The fixed-point iteration of a backward step stops when it moves the point by at most this
/// many kernel widths σ.
pub const INVERSE_TOLERANCE: f64 = 1e-10;

/// Most fixed-point iterations of one backward step.
pub const INVERSE_ITERATIONS: usize = 100;

/// The flow of space by the momenta of a fit (see the module documentation).
#[derive(Clone, Debug)]
pub struct AmbientFlow {
    /// The time step of each step: `1/N`, and 1 for a first step that extends a landmark move
    /// ([`Self::after_move`]).
    dts: Vec<f64>,
    /// [`INVERSE_TOLERANCE`]`·σ`.
    tolerance: f64,
    /// The landmarks and momenta of each time step `n = 0 … N−1`.
    steps: Vec<Sources>,
    kernel: GaussianKernel,
    /// `q^n`, `n = 0 … N−1`.
    positions: Vec<Vec<Vec3>>,
    /// `u^n` (`3k` numbers each).
    momenta: Vec<Vec<f64>>,
    /// `U^n = Σ_j |u^n_j|`.
    momentum_sums: Vec<f64>,
    /// `max_i |v^n(q^n_i)|`, the landmarks' fastest speed in step `n`.
    speeds: Vec<f64>,
    /// `S = Σ_n strain^n` (docs/method.md §3.7).
    total_strain: f64,
}

impl AmbientFlow {
    /// The flow of space of `flow` under the momenta `u`, with the landmark trajectory
    /// `trajectory` that [`Flow::shoot`] gives for them.
    ///
    /// Errors: [`Error::ShapeMismatch`] when `u` or the trajectory do not fit `flow`.
    pub fn new(flow: &Flow, trajectory: &Trajectory, u: &[f64]) -> Result<Self> {
        flow.check_sizes(trajectory.positions(0), u)?;
        if trajectory.time_points() != flow.time_steps() + 1 {
            return Err(Error::ShapeMismatch {
                what: "time points of the trajectory".into(),
                expected: flow.time_steps() + 1,
                found: trajectory.time_points(),
            });
        }
        let n_steps = flow.time_steps();
        let steps = (0..n_steps)
            .map(|n| {
                Sources::new(
                    flow.kernel(),
                    trajectory.positions(n),
                    flow.step_controls(u, n),
                )
            })
            .collect();
        let exact = GaussianKernel::new(flow.kernel().sigma())?;
        let strains = flow.step_strains(trajectory, u)?;
        let dt = flow.dt();
        let speeds = (0..n_steps)
            .map(|n| {
                (trajectory.positions(n).iter())
                    .zip(trajectory.positions(n + 1))
                    .map(|(a, b)| (b - a).norm() / dt)
                    .fold(0.0, f64::max)
            })
            .collect();
        let momenta: Vec<Vec<f64>> = (0..n_steps)
            .map(|n| flow.step_controls(u, n).to_vec())
            .collect();
        let momentum_sums = momenta
            .iter()
            .map(|m| {
                m.chunks_exact(3)
                    .map(|c| Vec3::from_column_slice(c).norm())
                    .sum()
            })
            .collect();
        Ok(Self {
            dts: vec![dt; n_steps],
            tolerance: INVERSE_TOLERANCE * flow.kernel().sigma(),
            steps,
            kernel: exact,
            positions: (0..n_steps)
                .map(|n| trajectory.positions(n).to_vec())
                .collect(),
            momenta,
            momentum_sums,
            speeds,
            total_strain: strains.iter().sum(),
        })
    }

    /// This flow after a first move of space that takes the points `from` to `to` exactly and
    /// extends it smoothly to all of space: the kernel interpolation at the flow's σ,
    /// `P(x) = x + Σ_j K(x, from_j) w_j` with `K w = to − from` (solved by Cholesky with two
    /// rounds of iterative refinement), run as one more step with `dt = 1` before the others
    /// (so forward, inverse, truncated and grid maps all include it; its inverse by the same
    /// fixed-point iteration, which converges while the move is small against σ). An automatic
    /// fit's projection onto the constraints after its affine alignment is such a move, known
    /// at the landmarks only.
    ///
    /// Errors: [`Error::ShapeMismatch`] for point sets of different sizes;
    /// [`Error::InvalidParameter`] when the kernel matrix of `from` is singular (two points
    /// at the same place) or a point is not finite.
    ///
    /// ```
    /// use medial_core::flow::ambient::AmbientFlow;
    /// use medial_core::flow::{Flow, FlowParams};
    /// use medial_core::Vec3;
    /// let params = FlowParams { sigma: 1.0, time_steps: 2, kinetic_weight: 0.0 };
    /// let flow = Flow::new(params, 2).unwrap();
    /// let q0 = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.5, 0.0, 0.0)];
    /// let u = vec![0.0; flow.momenta_len()];
    /// let still = AmbientFlow::new(&flow, &flow.shoot(&q0, &u).unwrap(), &u).unwrap();
    /// let from = [Vec3::new(0.0, 0.0, -0.1), Vec3::new(1.5, 0.0, 0.1)];
    /// let moved = still.after_move(&from, &q0).unwrap();
    /// let there = moved.forward(&from).unwrap();
    /// assert!((there[1] - q0[1]).norm() < 1e-12);
    /// ```
    pub fn after_move(mut self, from: &[Vec3], to: &[Vec3]) -> Result<Self> {
        if from.len() != to.len() {
            return Err(Error::ShapeMismatch {
                what: "points after the move".into(),
                expected: from.len(),
                found: to.len(),
            });
        }
        for p in from.iter().chain(to) {
            finite(p, "a point of the move")?;
        }
        let k = from.len();
        let matrix = nalgebra::DMatrix::from_fn(k, k, |i, j| {
            self.kernel
                .of_squared_distance((from[i] - from[j]).norm_squared())
        });
        let moves = nalgebra::DMatrix::from_fn(k, 3, |i, c| to[i][c] - from[i][c]);
        let cholesky = matrix.clone().cholesky().ok_or_else(|| {
            Error::InvalidParameter(
                "the kernel matrix of the moved points is singular (two points at one place?)"
                    .into(),
            )
        })?;
        let mut w = cholesky.solve(&moves);
        for _ in 0..2 {
            let residual = &moves - &matrix * &w;
            w += cholesky.solve(&residual);
        }
        let momenta: Vec<f64> = (0..k)
            .flat_map(|i| [w[(i, 0)], w[(i, 1)], w[(i, 2)]])
            .collect();
        let grad = |x: &Vec3| {
            let mut g = nalgebra::Matrix3::zeros();
            for (j, q) in from.iter().enumerate() {
                let d = x - q;
                let kv = self.kernel.of_squared_distance(d.norm_squared());
                let wj = Vec3::new(w[(j, 0)], w[(j, 1)], w[(j, 2)]);
                g -= kv / (self.sigma() * self.sigma()) * wj * d.transpose();
            }
            g.norm()
        };
        let strain = from.iter().map(grad).fold(0.0, f64::max);
        self.steps
            .insert(0, Sources::new(&self.kernel, from, &momenta));
        self.dts.insert(0, 1.0);
        self.positions.insert(0, from.to_vec());
        self.momentum_sums.insert(
            0,
            momenta
                .chunks_exact(3)
                .map(|c| Vec3::from_column_slice(c).norm())
                .sum(),
        );
        self.speeds.insert(
            0,
            from.iter()
                .zip(to)
                .map(|(a, b)| (b - a).norm())
                .fold(0.0, f64::max),
        );
        self.momenta.insert(0, momenta);
        self.total_strain += strain;
        Ok(self)
    }

    /// The kernel width σ.
    pub fn sigma(&self) -> f64 {
        self.kernel.sigma()
    }

    /// The flow's total strain `S = Σ_n strain^n` (docs/method.md §3.7).
    pub fn total_strain(&self) -> f64 {
        self.total_strain
    }

    /// The amplification `A = e^{4S}` of an error made in one step by the steps after it: each
    /// step `x ↦ x + dt v^n(x)` (or its inverse) stretches distances by at most
    /// `1 + 2 strain^n` (`1/(1 − 2 strain^n)` undone), twice the strain measured at the
    /// landmarks as a margin for the field between them, and `(1 + 2s)/(1 − 2s) ≤ e^{4s}` for
    /// the strains a fit keeps (`s ≤ 0.2`, a little beyond for a margin).
    pub fn amplification(&self) -> f64 {
        (4.0 * self.total_strain).exp()
    }

    /// The largest distance between a point mapped with the kernel truncated at `epsilon` and
    /// the exact map of it: `A ε Σ_n dt U^n` ([`Self::amplification`]; `U^n = Σ_j |u^n_j|`,
    /// each velocity off by at most `ε U^n`), 0 for `ε = 0`.
    pub fn truncation_bound(&self, epsilon: f64) -> f64 {
        let sum: f64 = self
            .momentum_sums
            .iter()
            .zip(&self.dts)
            .map(|(u, dt)| dt * u)
            .sum();
        self.amplification() * epsilon * sum
    }

    /// The kernel tolerance ε whose [`Self::truncation_bound`] is `mm` (at most
    /// [`crate::flow::kernel::MAX_TOLERANCE`]; 0, the exact kernel, when `mm` is 0).
    pub fn truncation_for(&self, mm: f64) -> f64 {
        let per_epsilon = self.truncation_bound(1.0);
        if mm.is_nan() || mm <= 0.0 {
            return 0.0;
        }
        if per_epsilon <= 0.0 {
            return crate::flow::kernel::MAX_TOLERANCE;
        }
        (mm / per_epsilon).min(crate::flow::kernel::MAX_TOLERANCE)
    }

    /// `φ₁(x)` (or `φ₁⁻¹(x)` with `inverse`) of every point, with the kernel truncated at
    /// `epsilon` (0: exact, the same as [`Self::forward`] and [`Self::inverse`] but slower),
    /// the points taken in blocks of consecutive points (`block` of them: give nearby points
    /// together, as a mesh's or a grid's order does). Within [`Self::truncation_bound`] of the
    /// exact map; the same bits for any thread count.
    ///
    /// Errors: as [`Self::forward`] and [`Self::inverse`].
    ///
    /// ```
    /// use medial_core::flow::ambient::AmbientFlow;
    /// use medial_core::flow::{Flow, FlowParams};
    /// use medial_core::Vec3;
    /// let params = FlowParams { sigma: 1.0, time_steps: 4, kinetic_weight: 0.0 };
    /// let flow = Flow::new(params, 2).unwrap();
    /// let q0 = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0)];
    /// let u = vec![0.1; flow.momenta_len()];
    /// let ambient = AmbientFlow::new(&flow, &flow.shoot(&q0, &u).unwrap(), &u).unwrap();
    /// let points: Vec<Vec3> = (0..50).map(|i| Vec3::new(0.2 * i as f64, 0.5, 0.0)).collect();
    /// let exact = ambient.forward(&points).unwrap();
    /// let fast = ambient.map_truncated(&points, false, 1e-12, 16).unwrap();
    /// let bound = ambient.truncation_bound(1e-12);
    /// assert!(exact.iter().zip(&fast).all(|(a, b)| (a - b).norm() <= bound));
    /// ```
    pub fn map_truncated(
        &self,
        points: &[Vec3],
        inverse: bool,
        epsilon: f64,
        block: usize,
    ) -> Result<Vec<Vec3>> {
        let blocks: Vec<Vec<Vec3>> = points.chunks(block.max(1)).map(<[Vec3]>::to_vec).collect();
        self.map_blocks(&blocks, inverse, epsilon)
    }

    /// [`Self::map_truncated`] of the points of `blocks`, each block's landmarks chosen near
    /// it, the results in the order of the blocks.
    pub(crate) fn map_blocks(
        &self,
        blocks: &[Vec<Vec3>],
        inverse: bool,
        epsilon: f64,
    ) -> Result<Vec<Vec3>> {
        let cutoff = self.kernel.truncated(epsilon)?.cutoff_radius();
        let mapped: Vec<Result<Vec<Vec3>>> = blocks
            .par_iter()
            .map(|block| {
                let mut block = block.clone();
                for x in &block {
                    finite(x, "the point")?;
                }
                if inverse {
                    self.inverse_block(&mut block, cutoff)?;
                } else {
                    self.forward_block(&mut block, cutoff)?;
                }
                for y in &block {
                    finite(y, "the flowed point")?;
                }
                Ok(block)
            })
            .collect();
        let mut out = Vec::with_capacity(blocks.iter().map(Vec::len).sum());
        for b in mapped {
            out.extend(b?);
        }
        Ok(out)
    }

    /// The landmarks of step `n` within `radius` of the box `[lo, hi]`, as sources (`None`:
    /// none), and whether they are all of them.
    fn near_sources(&self, n: usize, lo: &Vec3, hi: &Vec3, radius: f64) -> Option<Sources> {
        let r2 = radius * radius;
        let mut q = Vec::new();
        let mut u = Vec::new();
        for (j, p) in self.positions[n].iter().enumerate() {
            let d = Vec3::from_fn(|c, _| (lo[c] - p[c]).max(p[c] - hi[c]).max(0.0));
            if d.norm_squared() <= r2 {
                q.push(*p);
                u.extend_from_slice(&self.momenta[n][3 * j..3 * j + 3]);
            }
        }
        (!q.is_empty()).then(|| Sources::new(&self.kernel, &q, &u))
    }

    /// [`Self::map_truncated`] forward, of one block in place.
    fn forward_block(&self, block: &mut [Vec3], cutoff: f64) -> Result<()> {
        for n in 0..self.steps.len() {
            let (lo, hi) = bounds(block);
            if let Some(sources) = self.near_sources(n, &lo, &hi, cutoff) {
                let moved = map_points(
                    &Step {
                        sources: &sources,
                        dt: self.dts[n],
                    },
                    block,
                )?;
                block.copy_from_slice(&moved);
            }
        }
        Ok(())
    }

    /// [`Self::map_truncated`] inverse, of one block in place: step `n` undone with the
    /// landmarks within `cutoff + m` of the block, `m = 2 dt max_i |v^n(q^n_i)|`; when a point
    /// comes out farther than `m` from the block, the step is undone again with all landmarks.
    fn inverse_block(&self, block: &mut [Vec3], cutoff: f64) -> Result<()> {
        for n in (0..self.steps.len()).rev() {
            let (lo, hi) = bounds(block);
            let margin = 2.0 * self.dts[n] * self.speeds[n] + 1e-9 * self.kernel.sigma();
            let Some(sources) = self.near_sources(n, &lo, &hi, cutoff + margin) else {
                continue;
            };
            let undo = |sources: &Sources| {
                map_points(
                    &Undo {
                        sources,
                        dt: self.dts[n],
                        tolerance: self.tolerance,
                        n,
                    },
                    block,
                )
            };
            let mut before = undo(&sources)?;
            let inside =
                |x: &Vec3| (0..3).all(|c| x[c] >= lo[c] - margin && x[c] <= hi[c] + margin);
            if !before.iter().all(inside) {
                before = undo(&self.steps[n])?;
            }
            block.copy_from_slice(&before);
        }
        Ok(())
    }

    /// `φ₁(x)` for every point.
    ///
    /// Errors: [`Error::NonFinite`] for a point that is not finite or leaves the finite numbers.
    pub fn forward(&self, points: &[Vec3]) -> Result<Vec<Vec3>> {
        map_points(&Forward(self), points)
    }

    /// `φ₁⁻¹(y)` for every point.
    ///
    /// Errors: [`Error::NonFinite`] for a point that is not finite; [`Error::NotInvertible`]
    /// when a backward step does not converge (the first such point, in order).
    pub fn inverse(&self, points: &[Vec3]) -> Result<Vec<Vec3>> {
        map_points(&Inverse(self), points)
    }
}

/// The smallest box holding `points` (an empty box for none).
fn bounds(points: &[Vec3]) -> (Vec3, Vec3) {
    points.iter().fold(
        (Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.inf(p), hi.sup(p)),
    )
}

/// One forward step `x ↦ x + dt v(x)` of some sources.
struct Step<'a> {
    sources: &'a Sources,
    dt: f64,
}

impl PointMap for Step<'_> {
    #[inline(always)]
    fn map<V: F64Lanes>(&self, x: &Vec3) -> Result<Vec3> {
        Ok(x + self.dt * self.sources.velocity::<V>(x))
    }
}

/// Step `n` undone with some sources ([`backward_step`]).
struct Undo<'a> {
    sources: &'a Sources,
    dt: f64,
    tolerance: f64,
    n: usize,
}

impl PointMap for Undo<'_> {
    #[inline(always)]
    fn map<V: F64Lanes>(&self, y: &Vec3) -> Result<Vec3> {
        backward_step::<V>(self.sources, self.dt, self.tolerance, y)
            .map_err(|change| not_invertible(self.n, y, change))
    }
}

/// The error of a backward step `n` from `y` that did not converge.
fn not_invertible(n: usize, y: &Vec3, change: f64) -> Error {
    Error::NotInvertible(format!(
        "the backward step {n} of the flow from ({}, {}, {}) did not converge in \
         {INVERSE_ITERATIONS} fixed-point iterations (last change {change:.3e}): the \
         velocity varies too fast for its time step (more time_steps would invert it)",
        y.x, y.y, y.z
    ))
}

/// Refuses a point that is not finite.
fn finite(x: &Vec3, what: &str) -> Result<()> {
    if x.iter().all(|c| c.is_finite()) {
        Ok(())
    } else {
        Err(Error::NonFinite(format!(
            "{what} ({}, {}, {}) is not finite",
            x.x, x.y, x.z
        )))
    }
}

/// `φ₁` as a map of points.
struct Forward<'a>(&'a AmbientFlow);

impl PointMap for Forward<'_> {
    #[inline(always)]
    fn map<V: F64Lanes>(&self, x: &Vec3) -> Result<Vec3> {
        finite(x, "the point")?;
        let flow = self.0;
        let y = flow
            .steps
            .iter()
            .zip(&flow.dts)
            .fold(*x, |x, (step, &dt)| x + dt * step.velocity::<V>(&x));
        finite(&y, "the flowed point")?;
        Ok(y)
    }
}

/// `φ₁⁻¹` as a map of points.
struct Inverse<'a>(&'a AmbientFlow);

impl PointMap for Inverse<'_> {
    #[inline(always)]
    fn map<V: F64Lanes>(&self, y: &Vec3) -> Result<Vec3> {
        finite(y, "the point")?;
        let flow = self.0;
        let mut next = *y;
        for (n, step) in flow.steps.iter().enumerate().rev() {
            next = backward_step::<V>(step, flow.dts[n], flow.tolerance, &next)
                .map_err(|change| not_invertible(n, y, change))?;
        }
        Ok(next)
    }
}

/// The point `x` with `x + dt v(x) = next` by fixed-point iteration (module documentation), or
/// the last change when it does not converge.
#[inline(always)]
fn backward_step<V: F64Lanes>(
    step: &Sources,
    dt: f64,
    tolerance: f64,
    next: &Vec3,
) -> std::result::Result<Vec3, f64> {
    let mut x = next - dt * step.velocity::<V>(next);
    let mut change = f64::INFINITY;
    for _ in 0..INVERSE_ITERATIONS {
        let better = next - dt * step.velocity::<V>(&x);
        change = (better - x).norm();
        x = better;
        if change <= tolerance {
            return Ok(x);
        }
        if !change.is_finite() {
            break;
        }
    }
    Err(change)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flow::FlowParams;
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A flow of `k` random landmarks in a 8 mm cube under random momenta of size `strength`,
    /// its trajectory, momenta, and `m` random points about the landmarks.
    struct Case {
        flow: Flow,
        trajectory: Trajectory,
        u: Vec<f64>,
        points: Vec<Vec3>,
    }

    fn case(seed: u64, k: usize, steps: usize, strength: f64, m: usize) -> Case {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut point = |scale: f64| {
            Vec3::new(
                rng.gen_range(-scale..scale),
                rng.gen_range(-scale..scale),
                rng.gen_range(-scale..scale),
            )
        };
        let q0: Vec<Vec3> = (0..k).map(|_| point(4.0)).collect();
        let points = (0..m).map(|_| point(6.0)).collect();
        let u: Vec<f64> = (0..steps * k)
            .flat_map(|_| {
                let v = point(strength);
                [v.x, v.y, v.z]
            })
            .collect();
        let params = FlowParams {
            sigma: 1.5,
            time_steps: steps,
            kinetic_weight: 0.01,
        };
        let flow = Flow::new(params, k).unwrap();
        let trajectory = flow.shoot(&q0, &u).unwrap();
        Case {
            flow,
            trajectory,
            u,
            points,
        }
    }

    fn ambient(c: &Case) -> AmbientFlow {
        AmbientFlow::new(&c.flow, &c.trajectory, &c.u).unwrap()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(32))]

        #[test]
        fn the_template_comes_out_at_the_last_landmarks(
            seed in 0u64..1000, k in 1usize..120, steps in 1usize..12
        ) {
            let c = case(seed, k, steps, 0.5, 0);
            let moved = ambient(&c).forward(c.trajectory.positions(0)).unwrap();
            for (a, b) in moved.iter().zip(c.trajectory.final_positions()) {
                prop_assert!((a - b).norm() <= 1e-12 * (1.0 + b.norm()), "{a} vs {b}");
            }
        }

        #[test]
        fn the_inverse_undoes_the_forward_map(
            seed in 0u64..1000, k in 1usize..80, steps in 1usize..12
        ) {
            // Momenta small enough that every step is invertible a priori:
            // dt |∇v| ≤ dt · k · |u|max · √3 · e^{-1/2} / σ ≤ 0.35 (|u| ≤ 0.5 · steps / k per
            // component), the condition the inverse needs (module documentation).
            let strength = 0.5 * (steps as f64 / k as f64).min(1.0);
            let c = case(seed, k, steps, strength, 40);
            let flow = ambient(&c);
            let there = flow.forward(&c.points).unwrap();
            let back = flow.inverse(&there).unwrap();
            for (x, b) in c.points.iter().zip(&back) {
                prop_assert!((x - b).norm() <= 1e-8, "{x} → {b}");
            }
            let again = flow.forward(&flow.inverse(&c.points).unwrap()).unwrap();
            for (x, a) in c.points.iter().zip(&again) {
                prop_assert!((x - a).norm() <= 1e-8, "{x} → {a}");
            }
        }
    }

    #[test]
    fn maps_are_the_same_bits_whatever_the_thread_count() {
        let c = case(7, 150, 6, 0.5, 500);
        let flow = ambient(&c);
        let with_threads = |n| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap();
            pool.install(|| {
                let forward = flow.forward(&c.points).unwrap();
                (flow.inverse(&forward).unwrap(), forward)
            })
        };
        let one = with_threads(1);
        assert_eq!(one, with_threads(2));
        assert_eq!(one, with_threads(3));
    }

    #[test]
    fn a_step_too_large_to_undo_is_an_error() {
        // One step of momenta far beyond the kernel width: dt·|∇v| ≫ 1.
        let c = case(3, 20, 1, 200.0, 30);
        let err = ambient(&c).inverse(&c.points).unwrap_err();
        assert!(matches!(err, Error::NotInvertible(_)), "{err}");
        assert!(err.to_string().contains("did not converge"), "{err}");
    }

    #[test]
    fn points_that_are_not_finite_are_refused() {
        let c = case(3, 5, 2, 0.5, 0);
        let flow = ambient(&c);
        let bad = [Vec3::new(0.0, f64::NAN, 0.0)];
        assert!(matches!(flow.forward(&bad), Err(Error::NonFinite(_))));
        assert!(matches!(flow.inverse(&bad), Err(Error::NonFinite(_))));
    }

    #[test]
    fn momenta_of_another_size_are_refused() {
        let c = case(3, 5, 2, 0.5, 0);
        let err = AmbientFlow::new(&c.flow, &c.trajectory, &c.u[3..]).unwrap_err();
        assert!(matches!(err, Error::ShapeMismatch { .. }), "{err}");
    }
}
