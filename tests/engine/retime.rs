//! Momenta and multipliers carried between time grids (coarse to fine in time,
//! `AlSchedule::coarse_time_steps`): refining repeats each step's momenta, coarsening averages
//! them back, the refined flow follows the coarse one to first order in the step, and the
//! multipliers are interpolated in time.

use medial::fit::augmented_lagrangian::retime_multipliers;
use medial::flow::{retime_momenta, Flow, FlowParams};
use medial::Vec3;
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// `k` landmarks in a 4 mm box and momenta in `steps` steps of size about `speed`.
fn case(seed: u64, k: usize, steps: usize, speed: f64) -> (Vec<Vec3>, Vec<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let q = (0..k)
        .map(|_| Vec3::from_fn(|_, _| rng.gen_range(-2.0..2.0)))
        .collect();
    let u = (0..steps * k * 3)
        .map(|_| rng.gen_range(-speed..speed))
        .collect();
    (q, u)
}

fn flow(steps: usize, k: usize) -> Flow {
    let params = FlowParams {
        sigma: 1.5,
        time_steps: steps,
        kinetic_weight: 0.1,
    };
    Flow::new(params, k).unwrap()
}

proptest! {
    #[test]
    fn refining_repeats_each_step_and_coarsening_averages_it_back(
        seed in 0u64..1000, k in 1usize..6, steps in 1usize..5, f in 1usize..5,
    ) {
        let (_, u) = case(seed, k, steps, 1.0);
        let fine = retime_momenta(&u, k, steps, f * steps).unwrap();
        prop_assert_eq!(fine.len(), f * steps * k * 3);
        for (m, step) in fine.chunks_exact(k * 3).enumerate() {
            prop_assert_eq!(step, &u[(m / f) * k * 3..(m / f + 1) * k * 3]);
        }
        let back = retime_momenta(&fine, k, f * steps, steps).unwrap();
        for (a, b) in back.iter().zip(&u) {
            prop_assert!((a - b).abs() <= 1e-15 * b.abs(), "{a} against {b}");
        }
    }

    #[test]
    fn multipliers_keep_the_coarse_time_points_and_interpolate_between(
        seed in 0u64..1000, l in 1usize..5, steps in 1usize..5, f in 1usize..4,
    ) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let lambda: Vec<f64> = (0..steps * l).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let fine = retime_multipliers(&lambda, l, steps, f * steps);
        prop_assert_eq!(fine.len(), f * steps * l);
        let scale = 1.0 / f as f64;
        let coarse = |n: usize, j: usize| lambda[(n.max(1) - 1) * l + j];
        for m in 1..=f * steps {
            let (n, r) = (m / f, (m % f) as f64 / f as f64);
            for j in 0..l {
                let expected = scale * ((1.0 - r) * coarse(n, j) + r * coarse((n + 1).min(steps), j));
                prop_assert!((fine[(m - 1) * l + j] - expected).abs() <= 1e-15);
            }
        }
    }
}

#[test]
fn the_refined_flow_follows_the_coarse_one_to_first_order_in_the_step() {
    // Forward Euler in 2·N steps of the repeated momenta against N steps: the end points
    // differ by O(dt² · |∇v| |v|) per step, i.e. quadratically in the momenta's size.
    let (k, steps) = (12, 3);
    let gap = |speed: f64| {
        let (q0, u) = case(7, k, steps, speed);
        let coarse = flow(steps, k).shoot(&q0, &u).unwrap();
        let fine_flow = flow(2 * steps, k);
        let fine = fine_flow
            .shoot(&q0, &fine_flow.retimed_momenta(&u, steps).unwrap())
            .unwrap();
        let ke = (coarse.kinetic_energy() - fine.kinetic_energy()).abs() / coarse.kinetic_energy();
        let end = coarse
            .final_positions()
            .iter()
            .zip(fine.final_positions())
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        (end, ke)
    };
    let (big, big_ke) = gap(0.4);
    let (small, small_ke) = gap(0.1);
    assert!(big > 1e-6, "the two grids differ: {big}");
    // Four times smaller momenta: about sixteen times closer (quadratic), not four (linear).
    assert!(small < big / 10.0, "{small} against {big}");
    assert!(
        small_ke < big_ke / 2.0 && big_ke < 0.05,
        "{small_ke} {big_ke}"
    );
}

#[test]
fn momenta_between_grids_that_do_not_divide_are_refused() {
    let u = vec![0.0; 3 * 2 * 3];
    assert!(retime_momenta(&u, 2, 3, 4).is_err());
    assert!(retime_momenta(&u, 2, 3, 0).is_err());
    assert!(retime_momenta(&u[1..], 2, 3, 6).is_err());
}
