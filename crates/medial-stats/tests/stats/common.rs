//! Random designs and data, seeded.

use medial_stats::{Design, Observations};
use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A design of n subjects: intercept, a two-level group, a continuous covariate.
pub fn design(n: usize, seed: u64) -> Design {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let x = DMatrix::from_fn(n, 3, |i, j| match j {
        0 => 1.0,
        1 => f64::from(u8::from(i % 2 == 1)),
        _ => rng.gen_range(-1.0..1.0),
    });
    Design::new(vec!["intercept".into(), "group".into(), "age".into()], x).unwrap()
}

/// Standard normal noise (Box–Muller), `n` subjects × `m` elements, element-major.
pub fn noise(n: usize, m: usize, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n * m)
        .map(|_| {
            let (u, v): (f64, f64) = (rng.gen_range(f64::EPSILON..1.0), rng.gen());
            (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
        })
        .collect()
}

/// Noise plus `effect` × the group column.
pub fn data(design: &Design, m: usize, effect: f64, seed: u64) -> Observations {
    let n = design.subjects();
    let mut values = noise(n, m, seed);
    for e in 0..m {
        for i in 0..n {
            values[e * n + i] += effect * design.matrix()[(i, 1)] * (e % 3) as f64;
        }
    }
    Observations::new(n, values).unwrap()
}
