//! The exact adjoint gradient of the objective against central finite differences and an
//! independent dense implementation; determinism across thread counts and kernel caching.

use medial::attachment::ssd::Ssd;
use medial::attachment::Attachment;
use medial::fit::objective::{ConstraintSet, Objective, Penalty};
use medial::flow::{Flow, FlowParams};
use medial::testing::dense;
use medial::Vec3;
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Squared-distance constraints between landmark pairs: `C = |q_a − q_b|² − d²`.
struct PairDistances(Vec<(usize, usize, f64)>);

impl ConstraintSet for PairDistances {
    fn len(&self) -> usize {
        self.0.len()
    }
    fn evaluate(&self, q: &[Vec3], out: &mut [f64]) {
        for (o, &(a, b, d)) in out.iter_mut().zip(&self.0) {
            *o = (q[a] - q[b]).norm_squared() - d * d;
        }
    }
    fn accumulate_gradient(&self, q: &[Vec3], weights: &[f64], grad: &mut [Vec3]) {
        for (w, &(a, b, _)) in weights.iter().zip(&self.0) {
            let g = 2.0 * w * (q[a] - q[b]);
            grad[a] += g;
            grad[b] -= g;
        }
    }
}

struct Case {
    template: Vec<Vec3>,
    targets: Vec<Vec3>,
    controls: Vec<f64>,
    params: FlowParams,
    constraints: PairDistances,
    lambda: Vec<f64>,
    mu: f64,
}

fn random_case(seed: u64, k: usize, steps: usize) -> Case {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut point = |scale: f64| {
        Vec3::new(
            rng.gen_range(-scale..scale),
            rng.gen_range(-scale..scale),
            rng.gen_range(-scale..scale),
        )
    };
    let template: Vec<Vec3> = (0..k).map(|_| point(4.0)).collect();
    let nb = k * 2 / 3;
    let targets: Vec<Vec3> = template[..nb].iter().map(|p| p + point(1.0)).collect();
    let controls: Vec<f64> = (0..steps * k * 3)
        .map(|_| rng.gen_range(-1.5..1.5))
        .collect();
    let pairs: Vec<(usize, usize, f64)> = (0..k / 2)
        .map(|i| (i, k - 1 - i, rng.gen_range(0.5..3.0)))
        .collect();
    let lambda: Vec<f64> = (0..steps * pairs.len())
        .map(|_| rng.gen_range(-0.5..0.5))
        .collect();
    Case {
        template,
        targets,
        controls,
        params: FlowParams {
            sigma: 1.7,
            time_steps: steps,
            kinetic_weight: 0.05,
        },
        constraints: PairDistances(pairs),
        lambda,
        mu: 0.7,
    }
}

fn evaluate(case: &Case, flow: &Flow, u: &[f64], grad: Option<&mut [f64]>) -> f64 {
    let ssd = Ssd::new(case.targets.clone()).unwrap();
    let objective = Objective::new(flow, &case.template, &ssd, 1.3)
        .with_penalty(Penalty {
            constraints: &case.constraints,
            mu: case.mu,
            lambda: &case.lambda,
        })
        .unwrap();
    objective.evaluate(u, grad).unwrap().total
}

fn flow_of(case: &Case) -> Flow {
    Flow::new(case.params, case.template.len()).unwrap()
}

#[test]
fn gradient_matches_central_differences() {
    for seed in 0..4 {
        let case = random_case(seed, 24, 6);
        let flow = flow_of(&case);
        let mut grad = vec![0.0; case.controls.len()];
        evaluate(&case, &flow, &case.controls, Some(&mut grad));
        let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
        for _ in 0..5 {
            let dir: Vec<f64> = (0..grad.len()).map(|_| rng.gen_range(-1.0..1.0)).collect();
            let h = 1e-5;
            let shifted = |s: f64| -> Vec<f64> {
                case.controls
                    .iter()
                    .zip(&dir)
                    .map(|(u, d)| u + s * d)
                    .collect()
            };
            let fd = (evaluate(&case, &flow, &shifted(h), None)
                - evaluate(&case, &flow, &shifted(-h), None))
                / (2.0 * h);
            let exact: f64 = grad.iter().zip(&dir).map(|(g, d)| g * d).sum();
            let rel = (fd - exact).abs() / exact.abs().max(1e-12);
            assert!(rel <= 1e-6, "seed {seed}: directional derivative {exact} vs finite difference {fd} (rel {rel:e})");
        }
    }
}

