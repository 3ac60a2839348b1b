//! Which permutations are drawn: seeded random ones, or all the distinct ones when they are few.
//!
//! A permutation π gives subject i the residual of subject π(i). Subjects whose design rows are
//! equal are exchangeable without changing any statistic, so the distinct permutations are the
//! arrangements of the design rows' classes over the residuals: n! / Πₖ nₖ! of them (nₖ subjects
//! in class k; 70 for two groups of 4, 8! for 8 subjects with a continuous covariate). When that
//! count is at most the number asked for (plus the identity), every arrangement is used once
//! and the p-values are exact. Otherwise permutation k ≥ 1 is a Fisher–Yates shuffle by ChaCha8
//! seeded with the seed and stream k: it depends on (seed, k) only, whatever the thread that
//! draws it. Permutation 0 is always the identity.

use nalgebra::DMatrix;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The permutations of an analysis.
#[derive(Clone, Debug, PartialEq)]
pub enum Scheme {
    /// The identity and `count` seeded random permutations.
    Random {
        /// Subjects.
        subjects: usize,
        /// Random permutations (the total is one more).
        count: usize,
        /// The seed.
        seed: u64,
    },
    /// Every distinct permutation, the identity first.
    Exact(Vec<Vec<u32>>),
}

impl Scheme {
    /// Exact enumeration when the distinct permutations of design `x` number at most
    /// `count + 1`, else the identity and `count` random ones.
    pub fn choose(x: &DMatrix<f64>, count: usize, seed: u64) -> Self {
        let classes = row_classes(x);
        match distinct_arrangements(&classes) {
            Some(k) if k <= count as u128 + 1 => Self::Exact(arrangements(&classes)),
            _ => Self::Random {
                subjects: x.nrows(),
                count,
                seed,
            },
        }
    }

    /// Permutations in all, the identity included.
    pub fn len(&self) -> usize {
        match self {
            Self::Random { count, .. } => count + 1,
            Self::Exact(all) => all.len(),
        }
    }

    /// Whether there is none (never: the identity is always there).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether every distinct permutation is used.
    pub fn is_exact(&self) -> bool {
        matches!(self, Self::Exact(_))
    }

    /// Permutation `k` (0: the identity).
    pub fn permutation(&self, k: usize) -> Vec<u32> {
        match self {
            Self::Exact(all) => all[k].clone(),
            Self::Random { subjects, seed, .. } => {
                let mut p: Vec<u32> = (0..*subjects as u32).collect();
                if k > 0 {
                    let mut rng = ChaCha8Rng::seed_from_u64(*seed);
                    rng.set_stream(k as u64);
                    p.shuffle(&mut rng);
                }
                p
            }
        }
    }
}

/// The class of every row: rows with equal values share one, numbered by first appearance.
pub(crate) fn row_classes(x: &DMatrix<f64>) -> Vec<usize> {
    let mut firsts: Vec<usize> = Vec::new();
    (0..x.nrows())
        .map(
            |i| match firsts.iter().position(|&f| x.row(f) == x.row(i)) {
                Some(c) => c,
                None => {
                    firsts.push(i);
                    firsts.len() - 1
                }
            },
        )
        .collect()
}

/// n! / Πₖ nₖ!, or `None` beyond u128.
pub(crate) fn distinct_arrangements(classes: &[usize]) -> Option<u128> {
    // The product of binomials C(n₁ + … + nₖ, nₖ), each exact in integers.
    let mut counts: Vec<u128> = Vec::new();
    for &c in classes {
        if counts.len() <= c {
            counts.resize(c + 1, 0);
        }
        counts[c] += 1;
    }
    let (mut total, mut placed) = (1_u128, 0_u128);
    for &k in &counts {
        let mut binomial = 1_u128;
        for j in 1..=k {
            binomial = binomial.checked_mul(placed + j)? / j;
        }
        placed += k;
        total = total.checked_mul(binomial)?;
    }
    Some(total)
}

/// Every distinct arrangement of the classes, as permutations, the identity first.
fn arrangements(classes: &[usize]) -> Vec<Vec<u32>> {
    let n = classes.len();
    let class_count = classes.iter().max().map_or(0, |&c| c + 1);
    let members: Vec<Vec<u32>> = (0..class_count)
        .map(|c| {
            (0..n as u32)
                .filter(|&i| classes[i as usize] == c)
                .collect()
        })
        .collect();
    // The arrangement L gives residual j the design row of class L[j]; the k-th residual of
    // class c takes the k-th subject of class c: that is π⁻¹.
    let to_permutation = |arrangement: &[usize]| {
        let mut used = vec![0; class_count];
        let mut permutation = vec![0_u32; n];
        for (j, &c) in arrangement.iter().enumerate() {
            let subject = members[c][used[c]];
            used[c] += 1;
            permutation[subject as usize] = j as u32;
        }
        permutation
    };
    let mut all = vec![to_permutation(classes)];
    let mut arrangement = classes.to_vec();
    arrangement.sort_unstable();
    loop {
        if arrangement != classes {
            all.push(to_permutation(&arrangement));
        }
        // The next arrangement in lexicographic order.
        let Some(i) = (1..n).rev().find(|&i| arrangement[i - 1] < arrangement[i]) else {
            break;
        };
        let j = (i..n)
            .rev()
            .find(|&j| arrangement[j] > arrangement[i - 1])
            .expect("one is larger");
        arrangement.swap(i - 1, j);
        arrangement[i..].reverse();
    }
    all
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;

    #[test]
    fn two_groups_of_four_have_seventy_arrangements() {
        let x = DMatrix::from_fn(8, 2, |i, j| {
            if j == 0 {
                1.0
            } else {
                f64::from(u8::from(i >= 4))
            }
        });
        assert_eq!(row_classes(&x), [0, 0, 0, 0, 1, 1, 1, 1]);
        let scheme = Scheme::choose(&x, 100, 1);
        assert!(scheme.is_exact());
        assert_eq!(scheme.len(), 70);
        assert_eq!(scheme.permutation(0), (0..8).collect::<Vec<u32>>());
        // Distinct as pairings of residuals with groups, and each a permutation.
        let pairings: HashSet<Vec<bool>> = (0..70)
            .map(|k| {
                let p = scheme.permutation(k);
                let mut seen = p.clone();
                seen.sort_unstable();
                assert_eq!(seen, (0..8).collect::<Vec<u32>>());
                // Residual p[i] goes with subject i's group.
                let mut group_of_residual = vec![false; 8];
                for (i, &r) in p.iter().enumerate() {
                    group_of_residual[r as usize] = i >= 4;
                }
                group_of_residual
            })
            .collect();
        assert_eq!(pairings.len(), 70);
        assert!(!Scheme::choose(&x, 68, 1).is_exact());
    }

    #[test]
    fn counts_and_seeded_shuffles() {
        assert_eq!(distinct_arrangements(&[0, 1, 2, 3, 4]), Some(120));
        assert_eq!(distinct_arrangements(&[0, 0, 1, 1, 1, 2]), Some(60));
        assert_eq!(distinct_arrangements(&(0..40).collect::<Vec<_>>()), None);
        let scheme = Scheme::Random {
            subjects: 10,
            count: 5,
            seed: 7,
        };
        assert_eq!(scheme.permutation(3), scheme.permutation(3));
        assert_ne!(scheme.permutation(3), scheme.permutation(4));
        let other = Scheme::Random {
            subjects: 10,
            count: 5,
            seed: 8,
        };
        assert_ne!(scheme.permutation(3), other.permutation(3));
    }
}
