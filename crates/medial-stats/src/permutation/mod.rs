//! Permutation inference (Nichols & Holmes 2002; Winkler et al. 2014): the statistic recomputed
//! under permutations of the residuals (Freedman–Lane), and per permutation the maximum over
//! elements of the statistic, of the clusters' area and mass, and of TFCE. A p-value corrected
//! for the family-wise error is the fraction of permutations (the identity among them) whose
//! maximum reaches the observed value: p = #{k : maxₖ ≥ s} / N.
//!
//! Permutations are computed in parallel in fixed batches (each one matrix product per block of
//! elements) and every permutation is drawn from its own index ([`Scheme`]); the maxima are kept
//! per permutation and counted afterwards, so the results have the same bits for any number of
//! threads.
//!
//! | file | what it holds |
//! |---|---|
//! | `scheme` | [`Scheme`]: seeded random permutations or exact enumeration |

mod scheme;

pub use scheme::Scheme;

use rayon::prelude::*;

use crate::mesh::{largest_extents, tfce_into, Elements, Forest, TfceParameters, TfceScratch};
use crate::{Glm, Tail};

/// Permutations per batch: one matrix product per block of elements for all of them.
const BATCH: usize = 16;

/// What permutations measure beyond the maximum statistic.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Spatial<'a> {
    pub(crate) elements: &'a Elements,
    pub(crate) threshold: Option<f64>,
    pub(crate) tfce: Option<TfceParameters>,
}

/// The maxima of every permutation, the identity first: the null distributions.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NullDistributions {
    /// The maximum statistic (|t| if two-sided).
    pub statistic: Vec<f64>,
    /// The largest cluster area, with a cluster threshold.
    pub area: Vec<f64>,
    /// The largest cluster mass, with a cluster threshold.
    pub mass: Vec<f64>,
    /// The largest |TFCE|, with TFCE.
    pub tfce: Vec<f64>,
}

/// The maxima of one permutation.
#[derive(Clone, Copy, Debug, Default)]
struct Maxima {
    statistic: f64,
    area: f64,
    mass: f64,
    tfce: f64,
}

/// The statistic as inference sees it: |t| when two-sided.
pub(crate) fn magnitude(s: f64, tail: Tail) -> f64 {
    match tail {
        Tail::Positive => s,
        Tail::Both => s.abs(),
    }
}

/// The largest value that is not NaN, or −∞.
fn largest(values: impl Iterator<Item = f64>) -> f64 {
    values
        .filter(|v| !v.is_nan())
        .fold(f64::NEG_INFINITY, f64::max)
}

/// The observed maps (from permutation 0, the identity, computed with the others so that its
/// bits are those the maxima are compared with) and the null distributions.
pub(crate) struct Permuted {
    pub(crate) statistic: Vec<f64>,
    pub(crate) tfce: Option<Vec<f64>>,
    pub(crate) null: NullDistributions,
}

/// The maxima of a batch's permutations and, for the first batch, the observed maps.
type Batch = (Vec<Maxima>, Option<(Vec<f64>, Option<Vec<f64>>)>);

/// Runs every permutation of `scheme` through `glm`.
pub(crate) fn run(glm: &Glm, scheme: &Scheme, tail: Tail, spatial: Option<Spatial>) -> Permuted {
    let m = glm.elements();
    let batches = scheme.len().div_ceil(BATCH);
    let results: Vec<Batch> = (0..batches)
        .into_par_iter()
        .map_init(
            || {
                (
                    Vec::new(),
                    Forest::new(m),
                    TfceScratch::new(m),
                    vec![0.0; m],
                )
            },
            |(maps, forest, scratch, tfce_map), b| {
                let range = b * BATCH..((b + 1) * BATCH).min(scheme.len());
                let permutations: Vec<Vec<u32>> =
                    range.clone().map(|k| scheme.permutation(k)).collect();
                maps.resize(permutations.len() * m, 0.0);
                glm.statistics(&permutations, maps);
                let mut observed = None;
                let maxima = maps
                    .chunks_exact(m)
                    .enumerate()
                    .map(|(i, map)| {
                        let mut maxima = Maxima {
                            statistic: largest(map.iter().map(|&s| magnitude(s, tail))),
                            ..Maxima::default()
                        };
                        let mut tfce_values = None;
                        if let Some(spatial) = spatial {
                            if let Some(h) = spatial.threshold {
                                (maxima.area, maxima.mass) =
                                    largest_extents(map, h, tail, spatial.elements, forest);
                            }
                            if let Some(parameters) = &spatial.tfce {
                                tfce_into(
                                    map,
                                    parameters,
                                    tail,
                                    spatial.elements,
                                    scratch,
                                    tfce_map,
                                );
                                maxima.tfce = largest(tfce_map.iter().map(|v| v.abs()));
                                if b == 0 && i == 0 {
                                    tfce_values = Some(tfce_map.clone());
                                }
                            }
                        }
                        if b == 0 && i == 0 {
                            observed = Some((map.to_vec(), tfce_values));
                        }
                        maxima
                    })
                    .collect();
                (maxima, observed)
            },
        )
        .collect();
    let mut null = NullDistributions::default();
    let mut observed = None;
    for (maxima, first) in results {
        observed = observed.or(first);
        for x in maxima {
            null.statistic.push(x.statistic);
            if spatial.is_some_and(|s| s.threshold.is_some()) {
                null.area.push(x.area);
                null.mass.push(x.mass);
            }
            if spatial.is_some_and(|s| s.tfce.is_some()) {
                null.tfce.push(x.tfce);
            }
        }
    }
    let (statistic, tfce) = observed.expect("the identity is permutation 0");
    Permuted {
        statistic,
        tfce,
        null,
    }
}

/// The critical value of a null distribution at level `alpha`: the smallest of its values
/// whose p (as the p-values of permutations count it: the fraction of the N maxima, the identity included,
/// that reach it) is at most `alpha`, so that an observed value is significant exactly when it
/// reaches it: the (N − ⌊alpha N⌋ + 1)-th smallest without ties (the 951st of 1,000 at 0.05).
/// `None` for an empty distribution or one too short for any value to reach `alpha`.
///
/// ```
/// let null: Vec<f64> = (1..=100).map(f64::from).collect();
/// assert_eq!(medial_stats::permutation::critical_value(&null, 0.05), Some(96.0));
/// ```
pub fn critical_value(null: &[f64], alpha: f64) -> Option<f64> {
    let mut sorted = null.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    let allowed = ((alpha * n as f64).floor() as usize).min(n);
    if allowed == 0 {
        return None;
    }
    let candidate = sorted[n - allowed];
    let reaching = n - sorted.partition_point(|&x| x < candidate);
    if reaching <= allowed {
        Some(candidate)
    } else {
        sorted.into_iter().find(|&x| x > candidate)
    }
}

/// For each value, the fraction of `null` that reaches it: #{k : nullₖ ≥ v} / N (NaN for NaN).
pub(crate) fn exceedance(values: impl Iterator<Item = f64>, null: &[f64]) -> Vec<f64> {
    let mut sorted = null.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len() as f64;
    values
        .map(|v| {
            if v.is_nan() {
                f64::NAN
            } else {
                (sorted.len() - sorted.partition_point(|&x| x < v)) as f64 / n
            }
        })
        .collect()
}
