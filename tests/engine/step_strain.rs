//! The strain of each step of the flow (`Flow::step_strains`, `dt · max_i ‖∇v^n(q^n_i)‖_F`)
//! against central finite differences of the velocity field written out densely, exact and with
//! a truncated kernel, on any thread count.

use medial::flow::{Flow, FlowParams};
use medial::Vec3;
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Landmarks in a 6 mm box and momenta of size about `speed`.
fn case(seed: u64, k: usize, steps: usize, speed: f64) -> (Vec<Vec3>, Vec<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let q = (0..k)
        .map(|_| {
            Vec3::new(
                rng.gen_range(-3.0..3.0),
                rng.gen_range(-3.0..3.0),
                rng.gen_range(-3.0..3.0),
            )
        })
        .collect();
    let u = (0..steps * k * 3)
        .map(|_| rng.gen_range(-speed..speed))
        .collect();
    (q, u)
}

/// `v(x) = Σ_j exp(−|x − q_j|²/(2σ²)) u_j`, written out.
fn velocity(x: Vec3, q: &[Vec3], u: &[f64], sigma: f64) -> Vec3 {
    (q.iter().zip(u.chunks_exact(3)))
        .map(|(qj, uj)| {
            (-(x - qj).norm_squared() / (2.0 * sigma * sigma)).exp() * Vec3::from_column_slice(uj)
        })
        .sum()
}

/// `dt · max_i ‖∇v(q_i)‖_F` of each step by central differences of [`velocity`].
fn strains_by_differences(flow: &Flow, q0: &[Vec3], u: &[f64]) -> Vec<f64> {
    let trajectory = flow.shoot(q0, u).unwrap();
    let (k, h, sigma) = (q0.len(), 1e-5, flow.kernel().sigma());
    (0..flow.time_steps())
        .map(|n| {
            let (q, un) = (trajectory.positions(n), &u[n * k * 3..(n + 1) * k * 3]);
            let largest = (q.iter())
                .map(|&x| {
                    (0..3)
                        .map(|a| {
                            let e = h * Vec3::ith(a, 1.0);
                            let d = (velocity(x + e, q, un, sigma) - velocity(x - e, q, un, sigma))
                                / (2.0 * h);
                            d.norm_squared()
                        })
                        .sum::<f64>()
                        .sqrt()
                })
                .fold(0.0, f64::max);
            flow.dt() * largest
        })
        .collect()
}

#[test]
fn the_strain_of_each_step_is_the_velocity_gradient_at_the_landmarks() {
    let (q, u) = case(7, 40, 4, 2.0);
    let params = FlowParams {
        sigma: 1.5,
        time_steps: 4,
        kinetic_weight: 0.01,
    };
    let flow = Flow::new(params, q.len()).unwrap();
    let strains = flow.step_strains(&flow.shoot(&q, &u).unwrap(), &u).unwrap();
    let expected = strains_by_differences(&flow, &q, &u);
    assert_eq!(strains.len(), 4);
    for (s, e) in strains.iter().zip(&expected) {
        assert!(
            (s - e).abs() <= 1e-8 * e.max(1.0),
            "{strains:?} against {expected:?}"
        );
        assert!(*s > 0.0);
    }
    // Momenta twice as large: the first step's strain twice as large (its positions are the
    // template's).
    let doubled: Vec<f64> = u.iter().map(|x| 2.0 * x).collect();
    let twice = flow
        .step_strains(&flow.shoot(&q, &doubled).unwrap(), &doubled)
        .unwrap();
    assert!((twice[0] - 2.0 * strains[0]).abs() <= 1e-12 * strains[0]);
    // With the kernel truncated at 1e-10 the strains move by far less than that.
    let truncated = Flow::new(params, q.len())
        .unwrap()
        .with_kernel_tolerance(1e-10)
        .unwrap();
    let near = truncated
        .step_strains(&truncated.shoot(&q, &u).unwrap(), &u)
        .unwrap();
    for (a, b) in near.iter().zip(&strains) {
        assert!((a - b).abs() <= 1e-8 * b, "{near:?} against {strains:?}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(8))]
    /// The same bits on one thread as on the pool.
    #[test]
    fn the_strains_do_not_depend_on_the_thread_count(seed in 0u64..1000, k in 2usize..120) {
        let (q, u) = case(seed, k, 3, 1.0);
        let params = FlowParams { sigma: 1.0, time_steps: 3, kinetic_weight: 0.0 };
        let flow = Flow::new(params, k).unwrap();
        let trajectory = flow.shoot(&q, &u).unwrap();
        let pooled = flow.step_strains(&trajectory, &u).unwrap();
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let single = one.install(|| flow.step_strains(&trajectory, &u).unwrap());
        prop_assert_eq!(pooled.iter().map(|s| s.to_bits()).collect::<Vec<_>>(), single.iter().map(|s| s.to_bits()).collect::<Vec<_>>());
    }
}