#[test]
fn gradient_matches_dense_implementation() {
    for seed in 0..3 {
        let case = random_case(seed, 40, 8);
        let flow = flow_of(&case);
        let mut grad = vec![0.0; case.controls.len()];
        let value = evaluate(&case, &flow, &case.controls, Some(&mut grad));
        let ssd = Ssd::new(case.targets.clone()).unwrap();
        let steps = case.params.time_steps;
        let l = case.constraints.len();
        let (dense_value, dense_grad) = dense::objective(
            &case.template,
            &case.controls,
            case.params.sigma,
            steps,
            case.params.kinetic_weight,
            |n, q| {
                let mut c = vec![0.0; l];
                case.constraints.evaluate(q, &mut c);
                let lam = &case.lambda[(n - 1) * l..n * l];
                let mut value: f64 = c
                    .iter()
                    .zip(lam)
                    .map(|(c, lam)| 0.5 * case.mu * c * c - lam * c)
                    .sum();
                let weights: Vec<f64> = c
                    .iter()
                    .zip(lam)
                    .map(|(c, lam)| case.mu * c - lam)
                    .collect();
                let mut g = vec![Vec3::zeros(); q.len()];
                case.constraints.accumulate_gradient(q, &weights, &mut g);
                if n == steps {
                    let mut gd = vec![Vec3::zeros(); q.len()];
                    value += 1.3 * ssd.evaluate(q, Some(&mut gd)).unwrap().value;
                    g.iter_mut().zip(&gd).for_each(|(g, d)| *g += 1.3 * d);
                }
                (value, g)
            },
        );
        assert!(
            (value - dense_value).abs() <= 1e-12 * dense_value.abs(),
            "value {value} vs dense {dense_value}"
        );
        let scale = dense_grad.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        let worst = grad
            .iter()
            .zip(&dense_grad)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(
            worst <= 1e-10 * scale,
            "seed {seed}: max gradient difference {worst:e} (scale {scale:e})"
        );
    }
}

fn bits_with_threads(case: &Case, threads: usize) -> (u64, Vec<u64>) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let flow = flow_of(case);
        let mut grad = vec![0.0; case.controls.len()];
        let v = evaluate(case, &flow, &case.controls, Some(&mut grad));
        (v.to_bits(), grad.iter().map(|g| g.to_bits()).collect())
    })
}

#[test]
fn same_bits_with_one_two_or_three_threads() {
    let case = random_case(7, 301, 5);
    let reference = bits_with_threads(&case, 1);
    assert_eq!(reference, bits_with_threads(&case, 2));
    assert_eq!(reference, bits_with_threads(&case, 3));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Zero controls leave the template in place and cost only the attachment at the template.
    #[test]
    fn zero_controls_are_the_identity(seed in 0u64..1000, k in 2usize..30, steps in 1usize..6) {
        let case = random_case(seed, k, steps);
        let flow = flow_of(&case);
        let zero = vec![0.0; case.controls.len()];
        let trajectory = flow.shoot(&case.template, &zero).unwrap();
        prop_assert_eq!(trajectory.final_positions(), &case.template[..]);
        prop_assert_eq!(trajectory.kinetic_energy(), 0.0);
    }

    /// The kinetic energy is a positive semi-definite quadratic form of each step's controls.
    #[test]
    fn kinetic_energy_is_non_negative(seed in 0u64..1000, k in 1usize..25, steps in 1usize..5) {
        let case = random_case(seed, k, steps);
        let trajectory = flow_of(&case).shoot(&case.template, &case.controls).unwrap();
        prop_assert!(trajectory.kinetic_energy() >= 0.0);
    }
}

