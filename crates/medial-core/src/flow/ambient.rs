//! The flow of space by a fitted flow: any point moves with the velocity field of the landmarks,
//! by the fit's own rule (SPEC §3), so that meshes, point sets and images can be carried from the
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

use crate::flow::kernel::{map_points, F64Lanes, PointMap, Sources};
use crate::flow::{Flow, Trajectory};
use crate::{Error, Result, Vec3};

/// The fixed-point iteration of a backward step stops when it moves the point by at most this
/// many kernel widths σ.
pub const INVERSE_TOLERANCE: f64 = 1e-10;

/// Most fixed-point iterations of one backward step.
pub const INVERSE_ITERATIONS: usize = 100;

/// The flow of space by the momenta of a fit (see the module documentation).
#[derive(Clone, Debug)]
pub struct AmbientFlow {
    dt: f64,
    /// [`INVERSE_TOLERANCE`]`·σ`.
    tolerance: f64,
    /// The landmarks and momenta of each time step `n = 0 … N−1`.
    steps: Vec<Sources>,
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
        let steps = (0..flow.time_steps())
            .map(|n| {
                Sources::new(
                    flow.kernel(),
                    trajectory.positions(n),
                    flow.step_controls(u, n),
                )
            })
            .collect();
        Ok(Self {
            dt: flow.dt(),
            tolerance: INVERSE_TOLERANCE * flow.kernel().sigma(),
            steps,
        })
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
            .fold(*x, |x, step| x + flow.dt * step.velocity::<V>(&x));
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
            next = backward_step::<V>(step, flow.dt, flow.tolerance, &next).map_err(|change| {
                Error::NotInvertible(format!(
                    "the backward step {n} of the flow from ({}, {}, {}) did not converge in \
                     {INVERSE_ITERATIONS} fixed-point iterations (last change {change:.3e}): the \
                     velocity varies too fast for its time step (more time_steps would invert it)",
                    y.x, y.y, y.z
                ))
            })?;
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
            let c = case(seed, k, steps, 0.5, 40);
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
