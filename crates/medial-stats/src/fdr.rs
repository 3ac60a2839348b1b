//! False discovery rate: Benjamini–Hochberg q-values.

/// The Benjamini–Hochberg q-value of every p-value: q₍ᵢ₎ = min over j ≥ i of m p₍ⱼ₎ / j
/// (p sorted increasing, m the count of p-values that are not NaN), at most 1. NaN stays NaN.
/// Elements with q ≤ α are the discoveries at false discovery rate α.
///
/// ```
/// let q = medial_stats::q_values(&[0.01, 0.04, f64::NAN, 0.03, 0.5]);
/// assert_eq!(q[0], 0.04);
/// assert!((q[1] - 0.04 * 4.0 / 3.0).abs() < 1e-15);
/// assert!(q[2].is_nan());
/// ```
pub fn q_values(p: &[f64]) -> Vec<f64> {
    let mut order: Vec<usize> = (0..p.len()).filter(|&i| !p[i].is_nan()).collect();
    order.sort_by(|&a, &b| p[a].total_cmp(&p[b]).then(a.cmp(&b)));
    let m = order.len() as f64;
    let mut q = vec![f64::NAN; p.len()];
    let mut running = 1.0_f64;
    for (rank, &i) in order.iter().enumerate().rev() {
        running = running.min(m * p[i] / (rank + 1) as f64);
        q[i] = running;
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// q is the smallest α at which the step-up procedure rejects: p ≤ α·k/m for the k-th
        /// smallest, k the largest such rank.
        #[test]
        fn q_is_the_smallest_rejecting_level(p in proptest::collection::vec(0.0..1.0f64, 1..40)) {
            let q = q_values(&p);
            let m = p.len() as f64;
            let mut sorted = p.clone();
            sorted.sort_by(f64::total_cmp);
            let rejected = |alpha: f64| {
                let k = (1..=p.len()).rev().find(|&k| sorted[k - 1] <= alpha * k as f64 / m).unwrap_or(0);
                if k == 0 { 0.0 } else { sorted[k - 1] }
            };
            for (i, &qi) in q.iter().enumerate() {
                prop_assert!(qi >= p[i] * (1.0 - 1e-15) && qi <= 1.0);
                // Rejected at level q, not at a slightly smaller one.
                prop_assert!(p[i] <= rejected(qi * (1.0 + 1e-12)));
                if qi < 1.0 && qi > 0.0 {
                    prop_assert!(p[i] > rejected(qi * (1.0 - 1e-9)));
                }
            }
        }
    }
}