#[test]
fn bad_sizes_and_parameters_are_errors() {
    let case = random_case(1, 10, 3);
    let flow = flow_of(&case);
    assert!(flow.shoot(&case.template, &case.controls[1..]).is_err());
    assert!(flow.shoot(&case.template[1..], &case.controls).is_err());
    assert!(Flow::new(
        FlowParams {
            time_steps: 0,
            ..case.params
        },
        10
    )
    .is_err());
    assert!(Flow::new(
        FlowParams {
            sigma: -1.0,
            ..case.params
        },
        10
    )
    .is_err());
    assert!(Flow::new(
        FlowParams {
            kinetic_weight: f64::NAN,
            ..case.params
        },
        10
    )
    .is_err());
}

/// A case spread over a box 40 mm wide (σ = 1.7 mm), where a truncated kernel skips pairs.
fn spread_case(seed: u64, k: usize, steps: usize) -> Case {
    let mut case = random_case(seed, k, steps);
    for p in case.template.iter_mut().chain(&mut case.targets) {
        *p *= 5.0;
    }
    case
}

/// The truncated flow skips the same pairs in both passes, so its gradient is the exact
/// gradient of the truncated objective (ε = 1e-10: a pair crossing the cut under the finite
/// difference's step would move the value by at most ~1e-10 × the sums of the terms).
#[test]
fn truncated_gradient_matches_central_differences() {
    for seed in 0..3 {
        let case = spread_case(seed, 150, 4);
        let flow = flow_of(&case).with_kernel_tolerance(1e-10).unwrap();
        let mut grad = vec![0.0; case.controls.len()];
        let value = evaluate(&case, &flow, &case.controls, Some(&mut grad));
        let mut exact_grad = vec![0.0; case.controls.len()];
        let exact_value = evaluate(
            &case,
            &flow_of(&case),
            &case.controls,
            Some(&mut exact_grad),
        );
        assert!((value - exact_value).abs() <= 1e-8 * exact_value.abs());
        let mut rng = ChaCha8Rng::seed_from_u64(200 + seed);
        for _ in 0..4 {
            let dir: Vec<f64> = (0..grad.len()).map(|_| rng.gen_range(-1.0..1.0)).collect();
            let h = 1e-5;
            let shifted = |s: f64| -> Vec<f64> {
                (case.controls.iter().zip(&dir))
                    .map(|(u, d)| u + s * d)
                    .collect()
            };
            let fd = (evaluate(&case, &flow, &shifted(h), None)
                - evaluate(&case, &flow, &shifted(-h), None))
                / (2.0 * h);
            let derivative: f64 = grad.iter().zip(&dir).map(|(g, d)| g * d).sum();
            let rel = (fd - derivative).abs() / derivative.abs().max(1e-12);
            assert!(
                rel <= 1e-6,
                "seed {seed}: {derivative} vs finite difference {fd} (rel {rel:e})"
            );
        }
    }
}

#[test]
fn truncated_flow_is_the_same_bits_with_one_two_or_three_threads() {
    let case = spread_case(8, 700, 3);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let flow = flow_of(&case).with_kernel_tolerance(1e-8).unwrap();
            let mut grad = vec![0.0; case.controls.len()];
            let v = evaluate(&case, &flow, &case.controls, Some(&mut grad));
            (
                v.to_bits(),
                grad.iter().map(|g| g.to_bits()).collect::<Vec<_>>(),
            )
        })
    };
    let one = run(1);
    assert_eq!(one, run(2));
    assert_eq!(one, run(3));
}

#[test]
fn bad_kernel_tolerances_are_errors() {
    let case = random_case(1, 10, 3);
    for eps in [-1e-9, 0.7, f64::NAN] {
        assert!(
            flow_of(&case).with_kernel_tolerance(eps).is_err(),
            "ε = {eps}"
        );
    }
}
